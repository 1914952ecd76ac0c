"""servotau sim: the simulated HRP-2 as a robot process, served over Zenoh through the HAL.

The process speaks only the HAL protocol (docs/protocol.md), like a real-robot bridge would; ground
truth travels on its own key for evaluation. Stop it with Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from servotau.apps.config_args import HAL, SIM, add_config_args, config_files, hal_config


def register(sub) -> None:
    p = sub.add_parser("sim", help="serve the simulated HRP-2 over Zenoh (the robot process)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_config_args(p, SIM, HAL)
    p.add_argument("--port", type=int, help="listen on tcp/127.0.0.1:PORT (overrides [hal.server] listen)")
    p.add_argument("--clock", choices=("lockstep", "realtime"), help="override [hal.server] clock")
    p.add_argument("--seed", type=int, help="override the config's seed")
    p.add_argument("--log", help="Parquet log of what was served (frames, applied commands, truth)")
    p.add_argument("--max-ticks", type=int, help="stop after this many ticks")
    p.add_argument("--ready-file", help="touched once the robot is served (for scripts)")
    p.set_defaults(func=main)


def main(args) -> int:
    from servotau.hal.robot.config import server_config
    from servotau.hal.robot.server import serve
    from servotau.simrobot.sim import SimConfig, SimRobot

    if args.config and args.sim_config is None and (Path(args.config).is_file() or args.config.endswith(".toml")):
        # the flag's former meaning: the sim file
        print(f"servotau sim: --config {args.config} names a file: read as --sim-config (--config names a config "
              "folder)", file=sys.stderr)
        args = argparse.Namespace(**{**vars(args), "sim_config": args.config, "config": None})
    files = config_files(args, SIM, HAL)
    sim_config = SimConfig.from_toml(files.path(SIM.name))
    if args.seed is not None:
        sim_config = dataclasses.replace(sim_config, seed=args.seed)
    config = server_config(hal_config(files), port=args.port)
    changes = {k: v for k, v in (("clock", args.clock), ("log", args.log), ("max_ticks", args.max_ticks)) if v}
    config = dataclasses.replace(config, **changes)
    robot = SimRobot(sim_config)
    ready = (lambda: Path(args.ready_file).touch()) if args.ready_file else None
    print(f"servotau sim: {sim_config.scenario.name} scenario, {config.clock} clock, listening on "
          f"{', '.join(config.listen)}", flush=True)
    server = serve(robot, config, ready)
    print(f"servotau sim: stopped after {robot.seq} ticks ({robot.time:.2f} s sim time)", flush=True)
    return 0 if server is not None else 1
