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


def test_notes_head_the_file_as_comments_and_change_nothing_read(tmp_path):
    """save_toml(notes): the notes are the file's first comment lines; the parameters read back are the same."""
    p = params()
    text = p.save_toml(tmp_path / "m.toml", ["chosen by a test", "  RLEG_JOINT3: kept"]).read_text()
    assert text.startswith("# chosen by a test\n#   RLEG_JOINT3: kept\n# servotau motor parameters")
    assert MotorParameters.load_toml(tmp_path / "m.toml") == p


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
        ("n_samples = 1000\n", "n_samples = 1000\n[joints.RLEG_JOINT3.extra.stribeck]\ncoefficient = 1e-4\n"
         "[joints.RLEG_JOINT3.extra.stribeck.shape]\nv_s = -5.0\n",
         r"field 'joints.RLEG_JOINT3.extra.stribeck.shape.v_s' = -5.0: expected a finite number >= 0"),
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


def test_a_servo_model_file_keeps_its_format_byte_for_byte(tmp_path):
    """A servo-error model with k_tau and no offset writes no target, unit or offset key (the format of every
    existing motor file), and every shipped file reads as a servo-error model with k_tau."""
    m = MotorModel(k_tau=5.1e-5, k_v=0.006561, k_c=1e-4, loss=Loss.asymmetric(10.0), provenance="test",
                   metrics=FitMetrics(1e-4, 0.05, 1000))
    text = MotorParameters({"RLEG_JOINT3": m}).save_toml(tmp_path / "m.toml").read_text()
    assert text == (
        "# servotau motor parameters: dq_err = k_tau*tau + k_v*dq [+ k_c*sign(dq)] [+ extra terms]\n"
        "# Units: k_tau [rad/(N m)], k_v [rad/(rad/s)], k_c [rad], rms [rad].\nversion = 1\n\n"
        '[joints.RLEG_JOINT3]\nk_tau = 5.1e-05\nk_v = 0.006561\nk_c = 0.0001\nloss = "asymmetric"\nw = 10.0\n'
        'provenance = "test"\n\n[joints.RLEG_JOINT3.metrics]\nrms = 0.0001\noverestimation_rate = 0.05\n'
        "n_samples = 1000\n")
    for f in sorted((CONFIG_DIR / "motors").glob("*.toml")):
        p = MotorParameters.load_toml(f)
        assert all(p.servo_model(j).k_tau > 0 and p[j].offset is None and p[j].is_servo_error for j in p)


def test_a_model_without_k_tau_of_another_target_round_trips(tmp_path):
    """k_tau None (not in the model), an offset, target and unit: saved and read back equal; the signs of
    k_tau and k_v are free for a target that is not the servo error, checked for one that is."""
    m = MotorModel(k_tau=None, k_v=-3.0, k_c=1.5, offset=0.2, provenance="friction.csv", target="torque", unit="N m")
    path = MotorParameters({"J": m, "S": MotorModel(k_tau=-2.0, k_v=0.1, provenance="x", target="y", unit="A")}
                           ).save_toml(tmp_path / "f.toml")
    text = path.read_text()
    assert "\n[joints.J]\ntarget = \"torque\"\nunit = \"N m\"\nk_v = -3.0\nk_c = 1.5\noffset = 0.2\n" in text
    back = MotorParameters.load_toml(path)
    assert back["J"] == m and back["S"].k_tau == -2.0 and back.source == str(path)
    assert back["J"].terms().linear == ("k_v", "offset")
    dq = np.array([-0.5, 0.0, 0.25])
    np.testing.assert_allclose(back["J"].predict(None, dq), -3.0 * dq + 1.5 * np.sign(dq) + 0.2)
    with pytest.raises(IdentificationError, match=r"k_v = -3.0: expected a finite number >= 0 \[rad/\(rad/s\)\]"):
        MotorModel(k_tau=None, k_v=-3.0, provenance="x")
    path.write_text(path.read_text().replace('target = "torque"\nunit = "N m"\n', ""))
    with pytest.raises(ConfigError, match=r"field 'joints.J.k_v' = -3.0: expected a finite number >= 0"):
        MotorParameters.load_toml(path)


def test_the_controller_and_the_estimator_refuse_a_model_they_cannot_use(tmp_path):
    """MotorParameters.servo_model, and through it the control and estimation configs, refuse a model without
    k_tau, with an offset or of another target, naming the file, the joint and the key."""
    import copy
    import tomllib

    from servotau.control.config import ControlConfig
    from servotau.description import JOINT_NAMES, MODEL_PATH
    from servotau.estimation.config import EstimatorConfig
    from servotau.hal.types import RobotInfo

    shipped = MotorParameters.load_toml(CONFIG_DIR / "motors" / "hrp2_sim_identified.toml")
    m3 = shipped["RLEG_JOINT3"]
    cases = {"k_tau": MotorModel(None, m3.k_v, m3.k_c, provenance="user"),
             "offset": MotorModel(m3.k_tau, m3.k_v, offset=1e-4, provenance="user"),
             "target": MotorModel(None, 3.0, offset=0.2, provenance="user", target="torque", unit="N m")}
    with open(CONFIG_DIR / "control.toml", "rb") as f:
        control = tomllib.load(f)
    info = RobotInfo("test-robot", JOINT_NAMES, -np.full(30, 3.0), np.full(30, 3.0), 1e-3, str(MODEL_PATH))
    for key, bad in cases.items():
        path = MotorParameters({**shipped.models, "RLEG_JOINT3": bad}).save_toml(tmp_path / f"{key}.toml")
        expected = rf"^{path}: field 'joints\.RLEG_JOINT3\.{key}' "
        with pytest.raises(ConfigError, match=expected):
            MotorParameters.load_toml(path).servo_model("RLEG_JOINT3")
        data = copy.deepcopy(control)
        data["motors"] = str(path)
        with pytest.raises(ConfigError, match=rf"joints\.RLEG_JOINT3\.{key}"):
            ControlConfig.from_mapping(data, info)
        est = tmp_path / f"est_{key}.toml"
        est.write_text(f"[prediction]\nmotors = '{path}'\njoints = ['RLEG_JOINT3']\n")
        with pytest.raises(ConfigError, match=rf"{path}: field 'joints\.RLEG_JOINT3\.{key}'"):
            EstimatorConfig.from_toml(est)
    with pytest.raises(IdentificationError, match=r"^here: field 'k_tau' missing: expected the torque gain k_tau > 0"):
        cases["k_tau"].check_servo("here")
