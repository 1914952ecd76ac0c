"""A short simulated identification log (in process): sweeps and holds with the simulated operator's pushes."""

from __future__ import annotations

from pathlib import Path

from servotau.apps.identify import hal_for_collection
from servotau.apps.operator_script import write_sim_setup
from servotau.hal.registry import open_backend
from servotau.identification.collect import HoldPlan, SweepPlan
from servotau.identification.plan import CollectionPlan, load_plan
from servotau.identification.session import run_collection

__all__ = ["SHORT_PLAN", "collect_short_log", "short_plan"]

# A short collection plan (two joints, two holds) for the `servotau identify` commands
SHORT_PLAN_TEMPLATE = """[collect]
joints = ["RLEG_JOINT2", "RLEG_JOINT3"]
settle = 1.0
[collect.sweep]
a = 0.1
duration = {sweep}
[collect.hold]
move = 1.0
hold = {hold}
[[collect.hold.configurations]]
RLEG_JOINT2 = -0.453786
RLEG_JOINT3 = 0.872665
RLEG_JOINT4 = -0.418879
[[collect.hold.configurations]]
RLEG_JOINT2 = -1.0
RLEG_JOINT3 = 1.6
RLEG_JOINT4 = -0.6
[fit]
loss = "asymmetric"
w = 100.0
"""


def short_plan(sweep: float = 5.0, hold: float = 4.0) -> str:
    """A collection plan (TOML) of two right-leg joints: 1 s of settle, a sweep of ``sweep`` s per joint, two
    holds of ``hold`` s (1 s move each), fitted with the asymmetric loss (w = 100)."""
    return SHORT_PLAN_TEMPLATE.format(sweep=sweep, hold=hold)


SHORT_PLAN = short_plan()  # 23 s of robot time


def collect_short_log(folder: Path, joints: tuple[str, ...] = ("RLEG_JOINT3",), sweep: float = 4.0,
                      holds: int = 2, hold: float = 4.0) -> Path:
    """``folder/log.parquet``: 1 s of settle, a sweep of ``sweep`` s per joint, ``holds`` holds of the default
    plan's configurations (1 s move, ``hold`` s held, pushed through zero torque); the log's path."""
    base, _ = load_plan()
    plan = CollectionPlan(sweeps=tuple(SweepPlan(j, a=0.1, duration=sweep) for j in joints),
                          holds=HoldPlan(base.holds.configurations[:holds], move=1.0, hold=hold), settle=1.0)
    section, name = hal_for_collection("hal.toml", "inprocess", str(write_sim_setup(plan, folder)))
    log = folder / "log.parquet"
    with open_backend(section, backend=name) as backend:
        result = run_collection(backend, plan, log, source=name, progress=lambda _m: None)
    assert result.completed, result
    return log
