"""Tasks for the controller: task files (config/tasks/*.toml) or Python classes, run on any HAL backend.

::

    from servotau.control.loop import ControlLoop
    from servotau.control.tasks import FileTask, TaskRunner

    runner = TaskRunner(FileTask.load("swing"), backend.info)        # config/tasks/swing.toml
    loop = ControlLoop(backend, runner.manager(), hooks=[runner], settle=runner.task.settle)
    result = runner.run(loop)                                        # InfeasibleTask before anything moves

A task of your own subclasses :class:`Task` and returns :class:`Phase` objects built on the start posture
(references: :class:`Hold`, :class:`Sinusoids`, :class:`JerkLimited`, :class:`MinJerk`, :class:`Tabled`);
``servotau control --task mypkg.mytask:MyTask`` runs it. A torque phase may carry its own ``gains`` (``k6``, ``k_s``,
``k7``, ``k_d``, ``k_p``). docs/control.md ("Tasks") has the file format.
"""

from .build import FileTask, InfeasibleTask, Phase, PhaseGains, Task, check_feasible, phase_gains, task_control_config
from .lag import LagModel, LagPrediction
from .plugin import import_task, resolve_task
from .references import Hold, JerkLimited, JointReference, MinJerk, Sinusoids, Tabled
from .runner import Plan, TaskRunner
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
    "LagModel",
    "LagPrediction",
    "MinJerk",
    "Phase",
    "PhaseGains",
    "PhaseSpec",
    "Plan",
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
    "phase_gains",
    "resolve_task",
    "task_control_config",
    "task_path",
]
