"""The backend registry: one line of config picks the backend, ``backend = "zenoh" | "inprocess" | "replay"``.

Backends are keyed by name, each in its own module of :mod:`servotau.hal.backends` that reads its own
sub-table of ``[hal]`` (its ``from_config``). A backend module is imported only when it is opened, so a
missing optional dependency (zenoh for ``"zenoh"``) disables that backend alone, with a message saying
what to install, and :func:`available_backends` tells which backends this installation can open.

Layout (defaults in config/hal.toml)::

    [hal]
    backend = "zenoh"
    [hal.zenoh]       robot, connect, listen, mode, connect_timeout, frame_timeout, truth, realtime_priority
    [hal.inprocess]   robot = "module:callable", scenario, log, [hal.inprocess.kwargs]
    [hal.replay]      log
    [hal.server]      robot side: robot, listen, connect, mode, clock, log, max_ticks, ...
    [hal.safety]      robot-side firmware: watchdog, rate limits, command age, encoder faults (hal/robot/safety.py)
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from servotau.config import Section, load_toml

from .config import with_override
from .errors import HalError

if TYPE_CHECKING:
    from .backend import Backend


@dataclass(frozen=True)
class BackendEntry:
    """A registered backend: its module (with ``from_config(hal, *, port)``) and what it needs."""

    name: str  # the value of ``[hal] backend``
    module: str  # import path of the module
    requires: tuple[str, ...] = ()  # optional packages (import names) it needs
    install: str = ""  # how to get them, e.g. "pip install eclipse-zenoh"


_REGISTRY: dict[str, BackendEntry] = {}

ROBOT_TABLES = ("server", "safety")
"""Sub-tables of ``[hal]`` read by the robot side (:mod:`servotau.hal.robot.config`)."""


def register(name: str, module: str, requires: tuple[str, ...] = (), install: str = "") -> None:
    """Add (or replace) backend ``name``, implemented by ``module``'s ``from_config(hal, *, port)``."""
    _REGISTRY[name] = BackendEntry(name, module, tuple(requires), install)


register("zenoh", "servotau.hal.backends.zenoh", ("zenoh",), "pip install eclipse-zenoh")
register("inprocess", "servotau.hal.backends.inprocess")
register("replay", "servotau.hal.backends.replay", ("pyarrow",), "pip install pyarrow")

BACKENDS: tuple[str, ...] = tuple(_REGISTRY)
"""The built-in backends' names."""


def backend_names() -> tuple[str, ...]:
    """Every registered backend's name, in registration order."""
    return tuple(_REGISTRY)


def _missing(entry: BackendEntry) -> str | None:
    """Why ``entry`` cannot be opened here (a missing package), or None."""
    for pkg in entry.requires:
        if importlib.util.find_spec(pkg) is None:
            return (f'backend "{entry.name}" is unavailable: it needs the package {pkg!r}, which is not installed'
                    + (f" ({entry.install})" if entry.install else ""))
    return None


def available_backends() -> dict[str, str | None]:
    """Registered backend name -> None if it can be opened here, else why not (without importing it)."""
    return {name: _missing(entry) for name, entry in _REGISTRY.items()}


def backend_module(name: str) -> ModuleType:
    """The module of backend ``name`` (imported now); HalError if it is unknown or its dependencies are missing."""
    entry = _REGISTRY.get(name)
    if entry is None:
        raise HalError(f"backend {name!r}: expected one of {list(_REGISTRY)}")
    why = _missing(entry)
    if why is not None:
        raise HalError(why)
    try:
        return importlib.import_module(entry.module)
    except ImportError as exc:
        if exc.name in entry.requires:
            raise HalError(f'backend "{name}" is unavailable: {exc}' + (f" ({entry.install})" if entry.install else "")
                           ) from exc
        raise


def hal_section(config: Section | str | Path) -> Section:
    """The ``[hal]`` table of a config file or section (or the section itself if it has ``backend``);
    its sub-tables must be registered backends or the robot side's."""
    s = config if isinstance(config, Section) else load_toml(config)
    if "backend" not in s and "hal" in s:
        s = s.section("hal")
    s.check_keys(("backend", *_REGISTRY, *ROBOT_TABLES))
    return s


def overrides_from_args(args: Any) -> dict:
    """``backend`` and ``port`` overrides for :func:`open_backend` from argparse attributes (if set)."""
    return {k: getattr(args, k) for k in ("backend", "port") if getattr(args, k, None) is not None}


def open_backend(config: Section | str | Path, *, backend: str | None = None, port: int | None = None) -> Backend:
    """Open the backend selected by ``backend`` in ``[hal]`` (a config path or a Section).

    Args:
        config: the config (file path, or its root or ``[hal]`` Section).
        backend: overrides the config's ``backend`` (command line ``--backend``).
        port: zenoh only: connect to ``tcp/127.0.0.1:<port>`` instead of the configured endpoints.

    Raises:
        ConfigError: unknown backend or invalid option (names the file, the field, the expected value).
        HalError: the backend could not be opened (robot absent, log missing, dependency not installed...).
    """
    s = hal_section(config)
    if backend is not None:
        s = with_override(s, "backend", backend, "--backend")
    name = s.str("backend", choices=tuple(_REGISTRY))
    return backend_module(name).from_config(s, port=port)
