"""Plays a recorded log through the Backend interface (offline estimation, regression tests)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from servotau.config import Section

from ..backend import Backend
from ..errors import EndOfLog
from ..log import LogReader
from ..types import GroundTruth, SensorFrame


class ReplayBackend(Backend):
    """:meth:`read` returns the recorded frames in order (arrays equal to the recorded ones), then
    raises :class:`EndOfLog`; :meth:`write` records the commands (never applied) in :attr:`commands`.
    :meth:`ground_truth` gives the recorded truth of the last frame read, if the log has it."""

    def __init__(self, path: str | Path):
        self.log = LogReader(path)
        self.path = Path(path)
        self._frames = list(self.log.frames())
        if not self._frames:
            raise EndOfLog(f"{self.path}: the log has no frame: expected at least one row")
        self._next = 0
        self.commands: list[tuple[int, np.ndarray]] = []  # (seq answered, q_des [rad]) per write
        super().__init__(self.log.info, self._frames[0])

    def __len__(self) -> int:
        return len(self._frames)

    def read(self, timeout: float | None = None) -> SensorFrame:
        if self._next >= len(self._frames):
            raise EndOfLog(f"{self.path}: end of log after {len(self._frames)} frames "
                           f"(last seq {self._frames[-1].seq})")
        frame = self._frames[self._next]
        self._next += 1
        return self._returned(frame)

    def _send(self, q_des: np.ndarray, answers: SensorFrame) -> None:
        self.commands.append((answers.seq, q_des.copy()))

    def commands_array(self) -> tuple[np.ndarray, np.ndarray]:
        """``(seq (k,), q_des (k, nq))`` of the recorded writes."""
        seq = np.array([s for s, _ in self.commands], dtype=np.int64)
        q = np.array([q for _, q in self.commands]).reshape(len(self.commands), self.info.nq)
        return seq, q

    def ground_truth(self) -> GroundTruth | None:
        return self.log.truth(max(self._next - 1, 0))

    def status(self) -> dict:
        return {"robot": self.info.name, "clock": "replay", "path": str(self.path), "frames": len(self._frames),
                "next": self._next, "commands": len(self.commands)}


def from_config(hal: Section, *, port: int | None = None) -> ReplayBackend:
    """Open a :class:`ReplayBackend` on ``[hal.replay] log`` (``port`` is not used)."""
    r = hal.section("replay")
    r.check_keys(["log"])
    path = r.str("log")
    if not Path(path).exists():
        raise r.error("log", path, "an existing log file (.parquet)")
    return ReplayBackend(path)
