"""Checks that the workbench's own preprocessing, or a constant the model lacks, does not stand in for an effect.

The velocity differentiated here (:mod:`.data`) is biased where the motion spans few samples of its window: a
centred order-2 derivative's error grows with the third derivative of ``q``, which lag-like terms (delay, motor
lag, inertia) and the dynamics and memory probes can fit. :func:`derivative_checks` gives the log again with less
biased velocities; :func:`~.diagnose.diagnose` names such a term, and calls a log ``unexplained`` on such a probe,
only when it survives every one of them. :func:`smoothing_check` does the same for the torque's smoothing (a long
order-2 smoothing errs where the torque bends); :func:`preprocessing_checks` gives all of them. :func:`constant_error`
measures what a constant offset would remove from a servo-error model without one.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from servotau.actuator import Loss
from servotau.actuator.terms import OFFSET

from ..data.folds import Fold
from .data import Dataset, windows_text
from .evaluate import error_of
from .filters import differentiate
from .model import ModelSpec
from .probes import base_per_fold, heldout_prediction

__all__ = ["CHECK_ORDER_STEP", "CONSTANT_ERROR", "DIFFERENTIATION", "OFFSET_ADVICE", "SMOOTHING", "constant_error",
           "derivative_checks", "faster_derivative", "offset_spec", "preprocessing_checks", "smoothing_check",
           "with_derivatives"]

CHECK_ORDER_STEP = 2  # the higher-order check's polynomial order over the velocity's own: a centred first
# derivative's coefficients agree for orders 2k - 1 and 2k (order 2 -> 4: a cubic's derivative; 4 -> 6: a quintic's)
SMOOTH_CHECK_ORDER = 4  # polynomial order of the torque's check (smoothing_check)
DIFFERENTIATION = "the differentiation's error"  # the cause a derivative check gives
SMOOTHING = "the torque smoothing's error"  # the cause the smoothing check gives
CONSTANT_ERROR = "a constant error"  # the cause the offset check gives (the message's --offset advice looks for it)
OFFSET_ADVICE = "rerun the diagnosis with --offset on"  # in every message that finds a constant error the model lacks
FAST_MIN_WINDOW = 3  # [samples] shortest window of faster_derivative (order 2 over 3 samples: the central difference)


def faster_derivative(ds: Dataset, factor: float = 0.5) -> tuple[Dataset, int | str] | None:
    """``ds`` with ``dq`` (and ``ddq``) differentiated with ``factor`` times the window (odd, at least
    ``FAST_MIN_WINDOW``: a window of 5 samples shrinks to the central difference), and that window; None when the
    velocity is the log's own or no window can shrink. A joined log shrinks each recording's own window (the
    ``windows`` of its preprocessing; the windows as text when they differ, :func:`windows_text`). The check of
    :func:`~.diagnose.diagnose` that a lag-like effect is not the differentiation's own lag."""
    if not _differentiated_here(ds):
        return None
    windows = [p.window for p in ds.filter_parts()]
    fast = [min(w, max(FAST_MIN_WINDOW, int(round(factor * w)) | 1)) for w in windows]
    if fast == windows:
        return None
    return with_derivatives(ds, fast), fast[0] if len(set(fast)) == 1 else windows_text(fast)


def _differentiated_here(ds: Dataset) -> bool:
    """The velocity is the workbench's derivative of ``q`` (not the log's own), so it can be differentiated again."""
    return ds.preprocessing.get("dq", {}).get("source") == "derivative of q" and ds.dt is not None \
        and "q" in ds.signals


def with_derivatives(ds: Dataset, windows: list[int], orders: list[int] | None = None) -> Dataset:
    """``ds`` with ``dq`` (and ``ddq``, unless the log has its own) differentiated again from ``q``, each recording
    on its own runs and period with its window of ``windows`` (``ddq`` over twice it) and polynomial order of
    ``orders`` (default its own, :meth:`~.data.Dataset.filter_parts`; ``ddq`` at least 3); the preprocessing says
    so."""
    orders = [p.order for p in ds.filter_parts()] if orders is None else orders
    cols = {"dq": _per_recording(ds, ds.signals["q"], windows, 1, orders)}
    if "ddq_est" not in ds.signals:
        cols["ddq"] = _per_recording(ds, ds.signals["q"], windows, 2, [max(o, 3) for o in orders])
    parts = [(p.first, w, p.period) for p, w in zip(ds.filter_parts(), windows, strict=True)]
    dq = {**ds.preprocessing["dq"], "windows": parts, "orders": tuple(orders)}
    return replace(ds, signals=ds.signals.with_columns(**cols), preprocessing={**ds.preprocessing, "dq": dq})


def _per_recording(ds: Dataset, x: np.ndarray, windows: list[int], deriv: int, orders: list[int],
                   key: str = "dq") -> np.ndarray:
    """The ``deriv``-th derivative of ``x`` (0: smoothed), each recording of ``ds`` (as filtered for ``key``) on its
    own runs and period with its window of ``windows`` (twice it, less one, for ``deriv`` 2) and order of
    ``orders``."""
    runs, out = ds.signals.runs(), []
    for p, w, o in zip(ds.filter_parts(key), windows, orders, strict=True):
        local = [(r - p.first, e - p.first) for r, e in runs if p.first <= r < p.end]
        out.append(differentiate(x[p.first:p.end], local, p.period, deriv, w if deriv < 2 else 2 * w - 1, order=o))
    return np.concatenate(out)


def smoothing_check(ds: Dataset) -> tuple[Dataset, str] | None:
    """``ds`` with the torque smoothed less biased than the workbench's own, by a quartic fit over the same window
    (the centred order-2 fit's error grows with the torque's fourth derivative, the quartic's with its sixth: a long
    window's error follows the torque's bends, which lag-like terms fit), and how;
    None when the torque is the log's own or its window is under ``2 SMOOTH_CHECK_ORDER + 3`` samples (a quartic
    over fewer samples hardly smooths: the raw noise would decide the check)."""
    info = ds.preprocessing.get("tau", {})
    if info.get("source") != "smoothed" or "tau_raw" not in ds.signals or ds.dt is None:
        return None
    windows = [p.window for p in ds.filter_parts("tau")]
    if min(windows) < 2 * SMOOTH_CHECK_ORDER + 3:
        return None
    orders = (SMOOTH_CHECK_ORDER,) * len(windows)
    tau = _per_recording(ds, ds.signals["tau_raw"], windows, 0, orders, key="tau")
    prep = {**ds.preprocessing, "tau": {**info, "order": SMOOTH_CHECK_ORDER, "orders": orders}}
    return (replace(ds, signals=ds.signals.with_columns(tau=tau), preprocessing=prep),
            f"tau smoothed by a quartic fit over the same {info['window']} samples")


def derivative_checks(ds: Dataset) -> list[tuple[Dataset, str]]:
    """``ds`` with ``dq`` (and ``ddq``) differentiated less biased than the workbench's own, each with a phrase
    saying how: over half the window (:func:`faster_derivative`), and by a polynomial ``CHECK_ORDER_STEP`` orders
    higher over the same window (the centred order-2 derivative's error grows with the third derivative of ``q``,
    the cubic's with the fifth: at coarse sample periods, where even 3 samples span the servo's transients, a
    shorter window is not enough).
    Empty when the velocity is the log's own. The checks of :func:`~.diagnose.diagnose` that a lag-like effect
    or a probe is not the differentiation's own error."""
    if not _differentiated_here(ds):
        return []
    w0 = ds.preprocessing["dq"]["window"]
    out = []
    fast = faster_derivative(ds)
    if fast is not None:
        out.append((fast[0], f"dq over {fast[1]} samples instead of {w0}"))
    parts = ds.filter_parts()
    windows = [p.window for p in parts]
    higher = [p.order + CHECK_ORDER_STEP for p in parts]
    # a window of no more samples leaves the polynomial no freedom: finite differences again
    if all(w > o for w, o in zip(windows, higher, strict=True)):
        fit = "a cubic" if set(higher) == {4} else "a quintic" if set(higher) == {6} else "a higher-order"
        out.append((with_derivatives(ds, windows, higher), f"dq by {fit} fit over the same {w0} samples"))
    return out


def offset_spec(ds: Dataset, spec: ModelSpec) -> ModelSpec | None:
    """``spec`` with a constant offset, for a servo-error log whose model lacks one; else None."""
    if not ds.actuator or OFFSET in spec.linear:
        return None
    return replace(spec, linear=(*spec.linear, OFFSET))


def constant_error(ds: Dataset, spec: ModelSpec, loss: Loss, folds: list[Fold], e0: float, min_gain: float,
                   cache: dict) -> tuple[str, ...]:
    """The advice to rerun with ``--offset on`` when a constant offset would remove at least ``min_gain`` of the
    held-out error ``e0`` of ``spec``, a servo-error model without one (same blocks); else empty. A constant error is
    an encoder's zero, or a dead zone or friction under a load that never reverses: no other term tells them apart,
    and without the offset the effects that stand in for it (or none) are named."""
    with_offset = offset_spec(ds, spec)
    if with_offset is None or not e0 > 0:
        return ()
    pred = heldout_prediction(base_per_fold(ds, with_offset, loss, folds, cache), ds.n)
    gain = 1.0 - error_of(ds.target - pred, ds.target, loss) / e0
    if not gain >= min_gain:
        return ()
    return (f"a constant error: an offset in the model, which it lacks, removes {100 * gain:.0f} % of the held-out "
            "error (an encoder's zero, or a dead zone or friction under a load that never reverses): "
            f"{OFFSET_ADVICE} (a motor model for control takes no offset)",)


def preprocessing_checks(ds: Dataset) -> list[tuple[Dataset, str, str]]:
    """Every check of the workbench's preprocessing, as ``(dataset, how, cause)``: :func:`derivative_checks` (the
    differentiation's error) and :func:`smoothing_check` (the torque smoothing's error). Empty when the velocity and
    the torque are the log's own."""
    out = [(d, how, DIFFERENTIATION) for d, how in derivative_checks(ds)]
    smoothed = smoothing_check(ds)
    if smoothed is not None:
        out.append((*smoothed, SMOOTHING))
    return out
