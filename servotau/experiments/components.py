"""Control components (paper 5.5, Fig. 6): the RMS share of each command component in motion (K6 = 1, 0.1) and
force control."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .common import LEG, LEG_LABELS, OTHER_COMPONENTS, PAPER_COMPONENTS, Run, pyplot, simulate, write_table
from .force import force_run


def component_shares(run: Run) -> dict[str, np.ndarray]:
    """Per joint: RMS of each paper component / sum of their RMS (the other terms are reported apart)."""
    a = run.arrays()
    rms = {c: np.sqrt(np.mean(a[c] ** 2, axis=0)) for c in PAPER_COMPONENTS + OTHER_COMPONENTS}
    total = sum(rms[c] for c in PAPER_COMPONENTS)
    total = np.where(total > 0, total, np.nan)
    return {c: rms[c] / total for c in PAPER_COMPONENTS + OTHER_COMPONENTS}


def run_components(out: Path, quick: bool = False, rerun: bool = False, runs: dict | None = None) -> dict:
    out = out / "components"
    out.mkdir(parents=True, exist_ok=True)
    if runs is None:
        runs = {"motion K6=1": simulate("motion-K6=1", k6=1.0), "motion K6=0.1": simulate("motion-K6=0.1", k6=0.1),
                "force": force_run(quick, out, rerun)}
    shares = {name: component_shares(r) for name, r in runs.items()}
    header = ["experiment", "joint"] + list(PAPER_COMPONENTS) + ["dominant", "ff_extra", "(residual+integrals+switch)"]
    rows, dominant = [], {}
    for name, sh in shares.items():
        for j, label in enumerate(LEG_LABELS):
            vals = [float(100 * sh[c][j]) for c in PAPER_COMPONENTS]
            top = PAPER_COMPONENTS[int(np.nanargmax(vals))] if not np.all(np.isnan(vals)) else "-"
            dominant.setdefault(name, {})[label] = top
            rest = float(100 * sum(sh[c][j] for c in OTHER_COMPONENTS if c != "ff_extra"))
            rows.append([name, label] + vals + [top, float(100 * sh["ff_extra"][j]), rest])
    table = write_table(out / "component_shares_pct", header, rows)
    _plot_components(out / "fig6_components.png", shares)
    findings = {
        "motion: ff_friction dominates": {n: sum(v == "ff_friction" for v in dominant[n].values())
                                          for n in dominant if n.startswith("motion")},
        "force: ff_torque dominates": {n: sum(v == "ff_torque" for v in dominant[n].values())
                                       for n in dominant if n == "force"},
    }
    shares_pct = {n: {c: (100 * v).tolist() for c, v in sh.items()} for n, sh in shares.items()}
    summary = {"experiment": "components", "quick": quick, "shares_pct": shares_pct,
               "dominant": dominant, "findings_joint_counts": findings,
               "tripped": {n: r.tripped for n, r in runs.items()}, "table": table}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _plot_components(path: Path, shares: dict) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, len(shares), figsize=(4.5 * len(shares), 4.5), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, (name, sh) in zip(axes, shares.items(), strict=True):
        bottom = np.zeros(len(LEG))
        for c in PAPER_COMPONENTS:
            v = np.nan_to_num(100 * sh[c])
            ax.bar(range(len(LEG)), v, bottom=bottom, label=c)
            bottom += v
        ax.set_xticks(range(len(LEG)), LEG_LABELS, rotation=45, ha="right", fontsize=8)
        ax.set_title(name)
    axes[0].set_ylabel("share of RMS [%]")
    axes[-1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

