"""servotau.config_paths: where config files are found (packaged defaults, config folder, references, never the
working folder for a name the program chooses)."""

import logging
from importlib import resources

import pytest

from servotau.config import CONFIG_DIR, ConfigFiles, load_toml, resolve_config_path
from servotau.config_paths import show_loaded_files
from servotau.errors import ConfigError

SHIPPED = ("control.toml", "estimation.toml", "hal.toml", "identification.toml", "sensors.toml", "servo.toml",
           "sim.toml", "sim_identification.toml", "motors/example.toml", "scenarios/hanging.toml")


def test_the_defaults_are_the_package_resource():
    """CONFIG_DIR is servotau.defaults found by importlib.resources, and holds the shipped files."""
    assert CONFIG_DIR == resources.files("servotau.defaults")
    for name in SHIPPED:
        assert (CONFIG_DIR / name).is_file(), name


def test_a_reference_is_found_next_to_its_file_then_in_the_defaults_never_in_the_working_folder(tmp_path,
                                                                                                   monkeypatch):
    """``motors = "motors/x.toml"`` in DIR/control.toml: DIR/motors/x.toml if it exists, else the packaged one;
    the working folder's motors/x.toml is never read."""
    cwd, cfg = tmp_path / "cwd", tmp_path / "cfg"
    for folder in (cwd / "motors", cfg / "motors"):
        folder.mkdir(parents=True)
    (cwd / "motors" / "example.toml").write_text("not read")
    (cfg / "control.toml").write_text("")
    monkeypatch.chdir(cwd)
    assert resolve_config_path("motors/example.toml", cfg / "control.toml") == CONFIG_DIR / "motors/example.toml"
    (cfg / "motors" / "example.toml").write_text("")
    assert resolve_config_path("motors/example.toml", cfg / "control.toml") == cfg / "motors" / "example.toml"
    with pytest.raises(ConfigError, match=rf"motors/none.toml: config file not found \(looked in {cfg}, "):
        resolve_config_path("motors/none.toml", cfg / "control.toml")
    # a table not read from a file: the packaged defaults only
    assert resolve_config_path("motors/example.toml", "<mapping>") == CONFIG_DIR / "motors/example.toml"


def test_an_explicit_path_is_read_as_given(tmp_path, monkeypatch):
    """A caller's own path (a command-line file): as given, relative to the working folder; absolute as is."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.toml").write_text("a = 1\n")
    assert load_toml("mine.toml").data == {"a": 1}
    assert load_toml(tmp_path / "mine.toml").data == {"a": 1}
    with pytest.raises(ConfigError, match="gone.toml: config file not found$"):
        load_toml(tmp_path / "gone.toml")


def test_bad_files_are_clear_errors(tmp_path):
    """A folder, or a file that is not TOML: the error names it."""
    with pytest.raises(ConfigError, match=f"{tmp_path}: a folder: expected a TOML config file"):
        load_toml(tmp_path)
    bad = tmp_path / "bad.toml"
    bad.write_text("k_p = = 1\n")
    with pytest.raises(ConfigError, match=f"{bad}: not valid TOML"):
        load_toml(bad)


def test_config_files_choose_the_flag_then_the_folder_then_the_default(tmp_path, monkeypatch):
    """ConfigFiles.path: a file's own flag, else the config folder, else the packaged default; never the
    working folder (which holds a control.toml here)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "control.toml").write_text("not read")
    (tmp_path / "cfg").mkdir()
    (tmp_path / "cfg" / "hal.toml").write_text("")
    (tmp_path / "mine.toml").write_text("")
    assert ConfigFiles().path("control.toml") == CONFIG_DIR / "control.toml"
    files = ConfigFiles.create("cfg", {"estimation.toml": ("--estimation-config", "mine.toml"),
                                       "sim.toml": ("--sim-config", None)})
    assert files.path("hal.toml") == tmp_path / "cfg" / "hal.toml"
    assert files.path("control.toml") == CONFIG_DIR / "control.toml"
    assert files.path("estimation.toml") == tmp_path / "mine.toml"
    assert "cfg, then the packaged defaults" in files.describe() and "estimation.toml = mine.toml" in files.describe()
    # a flag naming a packaged default by its name, not in the working folder: that default
    named = ConfigFiles.create(None, {"sim.toml": ("--sim-config", "sim_identification.toml")})
    assert named.path("sim.toml") == CONFIG_DIR / "sim_identification.toml"
    with pytest.raises(ConfigError, match="nothing.toml: config file not found"):
        files.path("nothing.toml")


@pytest.mark.parametrize("folder, given, message", [
    ("missing", {}, "--config missing: config folder not found: expected a config folder"),
    ("file.toml", {}, "--config file.toml: not a folder: expected a config folder"),
    (None, {"control.toml": ("--control-config", "missing.toml")},
     r"--control-config missing.toml: config file not found: expected a TOML config file \(control.toml\)"),
    (None, {"control.toml": ("--control-config", ".")}, r"--control-config \.: not a file"),
])
def test_bad_folder_or_file_flags_are_clear_errors(tmp_path, monkeypatch, folder, given, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "file.toml").write_text("")
    with pytest.raises(ConfigError, match=message):
        ConfigFiles.create(folder, given)


def test_every_file_read_is_named_once(tmp_path, capsys):
    """show_loaded_files: each file read is one stderr line, once, the packaged defaults marked as such."""
    show_loaded_files()
    try:
        (tmp_path / "a.toml").write_text("")
        for _ in range(2):
            load_toml(tmp_path / "a.toml")
            load_toml(CONFIG_DIR / "hal.toml")
        err = capsys.readouterr().err.splitlines()
        assert err == [f"config: read {tmp_path / 'a.toml'}", f"config: read {CONFIG_DIR / 'hal.toml'} "
                                                                "(packaged default)"]
        show_loaded_files()  # a second command in the same process names the files again
        load_toml(tmp_path / "a.toml")
        assert capsys.readouterr().err == f"config: read {tmp_path / 'a.toml'}\n"
    finally:
        logger = logging.getLogger("servotau.config")
        for h in list(logger.handlers):
            logger.removeHandler(h)
        logger.propagate = True
        logger.setLevel(logging.NOTSET)
