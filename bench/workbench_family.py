"""The model workbench on an independent family of servo plants (issue 18, item 6): a confusion matrix.

Simulates single-joint position-servo plants written from first principles (servotau/experiments/plant_family.py,
no simrobot, no workbench code), each clean or with one or two hidden effects, sampled every 1 to 16 ms, and
runs the workbench's diagnosis (``servotau model diagnose``, paper base) on each log. Prints ONE JSON object:
per-effect hit rates (hidden effect ranked first / first or second; named; ``steps2``: named or the next to add once
the named one is in the model), the false-alarm rate on clean logs, per part
and per sample-period band, the confusion matrix, seconds. The parts are fixed seed ranges (plant_scoring.PARTS):

- tuning: seeds 0-49, which the workbench was tuned on;
- held_out: seeds 50-99, not tuned on, but looked at per seed;
- unseen: seeds 100-999 (the tests use 1000 and up), which nobody tunes on or looks at per seed: their progress is a
  counter, their misses are counted not listed, and ``--rows`` leaves them out unless ``--reveal-unseen``.

``--n 100`` runs the tuning and held-out parts, ``--n 150`` all three. Each part's ``detectable`` section repeats
the scores on the hidden effects an oracle could detect (the exact error the effect adds, from the plant's true
signals, removes at least the workbench's MIN_GAIN of the paper model's held-out error:
servotau/experiments/plant_oracle.py), counts the undetectable ones per effect and the detectable misses, and lists
the misses of the tuning and held-out parts. Progress on stderr.

    python bench/workbench_family.py --json [--n 100] [--quick] [--workers 2] [--rows rows.json [--reveal-unseen]]
"""

import argparse
import json
import sys
import time

from servotau.experiments.plant_scoring import PARTS, reveal, run_family, score


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print JSON (the only output format)")
    parser.add_argument("--n", type=int, default=100,
                        help="plants: seeds 0 .. n-1 (0-49 tuning, 50-99 held out, 100 and up unseen)")
    parser.add_argument("--quick", action="store_true", help="8 plants of 8 s")
    parser.add_argument("--duration", type=float, default=20.0, help="log length [s]")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rows", metavar="FILE", help="also write the per-log rows (JSON; without the unseen part's)")
    parser.add_argument("--reveal-unseen", action="store_true", help="--rows: write the unseen part's rows too")
    args = parser.parse_args()
    n, duration = (8, 8.0) if args.quick else (args.n, args.duration)
    start = time.perf_counter()
    say = lambda msg: print(f"[{time.perf_counter() - start:6.1f} s] {msg}", file=sys.stderr, flush=True)  # noqa: E731
    rows = run_family(range(n), workers=args.workers, duration=duration, progress=say)
    if args.rows:
        with open(args.rows, "w") as f:
            json.dump([r for r in rows if args.reveal_unseen or reveal(r)], f, indent=1)
    parts = {name: f"seeds {lo}..{(n if hi is None else min(hi, n)) - 1}" for name, lo, hi in PARTS if lo < n}
    result = {"n": n, "split": parts, "duration_s": duration, "base": "paper", **score(rows),
              "seconds": round(time.perf_counter() - start, 1),
              "diagnose_seconds_mean": round(sum(r["seconds"] for r in rows) / max(len(rows), 1), 2)}
    print(json.dumps(result))


if __name__ == "__main__":
    main()
