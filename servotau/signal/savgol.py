"""Savitzky-Golay filters: smoothed signals and their time derivatives (paper sections 2.1, 5.1).

A Savitzky-Golay (SG) filter fits a polynomial of degree ``order`` by least squares to the last
``window`` samples and returns the value or a derivative of that polynomial at one point of the
window. With a constant sampling period the fit is a fixed linear map, so every estimate is one
dot product with coefficients computed once by :func:`savgol_coeffs` (the least-squares solve of
:func:`scipy.signal.savgol_coeffs`, without importing :mod:`scipy.signal`, whose import takes about a second:
a process that only filters causally, such as the controller, never pays it).

The paper uses 80-sample windows at 1 kHz, order 2 for the encoders (q, dq, ddq) and order 1 for
the IMU and the F/T sensors (section 5.1; Algorithm 1 writes order 0 for the F/T sensors).

Evaluation point and delay (``eval_at``), for a causal window of N samples:

- ``"last"``: the polynomial is evaluated at the newest sample (``pos = N - 1``). It extrapolates
  the fit to "now", so for ``deriv < order`` the low-frequency delay is 0 samples, paid for with
  a much weaker noise attenuation than the centred fit. For ``deriv == order`` the estimate is
  the constant top derivative of the fit, which does not depend on the evaluation point: its
  delay is (N - 1) / 2 samples. Outputs of one filter may thus refer to different instants.
- ``"centre"``: the polynomial is evaluated at the middle of the window (``pos = (N - 1) / 2``,
  a half-integer for even N, as :func:`scipy.signal.savgol_coeffs` does by default). Every output
  is the estimate at ``t - (N - 1) / 2 * dt``: 39.5 ms for the paper's 80 samples at 1 kHz (the
  paper's "40 ms, half the window"). All derivatives share that time stamp.

:func:`delay` returns the low-frequency group delay, computed from the coefficients: if the
filter output for the input ``t**(k+1) / (k+1)!`` (whose k-th derivative is ``t``) is
``t - tau``, the delay is ``tau``. Closed form: ``(N - 1) / 2`` if ``deriv == order``, else
``N - 1 - pos``.

Non-finite samples: :meth:`CausalSavgol.update` rejects a sample containing NaN or inf with
:class:`~servotau.errors.EstimationError` and leaves the buffer and the outputs unchanged, so an
estimator can catch the error, flag the sample and go on. The next accepted sample is then
treated as one period after the last accepted one; callers who prefer to keep time alignment
can repeat the last good sample instead.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from scipy.linalg import lstsq
from scipy.ndimage import correlate1d

from servotau.errors import EstimationError

EvalAt = Literal["last", "centre"]
_EVAL_AT = ("last", "centre")


def savgol_coeffs(window: int, order: int, deriv: int = 0, delta: float = 1.0, pos: float | None = None,
                  use: Literal["dot", "conv"] = "dot") -> np.ndarray:
    """Coefficients of the SG filter that fits a polynomial of degree ``order`` to ``window`` samples and
    returns its ``deriv``-th derivative [unit / s**deriv] at sample ``pos`` of the window (0 = oldest; default:
    the middle), for samples ``delta`` [s] apart; ``use="dot"`` for a dot product with the samples oldest first,
    ``"conv"`` for a convolution. The same least-squares problem and solver as
    :func:`scipy.signal.savgol_coeffs` (a test checks the two equal to the bit). Arguments are not checked
    (callers check them)."""
    if pos is None:
        pos = (window - 1) / 2
    if deriv > order:
        return np.zeros(window)
    x = np.arange(-pos, window - pos, dtype=float)  # sample times relative to pos, in samples
    if use == "conv":
        x = x[::-1]
    a = x ** np.arange(order + 1, dtype=float).reshape(-1, 1)  # row k: x**k
    y = np.zeros(order + 1)
    y[deriv] = float(math.factorial(deriv)) / delta**deriv
    coeffs, *_ = lstsq(a, y, cond=np.finfo(float).eps * max(a.shape))
    return coeffs


def _check_int(name: str, value: object, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise EstimationError(f"{name}={value!r}: expected an integer >= {minimum}")
    return int(value)


def _check_settings(window: object, order: object, dt: object | None = None) -> tuple[int, int]:
    window = _check_int("window", window, 1)
    order = _check_int("order", order, 0)
    if order >= window:
        raise EstimationError(f"order={order}: expected order < window (window={window})")
    if dt is not None and (
        isinstance(dt, bool)
        or not isinstance(dt, int | float | np.number)
        or not dt > 0
        or not math.isfinite(dt)
    ):
        raise EstimationError(f"dt={dt!r}: expected a finite sampling period > 0 [s]")
    return window, order


def _check_deriv(deriv: object, order: int, name: str = "deriv") -> int:
    deriv = _check_int(name, deriv, 0)
    if deriv > order:
        raise EstimationError(f"{name}={deriv}: expected a derivative order <= order={order}")
    return deriv


def _eval_pos(window: int, eval_at: object) -> float:
    """Index in the window (0 = oldest) where the fitted polynomial is evaluated."""
    if eval_at == "last":
        return float(window - 1)
    if eval_at == "centre":
        return (window - 1) / 2
    raise EstimationError(f"eval_at={eval_at!r}: expected one of {_EVAL_AT}")


def causal_coeffs(window: int, order: int, deriv: int, dt: float, eval_at: EvalAt = "last") -> np.ndarray:
    """Coefficients of a causal SG filter, for ``np.dot(coeffs, x[-window:])``.

    Args:
        window: Number of samples in the window.
        order: Degree of the fitted polynomial.
        deriv: Derivative order of the estimate (0 = smoothed value).
        dt: Sampling period [s]; the estimate of derivative k is in [unit] / [s]**k.
        eval_at: ``"last"`` (newest sample) or ``"centre"`` (middle of the window).

    Returns:
        Array of shape (window,), oldest sample first.
    """
    window, order = _check_settings(window, order, dt)
    deriv = _check_deriv(deriv, order)
    pos = _eval_pos(window, eval_at)
    return savgol_coeffs(window, order, deriv=deriv, delta=float(dt), pos=pos, use="dot")


def delay(window: int, order: int, deriv: int = 0, eval_at: EvalAt = "last") -> float:
    """Low-frequency group delay of a causal SG filter [samples].

    The delay tau is defined by the response to ``x(t) = t**(k+1) / (k+1)!``, k = ``deriv``:
    the filter output is exactly ``t - tau`` (the filter is exact on polynomials of degree <=
    order, so the output is affine in t with unit slope).

    Args:
        window: Number of samples in the window.
        order: Degree of the fitted polynomial.
        deriv: Derivative order of the estimate.
        eval_at: ``"last"`` or ``"centre"``.

    Returns:
        The delay in samples: ``(window - 1) / 2`` if ``deriv == order``, else
        ``window - 1 - pos`` (0 for ``"last"``, ``(window - 1) / 2`` for ``"centre"``).
    """
    window, order = _check_settings(window, order)
    deriv = _check_deriv(deriv, order)
    pos = _eval_pos(window, eval_at)
    coeffs = savgol_coeffs(window, order, deriv=deriv, delta=1.0, pos=pos, use="dot")
    # Lag of each coefficient: the newest sample (last coefficient) has lag 0.
    lag = np.arange(window - 1, -1, -1, dtype=float)
    # Output at t = 0 is -tau; centre the lags on their mean to keep the powers small.
    t0 = (window - 1) / 2
    x = (t0 - lag) ** (deriv + 1) / math.factorial(deriv + 1)  # input shifted by t0
    return round(float(t0 - np.dot(coeffs, x)), 9)  # drop the round-off of the dot product


def savgol_centred(x: np.ndarray, window: int, order: int, dt: float, deriv: int = 0) -> np.ndarray:
    """Off-line (non-causal) SG filter of a recorded signal, aligned with the input time stamps.

    Each output sample is the estimate at its own time stamp, from the ``window`` samples
    centred on it (zero delay). At the first and last ``(window - 1) // 2`` samples the window
    cannot be centred: as ``scipy.signal.savgol_filter(mode="interp")``, the polynomial fitted to
    the first (last) full window is evaluated there. These edge estimates have no delay either
    but are noisier; drop them if that matters.

    Args:
        x: Signal of shape (T,) or (T, C), time along axis 0, uniformly sampled.
        window: Number of samples in the window; odd, so that it centres on a sample.
        order: Degree of the fitted polynomial.
        dt: Sampling period [s].
        deriv: Derivative order of the estimate, in [unit] / [s]**deriv.

    Returns:
        Float array with the shape of ``x``.
    """
    window, order = _check_settings(window, order, dt)
    deriv = _check_deriv(deriv, order)
    if window % 2 == 0:
        raise EstimationError(
            f"window={window}: expected an odd window for a centred filter "
            "(an even window centres between two samples)"
        )
    x = np.asarray(x, dtype=float)
    if x.ndim not in (1, 2):
        raise EstimationError(f"x has shape {x.shape}: expected (T,) or (T, C)")
    if x.shape[0] < window:
        raise EstimationError(f"x has {x.shape[0]} samples: expected at least window={window}")
    if not np.all(np.isfinite(x)):
        raise EstimationError("x contains NaN or inf: expected finite samples")
    from scipy.signal import savgol_filter  # here: importing scipy.signal takes about a second

    return savgol_filter(x, window, order, deriv=deriv, delta=float(dt), axis=0, mode="interp")


FEW_RUNS = 16
"""Up to this many runs, :func:`savgol_centred_runs` filters them one by one with :func:`savgol_centred` (the same
arithmetic to the bit as a recording filtered alone); more in one pass."""


def savgol_centred_runs(x: np.ndarray, runs: np.ndarray, window: int, order: int, dt: float, deriv: int = 0,
                        out: np.ndarray | None = None) -> np.ndarray:
    """:func:`savgol_centred` of each run ``[a, b)`` of ``runs`` (each at least ``window`` samples) of the 1-D
    signal ``x``, written into ``out`` (zeros by default; other samples left as they are). Up to ``FEW_RUNS`` runs
    (a log without gaps, a few recordings joined), one :func:`savgol_centred` call each; more (a log with thousands
    of gaps) in one pass, not one filter call per run. Inside a run the centred coefficients; at its
    first and last ``(window - 1) // 2`` samples the polynomial fitted to its first (last) full window, as
    :func:`savgol_centred`, evaluated with fixed coefficients per position (equal to its fit up to round-off)."""
    window, order = _check_settings(window, order, dt)
    deriv = _check_deriv(deriv, order)
    if window % 2 == 0:
        raise EstimationError(f"window={window}: expected an odd window for a centred filter")
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise EstimationError(f"x has shape {x.shape}: expected (T,)")
    out = np.zeros_like(x) if out is None else out
    runs = np.asarray(runs, dtype=np.intp).reshape(-1, 2)
    if not runs.size:
        return out
    if np.any(runs[:, 1] - runs[:, 0] < window):
        raise EstimationError(f"a run shorter than window={window}: expected runs of at least the window")
    if len(runs) <= FEW_RUNS:
        for a, b in runs:
            out[a:b] = savgol_centred(x[a:b], window, order, dt, deriv=deriv)
        return out
    if not all(np.isfinite(x[a:b]).all() for a, b in runs):
        raise EstimationError("x contains NaN or inf in a run: expected finite samples")
    h = window // 2
    coeffs = np.stack([savgol_coeffs(window, order, deriv=deriv, delta=float(dt), pos=p, use="dot")
                       for p in range(window)])  # row p: the fit of a window evaluated at its sample p
    inside = np.zeros(len(x) + 1, dtype=np.int64)  # +1 from a run's first centred sample, -1 past its last
    np.add.at(inside, runs[:, 0] + h, 1)
    np.add.at(inside, runs[:, 1] - h, -1)
    centred = np.flatnonzero(np.cumsum(inside[:-1]) > 0)
    if centred.size:
        out[centred] = correlate1d(np.nan_to_num(x), coeffs[h])[centred]  # samples between runs may be NaN
    head = x[runs[:, 0, None] + np.arange(window)]  # each run's first window
    tail = x[runs[:, 1, None] - window + np.arange(window)]  # and its last
    out[runs[:, 0, None] + np.arange(h)] = head @ coeffs[:h].T
    out[runs[:, 1, None] - h + np.arange(h)] = tail @ coeffs[h + 1:].T
    return out


class CausalSavgol:
    """On-line SG filter of ``n_channels`` signals sampled every ``dt``, without allocation per update.

    Samples go into a ring buffer of 2 * window rows where each sample is written twice (rows i
    and i + window), so the last ``window`` samples are always one contiguous block and every
    update is one ``np.dot(coeffs, block, out=...)``.

    Outputs are read-only views, one per entry of ``derivs``, of shape (n_channels,), that keep
    their identity and are refreshed in place by :meth:`update`. They hold NaN until
    ``window`` samples have been accepted (``ready`` is False until then).

    Example::

        sg = CausalSavgol(30, window=80, order=2, dt=1e-3, eval_at="centre")
        q, dq, ddq = sg.outputs  # views, refreshed by every update
        sg.update(encoders)  # [rad]
        if sg.ready:
            ...  # q, dq, ddq at t - sg.delays[k] * dt
    """

    def __init__(
        self,
        n_channels: int,
        window: int,
        order: int,
        dt: float,
        derivs: tuple[int, ...] = (0, 1, 2),
        eval_at: EvalAt = "last",
    ) -> None:
        """Precompute the coefficients and allocate the buffers.

        Args:
            n_channels: Number of signals filtered together.
            window: Number of samples in the window (even windows are allowed).
            order: Degree of the fitted polynomial.
            dt: Sampling period [s].
            derivs: Derivative orders to estimate, each <= order, without repetition.
            eval_at: ``"last"`` (newest sample) or ``"centre"`` (middle of the window).
        """
        n_channels = _check_int("n_channels", n_channels, 1)
        window, order = _check_settings(window, order, dt)
        try:
            derivs = tuple(derivs)
        except TypeError as exc:
            raise EstimationError(f"derivs={derivs!r}: expected a tuple of derivative orders") from exc
        if not derivs or len(set(derivs)) != len(derivs):
            raise EstimationError(f"derivs={derivs!r}: expected a non-empty tuple without repetition")
        derivs = tuple(_check_deriv(k, order, "derivs") for k in derivs)
        _eval_pos(window, eval_at)

        self.n_channels = n_channels
        self.window = window
        self.order = order
        self.dt = float(dt)
        self.derivs = derivs
        self.eval_at = eval_at
        self.delays = tuple(delay(window, order, k, eval_at) for k in derivs)  # [samples]

        coeffs = np.stack([causal_coeffs(window, order, k, dt, eval_at) for k in derivs])
        coeffs.flags.writeable = False
        self.coeffs = coeffs  # (len(derivs), window), oldest sample first
        self._buffer = np.zeros((2 * window, n_channels))
        # Views built once: the row pairs written by each update and the window that follows it.
        self._rows = [(self._buffer[i], self._buffer[i + window]) for i in range(window)]
        self._blocks = [self._buffer[i + 1 : i + 1 + window] for i in range(window)]
        self._out = np.full((len(derivs), n_channels), np.nan)
        self._check = np.zeros(n_channels, dtype=bool)
        views = []
        for row in self._out:
            view = row.view()
            view.flags.writeable = False
            views.append(view)
        self._outputs = tuple(views)
        self._head = window - 1  # row of the newest sample
        self._count = 0

    @property
    def outputs(self) -> tuple[np.ndarray, ...]:
        """Read-only estimates, one per entry of ``derivs``, in [unit] / [s]**k; NaN until ready."""
        return self._outputs

    @property
    def ready(self) -> bool:
        """True once ``window`` samples have been accepted."""
        return self._count >= self.window

    def output(self, deriv: int) -> np.ndarray:
        """Read-only estimate of derivative ``deriv`` (one of ``derivs``)."""
        if deriv not in self.derivs:
            raise EstimationError(f"deriv={deriv!r}: expected one of derivs={self.derivs}")
        return self._outputs[self.derivs.index(deriv)]

    def reset(self) -> None:
        """Forget all samples: not ready, outputs NaN."""
        self._buffer.fill(0.0)
        self._out.fill(np.nan)
        self._head = self.window - 1
        self._count = 0

    def update(self, x: np.ndarray) -> None:
        """Push one sample and refresh the outputs once the window is full.

        Args:
            x: Sample of shape (n_channels,); a float64 array avoids any allocation.

        Raises:
            EstimationError: ``x`` has the wrong shape or contains NaN or inf. The buffer and
                the outputs are then left unchanged.
        """
        if getattr(x, "shape", None) != (self.n_channels,):
            shape = np.shape(x)
            if shape != (self.n_channels,):
                raise EstimationError(f"x has shape {shape}: expected ({self.n_channels},)")
            x = np.asarray(x, dtype=float)
        np.isfinite(x, out=self._check)
        if not self._check.all():
            bad = np.flatnonzero(~self._check).tolist()
            raise EstimationError(f"x is NaN or inf at channels {bad}: expected finite values (rejected)")
        head = self._head + 1
        if head == self.window:
            head = 0
        low, high = self._rows[head]
        np.copyto(low, x)
        np.copyto(high, x)
        self._head = head
        if self._count < self.window:  # saturates: no int allocation once ready
            self._count += 1
            if self._count < self.window:
                return
        np.dot(self.coeffs, self._blocks[head], out=self._out)
