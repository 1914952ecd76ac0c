"""Torque estimation: estimated vs true joint torques on the motion run (K6 = 1), and the identified motor models
against the simulator's servo parameters (config/servo.toml, evaluation only)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .common import LEG, LEG_LABELS, PAPER_MODEL, Run, motors_file, pyplot, rerun_target, simulate, write_table


def run_estimation(out: Path, quick: bool = False, rerun: bool = False, run: Run | None = None) -> dict:
    out = out / "estimation"
    out.mkdir(parents=True, exist_ok=True)
    run = run or simulate("motion-K6=1", k6=1.0, rerun=rerun_target(out, rerun, "estimation"))
    a = run.arrays()
    err = a["tau_hat"] - a["tau_true"]
    rms = np.sqrt(np.mean(err**2, axis=0))
    peak = np.max(np.abs(a["tau_true"]), axis=0)
    rows = [[label, float(rms[j]), float(peak[j]), float(100 * rms[j] / peak[j]), float(np.max(np.abs(err[:, j])))]
            for j, label in enumerate(LEG_LABELS)]
    table = write_table(out / "estimation_torque_error", ["joint", "RMS error [N m]", "peak abs(tau) [N m]",
                                                            "RMS / peak [%]", "max error [N m]"], rows)
    plt = pyplot()
    fig, axes = plt.subplots(3, 2, figsize=(10, 7), sharex=True)
    for j, ax in enumerate(axes.T.ravel()):
        ax.plot(a["time"], a["tau_true"][:, j], "k", lw=1, label="true")
        ax.plot(a["time"], a["tau_hat"][:, j], lw=0.8, label="estimated")
        ax.set_ylabel(f"{LEG_LABELS[j]} [N m]", fontsize=8)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Joint torques on the motion run (K6 = 1): estimated vs true")
    fig.tight_layout()
    fig.savefig(out / "estimation_torques.png", dpi=110)
    plt.close(fig)
    summary = {"experiment": "estimation", "quick": quick, "rms_Nm": rms.tolist(), "peak_Nm": peak.tolist(),
               "tripped": run.tripped, "table": table, "identification": _identification_table(out)}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _identification_table(out: Path) -> str:
    """The motor files' parameters against the simulator's servo (ground truth, read here for evaluation only): the
    linear part ``k_tau = 1/kp``, ``k_v = (kd + b)/kp``, Coulomb ``tau_c/kp`` and the driver dead zone
    ``i_deadzone k_t/kp`` (both in [rad] of command error)."""
    from servotau.actuator import MotorParameters
    from servotau.config import CONFIG_DIR
    from servotau.description import JOINT_NAMES
    from servotau.simrobot.servo_config import load_servo_params

    servo = load_servo_params(CONFIG_DIR / "servo.toml", JOINT_NAMES, np.zeros(len(JOINT_NAMES)))
    files = {"default": motors_file(), "paper": PAPER_MODEL}
    models = {k: MotorParameters.load_toml(CONFIG_DIR / f).models for k, f in files.items()}

    def term(m, name):
        t = m.extra.get(name)
        return float("nan") if t is None else 1e3 * t.coefficient

    k_tau, k_v = servo.k_tau_nominal(), servo.k_v_nominal()
    rows = []
    for joint, label in zip(LEG, LEG_LABELS, strict=True):
        i = JOINT_NAMES.index(joint)
        d, pm = models["default"][joint], models["paper"][joint]
        coulomb = 1e3 * d.k_c if d.k_c else term(d, "coulomb")
        rows.append([label, d.k_tau, pm.k_tau, k_tau[i], d.k_v, pm.k_v, k_v[i], coulomb,
                     1e3 * servo.tau_c[i] * k_tau[i], term(d, "deadzone"),
                     1e3 * servo.i_deadzone[i] * servo.k_t[i] * k_tau[i]])
    header = ["joint", "k_tau default", "k_tau paper model", "1/kp", "k_v default", "k_v paper model", "(kd + b)/kp",
              "Coulomb default [mrad]", "tau_c/kp [mrad]", "dead band default [mrad]", "i_dz k_t/kp [mrad]"]
    return write_table(out / "identification_vs_servo", header, rows)

