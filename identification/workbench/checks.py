"""Checks that the workbench's own preprocessing does not stand in for a physical effect.

The velocity differentiated here (:mod:`.data`) is biased where the motion spans few samples of its window: a
centred order-2 derivative's error grows with the third derivative of ``q``, which lag-like terms (delay, motor
lag, inertia) and the dynamics and memory probes can fit. :func:`derivative_checks` gives the log again with less
biased velocities; :func:`~.diagnose.diagnose` names such a term, and calls a log ``unexplained`` on such a probe,
only when it survives every one of them.
"""

from __future__ import annotations

from dataclasses import replace

from .data import Dataset, differentiate, faster_derivative

__all__ = ["CHECK_ORDER", "derivative_checks"]

CHECK_ORDER = 4  # polynomial order of the cubic check (a first derivative's coefficients agree for orders 3 and 4)


def derivative_checks(ds: Dataset) -> list[tuple[Dataset, str]]:
    """``ds`` with ``dq`` (and ``ddq``) differentiated less biased than the workbench's own, each with a phrase
    saying how: over half the window (:func:`faster_derivative`), and by a cubic fit over the same window (the
    centred order-2 derivative's error grows with the third derivative of ``q``, the cubic's with the fifth: at
    coarse sample periods, where even 3 samples span the servo's transients, a shorter window is not enough).
    Empty when the velocity is the log's own. The checks of :func:`~.diagnose.diagnose` that a lag-like effect
    or a probe is not the differentiation's own error."""
    info = ds.preprocessing.get("dq", {})
    if info.get("source") != "derivative of q" or ds.dt is None or "q" not in ds.signals:
        return []
    w0 = info["window"]
    out = []
    fast = faster_derivative(ds)
    if fast is not None:
        out.append((fast[0], f"dq over {fast[1]} samples instead of {w0}"))
    runs, q = ds.signals.runs(), ds.signals["q"]
    cols = {"dq": differentiate(q, runs, ds.dt, 1, w0, order=CHECK_ORDER)}
    if "ddq_est" not in ds.signals:
        cols["ddq"] = differentiate(q, runs, ds.dt, 2, 2 * w0 - 1, order=CHECK_ORDER)
    out.append((replace(ds, signals=ds.signals.with_columns(**cols)),
                f"dq by a cubic fit over the same {w0} samples"))
    return out
