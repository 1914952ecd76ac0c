"""Tasks for the controller: task files (config/tasks/*.toml) or Python classes, run on any HAL backend.

::

    from servotau.control.loop import ControlLoop
    from servotau.control.tasks import FileTask, TaskRunner

    runner = TaskRunner(FileTask.load("swing"), backend.info)        # config/tasks/swing.toml
    loop = ControlLoop(backend, runner.manager(), hooks=[runner], settle=runner.task.settle)
    result = runner.run(loop)                                        # InfeasibleTask before anything moves

A task of your own subclasses :class:`Task` and returns :class:`Phase` objects built on the start posture
(references: :class:`Hold`, :class:`Sinusoids`, :class:`JerkLimited`, :class:`MinJerk`, :class:`Tabled`);
``servotau control --task mypkg.mytask:MyTask`` runs it. docs/control.md ("Tasks") has the file format.
"""

from .build import FileTask, InfeasibleTask, Phase, Task, check_feasible, task_control_config
from .plugin import import_task, resolve_task
from .references import Hold, JerkLimited, JointReference, MinJerk, Sinusoids, Tabled
from .runner import TaskRunner
from .spec import ForceSpec, PhaseSpec, ReferenceSpec, TaskSpec, Wave, load_task, task_path
from .status import StatusLine
from .table import Table, load_table

__all__ = [
    "FileTask",
    "ForceSpec",
    "Hold",
    "InfeasibleTask",
    "JerkLimited",
    "JointReference",
    "MinJerk",
    "Phase",
    "PhaseSpec",
    "ReferenceSpec",
    "Sinusoids",
    "StatusLine",
    "Table",
    "Tabled",
    "Task",
    "TaskRunner",
    "TaskSpec",
    "Wave",
    "check_feasible",
    "import_task",
    "load_table",
    "load_task",
    "resolve_task",
    "task_control_config",
    "task_path",
]
