"""A served robot in the controller's process: same firmware safety and lock-step semantics as the
Zenoh server, no transport, deterministic (the watchdog counts in robot time). For tests and batch
experiments."""

from __future__ import annotations

import json

import numpy as np

from servotau.config import Section

from ..backend import Backend
from ..config import import_object
from ..errors import HalError, MalformedMessage
from ..log import LogWriter
from ..robot import operator
from ..robot.config import safety_config
from ..robot.firmware import LOG_EXTRA, Firmware, SafetyConfig, checked_frame
from ..robot.gate import STALE, TAKE, CommandGate
from ..robot.served import ServedRobot
from ..types import GroundTruth, SensorFrame
from ..wire.protocol import decode_command, reject_reason


class InProcessBackend(Backend):
    """Drives ``robot`` directly: :meth:`write` steps it once (the first command answering a frame
    wins, a copy of it is rejected as a replay); :meth:`read` after :meth:`read` without a write steps it
    with no fresh command (the watchdog holds after ``hold_after`` [s] of robot time). :meth:`receive`
    takes a command as wire bytes, through the server's checks; :meth:`operator` answers an operator
    request (docs/protocol.md "State machine").

    Args:
        robot: the served robot.
        safety: firmware settings (watchdog, position-error trip).
        log: optional Parquet path recording what the robot side saw (like the server's log).
    """

    def __init__(self, robot: ServedRobot, safety: SafetyConfig | None = None, log: str | None = None):
        self.robot = robot
        self.firmware = Firmware(robot.info, safety)
        self.gate = CommandGate(lockstep=True, max_age_ticks=self.firmware.safety.max_command_age_ticks)
        self._current = self._observe(robot.read())  # frame of the current tick
        self._stepped_seq = -1  # seq of the last frame the robot stepped past
        self._servo_off = False
        self._want_truth = False  # ground_truth() was called: keep the truth of each stepped tick
        self._truth_before_step = None  # (seq, GroundTruth) of the last stepped tick
        self._truth_now = None  # (seq, GroundTruth) of the current tick, once asked (the robot has not stepped since)
        self._log = None
        if log:
            self._log = LogWriter(log, robot.info, truth=True, extra=LOG_EXTRA,
                                  metadata={"servotau.source": "inprocess"})
        super().__init__(robot.info, self._current)

    def _step(self) -> None:
        frame, fw = self._current, self.firmware
        truth = None
        if self._log is not None or self._want_truth:
            truth = self._truth_now[1] if self._truth_now and self._truth_now[0] == frame.seq else self._truth_of_now()
        if self._want_truth:
            self._truth_before_step = (frame.seq, truth)
        q_apply = fw.output(frame.q, frame.time, int(frame.status[0]))
        if self._log is not None:
            self._log.append(frame, q_apply, truth, {"hal/state": float(fw.state), "hal/wall_time": np.nan})
        if q_apply is None:
            if not self._servo_off:
                self.robot.servo_off()
                self._servo_off = True
            self.robot.step(fw.last_valid(frame.q))
        else:
            self.robot.step(q_apply)
        self._stepped_seq = frame.seq
        self._current = self._observe(self.robot.read())

    def _observe(self, frame: SensorFrame) -> SensorFrame:
        frame = checked_frame(frame)
        self.gate.published(frame.seq, frame.time)
        return frame

    def read(self, timeout: float | None = None) -> SensorFrame:
        if self._last_read is not None and self._current.seq == self._last_read.seq:
            self._step()  # read twice without a write: step without a fresh command
        return self._returned(self._current)

    def _send(self, q_des: np.ndarray, answers: SensorFrame) -> None:
        self._take(answers.seq, answers.time, q_des, self.hold_requested)

    def _take(self, seq: int, time: float, q_des: np.ndarray, hold: bool = False) -> str:
        verdict, why = self.gate.check(seq, time)
        if verdict == STALE:
            self.firmware.stale()
        elif verdict != TAKE:
            self.firmware.reject(verdict, why)
        else:
            self.firmware.accept(q_des, self._current.time, hold, self.gate.newest - seq)
            self.gate.applied(seq)
            self._step()
        return verdict

    def receive(self, payload: bytes) -> str:
        """Take a command as wire bytes, checked as the server checks them (docs/protocol.md
        "Validation"): the verdict, "take", "stale" or the reason it was rejected (gate.REJECT_REASONS)."""
        try:
            seq, time, q_des, hold = decode_command(payload, self.info.joint_names)
        except MalformedMessage as exc:
            reason = reject_reason(exc)
            self.firmware.reject(reason, str(exc))
            return reason
        return self._take(seq, time, np.array(q_des), hold)

    def operator(self, request: dict | bytes) -> dict:
        """Answer an operator request (``{"action": "reset"}``) as the server's ``.../operator`` does."""
        payload = request if isinstance(request, bytes) else json.dumps(request).encode()
        body, did = operator.answer(self.firmware, self.robot, self._current, payload)
        if did:
            self._servo_off = False
        return json.loads(body)

    def ground_truth(self) -> GroundTruth | None:
        """Ground truth of the tick of the last frame read (once the robot has stepped past it, only
        if ground_truth() was already called before that step); before the first read: the current."""
        self._want_truth = True
        last = self._last_read
        if last is None or last.seq == self._current.seq:
            return self._truth_of_now()
        if self._truth_before_step is not None and self._truth_before_step[0] == last.seq:
            return self._truth_before_step[1]
        return None

    def _truth_of_now(self) -> GroundTruth:
        """The robot's ground truth of the current tick, kept until it steps (a collection asks for it before the step
        that logs it)."""
        self._truth_now = (self._current.seq, self.robot.ground_truth())
        return self._truth_now[1]

    @property
    def robot_state(self) -> str:
        """Robot-side firmware state: waiting, running, holding or servo_off."""
        return self.firmware.state.name.lower()

    def status(self) -> dict:
        return {"robot": self.info.name, "clock": "inprocess", "seq": self._current.seq,
                "time": self._current.time, **self.firmware.status()}

    def close(self) -> None:
        if self._log is not None:
            self._log.close()
        super().close()



def from_config(hal: Section, *, port: int | None = None) -> InProcessBackend:
    """Build the robot of ``[hal.inprocess]`` (``robot = "module:callable"``, called as
    ``factory(scenario, **kwargs)``) behind the firmware of ``[hal.safety]`` (``port`` is not used)."""
    i = hal.section("inprocess")
    i.check_keys(["robot", "scenario", "log", "kwargs"])
    spec = i.str("robot")
    try:
        factory = import_object(spec)
    except HalError as exc:
        raise i.error("robot", spec, f"an importable 'module:callable' robot factory ({exc})") from exc
    scenario = i.str("scenario") if "scenario" in i else None
    kwargs = dict(i.section("kwargs", {}).data)
    robot = factory(scenario, **kwargs) if scenario is not None else factory(**kwargs)
    return InProcessBackend(robot, safety_config(hal), log=i.str("log") if "log" in i else None)
