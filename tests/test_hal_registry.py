"""hal/registry.py: one line of config picks the backend, each backend reads its own table; errors name file,
field and choices."""

from __future__ import annotations

import argparse

import pytest

from servotau.config import CONFIG_DIR, load_toml
from servotau.errors import ConfigError, HalError, HalTimeoutError
from servotau.hal import (
    BACKENDS,
    InProcessBackend,
    LogWriter,
    ReplayBackend,
    available_backends,
    backend_names,
    import_object,
    open_backend,
    overrides_from_args,
    register,
    server_config,
)
from servotau.simrobot.fake import FakeRobot


def _write(tmp_path, text: str):
    p = tmp_path / "hal.toml"
    p.write_text(text)
    return p


def test_unknown_backend_names_file_field_and_choices(tmp_path):
    """backend = "ros" fails with the file, the field and the valid choices."""
    p = _write(tmp_path, '[hal]\nbackend = "ros"\n')
    with pytest.raises(ConfigError, match=r"hal.toml: field 'hal.backend' = 'ros': expected one of "
                                          r"\['zenoh', 'inprocess', 'replay'\]"):
        open_backend(p)


def test_inprocess_and_replay_from_config(tmp_path):
    """inprocess builds the robot from an import string (+ kwargs); replay opens a log."""
    p = _write(tmp_path, '[hal]\nbackend = "inprocess"\n[hal.inprocess]\nrobot = "servotau.simrobot.fake:FakeRobot"\n'
                         "[hal.inprocess.kwargs]\nseed = 3\n[hal.safety]\nhold_after = 0.02\n")
    with open_backend(p) as b:
        assert isinstance(b, InProcessBackend) and b.firmware.safety.hold_after == 0.02
        assert b.read().seq == 0
    log = tmp_path / "x.parquet"
    robot = FakeRobot()
    with LogWriter(log, robot.info) as w:
        w.append(robot.read())
    with open_backend(load_toml(_write(tmp_path, f'backend = "replay"\n[replay]\nlog = "{log}"\n'))) as b:
        assert isinstance(b, ReplayBackend) and len(b) == 1


def test_bad_options_name_the_field(tmp_path):
    """A bad import string, a typo'd key or a bad timeout is reported with its field."""
    cases = {
        '[inprocess]\nrobot = "nowhere:Robot"': "field 'inprocess.robot' = 'nowhere:Robot'",
        '[zenoh]\nconect = ["tcp/127.0.0.1:1"]': "field 'zenoh.conect'",
        '[zenoh]\nframe_timeout = -1': "field 'zenoh.frame_timeout' = -1",
        '[replay]\nlog = "missing.parquet"': "field 'replay.log' = 'missing.parquet': expected an existing log",
    }
    for body, match in cases.items():
        backend = body.split("]")[0].strip("[")
        with pytest.raises(ConfigError, match=match):
            open_backend(_write(tmp_path, f'backend = "{backend}"\n{body}\n'))


def test_defaults_file_and_server_config():
    """config/hal.toml is valid: server side and safety settings parse."""
    cfg = server_config(CONFIG_DIR / "hal.toml")
    assert cfg.clock == "lockstep" and cfg.listen == ("tcp/127.0.0.1:7447",) and cfg.safety.hold_after > 0
    assert import_object("servotau.hal.log:LogWriter") is LogWriter


def test_command_line_overrides(tmp_path):
    """--backend replaces the config's choice (still validated); --port replaces the zenoh endpoint."""
    p = _write(tmp_path, '[hal]\nbackend = "zenoh"\n[hal.zenoh]\nconnect_timeout = 0.2\n'
                         '[hal.inprocess]\nrobot = "servotau.simrobot.fake:FakeRobot"\n')
    with open_backend(p, backend="inprocess") as b:
        assert isinstance(b, InProcessBackend)
    with pytest.raises(ConfigError, match=r"with --backend\): field 'hal.backend' = 'ros'"):
        open_backend(p, backend="ros")
    with pytest.raises(HalTimeoutError, match="tcp/127.0.0.1:9"):
        open_backend(p, port=9)
    assert overrides_from_args(argparse.Namespace(backend=None, port=7448, mode="x")) == {"port": 7448}


def test_realtime_priority_is_validated(tmp_path):
    """realtime_priority: 0 (normal scheduling) or a SCHED_FIFO priority 1..99, else the field is named."""
    p = _write(tmp_path, '[hal.server]\nclock = "realtime"\nrealtime_priority = 50\n')
    assert server_config(p).realtime_priority == 50
    with pytest.raises(ConfigError, match=r"field 'hal.server.realtime_priority' = 120: expected an integer >= 0 "
                                          r"<= 99"):
        server_config(_write(tmp_path, "[hal.server]\nrealtime_priority = 120\n"))


def test_each_backend_module_reads_its_own_table():
    """Every registered backend's module has from_config; the registry parses only [hal] backend."""
    from servotau.hal.registry import backend_module

    for name in backend_names():
        assert callable(backend_module(name).from_config), name
    assert set(BACKENDS) <= set(backend_names()) and available_backends()["inprocess"] is None


def test_a_missing_optional_dependency_disables_one_backend_with_a_clear_message(tmp_path, monkeypatch):
    """A backend whose package is absent is reported as unavailable (what to install); the others still open."""
    from servotau.hal import registry

    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    register("ros", "servotau_ros_backend", ("servotau_no_such_package",), "pip install servotau-no-such-package")
    why = available_backends()["ros"]
    assert "servotau_no_such_package" in why and "pip install servotau-no-such-package" in why
    p = _write(tmp_path, '[hal]\nbackend = "ros"\n[hal.ros]\n'
                         '[hal.inprocess]\nrobot = "servotau.simrobot.fake:FakeRobot"\n')
    with pytest.raises(HalError, match=r'backend "ros" is unavailable: .*servotau_no_such_package'):
        open_backend(p)
    with open_backend(p, backend="inprocess") as b:
        assert isinstance(b, InProcessBackend)
