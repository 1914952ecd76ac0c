"""Force control (paper 5.4, Fig. 5): standing, right foot on a 5 cm block, sinusoidal vertical force reference,
K6 = 0.1, K_f = 1; overshoot at the apexes, coupling on x and y, delay (cross-correlation)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .common import FORCE_AXES, FORCE_FREQUENCY, FORCE_KF, VARIANTS, Run, pyplot, rerun_target, simulate, write_table

__all__ = ["FORCE_AMPLITUDE", "FORCE_AXES", "FORCE_DURATION", "FORCE_FREQUENCY", "FORCE_K6", "FORCE_KF",
           "force_metrics", "force_profile", "force_run", "run_force"]

FORCE_AMPLITUDE = 40.0  # [N] of the sinusoid on f_z
FORCE_DURATION = 6.0  # [s] of sinusoid (3 periods)
FORCE_K6 = 0.1


def force_profile(t: float, f0: np.ndarray) -> np.ndarray:
    """f_z = f0_z + A sin(2 pi f t), f_x = f_y = 0 [N] (paper 5.4)."""
    return np.array([0.0, 0.0, f0[2] + FORCE_AMPLITUDE * np.sin(2 * np.pi * FORCE_FREQUENCY * t)])


def force_run(quick: bool, out: Path, rerun: bool = False, posture: str = "compatible", **overrides) -> Run:
    """The force task (``overrides``: of :func:`simulate`, e.g. ``motors``, ``force_axes``)."""
    duration = 2.0 / FORCE_FREQUENCY if quick else FORCE_DURATION
    return simulate("force", scenario="force", mode="torque", k6=FORCE_K6, swing=None, force_profile=force_profile,
                    duration=duration, rerun=rerun_target(out, rerun, "force"), posture=posture, **overrides)


def force_metrics(run: Run, key: str = "f_hat") -> dict:
    """Overshoot at the positive apexes [% of A] (the largest, and the apex error of largest magnitude), the error at
    the negative apexes (troughs, largest magnitude; positive: the force stays above the reference's minimum),
    coupling on x and y (max |f - f_d| / A [%]), delay [ms].

    The first period is skipped (the x/y references jump from the measured force to 0 at the start).
    """
    a = run.arrays()
    t, f_ref, f = a["time"], a["f_ref"], a[key]
    dt = float(t[1] - t[0])
    period = 1.0 / FORCE_FREQUENCY
    steady = t >= period
    apexes = np.arange(period / 4, t[-1], period)
    apexes = apexes[apexes >= period]
    over, under = [], []
    for ta in apexes:
        for when, out, peak in ((ta, over, np.max), (ta + period / 2, under, np.min)):
            w = np.abs(t - when) <= period / 4
            if w.sum() > 1 and when <= t[-1]:
                out.append(100.0 * (peak(f[w, 2]) - peak(f_ref[w, 2])) / FORCE_AMPLITUDE)
    coupling = [float(100.0 * np.max(np.abs(f[steady, i] - f_ref[steady, i])) / FORCE_AMPLITUDE) for i in (0, 1)]
    x = f[steady, 2] - f[steady, 2].mean()
    y = f_ref[steady, 2] - f_ref[steady, 2].mean()
    lags = np.arange(-int(0.2 / dt), int(0.2 / dt) + 1)
    n = len(x)
    xc = [np.dot(x[max(0, k):n + min(0, k)], y[max(0, -k):n - max(0, k)]) for k in lags]
    amp = 2 * np.sqrt(2) * np.std(x)  # sine amplitude from the RMS
    worst = max(over, key=abs) if over else float("nan")
    return {"overshoot_pct": float(max(over)) if over else float("nan"), "apex_error_pct": float(worst),
            "apex_overshoots_pct": [float(v) for v in over],
            "trough_error_pct": float(max(under, key=abs)) if under else float("nan"),
            "trough_errors_pct": [float(v) for v in under],
            "coupling_x_pct": coupling[0], "coupling_y_pct": coupling[1],
            "delay_ms": float(1e3 * lags[int(np.argmax(xc))] * dt),
            "amplitude_ratio": float(amp / (2 * FORCE_AMPLITUDE)),
            "rms_error_z_N": float(np.sqrt(np.mean((f[steady, 2] - f_ref[steady, 2]) ** 2)))}


def run_force(out: Path, quick: bool = False, rerun: bool = False, run: Run | None = None,
              posture: str = "compatible", compare: bool | None = None, servo: str | None = None,
              motors: str | None = None) -> dict:
    """Fig. 5 metrics of the force run (reference ``posture``); ``compare`` (default: full runs that are not
    given) also runs the other posture reference and reports its measured metrics next to them. ``servo``,
    ``motors``: the servo and motor files (None: the config's); with either, no comparison runs by default."""
    out = out / "force"
    out.mkdir(parents=True, exist_ok=True)
    given = {k: v for k, v in (("servo", servo), ("motors", motors)) if v is not None}
    compare = (run is None and not quick and not given) if compare is None else compare
    run = run or force_run(quick, out, rerun, posture, **given)
    metrics = _force_run_metrics(run)
    columns = {"measured (compensated f_hat)": metrics["measured"], "true (sole contact)": metrics["true"]}
    other_name, other_tripped = None, None
    if compare:
        other_name = "start" if posture == "compatible" else "compatible"
        others = {f"{other_name} posture": {"posture": other_name},
                  "forces only": {"force_axes": FORCE_AXES[:3]},
                  **{label: overrides for label, overrides in VARIANTS.items() if label != "paper model"}}
        other_tripped = {}
        for label, overrides in others.items():
            other = force_run(quick, out, False, **{"posture": posture, **given, **overrides})
            if other.tripped:
                other_tripped[label] = other.tripped
            metrics[f"measured, {label}"] = _force_run_metrics(other)["measured"]
            columns[f"measured, {label}"] = metrics[f"measured, {label}"]
        other_tripped = other_tripped or None
    rows = [[k] + [m[k] if m else float("nan") for m in columns.values()]
            for k in ("overshoot_pct", "apex_error_pct", "trough_error_pct", "coupling_x_pct", "coupling_y_pct",
                      "delay_ms", "amplitude_ratio",
                      "rms_error_z_N")]
    table = write_table(out / "force_metrics", ["metric", *columns], rows)
    if len(run.time) > 1:
        _plot_force(out / "fig5_force_tracking.png", run)
    summary = {"experiment": "force", "quick": quick, "k6": FORCE_K6, "k_f": FORCE_KF, "amplitude_N": FORCE_AMPLITUDE,
               "frequency_Hz": FORCE_FREQUENCY, "axes": list(FORCE_AXES), "posture": posture,
               "compared_posture": other_name, "servo": servo or "servo.toml", "motors": motors,
               "tripped": run.tripped, "compared_tripped": other_tripped, "metrics": metrics, "table": table}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _force_run_metrics(run: Run) -> dict:
    if run.tripped or len(run.time) < 2:
        return {"measured": None, "true": None}
    return {"measured": force_metrics(run, "f_hat"), "true": force_metrics(run, "f_true")}


def _plot_force(path: Path, run: Run) -> None:
    plt = pyplot()
    a = run.arrays()
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for i, ax in enumerate(axes):
        ax.plot(a["time"], a["f_ref"][:, i], "k--", label="reference", lw=1)
        ax.plot(a["time"], a["f_hat"][:, i], label="measured (compensated)", lw=0.8)
        ax.plot(a["time"], a["f_true"][:, i], label="true sole contact", lw=0.8, alpha=0.7)
        ax.set_ylabel(f"f_{'xyz'[i]} [N]")
    axes[0].legend(fontsize=7, ncol=3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"Right-foot force tracking, K6 = {FORCE_K6:g}, K_f = {FORCE_KF:g}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

