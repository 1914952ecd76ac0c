"""Static report: one HTML page with PNG plots (matplotlib, Agg backend) that a person can open.

``write_report(out_dir, ...)`` writes ``index.html`` and the PNG files next to it:
``timeseries.png`` (measurement and models, each model's fit in the legend, as MATLAB's ``compare``),
``residual_velocity.png``, ``residual_torque.png``, ``residual_position.png``, ``residual_time.png``,
``heatmap.png``, ``correlation.png`` (the residual's autocorrelation and its cross-correlation with the inputs,
with the 95 % band +-1.96/sqrt(N) of a white residual, as MATLAB's ``resid``), ``ranking.png`` and
``ladder.png`` (those that apply); and ``summary.json`` (the numbers, linked from the page) when given.
Coefficients are listed with their units; a title too wide for its plot is wrapped, never cut.
"""

from __future__ import annotations

import html
import json
import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from servotau.actuator import effect_names, get_effect

from .data import Dataset, describe, excitation_of
from .diagnose import Diagnosis
from .evaluate import Comparison, Metrics
from .ladder import Ladder
from .model import K_TAU, K_V, OFFSET, FittedModel
from .units import Unit, unit_of
from .views import ResidualViews, residual_views


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def fit_titles(fig) -> None:
    """Wrap each axes title onto more lines until it is no wider than its axes (a long model label never runs
    past the plot or into its neighbour)."""
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        title, text = ax.title, ax.title.get_text()
        width = ax.get_window_extent(renderer).width
        chars = len(text)
        while text and title.get_window_extent(renderer).width > width and chars > 8:
            chars = int(chars * 0.85)
            title.set_text(textwrap.fill(text, chars, break_long_words=True))


def _save(fig, path: Path) -> str:
    fit_titles(fig)
    fig.tight_layout()  # labels and the wrapped titles inside the figure
    fig.savefig(path, dpi=90)
    _plt().close(fig)
    return path.name


def _fit(c: Comparison) -> tuple[float, str]:
    """The fit [%] shown for a model: held-out when there is one, else training."""
    return (c.heldout.fit_percent, "held-out") if c.heldout is not None else (c.train.fit_percent, "training")


def coefficient_unit(name: str, si: str, effect: bool) -> str:
    """Unit of coefficient ``name`` (k_tau, k_v, offset or an effect) of a model of a target in ``si``; an effect's
    from its regressor's unit (``Effect.phi_unit``, per form when the unit depends on the shape)."""
    if not effect:
        return {K_TAU: f"{si}/(N m)", K_V: f"{si}/(rad/s)", OFFSET: si}.get(name, "?")
    phi = get_effect(name).phi_unit if name in effect_names() else None
    if phi is None:
        return f"{si} per unit of phi (actuator/effects/{name}.py)"
    if isinstance(phi, str):
        return _per(si, phi)
    return ", ".join(f"{_per(si, unit)} with {form}" for form, unit in phi.items())


def _per(si: str, phi: str) -> str:
    """[si / phi]: ``phi`` "1" dimensionless, "target" the target's unit."""
    return si if phi == "1" else ("-" if phi == "target" or phi == si else f"{si}/({phi})")


def _coefficients(label: str, m: FittedModel, u: Unit) -> str:
    rows = [[html.escape(k), f"{m.coefficients[k]:.6g}", html.escape(coefficient_unit(k, u.si, False))]
            for k in m.spec.linear]
    rows += [[html.escape(t.label()), f"{m.coefficients[t.effect]:.6g}",
              html.escape(coefficient_unit(t.effect, u.si, True))] for t in m.spec.terms]
    return f"<p><b>{html.escape(label)}</b></p>" + _table(rows, ["coefficient", "value", "unit"])


def _plot_timeseries(ds: Dataset, models: Sequence[tuple[str, Comparison]], path: Path, u: Unit) -> str:
    plt = _plt()
    fig, (a, b) = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    t = ds.time
    step = max(1, ds.n // 20000)
    a.plot(t[::step], u.scale * ds.target[::step], "k", lw=0.8, label="measured")
    for label, c in models:
        pred = c.heldout_prediction if c.heldout_prediction is not None else c.prediction
        fit, on = _fit(c)
        a.plot(t[::step], u.scale * pred[::step], lw=0.8, label=f"{label}: fit {fit:.1f} % ({on})")
        b.plot(t[::step], u.scale * (ds.target - pred)[::step], lw=0.6, label=label)
    a.set_ylabel(f"{u.name} [{u.symbol}]")
    a.set_title("measured and simulated output (fit = 100 (1 - |y - model| / |y - mean y|))")
    a.legend(fontsize=7, loc="upper right")
    b.set_ylabel(f"residual [{u.symbol}]")
    b.set_xlabel("time [s]" if ds.dt else "sample")
    return _save(fig, path)


def _band(ax, b, label, u: Unit):
    ax.plot(b.centre, u.scale * b.mean, ".-", label=label)
    ax.fill_between(b.centre, u.scale * (b.mean - b.std), u.scale * (b.mean + b.std), alpha=0.15)


def _plot_views(views: Sequence[tuple[str, ResidualViews]], out: Path, u: Unit) -> dict[str, str]:
    plt = _plt()
    files = {}
    fig, ax = plt.subplots(figsize=(8, 4))
    for label, v in views:
        for side, b in v.velocity.items():
            _band(ax, b, f"{label} {side}", u)
    ax.set_xscale("symlog", linthresh=1e-3)
    ax.axhline(0, color="k", lw=0.5)
    ax.set(xlabel="velocity [rad/s] (symlog)", ylabel=f"residual [{u.symbol}]", title="residual against velocity")
    ax.legend(fontsize=7)
    files["velocity"] = _save(fig, out / "residual_velocity.png")
    if views[0][1].torque is not None:
        fig, axes = plt.subplots(1, len(views), figsize=(6 * len(views), 4), squeeze=False)
        for ax, (label, v) in zip(axes[0], views, strict=True):
            for side, b in v.torque.items():
                _band(ax, b, side, u)
            ax.axhline(0, color="k", lw=0.5)
            ax.set(xlabel="torque [N m]", ylabel=f"residual [{u.symbol}]", title=f"{label}: against torque")
            ax.legend(fontsize=7)
        files["torque"] = _save(fig, out / "residual_torque.png")
    if views[0][1].position is not None:
        fig, ax = plt.subplots(figsize=(8, 3.5))
        for label, v in views:
            _band(ax, v.position, label, u)
        ax.set(xlabel="position [rad]", ylabel=f"residual [{u.symbol}]", title="residual against position")
        ax.legend(fontsize=7)
        files["position"] = _save(fig, out / "residual_position.png")
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for label, v in views:
        _band(ax, v.time, label, u)
    ax.set(xlabel="time [s]", ylabel=f"residual [{u.symbol}]", title="residual against time (window means)")
    ax.legend(fontsize=7)
    files["time"] = _save(fig, out / "residual_time.png")
    if views[0][1].heatmap is not None:
        fig, axes = plt.subplots(1, len(views), figsize=(6 * len(views), 4.2), squeeze=False)
        lim = max(np.nanmax(np.abs(v.heatmap)) for _, v in views) * u.scale
        for ax, (label, v) in zip(axes[0], views, strict=True):
            im = ax.pcolormesh(v.heatmap_dq_edges, v.heatmap_tau_edges, u.scale * v.heatmap.T, cmap="RdBu_r",
                               vmin=-lim, vmax=lim)
            ax.set(xlabel="velocity [rad/s]", ylabel="torque [N m]", title=f"{label}: mean residual [{u.symbol}]")
            fig.colorbar(im, ax=ax, label=f"mean residual [{u.symbol}]")
        files["heatmap"] = _save(fig, out / "heatmap.png")
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 3.8))
    conf = views[0][1].confidence
    for ax in (a, b):
        ax.axhspan(-conf, conf, color="0.85", label=f"95 % band +-1.96/sqrt(N), N = {views[0][1].n}")
        ax.axhline(0, color="k", lw=0.5)
    for label, v in views:
        lag = v.lags[v.lags >= 0]
        a.plot(lag, v.autocorrelation, label=label)
        for name, c in v.crosscorrelation.items():
            b.plot(v.lags, c, label=f"{label}: {name}")
    a.set(xlabel="lag [s]", ylabel="autocorrelation [-]", title="residual autocorrelation")
    b.set(xlabel="lag [s] (> 0: input leads)", ylabel="cross-correlation [-]",
          title="cross-correlation of the residual with the inputs")
    a.legend(fontsize=7)
    b.legend(fontsize=6)
    files["correlation"] = _save(fig, out / "correlation.png")
    return files


def _plot_ranking(d: Diagnosis, path: Path) -> str:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(9, 4))
    names = [c.effect for c in d.ranking] + [f"probe:{k}" for k in d.probes]
    gains = [c.heldout_gain if np.isfinite(c.heldout_gain) else 0.0 for c in d.ranking] + list(d.probes.values())
    colors = ["C0" if c.testable else "0.7" for c in d.ranking] + ["C2"] * len(d.probes)
    ax.bar(range(len(names)), [100 * g for g in gains], color=colors)
    ax.axhline(100 * d.min_gain, color="r", lw=0.8, ls="--", label=f"min_gain {100 * d.min_gain:.0f} %")
    ax.set_xticks(range(len(names)), names, rotation=60, ha="right", fontsize=8)
    ax.set(ylabel="held-out gain [%]", title="effects (blue; grey: untestable) and probes (green)")
    ax.legend(fontsize=7)
    return _save(fig, path)


def _plot_ladder(lad: Ladder, path: Path, u: Unit) -> str:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 3.5))
    x = range(len(lad.rungs))
    ax.plot(x, [u.scale * r.comparison.train.rms for r in lad.rungs], "o-", label="training")
    ax.plot(x, [u.scale * r.comparison.heldout.rms for r in lad.rungs], "s-", label="held-out")
    ax.set_xticks(list(x), [r.added or "base" for r in lad.rungs])
    ax.set(ylabel=f"RMS [{u.symbol}]", title="ladder: error after each added effect")
    ax.set_ylim(bottom=0)
    ax.legend()
    return _save(fig, path)


def _metrics_row(label: str, m: Metrics | None, u: Unit) -> str:
    if m is None:
        return f"<tr><td>{html.escape(label)}</td><td colspan=4>-</td></tr>"
    return (f"<tr><td>{html.escape(label)}</td><td>{m.fit_percent:.1f}</td><td>{u.num(m.rms)}</td>"
            f"<td>{u.scale**2 * m.asymmetric_loss:.3g}</td><td>{100 * m.overestimation_rate:.1f}</td></tr>")


def _table(rows: list[list[str]], head: list[str]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def write_report(
    out_dir: str | Path,
    ds: Dataset,
    *,
    comparison: Comparison | None = None,
    diagnosis: Diagnosis | None = None,
    ladder: Ladder | None = None,
    title: str = "servotau model workbench",
    summary: dict | None = None,
    unit: Unit | None = None,
    test: tuple[str, Metrics] | None = None,
) -> Path:
    """Write ``index.html`` and its plots into ``out_dir``; return the HTML path.

    ``unit``: how errors are scaled and labelled (default: from the target's role, :func:`.units.unit_of`).
    ``test``: a row of the metrics table for recordings the model was scored on but not fitted on (label, metrics).
    """
    u = unit or unit_of(ds)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    models: list[tuple[str, Comparison]] = []
    if ladder is not None:
        models = [(ladder.rungs[0].label, ladder.rungs[0].comparison)]
        if len(ladder.rungs) > 1:
            models.append((ladder.rungs[-1].label, ladder.rungs[-1].comparison))
        diagnosis = diagnosis or ladder.diagnoses[-1]
    elif diagnosis is not None:
        models = [(diagnosis.base.model.spec.label(), diagnosis.base)]
    elif comparison is not None:
        models = [(comparison.model.spec.label(), comparison)]
    parts = [f"<h1>{html.escape(title)}</h1>", "<p>" + "<br>".join(html.escape(x) for x in describe(ds)) + "</p>"]
    if diagnosis is not None:
        parts.append(f"<h2>Verdict: {html.escape(diagnosis.verdict)}</h2><p>{html.escape(diagnosis.message)}</p>")
    parts.append("<h2>Model against measurement</h2>")
    rows = []
    for label, c in models:
        rows.append(_metrics_row(f"{label} (training)", c.train, u))
        rows.append(_metrics_row(f"{label} (held-out)", c.heldout, u))
    if test is not None:
        rows.append(_metrics_row(*test, u))
    parts.append(f"<p>Error: {html.escape(u.quantity)} [{html.escape(u.symbol)}]</p>"
                 f"<table><tr><th>model</th><th>fit [%]</th><th>RMS [{u.symbol}]</th>"
                 f"<th>asymmetric loss [({u.symbol})^2]</th>"
                 "<th>over-estimation [%]</th></tr>" + "".join(rows) + "</table>")
    parts.append("<h2>Coefficients</h2>")
    parts += [_coefficients(label, c.model, u) for label, c in models]
    files = {"timeseries": _plot_timeseries(ds, models, out / "timeseries.png", u)}
    if ladder is not None and len(ladder.rungs) > 1:
        files["ladder"] = _plot_ladder(ladder, out / "ladder.png", u)
        rows = [[html.escape(r.label), html.escape(r.added or "-"), u.num(r.comparison.train.rms),
                 u.num(r.comparison.heldout.rms), f"{r.comparison.heldout.fit_percent:.1f}"]
                for r in ladder.rungs]
        head = ["model", "added", f"training RMS [{u.symbol}]", f"held-out RMS [{u.symbol}]", "held-out fit [%]"]
        parts += ["<h2>Ladder</h2>", _table(rows, head), f'<img src="{files["ladder"]}">']
    parts.append(f'<h2>Time series</h2><img src="{files["timeseries"]}">')
    views = [(label, residual_views(ds, c.residual)) for label, c in models]
    vfiles = _plot_views(views, out, u)
    parts.append("<h2>Where the model fails (held-out residuals)</h2>")
    parts += [f'<img src="{f}">' for f in vfiles.values()]
    if diagnosis is not None:
        files["ranking"] = _plot_ranking(diagnosis, out / "ranking.png")
        rows = []
        for c in diagnosis.ranking:
            shape = ", ".join(f"{k}={v:.3g}" for k, v in c.shape.items())
            note = "partially explained" if c.partial else ("grid edge" if c.at_grid_edge else "")
            rows.append([c.effect, f"{100 * c.heldout_gain:.1f}" if c.testable else "-",
                         f"{100 * c.train_gain:.1f}" if c.testable else "-", html.escape(shape),
                         "yes" if c.consistent else "no", "yes" if c.testable else html.escape(c.reason or ""),
                         "-" if c.explained is None else f"{100 * c.explained:.0f}", note])
        parts += [f"<h2>Ranking of the missing effects (against {html.escape(diagnosis.base.model.spec.label())})</h2>",
                  _table(rows, ["effect", "held-out gain [%]", "training gain [%]", "shape", "all blocks",
                                "testable", "of probe [%]", "note"]),
                  f'<img src="{files["ranking"]}">',
                  "<p>Probes (free functions of one family of signals), held-out gain: "
                  + ", ".join(f"{k} {100 * v:.1f} %" for k, v in diagnosis.probes.items()) + "</p>"]
        if diagnosis.confusion is not None:
            cf = diagnosis.confusion
            parts.append(f"<p><b>Confusable</b>: {cf.effects[0]} and {cf.effects[1]} (column correlation "
                         f"{cf.correlation:.2f}). Experiment: {html.escape(cf.experiment)}</p>")
        for other, text in diagnosis.experiments.items():
            parts.append(f"<p>To tell it from <b>{html.escape(other)}</b>: {html.escape(text)}</p>")
        exc = diagnosis.excitation
    else:
        exc = excitation_of(ds)
    parts.append("<h2>Excitation</h2><ul>" + "".join(f"<li>{html.escape(x)}</li>" for x in exc.lines()) + "</ul>")
    if summary is not None:
        (out / "summary.json").write_text(json.dumps(summary, indent=1), encoding="utf-8")
        parts.append('<h2>Numbers</h2><p>Every figure of this report as JSON: <a href="summary.json">summary.json</a>'
                     "</p>")
    style = ("<style>body{font-family:sans-serif;max-width:1200px;margin:auto;padding:0 8px}"
             "table{border-collapse:collapse;margin:4px 0}td,th{border:1px solid #bbb;padding:2px 6px;font-size:13px}"
             "img{max-width:100%;height:auto;display:block;margin:6px 0}h1,h2{overflow-wrap:anywhere}</style>")
    page = f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>{style}</head>"
    page += "<body>" + "\n".join(parts) + "</body></html>\n"
    path = out / "index.html"
    path.write_text(page, encoding="utf-8")
    return path
