"""examples/run_task.py: a Python task (jerk-limited move, a wave in torque mode) and the table example task
(config/tasks/table_example.toml and its CSV) end to end on the in-process simulator."""

from __future__ import annotations

import importlib.util
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "run_task.py"


def test_the_example_runs_its_tasks_to_their_end():
    spec = importlib.util.spec_from_file_location("run_task_example", EXAMPLE)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    lines = []
    results = example.main([], quick=True, progress=lines.append)
    assert [r.end for r in results] == ["completed", "completed"] and all(r.tripped is None for r in results)
    assert any("phase 2/3 wave: torque mode" in line for line in lines)
    assert any("phase 1/2 table: position mode, 1.00 s" in line for line in lines)
