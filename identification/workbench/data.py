"""Load a log table (Parquet, CSV or in-memory columns) into a :class:`Dataset` for the workbench.

Three layouts are recognised, in this order:

1. An explicit mapping of column roles (``roles={"target": "friction", "velocity": "v"}``): any table,
   e.g. a friction torque against velocity from another robot. Roles: ``target`` (what the model
   predicts), or ``command`` and ``position`` (then ``target = command - position``); ``torque``,
   ``velocity``, ``position``, ``time``, ``segment`` (held-out blocks of the cross-validation),
   ``acceleration``.
2. servotau's own logs (one row per tick): ``t``, ``q/<joint>``, ``q_des/<joint>``,
   ``est/tau/<joint>``, optional ``est/dq/<joint>``; pick the joint with ``joint`` (optional when the
   log has one joint). A Parquet log without ``est/tau/<joint>`` (``servotau identify collect`` writes
   the sensors, not estimates) gets the off-line estimator's torque and velocity, as
   ``servotau identify fit`` does (the data layer's ``load_aligned``: centred filters, F/T calibration,
   RNEA, the torque aligned with the command it answers). The simulator's ground truth (``true/*``) is never
   taken on its own: map it explicitly (``roles={"torque": "true/tau/<joint>"}``) to study the model
   without estimation error.
3. A single-joint table: ``t`` [s], ``q`` [rad], ``q_des`` [rad], ``tau`` [N m], optional ``dq``
   [rad/s] and ``segment``.

Then ``target = q_des - q`` [rad]. With a velocity column, ``dq`` is the log's own (said in the notes).
Without one, ``dq`` is the centred Savitzky-Golay derivative of ``q``, computed on each run of
valid samples, with a window and a polynomial order chosen from the data, never fixed milliseconds
(:func:`cv_derivative`: of orders 2 and 4, each with its window from :func:`cv_window`, the odd sample count whose
leave-one-out SG smoother best predicts each held-out encoder sample, between ``MIN_WINDOW`` samples and a bound
from the log length, the order whose smoother predicts better); ``ddq`` likewise (order 3 or the chosen one,
twice the window).
The torque is smoothed by a centred SG filter (order 2: no delay), its window chosen the same way from
the torque's own noise. The notes give the source and window (samples and seconds) of each. Windows are in
samples of the median time step; time steps longer than ``RUN_GAP`` periods end a run (filters do not
cross them) and are counted in the notes. Rows with NaN or inf in a used column are dropped and counted.

Bad input gets a note, never a silent guess: jittered time stamps are treated as uniform (the filters assume
the median period) and the note gives the jitter measured (robust spread of the steps, and the largest); beyond
``JITTER_TOL`` the lag-like effects cannot be told (:mod:`~servotau.actuator.excitation`). A constant column is
named; a constant torque, velocity or acceleration carries no information and is not used (the velocity is then
differentiated from ``q``). Values implausible in the unit the role expects
(:func:`~servotau.actuator.excitation.unit_doubts`:
a position over several turns, a servo error over half a turn, a torque or friction target over kN m, a velocity
over 50 rad/s, a sample period over 0.5 s) are noted; the diagnosis then cannot tell the effects that read them
(:func:`excitation_of`).
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from servotau.actuator.excitation import JITTER_TOL, Excitation, excitation_report, period_jitter, unit_doubts
from servotau.actuator.signals import Signals, per_run
from servotau.errors import IdentificationError

from ..data import read_table, resolve_roles, segments, shift, table_columns
from ..data.tables import servotau_joints
from .filters import cv_derivative, cv_window, differentiate
from .resolution import encoder_resolution, quantisation_floor

__all__ = ["MIN_SAMPLES", "OFFLINE_ESTIMATE", "TORQUE_COLUMN", "Dataset", "FilterPart", "align_torque", "describe",
           "excitation_of", "load_dataset", "windows_text"]

log = logging.getLogger(__name__)
OFFLINE_ESTIMATE = "off-line estimates from the log's sensors"  # in the note of a log estimated here (layout 2)
MIN_SAMPLES = 200
MAX_MAGNITUDE = 1e100  # a larger value overflows in the products of the fits (1e200 squared); no unit gives it
PERIOD_JUMPS = 0.05  # fraction of long time steps beyond which the period jumps (the log is resampled)
TORQUE_COLUMN = re.compile(r"tau|torque|friction|effort|trq", re.IGNORECASE)
"""A target column whose name matches holds a torque or friction [N m]; any other target's unit is the user's."""
RUN_GAP = 1.5  # [periods] a longer time step ends a run of samples (filters do not cross it)
_SIGNAL_OF_ROLE = {"position": "q", "command": "q_des", "torque": "tau", "velocity": "dq", "acceleration": "ddq",
                   "time": "t"}


@dataclass(frozen=True)
class FilterPart:
    """The centred Savitzky-Golay filter one recording's derived signal went through: rows ``first`` to ``end``
    (exclusive), ``window`` [samples], sample ``period`` [s], polynomial ``order``."""

    first: int
    end: int
    window: int
    period: float
    order: int


@dataclass(frozen=True, eq=False)
class Dataset:
    """One joint's samples, ready for fitting.

    Attributes:
        signals: :class:`Signals` (``t``, ``q``, ``q_des``, ``tau``, ``dq``, ``ddq`` where available, and
            every numeric column of the table under its own name).
        target: What the model predicts, ``q_des - q`` [rad] for actuator logs.
        segment: Segment label per sample (blocks of the cross-validation), or None.
        roles: Column used for each role.
        source: Where the data came from (file name or "table").
        joint: Joint name, or None.
        n_dropped: Rows dropped for NaN or inf.
        notes: What was derived (e.g. "dq: centred Savitzky-Golay derivative of q"), and what looked wrong
            (jitter, gaps, constant columns, implausible units).
        preprocessing: Per derived signal (``dq``, ``tau``): ``source`` ("log", "derivative of q",
            "smoothed") and, when filtered, ``window`` [samples] and ``seconds``; ``q``: the encoder's
            ``resolution`` [rad] when the angles sit on a lattice (:mod:`.resolution`). A joined log
            (:func:`~.recordings.combine`) adds ``windows``: per recording ``(first row, window [samples], period
            [s])``; ``window`` is then the recordings' common window, or the windows as text ("15 and 9",
            :func:`windows_text`) when they differ ("seconds" only when common).
    """

    signals: Signals
    target: np.ndarray
    segment: np.ndarray | None
    roles: Mapping[str, str]
    source: str
    joint: str | None = None
    n_dropped: int = 0
    notes: tuple[str, ...] = field(default_factory=tuple)
    preprocessing: Mapping[str, Mapping] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.target)

    @property
    def dt(self) -> float | None:
        return self.signals.dt

    @property
    def has_torque(self) -> bool:
        return "tau" in self.signals

    @property
    def actuator(self) -> bool:
        """The target is the paper's ``q_des - q`` (the model can be saved as a motor model)."""
        return "command" in self.roles and "position" in self.roles

    def filter_parts(self, key: str = "dq") -> list[FilterPart]:
        """The filter of each recording whose ``key`` (``dq``: the velocity, ``tau``: the torque) was filtered here,
        from :attr:`preprocessing` (one part for a single log; order 2 when unsaid)."""
        info = self.preprocessing[key]
        parts = info.get("windows", ((0, info["window"], self.dt),))
        ends = [a for a, _, _ in parts[1:]] + [self.n]
        orders = info.get("orders", (info.get("order", 2),) * len(parts))
        return [FilterPart(a, b, w, dt, o) for (a, w, dt), b, o in zip(parts, ends, orders, strict=True)]

    @property
    def time(self) -> np.ndarray:
        """Time [s], or the sample index if the table has none."""
        return self.signals["t"] if "t" in self.signals else np.arange(self.n, dtype=np.float64)


def load_dataset(
    source: str | Path | Mapping[str, np.ndarray] | object,
    *,
    joint: str | None = None,
    roles: Mapping[str, str] | None = None,
    min_samples: int = MIN_SAMPLES,
    smooth_torque_s: float | None = None,
    dq_window: int | None = None,
    dq_order: int | None = None,
    estimator_config=None,
) -> Dataset:
    """Read a log (file path, pyarrow Table or mapping of columns) into a :class:`Dataset`.

    Args:
        source: The log.
        joint: Joint of a servotau log (optional if it has one joint).
        roles: Column of each role (see the module doc), overriding the recognised layout.
        min_samples: Fewest valid samples accepted.
        smooth_torque_s: Window [s] of the centred SG smoothing of the torque (0: none; None: chosen
            from the torque's noise by :func:`cv_window`). A torque estimate is noisy; without smoothing,
            any term that averages neighbouring samples (a lag, a delay) would win by denoising it.
        dq_window: SG window [samples, odd] of the velocity when the log has no velocity column (None:
            chosen with its order from the encoder by :func:`cv_derivative`).
        dq_order: Polynomial order of that derivative (None: chosen with the window, or 2 with a given window).
        estimator_config: The off-line estimator's :class:`~servotau.estimation.EstimatorConfig` for a servotau
            log without an estimate (default: the packaged estimation.toml).

    Raises:
        IdentificationError: Missing or unknown column, unknown joint, too few samples, time not
            increasing, velocity needed but no time column, or ``smooth_torque_s`` not >= 0: the message names
            the column (or argument) and what was expected.
    """
    if smooth_torque_s is not None and not (math.isfinite(smooth_torque_s) and smooth_torque_s >= 0):
        raise IdentificationError(f"smooth_torque_s = {smooth_torque_s!r}: expected a window >= 0 s (0: no smoothing)")
    if isinstance(source, (str, Path)):
        columns = read_table(source)
        name = str(source)
        columns, estimated = _with_estimates(Path(source), columns, joint, roles, estimator_config)
    else:
        estimated = None
        columns = table_columns(source)
        name = "table"
    if not columns:
        raise IdentificationError(f"{name}: no numeric column: expected a table of samples")
    roles, joint = resolve_roles(columns, joint, roles)
    notes = [estimated] if estimated else []
    kept = _drop_constant(columns, dict(roles), notes)
    dropped = {col for role, col in roles.items() if role not in kept}
    roles = kept
    if "time" in roles:
        columns = _uniform(columns, roles, notes)
    used = {role: columns[col] for role, col in roles.items()}
    n_total = len(next(iter(columns.values())))
    if n_total == 0:
        raise IdentificationError(f"{name}: the columns {list(columns)} have no rows: expected a table of samples")
    valid = np.ones(n_total, dtype=bool)
    for role, arr in used.items():
        bad = ~np.isfinite(arr)
        if bad.all():
            raise IdentificationError(f"column '{roles[role]}' (role {role}): all {n_total} values are NaN or inf")
        valid &= ~bad
        peak = float(np.max(np.abs(arr[~bad])))
        if peak > MAX_MAGNITUDE:  # their squares, in every fit's cross products, overflow
            raise IdentificationError(f"column '{roles[role]}' (role {role}): values up to {peak:.3g}: expected "
                                      f"magnitudes below {MAX_MAGNITUDE:.0e} (the units of the column?)")
    n_dropped = int(n_total - valid.sum())
    if n_dropped:
        notes.append(f"dropped {n_dropped} of {n_total} rows with NaN or inf in "
                     f"{sorted(roles[r] for r, a in used.items() if not np.isfinite(a).all())}")
        log.warning("%s: %s", name, notes[-1])
    if valid.sum() < min_samples:
        raise IdentificationError(
            f"{name}: {int(valid.sum())} valid samples (after dropping {n_dropped} rows with NaN or inf): "
            f"expected at least {min_samples}"
        )
    dt = None
    if "time" in roles:
        t = used["time"][valid]
        steps = np.diff(t)
        if np.any(steps <= 0):
            k = int(np.argmax(steps <= 0))
            raise IdentificationError(
                f"column '{roles['time']}' (role time): not increasing at row {k + 1} ({t[k]} -> {t[k + 1]}): "
                "expected strictly increasing time [s]"
                + ("; the same time twice: several joints or recordings in one file? (split it, one per file)"
                   if steps[k] == 0 else "")
            )
        dt = float(np.median(steps))
    runs = segments(used["time"] if "time" in roles else None, dt, valid=valid, max_gap=RUN_GAP)
    if "time" in roles and dt is not None:
        jumps = int(np.sum(np.diff(used["time"][valid]) > RUN_GAP * dt))
        if jumps:
            notes.append(f"time: {jumps} steps longer than {RUN_GAP} x the median period {1e3 * dt:.3g} ms "
                         "(filters restart there)")
        jitter = _jitter_note(used["time"][valid], dt)
        if jitter:
            notes.append(jitter)
    if "velocity" not in roles:
        if "position" not in roles:
            raise IdentificationError("no velocity: expected a velocity column or a position column to differentiate")
        if dt is None:
            raise IdentificationError("no velocity column and no time column: expected 't' [s] to differentiate q")
    sig: dict = {}
    for role, arr in used.items():
        if role in _SIGNAL_OF_ROLE:
            sig[_SIGNAL_OF_ROLE[role]] = arr[valid]
    if "acceleration" in roles:
        sig["ddq_est"] = sig["ddq"]  # the log's own acceleration replaces the filtered one of the effects
    wq, oq = None, 2
    prep: dict[str, dict] = {}
    if "position" in roles and dt is not None and not {"velocity", "acceleration"} <= set(roles):
        if dq_window is not None:
            wq, oq = dq_window, 2 if dq_order is None else dq_order
        elif dq_order is not None:
            wq, oq = cv_window(used["position"], runs, dq_order), dq_order
        else:
            wq, oq = cv_derivative(used["position"], runs)
    if "velocity" in roles:
        notes.append(f"dq: the log's own velocity column '{roles['velocity']}'")
        prep["dq"] = {"source": "log", "column": roles["velocity"]}
    else:
        w = wq
        sig["dq"] = differentiate(used["position"], runs, dt, 1, w, oq)[valid]
        how = "chosen by cross-validation on the encoder" if dq_window is None else "given"
        prep["dq"] = {"source": "derivative of q", "window": int(w), "seconds": float(w * dt), "order": oq,
                      "chosen": "cross-validation" if dq_window is None else "given"}
        notes.append(f"dq: centred Savitzky-Golay derivative of q ({w} samples = {1e3 * w * dt:.3g} ms, order {oq}, "
                     f"{how})")
    if "acceleration" not in roles and "position" in roles and dt is not None:
        pos = used["position"]
        w2, o2 = 2 * wq - 1, max(oq, 3)
        sig["ddq"] = lambda: differentiate(pos, runs, dt, 2, w2, o2)[valid]
    if "torque" in roles and smooth_torque_s != 0 and dt is not None:
        if smooth_torque_s is None:
            wt = cv_window(used["torque"], runs, 2)
            how = "chosen by cross-validation on the torque's noise"
        else:
            wt = _window(smooth_torque_s, dt)
            how = "given"
        sig["tau_raw"] = sig["tau"]  # its noise floor scales the excitation's torque thresholds
        sig["tau"] = differentiate(used["torque"], runs, dt, 0, wt)[valid]
        prep["tau"] = {"source": "smoothed", "window": int(wt), "seconds": float(wt * dt), "order": 2,
                       "chosen": "cross-validation" if smooth_torque_s is None else "given"}
        notes.append(f"tau: centred Savitzky-Golay smoothing ({wt} samples = {1e3 * wt * dt:.3g} ms, order 2, "
                     f"no delay, {how})")
    res = encoder_resolution(sig["q"]) if "q" in sig else 0.0
    if res > 0:
        prep["q"] = {"source": "log", "resolution": res}
        notes.append(f"q: quantised to {res:.3g} rad (the encoder's resolution; effects within its rounding error, "
                     f"{1e6 * quantisation_floor(res):.3g} urad RMS, are not named)")
    if "target" in roles:
        target = used["target"][valid]
    else:
        target = used["command"][valid] - used["position"][valid]
    for col, arr in columns.items():
        if col not in sig and col not in dropped:
            sig[col] = arr[valid]
    n = int(valid.sum())
    segment = used["segment"][valid] if "segment" in roles else None
    torque = target if _torque_target(roles) else None
    for doubt in unit_doubts(sig.get("q"), target if "command" in roles else None, sig.get("tau_raw", sig.get("tau")),
                             dt, sig.get("dq"), torque):
        notes.append(f"units: {doubt}")
        log.warning("%s: %s", name, doubt)
    starts = np.searchsorted(np.flatnonzero(valid), [a for a, _ in runs])  # the runs, in rows kept
    return Dataset(Signals(sig, dt, n, starts=starts), target, segment, roles, name, joint, n_dropped, tuple(notes),
                   prep)


def _torque_target(roles: Mapping[str, str]) -> bool:
    """The target is a column holding a torque or a friction [N m] (by its name, ``TORQUE_COLUMN``)."""
    return "target" in roles and TORQUE_COLUMN.search(roles["target"]) is not None


def excitation_of(ds: Dataset) -> Excitation:
    """What the log ``ds`` exercised (:func:`~servotau.actuator.excitation_report`), its torque or friction target
    checked for its unit too."""
    torque = ds.target if _torque_target(ds.roles) else None
    return excitation_report(ds.signals, torque)


def windows_text(windows: list[int]) -> str:
    """Windows [samples] of the recordings as text: "15 and 9", "15, 9 and 9"."""
    return str(windows[0]) if len(windows) == 1 else ", ".join(map(str, windows[:-1])) + f" and {windows[-1]}"


def _with_estimates(path: Path, columns: dict[str, np.ndarray], joint: str | None,
                    roles: Mapping[str, str] | None, estimator_config=None) -> tuple[dict[str, np.ndarray], str | None]:
    """``columns`` plus ``est/tau/<joint>`` and ``est/dq/<joint>`` from the off-line estimator, for a
    servotau Parquet log that has sensors but no estimate of the joint (module doc, layout 2); and a
    note saying so (None when nothing was added)."""
    joints = servotau_joints(columns)
    if not joints or {"target", "command", "torque"} & set(roles or {}) or "imu/gyro_x" not in columns:
        return columns, None
    if joint is None and len(joints) == 1:
        joint = joints[0]
    if joint not in joints or f"est/tau/{joint}" in columns:
        return columns, None  # resolve_roles says what is wrong, or the log has its estimate
    from ..data import load_aligned

    log.info("%s: no est/tau/%s: estimating it off-line from the sensors", path, joint)
    s = load_aligned(path, [joint], estimator_config=estimator_config).samples[joint]
    note = (f"est/tau/{joint}, est/dq/{joint}: {OFFLINE_ESTIMATE} (identification/data/aligned.py, as "
            "`servotau identify fit`), not the simulator's ground truth")
    return {**columns, f"est/tau/{joint}": s.tau, f"est/dq/{joint}": s.dq}, note


def _drop_constant(columns: Mapping[str, np.ndarray], roles: dict[str, str], notes: list[str]) -> dict[str, str]:
    """``roles`` without a constant torque, velocity or acceleration column (they carry no information; the
    velocity is then differentiated from ``q``); every constant column of a role is noted."""
    for role, col in list(roles.items()):
        if role in ("time", "segment"):
            continue
        x = columns[col][np.isfinite(columns[col])]
        if x.size and np.ptp(x) == 0.0:
            dropped = role in ("torque", "velocity", "acceleration") and (role != "velocity" or "position" in roles)
            notes.append(f"column '{col}' (role {role}) is constant (= {x[0]:.6g}): it carries no information"
                         + ("; not used" if dropped else "; effects that read it cannot be told"))
            log.warning("%s", notes[-1])
            if dropped:
                del roles[role]
    return roles


def _uniform(columns: Mapping[str, np.ndarray], roles: Mapping[str, str], notes: list[str]) -> dict[str, np.ndarray]:
    """``columns`` resampled onto a uniform grid when the sample period jumps (more than ``PERIOD_JUMPS`` of the
    steps are longer than ``RUN_GAP`` median periods, the others within ``JITTER_TOL``: another period, not a few
    gaps nor jitter): the grid's period is the
    90th percentile of the steps (no sample is invented between coarse ones), values linear between the
    neighbouring samples (the segment label: the nearest sample's), grid points farther than a period from every
    sample dropped (the gaps stay gaps). Otherwise ``columns`` unchanged."""
    t = columns[roles["time"]]
    ok = np.isfinite(t)
    steps = np.diff(t[ok])
    if steps.size < 2 or np.any(steps <= 0):
        return dict(columns)  # load_dataset names the fault
    dt = float(np.median(steps))
    long = float(np.mean(steps > RUN_GAP * dt))
    if long <= PERIOD_JUMPS or period_jitter(t[ok], dt)[0] > JITTER_TOL:
        return dict(columns)  # a few gaps, or jitter (noted by load_dataset), not another period
    period = float(np.quantile(steps, 0.9))
    grid = np.arange(t[ok][0], t[ok][-1] + 0.5 * period, period)
    src = t[ok]
    k = np.clip(np.searchsorted(src, grid), 1, len(src) - 1)
    near = np.where(grid - src[k - 1] <= src[k] - grid, k - 1, k)
    keep = np.abs(src[near] - grid) <= period
    grid, near = grid[keep], near[keep]
    out = {}
    for col, x in columns.items():
        x = np.asarray(x, dtype=np.float64)[ok]
        out[col] = x[near] if col == roles.get("segment") else np.interp(grid, src, x)
    out[roles["time"]] = grid
    notes.append(f"time: the sample period jumps ({100 * long:.0f} % of the steps are longer than {RUN_GAP} x the "
                 f"median {1e3 * dt:.3g} ms): resampled onto a uniform {1e3 * period:.3g} ms grid (linear "
                 f"interpolation, {len(src)} -> {len(grid)} rows)")
    log.warning("%s", notes[-1])
    return out


def _jitter_note(t: np.ndarray, dt: float) -> str | None:
    """A note on jittered time stamps (steps within ``RUN_GAP`` periods that are not the median period), or None."""
    spread, worst = period_jitter(t, dt)
    if worst < 0.01:
        return None
    how = ("treated as uniform (the filters assume the median period)" if spread <= JITTER_TOL else
           f"more than {100 * JITTER_TOL:.0f} %: treated as uniform, but the lag-like effects cannot be told")
    return (f"time: steps jitter by {100 * spread:.0f} % of the median period {1e3 * dt:.3g} ms (robust spread; "
            f"largest {100 * worst:.0f} %): {how}")


def _window(seconds: float, dt: float) -> int:
    w = max(5, int(round(seconds / dt)))
    return w if w % 2 else w + 1


def describe(ds: Dataset) -> list[str]:
    """Human-readable lines: source, roles, samples, notes."""
    roles = ", ".join(f"{r}={c}" for r, c in ds.roles.items())
    period = f", period {1e3 * ds.dt:.3g} ms" if ds.dt else ""
    head = f"{ds.source}" + (f" joint {ds.joint}" if ds.joint else "")
    return [head, f"{ds.n} samples{period}", f"roles: {roles}", *ds.notes]


def align_torque(ds: Dataset, max_shift_s: float = 0.03) -> tuple[Dataset, float]:
    """Re-time the torque column against the encoders (an estimator's delay) and return the shift [s].

    While the command holds still (at least 10 % of the samples; pushes or loads change the torque
    there), the servo error follows the torque, ``d(dq_err)/dt ~ k_tau dtau/dt``, whatever the servo does
    with a moving command (delay, lag). The shift ``s`` (whole samples in ``[-max_shift_s, max_shift_s]``)
    that best correlates the two derivatives there is applied: ``tau(t + s)``, ``s > 0`` meaning the
    torque column was late. Without such holds nothing is shifted. Samples at the ends of each run hold its
    last value (no torque of another run is read).
    """
    if not ds.has_torque or ds.dt is None or max_shift_s <= 0 or "q_des" not in ds.signals:
        return ds, 0.0
    still = np.abs(np.gradient(ds.signals["q_des"])) < 1e-12
    kmax = int(round(max_shift_s / ds.dt))
    rows = np.flatnonzero(still)
    rows = rows[(rows >= kmax) & (rows < ds.n - kmax)]
    if len(rows) < 0.1 * ds.n:
        return ds, 0.0
    tau = ds.signals["tau"]
    de = np.gradient(ds.target)[rows]
    dtau = np.gradient(tau)
    best, best_c = 0, -np.inf
    for k in range(-kmax, kmax + 1):
        x = dtau[rows + k]
        c = float(np.corrcoef(x, de)[0, 1]) if np.std(x) > 0 else -np.inf
        if c > best_c:
            best, best_c = k, c
    if best == 0:
        return ds, 0.0
    cols = {k: per_run(lambda x: shift(x, best, fill="hold"), ds.signals.starts, ds.signals[k])
            for k in ("tau", "tau_raw") if k in ds.signals}  # the raw torque too: the torque check re-smooths it
    sig = ds.signals.with_columns(**cols)
    note = f"tau: advanced by {best * ds.dt * 1e3:.0f} ms to match the encoders (estimator delay)"
    return replace(ds, signals=sig, notes=(*ds.notes, note)), best * ds.dt
