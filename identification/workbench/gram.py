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

import numpy as np

TIE = 1e-9  # relative difference of two training losses below which the exact residuals decide
GRAM_DIGITS = 1e-12  # round-off of a loss from the Gram matrix, relative to |y|^2

__all__ = ["Normal", "loss_of", "near_ties"]


class Normal:
    """Normal equations of ``[base | cols]`` against ``y`` over the rows of ``mask`` (None: all rows), for
    any number of candidate column blocks ``cols``; the products of ``base`` and ``y`` computed once."""

    def __init__(self, base: np.ndarray, y: np.ndarray, mask: np.ndarray | None = None):
        self.mask = mask
        self.w = None if mask is None else mask.astype(np.float64)
        self.n = len(y) if mask is None else int(np.count_nonzero(mask))
        self.base = base
        self.bw = base if self.w is None else base * self.w[:, None]  # rows outside the mask weigh 0
        self.yw = y if self.w is None else y * self.w
        self.gbb = base.T @ self.bw
        self.by = self.bw.T @ y
        self.bsum = self.bw.sum(axis=0)
        self.yty = float(y @ self.yw)

    def system(self, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The Gram matrix, ``A.T y`` and the column sums of ``A = [base | cols]`` over the rows."""
        cw = cols if self.w is None else cols * self.w[:, None]
        gcb = cols.T @ self.bw
        g = np.block([[self.gbb, gcb.T], [gcb, cols.T @ cw]])
        return g, np.concatenate([self.by, cols.T @ self.yw]), np.concatenate([self.bsum, cw.sum(axis=0)])


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
