"""The closed low-level position servo of one HRP-2-like actuator, vectorised over joints.

Only desired angles go in, as on the real robot. Per joint, every 1 ms tick::

    q_des --(command delay)--> e = q_des - q_motor --(position dead zone)-->
    i_cmd = (kp (1 + g_dir sign(dq)) e - kd dq) / k_t --(driver dead zone, saturation)--> i
    tau = k_t i - friction(dq, load, temperature) - cogging(q)

All quantities are on the joint side of the gear: ``kp`` [N m/rad], ``kd`` [N m s/rad],
``k_t`` [N m/A] (motor torque constant times gear ratio), currents [A]. With every effect off
and no dead zone, the static relation is the paper's eq. 6 with
``k_tau = 1/kp`` and ``k_v = (kd + b)/kp``.

The servo's parameters and state live only in simrobot/: the controller side never sees them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

EFFECTS = (
    "coulomb_asym",
    "stribeck",
    "deadzone",
    "direction_gain",
    "backlash",
    "load_friction",
    "cogging",
    "thermal_drift",
    "saturation",
    "delay",
    "elastic",
)
"""Hidden effects the paper's linear model lacks; all off by default (see config/servo.toml)."""


@dataclass(frozen=True)
class ServoParams:
    """Per-joint servo parameters, arrays of shape (n,) in RobotInfo joint order."""

    kp: np.ndarray  # [N m/rad] position gain (joint-side torque per rad of error)
    kd: np.ndarray  # [N m s/rad] velocity gain
    k_t: np.ndarray  # [N m/A] joint-side torque constant
    i_deadzone: np.ndarray  # [A] driver dead zone on the current command
    i_max: np.ndarray  # [A] current saturation
    g_dir: np.ndarray  # [-] gain change with the sign of the velocity: kp (1 + g_dir sign(dq))
    b: np.ndarray  # [N m s/rad] viscous friction
    tau_c: np.ndarray  # [N m] Coulomb friction
    tau_s: np.ndarray  # [N m] Stribeck (breakaway) friction above Coulomb
    v_s: np.ndarray  # [rad/s] Stribeck velocity
    v_eps: np.ndarray  # [rad/s] smoothing of sign(dq) in friction (tanh(dq / v_eps))
    # Hidden effects (zero means off).
    tau_c_asym: np.ndarray  # [N m] Coulomb asymmetry: friction is tau_c + tau_c_asym moving up, tau_c - tau_c_asym down
    e_deadzone: np.ndarray  # [rad] dead zone on the position error
    mu_load: np.ndarray  # [-] load-dependent friction: mu_load |tau|
    cog_amp: np.ndarray  # [N m] position-periodic ripple amplitude
    cog_period: np.ndarray  # [rad] ripple period in joint angle
    thermal_alpha: np.ndarray  # [1/K] friction change per kelvin (negative: friction falls when warm)
    thermal_r: np.ndarray  # [K/(A^2 s)] heating per squared current
    thermal_tau: np.ndarray  # [s] thermal time constant
    delay_ticks: np.ndarray  # [ticks] command delay (int)
    gear_k: np.ndarray  # [N m/rad] gear stiffness (0: rigid)
    gear_d: np.ndarray  # [N m s/rad] gear damping
    backlash: np.ndarray  # [rad] total backlash width (0: none)
    motor_inertia: np.ndarray = field(default=None)  # [kg m^2] reflected rotor inertia (elastic joints)

    @property
    def n(self) -> int:
        return len(self.kp)

    @property
    def flexible(self) -> np.ndarray:
        """Joints whose gear is simulated as a spring (elastic or backlash): motor-side state."""
        return (self.gear_k > 0) | (self.backlash > 0)

    def k_tau_nominal(self) -> np.ndarray:
        """The paper's k_tau = 1/kp [rad/(N m)] of the linear part."""
        return 1.0 / self.kp

    def k_v_nominal(self) -> np.ndarray:
        """The paper's k_v = (kd + b)/kp [rad/(rad/s)] of the linear part."""
        return (self.kd + self.b) / self.kp


class Servo:
    """State and update of all the joints' servos (vectorised, no allocation in :meth:`torque`)."""

    def __init__(self, params: ServoParams, period: float):
        self.p = params
        self.period = period  # [s]
        n = params.n
        self.enabled = True
        max_delay = int(np.max(params.delay_ticks)) if n else 0
        self._cmd_hist = np.zeros((max_delay + 1, n))
        self._hist_i = 0
        self._primed = False
        self.temperature = np.zeros(n)  # [K] above ambient
        self.current = np.zeros(n)  # [A]
        self.tau_motor = np.zeros(n)  # [N m] motor torque through the gear (before friction)
        self.tau_prev = np.zeros(n)  # [N m] last transmitted torque (for load friction)
        self._idx = np.arange(n)

    def delayed_command(self, q_des: np.ndarray) -> np.ndarray:
        """Push ``q_des`` into the command history and return what each joint's servo sees now."""
        h = self._cmd_hist
        if not self._primed:
            h[:] = q_des
            self._primed = True
        self._hist_i = (self._hist_i + 1) % h.shape[0]
        h[self._hist_i] = q_des
        return h[(self._hist_i - self.p.delay_ticks) % h.shape[0], self._idx]

    def motor_torque(self, q_cmd: np.ndarray, q_m: np.ndarray, dq_m: np.ndarray) -> np.ndarray:
        """Torque the motor puts through the gear [N m] for servo input ``q_cmd`` [rad] at motor-side
        angle ``q_m`` [rad] and velocity ``dq_m`` [rad/s]; updates ``current``."""
        p = self.p
        if not self.enabled:
            self.current[:] = 0.0
            self.tau_motor[:] = 0.0
            return self.tau_motor
        e = q_cmd - q_m
        e = np.sign(e) * np.maximum(np.abs(e) - p.e_deadzone, 0.0)
        kp = p.kp * (1.0 + p.g_dir * np.tanh(dq_m / p.v_eps))  # smooth sign: no chatter at rest
        i_cmd = (kp * e - p.kd * dq_m) / p.k_t
        i = np.sign(i_cmd) * np.maximum(np.abs(i_cmd) - p.i_deadzone, 0.0)
        np.clip(i, -p.i_max, p.i_max, out=self.current)
        np.multiply(p.k_t, self.current, out=self.tau_motor)
        return self.tau_motor

    def friction(self, q_m: np.ndarray, dq_m: np.ndarray) -> np.ndarray:
        """Friction and ripple torque [N m] opposing the motion (subtracted from the motor torque)."""
        p = self.p
        s = np.tanh(dq_m / p.v_eps)
        heat = 1.0 + p.thermal_alpha * self.temperature
        coulomb = (p.tau_c + p.tau_s * np.exp(-((dq_m / p.v_s) ** 2)) + p.mu_load * np.abs(self.tau_prev)) * s
        asym = p.tau_c_asym * np.abs(s)
        cog = p.cog_amp * np.sin(2.0 * np.pi * q_m / p.cog_period)
        return heat * (p.b * dq_m + coulomb) + asym + cog

    def damping(self, dq_m: np.ndarray) -> np.ndarray:
        """Slope -d(motor torque - friction)/d(dq) [N m s/rad] at velocity ``dq_m``: the part the
        simulator integrates implicitly (a stiff servo and a steep Coulomb slope chatter at 1 kHz when
        integrated explicitly)."""
        p = self.p
        active = (np.abs(self.current) > 0.0) & (np.abs(self.current) < p.i_max) & self.enabled
        sech2 = 1.0 - np.tanh(dq_m / p.v_eps) ** 2
        coulomb = p.tau_c + p.tau_s * np.exp(-((dq_m / p.v_s) ** 2)) + p.mu_load * np.abs(self.tau_prev)
        return p.kd * active + (1.0 + p.thermal_alpha * self.temperature) * (p.b + coulomb * sech2 / p.v_eps)

    def heat(self) -> None:
        """Advance the winding temperature by one period (dissipated power heats, ambient cools)."""
        p = self.p
        self.temperature += self.period * (p.thermal_r * self.current**2 - self.temperature / p.thermal_tau)
