"""Tests of servotau.actuator.toml_writer (tomli-w with a header and the refusal of non-finite floats)."""

import math
import tomllib

import pytest

from servotau.actuator import toml_writer as tw
from servotau.actuator.model import EffectTerm, FitMetrics, MotorModel
from servotau.actuator.motor_file import MotorParameters


def test_values_round_trip_through_tomllib():
    """Strings with quotes, backslashes and control characters, floats, nested and inline-worthy tables and
    dotted keys read back equal (signs of zero included); the header lines come first as comments."""
    data = {
        "s": 'a "b" \\ c\n\t\x01\x7f é \U0001f600',
        "f": [1e-300, 5.1e-05, 1.0 / 3.0, -0.0, 1e20],
        "t": {"x y": 1.5, "n": 3, "b": True, "deep": {"a.b": 1}},
        "empty": {},
    }
    text = tw.dumps(data, ["first line", "second: [rad]"])
    assert text.startswith("# first line\n# second: [rad]\n")
    back = tomllib.loads(text)
    assert back == data
    for v, w in zip(back["f"], data["f"], strict=True):
        assert math.copysign(1, v) == math.copysign(1, w)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_refused_naming_the_key(bad):
    """NaN and infinity cannot be written; the error names the dotted key."""
    with pytest.raises(ValueError, match=r"non-finite float joints\.J\.k_v"):
        tw.dumps({"joints": {"J": {"k_v": bad}}})


def test_motor_file_content_is_what_the_hand_written_writer_wrote(tmp_path):
    """The motor file written through tomli-w parses to the same table as the former writer's text (kept here
    verbatim for one joint with metrics and an extra term, and one model of another target)."""
    servo = MotorModel(k_tau=5.1e-05, k_v=0.006561, k_c=1e-4, provenance='log "a"; 2025',
                       metrics=FitMetrics(rms=1.2e-4, overestimation_rate=0.04, n_samples=20000),
                       extra={"deadzone": EffectTerm(0.001, {"e_deadzone": 0.003})})
    friction = MotorModel(k_tau=None, k_v=2.98, k_c=1.49, offset=0.2, target="torque", unit="N m",
                          provenance="friction.csv")
    path = MotorParameters({"RLEG_JOINT3": servo, "joint x": friction}).save_toml(tmp_path / "m.toml")
    former = """
version = 1

[joints.RLEG_JOINT3]
k_tau = 5.1e-05
k_v = 0.006561
k_c = 0.0001
loss = "least_squares"
provenance = "log \\"a\\"; 2025"

[joints.RLEG_JOINT3.metrics]
rms = 0.00012
overestimation_rate = 0.04
n_samples = 20000

[joints.RLEG_JOINT3.extra.deadzone]
coefficient = 0.001
shape = { e_deadzone = 0.003 }

[joints."joint x"]
target = "torque"
unit = "N m"
k_v = 2.98
k_c = 1.49
offset = 0.2
loss = "least_squares"
provenance = "friction.csv"
"""
    text = path.read_text()
    assert tomllib.loads(text) == tomllib.loads(former)
    assert text.startswith("# servotau motor parameters:") and "# A joint with 'target'" in text
    back = MotorParameters.load_toml(path)
    assert back["RLEG_JOINT3"].extra["deadzone"].shape == {"e_deadzone": 0.003}
