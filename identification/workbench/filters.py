"""Savitzky-Golay filters chosen from the data: the window and polynomial order of the velocity's derivative and the
torque's smoothing (:func:`cv_window`, :func:`cv_derivative`, by leave-one-out prediction of each sample from its
neighbours), and the centred filter on each run of samples (:func:`differentiate`). :mod:`.data` applies them when a
log is loaded; :mod:`.checks` applies them again with less biased settings."""

from __future__ import annotations

import numpy as np

__all__ = ["DQ_ORDERS", "MAX_WINDOW", "MIN_WINDOW", "SE_BLOCKS", "cv_derivative", "cv_window", "differentiate"]

MIN_WINDOW = 5  # [samples] shortest SG window considered by cv_window
MAX_WINDOW = 101  # [samples] longest SG window considered by cv_window
DQ_ORDERS = (2, 4)  # polynomial orders of the velocity's SG derivative, one chosen per log (cv_derivative)
SE_BLOCKS = 20  # contiguous blocks over which cv_derivative estimates the standard error of a difference


def _loo_coeffs(window: int, order: int) -> np.ndarray:
    """Weights of the leave-one-out SG smoother: the polynomial of ``order`` fitted to the ``window - 1``
    samples around the centre, without it, evaluated at the centre."""
    h = window // 2
    j = np.array([k for k in range(-h, h + 1) if k != 0], dtype=float)
    a = np.vander(j / h, order + 1, increasing=True)
    row = np.linalg.pinv(a)[0]  # value at offset 0
    c = np.zeros(window)
    c[np.arange(window) != h] = row
    return c


def cv_window(x: np.ndarray, runs: list[tuple[int, int]], order: int = 2, *,
              min_window: int = MIN_WINDOW, max_window: int = MAX_WINDOW) -> int:
    """SG window [samples, odd] chosen from the data: the one whose leave-one-out smoother (fitted on the
    neighbours, not the sample) best predicts each sample of ``x`` (mean squared error over the interiors
    of the runs). Noise pulls it longer, curvature shorter. Bounded by ``min_window`` and ``max_window``
    and by a tenth of the longest run; the longest window within 2 % of the best error is taken (the
    error is flat near its minimum; a longer window is less noisy for the derivative)."""
    return _cv(x, runs, order, min_window, max_window)[0]


def cv_derivative(x: np.ndarray, runs: list[tuple[int, int]], orders: tuple[int, ...] = DQ_ORDERS) -> tuple[int, int]:
    """``(window, order)`` of the SG derivative of ``x``: each order of ``orders`` with its :func:`cv_window`; a
    higher order replaces a lower one only where its leave-one-out smoother predicts the held-out samples better by
    more than one standard error of the difference (the one-standard-error rule: the simpler filter unless the data
    show otherwise; the error is estimated over ``SE_BLOCKS`` contiguous blocks, as neighbouring residuals share
    their windows). A higher order follows faster motion over the same window (the order-2 derivative's error grows
    with the third derivative of ``x``, the quartic's with the fifth) and takes a longer window against the noise:
    the held-out error weighs the two. On most of the plant family's clean logs (1-16 ms) the quartic wins and errs
    3-4 times less than the order-2 derivative against the true velocity."""
    best = None  # (window used, order, window of the best held-out error)
    for order in orders:
        window, err, best_window = _cv(x, runs, order, MIN_WINDOW, MAX_WINDOW)
        if not np.isfinite(err):
            continue
        if best is None or _better(x, runs, (best[2], best[1]), (best_window, order)):
            best = (window, order, best_window)
    return best[:2] if best is not None else (cv_window(x, runs, orders[0]), orders[0])


def _better(x: np.ndarray, runs: list[tuple[int, int]], old: tuple[int, int], new: tuple[int, int]) -> bool:
    """Whether the leave-one-out smoother ``new`` (window, order; each order at its best window) beats ``old`` on
    ``x`` by more than one standard error of the mean difference of their squared residuals (same samples: the
    interiors of the runs for the longer window; ``SE_BLOCKS`` contiguous blocks)."""
    hi = max(old[0], new[0])
    diff = np.concatenate([_loo_residuals(x[a:b], *old, hi) ** 2 - _loo_residuals(x[a:b], *new, hi) ** 2
                           for a, b in runs if b - a > hi])
    if diff.size < 2 * SE_BLOCKS or not np.all(np.isfinite(diff)):
        return False
    blocks = diff[: diff.size // SE_BLOCKS * SE_BLOCKS].reshape(SE_BLOCKS, -1).mean(axis=1)
    return float(np.mean(diff)) > float(np.std(blocks, ddof=1)) / np.sqrt(SE_BLOCKS)


def _loo_residuals(seg: np.ndarray, window: int, order: int, hi: int) -> np.ndarray:
    """``seg`` minus its leave-one-out prediction, on the interior a window of ``hi`` samples leaves."""
    pred = np.convolve(seg, _loo_coeffs(window, order)[::-1], mode="valid")
    h0 = (hi - window) // 2
    return seg[hi // 2: len(seg) - hi // 2] - pred[h0: len(pred) - h0]


def _cv(x: np.ndarray, runs: list[tuple[int, int]], order: int, min_window: int, max_window: int
        ) -> tuple[int, float, int]:
    """:func:`cv_window`'s window, the best held-out error and the window that gives it (inf when no run is long
    enough)."""
    x = np.asarray(x, dtype=float)
    longest = max((b - a for a, b in runs), default=0)
    hi = min(max_window, longest // 10)
    hi = hi if hi % 2 else hi - 1
    lo = max(min_window, order + 3 if (order + 3) % 2 else order + 4)
    if hi <= lo:
        return lo, np.inf, lo
    cands = sorted({int(round(w)) | 1 for w in np.geomspace(lo, hi, 16)})
    errs = []
    segs = [x[a:b] for a, b in runs if b - a >= hi and np.all(np.isfinite(x[a:b]))]
    for w in cands:
        r = [_loo_residuals(seg, w, order, hi) for seg in segs]  # the same interior for every window
        n = sum(len(ri) for ri in r)
        errs.append(sum(float(ri @ ri) for ri in r) / n if n else np.inf)
    errs = np.asarray(errs)
    if not np.isfinite(errs).any():
        return lo, np.inf, lo
    best = float(np.min(errs))
    ok = [w for w, e in zip(cands, errs, strict=True) if e <= 1.02 * best]
    return max(ok), best, cands[int(np.argmin(errs))]


def differentiate(x: np.ndarray, runs: list[tuple[int, int]], dt: float, deriv: int, window: int,
                   order: int | None = None) -> np.ndarray:
    """Centred SG derivative of ``x`` on each run with a ``window`` of samples (polynomial ``order``, default
    ``deriv + 1`` and at least 2); runs shorter than the window use a shorter window (finite differences when
    it leaves no more samples than the order); the runs that share a window go to one
    :func:`~servotau.signal.savgol.savgol_centred_runs` call."""
    from servotau.signal.savgol import savgol_centred_runs

    out = np.zeros_like(x)
    w = window if window % 2 else window + 1
    order = max(2, deriv + 1) if order is None else order
    by_window: dict[int, list[tuple[int, int]]] = {}
    for a, b in runs:
        m = b - a
        wr = min(w, m if m % 2 else m - 1)
        if wr <= order:  # too short for the filter: finite differences (or zero for a single sample)
            seg = x[a:b]
            for _ in range(deriv):
                seg = np.gradient(seg, dt) if len(seg) > 1 else np.zeros_like(seg)
            out[a:b] = seg
        else:
            by_window.setdefault(wr, []).append((a, b))
    for wr, group in by_window.items():
        savgol_centred_runs(x, np.asarray(group), wr, order, dt, deriv, out=out)
    return out
