"""Tests of servotau.actuator.toml_writer."""

import math
import tomllib

import pytest

from servotau.actuator import toml_writer as tw


def test_values_round_trip_through_tomllib():
    """Strings with quotes, backslashes and control characters, floats and inline tables read back equal."""
    values = {
        "s": 'a "b" \\ c\n\t\x01\x7f é \U0001f600',
        "f": [1e-300, 5.1e-05, 1.0 / 3.0, -0.0, 1e20],
        "t": {"x y": 1.5, "n": 3, "b": True},
    }
    text = "\n".join(
        [
            f"s = {tw.value(values['s'])}",
            *(f"f{i} = {tw.value(v)}" for i, v in enumerate(values["f"])),
            f"t = {tw.value(values['t'])}",
            f"{tw.key('a.b')} = 1",
        ]
    )
    data = tomllib.loads(text)
    assert data["s"] == values["s"] and data["t"] == values["t"] and data["a.b"] == 1
    for i, v in enumerate(values["f"]):
        assert data[f"f{i}"] == v and math.copysign(1, data[f"f{i}"]) == math.copysign(1, v)


def test_non_finite_refused():
    """NaN and inf cannot be written."""
    with pytest.raises(ValueError, match="non-finite"):
        tw.value(math.nan)
