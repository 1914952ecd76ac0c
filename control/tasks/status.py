"""The controller's status line, about once a second of robot time.

::

    t 12.0 s  torque  phase 2/3 swing  |q_ref-q| max 3.1 mrad RLEG_JOINT3  |tau_d-tau_hat| max 4.2 N m RLEG_JOINT2  ok

The worst tracking error ``|q_ref - q|`` (encoders) and the worst torque error ``|tau_d - tau_hat|`` (torque
joints in torque mode; ``-`` otherwise) are over the ticks since the last line; the last field is the safety
state (``ok``, ``TRIPPED <check>``, ``holding`` after a reset, ``stopping``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..loop import ControlLoop, LoopHook, Tick

STATUS_PERIOD = 1.0  # [s] robot time between two status lines


class StatusLine(LoopHook):
    """Prints :func:`status_text` every ``period`` [s] of robot time through ``emit`` (module doc)."""

    def __init__(self, loop: ControlLoop, emit: Callable[[str], None], runner=None, period: float = STATUS_PERIOD):
        self.loop, self.emit, self.runner, self.period = loop, emit, runner, period
        n = loop.info.nq
        self.names = loop.info.joint_names
        self.e_q, self.e_tau = np.zeros(n), np.zeros(n)
        self._next: float | None = None
        self.lines = 0

    def on_tick(self, tick: Tick) -> None:
        np.maximum(self.e_q, np.abs(tick.reference.q - tick.frame.q), out=self.e_q)
        terms = tick.terms
        if terms.mode == "torque":
            mask = self.loop.manager.torque_mask
            np.maximum(self.e_tau, np.abs(terms.e_tau) * mask, out=self.e_tau)
        t = float(tick.frame.time)
        if self._next is None:
            self._next = t + self.period
        if t + 1e-9 >= self._next:
            self._next += self.period * max(1, int((t - self._next) // self.period) + 1)
            self.emit(self.text(tick))
            self.e_q.fill(0.0)
            self.e_tau.fill(0.0)
            self.lines += 1

    def text(self, tick: Tick) -> str:
        manager = self.loop.manager
        jq = int(np.argmax(self.e_q))
        parts = [f"t {tick.frame.time:.1f} s", f"{manager.mode.value}"]
        if self.runner is not None:
            n = len(self.runner.phases)
            parts.append(f"phase {min(self.runner.index + 1, n)}/{n} {self.runner.phase_name}")
        parts.append(f"|q_ref-q| max {1e3 * self.e_q[jq]:.1f} mrad {self.names[jq]}")
        if self.e_tau.any():
            jt = int(np.argmax(self.e_tau))
            parts.append(f"|tau_d-tau_hat| max {self.e_tau[jt]:.1f} N m {self.names[jt]}")
        else:
            parts.append("|tau_d-tau_hat| -")
        if manager.tripped:
            parts.append(f"TRIPPED {manager.report.check} {manager.report.where}".rstrip())
        else:
            parts.append({"holding": "holding (reset)", "stopping": "stopping"}.get(self.loop.state, "ok"))
        return "  ".join(parts)
