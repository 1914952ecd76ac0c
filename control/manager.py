"""Control manager: position or torque mode with bumpless switches, safety checks and a latched hold.

Each tick (:meth:`ControlManager.tick`) takes the raw :class:`~servotau.hal.types.SensorFrame`, the estimate
and the reference, and returns the :class:`~servotau.control.terms.ControlTerms` whose ``q_des`` goes to
the robot::

    manager = ControlManager.from_toml(info)                # config/control.toml
    manager.request_mode(Mode.TORQUE)                       # applied at the next tick, bumpless
    terms = manager.tick(frame, estimate, trajectory.sample(t))
    backend.write_array(terms.q_des)
    if manager.tripped: print(manager.report.message)       # latched until manager.reset()

Modes:

- ``position``: ``q_des = q_ref`` (the native servo; the paper's baseline).
- ``torque``: ``q_des = q + dq_err`` on torque-controlled joints (eq. 10-12, :mod:`.law`), ``q_ref`` elsewhere.
  ``q`` is the encoder reading of the frame (not the filtered estimate): the servo sees exactly ``dq_err``.
- torque mode falls back to position control (bumpless) while the estimate is invalid after more skipped
  frames than the estimator's ``max_gap`` (``gap_fallback = "position"``, counted in ``gap_fallbacks``; with
  ``"trip"``: the ``estimate_gap`` trip), and returns to torque mode once it is valid again.
- ``hold``: entered by a safety trip; ``q_des`` = the last valid measured angles at the trip, the torque terms
  zero, the integrals frozen. For the first ``safety.hold_brake_time`` the hold also brakes: ``q_des -=
  hold_damping * dq`` (encoders' backward difference within +-``max_velocity``, not the delayed estimate; the
  term fades out with a half-cosine), which adds the damping ``k_p hold_damping`` to a servo that stops a moving
  joint with too little (HRP-2's hip: damping ratio about 0.3 alone, so a joint caught at 1.8 rad/s overshoots
  ~11 mrad).
  Every held tick the checks still run on the frame, the estimate and the held command, without latching:
  :attr:`ControlManager.condition` says whether the trip's cause is still there.
  Only a reset leaves the hold (into position mode): :meth:`try_reset` refuses while a check still fails,
  :meth:`reset` clears it unconditionally.

Bumpless switch: on a mode change the offset ``last q_des - new command`` is added to the new command and
faded to zero over ``fade_time`` with a half-cosine, so the first command of the new mode equals the last
one of the old mode and the command's slope is continuous. The torque integral starts empty.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

from servotau.errors import ControlError
from servotau.hal.types import RobotInfo, SensorFrame

from .config import DEFAULT_PATH, ControlConfig
from .dynamics import BaseState
from .law import TorqueControlLaw
from .safety import SafetyMonitor, SafetyReport
from .terms import ControlTerms

log = logging.getLogger(__name__)


class Mode(StrEnum):
    POSITION = "position"
    TORQUE = "torque"
    HOLD = "hold"


@dataclass
class StateEstimate:
    """Plain-array estimate for :meth:`ControlManager.tick` (the estimator's ``Estimate`` has the same fields).

    Joint arrays (n,) in RobotInfo order; ``wrenches`` (4, 6) compensated external wrenches at the F/T
    sensors (HAL order, environment on the robot); base fields (3,) in the waist frame (floating base only).
    """

    q: np.ndarray  # [rad]
    dq: np.ndarray  # [rad/s]
    ddq: np.ndarray  # [rad/s^2]
    tau: np.ndarray  # [N m]
    wrenches: np.ndarray | None = None  # [N, N m]
    base_angular_velocity: np.ndarray | None = None  # [rad/s]
    base_angular_acceleration: np.ndarray | None = None  # [rad/s^2]
    base_specific_force: np.ndarray | None = None  # [m/s^2]
    valid: bool = True
    gap_flush: int = 0  # ticks until the estimate is valid again after skipped frames (estimator's Estimate.gap_flush)


class ControlManager:
    """Modes, bumpless switches, safety and the per-tick outputs of the torque controller."""

    def __init__(self, info: RobotInfo, config: ControlConfig, model_path: str | Path | None = None):
        if tuple(config.joint_names) != tuple(info.joint_names):
            raise ControlError(f"config joints {list(config.joint_names)}: expected the robot's joints, in order "
                               f"{list(info.joint_names)}")
        self.info = info
        self.config = config
        n = info.nq
        self.law = TorqueControlLaw(config, str(model_path or info.model_path), info.period, info)
        self.safety = SafetyMonitor(info, config.safety)
        self.terms = self.law.make_terms()
        self.torque_mask = config.torque_mask.copy()
        self._position_mask = (~self.torque_mask).astype(float)
        self._mode = Mode.POSITION
        self._requested = Mode.POSITION
        self._report: SafetyReport | None = None
        self._condition: SafetyReport | None = None  # a check failing on the last held tick
        self._offset = np.zeros(n)  # [rad] bumpless-switch offset at the switch
        self._t_switch = -math.inf
        self._fading = False
        self._started = False  # a command was sent (terms.q_des holds the last one)
        self._q_good = np.clip(np.zeros(n), info.q_min, info.q_max)  # last finite encoder reading
        self._q_hold = np.zeros(n)
        self._t_hold = 0.0  # [s] robot time of the trip
        self._q_last = np.full(n, np.nan)  # [rad] encoders of the previous frame
        self._t_last = math.nan  # [s] its robot time
        self._dq_fd = np.zeros(n)  # [rad/s] encoders' backward difference (0 where not finite)
        self._cmd = np.zeros(n)
        self.gap_fallbacks = 0  # torque mode fell back to position control after skipped frames (gap_fallback)

    @classmethod
    def from_toml(cls, info: RobotInfo, path: str | Path = DEFAULT_PATH) -> ControlManager:
        """Manager for ``info`` with the settings of ``path`` (default ``config/control.toml``), k_p scheduled and
        the predicted loop checked at the model's neutral posture (:func:`~.tuning.tuned`)."""
        from servotau.config import load_toml

        from .tuning import tuned

        motors = str(load_toml(path).data.get("motors"))
        return cls(info, tuned(ControlConfig.from_toml(path, info), info, motors))

    # -- state -------------------------------------------------------------------------------------
    @property
    def mode(self) -> Mode:
        """Mode of the last tick."""
        return self._mode

    @property
    def tripped(self) -> bool:
        return self._report is not None

    @property
    def report(self) -> SafetyReport | None:
        """Why the controller is holding, or None."""
        return self._report

    @property
    def condition(self) -> SafetyReport | None:
        """While holding: the check that still fails on the last tick (frame, estimate, held command), or None."""
        return self._condition if self._report is not None else None

    @property
    def hold_posture(self) -> np.ndarray:
        """[rad] (n,) the posture held since the trip (the last valid measured angles; read-only view)."""
        v = self._q_hold.view()
        v.flags.writeable = False
        return v

    def request_mode(self, mode: Mode | str) -> None:
        """Switch to ``position`` or ``torque`` at the next tick (bumpless).

        Raises:
            ControlError: Unknown mode, ``hold`` requested, torque mode without torque-controlled joints, or
                a latched trip (call :meth:`reset` first).
        """
        try:
            mode = Mode(mode)
        except ValueError:
            raise ControlError(f"mode {mode!r}: expected 'position' or 'torque'") from None
        if mode == Mode.HOLD:
            raise ControlError("mode 'hold': expected 'position' or 'torque' (hold is entered by a safety trip)")
        if self._report is not None:
            raise ControlError(f"cannot switch to {mode.value} mode: {self._report.message}; call reset() first")
        if mode == Mode.TORQUE and not self.torque_mask.any():
            raise ControlError(f"torque mode: no torque-controlled joint in {self.config.source}: expected a "
                               "non-empty torque_joints")
        self._requested = mode

    def try_reset(self) -> str | None:
        """Clear a latched trip if no check fails on the last held tick (:attr:`condition`): back to position mode.

        Returns:
            None if the trip was cleared (or there was none), else why not (the failing check's message).
        """
        if self._report is None:
            return None
        if self._condition is not None:
            return f"the trip condition still holds: {self._condition.message}"
        self.reset()
        return None

    def reset(self) -> None:
        """Clear a latched trip: back to position mode, faded from the held angles."""
        if self._report is not None:
            log.warning("safety latch reset (was: %s)", self._report.message)
        self._report = None
        self._condition = None
        self.terms.tripped = False
        self._requested = Mode.POSITION
        self.safety.reset()

    def set_force_reference(self, f_d: np.ndarray) -> None:
        """Desired wrench [N, N m] (6,) of the force task, at the task frame."""
        self.law.inverse_dynamics.set_force_reference(f_d)

    # -- per tick ----------------------------------------------------------------------------------
    def tick(self, frame: SensorFrame, estimate, reference, robot_servo_off: bool = False) -> ControlTerms:
        """One control period.

        Args:
            frame: The raw sensor frame of this tick (encoders give ``q`` of the command).
            estimate: :class:`StateEstimate` or the estimator's ``Estimate`` (``q, dq, ddq, tau``, ``wrenches``
                with contacts, base fields with a floating base); None or ``valid == False`` while the
                estimator fills its windows (position mode only).
            reference: Desired ``q, dq, ddq`` (n,) [rad, rad/s, rad/s^2], e.g. a ``TrajectoryPoint``.
            robot_servo_off: The robot reports its servos cut (a robot-side trip, the backend's ``robot_state``):
                the ``robot_servo_off`` trip, whose condition holds while it lasts.

        Returns:
            The outputs of this tick (the same object every tick); send ``q_des`` to the robot.
        """
        t = self.terms
        t.time, t.seq = frame.time, frame.seq
        self._difference(frame)
        has_estimate = estimate is not None and getattr(estimate, "valid", True)
        off = SafetyReport("robot_servo_off", "robot", 1.0, 0.0, float(frame.time), int(frame.seq)) \
            if robot_servo_off else None
        if self._report is not None:
            t = self._hold(frame)
            self._condition = off or self._check_hold(frame, estimate if has_estimate else None, t.dq_err)
            return t
        if off is not None:
            return self._trip(frame, off)
        report = self.safety.check_frame(frame)
        if report is None and has_estimate:
            report = self.safety.check_estimate(frame, estimate.q, estimate.dq, estimate.ddq, estimate.tau)
        mode = self._requested
        if report is None and mode == Mode.TORQUE and not has_estimate:
            flush = int(getattr(estimate, "gap_flush", 0) or 0)
            if flush and self.config.gap_fallback == "position":
                mode = Mode.POSITION  # until the estimate is valid again (bumpless both ways)
                if self._mode == Mode.TORQUE:
                    self.gap_fallbacks += 1
            elif flush:
                report = SafetyReport("estimate_gap", "", flush, 0.0, float(frame.time), int(frame.seq))
            else:
                report = SafetyReport("invalid_estimate", "", math.nan, 0.0, float(frame.time), int(frame.seq))
        if report is not None:
            return self._trip(frame, report)
        q = frame.q
        np.copyto(self._q_good, q)  # finite: checked above
        switching = mode != self._mode
        if switching and mode == Mode.TORQUE:
            self.law.reset()
        dq_err = None
        if has_estimate:
            dq_err = self.law.update(t, estimate.q, estimate.dq, estimate.ddq, estimate.tau, reference.q,
                                     reference.dq, reference.ddq, getattr(estimate, "wrenches", None),
                                     self._base(estimate), q_encoder=q)
        cmd = self._cmd
        np.subtract(reference.q, q, out=t.position_command)  # q_ref - q
        if mode == Mode.TORQUE:
            # cmd = q + dq_err on torque joints, q_ref elsewhere: q + dq_err + position_command (masked)
            t.position_command *= self._position_mask
            np.add(q, dq_err, out=cmd)
            np.add(cmd, t.position_command, out=cmd)
        else:
            np.copyto(cmd, reference.q)
            if has_estimate or switching:
                self.law.clear(t)  # the torque components are 0 outside torque mode
        if switching:
            if self._started:
                np.subtract(t.q_des, cmd, out=self._offset)  # t.q_des still holds the last command
                self._fading = True
            self._t_switch = float(frame.time)
            log.info("control mode %s -> %s at t = %.3f s", self._mode.value, mode.value, frame.time)
        if self._fading:
            w = self._fade(float(frame.time) - self._t_switch)
            np.multiply(self._offset, w, out=t.switch_offset)
            self._fading = w > 0.0
        np.add(cmd, t.switch_offset, out=t.q_des)
        np.subtract(t.q_des, q, out=t.dq_err)
        report = self.safety.check_command(frame, t.dq_err)
        if report is not None:
            return self._trip(frame, report)
        self._mode = mode
        t.mode = mode.value
        self._started = True
        return t

    # -- internals ---------------------------------------------------------------------------------
    def _fade(self, elapsed: float) -> float:
        """Weight of the switch offset: 1 at the switch, 0 after ``fade_time``, half-cosine in between."""
        T = self.config.fade_time
        if elapsed >= T:
            return 0.0
        return 0.5 * (1.0 + math.cos(math.pi * max(elapsed, 0.0) / T))

    def _difference(self, frame: SensorFrame) -> None:
        """Update the encoders' backward difference [rad/s] (0 for a joint without two finite readings; within
        +-``safety.max_velocity``)."""
        dt = float(frame.time) - self._t_last
        if dt > 0.0:
            np.subtract(frame.q, self._q_last, out=self._dq_fd)
            self._dq_fd /= dt
        else:
            self._dq_fd.fill(0.0)
        self._dq_fd[~np.isfinite(self._dq_fd)] = 0.0
        v = self.config.safety.max_velocity  # an encoder glitch must not become a large braking command
        np.clip(self._dq_fd, -v, v, out=self._dq_fd)
        np.copyto(self._q_last, frame.q)
        self._t_last = float(frame.time)

    def _base(self, estimate) -> BaseState | None:
        if self.config.base != "floating":
            return None
        return BaseState(estimate.base_angular_velocity, estimate.base_angular_acceleration,
                         estimate.base_specific_force)

    def _trip(self, frame: SensorFrame, report: SafetyReport) -> ControlTerms:
        self._report = report
        self._condition = report
        q = frame.q
        np.copyto(self._q_hold, self._q_good)  # last finite reading
        if not (report.check == "sensor_status" and report.where == "encoders"):  # else no valid angle in it
            np.copyto(self._q_hold, q, where=np.isfinite(q))
        self._t_hold = float(frame.time)
        log.error("%s: holding the last valid measured posture", report.message)
        return self._hold(frame)

    def _check_hold(self, frame: SensorFrame, estimate, dq_err: np.ndarray) -> SafetyReport | None:
        """The checks of a running tick on a held one (frame, estimate, held command), latching nothing."""
        report = self.safety.check_frame(frame)
        if report is None and estimate is not None:
            report = self.safety.check_estimate(frame, estimate.q, estimate.dq, estimate.ddq, estimate.tau)
        if report is None:
            report = self.safety.check_command(frame, dq_err)
        return report

    def _hold(self, frame: SensorFrame) -> ControlTerms:
        t = self.terms
        self._mode = Mode.HOLD
        t.mode = Mode.HOLD.value
        t.tripped = True
        t.q_des[:] = self._q_hold
        s = self.config.safety
        elapsed = float(frame.time) - self._t_hold
        if s.hold_damping > 0.0 and elapsed < s.hold_brake_time:
            w = 0.5 * (1.0 + math.cos(math.pi * max(elapsed, 0.0) / s.hold_brake_time))
            t.q_des -= (s.hold_damping * w) * self._dq_fd
        np.subtract(t.q_des, frame.q, out=t.dq_err)
        t.position_command[:] = t.dq_err
        t.switch_offset.fill(0.0)
        self._fading = False
        self.law.clear(t)
        self._started = True
        return t

