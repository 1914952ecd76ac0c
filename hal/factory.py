"""Choose a backend by one line of config: ``backend = "zenoh" | "inprocess" | "replay"``.

Layout (defaults in config/hal.toml)::

    [hal]
    backend = "zenoh"
    [hal.zenoh]       robot, connect, listen, mode, connect_timeout, frame_timeout, truth
    [hal.inprocess]   robot = "module:callable", scenario, log, [hal.inprocess.kwargs]
    [hal.replay]      log
    [hal.server]      robot side: robot, listen, connect, mode, clock, log, max_ticks, ...
    [hal.safety]      robot-side firmware: hold_after, servo_off_after, max_position_error
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

from servotau.config import Section, load_toml

from .backend import Backend
from .errors import HalError
from .firmware import SafetyConfig

BACKENDS = ("zenoh", "inprocess", "replay")
_TABLES = ("backend", *BACKENDS, "server", "safety")


def import_object(spec: str) -> Any:
    """The object named by an import string ``"package.module:attribute"`` (imported now)."""
    mod_name, sep, attr = spec.partition(":")
    if not sep or not mod_name or not attr:
        raise HalError(f"import string {spec!r}: expected 'package.module:attribute'")
    try:
        obj = importlib.import_module(mod_name)
    except ImportError as exc:
        raise HalError(f"import string {spec!r}: cannot import {mod_name}: {exc}") from exc
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise HalError(f"import string {spec!r}: {mod_name} has no attribute {attr!r}") from None
    return obj


def hal_section(config: Section | str | Path) -> Section:
    """The ``[hal]`` table of a config file or section (or the section itself if it has ``backend``)."""
    s = config if isinstance(config, Section) else load_toml(config)
    if "backend" not in s and "hal" in s:
        s = s.section("hal")
    s.check_keys(_TABLES)
    return s


def _str_list(s: Section, key: str, default: list[str]) -> list[str]:
    value = s.data.get(key, default)
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise s.error(key, value, 'a list of zenoh endpoints, e.g. ["tcp/127.0.0.1:7447"]')
    return value


def safety_config(config: Section | str | Path) -> SafetyConfig:
    """Robot-side firmware settings from ``[hal.safety]`` (defaults if absent)."""
    return SafetyConfig.from_section(hal_section(config).section("safety", {}))


def server_config(config: Section | str | Path, *, port: int | None = None):
    """:class:`~servotau.hal.server.ServerConfig` from ``[hal.server]`` and ``[hal.safety]``
    (``port``: listen on ``tcp/127.0.0.1:<port>`` instead of the configured endpoints)."""
    from .server import ServerConfig

    s = hal_section(config)
    srv = s.section("server", {})
    if port is not None:
        srv = _override(srv, "listen", [f"tcp/127.0.0.1:{port}"], "--port")
    return ServerConfig.from_section(srv, safety_config(s))


def overrides_from_args(args: Any) -> dict:
    """``backend`` and ``port`` overrides for :func:`open_backend` from argparse attributes (if set)."""
    return {k: getattr(args, k) for k in ("backend", "port") if getattr(args, k, None) is not None}


def _override(s: Section, key: str, value: Any, flag: str) -> Section:
    return Section({**s.data, key: value}, f"{s.file} (with {flag})", s.prefix)


def open_backend(config: Section | str | Path, *, backend: str | None = None, port: int | None = None) -> Backend:
    """Open the backend selected by ``backend`` in ``[hal]`` (a config path or a Section).

    Args:
        config: the config (file path, or its root or ``[hal]`` Section).
        backend: overrides the config's ``backend`` (command line ``--backend``).
        port: zenoh only: connect to ``tcp/127.0.0.1:<port>`` instead of the configured endpoints.

    Raises:
        ConfigError: unknown backend or invalid option (names the file, the field, the expected value).
        HalError: the backend could not be opened (robot absent, log missing...).
    """
    s = hal_section(config)
    if backend is not None:
        s = _override(s, "backend", backend, "--backend")
    name = s.str("backend", choices=BACKENDS)
    if name == "zenoh":
        from .zenoh_backend import ZenohBackend

        z = s.section("zenoh", {})
        z.check_keys(["robot", "connect", "listen", "mode", "connect_timeout", "frame_timeout", "truth",
                      "realtime_priority"])
        if port is not None:
            z = _override(z, "connect", [f"tcp/127.0.0.1:{port}"], "--port")
        return ZenohBackend(
            z.str("robot", "hrp2"),
            connect=_str_list(z, "connect", ["tcp/127.0.0.1:7447"]),
            listen=_str_list(z, "listen", []),
            mode=z.str("mode", "peer", choices=["peer", "client"]),
            connect_timeout=z.float("connect_timeout", 10.0, min=0, strict_min=True, unit="s"),
            frame_timeout=z.float("frame_timeout", 0.1, min=0, strict_min=True, unit="s"),
            truth=z.bool("truth", True),
            realtime_priority=z.int("realtime_priority", 0, min=0, max=99),
        )
    if name == "inprocess":
        from .inprocess import InProcessBackend

        i = s.section("inprocess")
        i.check_keys(["robot", "scenario", "log", "kwargs"])
        spec = i.str("robot")
        try:
            factory = import_object(spec)
        except HalError as exc:
            raise i.error("robot", spec, f"an importable 'module:callable' robot factory ({exc})") from exc
        scenario = i.str("scenario") if "scenario" in i else None
        kwargs = dict(i.section("kwargs", {}).data)
        robot = factory(scenario, **kwargs) if scenario is not None else factory(**kwargs)
        return InProcessBackend(robot, safety_config(s), log=i.str("log") if "log" in i else None)
    from .replay import ReplayBackend

    r = s.section("replay")
    r.check_keys(["log"])
    path = r.str("log")
    if not Path(path).exists():
        raise r.error("log", path, "an existing log file (.parquet)")
    return ReplayBackend(path)
