"""``servotau experiment``: the paper's experiments (Del Prete et al. 2015, section 5) on the simulated HRP-2.

Each run is deterministic (in-process lock-step backend, fixed seed; :mod:`.common`):

- ``motion`` (5.3, Tables 2-3, Fig. 4; :mod:`.motion`): the hanging robot swings its right leg under the native
  position servo and under torque control at K6 = 1, 0.5, 0.25, 0.1; RMS and max tracking error per right-leg joint
  [mrad], on the TRUE joint angles (simulator ground truth).
- ``force`` (5.4, Fig. 5; :mod:`.force`): standing, right foot on a 5 cm block, sinusoidal vertical force reference,
  K6 = 0.1, K_f = 1; overshoot at the apexes, coupling on x and y, delay (cross-correlation).
- ``components`` (5.5, Fig. 6; :mod:`.components`): RMS share of each command component in motion (K6 = 1, 0.1)
  and force control.
- ``estimation`` (:mod:`.estimation`): estimated vs true joint torques on the motion run (K6 = 1), and the
  identified motor models against the simulator's servo parameters (config/servo.toml, evaluation only).

``motion`` and ``force`` run on any servo and motor file: ``servotau experiment motion --servo FILE --motors FILE
--out DIR`` (the servo file has config/servo.toml's field names; the motor file is e.g. ``servotau identify run``'s);
both are checked before anything moves (:func:`check_files`), only the K6 sweep (or the force run) is run, and
docs/results.md is left alone unless ``--doc`` names it.

Every experiment writes ``<out>/<name>/``: ``summary.json``, tables (CSV and Markdown), PNG figures and,
with ``--rerun``, one ``.rrd`` per run; then :func:`~.report.write_results` regenerates ``docs/results.md`` from
all the summaries found under ``<out>`` and the prose of ``results.md.in``. A safety trip is a result (its message
is recorded), not a crash.
"""

from __future__ import annotations

from pathlib import Path

from servotau.errors import ConfigError

from .components import run_components
from .estimation import run_estimation
from .force import run_force
from .motion import run_motion
from .report import write_results

EXPERIMENTS = {"motion": run_motion, "force": run_force, "components": run_components, "estimation": run_estimation}

__all__ = ["EXPERIMENTS", "main", "register", "write_results"]


def register(sub) -> None:
    p = sub.add_parser("experiment", help="reproduce the paper's experiments (section 5) on the simulated robot")
    p.add_argument("name", choices=(*EXPERIMENTS, "all"), help="which experiment")
    p.add_argument("--out", default="runs/experiments", help="output directory (tables, figures, summaries)")
    p.add_argument("--quick", action="store_true", help="short version (fewer controllers, shorter force run)")
    p.add_argument("--rerun", action="store_true", help="also save one Rerun .rrd per run under --out")
    p.add_argument("--doc", default=None,
                   help="results document regenerated from --out ('' to skip; default docs/results.md, none with "
                   "--servo or --motors)")
    p.add_argument("--servo", help="motion, force: servo config file of the simulated robot (default "
                   "config/servo.toml; field names as config/servo.toml)")
    p.add_argument("--motors", help="motion, force: the controller's motor file (default: config/control.toml's), e.g. "
                   "from servotau identify run")
    p.set_defaults(func=main)


def main(args) -> int:
    out = Path(args.out)
    names = list(EXPERIMENTS) if args.name == "all" else [args.name]
    given = {k: v for k, v in (("servo", args.servo), ("motors", args.motors)) if v}
    if given:
        check_files(args.servo, args.motors)
        if any(n not in ("motion", "force") for n in names):
            raise ConfigError(f"--servo/--motors with experiment '{args.name}': expected motion or force")
    doc = args.doc if args.doc is not None else ("" if given else "docs/results.md")
    for name in names:
        summary = EXPERIMENTS[name](out, quick=args.quick, rerun=args.rerun, **given)
        print(f"== {name} ({out / name})")
        for key in ("tables", "table"):
            if key in summary:
                tables = summary[key] if isinstance(summary[key], dict) else {"": summary[key]}
                for t in tables.values():
                    print(t)
    if doc:
        write_results(out, Path(doc))
        print(f"wrote {doc}")
    return 0


def check_files(servo: str | None, motors: str | None) -> None:
    """Read and check the servo file (every joint, no negative gain) and the motor file (every torque joint of
    config/control.toml, a loop the model predicts stable) before anything moves; errors name the file, the joint
    and the field."""
    from servotau.description import JOINT_NAMES

    if servo is not None:
        from servotau.config import resolve_config_path
        from servotau.simrobot.servo_config import check_servo_file

        check_servo_file(resolve_config_path(servo), JOINT_NAMES)
    if motors is not None:
        from servotau.simrobot.sim import SimRobot

        from .common import control_config, sim_config

        robot = SimRobot(sim_config("hanging", 0, servo))
        control_config(robot.info, None, (), motors=motors)  # the torque joints' models and their predicted loops
