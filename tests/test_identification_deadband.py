"""Tests of servotau.identification.deadband (the dead band on the holds of a log, through the data layer) and of
`servotau model add --save --dead-band holds` (the controller's motor file in one step)."""

import json
from types import SimpleNamespace

import numpy as np
import pytest
from support.identification import collect_short_log

from servotau.actuator import EffectTerm, MotorModel, MotorParameters
from servotau.actuator.effects.deadzone import BAND
from servotau.cli import main as cli
from servotau.identification.deadband import main as deadband_main
from servotau.identification.deadband import with_dead_bands

K_TAU = 2e-4  # [rad/(N m)]
JOINT = "RLEG_JOINT3"
ADD = ["--joint", JOINT, "--base", "paper", "--loss", "asymmetric", "--w", "100", "--effect", "coulomb", "--effects",
       "coulomb", "--quiet"]


def _holds(d=4e-4, n=2000, noise=2e-5, seed=0):
    """Samples at rest with torques of both signs: dq_err = k_tau tau + d sign(tau) + noise."""
    rng = np.random.default_rng(seed)
    tau = np.concatenate([rng.uniform(1.5, 20.0, n), rng.uniform(-20.0, -1.5, n)])
    dq_err = K_TAU * tau + d * np.sign(tau) + noise * rng.standard_normal(2 * n)
    return dq_err, tau, np.zeros(2 * n)


def test_with_dead_bands_completes_every_joint_of_a_motor_file_from_the_aligned_holds():
    """The motor file's deadzone terms come from the holds of the data layer's aligned samples, with each joint's
    own k_tau; the other terms and the joints' order are kept."""
    dq_err, tau, dq = _holds(d=3e-4)
    samples = {"A": SimpleNamespace(dq_err=dq_err, tau=tau, dq=dq),
               "B": SimpleNamespace(dq_err=dq_err + 1e-4 * tau, tau=tau, dq=dq)}  # k_tau 3e-4 for B
    coulomb = {"coulomb": EffectTerm(1e-4, {"v_eps": 0.01})}
    base = MotorParameters({"A": MotorModel(K_TAU, 0.01, extra=coulomb, provenance="fit A"),
                            "B": MotorModel(K_TAU + 1e-4, 0.01, provenance="fit B")})
    params, bands = with_dead_bands(base, SimpleNamespace(samples=samples), "log.parquet")
    assert list(params) == ["A", "B"] and set(bands) == {"A", "B"}
    for joint in ("A", "B"):
        dz = params[joint].extra["deadzone"]
        assert dz.coefficient == pytest.approx(3e-4, abs=3e-6) == bands[joint].d
        assert dz.shape == {"band": BAND, "damping_share": 0.0}
        assert params[joint].provenance.endswith("deadzone: identification/deadband.py on the holds of log.parquet")
    assert list(params["A"].extra) == ["deadzone", "coulomb"]


@pytest.fixture(scope="module")
def ident_log(tmp_path_factory):
    """A 15 s simulated collection: the knee swept, then two holds pushed through zero torque."""
    return collect_short_log(tmp_path_factory.mktemp("deadband"))


def test_model_add_with_the_dead_band_of_the_holds_writes_the_two_step_file(ident_log, tmp_path, capsys, monkeypatch):
    """`model add --save OUT --dead-band holds` writes, byte for byte, what `model add --save` then
    `python -m servotau.identification.deadband` write: the workbench's model with its deadzone term measured on
    the holds of the same log (with the model's own k_tau)."""
    monkeypatch.chdir(ident_log.parent)  # the provenance names the log as given
    fitted, two_step, one_step = tmp_path / "fitted.toml", tmp_path / "two_step.toml", tmp_path / "one_step.toml"
    assert cli(["model", "add", ident_log.name, *ADD, "--save", str(fitted)]) == 0
    assert deadband_main([ident_log.name, str(fitted), str(two_step)]) == 0
    capsys.readouterr()
    assert cli(["model", "add", ident_log.name, *ADD, "--save", str(one_step), "--dead-band", "holds", "--json"]) == 0
    saved = json.loads(capsys.readouterr().out)["saved"]
    assert one_step.read_bytes() == two_step.read_bytes()
    model = MotorParameters.load_toml(one_step)[JOINT]
    fit = MotorParameters.load_toml(fitted)[JOINT]
    dz = model.extra["deadzone"]
    assert dz.shape == {"band": BAND, "damping_share": 0.0} and dz.coefficient == saved["dead_band"] > 0
    assert (model.k_tau, model.k_v, model.k_c, model.metrics) == (fit.k_tau, fit.k_v, fit.k_c, fit.metrics)
    holds = f"deadzone: identification/deadband.py on the holds of {ident_log.name}"
    assert model.provenance == f"{fit.provenance}; {holds}"


@pytest.mark.parametrize(("argv", "message"), [
    ([], "--dead-band holds: expected --save FILE"),
    (["--save", "{tmp}/x.toml"], "names no joint: expected a servotau log"),
])
def test_dead_band_option_needs_a_saved_joint_of_a_servotau_log(capsys, tmp_path, argv, message):
    """--dead-band without --save, or on a table that names no joint, is a clean error before any fit."""
    from servotau.identification.data import write_table

    rng = np.random.default_rng(0)
    t = np.arange(2000) * 1e-3  # a single-joint table: t, q, q_des, tau, dq
    table = write_table({"t": t, "q": np.sin(t), "q_des": np.sin(t) + 1e-4 * rng.standard_normal(2000),
                         "tau": 10 * np.cos(t), "dq": np.cos(t)}, tmp_path / "t.parquet")
    argv = [a.format(tmp=tmp_path) for a in argv]
    assert cli(["model", "add", str(table), "--dead-band", "holds", *argv]) == 2
    assert message in capsys.readouterr().err
