"""Torque control on a family of simulated servos it was not tuned on (issue 22, item 4).

Per draw of the family (servotau/experiments/servo_family.py: gains 0.6-1.5x, damping 0.5-1.5x, Coulomb 0.5-2x,
Stribeck 0.2-1.5 N m, driver dead zone 0.1-0.5 A, direction gain 0-0.15, current limit 10-20 A, per joint group),
the chain runs unattended, as a user would run it:

1. ``servotau identify run --servo DRAW.toml --out motors.toml`` (collection on the inprocess simulator with that
   servo, the paper's fit, the workbench's effects, the dead band on the holds);
2. ``servotau experiment motion --servo DRAW.toml --motors motors.toml``: the right-leg swing under the position
   servo and under torque control at each K6, errors on the true joint angles.

Scores, per K6 and per part: the share of (draw, leg joint, mean|max) where torque control beats the servo, and the
trips. Parts: ``tuning`` (seeds 0 .. n_tuning - 1, the draws the controller's tuning was looked at on) and
``held_out`` (seeds 1000 .. 1000 + n_held_out - 1, never looked at while tuning). Prints ONE JSON object; progress on
stderr. In the slow set (tests/test_bench_servo_family.py).

    python bench/servo_family.py --json [--tuning 4] [--held-out 4] [--out runs/servo_family] [--effects a,b]
                                 [--doc docs/results.md]
    python bench/servo_family.py --json --merge part1.json part2.json --doc docs/results.md
"""

import argparse
import json
import sys
import time
from pathlib import Path

from servotau.experiments.servo_family import merge, run_draw, score, write_section

HELD_OUT_SEED0 = 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print JSON (the only output format)")
    parser.add_argument("--tuning", type=int, default=4, help="draws of the tuning part (seeds 0 ..)")
    parser.add_argument("--held-out", type=int, default=4,
                        help=f"draws of the held-out part (seeds {HELD_OUT_SEED0} ..)")
    parser.add_argument("--k6", default="1,0.5,0.25", help="comma-separated K6 of the torque runs")
    parser.add_argument("--effects", default="deadzone,coulomb",
                        help="effects the workbench may add in identify run (fewer: faster)")
    parser.add_argument("--max-steps", type=int, default=2, help="most effects per joint in identify run")
    parser.add_argument("--out", default="runs/servo_family", help="folder of the servo files, logs and motor files")
    parser.add_argument("--doc", metavar="MD", help="write the section of this results document (docs/results.md)")
    parser.add_argument("--merge", nargs="+", metavar="JSON",
                        help="run nothing: merge these outputs of earlier runs (e.g. parts run in parallel)")
    parser.add_argument("--skip-done", action="store_true",
                        help="reuse the rows of draws already finished under --out (their row.json)")
    parser.add_argument("--reuse-identification", action="store_true",
                        help="keep the motor files of draws identified earlier under --out; run only the experiments")
    parser.add_argument("--from-rows", action="store_true",
                        help="run nothing: score the draws finished under --out (their row.json)")
    args = parser.parse_args()
    if args.tuning < 0 or args.held_out < 0 or args.tuning + args.held_out == 0:
        parser.error("--tuning and --held-out: expected integers >= 0, not both 0")
    if args.merge:
        result = merge([json.loads(Path(p).read_text()) for p in args.merge])
        finish(result, args.doc)
        return
    k6 = tuple(float(x) for x in args.k6.split(","))
    if args.from_rows:
        rows = {"tuning": [], "held_out": []}
        for path in sorted(Path(args.out).glob("draw_*/row.json"), key=lambda p: int(p.parent.name[5:])):
            row = json.loads(path.read_text())
            rows["held_out" if row["seed"] >= HELD_OUT_SEED0 else "tuning"].append(row)
        finish({"k6": list(k6), "seeds": {p: [r["seed"] for r in v] for p, v in rows.items()},
                "effects": args.effects.split(","), "max_steps": args.max_steps,
                "parts": {p: score(v, k6) for p, v in rows.items()},
                "all": score([x for v in rows.values() for x in v], k6), "draws": rows,
                "seconds": None}, args.doc)
        return
    start = time.perf_counter()
    say = lambda msg: print(f"[{time.perf_counter() - start:7.1f} s] {msg}", file=sys.stderr, flush=True)  # noqa: E731
    seeds = {"tuning": list(range(args.tuning)),
             "held_out": list(range(HELD_OUT_SEED0, HELD_OUT_SEED0 + args.held_out))}
    effects = tuple(e for e in args.effects.split(",") if e)
    def row(seed: int) -> dict:
        done = Path(args.out) / f"draw_{seed}" / "row.json"
        if args.skip_done and done.exists():
            return json.loads(done.read_text())
        return run_draw(seed, Path(args.out), k6, effects=effects, max_steps=args.max_steps, progress=say,
                        reuse_identification=args.reuse_identification)

    rows = {part: [row(s) for s in part_seeds] for part, part_seeds in seeds.items()}
    result = {"k6": list(k6), "seeds": seeds, "effects": list(effects), "max_steps": args.max_steps,
              "parts": {part: score(r, k6) for part, r in rows.items()},
              "all": score([x for r in rows.values() for x in r], k6),
              "draws": {part: r for part, r in rows.items()},
              "seconds": round(time.perf_counter() - start, 1)}
    finish(result, args.doc)


def finish(result: dict, doc: str | None) -> None:
    """Print the result; with ``doc``, write its section there."""
    if doc:
        from servotau.config import CONFIG_DIR, load_toml

        data = load_toml(CONFIG_DIR / "control.toml").data
        write_section(result, Path(doc), data["defaults"], data)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
