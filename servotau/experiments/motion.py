"""Motion control (paper 5.3, Tables 2-3, Fig. 4): the hanging robot swings its right leg under the native position
servo and under torque control at K6 = 1, 0.5, 0.25, 0.1 (and the variants beside the sweep); RMS and max tracking
error per right-leg joint [mrad], on the TRUE joint angles (simulator ground truth)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .common import (
    LEG_LABELS,
    SWING,
    VARIANTS,
    Run,
    motors_file,
    pyplot,
    rerun_target,
    run_label,
    simulate,
    write_table,
)

K6_VALUES = (1.0, 0.5, 0.25, 0.1)
# (K6, k7 [s]) runs beside the sweep with a constant velocity gain (k7_scaling = "constant"): the config's k7 at
# K6 = 1, i.e. the sweep before the velocity gain followed K6
MOTION_EXTRA = ((0.25, 0.001),)
VARIANT_K6 = (1.0, 0.25)  # the K6 of the VARIANTS runs
NO_POSITION_INTEGRAL_K6 = (1.0, 0.1)  # runs with k_iq = 0 (the paper's law): what the position integral adds


# Paper, Tables 2 and 3 (rad * 1e3 = mrad); the paper has no hip-yaw row.
PAPER_MEAN = {
    "position": {"hip roll": 0.020, "hip pitch": 0.056, "knee": 0.115, "ankle pitch": 0.064, "ankle roll": 0.029},
    "K6=1": {"hip roll": 0.005, "hip pitch": 0.018, "knee": 0.060, "ankle pitch": 0.017, "ankle roll": 0.015},
    "K6=0.5": {"hip roll": 0.008, "hip pitch": 0.035, "knee": 0.061, "ankle pitch": 0.034, "ankle roll": 0.029},
    "K6=0.25": {"hip roll": 0.016, "hip pitch": 0.064, "knee": 0.067, "ankle pitch": 0.063, "ankle roll": 0.059},
    "K6=0.1": {"hip roll": 0.040, "hip pitch": 0.139, "knee": 0.094, "ankle pitch": 0.148, "ankle roll": 0.136},
}
PAPER_MAX = {
    "position": {"hip roll": 4.79, "hip pitch": 17.01, "knee": 61.86, "ankle pitch": 19.56, "ankle roll": 6.11},
    "K6=1": {"hip roll": 2.35, "hip pitch": 7.87, "knee": 39.64, "ankle pitch": 4.84, "ankle roll": 2.55},
    "K6=0.5": {"hip roll": 2.95, "hip pitch": 7.83, "knee": 41.55, "ankle pitch": 5.92, "ankle roll": 3.69},
    "K6=0.25": {"hip roll": 2.85, "hip pitch": 10.40, "knee": 41.19, "ankle pitch": 10.39, "ankle roll": 6.80},
    "K6=0.1": {"hip roll": 5.76, "hip pitch": 22.78, "knee": 49.33, "ankle pitch": 22.43, "ankle roll": 16.44},
}


def motion_errors(run: Run) -> tuple[np.ndarray, np.ndarray]:
    """RMS (Table 2 formula) and max |q_d - q| per right-leg joint [mrad], on the true joint angles."""
    if not run.time:  # refused before moving, or tripped before the task: no record
        return np.full(len(LEG_LABELS), np.nan), np.full(len(LEG_LABELS), np.nan)
    a = run.arrays()
    e = a["q_ref"] - a["q_true"]
    return 1e3 * np.sqrt(np.mean(e**2, axis=0)), 1e3 * np.max(np.abs(e), axis=0)


def motion_runs(quick: bool, out: Path, rerun: bool = False, servo: str | None = None, motors: str | None = None,
                gains: tuple[float, ...] | None = None) -> dict[str, Run]:
    """The position-servo run and the torque runs of the K6 sweep (quick: K6 = 1 and 0.1 only; ``gains``: these
    K6). With a ``servo`` or ``motors`` file (relative to config/ or a path) only the sweep runs, on that servo
    with that motor file (the variants compare motor files of the nominal servo)."""
    gains = gains or ((1.0, 0.1) if quick else K6_VALUES)
    given = {"servo": servo, "motors": motors}
    runs = {"position": simulate("motion-position", mode="position", k6=None,
                                 rerun=rerun_target(out, rerun, "motion-position"), **given)}
    for k6 in gains:
        name = run_label(k6)
        runs[name] = simulate(f"motion-{name}", mode="torque", k6=k6, rerun=rerun_target(out, rerun, f"motion-{name}"),
                              **given)
    if servo is not None or motors is not None:
        return runs
    for k6, k7 in (() if quick else MOTION_EXTRA):
        name = f"{run_label(k6)} k7={k7:g}"
        runs[name] = simulate(f"motion-{name}", mode="torque", k6=k6, k7=k7)
    for k6 in (() if quick else NO_POSITION_INTEGRAL_K6):
        name = f"{run_label(k6)} k_iq=0"
        runs[name] = simulate(f"motion-{name}", mode="torque", k6=k6, k_iq=0.0)
    for label, overrides in ({} if quick else VARIANTS).items():
        for k6 in VARIANT_K6:
            name = f"{run_label(k6)} {label}"
            runs[name] = simulate(f"motion-{name}", mode="torque", k6=k6, **overrides)
    return runs


def run_motion(out: Path, quick: bool = False, rerun: bool = False, runs: dict | None = None,
               servo: str | None = None, motors: str | None = None) -> dict:
    """Tables 2-3 and Fig. 4 of the paper (on ``servo`` with ``motors`` if given, see :func:`motion_runs`); returns
    (and writes) the summary."""
    out = out / "motion"
    out.mkdir(parents=True, exist_ok=True)
    runs = runs or motion_runs(quick, out, rerun, servo, motors)
    errors = {name: motion_errors(r) for name, r in runs.items()}
    pos_mean, pos_max = errors["position"]
    mean_rows, max_rows = [], []
    for j, label in enumerate(LEG_LABELS):
        mean_rows.append([label] + [float(errors[n][0][j]) for n in runs])
        max_rows.append([label] + [float(errors[n][1][j]) for n in runs])
    header = ["joint"] + [f"{n} (TRIP)" if r.tripped else n for n, r in runs.items()]
    tables = {"mean": write_table(out / "motion_mean_mrad", header, mean_rows),
              "max": write_table(out / "motion_max_mrad", header, max_rows)}
    passes = {}
    for name in runs:
        if name == "position":
            continue
        m, x = errors[name]
        passes[name] = {label: {"mean": bool(m[j] < pos_mean[j]), "max": bool(x[j] < pos_max[j])}
                        for j, label in enumerate(LEG_LABELS)}
    _plot_motion(out / "fig4_motion_errors.png", runs)
    summary = {"experiment": "motion", "quick": quick, "swing": SWING, "controllers": list(runs),
               "motors": motors or motors_file(), "servo": servo or "servo.toml",
               "mean_mrad": {n: errors[n][0].tolist() for n in runs},
               "max_mrad": {n: errors[n][1].tolist() for n in runs},
               "tripped": {n: r.tripped for n, r in runs.items()}, "beats_position": passes, "tables": tables}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _plot_motion(path: Path, runs: dict[str, Run]) -> None:
    """Fig. 4: tracking error of hip roll and ankle pitch for every controller."""
    plt = pyplot()
    joints = (1, 4)  # hip roll, ankle pitch (the paper's Fig. 4)
    fig, axes = plt.subplots(len(joints) + 1, 1, figsize=(9, 8), sharex=True)
    ref = runs["position"].arrays()
    for j in range(1, 5):
        axes[0].plot(ref["time"], ref["q_ref"][:, j], label=LEG_LABELS[j])
    axes[0].set_ylabel("q_d [rad]")
    axes[0].legend(fontsize=7, ncol=4)
    for ax, j in zip(axes[1:], joints, strict=True):
        for name, run in runs.items():
            if not run.time:
                continue
            a = run.arrays()
            ax.plot(a["time"], 1e3 * (a["q_ref"][:, j] - a["q_true"][:, j]), label=name, lw=0.8)
        ax.set_ylabel(f"{LEG_LABELS[j]} error [mrad]")
        ax.legend(fontsize=7, ncol=5)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle("Right-leg swing, hanging robot: q_d - q (true)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

