"""servotau identify: collect actuator-identification data on a robot, fit the motor parameters.

    servotau identify collect --out runs/ident.parquet [--config DIR] [--hal hal.toml]
                              [--backend inprocess|zenoh --port N] [--plan identification.toml]
                              [--joints RLEG_JOINT0,...] [--sim-config ...]
    servotau identify fit runs/ident.parquet [--config DIR] [--joints ...] [--loss asymmetric|least_squares] [--w 100]
                          [--two-stage] [--out config/motors/identified.toml] [--json]
    servotau identify run --out motors.toml [--servo servo.toml] [--backend inprocess|zenoh --port N] [--json]

collect plays the plan (settle, high-velocity sweeps, high-torque holds; paper section 3.4) on any
HAL backend and writes the project's Parquet log; on the inprocess backend the simulated robot is
built from --sim-config (default config/sim_identification.toml: the hanging robot whose scripted
operator pushes the right foot during the plan's holds). fit estimates dq and tau off-line from the
log's sensors (non-causal, centred filters; never the ground truth), fits every joint and writes the
motor-parameter file that the controller reads. run does it all in one go: collect (on the inprocess
simulator built with --servo, or on the robot behind --backend zenoh), the paper's fit, the workbench's effects
that lower the held-out error, the dead band measured on the holds, and writes the controller's motor file with
each joint's choice and why (identification/motor_file.py). See docs/identification.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from servotau.apps.config_args import ESTIMATION, HAL, PLAN, SIM_IDENTIFICATION, add_config_args, config_files
from servotau.config import Section
from servotau.errors import IdentificationError

DEFAULT_SIM_CONFIG = "sim_identification.toml"
DEFAULT_MOTORS = "motors/identified.toml"  # in the config folder (control.toml: motors = "motors/identified.toml")


def register(sub) -> None:
    p = sub.add_parser("identify", help="actuator identification: collect data, fit k_tau and k_v (paper sec. 3)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    cmds = p.add_subparsers(dest="identify_command", required=True, metavar="STEP")

    c = cmds.add_parser("collect", help="run the collection plan on a HAL backend and record a Parquet log")
    c.add_argument("--out", required=True, help="Parquet log to write")
    c.add_argument("--backend", choices=("inprocess", "zenoh"), help="override the config's backend")
    c.add_argument("--port", type=int, help="zenoh: the robot's port on 127.0.0.1 (overrides the config)")
    c.add_argument("--joints", help="comma-separated joints to sweep (default: the plan's)")
    add_config_args(c, HAL, PLAN, SIM_IDENTIFICATION)
    c.add_argument("--ignore-timing", action="store_true",
                   help="inprocess only: run even if the scenario's pushes miss the plan's hold windows")
    c.set_defaults(func=collect_main)

    f = cmds.add_parser("fit", help="fit the actuator model of each joint on a collected log")
    f.add_argument("log", help="Parquet log from servotau identify collect (or any log with q_des)")
    f.add_argument("--joints", help="comma-separated joints to fit (default: the swept joints of the log)")
    add_config_args(f, PLAN, ESTIMATION)
    f.add_argument("--loss", choices=("asymmetric", "least_squares"), help="loss of the written fit")
    f.add_argument("--w", type=float, help="over-estimation weight of the asymmetric loss (default: plan, 100)")
    f.add_argument("--two-stage", action="store_true", help="write the two-stage fit (k_tau static, then k_v)")
    f.add_argument("--coulomb", action="store_true", help="also fit k_c sign(dq) in the written fit")
    f.add_argument("--downsample", type=int, help="keep every n-th valid sample (default: plan)")
    f.add_argument("--out", help=f"motor-parameter file to write (default: {DEFAULT_MOTORS} of the --config folder, "
                                 "or of config/ in a source checkout)")
    f.add_argument("--no-write", action="store_true", help="do not write the motor file")
    f.add_argument("--json", action="store_true", help="print one JSON object with the per-joint results")
    f.set_defaults(func=fit_main)

    r = cmds.add_parser("run", help="collect, estimate, fit the paper's model, add the workbench's effects and the "
                        "dead band, write the controller's motor file (no manual step)")
    r.add_argument("--out", required=True, help="motor-parameter file to write (the controller's motors file)")
    r.add_argument("--servo", help="inprocess only: servo config file of the simulated robot "
                   "(default config/servo.toml)")
    r.add_argument("--log", help="identification log to write (default: OUT with the suffix .parquet)")
    r.add_argument("--hal", default="hal.toml", help="HAL config: [hal] backend = zenoh | inprocess")
    r.add_argument("--backend", choices=("inprocess", "zenoh"), help="override the config's backend")
    r.add_argument("--port", type=int, help="zenoh: the robot's port on 127.0.0.1 (overrides the config)")
    r.add_argument("--plan", default="identification.toml", help="collection plan (default config/identification.toml)")
    r.add_argument("--joints", help="comma-separated joints (default: the plan's)")
    r.add_argument("--sim-config", default=DEFAULT_SIM_CONFIG,
                   help="inprocess only: simulation config (scenario with the scripted operator)")
    r.add_argument("--effects", help="effects the workbench may add (default: coulomb,deadzone,stribeck)")
    r.add_argument("--max-steps", type=int, default=3, help="most effects added per joint")
    r.add_argument("--json", action="store_true", help="print one JSON object with the per-joint choices")
    r.set_defaults(func=run_main)


# -- collect ------------------------------------------------------------------------------------------------
def hal_for_collection(hal: str, backend: str | None, sim_config: str) -> tuple[Section, str]:
    """The ``[hal]`` section of ``hal`` with the inprocess robot built from ``sim_config`` (the HAL's
    inprocess factory takes a sim config path as its ``scenario``), and the backend name."""
    from servotau.hal.registry import hal_section

    s = hal_section(hal)
    name = backend or s.str("backend", choices=("zenoh", "inprocess", "replay"))
    if name == "replay":
        raise IdentificationError(f"{s.file}: backend = \"replay\": expected a live robot (inprocess or zenoh) "
                                  "to collect on; pass --backend inprocess|zenoh")
    if name == "inprocess":
        from servotau.config import resolve_config_path

        resolve_config_path(sim_config)  # a clear error now if it does not exist
        inproc = dict(s.data.get("inprocess", {}))
        inproc["scenario"] = sim_config
        s = Section({**s.data, "backend": name, "inprocess": inproc}, f"{s.file} (with --sim-config)", s.prefix)
    return s, name


def collect_main(args) -> int:
    files = config_files(args, HAL, PLAN, SIM_IDENTIFICATION)
    collect(str(files.path(HAL.name)), args.backend, args.port, str(files.path(PLAN.name)), args.joints,
            str(files.path(SIM_IDENTIFICATION.name)), args.ignore_timing, args.out,
            progress=lambda m: print(m, flush=True))
    return 0


def collect(hal: str, backend_name: str | None, port: int | None, plan_file: str, joints_arg: str | None,
            sim_config: str, ignore_timing: bool, out: str, progress) -> None:
    """Play the plan on the backend and write the log ``out`` (``servotau identify collect``)."""
    from servotau.hal.registry import open_backend
    from servotau.identification.plan import check_joints, load_plan, parse_joints
    from servotau.identification.session import run_collection

    from .operator_script import check_timing

    plan, _ = load_plan(plan_file)
    section, name = hal_for_collection(hal, backend_name, sim_config)
    joints = parse_joints(joints_arg)
    backend = open_backend(section, backend=name, port=port)
    with backend:
        if joints is not None:
            check_joints(joints, backend.info.joint_names, "--joints")
            plan = plan.with_joints(joints)
        else:
            check_joints(plan.joints, backend.info.joint_names, f"{plan.source}: [collect] joints")
        robot = getattr(backend, "robot", None)
        scenario = getattr(getattr(robot, "config", None), "scenario", None)
        if scenario is not None:
            problems = check_timing(plan, scenario.operator, backend.info.period)
            if problems:
                msg = (f"scenario '{scenario.name}' of {sim_config} does not match the plan {plan.source}: "
                       + "; ".join(problems[:3]) + " (expected pushes inside the hold windows: see "
                       "docs/identification.md, or --ignore-timing)")
                if not ignore_timing:
                    raise IdentificationError(msg)
                print(f"servotau identify: warning: {msg}", file=sys.stderr)
        meta = {"servotau.identification.hal": str(section.file)}
        if name == "inprocess":
            meta["servotau.identification.sim_config"] = sim_config
        result = run_collection(backend, plan, out, source=name, metadata=meta, progress=progress)
    progress(f"wrote {out}: {result.rows} ticks, {result.robot_seconds:.1f} s robot time in "
          f"{result.wall_seconds:.1f} s wall" + (" (with ground truth, for evaluation only)" if result.truth else ""))


# -- fit ------------------------------------------------------------------------------------------------
def _default_motors(files):
    """Where ``fit`` writes without ``--out``: motors/identified.toml of the ``--config`` folder, or of config/ in a
    source checkout (the packaged defaults of an installed wheel are not for writing)."""
    from servotau.config import REPO_ROOT

    if files.folder is not None:
        return files.folder / DEFAULT_MOTORS
    if files.defaults.resolve() == (REPO_ROOT / "config").resolve():
        return files.defaults / DEFAULT_MOTORS
    raise IdentificationError(f"no --out and no --config: expected a motor file to write (--out FILE) or a config "
                              f"folder (--config DIR, written to DIR/{DEFAULT_MOTORS}); the packaged defaults in "
                              f"{files.defaults} are not for writing")


def fit_main(args) -> int:
    from dataclasses import replace

    from servotau.actuator.loss import Loss
    from servotau.identification.pipeline import fit_log, write_motor_file
    from servotau.identification.plan import LossKeys, load_plan, parse_joints

    files = config_files(args, PLAN, ESTIMATION)
    _, settings = load_plan(files.path(PLAN.name))
    if args.w is not None and (args.loss or settings.loss.kind) == "least_squares":
        raise IdentificationError(f"--w {args.w}: expected no weight with the least-squares loss")
    kind = args.loss or settings.loss.kind
    w = args.w if args.w is not None else (settings.loss.w or LossKeys().w)
    loss = Loss.asymmetric(w) if kind == "asymmetric" else Loss.least_squares()
    changes = {"loss": loss}
    if args.two_stage:
        changes["two_stage"] = True
    if args.coulomb:
        changes["coulomb"] = True
    if args.downsample is not None:
        changes["downsample"] = args.downsample
    settings = replace(settings, **changes)
    from servotau.estimation import EstimatorConfig

    estimation = EstimatorConfig.from_toml(files.path(ESTIMATION.name))
    report = fit_log(args.log, joints=parse_joints(args.joints), settings=settings, estimator_config=estimation,
                     progress=(lambda m: print(m, file=sys.stderr)) if args.json else print)
    if not args.no_write:
        out = args.out or _default_motors(files)
        try:
            path = write_motor_file(report, out)
        except IdentificationError:
            print(json.dumps(report.to_dict()) if args.json else report.table())  # the fits, then the error
            raise
        report = replace(report, motor_file=str(path))
    if args.json:
        print(json.dumps(report.to_dict()))
    else:
        print(report.table())
        if report.motor_file:
            print(f"wrote {report.motor_file}")
    return 0


# -- run ------------------------------------------------------------------------------------------------
def sim_config_with_servo(servo: str, sim_config: str, out: Path) -> str:
    """A sim config file ``out``: ``sim_config`` (scenario, sensors, seed) with its servo file replaced by ``servo``,
    which is read and checked first (a clear error naming the file, the joint and the field before anything
    moves)."""
    from servotau.config import load_toml, resolve_config_path
    from servotau.description import JOINT_NAMES
    from servotau.simrobot.servo_config import check_servo_file

    servo_path = resolve_config_path(servo).resolve()
    check_servo_file(servo_path, JOINT_NAMES)
    root = load_toml(sim_config)
    lines = [f"# {sim_config} with the servo {servo_path} (servotau identify run)"]
    for key in ("scenario", "sensors"):
        if key in root:
            lines.append(f'{key} = "{resolve_config_path(root.str(key)).resolve()}"')
    lines.append(f'servo = "{servo_path}"')
    if "seed" in root:
        lines.append(f"seed = {root.int('seed')}")
    if "scenario" not in root:
        raise IdentificationError(f"{sim_config}: field 'scenario' missing: expected the scenario with the scripted "
                                  "operator (config/sim_identification.toml)")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    return str(out)


def run_main(args) -> int:
    from servotau.identification.motor_file import CANDIDATES, build_motor_file, write_motor_file

    out = Path(args.out)
    log = args.log or str(out.with_suffix(".parquet"))
    if args.max_steps < 0:
        raise IdentificationError(f"--max-steps {args.max_steps}: expected an integer >= 0")
    effects = CANDIDATES
    if args.effects:
        from servotau.actuator import effect_names

        effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
        unknown = [e for e in effects if e not in effect_names()]
        if unknown:
            raise IdentificationError(f"--effects: unknown effect(s) {unknown}: expected names among {effect_names()}")
    say = (lambda m: print(m, file=sys.stderr, flush=True)) if args.json else (lambda m: print(m, flush=True))
    sim_config = args.sim_config
    if args.servo:
        if (args.backend or "inprocess") != "inprocess":
            raise IdentificationError(f"--servo {args.servo}: expected --backend inprocess (the servo file configures "
                                      "the simulated robot)")
        sim_config = sim_config_with_servo(args.servo, args.sim_config, out.with_suffix(".sim.toml"))
        args.backend = "inprocess"
    collect(args.hal, args.backend, args.port, args.plan, args.joints, sim_config, False, log, progress=say)
    report = build_motor_file(log, None, candidates=effects, max_steps=args.max_steps, plan=args.plan, progress=say)
    path = write_motor_file(report, out)
    if args.json:
        print(json.dumps({**report.to_dict(), "motor_file": str(path)}))
    else:
        print(report.table())
        print(f"wrote {path}")
    return 0
