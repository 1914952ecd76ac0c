"""The TOML config loader: sections, and config dataclasses declared with ``setting``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from servotau.config import Section, check_settings, load_dataclass, setting
from servotau.errors import ConfigError, ControlError


@dataclass(frozen=True)
class _Inner:
    rate: float = setting(2.0, unit="1/s", min=0)


@dataclass(frozen=True)
class _Settings:
    period: float = setting(unit="s", min=0, strict_min=True)
    count: int = setting(3, min=1)
    enabled: bool = setting(True)
    mode: str = setting("fast", choices=("fast", "slow"))
    gains: tuple[float, ...] = setting((1.0, 2.0), unit="-", min=0)
    offset: tuple[float, float, float] = setting((0.0, 0.0, 0.0), unit="m")
    limit: float | None = setting(None, unit="rad", min=0, strict_min=True)
    inner: _Inner = setting(_Inner())

    def __post_init__(self):
        check_settings(self, ControlError)


def _section(data: dict) -> Section:
    return Section(data, "cfg.toml", "ctl")


def test_load_dataclass_reads_fields_and_keeps_defaults():
    """Present keys are converted to the field types; absent keys take the dataclass defaults."""
    s = load_dataclass(_Settings, _section({"period": 1e-3, "gains": [1, 0.5], "limit": 0.1, "inner": {"rate": 4}}))
    assert s == _Settings(period=1e-3, gains=(1.0, 0.5), limit=0.1, inner=_Inner(4.0))
    assert isinstance(s.gains, tuple) and isinstance(s.gains[0], float)
    assert s.count == 3 and s.mode == "fast" and s.offset == (0.0, 0.0, 0.0)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({}, "cfg.toml: field 'ctl.period' missing: expected a value > 0 [s]"),
        ({"period": 0.0}, "cfg.toml: field 'ctl.period' = 0.0: expected a finite number > 0 [s]"),
        ({"period": 1, "count": 0}, "field 'ctl.count' = 0: expected an integer >= 1"),
        ({"period": 1, "count": 2.5}, "field 'ctl.count' = 2.5: expected an integer >= 1"),
        ({"period": 1, "enabled": 1}, "field 'ctl.enabled' = 1: expected true or false"),
        ({"period": 1, "mode": "medium"}, "field 'ctl.mode' = 'medium': expected one of ['fast', 'slow']"),
        ({"period": 1, "gains": [1, -1]}, "field 'ctl.gains' = [1, -1]: expected a list of finite numbers >= 0 [-]"),
        ({"period": 1, "offset": [0, 0]}, "field 'ctl.offset' = [0, 0]: expected a list of 3 finite numbers [m]"),
        ({"period": 1, "inner": {"rate": -1}}, "field 'ctl.inner.rate' = -1: expected a finite number >= 0 [1/s]"),
        ({"period": 1, "perod": 1}, "field 'ctl.perod' = 1: expected a known field, one of"),
    ],
)
def test_load_dataclass_errors_name_file_field_value_and_expected(data, message):
    """A bad value is refused with the file, the dotted field, the value and the expected value and unit."""
    with pytest.raises(ConfigError) as exc:
        load_dataclass(_Settings, _section(data))
    assert message in str(exc.value)


def test_load_dataclass_ignores_keys_owned_by_another_reader_and_takes_given_fields():
    """``ignore`` lets a sub-table pass; ``given`` fields are not read from the file."""
    s = load_dataclass(_Settings, _section({"count": 5, "other": {}}), ignore=["other"], period=0.5)
    assert (s.period, s.count) == (0.5, 5)


def test_check_settings_validates_direct_construction_with_the_callers_error():
    """Building the dataclass directly checks the same bounds and raises the caller's error type."""
    with pytest.raises(ControlError, match=r"_Settings.period = -1: expected a finite number > 0 \[s\]"):
        _Settings(period=-1)
    with pytest.raises(ControlError, match=r"_Settings.inner = 3: expected a _Inner"):
        _Settings(period=1, inner=3)
    assert _Settings(period=1).period == 1.0 and isinstance(_Settings(period=1).period, float)


def test_post_init_errors_are_reported_with_the_file():
    """An error raised by the dataclass's own checks names the file and section."""

    @dataclass(frozen=True)
    class Ordered:
        low: float = setting(0.0)
        high: float = setting(1.0)

        def __post_init__(self):
            if self.high <= self.low:
                raise ControlError(f"Ordered.high = {self.high}: expected > low = {self.low}")

    with pytest.raises(ConfigError, match=r"cfg.toml \[ctl\]: Ordered.high = 0.0: expected > low = 1.0"):
        load_dataclass(Ordered, _section({"low": 1.0, "high": 0.0}))


@dataclass(frozen=True)
class _Window:
    window: int = setting(80, min="order + 2")
    order: int = setting(2, min=0)
    hold: float = setting(0.05, unit="s", min=0, strict_min=True)
    off: float = setting(1.0, unit="s", min="hold", strict_min=True)

    def __post_init__(self):
        check_settings(self, ControlError)


def test_a_bound_may_name_another_field():
    """``min="order + 2"`` bounds a field by another one (given or default); the message shows both."""
    assert load_dataclass(_Window, _section({"window": 4})) == _Window(4, 2)
    with pytest.raises(ConfigError, match=r"field 'ctl.window' = 3: expected an integer >= order \+ 2 = 4$"):
        load_dataclass(_Window, _section({"window": 3}))
    with pytest.raises(ConfigError, match=r"field 'ctl.window' = 80: expected an integer >= order \+ 2 = 82"):
        load_dataclass(_Window, _section({"order": 80}))
    with pytest.raises(ConfigError, match=r"field 'ctl.off' = 1.0: expected a finite number > hold = 2 \[s\]"):
        load_dataclass(_Window, _section({"hold": 2.0}))
    with pytest.raises(ControlError, match=r"_Window.off = 0.01: expected a finite number > hold = 0.05 \[s\]"):
        _Window(off=0.01)


def test_base_instance_fills_missing_keys_and_nested_tables_start_from_the_field_default():
    """``base`` supplies the missing keys; a nested table's missing keys keep the field default's values."""
    assert load_dataclass(_Window, _section({"window": 10}), base=_Window(20, 3)) == _Window(10, 3)

    @dataclass(frozen=True)
    class Outer:
        enc: _Window = setting(_Window(40, 3))

    assert load_dataclass(Outer, _section({"enc": {"window": 30}})).enc == _Window(30, 3)


@dataclass(frozen=True)
class _Arrays:
    bias: np.ndarray = setting(unit="rad/s", shape=(3,), factory=lambda: np.zeros(3))
    ranges: np.ndarray = setting(unit="N", min=0, shape=(2, 2), factory=lambda: np.ones((2, 2)))

    def __post_init__(self):
        check_settings(self, ControlError)


def test_arrays_of_a_given_shape():
    """An ``np.ndarray`` field is read from (nested) lists of numbers of its shape, bounds per element."""
    a = load_dataclass(_Arrays, _section({"bias": [1, 2, 3]}))
    assert a.bias.tolist() == [1.0, 2.0, 3.0] and a.bias.dtype == float and a.ranges.tolist() == [[1, 1], [1, 1]]
    with pytest.raises(ConfigError, match=r"'ctl.bias' = \[1, 2\]: expected a list of 3 finite numbers \[rad/s\]"):
        load_dataclass(_Arrays, _section({"bias": [1, 2]}))
    with pytest.raises(ConfigError, match=r"'ctl.bias' = \[1, True, 3\]: expected a list of 3 finite numbers"):
        load_dataclass(_Arrays, _section({"bias": [1, True, 3]}))
    with pytest.raises(ConfigError, match=r"'ctl.ranges' = \[\[1, -1\], \[1, 1\]\]: expected a 2 x 2 array of "
                                          r"finite numbers >= 0 \[N\]"):
        load_dataclass(_Arrays, _section({"ranges": [[1, -1], [1, 1]]}))
    with pytest.raises(ControlError, match=r"_Arrays.bias = \[0.0, 0.0\]: expected a list of 3 finite numbers"):
        _Arrays(bias=np.zeros(2))


def test_numpy_scalars_are_numbers():
    """numpy integers and floats pass as int and float (converted to the Python types)."""
    w = _Window(np.int64(10), np.int64(2), np.float32(0.5), 2.0)
    assert type(w.window) is int and w.window == 10 and type(w.hold) is float


def test_read_setting_reads_one_field_under_another_key():
    """``read_setting`` applies a field's type, bounds, unit and default to a key of another layout."""
    from servotau.config import read_setting

    sec = Section({"resolution": 2, "bad": -1}, "cfg.toml", "encoders")
    assert read_setting(_Settings, "period", sec, "resolution") == 2.0
    assert read_setting(_Settings, "count", sec, "missing") == 3
    with pytest.raises(ConfigError, match=r"field 'encoders.bad' = -1: expected a finite number > 0 \[s\]"):
        read_setting(_Settings, "period", sec, "bad")
    with pytest.raises(ConfigError, match=r"field 'encoders.period' missing: expected a value > 0 \[s\]"):
        read_setting(_Settings, "period", sec)
