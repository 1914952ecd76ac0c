"""Which decoded commands the robot side takes: the checks of docs/protocol.md "Validation" that need the
robot's own history (the frames it published, the commands it applied), shared by the server and the
in-process backend.

A command ``(seq, time)`` is, in this order:

- ``future``: it answers a frame not published yet;
- ``replay``: it answers the frame whose command was already applied (a copy never re-arms the watchdog);
- ``too_old`` (realtime only): it answers a frame more than ``max_age_ticks`` older than the newest;
- ``time``: its time is not the time of the frame it answers (known for the last ``HISTORY`` frames);
- stale: it answers a frame older than the current one (lock-step) or than the frame whose command was
  applied last (realtime): counted, not applied, not an error (a late duplicate);
- else taken.
"""

from __future__ import annotations

import numpy as np

HISTORY = 4096  # frames whose time is remembered (> any max_command_age_ticks)

REJECT_REASONS = ("header", "version", "flags", "counts", "values", "not_claimer", "future", "time", "replay",
                  "too_old")
"""Counted reasons of a rejected command: the first five from decoding (hal/wire/protocol.py), the others
from :class:`CommandGate`."""

TAKE, STALE = "take", "stale"


class CommandGate:
    """Published frames and applied commands of one robot; :meth:`check` classifies a decoded command."""

    def __init__(self, lockstep: bool, max_age_ticks: int):
        self.lockstep = lockstep
        self.max_age_ticks = int(max_age_ticks)
        self._seqs = np.full(HISTORY, -1, dtype=np.int64)
        self._times = np.zeros(HISTORY)
        self.newest = -1  # seq of the newest published frame
        self.applied_seq = -1  # seq answered by the last applied command

    def published(self, seq: int, time: float) -> None:
        """Frame ``seq`` with robot time ``time`` [s] is on the wire."""
        self._seqs[seq % HISTORY], self._times[seq % HISTORY] = seq, time
        self.newest = max(self.newest, seq)

    def applied(self, seq: int) -> None:
        """The command answering frame ``seq`` was applied."""
        self.applied_seq = max(self.applied_seq, seq)

    def check(self, seq: int, time: float) -> tuple[str, str]:
        """``(verdict, message)``: verdict TAKE, STALE, or a reason of :data:`REJECT_REASONS`."""
        if seq > self.newest:
            return "future", f"answers frame {seq}, not published yet (newest: {self.newest})"
        if seq == self.applied_seq:
            return "replay", f"answers frame {seq}, whose command was already applied"
        age = self.newest - seq
        if not self.lockstep and age > self.max_age_ticks:
            return "too_old", f"answers frame {seq}, {age} ticks old: expected <= max_command_age_ticks = " \
                              f"{self.max_age_ticks}"
        i = seq % HISTORY
        if self._seqs[i] == seq and time != self._times[i]:
            return "time", f"answering frame {seq} carries time {time!r}: expected its frame's time " \
                           f"{self._times[i]!r} [s]"
        if seq < self.applied_seq or (self.lockstep and seq != self.newest):
            return STALE, f"answers frame {seq}, older than the current one"
        return TAKE, ""


class PendingCommand:
    """Realtime: the newest admitted command received during a tick, applied at its end, and the oldest frame
    answered by a COMMAND_HOLD command among those received (a controller that fell behind sends several at once:
    the robot holds the posture of the first one's frame)."""

    def __init__(self):
        self.clear()

    def clear(self) -> None:
        self._command: tuple[np.ndarray, float, int, bool] | None = None  # (q_des [rad], received [s], seq, hold)
        self._hold_seq: int | None = None

    def offer(self, q_des: np.ndarray, received: float, seq: int, hold: bool) -> bool:
        """A command answering frame ``seq``; False if an already pending one answers a newer frame (stale)."""
        if hold:
            self._hold_seq = seq if self._hold_seq is None else min(self._hold_seq, seq)
        if self._command is not None and seq < self._command[2]:
            return False
        self._command = (q_des, received, seq, hold)
        return True

    def take(self) -> tuple[np.ndarray, float, int, bool, int] | None:
        """``(q_des, received, seq, hold, first)`` of the newest command, ``first`` the seq the hold starts from (the
        oldest HOLD command's frame, else ``seq``), and clear; None if none came."""
        command, hold_seq = self._command, self._hold_seq
        self.clear()
        if command is None:
            return None
        return (*command, hold_seq if command[3] and hold_seq is not None else command[2])
