"""Speed of the model workbench (issue 18, item 7): diagnose on 10^5 samples with the whole effect library.

The log is a clean plant of the independent family (servotau/experiments/plant_family.py) at 1 kHz, 100 s.
Prints ONE JSON object: samples, seconds (diagnose only, and load + diagnose), the target (<= 10 s on a 2-core
machine) and whether it is met.

    python bench/workbench_speed.py --json [--samples 100000]
"""

import argparse
import json
import time

from servotau.experiments.plant_family import draw_plant, measure, simulate
from servotau.identification.workbench import diagnose, effect_names, load_dataset, parse_spec

TARGET_S = 10.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print JSON (the only output format)")
    parser.add_argument("--samples", type=int, default=100_000)
    args = parser.parse_args()
    plant = draw_plant(0, hidden=("coulomb",), period=1e-3, duration=args.samples * 1e-3)
    log = measure(plant, simulate([plant], args.samples * 1e-3)[0])
    start = time.perf_counter()
    ds = load_dataset(log)
    loaded = time.perf_counter()
    d = diagnose(ds, parse_spec("paper", ds.signals))
    end = time.perf_counter()
    print(json.dumps({"samples": int(ds.n), "effects": len(effect_names()), "verdict": d.verdict,
                      "diagnose_s": round(end - loaded, 2), "load_and_diagnose_s": round(end - start, 2),
                      "target_s": TARGET_S, "met": end - start <= TARGET_S}))


if __name__ == "__main__":
    main()
