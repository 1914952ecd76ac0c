"""One identification collection on a HAL backend, recorded to the project's Parquet log.

:func:`run_collection` plays a :class:`~servotau.identification.plan.CollectionPlan` (settle, sweeps,
wait, holds) with the :class:`~servotau.identification.collect.Collector`, one ``read``/``write`` per
tick, and appends every tick to a :class:`~servotau.hal.log.LogWriter`: the frame, the command that
answered it, the ground truth if the backend has one (simulation, evaluation only) and two extra
columns, ``ident/phase`` (index in :data:`~servotau.identification.plan.PHASES`) and ``ident/joint``
(index of the swept joint in ``RobotInfo.joint_names``, -1 outside sweeps). The plan, the backend and
the date go to the log's metadata (``servotau.identification.*``), for the fit's provenance.
"""

from __future__ import annotations

import datetime
import json
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servotau.hal.types import SensorFrame

from .collect import Collector, HoldPlan
from .plan import PHASES, CollectionPlan, ticks

log = logging.getLogger(__name__)

PHASE_COLUMN = "ident/phase"
JOINT_COLUMN = "ident/joint"
META_PLAN = "servotau.identification.plan"
META_BACKEND = "servotau.identification.backend"
META_DATE = "servotau.identification.date"
META_JOINTS = "servotau.identification.joints"
PROGRESS_EVERY = 5.0  # [s] of robot time between progress lines
FIRST_TRUTH_TRIES = 40  # calls of ground_truth() for the first frame (zenoh waits 5 ms per call)


class _TruthTap:
    """The backend, plus the ground truth of each frame fetched right after reading it."""

    def __init__(self, backend):
        self.backend = backend
        self.info = backend.info
        self.truth = None
        self.truth_seq = -1

    def read(self) -> SensorFrame:
        frame = self.backend.read()
        self.truth = self.backend.ground_truth()
        for _ in range(FIRST_TRUTH_TRIES if self.truth_seq < 0 and self.truth is None else 0):
            # The first frame decides the log's truth columns: over zenoh its truth may come a little later.
            self.truth = self.backend.ground_truth()
            if self.truth is not None:
                break
        self.truth_seq = frame.seq
        return frame

    def write(self, q_des: Mapping[str, float]) -> None:
        self.backend.write(q_des)


class _LabelledCollector(Collector):
    """The Collector, with the current phase and swept joint kept for the log."""

    phase = "settle"
    joint = -1

    def hold_still(self, seconds: float, phase: str) -> None:
        self.phase, self.joint = phase, -1
        q = self.q_des.copy()
        for _ in self._ticks(seconds):
            self._tick(q)

    def run_holds(self, plan: HoldPlan) -> None:
        for i, config in enumerate(plan.configurations):
            self.phase, self.joint = "move", -1
            self.progress(f"hold {i + 1}/{len(plan.configurations)}: moving to {dict(config)}")
            self.move_to(config, plan.move)
            self.phase = "hold"
            self.progress(f"PUSH NOW on the feet for {plan.hold:.0f} s (large torques, joints still)")
            hold = self.q_des.copy()
            for _ in self._ticks(plan.hold):
                self._tick(hold)


@dataclass(frozen=True)
class CollectionResult:
    rows: int  # ticks recorded
    robot_seconds: float  # [s]
    wall_seconds: float  # [s]
    truth: bool  # ground-truth columns recorded
    completed: bool  # the whole plan ran


def run_collection(backend, plan: CollectionPlan, out: str | Path, *, source: str,
                   progress: Callable[[str], None] = print, metadata: Mapping[str, str] | None = None
                   ) -> CollectionResult:
    """Run ``plan`` on ``backend`` and record every tick to the Parquet log ``out``.

    The log is closed (and complete up to the last tick) even when the run stops on an error or
    Ctrl-C; the exception then propagates.

    Args:
        backend: An open HAL backend (any: inprocess, zenoh; a real robot).
        plan: What to play.
        out: Log path (.parquet).
        source: Backend name recorded in the metadata (``"inprocess"``, ``"zenoh"``...).
        progress: Called with one line per event and every :data:`PROGRESS_EVERY` s of robot time.
        metadata: Extra log metadata.
    """
    from servotau.hal.log import LogWriter

    info = backend.info
    tap = _TruthTap(backend)
    meta = {
        "servotau.source": source,
        META_BACKEND: source,
        META_DATE: datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        META_PLAN: json.dumps(plan.to_dict()),
        META_JOINTS: json.dumps(list(plan.joints)),
        **(metadata or {}),
    }
    total = plan.duration
    state = {"rows": 0, "t0": None, "next": 0.0}
    wall0 = time.perf_counter()

    def say(msg: str, t: float) -> None:
        progress(f"[{t:6.1f}/{total:.1f} s robot, {time.perf_counter() - wall0:6.1f} s wall] {msg}")

    if backend.ground_truth() is None:
        # Over zenoh the simulator publishes ground truth once it sees a subscriber: the first frame may
        # never get one. Hold one tick (not recorded); the collection starts at the next frame.
        backend.write_array(backend.read().q)
    sink = {}

    def record(frame: SensorFrame, q_des: np.ndarray) -> None:
        truth = tap.truth if tap.truth_seq == frame.seq else None
        sink["writer"].append(frame, q_des, truth, {PHASE_COLUMN: float(PHASES.index(collector.phase)),
                                                    JOINT_COLUMN: float(collector.joint)})
        state["rows"] += 1
        t = frame.time - state["t0"]
        if t >= state["next"]:
            state["next"] += PROGRESS_EVERY
            joint = f" {info.joint_names[collector.joint]}" if collector.joint >= 0 else ""
            say(f"{collector.phase}{joint}", t)

    def relay(msg: str) -> None:  # the Collector's own per-2-s sweep lines duplicate the periodic ones
        if not msg.startswith("  "):
            say(msg, collector.frame.time - state["t0"])

    collector = _LabelledCollector(tap, record, progress=relay)
    state["t0"] = collector.frame.time
    has_truth = tap.truth is not None  # the log has truth columns if the backend gives truth (simulation)
    with LogWriter(out, info, truth=has_truth, extra=[PHASE_COLUMN, JOINT_COLUMN], metadata=meta) as writer:
        sink["writer"] = writer
        if has_truth and abs(state["t0"]) > 2.5 * info.period:
            log.warning("the collection starts at sim time %.3f s, not 0: a scenario's scripted pushes "
                        "(sim time) will not match the plan's hold windows", state["t0"])
        say(f"collecting {len(plan.sweeps)} sweeps ({', '.join(plan.joints) or 'none'}) and "
            f"{len(plan.holds.configurations)} holds on {info.name} ({source}) into {out}", 0.0)
        period = info.period
        completed = False
        try:
            collector.hold_still(plan.settle, "settle")
            for sweep in plan.sweeps:
                collector.phase, collector.joint = "sweep", info.joint_index(sweep.joint)
                collector.run_sweep(sweep)
            if plan.holds_start > 0:
                wait = ticks(plan.holds_start, period) - state["rows"]
                collector.hold_still(max(wait, 0) * period, "wait")
            collector.run_holds(plan.holds)
            completed = True
        finally:
            rows = state["rows"]
            ended = "done" if completed else "STOPPED early"
            say(f"{ended}: {rows} ticks recorded to {out}", rows * period)
    return CollectionResult(rows=rows, robot_seconds=rows * period, wall_seconds=time.perf_counter() - wall0,
                            truth=has_truth, completed=completed)
