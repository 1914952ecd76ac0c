"""Integral of the joint-position error, added to the desired torque of eq. 12 (not in the paper).

::

    tau_iq = P K_s i_q                                                       [N m]
    i_q   <- clip(i_q + dt k_iq [|dq_d| < v_rest] P e_q, -limit, limit)      [rad]
    P      = I - J^T (J J^T)^+ J     (J: the force task's regulated rows on the integrating joints; I without one)

At a low position stiffness K_s (K6 = 0.1) a joint at rest stays wherever static friction and the motor
model's error at rest leave it, (model error) / K6 away from its reference. The integral removes that offset.
It integrates only while the joint's reference is at rest (conditional integration: during a motion the
tracking error is dynamic and an integral winds up, docs/control.md), and it is clamped to ``limit`` [rad] of
equivalent position error. With a force task, the integral and its torque are projected out of the task's
directions (``J tau_iq = 0``), so it does not fight the force feedback: a joint-space integral there pushed the
contact and cost the force task's apex error 1-3 points (docs/control.md).
"""

from __future__ import annotations

import numpy as np

from servotau.errors import ControlError


class PositionIntegral:
    """Conditional, clamped, task-projected integral of ``e_q``; its output ``tau`` (n,) [N m] is refreshed in
    place by :meth:`update`."""

    def __init__(self, k_s: np.ndarray, k_iq: np.ndarray, limit: np.ndarray, rest_velocity: float, period: float):
        """
        Args:
            k_s: (n,) [N m/rad] position stiffness of eq. 12.
            k_iq: (n,) [1/s] integral rate (1 / integral time), 0 on joints without the integral.
            limit: (n,) [rad] clamp of the integral ``|i_q|``.
            rest_velocity: [rad/s] the integral runs on a joint while ``|dq_d| <`` this.
            period: [s] control period.
        """
        arrays = {}
        for name, value, unit in (("k_s", k_s, "N m/rad"), ("k_iq", k_iq, "1/s"), ("limit", limit, "rad")):
            arr = np.array(value, dtype=float)
            if arr.ndim != 1 or arr.shape != np.shape(k_s) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ControlError(f"PositionIntegral {name} = {value!r}: expected {np.size(k_s)} finite numbers "
                                   f">= 0 [{unit}]")
            arrays[name] = arr
        if not rest_velocity > 0 or not np.isfinite(rest_velocity):
            raise ControlError(f"rest_velocity = {rest_velocity!r}: expected a finite number > 0 [rad/s]")
        if not period > 0 or not np.isfinite(period):
            raise ControlError(f"period = {period!r}: expected a finite number > 0 [s]")
        self.k_s, self.limit = arrays["k_s"], arrays["limit"]
        self._rate = arrays["k_iq"] * period  # [1/tick]
        self.rest_velocity = float(rest_velocity)
        self.active = bool(np.any(self._rate > 0))
        self._cols = np.flatnonzero(self._rate > 0)  # integrating joints
        self._eye = np.eye(self._cols.size)
        n = self.k_s.size
        self.i_q = np.zeros(n)  # [rad] integral state
        self.tau = np.zeros(n)  # [N m] output
        self._v = np.zeros(n)

    def reset(self) -> None:
        """Empty the integral (on entering torque mode)."""
        self.i_q.fill(0.0)
        self.tau.fill(0.0)

    def update(self, e_q: np.ndarray, dq_d: np.ndarray, task_jacobian: np.ndarray | None = None) -> np.ndarray:
        """Advance one tick and return ``tau`` (n,) [N m].

        Args:
            e_q: (n,) [rad] ``q_d - q_hat``.
            dq_d: (n,) [rad/s] reference velocity (the integral runs where ``|dq_d| < rest_velocity``).
            task_jacobian: (k, n) regulated rows of the force task at this tick, or None.
        """
        if not self.active:
            return self.tau
        cols, v = self._cols, self._v
        proj = None if task_jacobian is None else self._projector(task_jacobian[:, cols])
        np.multiply(self._rate * (np.abs(dq_d) < self.rest_velocity), e_q, out=v)
        self.i_q[cols] += v[cols] if proj is None else proj @ v[cols]
        np.clip(self.i_q, -self.limit, self.limit, out=self.i_q)
        np.multiply(self.k_s, self.i_q, out=v)
        self.tau[cols] = v[cols] if proj is None else proj @ v[cols]
        return self.tau

    def _projector(self, jac: np.ndarray) -> np.ndarray:
        """``I - J^T (J J^T)^+ J``: the orthogonal projector onto the null space of ``J`` (k, integrating joints)."""
        x = np.linalg.lstsq(jac @ jac.T, jac, rcond=1e-10)[0]  # (J J^T)^+ J
        return self._eye - jac.T @ x
