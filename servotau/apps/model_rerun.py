"""Interactive views in Rerun (``--rerun save:FILE|connect:ADDR|spawn``).

Entities: ``model/measured`` and ``model/<model>/{prediction,residual}`` on the ``time`` timeline (their series
named with the unit, the prediction with the model's fit [%], as MATLAB's ``compare``);
``residual/<model>/{velocity,torque,position}`` as 2D scatter plots (x: the signal, y: the residual in the
target's unit, identification/workbench/units.py: urad for a servo log, mN m or N m for a torque table);
``residual/<model>/heatmap`` (mean residual on a velocity x torque grid); ``diagnosis/ranking`` (a bar
chart of held-out gains) and ``diagnosis/report`` (the verdict, the ranking and the ladder as text).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from servotau.identification.workbench.data import Dataset
from servotau.identification.workbench.diagnose import Diagnosis
from servotau.identification.workbench.evaluate import Comparison
from servotau.identification.workbench.ladder import Ladder
from servotau.identification.workbench.units import Unit, unit_of
from servotau.identification.workbench.views import residual_views

MAX_POINTS = 5000
TIMELINE = "time"


def _entity(label: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in label)


def _scatter(rec, path: str, x: np.ndarray, y: np.ndarray, scale_x: float, scale_y: float) -> None:
    import rerun as rr

    step = max(1, len(x) // MAX_POINTS)
    pts = np.column_stack([scale_x * x[::step], scale_y * y[::step]])
    colors = np.where((y[::step] >= 0)[:, None], [[200, 80, 60]], [[60, 100, 200]]).astype(np.uint8)
    rec.log(path, rr.Points2D(pts, colors=colors, radii=0.5), static=True)


def log_to_rerun(
    rec,
    ds: Dataset,
    *,
    comparison: Comparison | None = None,
    diagnosis: Diagnosis | None = None,
    ladder: Ladder | None = None,
    unit: Unit | None = None,
) -> None:
    """Send the models, their residual views and the diagnosis to the recording ``rec``.

    Values are scaled by ``unit`` (default: from the target's role) and the report names its symbol.
    """
    import rerun as rr

    if rec is None:
        return
    models: Sequence[tuple[str, Comparison]]
    if ladder is not None:
        models = [(r.label, r.comparison) for r in ladder.rungs]
        diagnosis = diagnosis or ladder.diagnoses[-1]
    elif diagnosis is not None:
        models = [(diagnosis.base.model.spec.label(), diagnosis.base)]
    else:
        models = [(comparison.model.spec.label(), comparison)]
    u = unit or unit_of(ds)
    t = ds.time
    index = [rr.TimeColumn(TIMELINE, duration=t)]
    rec.log("model/measured", rr.SeriesLines(names=[f"measured {u.name} [{u.symbol}]"]), static=True)
    rec.send_columns("model/measured", index, rr.Scalars.columns(scalars=u.scale * ds.target))
    s = ds.signals
    for label, c in models:
        name = _entity(label)
        pred = c.heldout_prediction if c.heldout_prediction is not None else c.prediction
        fit = c.heldout.fit_percent if c.heldout is not None else c.train.fit_percent
        rec.log(f"model/{name}/prediction", rr.SeriesLines(names=[f"{label}: fit {fit:.1f} % [{u.symbol}]"]),
                static=True)
        rec.log(f"model/{name}/residual", rr.SeriesLines(names=[f"{label} residual [{u.symbol}]"]), static=True)
        rec.send_columns(f"model/{name}/prediction", index, rr.Scalars.columns(scalars=u.scale * pred))
        rec.send_columns(f"model/{name}/residual", index, rr.Scalars.columns(scalars=u.scale * (ds.target - pred)))
        r = ds.target - pred
        _scatter(rec, f"residual/{name}/velocity", s["dq"], r, 1000.0, u.scale)  # x in mrad/s
        if "tau" in s:
            _scatter(rec, f"residual/{name}/torque", s["tau"], r, 1.0, u.scale)
        if "q" in s:
            _scatter(rec, f"residual/{name}/position", s["q"], r, 1000.0, u.scale)  # x in mrad
        v = residual_views(ds, r)
        if v.heatmap is not None:
            rec.log(f"residual/{name}/heatmap", rr.Tensor(np.nan_to_num(u.scale * v.heatmap).T,
                                                          dim_names=["torque bin", "velocity bin"]), static=True)
    lines = [f"Error: {u.quantity} [{u.symbol}]", ""]
    if diagnosis is not None:
        rec.log("diagnosis/ranking", rr.BarChart([100 * (c.heldout_gain if c.testable else 0.0)
                                                  for c in diagnosis.ranking]), static=True)
        lines += [f"# Verdict: {diagnosis.verdict}", "", diagnosis.message, "", "| rank | effect | held-out gain [%] |",
                  "|---|---|---|"]
        lines += [f"| {i + 1} | {c.effect} | {100 * c.heldout_gain:.1f} |" if c.testable
                  else f"| - | {c.effect} | untestable: {c.reason} |" for i, c in enumerate(diagnosis.ranking)]
    if ladder is not None:
        lines += ["", "# Ladder", "", f"| model | training RMS [{u.symbol}] | held-out RMS [{u.symbol}] |",
                  "|---|---|---|"]
        lines += [f"| {r.label} | {u.num(r.comparison.train.rms)} | {u.num(r.comparison.heldout.rms)} |"
                  for r in ladder.rungs]
    if len(lines) > 2:
        rec.log("diagnosis/report", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)
    rec.flush()
