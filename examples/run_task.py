"""Build and run controller tasks from Python, on any HAL backend (here the in-process simulator).

    .venv/bin/python examples/run_task.py                  # the Python task below, then config/tasks/table_example
    .venv/bin/python examples/run_task.py --task swing     # any task name, file or module:attribute

A task is a :class:`~servotau.control.tasks.Task` whose ``phases(info, q_start)`` returns phases built on the start
posture: a joint reference (hold, sinusoids, jerk-limited or minimum-jerk waypoints, a table), a mode, a duration.
The runner checks every phase against the robot's limits on the first frame, before any command, then runs them
on the control loop after the settle phase (F/T calibration); the result says how the run ended.
"""

from __future__ import annotations

import argparse

import numpy as np

from servotau.control.loop import ControlLoop
from servotau.control.tasks import (
    FileTask,
    Hold,
    JerkLimited,
    Phase,
    Sinusoids,
    Task,
    TaskRunner,
    Wave,
    resolve_task,
)
from servotau.hal.registry import open_backend


class KneeWave(Task):
    """Bend the right knee by 0.3 rad (jerk-limited, time-optimal), wave it in torque mode for whole periods (the
    wave ends where it began: the next phase starts there, as the feasibility check requires), hold."""

    name = "knee_wave"
    settle = 0.5  # [s]
    frequency = 2.0  # [Hz]

    def __init__(self, periods: int = 2):
        self.periods = periods

    def phases(self, info, q_start):
        knee = info.joint_index("RLEG_JOINT3")
        bent = np.array(q_start, dtype=float)
        bent[knee] += 0.3  # [rad]
        move = JerkLimited(q_start, [bent], v_max=1.0, a_max=5.0, j_max=50.0)
        wave = Sinusoids(bent, info.joint_names, {"RLEG_JOINT3": Wave(amplitude=0.03, frequency=self.frequency,
                                                                        ramp=0.25)})
        return [Phase("bend", move, "position"),
                Phase("wave", wave, "torque", duration=self.periods / self.frequency),
                Phase("hold", Hold(bent), "torque", duration=0.3)]


def run(backend, task: Task, progress=print):
    """Run ``task`` on ``backend`` until it ends; returns the loop's result."""
    runner = TaskRunner(task, backend.info, progress=progress)
    loop = ControlLoop(backend, runner.manager(), hooks=[runner], settle=task.settle)
    return runner.run(loop)


def main(argv=None, quick: bool = False, progress=print) -> list:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", help="a task name, file or module:attribute (default: KneeWave, then table_example)")
    args = ap.parse_args(argv)
    tasks = [resolve_task(args.task)] if args.task else [KneeWave(1 if quick else 2), FileTask.load("table_example")]
    results = []
    for task in tasks:
        if quick:  # the example's test: the settle phase 0.2 s, a file task's timed phases cut to 0.25 s
            task = task.shortened(0.25, settle=0.2) if isinstance(task, FileTask) else task
            task.settle = 0.2
        backend = open_backend("hal.toml", backend="inprocess")  # the simulator in this process
        try:
            result = run(backend, task, progress)
        finally:
            backend.close()
        progress(f"{task.name}: {result.end}, {result.sim_seconds:.2f} s robot time, trip: {result.tripped}")
        results.append(result)
    return results


if __name__ == "__main__":
    main()
