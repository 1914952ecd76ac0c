"""Time one CausalSavgol update (80 samples, order 2, derivs 0-2, 1 kHz) for 30 and 40 channels.

Prints JSON: {"<n_channels>": <microseconds per update>, ...}, the median of 5 runs.
"""

import argparse
import json
import time

import numpy as np

from servotau.signal.savgol import CausalSavgol


def time_update(n_channels: int, n_updates: int = 20_000, n_runs: int = 5) -> float:
    """Median time of one update [us]."""
    sg = CausalSavgol(n_channels, window=80, order=2, dt=1e-3, derivs=(0, 1, 2), eval_at="centre")
    samples = np.random.default_rng(0).standard_normal((256, n_channels))
    runs = []
    for _ in range(n_runs):
        start = time.perf_counter()
        for i in range(n_updates):
            sg.update(samples[i & 255])
        runs.append((time.perf_counter() - start) / n_updates * 1e6)
    return float(np.median(runs))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--json", action="store_true", help="print JSON (the only output format)")
    parser.parse_args()
    result = {"window": 80, "order": 2, "derivs": [0, 1, 2]}
    result["us_per_update"] = {str(n): round(time_update(n), 2) for n in (30, 40)}
    print(json.dumps(result))


if __name__ == "__main__":
    main()
