"""The simulated operator of the high-torque phase: scripted pushes on the right foot, timed on a plan.

On the real robot a person pushes the feet when ``servotau identify collect`` says so. In the simulator
the scenario's ``[[operator]]`` pushes (:class:`~servotau.simrobot.scenario.OperatorPush`, sim time)
play that person; they must fall inside the hold windows of the collection plan
(:meth:`CollectionPlan.hold_windows`), when the joints are held still. :func:`push_script` builds the
pushes for a plan (``config/scenarios/identification.toml`` was written from it for the default plan),
:func:`check_timing` verifies that a scenario's pushes and a plan agree.

Every hold window gets three pushes, each loading the joints in both directions (a full sine period,
or a positive ramp followed by a negative one), in several directions: forward force with a pitch
torque (hip pitch, knee, ankle pitch), lateral force with a roll torque (hip and ankle roll), a yaw
torque with a vertical force (hip yaw). Pure torques on the foot pass through every joint of the leg
whose axis they share; forces mostly swing the hanging robot.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from servotau.identification.plan import CollectionPlan
from servotau.simrobot.scenario import OperatorPush

BODY = "RLEG_FOOT"  # beyond the right ankle F/T sensor: the estimator sees the push
MARGIN = 0.25  # [s] of each hold window left without push at each end (of a 6 s window; scaled)

# (force [N], torque [N m]) peaks of the three pushes of a window, in the world frame.
# A hanging robot swings away from a force, so pure torques load the joints best; each force is given
# the sign whose moment about the ankle (the push acts about 0.1 m below it) adds to the torque.
_LOADS = (
    ((150.0, 0.0, 0.0), (0.0, -30.0, 0.0)),
    ((0.0, 120.0, 0.0), (30.0, 0.0, 0.0)),
    ((0.0, 0.0, 100.0), (0.0, 0.0, 30.0)),
)


def push_script(plan: CollectionPlan, body: str = BODY, scale: float = 1.0) -> list[OperatorPush]:
    """Pushes inside every hold window of ``plan``; window ``i`` uses sines if ``i`` is even, else ramps
    (+ then -); the loads are multiplied by ``scale``."""
    out = []
    for i, (start, end) in enumerate(plan.hold_windows()):
        margin = MARGIN * (end - start) / 6.0
        slot = (end - start - 2 * margin) / len(_LOADS)
        sign = 1.0 if i % 4 < 2 else -1.0  # alternate which direction comes first
        for k, (force, torque) in enumerate(_LOADS):
            t0 = start + margin + k * slot
            f, tq = sign * scale * np.array(force), sign * scale * np.array(torque)
            if i % 2 == 0:
                out.append(OperatorPush(body, t0, slot, f, tq, "sine", 1.0 / slot))
            else:
                half = slot / 2
                out.append(OperatorPush(body, t0, half, f, tq, "ramp"))
                out.append(OperatorPush(body, t0 + half, half, -f, -tq, "ramp"))
    return out


def check_timing(plan: CollectionPlan, pushes: Sequence[OperatorPush], period: float = 1e-3) -> list[str]:
    """Problems of a scenario's pushes against a plan's hold windows (empty list: they agree).

    A push must lie inside one hold window (``period`` [s] of tolerance); every window should have one.
    """
    windows = plan.hold_windows()
    problems = []
    used = set()
    for p in pushes:
        inside = [i for i, (a, b) in enumerate(windows) if p.start >= a - period and p.start + p.duration <= b + period]
        if not inside:
            problems.append(f"push on {p.body} at [{p.start:g}, {p.start + p.duration:g}] s is outside every hold "
                            f"window {[(round(a, 3), round(b, 3)) for a, b in windows]}")
        used.update(inside)
    for i, (a, b) in enumerate(windows):
        if i not in used:
            problems.append(f"hold window {i} [{a:g}, {b:g}] s has no push: no torque to identify k_tau from")
    return problems


def scenario_toml(plan: CollectionPlan, *, name: str = "identification", header: str = "",
                  pushes: Sequence[OperatorPush] | None = None) -> str:
    """A hanging-robot scenario file with :func:`push_script` pushes (or ``pushes``)."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += [
        f'name = "{name}"',
        'initial_posture = "half_sitting"',
        "base_height = 0.75          # [m] waist height: the soles hang about 10 cm above the floor",
        "floor = true",
        "lift = true",
        "string_length = 0.6         # [m] from the anchors above the shoulders",
        "string_damping = 200.0      # [N s/m] damping of the strings",
        "base_damping = 5.0          # [N m s/rad] air and string friction on the base rotation",
    ]

    def vec(v) -> str:
        return "[" + ", ".join(f"{float(x):g}" for x in v) + "]"

    for p in pushes if pushes is not None else push_script(plan):
        lines += ["", "[[operator]]", f'body = "{p.body}"', f"start = {p.start:.4f}         # [s] sim time",
                  f"duration = {p.duration:.4f}      # [s]", f"force = {vec(p.force)}      # [N] world frame, peak",
                  f"torque = {vec(p.torque)}     # [N m] world frame, peak", f'profile = "{p.profile}"']
        if p.profile == "sine":
            lines.append(f"frequency = {p.frequency:.6g}   # [Hz] one full period: both directions")
    return "\n".join(lines) + "\n"


def write_sim_setup(plan: CollectionPlan, folder: str | Path, name: str = "identification") -> Path:
    """Write ``<folder>/<name>_scenario.toml`` (the hanging robot with :func:`push_script` pushes for
    ``plan``) and ``<folder>/<name>_sim.toml`` pointing to it; return the sim config path, for
    ``servotau identify collect --sim-config`` (a plan other than the default needs its own pushes)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    scenario = folder / f"{name}_scenario.toml"
    scenario.write_text(scenario_toml(plan, name=name, header=f"Pushes for the plan {plan.source}."), encoding="utf-8")
    sim = folder / f"{name}_sim.toml"
    sim.write_text(f"# Simulation for the plan {plan.source}\nscenario = {json.dumps(str(scenario.resolve()))}\n"
                   'servo = "servo.toml"\nsensors = "sensors.toml"\nseed = 0\n', encoding="utf-8")
    return sim
