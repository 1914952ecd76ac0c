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
  ``duration`` [s] has passed or the safety monitor trips (the manager holds the measured position; the
  loop writes that command and stops).

Each tick, in this order: (calibration,) ``estimator.update(frame)``, (the mode request and
:meth:`LoopHook.settled`,) the reference, :meth:`LoopHook.before_control`, ``manager.tick``,
``backend.write``, ``backend.ground_truth()`` (only if a hook ``wants_truth``), :meth:`LoopHook.on_tick`,
the trip check, ``backend.read()``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from servotau.estimation import Estimate, EstimatorConfig, TorqueEstimator, calibrate_ft_offsets
from servotau.hal.types import SensorFrame

from .manager import ControlManager, Mode
from .terms import ControlTerms
from .trajectory import TrajectoryPoint

SETTLE = 0.5  # [s] in position mode before the run's mode: filters fill, F/T offsets are calibrated
ESTIMATOR_VARIANT = "low_delay"  # the estimator variant the torque controller is stable with in simulation


def estimator_config() -> EstimatorConfig:
    """config/estimation.toml with the loop's variant (:data:`ESTIMATOR_VARIANT`)."""
    return EstimatorConfig.from_toml(variant=ESTIMATOR_VARIANT)


@dataclass
class Tick:
    """One tick of the loop, as hooks and the reference see it.

    The arrays belong to their producers (the frame, the estimator's preallocated ``Estimate``, the
    manager's ``ControlTerms``) and are overwritten on the next tick: copy what must outlive it.
    """

    k: int  # tick index from the loop's first read
    t: float  # [s] from the end of the settle phase ((k - settle_ticks) * period; negative while settling)
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


@dataclass(frozen=True)
class LoopResult:
    ticks: int  # ticks run (the tripping tick included)
    period: float  # [s]
    wall_seconds: float  # [s] wall time of the run
    tripped: str | None  # the safety report's message, or None

    @property
    def sim_seconds(self) -> float:
        """[s] robot time of the run."""
        return self.ticks * self.period


Reference = Callable[[Tick], TrajectoryPoint]


class ControlLoop:
    """The one read -> estimate -> tick -> write loop over a HAL backend (module doc).

    Args:
        backend: HAL backend (``info``, ``read()``, ``write({joint: q_des})``, ``ground_truth()``).
        manager: The controller (default: config/control.toml).
        estimator: The torque estimator (default: config/estimation.toml, variant :data:`ESTIMATOR_VARIANT`).
        mode: Mode requested after the settle phase: ``position`` or ``torque``.
        settle: [s] of position mode first (0: no settle phase, no F/T calibration).
        hooks: Observers called every tick, in order.
        ft_offsets: ``f(settle_frames) -> (n_ft, 6)`` F/T offsets [N, N m] (default: calibrated on the frames,
            :func:`~servotau.estimation.calibrate_ft_offsets`; pass another when the feet are loaded).
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
        self._ft_offsets = ft_offsets or self._calibrate
        self._frame: SensorFrame | None = None
        self.hold: TrajectoryPoint | None = None  # the start posture, at rest (set by start())

    def _calibrate(self, frames: list[SensorFrame]) -> np.ndarray:
        return calibrate_ft_offsets(frames, self.info, self.estimator.config)

    def start(self) -> SensorFrame:
        """Read the first frame (once): its ``q`` is the start posture held while settling."""
        if self._frame is None:
            self._frame = self.backend.read()
            n = self.info.nq
            self.hold = TrajectoryPoint(self._frame.q.copy(), np.zeros(n), np.zeros(n))
        return self._frame

    def run(self, reference: Reference | None, duration: float) -> LoopResult:
        """Settle, then ``duration`` [s] in the run's mode following ``reference(tick)`` (None: hold the start).

        Raises:
            HalError: The robot is lost (from ``read``/``write``).
        """
        frame = self.start()
        backend, manager, estimator, hooks = self.backend, self.manager, self.estimator, self.hooks
        names, dt, n_settle = self.info.joint_names, self.info.period, self.settle_ticks
        truth_wanted = any(h.wants_truth for h in hooks)
        clock = time.perf_counter_ns
        settle_frames: list[SensorFrame] = []
        total = n_settle + int(round(duration / dt))
        t_wall = time.perf_counter()
        k = -1
        for k in range(total):
            if k == n_settle - 1:
                estimator.set_ft_offsets(self._ft_offsets(settle_frames))
            if k < n_settle:
                settle_frames.append(frame)
            t0 = clock()
            estimate = estimator.update(frame)
            tick = Tick(k, (k - n_settle) * dt, frame, estimate, estimation_ns=clock() - t0)
            if k == n_settle:
                if self.mode != Mode.POSITION:
                    manager.request_mode(self.mode)
                for h in hooks:
                    h.settled(tick)
            tick.reference = self.hold if k < n_settle or reference is None else reference(tick)
            for h in hooks:
                h.before_control(tick)
            t0 = clock()
            tick.terms = terms = manager.tick(frame, estimate if estimate.valid else None, tick.reference)
            tick.control_ns = clock() - t0
            backend.write(dict(zip(names, terms.q_des, strict=True)))
            if truth_wanted:
                tick.truth = backend.ground_truth()
            for h in hooks:
                h.on_tick(tick)
            if manager.tripped:
                break
            frame = backend.read()
        return LoopResult(ticks=k + 1, period=dt, wall_seconds=time.perf_counter() - t_wall,
                          tripped=manager.report.message if manager.tripped else None)
