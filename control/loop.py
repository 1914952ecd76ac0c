"""The control loop: read -> estimate -> tick -> write, once per period, with hooks.

The controller process (``servotau control``), the experiments and the benchmark run this loop::

    loop = ControlLoop(backend, mode="torque", hooks=[MyLogger()])
    frame = loop.start()                                    # first read: the start posture
    swing = right_leg_swing(backend.info.joint_names, frame.q, 3.0)
    result = loop.run(lambda tick: swing.sample(tick.t), duration=3.5)

Phases:

- settle (``settle`` [s], default :data:`SETTLE`): position mode, holding the start posture while the
  estimator's filters fill. On the last settle tick, before its estimate, the F/T offsets are calibrated
  from the frames of the settle ticks before it (the end effectors must touch nothing; with loaded feet
  pass ``ft_offsets``) and set in the estimator, so that the F/T filter refills with compensated readings.
- reference: the run's ``mode`` is requested on the first tick after the settle phase (the manager
  switches bumplessly), then ``reference(tick)`` gives the desired joint state every tick until
  ``duration`` [s] of robot time has passed or the safety monitor trips.
- end: ``reference(tick)`` returning None ends the run (``completed``: a task's last phase is over);
  ``duration`` None runs until then, or until stopped.
- stop (``request_stop()``, Ctrl-C, the operator's ``stop``): the reference comes to rest within
  :data:`~.trajectory.STOP_ACCELERATION` and ``STOP_JERK`` from its last state (jerk-limited), the manager switches to
  position mode (bumpless: the switch offset fades over ``fade_time``), and once both are done the run ends
  (``stopped``); the stopping reference stays within the joint range less ``joint_limit_margin``. A stop while
  a trip is latched ends the run at once (the hold was written).
- hold (after a trip): the manager holds the last valid measured posture (torque terms zero, integrals
  frozen) and the loop keeps answering every frame, reporting the trip once (:meth:`LoopHook.tripped`),
  until an operator acts through an :class:`~servotau.control.operator.OperatorChannel`: ``reset`` (refused
  while the trip's cause is still there) goes back to position control at the held posture, which the loop
  then keeps; ``release`` ends the run. ``hold_timeout`` [s] of robot time without a release ends it too
  (default 0: the loop stops on the tripping tick, after writing the hold).
- operator: ``position``/``torque`` request that mode (refused while a trip is latched); other actions go to
  ``actions`` (e.g. a task runner's ``start``). An action whose work must not run on the loop's thread (reading and
  building a task) returns a :class:`Deferred`; the loop answers the operator on the tick it is finished.

Time is the robot's: a tick's ``t`` and the phases count robot ticks from the first frame (``frame.seq``), so
frames skipped by a late controller shorten neither the settle phase nor the run, and the estimator fills
them in as a counted gap (:mod:`servotau.estimation.estimator`).

Each tick, in this order: (calibration,) ``estimator.update(frame)``, (the mode request and
:meth:`LoopHook.settled`,) the reference, :meth:`LoopHook.before_control`, ``manager.tick``,
``backend.write``, ``backend.ground_truth()`` (only if a hook ``wants_truth``), :meth:`LoopHook.on_tick`,
the trip check (and :meth:`LoopHook.tripped`), the operator's action, ``backend.read()``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from servotau.errors import ServotauError
from servotau.estimation import Estimate, FtOffsetAverage, TorqueEstimator
from servotau.hal.types import SensorFrame

from .estimator_variant import estimator_config
from .manager import ControlManager, Mode
from .operator import OperatorChannel
from .safety import SafetyReport
from .terms import ControlTerms
from .trajectory import TrajectoryPoint, stopping_segment

log = logging.getLogger(__name__)

SETTLE = 0.5  # [s] in position mode before the run's mode: filters fill, F/T offsets are calibrated
DETAIL_TICKS = 100  # the operator's status detail (robot time, mode, phase) is refreshed every this many ticks


@dataclass
class Tick:
    """One tick of the loop, as hooks and the reference see it.

    The arrays belong to their producers (the frame, the estimator's preallocated ``Estimate``, the
    manager's ``ControlTerms``) and are overwritten on the next tick: copy what must outlive it.
    """

    k: int  # tick index from the loop's first read
    t: float  # [s] robot time from the end of the settle phase ((robot ticks - settle_ticks) * period; < 0: settling)
    frame: SensorFrame  # what the robot sent this tick
    estimate: Estimate  # the estimator's output for ``frame`` (check ``estimate.valid``)
    reference: TrajectoryPoint | None = None  # desired q, dq, ddq of this tick (set before the control tick)
    terms: ControlTerms | None = None  # the controller's outputs (set by the control tick)
    truth: object | None = None  # backend.ground_truth() after the write, if a hook wants it (evaluation only)
    estimation_ns: int = 0  # [ns] wall time of estimator.update
    control_ns: int = 0  # [ns] wall time of manager.tick

    @property
    def settling(self) -> bool:
        """True during the settle phase."""
        return self.t < 0


class LoopHook:
    """Observer of a :class:`ControlLoop` (logging, streaming, evaluation): override what you need."""

    wants_truth: bool = False
    """The loop reads ``backend.ground_truth()`` after every write (simulation only) into ``tick.truth``."""

    def settled(self, tick: Tick) -> None:
        """First tick after the settle phase: offsets calibrated, the run's mode just requested."""

    def before_control(self, tick: Tick) -> None:
        """After the estimate and the reference, before the control tick (e.g. set a force reference)."""

    def on_tick(self, tick: Tick) -> None:
        """After the command is written (``tick.terms`` set; ``tick.truth`` if ``wants_truth``)."""

    def tripped(self, tick: Tick, report: SafetyReport) -> None:
        """Once per safety trip, on the tripping tick, after :meth:`on_tick` (the hold is written)."""


@dataclass(frozen=True)
class LoopResult:
    ticks: int  # ticks run (the tripping tick and the held ticks included)
    period: float  # [s]
    wall_seconds: float  # [s] wall time of the run
    tripped: str | None  # the first safety report's message, or None
    robot_ticks: int = 0  # robot ticks from the first frame to the last (ticks + skipped frames)
    end: str = "completed"  # "completed" (duration or task over), "stopped", "released" (operator), "hold_timeout"
    trips: int = 0  # safety trips (a reset hold can trip again)
    resets: int = 0  # trips cleared by an operator's reset
    gaps: int = 0  # gaps of skipped frames (the estimator's count)
    missing_frames: int = 0  # frames skipped in them
    longest_gap: int = 0  # [frames]

    @property
    def sim_seconds(self) -> float:
        """[s] robot time of the run."""
        return self.robot_ticks * self.period


class Deferred:
    """The answer to an operator action that finishes later, off the loop's thread (e.g. a task built by a worker):
    the action's handler returns one and calls :meth:`finish` once done (on the loop's thread, from a hook); the loop
    answers the operator at the end of that tick."""

    __slots__ = ("done", "refusal")

    def __init__(self):
        self.done = False
        self.refusal: str | None = None

    def finish(self, refusal: str | None = None) -> None:
        """Done: None (the action applies), or why it is refused."""
        self.refusal, self.done = refusal, True


Reference = Callable[[Tick], TrajectoryPoint | None]
Action = Callable[[dict, Tick], str | Deferred | None]  # an operator action's handler: None (done), why it is
# refused, or a Deferred answer


class ControlLoop:
    """The one read -> estimate -> tick -> write loop over a HAL backend (module doc).

    Args:
        backend: HAL backend (``info``, ``read()``, ``write({joint: q_des})``, ``ground_truth()``).
        manager: The controller (default: config/control.toml).
        estimator: The torque estimator (default: config/estimation.toml, variant :data:`ESTIMATOR_VARIANT`).
        mode: Mode requested after the settle phase: ``position`` or ``torque``.
        settle: [s] of position mode first (0: no settle phase, no F/T calibration).
        hooks: Observers called every tick, in order.
        ft_offsets: ``f(settle_frames) -> (n_ft, 6)`` F/T offsets [N, N m] (pass one when the feet are loaded;
            default: the estimates of the settle ticks averaged as they come,
            :class:`~servotau.estimation.FtOffsetAverage`, as :func:`~servotau.estimation.calibrate_ft_offsets`
            would compute them on the frames but without a second pass that stalls the loop).
    """

    def __init__(self, backend, manager: ControlManager | None = None, estimator: TorqueEstimator | None = None,
                 *, mode: Mode | str = Mode.POSITION, settle: float = SETTLE, hooks: Sequence[LoopHook] = (),
                 ft_offsets: Callable[[list[SensorFrame]], np.ndarray] | None = None):
        self.backend = backend
        self.info = info = backend.info
        self.manager = manager if manager is not None else ControlManager.from_toml(info)
        self.estimator = estimator if estimator is not None else TorqueEstimator(info, estimator_config())
        self.mode = Mode(mode)
        self.settle_ticks = int(round(settle / info.period))
        self.hooks = tuple(hooks)
        self._ft_offsets = ft_offsets
        self._frame: SensorFrame | None = None
        self.hold: TrajectoryPoint | None = None  # the start posture, at rest (set by start())
        self._stop_requested = False
        margin = self.manager.config.safety.joint_limit_margin
        self._q_range = (info.q_min + margin, info.q_max - margin)  # [rad] where a stopping reference may go
        self.state = "starting"  # the operator states (control/operator.py STATES)
        self.describe: Callable[[], dict] = dict  # more of the status detail, e.g. a task runner's phase

    def request_stop(self) -> None:
        """Stop the run smoothly (module doc), from any thread or a signal handler: taken at the next tick."""
        self._stop_requested = True

    def start(self) -> SensorFrame:
        """Read the first frame (once): its ``q`` is the start posture held while settling."""
        if self._frame is None:
            self._frame = self.backend.read()
            n = self.info.nq
            self.hold = TrajectoryPoint(self._frame.q.copy(), np.zeros(n), np.zeros(n))
        return self._frame

    def run(self, reference: Reference | None, duration: float | None, *, operator: OperatorChannel | None = None,
            hold_timeout: float | None = 0.0, actions: Mapping[str, Action] | None = None) -> LoopResult:
        """Settle, then ``duration`` [s] of robot time in the run's mode following ``reference(tick)`` (None: hold
        the start); after a safety trip, the latched hold (module doc) until the operator or ``hold_timeout``.

        Args:
            reference: The desired joint state of each tick after the settle phase (None from it: the end).
            duration: [s] robot time after the settle phase (None: until the reference ends or a stop).
            operator: Where an operator's ``reset``/``release``/``status`` arrive (:mod:`.operator`), or None.
            hold_timeout: [s] robot time the loop keeps holding after a trip (or after a reset) before it releases
                by itself; None: until the operator releases; 0 (default): it stops on the tripping tick.

        Raises:
            HalError: The robot is lost (from ``read``/``write``).
        """
        frame = self.start()
        backend, manager, estimator, hooks = self.backend, self.manager, self.estimator, self.hooks
        names, dt, n_settle = self.info.joint_names, self.info.period, self.settle_ticks
        truth_wanted = any(h.wants_truth for h in hooks)
        set_hold = getattr(backend, "set_hold", None)  # a HAL backend: the robot holds by itself once tripped
        if truth_wanted:  # before the first write: a backend that keeps truth per step (inprocess) starts keeping it
            backend.ground_truth()
        clock = time.perf_counter_ns
        settle_frames: list[SensorFrame] = []  # for a given ft_offsets function
        average = FtOffsetAverage(self.info, estimator.ft_offsets) if self._ft_offsets is None else None
        total = n_settle + int(round(duration / dt)) if duration is not None else None
        actions = dict(actions or {})
        stopping = None  # (stop segment, robot time [s] of the stop) while stopping
        last_ref: TrajectoryPoint | None = None
        seq0 = frame.seq
        state = "settling" if n_settle else "running"
        calibrated, settled = n_settle == 0, False
        held: TrajectoryPoint | None = None  # the posture held since a trip (also after a reset)
        t_hold = 0.0  # [s] robot time the current hold started (trip or reset)
        first_trip: str | None = None
        trips = resets = 0
        end = "completed"
        self.state = state
        if operator is not None:
            operator.publish(state)
        t_wall = time.perf_counter()
        deferred: list = []  # (Deferred, request) of actions still being prepared off this thread
        k, i = -1, 0
        try:
            while True:
                k += 1
                i = frame.seq - seq0  # robot ticks since the first frame: frames may be skipped
                if not calibrated and i >= n_settle - 1:
                    offsets = average.offsets(estimator.config) if average else self._ft_offsets(settle_frames)
                    estimator.set_ft_offsets(offsets)
                    calibrated = True
                if i < n_settle and average is None:
                    settle_frames.append(frame)
                t0 = clock()
                estimate = estimator.update(frame)
                if not calibrated and average is not None:
                    average.add(estimate)
                tick = Tick(k, (i - n_settle) * dt, frame, estimate, estimation_ns=clock() - t0)
                if not settled and i >= n_settle:
                    settled = True
                    if state == "settling":
                        state = "running"
                    if self.mode != Mode.POSITION and not manager.tripped and stopping is None \
                            and not self._stop_requested:  # a stop asked while settling: position mode stays
                        manager.request_mode(self.mode)
                    for h in hooks:
                        h.settled(tick)
                if self._stop_requested and stopping is None and state != "done":
                    self._stop_requested = False
                    if state == "tripped":
                        end = "stopped"
                        break
                    stopping = self._begin_stop(last_ref or self.hold, float(frame.time))
                    state = "stopping"
                if held is not None:
                    tick.reference = held
                elif stopping is not None:
                    q, dq, ddq = stopping[0].sample(float(frame.time) - stopping[1])
                    np.clip(q, *self._q_range, out=q)  # braking never carries the reference out of the joint range
                    tick.reference = TrajectoryPoint(q, dq, ddq)
                elif i < n_settle or reference is None:
                    tick.reference = self.hold
                else:
                    tick.reference = reference(tick)
                    if tick.reference is None:  # the task is over
                        end = "completed"
                        break
                last_ref = tick.reference
                for h in hooks:
                    h.before_control(tick)
                t0 = clock()
                off = getattr(backend, "robot_state", None) == "servo_off"  # a robot-side trip
                tick.terms = terms = manager.tick(frame, estimate, tick.reference, off)  # estimate used only if valid
                tick.control_ns = clock() - t0
                if set_hold is not None:
                    set_hold(manager.tripped)  # COMMAND_HOLD on every command while tripped (docs/protocol.md)
                backend.write(dict(zip(names, terms.q_des, strict=True)))
                if truth_wanted:
                    tick.truth = backend.ground_truth()
                for h in hooks:
                    h.on_tick(tick)
                if manager.tripped and state != "tripped":  # a new trip: latch, report once
                    state, trips, t_hold = "tripped", trips + 1, float(frame.time)
                    first_trip = first_trip or manager.report.message
                    n = self.info.nq
                    held = TrajectoryPoint(manager.hold_posture.copy(), np.zeros(n), np.zeros(n))
                    for h in hooks:
                        h.tripped(tick, manager.report)
                self.state = state
                if operator is not None:
                    detail = None
                    if k % DETAIL_TICKS == 0:  # status's detail, refreshed every DETAIL_TICKS ticks
                        detail = {"time": float(frame.time), "mode": manager.mode.value, **self.describe()}
                    operator.publish(state, manager.report.message if manager.tripped else None, detail)
                    for d, request in [x for x in deferred if x[0].done]:
                        deferred.remove((d, request))
                        refusal = "the run is stopping" if state == "stopping" and d.refusal is None else d.refusal
                        if refusal is None and state == "holding":  # after a reset: the new task drives again
                            held, state = None, "running"
                        operator.answer(request, refusal is None, state, refusal)
                    pending = operator.take()
                    if pending is not None:
                        if pending.action == "release":
                            operator.answer(pending, True, "released")
                            end = "released"
                            break
                        if pending.action == "stop":
                            if state == "tripped":
                                operator.answer(pending, True, "stopped")
                                end = "stopped"
                                break
                            if stopping is None:
                                stopping = self._begin_stop(last_ref, float(frame.time))
                                state = "stopping"
                            operator.answer(pending, True, state)
                        elif pending.action in ("position", "torque"):
                            refusal = None
                            if state == "stopping":
                                refusal = "the run is stopping"
                            else:
                                try:
                                    manager.request_mode(pending.action)
                                except ServotauError as exc:
                                    refusal = str(exc)
                            operator.answer(pending, refusal is None, state, refusal)
                        elif pending.action in actions:
                            refusal = "the run is stopping" if state == "stopping" else actions[pending.action](
                                pending.args, tick)
                            if isinstance(refusal, Deferred):
                                deferred.append((refusal, pending))
                            else:
                                if refusal is None and state == "holding":  # after a reset: the new task drives
                                    held, state = None, "running"
                                operator.answer(pending, refusal is None, state, refusal)
                        elif pending.action != "reset":
                            operator.answer(pending, False, state, f"{pending.action}: not served by this loop")
                        elif state == "tripped":  # reset
                            refusal = manager.try_reset()
                            if refusal is None:
                                state, resets, t_hold = "holding", resets + 1, float(frame.time)
                                log.warning("operator reset at t = %.3f s: position control at the held posture",
                                            frame.time)
                            operator.answer(pending, refusal is None, state, refusal)
                        else:
                            operator.answer(pending, True, state, None)  # nothing latched: nothing to reset
                if state in ("tripped", "holding"):
                    if hold_timeout is not None and float(frame.time) - t_hold >= hold_timeout - 1e-9:
                        end = "hold_timeout"
                        if hold_timeout > 0:
                            log.warning("no operator release within hold_timeout = %g s of robot time: releasing",
                                        hold_timeout)
                        break
                elif stopping is not None:
                    if float(frame.time) - stopping[1] >= max(stopping[0].duration,
                                                              manager.config.fade_time) - 1e-9:
                        end = "stopped"
                        break
                elif total is not None and i >= total - 1:
                    break
                frame = backend.read()
        finally:
            self.state = {"completed": "done", "stopped": "stopped"}.get(end, "released")
            for _, request in deferred:
                operator.answer(request, False, self.state, f"the control loop has ended ({self.state})")
            if operator is not None:
                operator.close(self.state)
        return LoopResult(ticks=k + 1, period=dt, wall_seconds=time.perf_counter() - t_wall, tripped=first_trip,
                          robot_ticks=i + 1, end=end, trips=trips, resets=resets, gaps=estimator.gaps,
                          missing_frames=estimator.missing_frames, longest_gap=estimator.longest_gap)

    def _begin_stop(self, last: TrajectoryPoint, t: float):
        """The stop segment from the last reference (module doc) and the switch to position mode."""
        log.info("stopping at t = %.3f s: the reference comes to rest, position mode", t)
        if not self.manager.tripped:
            self.manager.request_mode(Mode.POSITION)
        return stopping_segment(last.q, last.dq, last.ddq), t
