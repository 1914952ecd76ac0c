"""A tiny simulated robot without physics: 30 joints, first-order position servos, seeded noise.

It serves the HAL's tests and benchmarks (``python -m servotau.hal --robot servotau.simrobot.fake:FakeRobot``)
where the HRP-2 simulation would only cost time; it loads neither MuJoCo nor Pinocchio.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from servotau.errors import ConfigError
from servotau.hal.types import GroundTruth, RobotInfo, SensorFrame


class FakeRobot:
    """Implements :class:`servotau.hal.robot.served.ServedRobot` without physics (deterministic for a given seed)."""

    def __init__(self, scenario: str | None = None, *, seed: int = 0, n_joints: int = 30, period: float = 1e-3,
                 time_constant: float = 0.02, noise: float = 1e-4, name: str = "fake",
                 encoder_faults: list[dict] | tuple = ()):
        names = tuple(f"J{i:02d}" for i in range(n_joints))
        self.info = RobotInfo(name=name, joint_names=names, q_min=np.full(n_joints, -1.5),
                              q_max=np.full(n_joints, 1.5), period=period, model_path="")
        self.time_constant = time_constant  # [s]
        self.noise = noise  # [rad] encoder noise standard deviation
        self._rng = np.random.default_rng(seed)
        self._q = 0.1 * np.sin(np.arange(n_joints))  # [rad]
        self._dq = np.zeros(n_joints)  # [rad/s]
        self._seq = 0
        self._off = False
        self._frame: SensorFrame | None = None
        self._last_q: np.ndarray | None = None  # the previous frame's encoder reading (stale faults)
        self._zero_truth: GroundTruth | None = None
        self.applied: list[np.ndarray] = []  # q_des received by step(), for tests
        # Scripted encoder faults (tests, bench/faults.py): {"kind": "nan" | "stale", "start": [s],
        # "duration": [s], "joints": [names] (optional: all)}, in robot time.
        self.encoder_faults = tuple(_encoder_fault(f, names) for f in encoder_faults)

    def _wrenches(self) -> np.ndarray:
        w = np.zeros((4, 6))
        w[0:2, 2] = 270.0  # [N] about half of a 55 kg robot's weight on each ankle
        return w

    def read(self) -> SensorFrame:
        if self._frame is None or self._frame.seq != self._seq:
            r = self._rng
            n = self.info.nq
            self._frame = SensorFrame(
                time=self._seq * self.info.period,
                seq=self._seq,
                q=self._q + self.noise * r.standard_normal(n),
                imu_angular_velocity=1e-3 * r.standard_normal(3),
                imu_linear_acceleration=np.array([0.0, 0.0, 9.81]) + 1e-2 * r.standard_normal(3),
                wrenches=self._wrenches() + 0.5 * r.standard_normal((4, 6)),
                status=np.zeros(6, dtype=np.uint8),
            )
            self._apply_faults()
        return self._frame

    def _apply_faults(self) -> None:
        f, prev = self._frame, self._last_q
        for kind, start, duration, joints in self.encoder_faults:
            if start <= f.time < start + duration:
                f.q[joints] = np.nan if kind == "nan" or prev is None else prev[joints]
                f.status[0] = max(int(f.status[0]), 2 if kind == "nan" else 1)  # STATUS_INVALID / STATUS_STALE
        self._last_q = f.q.copy()

    def step(self, q_des: np.ndarray) -> None:
        q_des = np.asarray(q_des, dtype=float)
        assert q_des.shape == (self.info.nq,) and np.isfinite(q_des).all(), q_des
        self.applied.append(q_des.copy())
        self._dq = np.zeros(self.info.nq) if self._off else (q_des - self._q) / self.time_constant
        self._q = self._q + self._dq * self.info.period
        self._seq += 1

    def servo_off(self) -> None:
        self._off = True

    def servo_on(self) -> None:
        """Servos back on (the operator's reset of a latched servo-off)."""
        self._off = False

    def ground_truth(self) -> GroundTruth:
        n = self.info.nq
        if self._zero_truth is None:  # every field, zeros
            self._zero_truth = GroundTruth.from_vector(0.0, 0, np.zeros(100 * n + 1000), n)
        return replace(self._zero_truth, time=self._seq * self.info.period, seq=self._seq, q=self._q.copy(),
                       dq=self._dq.copy(), base_position=np.array([0.0, 0.0, 0.65]),
                       base_quat_wxyz=np.array([1.0, 0.0, 0.0, 0.0]), wrenches=self._wrenches())


def _encoder_fault(f: dict, names: tuple[str, ...]) -> tuple[str, float, float, np.ndarray]:
    """``(kind, start [s], duration [s], joint indices)`` of one scripted encoder fault."""
    if not isinstance(f, dict) or f.get("kind") not in ("nan", "stale") or not {"kind", "start", "duration"} <= set(f):
        raise ConfigError(f'encoder fault {f!r}: expected {{"kind": "nan" | "stale", "start": s, "duration": s, '
                         '"joints": [names] (optional)}')
    unknown = [j for j in f.get("joints", names) if j not in names]
    if unknown:
        raise ConfigError(f"encoder fault joints {unknown}: expected joints of the robot {list(names)}")
    joints = [names.index(j) for j in f.get("joints", names)]
    return f["kind"], float(f["start"]), float(f["duration"]), np.array(joints, dtype=int)
