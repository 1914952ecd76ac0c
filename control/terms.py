"""Per-tick outputs of the controller, preallocated once and refreshed in place (for streaming and logs).

The command splits into the components of the paper's section 5.5 (all in [rad] of ``dq_err``)::

    dq_err = q_des - q = ff_torque + ff_friction + ff_extra + fb_position + fb_velocity + fb_acceleration
                         + fb_force + fb_torque_residual + fb_integral + fb_position_integral + position_command
                         + switch_offset

- ``ff_torque``          K_tau (M ddq_d + h - J^T f_d)  (contacts not regulated: their measured wrench)
- ``ff_friction``        K_v dq_ff + k_c tanh(dq_s / v_s), dq_ff = dq_hat (the paper) or dq_d, dq_s = dq_ff or
  dq_d (config ``velocity_feedforward``)
- ``ff_extra``           the motor model's extra effect terms (model workbench: deadzone, direction_gain,
  stribeck, delay, ...), i.e. the model's prediction at (tau*, dq_hat, q_hat, ...) minus its paper part
- ``fb_position``        K6 e_q = K_tau (1 + K_p) K_s e_q
- ``fb_velocity``        K7 de_q = K_tau (1 + K_p) K_d de_q
- ``fb_acceleration``    K8 dde_q = K_tau K_p M (ddq_d - ddq_hat)
- ``fb_force``           K9 e_f = -K_tau (K_p J^T (I + K_f) + J^T K_f) e_f
- ``fb_torque_residual`` -K_tau K_p (tau_hat - (M ddq_hat + h - J^T f_hat)): the part of the torque feedback
  not explained by the model (0 when the estimator's torque is the model's, as the paper assumes)
- ``fb_integral``        K_tau K_i integral(e_tau)
- ``fb_position_integral`` K_tau (1 + K_p) tau_iq, the conditional position integral (control/position_integral.py;
  not in the paper)
- ``position_command``   q_ref - q on position-controlled joints (every joint in position mode), q_hold - q in hold
- ``switch_offset``      the fading offset of a bumpless mode switch

The ``fb_*`` and ``ff_*`` terms are 0 on position-controlled joints and outside torque mode.
"""

from __future__ import annotations

import numpy as np

from servotau.errors import ControlError

COMPONENTS: tuple[str, ...] = (
    "ff_torque",
    "ff_friction",
    "ff_extra",
    "fb_position",
    "fb_velocity",
    "fb_acceleration",
    "fb_force",
    "fb_torque_residual",
    "fb_integral",
    "fb_position_integral",
    "position_command",
    "switch_offset",
)
"""Components of the command, each (n,) [rad]; they sum to ``dq_err``."""

TORQUE_COMPONENTS: tuple[str, ...] = COMPONENTS[:10]
"""The components of the torque law (eq. 13-14 plus extra motor-model terms, residual and integrals)."""

SIGNALS: tuple[str, ...] = ("q_des", "dq_err", "tau_d", "tau_star", "tau_hat", "e_tau", "e_q", "de_q", "dde_q")
"""Other joint signals, each (n,): [rad], [rad], [N m] x 4, [rad], [rad/s], [rad/s^2]."""

WRENCHES: tuple[str, ...] = ("f_d", "f_hat", "e_f")
"""Force-task wrenches, each (6,) [N, N m] at the task frame (0 without a force task)."""


class ControlTerms:
    """Every output of one tick; arrays keep their identity from tick to tick (stream them by reference)."""

    def __init__(self, n: int, shared: dict[str, np.ndarray] | None = None):
        """Zero arrays for ``n`` joints; ``shared`` names arrays that are used as they are (the producer's own
        output buffers, to avoid a copy per tick)."""
        self.time = float("nan")  # [s] robot time of the frame
        self.seq = -1  # frame sequence number
        self.mode = "position"  # Mode value of this tick
        self.tripped = False  # True once a safety check tripped (latched)
        for name in COMPONENTS + SIGNALS:
            setattr(self, name, np.zeros(n))
        for name in WRENCHES:
            setattr(self, name, np.zeros(6))
        for name, arr in (shared or {}).items():
            expected = getattr(self, name, None)
            if expected is None or np.shape(arr) != expected.shape:
                raise ControlError(f"shared[{name!r}]: expected a known output of shape {np.shape(expected)}")
            setattr(self, name, arr)

    def components(self) -> dict[str, np.ndarray]:
        """The command components by name (the arrays themselves, not copies)."""
        return {name: getattr(self, name) for name in COMPONENTS}

    def component_sum(self, out: np.ndarray | None = None) -> np.ndarray:
        """Sum of :data:`COMPONENTS` (equals ``dq_err``)."""
        out = np.zeros_like(self.dq_err) if out is None else out
        out.fill(0.0)
        for name in COMPONENTS:
            out += getattr(self, name)
        return out

    def as_dict(self) -> dict[str, object]:
        """A copy of everything, for logging."""
        arrays = {name: getattr(self, name).copy() for name in COMPONENTS + SIGNALS + WRENCHES}
        return {"time": self.time, "seq": self.seq, "mode": self.mode, "tripped": self.tripped, **arrays}
