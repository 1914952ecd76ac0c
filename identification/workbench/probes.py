"""Non-parametric probes of the diagnosis (:mod:`.diagnose`): flexible functions of one family of signals,
fitted to the current model's residual on the training blocks and scored on the held-out block.

The families: bins of velocity; of torque by velocity sign; of ``u`` by velocity sign; of position; a
polynomial drift in time; lagged differences of ``u`` and ``q_des`` (``dynamics``); and the residual's own past
(``memory``). A probe's held-out gain is what a free function of its signals removes: the yardstick of the
effects of its family. The memory probe finds a state no term models; :data:`MEMORY_CANDIDATES` are the states it
names (pre-sliding friction hysteresis, a dead band crossed freely), with what their effects did.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servotau.actuator import Loss
from servotau.actuator.signals import advanced, delayed, ticks

from ..data.folds import Fold
from .data import Dataset
from .evaluate import error_of
from .model import FittedModel, ModelSpec, design, fit_spec, solve

MEMORY_HORIZON_S = 0.021  # [s] the memory probe's step h
MEMORY_LAGS = (1, 2, 4)
"""The memory probe predicts the held-out residual from its own values ``k h`` earlier (``k`` in ``MEMORY_LAGS``,
``h`` = ``MEMORY_HORIZON_S`` [s], the torque's smoothing window): noise that the workbench's filters spread over
neighbouring samples is forgotten after ``h`` (the velocity's longer SG window carries ``k_v`` times a
differentiated encoder noise, orders smaller), so a residual still predictable ``h`` ahead has a state no term
models. Three coefficients fitted on the training blocks, the residual's past read as on-line (causal)."""

MEMORY_CANDIDATES = (
    ("pre-sliding friction hysteresis", ("dahl", "lugre")),
    ("a dead band crossed freely in a log without the command (the error depends on where the joint entered)",
     ("deadzone",)),
)
"""States the memory probe points at when no term names them: what each is, and the effects that model it."""


@dataclass(eq=False)
class FoldBase:
    """The current model fitted on one fold's training blocks: its design, and its prediction of every row."""

    fold: Fold
    ctx: dict
    names: list[str]
    a: np.ndarray
    pred: np.ndarray  # base prediction on all rows, fitted on the fold's training rows


def base_per_fold(ds: Dataset, spec: ModelSpec, loss: Loss, folds: list[Fold], cache: dict) -> list[FoldBase]:
    out = []
    for f in folds:
        m = fit_spec(ds.signals, ds.target, spec, loss, rows=f.train, cache=cache, drop_unexcited=True)
        ctx = m.context(ds.signals)
        names, a, _ = design(ds.signals, spec, ctx, cache)
        x = solve(names, a, ds.target, loss, f.train, drop_unexcited=True)
        out.append(FoldBase(f, ctx, names, a, a @ x))
    return out


def heldout_prediction(bases: list[FoldBase], n: int) -> np.ndarray:
    """Each sample predicted by the fold that holds it out (NaN where no fold does)."""
    pred = np.full(n, np.nan)
    for b in bases:
        pred[b.fold.test] = b.pred[b.fold.test]
    return pred


@dataclass(frozen=True, eq=False)
class Bins:
    """A one-hot family kept as its bin indices: ``index`` of each sample in ``0 .. k - 1``, every bin used by some
    sample (the columns ``index == j`` of a dense design, without a 100k x k matrix)."""

    index: np.ndarray
    k: int

    def columns(self) -> np.ndarray:
        """The dense one-hot design (n x k), for tests."""
        m = np.zeros((len(self.index), self.k))
        m[np.arange(len(self.index)), self.index] = 1.0
        return m


def _bins(index: np.ndarray, k: int) -> Bins:
    """The ``k`` possible bins of ``index`` renumbered to the used ones, in order."""
    used = np.bincount(index, minlength=k) > 0
    return Bins((np.cumsum(used) - 1)[index], int(np.count_nonzero(used)))


def _quantile_bins(x: np.ndarray, k: int) -> np.ndarray:
    edges = np.unique(np.quantile(x, np.linspace(0, 1, k + 1)[1:-1]))
    return np.searchsorted(edges, x)


def _velocity_class(dq: np.ndarray, v: float = 0.01) -> np.ndarray:
    return np.where(dq > v, 2, np.where(dq < -v, 0, 1))


def _by_class(x: np.ndarray, cls: np.ndarray, k: int) -> Bins:
    b = _quantile_bins(x, k)
    return _bins(cls * (b.max() + 1) + b, 3 * (b.max() + 1))


def probe_columns(signals, u: np.ndarray, only: str | None = None) -> dict[str, Bins | np.ndarray]:
    """Flexible regressors of each signal family (of ``only`` if given): :class:`Bins` for the one-hot families
    (velocity, torque and ``u`` by velocity sign, position), dense columns without any sample dropped for the
    others (time, dynamics)."""
    want = lambda family: only is None or only == family  # noqa: E731
    dq = signals["dq"]
    out: dict[str, Bins | np.ndarray] = {}
    if want("velocity"):
        out["velocity"] = _bins(_quantile_bins(dq, 24), 24)
    if want("torque") or want("servo_error"):
        cls = _velocity_class(dq)
        if "tau" in signals and want("torque"):
            out["torque"] = _by_class(signals["tau"], cls, 12)
        if want("servo_error"):
            out["servo_error"] = _by_class(u, cls, 12)
    if "q" in signals and want("position"):
        q = signals["q"]
        span = float(np.ptp(q))
        if span > 0:
            out["position"] = _bins(np.minimum(((q - q.min()) / span * 64).astype(int), 63), 64)
    if "t" in signals and want("time"):
        t = signals["t"]
        x = (t - t.mean()) / (np.ptp(t) or 1.0)
        s = np.tanh(dq / 0.01)
        out["time"] = np.column_stack([x, x * x, x * dq, x * x * dq, x * s, x * x * s])
    if signals.dt is not None and want("dynamics"):
        cols, starts = [], signals.starts  # lags and leads read no sample of another recording or run
        for lag in (0.002, 0.005, 0.01, 0.02, 0.04):
            k = ticks(lag, signals.dt)
            cols += [delayed(u, k, starts) - u, advanced(u, k, starts) - u]
            if "q_des" in signals:
                cols.append(signals["q_des"] - delayed(signals["q_des"], k, starts))
        if "ddq" in signals:
            cols.append(signals["ddq"])
        out["dynamics"] = np.column_stack(cols)
    return {k: m if isinstance(m, Bins) else _nonzero_columns(m) for k, m in out.items()}


def _nonzero_columns(m: np.ndarray) -> np.ndarray:
    keep = m.any(axis=0)
    return m if keep.all() else m[:, keep]


def _ridge(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Coefficients of ``a x ~ b``: the columns scaled to unit RMS, a ridge of 1e-6 times the mean diagonal."""
    scale = np.sqrt(np.mean(a * a, axis=0))
    scale[scale == 0] = 1.0
    an = a / scale
    g = an.T @ an
    if not np.trace(g) > 0:  # every column is zero (e.g. the residual of a log whose error never moves)
        return np.zeros(a.shape[1])
    g[np.diag_indices_from(g)] += 1e-6 * np.trace(g) / len(g)
    return np.linalg.solve(g, an.T @ b) / scale


def _bin_ridge(index: np.ndarray, k: int, b: np.ndarray) -> np.ndarray:
    """:func:`_ridge` of the one-hot design of ``index`` (``k`` bins) in closed form, linear in the samples: the
    scaled Gram matrix is diagonal, ``n`` for a bin with samples (scale ``sqrt(count / n)``), 0 for an empty one
    (scale 1), so each coefficient is its bin's sum of ``b`` over ``count + ridge count / n``."""
    n = len(index)
    count = np.bincount(index, minlength=k)
    total = np.bincount(index, weights=b, minlength=k)
    used = count > 0
    scale = np.where(used, np.sqrt(count / n), 1.0)
    g = np.where(used, float(n), 0.0)
    return total / scale / (g + 1e-6 * g.sum() / k) / scale


def probe_gains(
    ds: Dataset, bases: list[FoldBase], base: FittedModel, loss: Loss, e0: float, only: str | None = None
) -> dict[str, float]:
    y = ds.target
    cols = probe_columns(ds.signals, base.u(ds.signals), only)
    out = {}
    for family, p in cols.items():
        if (p.k if isinstance(p, Bins) else p.shape[1]) == 0:
            continue
        pred = np.full(ds.n, np.nan)
        for b in bases:
            tr, te = b.fold.train, b.fold.test
            if isinstance(p, Bins):
                beta = _bin_ridge(p.index[tr], p.k, y[tr] - b.pred[tr])
                pred[te] = b.pred[te] + beta[p.index[te]]
            else:
                beta = _ridge(p[tr], y[tr] - b.pred[tr])
                pred[te] = b.pred[te] + p[te] @ beta
        out[family] = 1.0 - error_of(y - pred, y, loss) / e0 if e0 > 0 else 0.0
    if ds.signals.dt is not None and only in (None, "memory"):
        out["memory"] = _memory_gain(ds, bases, loss, e0)
    return out


def _memory_gain(ds: Dataset, bases: list[FoldBase], loss: Loss, e0: float) -> float:
    """Held-out gain of predicting the residual from its own past (:data:`MEMORY_LAGS` x :data:`MEMORY_HORIZON_S`):
    per block, the residual of the model fitted on the other blocks, its past read causally."""
    y = ds.target
    h = ticks(MEMORY_HORIZON_S, ds.signals.dt)
    pred = np.full(ds.n, np.nan)
    for b in bases:
        tr, te = b.fold.train, b.fold.test
        r = y - b.pred
        p = np.column_stack([delayed(r, k * h, ds.signals.starts) for k in MEMORY_LAGS])
        pred[te] = b.pred[te] + p[te] @ _ridge(p[tr], r[tr])
    return 1.0 - error_of(y - pred, y, loss) / e0 if e0 > 0 else 0.0




def memory_candidates(ranking, min_gain: float) -> list[str]:
    """:data:`MEMORY_CANDIDATES` as text, each with what its effects did in ``ranking`` (candidates with
    ``effect``, ``testable``, ``heldout_gain``, ``reason``): tried and how much they removed, untestable and why,
    or not in the library tested."""
    by_name = {c.effect: c for c in ranking}
    out = []
    for what, names in MEMORY_CANDIDATES:
        tried = [by_name[n] for n in names if n in by_name]
        if not tried:
            out.append(f"{what} ({'/'.join(names)}: not in the library tested)")
            continue
        parts = []
        for c in tried:
            if c.testable:
                parts.append(f"{c.effect} tried, removes {100 * c.heldout_gain:.0f} %")
            else:
                parts.append(f"{c.effect} untestable: {c.reason}")
        out.append(f"{what} ({'; '.join(parts)}; {100 * min_gain:.0f} % names an effect)")
    return out
