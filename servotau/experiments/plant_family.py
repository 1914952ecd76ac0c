"""A family of single-joint position-servo plants, written independently of simrobot and of the workbench.

Issue 18, item 6: validate the model workbench (``servotau model diagnose``) on plants it was not built with.
Nothing here imports ``servotau.simrobot``, ``servotau.actuator`` or ``servotau.identification``: the physics is
written from first principles below, and the logs are plain tables ``t, q, q_des, tau`` (the workbench's
single-joint layout). The truth (which effects are hidden) rides in a side dict, never in the table.

Plant (angles and torques on the joint side of the gear, SI units)::

    command        r(t) = q_des(t - d)                                  d: delay (0 unless 'delay')
    servo (PD)     u = (1 - a_th H) (K (r - q_m) - D dq_m)  (H: heat, 'thermal_drift': the torque constant falls)
    driver         u' = dz(u, delta)              dead zone of the driver ('deadzone'), else u' = u
    motor          T_m dtau_m/dt = u' - tau_m     first-order current loop ('motor_lag'), else tau_m = u';
                                                  T_m 3 .. 30 ms, at most 0.7 D / K (the loop stays stable)
                   tau_m clipped to +-tau_max     ('saturation')
    friction       f(dq_m, q_m, tau_j): coulomb, coulomb_asym, stribeck, viscous_power, load_friction, cogging
    rigid joint    J ddq = tau_j - G sin(q + phi),   tau_j = tau_m - f,   q_m = q
    backlash       J_m ddq_m = tau_m - f - tau_j,  J ddq_l = tau_j - G sin(q_l + phi),
                   tau_j = k_c dz(q_m - q_l, b/2) + c_c (dq_m - dq_l) in contact, 0 inside the play
    log            q = round(q_m / res) res,  tau = tau_j + N(0, sigma) (+ c_th H, 'thermal_drift'),
                   sampled every Ts (1 .. 16 ms) from a 0.1 ms simulation

The clean plant (no hidden effect) obeys the paper's model exactly: ``q_des - q_m = tau_j / K + (D / K) dq_m``.
The plants are simulated side by side (numpy arrays over plants, one loop over fine steps).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

EFFECTS = ("coulomb", "coulomb_asym", "stribeck", "viscous_power", "backlash", "deadzone", "cogging",
           "thermal_drift", "load_friction", "motor_lag", "delay", "saturation")
DT = 1e-4        # [s] simulation step
RECORD = 1e-3    # [s] recording grid (every sample period is a multiple of it)
DURATION = 20.0  # [s] default log length
G_REF = 9.81
# Largest motor lag T [s] as a fraction of the servo's D / K [s]. With the lag, the loop J T s^3 + J s^2 + D s + K
# is stable only for T < D / K (Routh-Hurwitz, whatever J); at 0.7 D / K its least-damped pole keeps a damping
# ratio >= 0.077 for servo damping ratios 0.4 .. 1. A lag drawn beyond it (35 % of the 3 .. 30 ms draws) is clipped.
LAG_MARGIN = 0.7


@dataclass(frozen=True)
class Plant:
    """One plant: parameters, hidden effects with their parameters, and the command."""

    seed: int
    hidden: tuple[str, ...]
    K: float            # servo stiffness [N m/rad]
    D: float            # servo damping [N m s/rad]
    J: float            # link inertia [kg m^2]
    G: float            # gravity load amplitude [N m]
    phi: float          # gravity phase [rad]
    period: float       # sample period [s]
    sigma: float        # torque noise [N m]
    res: float          # encoder resolution [rad]
    tau_scale: float    # typical torque [N m] (effect sizes are fractions of it)
    command: tuple = ()  # segments, see command_of
    effect: dict = field(default_factory=dict)  # parameters of the hidden effects

    def truth(self) -> dict:
        """The side dict: what is hidden (never in the log)."""
        return {"seed": self.seed, "hidden": list(self.hidden), "period_ms": round(1e3 * self.period),
                "K": self.K, "D": self.D, "J": self.J, "G": self.G, "sigma": self.sigma, "res": self.res,
                "effect": {k: dict(v) for k, v in self.effect.items()}}


def _loguniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_command(rng, duration: float) -> tuple:
    """Holds, sinusoids at several amplitudes and frequencies, and a chirp, as (kind, t0, t1, a, f0, f1)."""
    kinds = ["sine", "chirp", "sine", "sine_slow"]
    rng.shuffle(kinds)
    seg = duration / len(kinds)
    out = []
    for i, kind in enumerate(kinds):
        t0, t1 = i * seg + 0.04 * duration, (i + 1) * seg - 0.03 * duration  # holds between the segments
        amp = _loguniform(rng, 0.05, 0.8)
        if kind == "sine":
            f0 = f1 = _loguniform(rng, 0.3, 2.0)
        elif kind == "sine_slow":
            f0 = f1 = _loguniform(rng, 0.05, 0.3)
        else:
            f0, f1 = _loguniform(rng, 0.1, 0.4), _loguniform(rng, 1.5, 4.0)
        amp = min(amp, 8.0 / (2 * math.pi * max(f0, f1)) ** 2 + 0.02)  # keep accelerations moderate
        out.append((kind, t0, t1, amp, f0, f1))
    return tuple(out)


def command_of(segments: tuple, offset: float, t: np.ndarray) -> np.ndarray:
    """q_des(t): offset plus each segment under a smooth (raised-cosine) envelope; holds between them."""
    t = np.asarray(t, dtype=float)
    q = np.full_like(t, offset)
    for _kind, t0, t1, amp, f0, f1 in segments:
        inside = (t > t0) & (t < t1)
        x = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
        ramp = 1 / 12  # of the segment (0.3 s in a 20 s log)
        env = np.clip(np.minimum(x, 1 - x) / ramp, 0.0, 1.0)
        env = 0.5 - 0.5 * np.cos(np.pi * env)
        phase = 2 * np.pi * (f0 * (t - t0) + 0.5 * (f1 - f0) * (t - t0) ** 2 / (t1 - t0))
        q = q + np.where(inside, amp * env * np.sin(phase), 0.0)
    return q


def draw_hidden(rng) -> tuple[str, ...]:
    """Clean (1/4), one effect (1/2) or a pair (1/4)."""
    x = rng.uniform()
    if x < 0.25:
        return ()
    if x < 0.75:
        return (str(rng.choice(EFFECTS)),)
    a, b = rng.choice(len(EFFECTS), size=2, replace=False)
    return tuple(sorted((EFFECTS[a], EFFECTS[b])))


def draw_plant(seed: int, hidden: tuple[str, ...] | None = None, *, period: float | None = None,
               duration: float = DURATION) -> Plant:
    """Plant ``seed``: parameters over wide ranges; ``hidden`` drawn from the seed unless given."""
    rng = np.random.default_rng([18, seed])
    if hidden is None:
        hidden = draw_hidden(rng)
    K = _loguniform(rng, 200.0, 5000.0)               # 25x range of servo stiffness
    J = _loguniform(rng, 0.02, 0.5)
    zeta = rng.uniform(0.4, 1.0)
    D = 2 * zeta * math.sqrt(K * J)
    G = rng.uniform(0.0, 1.0) * _loguniform(rng, 1.0, 30.0)
    phi = rng.uniform(-1.0, 1.0)
    if period is None:
        period = RECORD * int(round(_loguniform(rng, 1.0, 16.0)))
    command = draw_command(rng, duration)
    acc = max((2 * math.pi * max(f0, f1)) ** 2 * a for _k, _t0, _t1, a, f0, f1 in command)
    tau_scale = G + J * acc + 0.5
    sigma = _loguniform(rng, 0.002, 0.03) * tau_scale
    res = 2 * math.pi / 2 ** int(rng.integers(13, 21))
    p: dict[str, dict] = {}
    fr = lambda lo, hi: _loguniform(rng, lo, hi) * tau_scale  # noqa: E731  (a fraction of the torque scale)
    for e in hidden:
        if e == "coulomb":
            p[e] = {"fc": fr(0.03, 0.12)}
        elif e == "coulomb_asym":
            p[e] = {"fc_pos": fr(0.02, 0.1), "fc_neg": fr(0.02, 0.1) * 0.3}
        elif e == "stribeck":
            p[e] = {"fc": fr(0.02, 0.06), "fs": fr(0.04, 0.12), "vs": _loguniform(rng, 0.02, 0.2)}
        elif e == "viscous_power":
            p[e] = {"cv": fr(0.03, 0.12), "delta": rng.uniform(0.3, 0.6), "v_ref": 0.5}
        elif e == "backlash":
            p[e] = {"play": _loguniform(rng, 2e-3, 2e-2), "inertia_ratio": rng.uniform(0.05, 0.15)}
        elif e == "deadzone":
            p[e] = {"delta": fr(0.03, 0.1)}
        elif e == "cogging":
            p[e] = {"amp": fr(0.02, 0.08), "period": _loguniform(rng, 0.02, 0.2), "phase": rng.uniform(0, 6.28)}
        elif e == "thermal_drift":
            p[e] = {"gain_drop": rng.uniform(0.15, 0.35), "offset": fr(0.02, 0.06), "tau_th": rng.uniform(4, 10)}
        elif e == "load_friction":
            p[e] = {"mu": rng.uniform(0.05, 0.2)}
        elif e == "motor_lag":  # at most LAG_MARGIN D / K: the servo loop stays stable (see LAG_MARGIN)
            p[e] = {"T": min(_loguniform(rng, 3e-3, 3e-2), LAG_MARGIN * D / K)}
        elif e == "delay":
            p[e] = {"d": RECORD * 0.1 * int(round(10 * _loguniform(rng, 2.0, 15.0)))}
        elif e == "saturation":
            p[e] = {"fraction": rng.uniform(0.55, 0.8)}
        else:
            raise ValueError(f"unknown effect {e!r}: expected one of {EFFECTS}")
    return Plant(seed, tuple(hidden), K, D, J, G, phi, period, sigma, res, tau_scale, command, p)


def _dz(x, w):
    return np.sign(x) * np.maximum(np.abs(x) - w, 0.0)


def _col(plants, effect, key, default=0.0):
    return np.array([pl.effect[effect][key] if effect in pl.effect else default for pl in plants], dtype=float)


def simulate(plants: list[Plant], duration: float = DURATION, *, dt: float = DT) -> list[dict]:
    """Simulate the plants side by side; return per plant the true signals on the 1 ms grid.

    Each result has ``t``, ``q_des`` (the logged command), ``q`` (true motor-side angle), ``dq`` (its true
    velocity), ``tau`` (true joint torque), ``tau_m`` (motor torque), ``heat``.
    """
    n = len(plants)
    K = np.array([p.K for p in plants])
    D = np.array([p.D for p in plants])
    J = np.array([p.J for p in plants])
    G = np.array([p.G for p in plants])
    phi = np.array([p.phi for p in plants])
    offset = 0.3 * phi  # the command's rest angle
    steps = int(round(duration / dt))
    every = int(round(RECORD / dt))
    t_fine = np.arange(steps) * dt
    delay = _col(plants, "delay", "d")
    cmd_log = np.stack([command_of(p.command, o, t_fine) for p, o in zip(plants, offset, strict=True)])
    cmd_srv = cmd_log  # what the servo tracks: the logged command, delayed for the plants with a delay
    if np.any(delay > 0):
        cmd_srv = cmd_log.copy()
        for k in np.flatnonzero(delay > 0):
            cmd_srv[k] = command_of(plants[k].command, offset[k], t_fine - delay[k])
    # effects, as per-plant coefficients (zero when absent)
    fc = _col(plants, "coulomb", "fc") + _col(plants, "stribeck", "fc")
    fc_pos, fc_neg = _col(plants, "coulomb_asym", "fc_pos"), _col(plants, "coulomb_asym", "fc_neg")
    fs, vs = _col(plants, "stribeck", "fs"), _col(plants, "stribeck", "vs", 1.0)
    cv, cdelta = _col(plants, "viscous_power", "cv"), _col(plants, "viscous_power", "delta", 1.0)
    mu = _col(plants, "load_friction", "mu")
    cog, cog_p, cog_ph = _col(plants, "cogging", "amp"), _col(plants, "cogging", "period", 1.0), _col(
        plants, "cogging", "phase")
    dz_delta = _col(plants, "deadzone", "delta")
    t_lag = _col(plants, "motor_lag", "T")
    lag_a = np.where(t_lag > 0, 1 - np.exp(-dt / np.maximum(t_lag, 1e-12)), 1.0)
    g_drop, th_off, tau_th = (_col(plants, "thermal_drift", "gain_drop"), _col(plants, "thermal_drift", "offset"),
                              _col(plants, "thermal_drift", "tau_th", 1.0))
    tau_scale = np.array([p.tau_scale for p in plants])
    sat = _col(plants, "saturation", "fraction")
    tau_max = np.where(sat > 0, sat * tau_scale, np.inf)
    bl = np.array(["backlash" in p.effect for p in plants])
    half_play = _col(plants, "backlash", "play") / 2
    J_m = _col(plants, "backlash", "inertia_ratio") * J
    k_c = np.where(bl, np.minimum(20 * K, 0.2 * np.maximum(J_m, 1e-9) / dt ** 2), 0.0)
    c_c = 2 * 0.7 * np.sqrt(k_c * J_m)
    f_total = fc + fc_pos + fs + cv + mu * tau_scale + 1e-9
    v_eps = np.maximum(2e-3, 3 * f_total * dt / np.where(bl, np.maximum(J_m, 1e-9), J))
    # state: motor side q_m, v_m; link q_l, v_l (= motor side unless backlash); motor torque; joint torque; heat
    q_m = cmd_srv[:, 0].copy()
    q_l = q_m.copy()
    v_m = np.zeros(n)
    v_l = np.zeros(n)
    tau_m = G * np.sin(q_m + phi)
    tau_j = tau_m.copy()
    heat = np.zeros(n)
    n_rec = steps // every
    rec = {k: np.empty((n, n_rec)) for k in ("q", "dq", "tau", "tau_m", "heat")}
    # terms whose coefficient is zero for every plant of the batch add exact zeros: skipped, same result
    asym, stribeck, viscous = np.any(fc_pos) or np.any(fc_neg), np.any(fs), np.any(cv)
    load, cogging, deadzone, backlash = np.any(mu), np.any(cog), np.any(dz_delta), np.any(bl)
    drift, saturation = np.any(g_drop), np.any(sat)
    for i in range(steps):
        u = K * (cmd_srv[:, i] - q_m) - D * v_m
        if drift:
            u = (1 - g_drop * heat) * u
        if deadzone:
            u = np.where(dz_delta > 0, _dz(u, dz_delta), u)
        tau_m = tau_m + lag_a * (u - tau_m)
        if saturation:
            tau_m = np.clip(tau_m, -tau_max, tau_max)
        s = np.tanh(v_m / v_eps)
        f = fc * s
        if asym:
            f = f + np.where(v_m > 0, fc_pos, fc_neg) * np.abs(s)
        if stribeck:
            f = f + fs * s * np.exp(-(v_m / vs) ** 2)
        if viscous:
            f = f + cv * s * (np.abs(v_m) / 0.5) ** cdelta
        if load:
            f = f + mu * np.abs(tau_j) * s  # |tau_j| of the previous step
        if cogging:
            f = f + cog * np.sin(2 * np.pi * q_m / cog_p + cog_ph)
        heat = heat + dt * ((tau_m / tau_scale) ** 2 - heat) / tau_th
        # rigid joint: J a = tau_m - f - g(q)
        a = (tau_m - f - G * np.sin(q_m + phi)) / J
        tau_j = tau_m - f
        if backlash:  # two bodies and a contact through the play
            gap = q_m - q_l
            contact = np.abs(gap) > half_play
            tj_bl = np.where(contact, k_c * _dz(gap, half_play) + c_c * (v_m - v_l), 0.0)
            a_m = (tau_m - f - tj_bl) / np.maximum(J_m, 1e-9)
            a_l = (tj_bl - G * np.sin(q_l + phi)) / J
            tau_j = np.where(bl, tj_bl, tau_j)
            a = np.where(bl, a_m, a)
        if i % every == 0:  # the state and the torques it produces, at the same instant
            j = i // every
            rec["q"][:, j], rec["dq"][:, j], rec["tau"][:, j] = q_m, v_m, tau_j
            rec["tau_m"][:, j], rec["heat"][:, j] = tau_m, heat
        v_m = v_m + dt * a
        q_m = q_m + dt * v_m
        if backlash:
            v_l = np.where(bl, v_l + dt * a_l, v_m)
            q_l = np.where(bl, q_l + dt * v_l, q_m)
    t = np.arange(n_rec) * RECORD
    out = []
    for k, _p in enumerate(plants):
        r = {name: v[k] for name, v in rec.items()}
        r["t"] = t
        r["q_des"] = cmd_log[k, ::every][:n_rec]
        r["thermal_offset"] = th_off[k] * r["heat"]
        out.append(r)
    return out


def measure(plant: Plant, true: dict) -> dict:
    """The log a controller would write: sampled every ``plant.period``, quantised encoder, noisy torque."""
    step = int(round(plant.period / RECORD))
    rng = np.random.default_rng([18, plant.seed, 1])
    sl = slice(0, None, step)
    q = np.round(true["q"][sl] / plant.res) * plant.res
    tau = true["tau"][sl] + true["thermal_offset"][sl] + rng.normal(0.0, plant.sigma, q.size)
    return {"t": true["t"][sl].copy(), "q": q, "q_des": true["q_des"][sl].copy(), "tau": tau}


def write_csv(log: dict, path) -> None:
    """The log as the workbench reads it: a CSV with columns t, q, q_des, tau."""
    cols = ("t", "q", "q_des", "tau")
    data = np.column_stack([log[c] for c in cols])
    np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="", fmt="%.10g")
