"""Tests of servotau.actuator.model and .motor_file: the MotorModel and its TOML file."""

import math

import numpy as np
import pytest

from servotau.actuator import EffectTerm, FitMetrics, Loss, MotorModel, MotorParameters
from servotau.config import CONFIG_DIR
from servotau.errors import ConfigError, IdentificationError
from servotau.identification import fit_linear_model, fit_two_stage, make_synthetic

GOOD = """version = 1
[joints.RLEG_JOINT3]
k_tau = 5.1e-05
k_v = 0.006561
loss = "asymmetric"
w = 10.0
provenance = "test"
[joints.RLEG_JOINT3.metrics]
rms = 1e-4
overestimation_rate = 0.05
n_samples = 1000
"""


def params():
    return MotorParameters(
        {
            "RLEG_JOINT3": MotorModel(
                k_tau=5.1e-5,
                k_v=0.006561,
                k_c=1.234567890123e-4,
                extra={"deadzone": EffectTerm(1e-3, {"e_deadzone": 3e-3, "tau_band": 0.7})},
                loss=Loss.asymmetric(10.0),
                provenance='runs/ident.parquet; 2025-01-01; backend=mujoco; "quoted" \\ tab\t',
                metrics=FitMetrics(1.1e-4, 0.031, 20000),
            ),
            "joint with space": MotorModel(k_tau=1.0 / 3.0, k_v=0.0, provenance="hand"),
        }
    )


def test_round_trip(tmp_path):
    """save_toml then load_toml gives back equal parameters, floats bit for bit."""
    p = params()
    path = p.save_toml(tmp_path / "motors" / "m.toml")
    back = MotorParameters.load_toml(path)
    assert back == p
    assert back["joint with space"].k_tau == 1.0 / 3.0
    assert list(back) == ["RLEG_JOINT3", "joint with space"] and len(back) == 2


def test_from_fit_and_predict(tmp_path):
    """A model built from a fit carries its coefficients, loss and metrics, and predicts like the fit."""
    d = make_synthetic(500, seed=0)
    fit = fit_linear_model(d.tau, d.dq, d.dq_err, coulomb=True, loss=Loss.asymmetric(5.0))
    m = MotorModel.from_fit(fit, provenance="synthetic")
    assert (m.k_tau, m.k_v, m.k_c) == (fit["k_tau"], fit["k_v"], fit["k_c"])
    assert m.loss == Loss.asymmetric(5.0) and m.metrics.n_samples == 500
    expected = fit.x @ np.vstack([d.tau, d.dq, np.sign(d.dq)])
    np.testing.assert_allclose(m.predict(d.tau, d.dq), expected, rtol=1e-12, atol=1e-15)
    two = MotorModel.from_fit(fit_two_stage(d.tau, d.dq, d.dq_err, moving_loss=Loss.asymmetric(5.0)), "synthetic")
    assert "two-stage losses" in two.provenance and two.k_c is None


def test_example_file_loads():
    """config/motors/example.toml is a valid motor-parameter file."""
    p = MotorParameters.load_toml(CONFIG_DIR / "motors" / "example.toml")
    assert "RLEG_JOINT3" in p and p["RLEG_JOINT3"].k_tau > 0


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        (
            "k_tau = 5.1e-05",
            "k_tau = -5.1e-05",
            r"field 'joints.RLEG_JOINT3.k_tau' = -5.1e-05: expected a finite "
            r"number > 0 \[rad/\(N m\)\]",
        ),
        ("k_v = 0.006561\n", "", r"field 'joints.RLEG_JOINT3.k_v' missing: expected a finite number >= 0"),
        ("k_v = 0.006561", "k_v = nan", r"field 'joints.RLEG_JOINT3.k_v' = nan: expected a finite number"),
        ("w = 10.0", "w = 1.0", r"field 'joints.RLEG_JOINT3.w' = 1.0: expected a finite number > 1"),
        ('loss = "asymmetric"', 'loss = "huber"', r"field 'joints.RLEG_JOINT3.loss' = 'huber': expected one of"),
        ("rms = 1e-4", "rms = 1e-4\nrmse = 2", r"field 'joints.RLEG_JOINT3.metrics.rmse' = 2: expected a known"),
        (
            "overestimation_rate = 0.05",
            "overestimation_rate = 1.5",
            r"overestimation_rate' = 1.5: expected a "
            r"finite number >= 0 <= 1",
        ),
        ("version = 1", "version = 2", r"field 'version' = 2: expected 1"),
        ('provenance = "test"\n', "", r"field 'joints.RLEG_JOINT3.provenance' missing: expected a string"),
    ],
)
def test_bad_file_names_file_and_field(tmp_path, old, new, match):
    """A bad value, missing field, NaN or unknown field fails with the file, the field and the expectation."""
    path = tmp_path / "bad.toml"
    assert old in GOOD
    path.write_text(GOOD.replace(old, new))
    with pytest.raises(ConfigError, match=match) as err:
        MotorParameters.load_toml(path)
    assert str(err.value).startswith(str(path))


def test_constructor_validates():
    """MotorModel refuses negative, non-finite or missing values at construction."""
    with pytest.raises(IdentificationError, match=r"k_tau = -1.0: expected a finite number > 0"):
        MotorModel(k_tau=-1.0, k_v=0.01, provenance="x")
    with pytest.raises(IdentificationError, match=r"k_v = nan"):
        MotorModel(k_tau=1e-4, k_v=math.nan, provenance="x")
    with pytest.raises(IdentificationError, match=r"provenance = '': expected a non-empty string"):
        MotorModel(k_tau=1e-4, k_v=0.01)
    with pytest.raises(IdentificationError, match=r"overestimation_rate = 2: expected a number in \[0, 1\]"):
        FitMetrics(1e-4, 2, 10)
    with pytest.raises(IdentificationError, match=r"joint 'J9' has no motor model"):
        params()["J9"]


def test_membership_of_an_unknown_joint_is_false_and_lookup_names_it():
    """`joint in params` answers False for an unknown joint; params[joint] raises naming the known joints."""
    import pytest as _pytest

    from servotau.actuator import MotorParameters
    from servotau.config import CONFIG_DIR
    from servotau.errors import IdentificationError

    params = MotorParameters.load_toml(CONFIG_DIR / "motors" / "hrp2_sim_identified.toml")
    assert "RLEG_JOINT3" in params and "LARM_JOINT0" not in params
    with _pytest.raises(IdentificationError, match="RLEG_JOINT0"):
        params["LARM_JOINT0"]
