"""Excitation report: what the data exercised, so that an effect the data never excited is reported as
untestable, not as absent; and the requirements several effects share (each effect's ``needs`` in its file).

Every threshold is scaled to the log itself, not to one robot: the velocity's noise floor (the robust spread of
its second difference, :func:`noise_floor`) and its peak (``PEAK_QUANTILE`` of ``|dq|``) set what counts as
holding still, moving and fast motion; the torque's noise floor and peak set the hysteresis of its sign changes;
the sample period sets which lag-like shapes the log resolves (:func:`resolvable`, :class:`ResolvedGrid`). A
requirement's reason names the value measured on the log and the one needed.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass

import numpy as np

from .signals import SG_MIN, Signals

NOISE_MULTIPLE = 3.0
"""Holding still: ``|dq|`` below ``NOISE_MULTIPLE`` velocity noise floors (or ``HOLD_FRACTION`` of the peak)."""
HOLD_FRACTION = 0.01
MOVE_FRACTION = 0.05
"""Moving: ``|dq|`` above twice the hold threshold and ``MOVE_FRACTION`` of the peak speed."""
FAST_FRACTION = 0.5
"""Fast motion: ``|dq|`` above ``FAST_FRACTION`` of the peak speed (and twice the move threshold); slow motion:
between the hold threshold and that."""
PEAK_QUANTILE = 0.99
"""The peak of ``|dq|`` and ``|tau|``: this quantile (a few spikes do not set the scale)."""
TORQUE_HYSTERESIS = 0.05
"""A torque sign change counts beyond ``TORQUE_HYSTERESIS`` of the torque peak and ``NOISE_MULTIPLE`` noise floors."""
MIN_SPAN = 50
"""[samples] Fewest samples of slow, fast or held motion an effect that needs it accepts."""
RESOLVE_PERIODS = 2.0
"""A lag-like shape (a delay, a time constant, the inertia term's lag) shorter than this many sample periods is
not resolved by the log: it is not offered, and an effect left without shapes cannot be told."""
JITTER_TOL = 0.25
"""Robust spread of the time steps [periods] up to which a log counts as uniformly sampled; beyond it the timing
cannot resolve a lag-like effect."""
GAP = 1.5
"""[periods] A longer time step is a gap (the filters restart), not jitter."""
TURNS = 2.0
"""A position column spanning more turns than this, or a servo error beyond ``MAX_ERROR``, is doubted to be in rad."""
MAX_ERROR = math.pi  # [rad]
"""Half a turn: a position servo whose error passes it no longer holds a position (a compliant real servo under
load reaches 1.3 rad: the measured Dynamixel XL330 pendulum logs, tests/data/xl330_pendulum)."""
MAX_TORQUE = 1e3  # [N m] a torque beyond this is doubted to be in N m (mN m?)
MAX_SPEED = 50.0  # [rad/s]
"""A joint velocity beyond this is doubted to be in rad/s (deg/s?): faster than the fastest legged robots' joints
(about 40 rad/s); a motor-side table faster than it needs its speed divided by the gear ratio."""
MAX_PERIOD = 0.5  # [s]
"""A sample period beyond this is doubted to be in s (ms, or a sample index?): five times the slowest measured servo
log we read (the STS3215 at 10 Hz, tests/data/sts3215_backlash); a time column in ms gives 1 at 1 kHz."""
NOISY_POSITION = 0.5
"""The position is mostly noise when its noise floor (:func:`noise_floor`) passes this fraction of its standard
deviation: white noise, or a column that is not an angle (a smooth motion's floor is a few % of its spread even at
a 20 ms period)."""


@dataclass(frozen=True)
class Excitation:
    """What a log exercised, with the thresholds measured on it.

    Attributes:
        duration: Length of the log [s] (sample count times period if the time is known).
        n_samples: Number of samples.
        velocity_reversals: Changes of direction between moves faster than ``v_move``.
        hold_time: Time with ``|dq| < v_hold`` [s].
        slow_time: Time with ``v_hold <= |dq| < v_fast`` [s].
        fast_time: Time with ``|dq| > v_fast`` [s].
        quadrants: Fraction of the moving samples in each (velocity sign, torque sign) quadrant,
            keys ``"+,+"``, ``"+,-"``, ``"-,+"``, ``"-,-"`` (empty without torque).
        torque_range: Smallest and largest torque [N m] (None without torque).
        torque_reversals_at_rest: Sign changes of the torque while holding still: the command still if
            the log has one, else ``|dq| < v_hold`` (hysteresis ``tau_threshold``).
        torque_reversals: Sign changes of the torque anywhere (same hysteresis).
        loaded_motion: Fraction of the moving samples with ``|tau|`` above 30 % of its peak.
        velocity_range: Smallest and largest velocity [rad/s].
        position_range: Smallest and largest position [rad] (None without position).
        period: Sample period [s] (None without time).
        period_jitter: Robust spread of the time steps [periods] (:func:`period_jitter`).
        position_gap: Largest stretch [rad] of the positions sampled where a function of the position is known
            only from one or two samples (:func:`position_coverage`; None without position).
        position_dense: Longest stretch [rad] of the positions sampled densely (:func:`position_coverage`; None
            without position).
        unit_doubts: Values implausible in the role's unit (:func:`unit_doubts`).
        faults: What makes the log unfit to test any effect (a position that never changes, or is mostly noise).
        velocity_noise: Noise floor of ``dq`` [rad/s] (:func:`noise_floor`).
        v_peak: Peak speed [rad/s] (``PEAK_QUANTILE`` of ``|dq|``).
        v_hold, v_move, v_fast: Thresholds of holding still, moving and fast motion [rad/s], from the two above.
        torque_noise: Noise floor of the torque [N m] (of the raw column when the log's torque was smoothed).
        tau_threshold: Hysteresis of the torque's sign changes [N m].
    """

    duration: float
    n_samples: int
    velocity_reversals: int
    hold_time: float
    slow_time: float
    fast_time: float
    quadrants: dict[str, float]
    torque_range: tuple[float, float] | None
    torque_reversals_at_rest: int
    torque_reversals: int
    loaded_motion: float
    velocity_range: tuple[float, float]
    position_range: tuple[float, float] | None
    period: float | None = None
    velocity_noise: float = 0.0
    v_peak: float = 0.0
    v_hold: float = 0.0
    v_move: float = 0.0
    v_fast: float = 0.0
    torque_noise: float | None = None
    tau_threshold: float | None = None
    period_jitter: float = 0.0
    position_gap: float | None = None
    position_dense: float | None = None
    unit_doubts: tuple[str, ...] = ()
    faults: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return asdict(self)

    @property
    def min_span(self) -> float:
        """[s] Shortest slow, fast or held motion an effect that needs it accepts (``MIN_SPAN`` samples); 0 without
        a period, when the times of motion are 0 too (no span is measured, none is refused)."""
        return MIN_SPAN * (self.period or 0.0)

    def lines(self) -> list[str]:
        """Human-readable summary, one fact per line."""
        out = [
            f"duration {self.duration:.1f} s, {self.n_samples} samples"
            + (f", period {1e3 * self.period:.3g} ms" if self.period else ""),
            f"velocity: peak {self.v_peak:.3g} rad/s ({100 * PEAK_QUANTILE:.0f} % of |dq|), noise floor "
            f"{self.velocity_noise:.2g} rad/s; thresholds hold < {self.v_hold:.2g}, moving > {self.v_move:.2g}, "
            f"fast > {self.v_fast:.2g} rad/s",
            f"velocity reversals: {self.velocity_reversals} (moves faster than {self.v_move:.2g} rad/s)",
            f"hold {self.hold_time:.1f} s, slow motion {self.slow_time:.1f} s, fast motion {self.fast_time:.1f} s",
            f"velocity range [{self.velocity_range[0]:.3g}, {self.velocity_range[1]:.3g}] rad/s",
        ]
        if self.torque_range is not None:
            quad = ", ".join(f"{k}: {100 * v:.0f} %" for k, v in self.quadrants.items())
            out += [
                f"torque range [{self.torque_range[0]:.3g}, {self.torque_range[1]:.3g}] N m, noise floor "
                f"{self.torque_noise:.2g} N m; {self.torque_reversals} sign changes beyond "
                f"+-{self.tau_threshold:.2g} N m, {self.torque_reversals_at_rest} at rest",
                f"quadrants (velocity sign, torque sign) of moving samples: {quad}",
                f"loaded motion (|tau| > 30 % of its peak while moving): {100 * self.loaded_motion:.0f} %",
            ]
        if self.position_range is not None:
            line = f"position range [{self.position_range[0]:.4g}, {self.position_range[1]:.4g}] rad"
            if self.position_gap is not None and self.position_dense is not None:
                line += (f", largest stretch sampled fewer than {VISITS} times per {100 / POSITION_BINS:g} % of the "
                         f"range {self.position_gap:.3g} rad, longest sampled more often {self.position_dense:.3g} rad")
            out.append(line)
        if self.period_jitter > 0.0:
            out.append(f"time steps jitter by {100 * self.period_jitter:.0f} % of the period (robust spread)")
        out += [f"units doubted: {d}" for d in self.unit_doubts] + [f"fault: {f}" for f in self.faults]
        return out


def noise_floor(x: np.ndarray, difference: int = 2) -> float:
    """White-noise standard deviation of ``x`` from its high-frequency part: the robust spread (1.4826 times the
    median absolute value) of its ``difference``-th difference over the root of that difference's white-noise gain
    (``binom(2 k, k)``: 6 for the second, 70 for the fourth); a smooth motion hardly contributes, and less with a
    higher difference (a 2 Hz, 0.5 rad sine at 20 ms: 13 mrad with the second, 0.2 mrad with the fourth). 0 for
    fewer than ``difference + 1`` samples or a quantised signal that mostly holds still."""
    x = np.asarray(x, dtype=np.float64)
    if x.size <= difference:
        return 0.0
    return float(1.4826 * np.median(np.abs(np.diff(x, difference))) / math.sqrt(math.comb(2 * difference, difference)))


def period_jitter(t: np.ndarray, period: float) -> tuple[float, float]:
    """``(spread, largest)``: the robust spread (1.4826 times the median) and the largest of ``|step / period - 1|``
    over the time steps of ``t`` [s] that are not gaps (at most ``GAP`` periods)."""
    steps = np.diff(np.asarray(t, dtype=np.float64))
    dev = np.abs(steps[steps <= GAP * period] / period - 1.0)
    if dev.size == 0:
        return 0.0, 0.0
    return 1.4826 * float(np.median(dev)), float(dev.max())


def unit_doubts(q: np.ndarray | None, error: np.ndarray | None, tau: np.ndarray | None, period: float | None = None,
                dq: np.ndarray | None = None, torque_target: np.ndarray | None = None) -> list[str]:
    """Values implausible in the unit their role expects: a position ``q`` [rad] over ``TURNS`` turns, a servo
    error ``q_des - q`` [rad] beyond ``MAX_ERROR``, a torque ``tau`` or a torque target (a friction column) beyond
    ``MAX_TORQUE`` [N m], a velocity ``dq`` beyond ``MAX_SPEED`` [rad/s] (each its 99th percentile or range), a
    sample ``period`` beyond ``MAX_PERIOD`` [s]; each doubt names the value measured and the bound."""
    out = []
    if period is not None and period > MAX_PERIOD:
        out.append(f"the sample period is {period:.4g} s (more than {MAX_PERIOD:g} s): expected the time in [s] (a "
                   "servo log is sampled every 0.5 to 100 ms); milliseconds, or a sample index? (convert the column)")
    if q is not None and q.size and np.ptp(q) > TURNS * 2 * np.pi:
        out.append(f"the position spans {np.ptp(q):.4g} rad ({np.ptp(q) / (2 * np.pi):.3g} turns, more than "
                   f"{TURNS:g}): expected [rad]; degrees? (convert the column)")
    if error is not None and error.size:
        e = float(np.quantile(np.abs(error), PEAK_QUANTILE))
        if e > MAX_ERROR:
            out.append(f"the servo error q_des - q reaches {e:.4g} rad ({100 * PEAK_QUANTILE:.0f} % of |error|, "
                       f"more than {MAX_ERROR:g} rad): expected [rad]; degrees? (convert the columns)")
    if dq is not None and dq.size:
        v = float(np.quantile(np.abs(dq), PEAK_QUANTILE))
        if v > MAX_SPEED:
            out.append(f"the velocity reaches {v:.4g} rad/s ({100 * PEAK_QUANTILE:.0f} % of |dq|, more than "
                       f"{MAX_SPEED:g} rad/s): expected [rad/s] at the joint; deg/s? (convert the column; a motor-side "
                       "velocity: divide it by the gear ratio)")
    for what, x in (("torque", tau), ("torque target", torque_target)):
        if x is not None and x.size:
            m = float(np.quantile(np.abs(x), PEAK_QUANTILE))
            if m > MAX_TORQUE:
                out.append(f"the {what} reaches {m:.4g} ({100 * PEAK_QUANTILE:.0f} % of its magnitude, more than "
                           f"{MAX_TORQUE:g} N m): expected [N m]; mN m? (convert the column)")
    return out


def position_noise_fault(q: np.ndarray | None) -> str | None:
    """Why the position ``q`` [rad] is unfit to learn from when it is mostly noise (``NOISY_POSITION``); else None."""
    if q is None or q.size < 3:
        return None
    spread = float(np.std(q))
    floor = noise_floor(q)
    if spread > 0 and floor > NOISY_POSITION * spread:
        return (f"the position is mostly noise (its sample-to-sample noise floor {floor:.3g} rad is "
                f"{100 * floor / spread:.0f} % of its standard deviation {spread:.3g} rad, more than "
                f"{100 * NOISY_POSITION:.0f} %): not the joint's angle, or no motion to learn from")
    return None


POSITION_BINS = 100  # bins of the position range (its 1 % to 99 % quantiles) of position_coverage
VISITS = 3  # samples in a bin where a function of the position is known


def _visited(q: np.ndarray) -> tuple[np.ndarray, float]:
    """Whether each of ``POSITION_BINS`` bins of the position range holds ``VISITS`` samples, and the bin width
    [rad] (0 when the range is empty)."""
    lo, hi = np.quantile(q, (0.01, 0.99))
    if hi <= lo:
        return np.ones(POSITION_BINS, dtype=bool), 0.0
    counts, _ = np.histogram(q, bins=POSITION_BINS, range=(lo, hi))
    return counts >= VISITS, float((hi - lo) / POSITION_BINS)


def _longest_run(flags: np.ndarray) -> int:
    run = longest = 0
    for f in flags:
        run = run + 1 if f else 0
        longest = max(longest, run)
    return longest


def position_coverage(q: np.ndarray) -> tuple[float, float]:
    """``(gap, dense)`` [rad] of the position range, from one histogram: the largest stretch without a bin visited by
    ``VISITS`` samples (where a function of the position is known only from a sample or two), and the longest
    stretch whose every bin is (where it is known densely)."""
    visited, width = _visited(q)
    sparse = _longest_run(~visited)
    return ((sparse + 1) * width if sparse else 0.0), _longest_run(visited) * width


def _reversals(x: np.ndarray, threshold: float) -> int:
    """Sign changes of ``x`` counting only excursions beyond ``threshold``."""
    s = np.where(x > threshold, 1, np.where(x < -threshold, -1, 0))
    s = s[s != 0]
    return int(np.count_nonzero(np.diff(s))) if s.size else 0


def speed_thresholds(dq: np.ndarray) -> tuple[float, float, float, float, float]:
    """``(noise floor, peak, v_hold, v_move, v_fast)`` [rad/s] of one log's velocity (see the module doc)."""
    noise = noise_floor(dq)
    peak = float(np.quantile(np.abs(dq), PEAK_QUANTILE)) if len(dq) else 0.0
    v_hold = max(NOISE_MULTIPLE * noise, HOLD_FRACTION * peak)
    v_move = max(2.0 * v_hold, MOVE_FRACTION * peak)
    v_fast = max(2.0 * v_move, FAST_FRACTION * peak)
    return noise, peak, v_hold, v_move, v_fast


def excitation_report(signals: Signals, torque_target: np.ndarray | None = None) -> Excitation:
    """What ``signals`` exercised (``dq`` required, ``tau`` / ``tau_raw`` / ``q`` / ``q_des`` / ``t`` used when
    present; ``tau_raw`` is the unsmoothed torque whose noise floor sets the torque's hysteresis); a
    ``torque_target`` [N m] (a friction column the model predicts) is checked for its unit too."""
    dq = np.asarray(signals["dq"], dtype=np.float64)
    n = len(dq)
    period = signals.dt
    dt = period or 0.0
    speed = np.abs(dq)
    noise_v, peak_v, v_hold, v_move, v_fast = speed_thresholds(dq)
    hold = speed < v_hold
    moving = speed > v_move
    tau = signals["tau"] if "tau" in signals else None
    quadrants: dict[str, float] = {}
    torque_range = torque_noise = tau_threshold = None
    rest_rev = rev = 0
    loaded = 0.0
    if tau is not None:
        torque_range = (float(tau.min()), float(tau.max()))
        torque_noise = noise_floor(signals["tau_raw"] if "tau_raw" in signals else tau)
        peak = float(np.quantile(np.abs(tau), PEAK_QUANTILE)) or float(np.max(np.abs(tau))) or 1.0
        tau_threshold = max(TORQUE_HYSTERESIS * peak, NOISE_MULTIPLE * torque_noise)
        m = max(int(moving.sum()), 1)
        for sv, sn in ((1, "+"), (-1, "-")):
            for st, tn in ((1, "+"), (-1, "-")):
                sel = moving & (np.sign(dq) == sv) & (np.sign(tau) == st)
                quadrants[f"{sn},{tn}"] = float(np.count_nonzero(sel) / m)
        rev = _reversals(tau, tau_threshold)
        still = hold
        if "q_des" in signals:  # a hold is where the command holds still (the joint may creep in a dead band)
            still = np.abs(np.gradient(signals["q_des"])) < 1e-12
        rest_rev = _count_rest_reversals(tau, still, tau_threshold)
        loaded = float(np.count_nonzero(moving & (np.abs(tau) > 0.3 * peak)) / m)
    q = signals["q"] if "q" in signals else None
    gap, dense = (None, None) if q is None or q.size < 3 else position_coverage(q)
    jitter = period_jitter(signals["t"], period)[0] if period and "t" in signals else 0.0
    error = signals["q_des"] - q if q is not None and "q_des" in signals else None
    doubts = unit_doubts(q, error, signals["tau_raw"] if "tau_raw" in signals else tau, period, dq, torque_target)
    if q is not None and q.size and np.ptp(q) == 0.0:
        fault = f"the position never changes (= {q[0]:.6g} rad): the joint never moved"
    else:
        fault = position_noise_fault(q)
    return Excitation(
        duration=float(n * dt),
        n_samples=n,
        velocity_reversals=_reversals(dq, v_move),
        hold_time=float(hold.sum() * dt),
        slow_time=float(np.count_nonzero(~hold & (speed < v_fast)) * dt),
        fast_time=float(np.count_nonzero(speed > v_fast) * dt),
        quadrants=quadrants,
        torque_range=torque_range,
        torque_reversals_at_rest=rest_rev,
        torque_reversals=rev,
        loaded_motion=loaded,
        velocity_range=(float(dq.min()), float(dq.max())),
        position_range=None if q is None else (float(q.min()), float(q.max())),
        period=period,
        velocity_noise=noise_v,
        v_peak=peak_v,
        v_hold=v_hold,
        v_move=v_move,
        v_fast=v_fast,
        torque_noise=torque_noise,
        tau_threshold=tau_threshold,
        period_jitter=jitter,
        position_gap=gap,
        position_dense=dense,
        unit_doubts=tuple(doubts),
        faults=(fault,) if fault else (),
    )


def _count_rest_reversals(tau: np.ndarray, hold: np.ndarray, threshold: float) -> int:
    """Torque sign changes inside runs of holding still."""
    count = 0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], hold.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        count += _reversals(tau[a:b], threshold)
    return count


# -- what the sample period resolves -------------------------------------------------------------------
def shortest(key: str, period: float | None) -> float:
    """[s] Shortest value of the time parameter ``key`` of a shape that a log sampled every ``period`` resolves:
    ``SG_MIN - 0.5`` periods for an acceleration ``window`` (a shorter one would be clamped to
    :data:`~.signals.SG_MIN` samples), ``RESOLVE_PERIODS`` periods otherwise (0 without a period)."""
    if not period:
        return 0.0
    return (SG_MIN - 0.5) * period if key == "window" else RESOLVE_PERIODS * period


def resolvable(shape: Mapping[str, float], keys: Iterable[str], period: float | None) -> bool:
    """Every time parameter of ``shape`` named in ``keys`` is 0 (none) or resolved at ``period`` [s]."""
    return all(shape[k] == 0.0 or shape[k] >= shortest(k, period) for k in keys if k in shape)


@dataclass(frozen=True)
class ResolvedGrid:
    """An effect's grid restricted to the shapes the log's sample period resolves (:func:`resolvable`): called
    with the signals, the shapes whose time parameters ``keys`` [s] are at least :func:`shortest`. A shape whose
    time parameters are all 0 (``motor_lag``'s derivative form, ``delay``'s velocity form) comes with the resolved
    ones (unless ``zero_alone``): it stands for lags shorter than they are, which the log resolves no better. When
    no shape with a positive time parameter is resolved: those zero forms alone, or the whole grid if there are
    none (the effect's ``needs`` then says it cannot be told, see :func:`lag_resolved`)."""

    shapes: tuple[Mapping[str, float], ...]
    keys: tuple[str, ...]
    zero_alone: bool = False
    """The zero forms come only where no shape with a positive time parameter is resolved (``delay``'s velocity
    form: beside a resolved delay it is a second look-alike of the command's velocity, which fits a derivative's
    error on a clean log)."""

    def _timed(self, shape: Mapping[str, float]) -> bool:
        """``shape`` has a positive time parameter (it is not a zero form)."""
        return any(shape.get(k, 0.0) > 0.0 for k in self.keys)

    def resolves(self, period: float | None) -> bool:
        """A shape with a positive time parameter is resolved at ``period`` [s]."""
        return any(resolvable(g, self.keys, period) and self._timed(g) for g in self.shapes)

    def __call__(self, signals: Signals) -> tuple[Mapping[str, float], ...]:
        if not self.resolves(signals.dt):
            return tuple(g for g in self.shapes if not self._timed(g)) or self.shapes
        out = tuple(g for g in self.shapes if resolvable(g, self.keys, signals.dt))
        return tuple(g for g in out if self._timed(g)) if self.zero_alone else out


def steady_timing(e: Excitation, what: str) -> str | None:
    """Why the log's timing cannot resolve a ``what`` (e.g. "delay") at all, or None: time steps that jitter by
    more than ``JITTER_TOL``."""
    if e.period_jitter > JITTER_TOL:
        return (f"cannot tell: the time steps jitter by {100 * e.period_jitter:.0f} % of the period (more than "
                f"{100 * JITTER_TOL:.0f} %): the timing cannot resolve a {what}")
    return None


def lag_resolved(e: Excitation, grid: ResolvedGrid, what: str) -> str | None:
    """Why the log's timing resolves no shape of ``grid`` (``what``: e.g. "time constant"), or None: time steps
    that jitter (:func:`steady_timing`), or a sample period longer than every shape allows."""
    if reason := steady_timing(e, what):
        return reason
    if grid.resolves(e.period):
        return None
    ranges = []
    for k in grid.keys:
        values = sorted({g[k] for g in grid.shapes if g.get(k, 0.0) > 0.0})
        if values:
            ranges.append(f"{k} {1e3 * values[0]:.3g}-{1e3 * values[-1]:.3g} ms (needs >= "
                          f"{1e3 * shortest(k, e.period):.3g} ms)")
    return (f"cannot tell: the sample period {1e3 * (e.period or 0.0):.3g} ms resolves no {what} of the grid: "
            + "; ".join(ranges))


# -- requirements shared by several effects: a reason string when the data cannot test the effect ------
def units_plausible(e: Excitation) -> str | None:
    """A joint that moved, and values plausible in the units the roles expect (every effect's shapes are in rad,
    rad/s and N m)."""
    if e.faults:
        return "cannot tell: " + "; ".join(e.faults)
    if e.unit_doubts:
        return "cannot tell: units doubted: " + "; ".join(e.unit_doubts)
    return None


def both_directions(e: Excitation) -> str | None:
    """Motion in both directions (at least two velocity reversals beyond the log's move threshold)."""
    if e.velocity_reversals < 2:
        lo, hi = e.velocity_range
        where = " (the velocity never crosses zero)" if lo > 0.0 or hi < 0.0 else ""
        return (f"only {e.velocity_reversals} velocity reversals beyond +-{e.v_move:.2g} rad/s "
                f"(velocity range [{lo:.3g}, {hi:.3g}] rad/s{where}): expected motion in both directions (>= 2)")
    return None


def has_torque(e: Excitation) -> str | None:
    """A torque column."""
    return "no torque column" if e.torque_range is None else None


def fast_motion(e: Excitation) -> str | None:
    """Fast motion (the dynamics effects): at least ``MIN_SPAN`` samples above the log's fast threshold."""
    if e.fast_time < e.min_span:
        return (f"fast motion {e.fast_time:.2g} s (|dq| > {e.v_fast:.2g} rad/s: half the peak {e.v_peak:.2g} "
                f"rad/s, above the noise floor {e.velocity_noise:.2g} rad/s): expected >= {e.min_span:.2g} s "
                f"({MIN_SPAN} samples)")
    return None


def slow_motion(e: Excitation) -> str | None:
    """Slow motion: at least ``MIN_SPAN`` samples between the log's hold and fast thresholds."""
    if e.slow_time < e.min_span:
        return (f"slow motion {e.slow_time:.2g} s ({e.v_hold:.2g} to {e.v_fast:.2g} rad/s): expected >= "
                f"{e.min_span:.2g} s ({MIN_SPAN} samples)")
    return None


def slow_and_fast(e: Excitation) -> str | None:
    """Slow and fast motion: at least ``MIN_SPAN`` samples of each."""
    if e.slow_time < e.min_span or e.fast_time < e.min_span:
        return (f"slow motion {e.slow_time:.2g} s ({e.v_hold:.2g} to {e.v_fast:.2g} rad/s), fast motion "
                f"{e.fast_time:.2g} s (> {e.v_fast:.2g} rad/s): expected >= {e.min_span:.2g} s ({MIN_SPAN} "
                "samples) of each")
    return None


def held(e: Excitation) -> str | None:
    """Holding still: at least ``MIN_SPAN`` samples below the log's hold threshold."""
    if e.hold_time < e.min_span:
        return (f"hold time {e.hold_time:.2g} s (|dq| < {e.v_hold:.2g} rad/s, {NOISE_MULTIPLE:g} x the noise floor "
                f"or {100 * HOLD_FRACTION:g} % of the peak): expected >= {e.min_span:.2g} s ({MIN_SPAN} samples)")
    return None
