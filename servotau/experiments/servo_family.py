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

import json
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
             max_steps: int = 3, progress=None, reuse_identification: bool = False) -> dict:
    """The unattended chain on draw ``seed``: its servo file, ``servotau identify run`` on it (motor file), the
    motion experiment (position servo and torque control at each ``k6``) with that servo and motor file. Returns the
    row: errors per run [mrad], trips, and per K6 which (leg joint, mean|max) torque control wins.

    ``reuse_identification``: keep the motor file of an earlier run of this draw under ``out`` (its
    ``identification.json`` and ``motors.toml``, for the same servo file) and run only the experiments: the
    identification does not depend on the controller's gains."""
    import time

    from servotau.apps.identify import collect, sim_config_with_servo
    from servotau.identification.motor_file import CANDIDATES, build_motor_file, write_motor_file

    say = progress or (lambda _m: None)
    folder = out / f"draw_{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    servo = write_servo_file(draw(seed), folder / "servo.toml")
    done = folder / "identification.json"
    if reuse_identification and done.exists() and (folder / "motors.toml").exists():
        kept = json.loads(done.read_text())
        if kept.get("servo") == servo.read_text():
            say(f"draw {seed}: motor file of an earlier identification ({kept['identify_seconds']:.0f} s)")
            return _experiments(seed, folder, servo, folder / "motors.toml", k6, kept["choices"],
                                kept["identify_seconds"], say)
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
    choices = {j: c.to_dict() for j, c in report.choices.items()}
    done.write_text(json.dumps({"servo": servo.read_text(), "identify_seconds": round(t_ident, 1),
                                "choices": choices}, indent=1))
    return _experiments(seed, folder, servo, motors, k6, choices, t_ident, say)


def _experiments(seed: int, folder: Path, servo: Path, motors: Path, k6: tuple[float, ...], choices: dict,
                 t_ident: float, say) -> dict:
    """The motion experiment of one draw with its motor file, and the draw's row (written to row.json)."""
    from .common import LEG_LABELS, run_label
    from .motion import motion_errors, motion_runs

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
    row = {"seed": seed, "servo": str(servo), "motors": str(motors), "identify_seconds": round(t_ident, 1),
           "choices": choices,
           "mean_mrad": {n: e[0].tolist() for n, e in errors.items()},
           "max_mrad": {n: e[1].tolist() for n, e in errors.items()},
           "tripped": tripped, "wins": wins}
    (folder / "row.json").write_text(json.dumps(row, indent=1))  # kept if a longer benchmark is stopped
    return row


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


# -- the docs/results.md section ------------------------------------------------------------------------------
TARGETS = {"K6=1": 0.9, "K6=0.5": 0.9, "K6=0.25": 0.8}  # share of (draw, leg joint, mean|max) won, issue 22
BEGIN, END = "<!-- servo_family: generated by bench/servo_family.py --doc -->", "<!-- /servo_family -->"


def merge(results: list[dict]) -> dict:
    """One result from several runs of bench/servo_family.py (e.g. its parts run in parallel): draws joined per
    part, scores recomputed, seconds the longest."""
    k6 = tuple(results[0]["k6"])
    draws: dict[str, list] = {}
    for r in results:
        if tuple(r["k6"]) != k6:
            raise ValueError(f"results with different K6: {r['k6']} vs {list(k6)}")
        for part, rows in r["draws"].items():
            draws.setdefault(part, []).extend(rows)
    return {**results[0], "seeds": {p: [x["seed"] for x in rows] for p, rows in draws.items()}, "draws": draws,
            "parts": {p: score(rows, k6) for p, rows in draws.items()},
            "all": score([x for rows in draws.values() for x in rows], k6),
            "seconds": None}  # the parts may reuse draws of earlier runs: their own times are in the rows


def section_markdown(result: dict, control: dict, top: dict | None = None) -> str:
    """The docs/results.md section of a bench result; ``control`` is config/control.toml's [defaults] (its gains),
    ``top`` its top-level settings (position_feedback, gain_schedule)."""
    from .common import LEG_LABELS

    top = top or {}
    schedule = (", lowered per joint to keep the identified model's margin (gain_schedule = \"margin\")"
                if top.get("gain_schedule") == "margin" else "")
    position = "encoder" if top.get("position_feedback") == "encoder" else "estimate q_hat"

    lines = [BEGIN, "## Torque control on a family of servos (issue 22, `bench/servo_family.py`)", "",
             "Each draw of servotau/experiments/servo_family.py (per joint group: servo gain x0.6-1.5, damping "
             "x0.5-1.5, Coulomb x0.5-2, Stribeck 0.2-1.5 N m, driver dead zone 0.1-0.5 A, direction gain 0-0.15, "
             "current limit 10-20 A) runs the chain unattended: `servotau identify run --servo DRAW` (workbench "
             f"candidates {', '.join(result['effects'])}, at most {result['max_steps']} per joint), then "
             "`servotau experiment motion --servo DRAW --motors motors.toml` (position servo, then torque control at "
             "each K6; errors on the true joint angles). Gains: config/control.toml "
             f"(k_p = {control.get('k_p')}{schedule}, k7 = {control.get('k7_per_k_v', control.get('k7'))}"
             f"{' k_v' if 'k7_per_k_v' in control else ' s'}"
             f"{' / sqrt(K6)' if control.get('k7_scaling') == 'inverse_sqrt_k6' else ''}, k_iq = "
             f"{control.get('k_iq')} /s, position error from the {position}). A run that trips, or that the model "
             "refuses before it moves, counts as lost on every joint. Parts: tuning = seeds the gains were looked "
             "at on; held out = seeds never looked at while tuning.", "",
             "Share of (draw, leg joint, mean|max) where torque control beats the position servo (target):", "",
             "| part | draws | " + " | ".join(f"{k} ({100 * TARGETS.get(k, 0):.0f} %)" for k in result["all"]) + " |",
             "|---|---|" + "---|" * len(result["all"])]
    for part, s in [*result["parts"].items(), ("all", result["all"])]:
        n = len(result["draws"][part]) if part in result["draws"] else sum(len(v) for v in result["draws"].values())
        cells = [f"{v['wins']}/{v['cases']} = {100 * v['share']:.0f} %" + (f", TRIP seeds {v['trips']}" if v["trips"]
                                                                              else "") if v["cases"] else "-"
                 for v in s.values()]
        lines.append(f"| {part} | {n} | " + " | ".join(cells) + " |")
    def met(k: str, t: float) -> str:
        s = result["all"][k]
        return "met" if s["cases"] and s["share"] >= t and not s["trips"] else "MISSED"

    lines += ["", "Targets: " + ", ".join(f"{k} {met(k, t)}" for k, t in TARGETS.items() if k in result["all"]) + ".",
              "",
        "Per draw, max error [mrad] per leg joint (" + ", ".join(LEG_LABELS) + "), position servo then each K6:", ""]
    for part, rows in result["draws"].items():
        for r in rows:
            runs = "; ".join(f"{n}{' TRIP' if r['tripped'].get(n) else ''}: "
                             + " ".join(f"{v:.3g}" for v in r["max_mrad"][n]) for n in r["max_mrad"])
            lines.append(f"- {part} seed {r['seed']}: {runs}")
    ident = [r["identify_seconds"] for rows in result["draws"].values() for r in rows]
    took = (f", {result['seconds']:.0f} s" if result.get("seconds")
            else f", identification {min(ident):.0f}-{max(ident):.0f} s per draw" if ident else "")
    lines += ["", f"Measured once on the shared 2-core machine{took}.", END]
    return "\n".join(lines)


def write_section(result: dict, doc: Path, control: dict, top: dict | None = None) -> None:
    """Replace (or append) the section in ``doc``."""
    text = doc.read_text() if doc.exists() else ""
    new = section_markdown(result, control, top)
    if BEGIN in text and END in text:
        text = text[:text.index(BEGIN)] + new + text[text.index(END) + len(END):]
    else:
        text = text.rstrip("\n") + "\n\n" + new + "\n"
    doc.write_text(text)
