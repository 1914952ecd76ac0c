"""User-written tasks by import path: ``--task mypkg.mytask:Task`` (``module:attribute``).

The attribute is a task object, or a class (or factory) called without arguments that returns one. A task
has ``name`` and ``phases(info, q_start) -> Sequence[Phase]`` (:class:`~.build.Task`; subclassing it gives
the defaults of ``settle`` and ``ft_offsets``). A path that cannot be imported, or an object without that
interface, is a :class:`~servotau.errors.ConfigError` that says which and what was expected.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from servotau.errors import ConfigError

from .build import FileTask, Task

EXPECTED = "a task: an object (or a class called without arguments) with name and phases(info, q_start)"


def import_task(path: str) -> Task:
    """The task at ``module:attribute`` (module doc).

    Raises:
        ConfigError: Not ``module:attribute``, the module or attribute cannot be imported, or the object is no task.
    """
    module_name, _, attr = path.partition(":")
    if not module_name or not attr:
        raise ConfigError(f"--task {path}: expected module:attribute, e.g. mypkg.mytask:Task")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # noqa: BLE001 - any failure of the user's module is reported, not raised through
        raise ConfigError(f"--task {path}: cannot import module {module_name} ({type(exc).__name__}: {exc}): "
                          "expected an importable module (on PYTHONPATH or installed)") from None
    obj = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ConfigError(f"--task {path}: module {module_name} has no attribute {attr}: expected {EXPECTED}")
        obj = getattr(obj, part)
    if isinstance(obj, type) or (callable(obj) and not hasattr(obj, "phases")):
        try:
            obj = obj()
        except Exception as exc:  # noqa: BLE001
            raise ConfigError(f"--task {path}: calling {attr}() failed ({type(exc).__name__}: {exc}): "
                              f"expected {EXPECTED}") from None
    missing = [a for a in ("name", "phases") if not hasattr(obj, a)]
    if missing or not callable(obj.phases):
        raise ConfigError(f"--task {path}: {type(obj).__name__} lacks {', '.join(missing) or 'a callable phases'}: "
                          f"expected {EXPECTED}")
    for attr_name, default in (("settle", Task.settle), ("ft_offsets", Task.ft_offsets), ("source", path)):
        if not hasattr(obj, attr_name):
            try:
                setattr(obj, attr_name, default)
            except AttributeError:
                pass
    return obj


def resolve_task(name: str, duration: float | None = None) -> Task:
    """A task by name (config/tasks/NAME.toml), file path or import path ``module:attribute`` (:mod:`.plugin`)."""
    if ":" in name and not Path(name).exists():
        if duration is not None:
            raise ConfigError(f"--duration: applies to task files only, not to {name}")
        return import_task(name)
    return FileTask.load(name, duration)
