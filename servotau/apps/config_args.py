"""The config flags every process takes: ``--config DIR`` and one flag per file, and the lines naming the files read.

Rule (README.md, "Configuration"): a file given by its own flag (``--control-config FILE``) is read as given; else
it comes from the ``--config DIR`` folder; else from the packaged defaults (:data:`servotau.config.CONFIG_DIR`).
A file the program chooses is never looked up in the working folder. A path inside a config file is looked up
next to that file, then among the packaged defaults. Every file read is named on stderr, once, by
:func:`servotau.config_paths.show_loaded_files` (the ``servotau.config`` logger's lines, shown by the entry points).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from servotau.config import ConfigFiles, Section

CONFIG_HELP = ("config folder (e.g. from servotau config init DIR): each file not given by its own flag comes from "
               "DIR, else from the packaged defaults; never from the working folder")


@dataclass(frozen=True)
class ConfigFlag:
    """A config file a command reads and the flag that overrides it."""

    name: str  # the file's name in a config folder, e.g. "control.toml"
    flags: tuple[str, ...]  # the option strings, e.g. ("--control-config",)
    dest: str  # the argparse attribute
    help: str

    @property
    def flag(self) -> str:
        return self.flags[0]


HAL = ConfigFlag("hal.toml", ("--hal-config", "--hal"), "hal",
                 "HAL config: [hal] backend = zenoh | inprocess | replay, [hal.server], [hal.safety]")
CONTROL = ConfigFlag("control.toml", ("--control-config",), "control_config", "controller config (gains, motors, "
                                                                              "safety limits)")
ESTIMATION = ConfigFlag("estimation.toml", ("--estimation-config",), "estimation_config",
                        "torque-estimator config (filters, calibration)")
SIM = ConfigFlag("sim.toml", ("--sim-config",), "sim_config", "simulation config (scenario, servo, sensors, seed)")
SIM_IDENTIFICATION = ConfigFlag("sim_identification.toml", ("--sim-config",), "sim_config",
                                "inprocess only: simulation config (scenario with the scripted operator)")
PLAN = ConfigFlag("identification.toml", ("--plan",), "plan", "identification plan (collection, [fit] defaults)")


def add_config_args(parser: argparse.ArgumentParser, *files: ConfigFlag) -> None:
    """Add ``--config DIR`` and each file's own flag (``FILE``, default: from the config folder)."""
    parser.add_argument("--config", metavar="DIR", help=CONFIG_HELP)
    for f in files:
        parser.add_argument(*f.flags, dest=f.dest, metavar="FILE", default=None,
                            help=f"{f.help} (default: {f.name} of the config folder)")


def config_files(args: argparse.Namespace, *files: ConfigFlag, announce: bool = True) -> ConfigFiles:
    """The process's :class:`~servotau.config.ConfigFiles` from the flags of :func:`add_config_args` (a line on
    stderr says where files come from, with ``announce``).

    Raises:
        ConfigError: A bad ``--config`` folder or file flag (naming it).
    """
    folder = getattr(args, "config", None)
    chosen = ConfigFiles.create(folder, {f.name: (f.flag, getattr(args, f.dest, None)) for f in files})
    if announce:
        print(chosen.describe(), file=sys.stderr, flush=True)
    return chosen


def forward(args: argparse.Namespace, *files: ConfigFlag) -> list[str]:
    """The config flags of ``args`` as command-line arguments for a child process (absolute paths)."""
    out = []
    if getattr(args, "config", None):
        out += ["--config", str(Path(args.config).absolute())]
    for f in files:
        value = getattr(args, f.dest, None)
        if value:
            out += [f.flag, str(Path(value).absolute())]
    return out


def hal_config(files: ConfigFiles) -> Section:
    """``hal.toml``'s ``[hal]`` table, its ``[hal.inprocess] scenario`` resolved next to the file (the backend
    hands the factory a path: the working folder must not be searched for it)."""
    from servotau.config import resolve_config_path
    from servotau.hal.registry import hal_section

    s = hal_section(files.path(HAL.name))
    inproc = s.data.get("inprocess")
    if isinstance(inproc, dict) and isinstance(inproc.get("scenario"), str):
        scenario = str(resolve_config_path(inproc["scenario"], s.file).absolute())
        s = Section({**s.data, "inprocess": {**inproc, "scenario": scenario}}, s.file, s.prefix)
    return s


def torque_estimator(files: ConfigFiles, info):
    """The torque estimator of the control loop (``estimation.toml``, the loop's variant) for the robot ``info``."""
    from servotau.control.estimator_variant import ESTIMATOR_VARIANT
    from servotau.estimation import EstimatorConfig, TorqueEstimator

    return TorqueEstimator(info, EstimatorConfig.from_toml(files.path(ESTIMATION.name), variant=ESTIMATOR_VARIANT))


def hanging_sim(files: ConfigFiles):
    """The hanging robot's :class:`~servotau.simrobot.sim.SimConfig` from ``scenarios/hanging.toml``, ``servo.toml``
    and ``sensors.toml`` of the config folder (else the packaged defaults)."""
    from servotau.simrobot.scenario import Scenario
    from servotau.simrobot.sensors import SensorConfig
    from servotau.simrobot.sim import SimConfig

    return SimConfig(scenario=Scenario.from_toml(files.path("scenarios/hanging.toml")),
                     servo_path=files.path("servo.toml"), sensors=SensorConfig.from_toml(files.path("sensors.toml")))
