"""servotau config init|path and the config flags of the processes (--config DIR, a flag per file, the files
read named on stderr, clear errors for a bad folder or file, nothing read from the working folder)."""

import argparse
import logging

import pytest

from servotau.apps import config_args, config_cmd
from servotau.cli import main
from servotau.config import CONFIG_DIR, ConfigFiles
from servotau.errors import ConfigError
from servotau.hal.robot.cli import main as hal_main


@pytest.fixture(autouse=True)
def _config_logger():
    """cli.main names the files read through the servotau.config logger: leave it as it was."""
    logger = logging.getLogger("servotau.config")
    state = (list(logger.handlers), logger.propagate, logger.level)
    yield
    logger.handlers[:], logger.propagate = state[0], state[1]
    logger.setLevel(state[2])


@pytest.fixture
def cfg(tmp_path):
    """A config folder written by ``servotau config init``."""
    folder = tmp_path / "cfg"
    config_cmd.init(folder)
    return folder


def test_config_init_copies_every_default_and_refuses_to_overwrite(tmp_path, capsys):
    """init writes each default file (sub-folders kept, same bytes); a second init is refused naming the files
    that exist, unless --force; a file in the way is refused."""
    folder = tmp_path / "cfg"
    assert main(["config", "init", str(folder)]) == 0
    names = config_cmd.default_files()
    assert {"control.toml", "hal.toml", "motors/example.toml", "scenarios/hanging.toml"} <= {str(n) for n in names}
    assert "__init__.py" not in {n.name for n in names}
    for n in names:
        assert (folder / n).read_bytes() == (CONFIG_DIR / n).read_bytes(), n
    assert capsys.readouterr().out.splitlines() == [str(folder / n) for n in names]
    (folder / "control.toml").write_text("edited")
    assert main(["config", "init", str(folder)]) == 2
    assert f"{folder}: {len(names)} config files exist already" in capsys.readouterr().err
    assert (folder / "control.toml").read_text() == "edited"
    assert main(["config", "init", str(folder), "--force"]) == 0
    assert (folder / "control.toml").read_bytes() == (CONFIG_DIR / "control.toml").read_bytes()
    with pytest.raises(ConfigError, match="control.toml: not a folder"):
        config_cmd.init(folder / "control.toml")


def test_config_path_prints_the_packaged_defaults(capsys):
    assert main(["config", "path"]) == 0
    assert capsys.readouterr().out == f"{CONFIG_DIR}\n"


def _bad_gain(path):
    text = path.read_text()
    assert "\nk_p = 0.5 " in text
    path.write_text(text.replace("\nk_p = 0.5 ", "\nk_p = -7.0 ", 1))


def test_control_reads_its_config_folder_and_refuses_a_bad_file(cfg, tmp_path, monkeypatch, capsys):
    """The issue's case: k_p = -7 in the control.toml of --config DIR (or of --control-config FILE) is refused
    with exit 2 naming the file and the field; the lines on stderr name the folder and the files read."""
    monkeypatch.chdir(tmp_path)
    _bad_gain(cfg / "control.toml")
    assert main(["control", "--backend", "inprocess", "--config", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert f"config folder: {cfg}, then the packaged defaults" in err
    assert f"config: read {cfg / 'hal.toml'}\n" in err and f"config: read {cfg / 'sim.toml'}\n" in err
    assert f"{cfg / 'control.toml'}: field 'defaults.k_p' = -7.0: expected a finite number >= 0" in err
    mine = tmp_path / "mine.toml"
    mine.write_text((cfg / "control.toml").read_text())
    (cfg / "control.toml").write_bytes((CONFIG_DIR / "control.toml").read_bytes())
    assert main(["control", "--backend", "inprocess", "--config", str(cfg), "--control-config", "mine.toml"]) == 2
    err = capsys.readouterr().err
    assert "control.toml = mine.toml" in err and "mine.toml: field 'defaults.k_p' = -7.0" in err


def test_nothing_is_read_from_the_working_folder(tmp_path, monkeypatch, capsys):
    """hal.toml, config/hal.toml and control.toml in the working folder, all invalid, are not read: ctl reads the
    packaged hal.toml (and says so), then finds no robot to connect to (exit 2 for that, not for a config error)."""
    for name in ("hal.toml", "config/hal.toml", "control.toml", "config/control.toml"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("this is = = not toml")
    monkeypatch.chdir(tmp_path)
    from servotau.apps.processes import free_port

    assert main(["ctl", "status", "--port", str(free_port()), "--timeout", "0.2"]) == 2
    err = capsys.readouterr().err
    assert f"config: read {CONFIG_DIR / 'hal.toml'} (packaged default)" in err
    assert "not valid TOML" not in err and "servotau ctl: cannot open a zenoh session" in err


@pytest.mark.parametrize("argv", [["sim"], ["control"], ["demo"], ["identify", "fit", "log.parquet"],
                                  ["identify", "collect", "--out", "x.parquet"], ["model", "simulate", "x.parquet"],
                                  ["ctl", "status"]])
def test_a_missing_config_folder_is_a_clear_error_before_anything_starts(tmp_path, monkeypatch, capsys, argv):
    monkeypatch.chdir(tmp_path)
    assert main([*argv, "--config", "nowhere"]) == 2
    assert "--config nowhere: config folder not found: expected a config folder" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # nothing written (demo's output folder included)


def test_a_missing_file_flag_is_a_clear_error(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["sim", "--sim-config", "nope.toml"]) == 2
    err = capsys.readouterr().err
    assert "--sim-config nope.toml: config file not found: expected a TOML config file (sim.toml)" in err
    assert main(["identify", "fit", "log.parquet", "--estimation-config", "e.toml"]) == 2
    assert "--estimation-config e.toml: config file not found" in capsys.readouterr().err
    assert main(["sim", "--config", "old.toml"]) == 2  # the former meaning of sim's --config: the sim file
    err = capsys.readouterr().err
    assert "--config old.toml names a file: read as --sim-config" in err
    assert "--sim-config old.toml: config file not found" in err


def test_the_hal_module_takes_a_config_folder(tmp_path, capsys):
    """python -m servotau.hal --config DIR: a missing folder, or a --scenario not in it, is a one-line error,
    exit 2, before the robot is built."""
    assert hal_main(["--robot", "servotau.simrobot.sim:SimRobot.from_config", "--config", str(tmp_path / "no")]) == 2
    assert "--config" in capsys.readouterr().err
    assert hal_main(["--robot", "servotau.simrobot.sim:SimRobot.from_config", "--config", str(tmp_path),
                     "--scenario", "scenarios/none.toml"]) == 2
    err = capsys.readouterr().err
    assert "scenarios/none.toml: config file not found" in err and f"config folder: {tmp_path}" in err


def test_forward_passes_the_flags_given_as_absolute_paths(tmp_path, monkeypatch):
    """demo passes --config and the file flags on to its processes, absolute (they may run elsewhere)."""
    monkeypatch.chdir(tmp_path)
    args = argparse.Namespace(config="cfg", hal=None, control_config="c.toml", estimation_config=None)
    assert config_args.forward(args, config_args.HAL, config_args.CONTROL, config_args.ESTIMATION) == [
        "--config", str(tmp_path / "cfg"), "--control-config", str(tmp_path / "c.toml")]


def test_the_hanging_sim_and_the_inprocess_scenario_come_from_the_folder(cfg):
    """model simulate's robot and hal.toml's [hal.inprocess] scenario are the config folder's files."""
    sim = config_args.hanging_sim(ConfigFiles.create(cfg))
    assert sim.servo_path == cfg / "servo.toml" and sim.scenario.name == "hanging"
    hal = config_args.hal_config(ConfigFiles.create(cfg))
    assert hal.data["inprocess"]["scenario"] == str(cfg / "sim.toml") and hal.file == str(cfg / "hal.toml")
