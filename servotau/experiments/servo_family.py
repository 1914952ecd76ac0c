"""A family of simulated HRP-2 servos drawn around config/servo.toml (issue 22): servo files the controller was
not tuned on.

Each draw scales the nominal servo of every joint group independently (one draw per group, both legs alike):

| field | draw |
|---|---|
| kp (servo gain) | x U(0.6, 1.5) |
| kd, b (damping) | x U(0.5, 1.5), one factor for both |
| tau_c (Coulomb) | x U(0.5, 2) |
| tau_s (Stribeck breakaway above Coulomb) | U(0.2, 1.5) N m |
| i_deadzone (driver dead zone) | U(0.1, 0.5) A |
| g_dir (direction gain) | U(0, 0.15) |
| i_max (current limit) | U(10, 20) A |

The draws come from ``numpy.random.default_rng(seed)`` only; :func:`write_servo_file` writes a servo file with
the same field names as config/servo.toml (read back by :func:`servotau.simrobot.servo_config.load_servo_params`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

# field -> (kind, low, high): "scale" multiplies the nominal value, "value" replaces it
RANGES: dict[str, tuple[str, float, float]] = {
    "kp": ("scale", 0.6, 1.5),
    "damping": ("scale", 0.5, 1.5),  # kd and b
    "tau_c": ("scale", 0.5, 2.0),
    "tau_s": ("value", 0.2, 1.5),
    "i_deadzone": ("value", 0.1, 0.5),
    "g_dir": ("value", 0.0, 0.15),
    "i_max": ("value", 10.0, 20.0),
}


@dataclass(frozen=True)
class ServoDraw:
    """One servo of the family: the seed and, per joint group, the drawn factors and values."""

    seed: int
    groups: dict  # group name -> {field: drawn value} (RANGES' fields)


def draw(seed: int, nominal: str | Path | None = None) -> ServoDraw:
    """The draw of ``seed`` for every group of the nominal servo file (default config/servo.toml)."""
    from servotau.config import CONFIG_DIR, load_toml

    root = load_toml(nominal or CONFIG_DIR / "servo.toml")
    rng = np.random.default_rng(seed)
    groups = {}
    for name in root.section("groups").keys():
        groups[name] = {f: float(rng.uniform(lo, hi)) for f, (_, lo, hi) in RANGES.items()}
    return ServoDraw(seed, groups)


def _toml_value(v) -> str:
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(float(v))


def servo_mapping(d: ServoDraw, nominal: str | Path | None = None) -> dict:
    """The servo file's content for draw ``d``: the nominal file with every group's fields drawn."""
    from servotau.config import CONFIG_DIR, load_toml

    root = load_toml(nominal or CONFIG_DIR / "servo.toml")
    defaults = dict(root.section("defaults", {}).data)
    groups = {}
    for name in root.section("groups").keys():
        g = dict(root.section("groups").section(name).data)
        f = d.groups[name]
        g["kp"] = g["kp"] * f["kp"]
        g["kd"] = g["kd"] * f["damping"]
        g["b"] = g["b"] * f["damping"]
        g["tau_c"] = g["tau_c"] * f["tau_c"]
        for key in ("tau_s", "i_deadzone", "g_dir", "i_max"):
            g[key] = f[key]
        groups[name] = g
    return {"defaults": defaults, "groups": groups}


def write_servo_file(d: ServoDraw, path: str | Path, nominal: str | Path | None = None) -> Path:
    """Write the servo file of draw ``d`` (config/servo.toml's layout and field names)."""
    data = servo_mapping(d, nominal)
    lines = [f"# Servo of the family (servotau/experiments/servo_family.py), seed {d.seed}: config/servo.toml's",
             "# groups with drawn gains, damping, Coulomb and Stribeck friction, driver dead zone, direction gain and",
             "# current limit.",
             "", "[defaults]"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in data["defaults"].items()]
    for name, g in data["groups"].items():
        lines += ["", f"[groups.{name}]"] + [f"{k} = {_toml_value(v)}" for k, v in g.items()]
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text("\n".join(lines) + "\n")
    return p


# -- the chain on one draw, and the scores -------------------------------------------------------------------
def run_draw(seed: int, out: Path, k6: tuple[float, ...], *, effects: tuple[str, ...] | None = None,
             max_steps: int = 3, progress=None) -> dict:
    """The unattended chain on draw ``seed``: its servo file, ``servotau identify run`` on it (motor file), the
    motion experiment (position servo and torque control at each ``k6``) with that servo and motor file. Returns the
    row: errors per run [mrad], trips, and per K6 which (leg joint, mean|max) torque control wins."""
    import time

    from servotau.apps.identify import collect, sim_config_with_servo
    from servotau.identification.motor_file import CANDIDATES, build_motor_file, write_motor_file

    from .common import LEG_LABELS, run_label
    from .motion import motion_errors, motion_runs

    say = progress or (lambda _m: None)
    folder = out / f"draw_{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    servo = write_servo_file(draw(seed), folder / "servo.toml")
    start = time.perf_counter()
    sim = sim_config_with_servo(str(servo), "sim_identification.toml", folder / "sim_identification.toml")
    log = folder / "ident.parquet"
    collect("hal.toml", "inprocess", None, "identification.toml", None, sim, False, str(log),
            progress=lambda m: None)
    report = build_motor_file(log, None, candidates=effects or CANDIDATES, max_steps=max_steps)
    motors = write_motor_file(report, folder / "motors.toml")
    t_ident = time.perf_counter() - start
    say(f"draw {seed}: identified in {t_ident:.0f} s: "
        + "; ".join(f"{j}: {'+'.join(c.effects) or '-'}{' +db' if c.dead_band_kept else ''}"
                    for j, c in report.choices.items()))
    runs = motion_runs(False, folder / "motion", servo=str(servo.resolve()), motors=str(motors.resolve()), gains=k6)
    errors = {name: motion_errors(r) for name, r in runs.items()}
    pos_mean, pos_max = errors["position"]
    wins, tripped = {}, {}
    for g in k6:
        name = run_label(g)
        m, x = errors[name]
        tripped[name] = runs[name].tripped
        wins[name] = {label: {"mean": bool(m[j] < pos_mean[j] and not runs[name].tripped),
                              "max": bool(x[j] < pos_max[j] and not runs[name].tripped)}
                      for j, label in enumerate(LEG_LABELS)}
    say(f"draw {seed}: " + ", ".join(f"{n}: {sum(v for w in wins[n].values() for v in w.values())}/12"
                                     f"{' TRIP' if tripped[n] else ''}" for n in wins))
    return {"seed": seed, "servo": str(servo), "motors": str(motors), "identify_seconds": round(t_ident, 1),
            "choices": {j: c.to_dict() for j, c in report.choices.items()},
            "mean_mrad": {n: e[0].tolist() for n, e in errors.items()},
            "max_mrad": {n: e[1].tolist() for n, e in errors.items()},
            "tripped": tripped, "wins": wins}


def score(rows: list[dict], k6: tuple[float, ...]) -> dict:
    """Per K6: wins / cases over (draw, leg joint, mean|max), the share, and the draws that tripped."""
    from .common import run_label

    out = {}
    for g in k6:
        name = run_label(g)
        cases = [v for r in rows for w in r["wins"][name].values() for v in w.values()]
        out[name] = {"wins": int(sum(cases)), "cases": len(cases),
                     "share": round(sum(cases) / len(cases), 3) if cases else None,
                     "trips": [r["seed"] for r in rows if r["tripped"][name]]}
    return out
