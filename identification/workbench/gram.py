"""Least squares from cross products (Gram matrices): the diagnosis's many small fits without copying rows.

The diagnosis fits the same base columns with each shape of each effect on each fold's training rows. Instead
of stacking and selecting the rows of every trial matrix, the products of the base columns (and the target)
with themselves are computed once per fold, and each trial adds only its own columns' products; the normal
equations are then solved with the same column scaling and refusals as :func:`~.model.solve`. A fold's rows
are selected by zero weights, not by subtraction, so a column that is zero or constant on them is exactly so
here too. Results equal those of fitting the selected rows directly up to round-off; the training loss from
the Gram matrix loses digits when the fit is close (``|y|^2 >> loss``), so :func:`near_ties` says which
candidates to score again from their residuals.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from servotau.actuator import Signals, get_effect
from servotau.actuator.terms import OFFSET
from servotau.errors import IdentificationError

from ..validation import MAX_CONDITION, MIN_SAMPLES_PER_PARAMETER, check_min_samples

TIE = 1e-9  # relative difference of two training losses below which the exact residuals decide
GRAM_DIGITS = 1e-12  # round-off of a loss from the Gram matrix, relative to |y|^2

__all__ = ["Normal", "UNormal", "check_condition", "check_excited", "loss_of", "near_ties", "solve_gram"]


class Normal:
    """Normal equations of ``[base | cols]`` against ``y`` over the rows of ``mask`` (None: all rows), for
    any number of candidate column blocks ``cols``; the products of ``base`` and ``y`` computed once."""

    def __init__(self, base: np.ndarray, y: np.ndarray, mask: np.ndarray | None = None):
        self.mask = mask
        self.w = None if mask is None else mask.astype(np.float64)
        self.n = len(y) if mask is None else int(np.count_nonzero(mask))
        self.base = base
        w = np.ones(len(y)) if self.w is None else self.w
        # [base | y | 1] with the rows outside the mask weighted 0: one product gives a candidate's cross terms
        self.rhs = np.column_stack([base, y, np.ones(len(y))]) * w[:, None]
        k = base.shape[1]
        g = base.T @ self.rhs
        self.gbb, self.by, self.bsum = g[:, :k], g[:, k], g[:, k + 1]
        self.yty = float(y @ self.rhs[:, k])

    def system(self, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The Gram matrix, ``A.T y`` and the column sums of ``A = [base | cols]`` over the rows."""
        k = self.gbb.shape[0]
        c = cols.T @ self.rhs  # cols against base, y and 1
        cc = cols.T @ (cols if self.w is None else cols * self.w[:, None])
        g = np.block([[self.gbb, c[:, :k].T], [c[:, :k], cc]])
        return g, np.concatenate([self.by, c[:, k]]), np.concatenate([self.bsum, c[:, k + 1]])


def loss_of(x: np.ndarray, g: np.ndarray, aty: np.ndarray, yty: float) -> float:
    """Sum of squared residuals ``|y - A x|^2`` from the normal equations."""
    return float(yty - 2.0 * x @ aty + x @ g @ x)


def near_ties(losses: list[float], yty: float) -> list[int]:
    """Indices of the losses too close to the least one to be ordered by their Gram values (round-off): empty
    when the least is clear."""
    finite = [v for v in losses if np.isfinite(v)]
    if not finite:
        return []
    best = min(finite)
    tol = TIE * abs(best) + GRAM_DIGITS * abs(yty)
    close = [i for i, v in enumerate(losses) if np.isfinite(v) and v <= best + tol]
    return close if len(close) > 1 else []


def solve_gram(names: list[str], gram: np.ndarray, atb: np.ndarray, colsum: np.ndarray, n: int) -> np.ndarray:
    """:func:`~.model.solve` by least squares from the normal equations of the ``n`` rows: ``gram = A.T A``,
    ``atb = A.T b`` and the column sums of ``A`` (see :mod:`.gram`); the same scaling and refusals."""
    check_min_samples(n, MIN_SAMPLES_PER_PARAMETER * len(names), f"fit (coefficients {names})")
    ms = np.diag(gram) / n
    check_excited(names, ms, colsum / n)
    scale = np.sqrt(ms)
    gn = gram / np.outer(scale, scale)
    check_condition(names, gn, n)
    return np.linalg.solve(gn, atb / scale) / scale


def check_excited(names: list[str], ms: np.ndarray, mean: np.ndarray) -> None:
    """Refuse a zero or constant column (``ms``: mean square, ``mean``: mean of each column) but the offset."""
    for j, name in enumerate(names):
        if name == OFFSET:
            continue
        if not ms[j] > 0.0 or ms[j] - mean[j] ** 2 <= 1e-20 * ms[j]:
            raise IdentificationError(f"regressor column '{name}' is zero or constant: no excitation")


def check_condition(names: list[str], gram: np.ndarray, n: int) -> None:
    """Refuse dependent columns: condition number of the column-scaled ``gram`` above ``MAX_CONDITION``."""
    eig = np.linalg.eigvalsh(gram / n)
    cond = float(np.sqrt(eig[-1] / eig[0])) if eig[0] > 0 else np.inf
    if not cond <= MAX_CONDITION:
        raise IdentificationError(
            f"regressor columns {names} are linearly dependent (condition number {cond:.3g}): "
            f"expected <= {MAX_CONDITION:g}"
        )


class UNormal:
    """The least-squares rounds of :func:`~.model.fit_spec`'s fixed point from normal equations (:mod:`.gram`): the
    products of the columns that do not read ``u`` computed once, each round adding those of the terms that do;
    solved in :func:`~.model.design`'s column order (the same names in the same order, the same refusals)."""

    def __init__(self, spec, names: list[str], normal: Normal, plain_slices: list):
        """``spec``: the :class:`~.model.ModelSpec`; ``names`` and ``plain_slices``: the names and term slices of
        :func:`~.model.design` for its terms that do not read ``u``; ``normal``: their normal equations."""
        self.spec, self.names, self.normal = spec, names, normal
        plain = {effect: sl for effect, _, sl in plain_slices}
        # per term of the spec: its slice of the plain design, or None (it reads u: its columns come each round)
        self.layout = [(t, plain.get(t.effect)) for t in spec.terms]

    def solve(self, signals: Signals, ctx: Mapping[str, np.ndarray]) -> tuple[list[str], np.ndarray, list]:
        """Names, coefficients and term slices as :func:`~.model.design` and :func:`~.model.solve` give them,
        with ``u`` of ``ctx``."""
        su = signals.with_columns(**ctx)
        k_plain = len(self.names)
        perm = list(range(len(self.spec.linear)))
        names = self.names[: len(perm)]
        slices, blocks = [], []
        for t, sl in self.layout:
            if sl is None:
                m = get_effect(t.effect).columns(su, t.shape)
                start = k_plain + sum(b.shape[1] for b in blocks)
                blocks.append(m)
                idx = list(range(start, start + m.shape[1]))
                new = [t.effect] if m.shape[1] == 1 else [f"{t.effect}#{i}" for i in range(m.shape[1])]
            else:
                idx, new = list(range(sl.start, sl.stop)), self.names[sl]
            slices.append((t.effect, t.shape, slice(len(perm), len(perm) + len(idx))))
            perm += idx
            names += new
        g, aty, colsum = self.normal.system(np.column_stack(blocks))
        p = np.asarray(perm)
        return names, solve_gram(names, g[np.ix_(p, p)], aty[p], colsum[p], self.normal.n), slices
