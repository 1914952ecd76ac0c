"""Build :class:`ServoParams` from config/servo.toml, with every field validated."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from servotau.config import Section, load_toml

from .servo import EFFECTS, ServoParams

# Field -> (unit, lower bound, strict). Every field is per joint.
_BASE_FIELDS = {
    "kp": ("N m/rad", 0.0, True),
    "kd": ("N m s/rad", 0.0, False),
    "k_t": ("N m/A", 0.0, True),
    "b": ("N m s/rad", 0.0, False),
    "tau_c": ("N m", 0.0, False),
    "tau_s": ("N m", 0.0, False),
    "v_s": ("rad/s", 0.0, True),
    "v_eps": ("rad/s", 0.0, True),
    "i_deadzone": ("A", 0.0, False),
    "i_max": ("A", 0.0, True),
    "g_dir": ("-", -0.9, False),
}
_REQUIRED_BASE = ("kp", "kd", "k_t", "b", "tau_c")

# Hidden effect -> {parameter: (default when switched on, unit, lower bound, strict)}.
EFFECT_PARAMS: dict[str, dict[str, tuple[float, str, float, bool]]] = {
    "coulomb_asym": {"tau_c_asym": (3.0, "N m", -1e9, False)},
    "stribeck": {"tau_s": (6.0, "N m", 0.0, False), "v_s": (0.15, "rad/s", 0.0, True)},
    "deadzone": {"e_deadzone": (3e-3, "rad", 0.0, False)},
    "direction_gain": {"g_dir": (0.4, "-", -0.9, False)},
    "backlash": {"backlash": (4e-3, "rad", 0.0, True), "gear_k": (2e4, "N m/rad", 0.0, True),
                 "gear_d": (20.0, "N m s/rad", 0.0, False)},
    "load_friction": {"mu_load": (0.15, "-", 0.0, False)},
    "cogging": {"cog_amp": (3.0, "N m", 0.0, False), "cog_period": (0.08, "rad", 0.0, True)},
    "thermal_drift": {"thermal_alpha": (-0.02, "1/K", -1.0, False), "thermal_r": (2.0, "K/(A^2 s)", 0.0, False),
                      "thermal_tau": (30.0, "s", 0.0, True)},
    "saturation": {"i_max": (2.5, "A", 0.0, True)},
    "delay": {"delay_ticks": (8, "ticks", 0, False)},
    "elastic": {"gear_k": (3000.0, "N m/rad", 0.0, True), "gear_d": (10.0, "N m s/rad", 0.0, False)},
}
assert set(EFFECT_PARAMS) == set(EFFECTS)

# Values of the hidden-effect fields when no effect is on.
_OFF = {"tau_c_asym": 0.0, "e_deadzone": 0.0, "mu_load": 0.0, "cog_amp": 0.0, "cog_period": 1.0,
        "thermal_alpha": 0.0, "thermal_r": 0.0, "thermal_tau": 1.0, "delay_ticks": 0, "gear_k": 0.0,
        "gear_d": 0.0, "backlash": 0.0}


def _joint_list(sec: Section, joint_names: Sequence[str]) -> list[str]:
    raw = sec.data.get("joints")
    if raw == "all":
        return list(joint_names)
    if not isinstance(raw, list) or not raw or not all(isinstance(j, str) for j in raw):
        raise sec.error("joints", raw if raw is not None else "missing", '"all" or a non-empty list of joint names')
    for j in raw:
        if j not in joint_names:
            raise sec.error("joints", j, f"a joint name, one of {list(joint_names)}")
    return raw


def load_servo_params(
    path: str | Path, joint_names: Sequence[str], armature: np.ndarray, effects_override: dict | None = None
) -> ServoParams:
    """Read the servo file for ``joint_names`` (armature [kg m^2] is the reflected rotor inertia).

    ``effects_override`` replaces the file's ``[effects]`` table (same layout, used by tests and
    data generators to switch hidden effects on without writing a file).
    """
    root = load_toml(path)
    root.check_keys(["defaults", "groups", "joints", "effects"])
    n = len(joint_names)
    idx = {j: i for i, j in enumerate(joint_names)}
    values = {f: np.full(n, np.nan) for f in _BASE_FIELDS}
    defaults = root.section("defaults", {})
    defaults.check_keys(_BASE_FIELDS)
    for f, (unit, lo, strict) in _BASE_FIELDS.items():
        if f in defaults:
            values[f][:] = defaults.float(f, min=lo, strict_min=strict, unit=unit)

    def apply(sec: Section, joints: list[str]) -> None:
        sec.check_keys(["joints", *_BASE_FIELDS])
        for f, (unit, lo, strict) in _BASE_FIELDS.items():
            if f in sec:
                v = sec.float(f, min=lo, strict_min=strict, unit=unit)
                for j in joints:
                    values[f][idx[j]] = v

    groups = root.section("groups", {})
    for g in groups.keys():
        sec = groups.section(g)
        apply(sec, _joint_list(sec, joint_names))
    per_joint = root.section("joints", {})
    for j in per_joint.keys():
        if j not in idx:
            raise per_joint.error(j, "{...}", f"a joint name, one of {list(joint_names)}")
        apply(per_joint.section(j), [j])
    for f in _BASE_FIELDS:
        missing = [joint_names[i] for i in np.flatnonzero(np.isnan(values[f]))]
        if missing:
            if f in _REQUIRED_BASE or f not in defaults:
                raise root.error(f"groups.*.{f}", "missing", f"a value of '{f}' for joints {missing}")

    hidden = {f: np.full(n, v, dtype=int if f == "delay_ticks" else float) for f, v in _OFF.items()}
    if effects_override is None:
        effects = root.section("effects", {})
    else:
        effects = Section(effects_override, root.file, "effects")
    for name in effects.keys():
        if name not in EFFECT_PARAMS:
            raise effects.error(name, "{...}", f"a hidden effect, one of {list(EFFECTS)}")
        sec = effects.section(name)
        sec.check_keys(["joints", *EFFECT_PARAMS[name]])
        joints = [idx[j] for j in _joint_list(sec, joint_names)]
        for f, (default, unit, lo, strict) in EFFECT_PARAMS[name].items():
            if f == "delay_ticks":
                v = sec.int(f, default, min=0, max=1000)
            else:
                v = sec.float(f, default, min=lo, strict_min=strict, unit=unit)
            target = values if f in values else hidden
            target[f][joints] = v
    return ServoParams(**values, **hidden, motor_inertia=np.asarray(armature, dtype=float).copy())


def check_servo_file(path: str | Path, joint_names: Sequence[str]) -> ServoParams:
    """Read and validate the servo file ``path`` for ``joint_names`` before a robot is built from it: a missing
    joint or field, a negative or zero gain raise a :class:`~servotau.errors.ConfigError` naming the file, the
    field and the joints (armature taken as zero: only the file is checked)."""
    return load_servo_params(path, joint_names, np.zeros(len(joint_names)))
