"""Speed of the model workbench (issue 18, item 7): diagnose on 10^5 samples with the whole effect library.

The log is a plant of the independent family (servotau/experiments/plant_family.py) at 1 kHz, 100 s, with a
hidden Coulomb friction. Prints ONE JSON object: samples, seconds (diagnose only, and load + diagnose), the
target (<= 10 s on a 2-core machine), whether it is met, the CPU seconds of the process over load + diagnose
(``cpu_s``: what an unloaded machine would take with one BLAS thread; wall time on a shared machine moves with its
load) and the wall and CPU seconds of each stage (``stages``, ``stages_cpu``; exclusive: a stage's time excludes
the stages it calls):

- ``load``: reading the columns and differentiating (``load_dataset`` without the window choice);
- ``window``: the SG windows and orders chosen by cross-validation (``cv_window``, ``cv_derivative``);
- ``base``: the current model's shapes, its fit and its held-out prediction (``compare``, ``base_per_fold``);
- ``grid``: every effect's held-out score, each shape of its grid fitted on each fold's training blocks;
- ``full``: every effect's shape and coefficient on all samples;
- ``check``: the faster-derivative checks of a lag-like effect and of a probe that would call the log
  ``unexplained`` (``recheck_probes``: its base fits; the probes it re-runs count as ``probes``);
- ``probes``: the non-parametric probes;
- ``next``: the next effect to add (its re-scored effects count as ``grid`` and ``full``);
- ``verdict``: the verdict (confusion, tail);
- ``other``: the rest of ``diagnose``.

A second log, the same with a share ``--gaps`` of its rows (default 5 %) made NaN at random (a logger that drops
samples: thousands of runs, every filter with memory or a window restarts at each), is loaded and diagnosed in the
same run: ``gappy`` gives its samples, runs, seconds and their ratio to the log without gaps (``--gaps 0``: not run).

    python bench/workbench_speed.py --json [--samples 100000] [--repeat 1] [--gaps 0.05]
"""

import argparse
import json
import sys
import time
from contextlib import contextmanager

import numpy as np
import scipy.signal  # noqa: F401  (the filters import it on first use: a second of imports, not of the workbench)

from servotau.experiments.plant_family import draw_plant, measure, simulate
from servotau.identification.workbench import diagnose, effect_names, load_dataset, parse_spec

TARGET_S = 10.0
STAGES = {  # module -> {function: stage}; functions a version of the code lacks are skipped; "x?": x if called
    # directly by diagnose, else part of the caller's stage
    "servotau.identification.workbench.data": {"cv_window": "window", "cv_derivative": "window"},
    "servotau.identification.workbench.diagnose": {
        "compare": "base", "base_per_fold": "base", "resolve_shapes": "base?", "_score_effect": "grid",
        "_full_fit": "full", "_checked": "check", "_gain_with": "check", "probe_gains": "probes", "_then": "next",
        "verdict_of": "verdict", "recheck_probes": "check",
    },
    "servotau.identification.workbench.verdict": {"probe_gains": "probes"},
}


class StageClock:
    """Exclusive wall and CPU time per stage: a stage entered inside another pauses the outer one."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self._stack: list[str] = []
        self._t, self._c = time.perf_counter(), time.process_time()

    def _tick(self) -> None:
        now, cpu = time.perf_counter(), time.process_time()
        if self._stack:
            top = self._stack[-1]
            self.seconds[top] = self.seconds.get(top, 0.0) + now - self._t
            self.cpu[top] = self.cpu.get(top, 0.0) + cpu - self._c
        self._t, self._c = now, cpu

    @contextmanager
    def stage(self, name: str):
        self._tick()
        self._stack.append(name)
        try:
            yield
        finally:
            self._tick()
            self._stack.pop()

    def wrap(self, fn, name: str):
        def timed(*args, **kwargs):
            if name.endswith("?") and self._stack[-1:] != ["other"]:
                return fn(*args, **kwargs)
            with self.stage(name.rstrip("?")):
                return fn(*args, **kwargs)
        return timed


@contextmanager
def instrumented(clock: StageClock):
    """The functions of :data:`STAGES` wrapped in their modules (calls through the module globals are timed),
    restored on exit."""
    saved = []
    for module, funcs in STAGES.items():
        mod = sys.modules[module]
        for fn, stage in funcs.items():
            if hasattr(mod, fn):
                saved.append((mod, fn, getattr(mod, fn)))
                setattr(mod, fn, clock.wrap(getattr(mod, fn), stage))
    try:
        yield
    finally:
        for mod, fn, orig in saved:
            setattr(mod, fn, orig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print JSON (the only output format)")
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=1, help="runs of load + diagnose; the fastest is reported")
    parser.add_argument("--gaps", type=float, default=0.05, help="share of rows dropped in the second log (0: none)")
    args = parser.parse_args()
    if not 0.0 <= args.gaps < 0.5:
        parser.error(f"--gaps {args.gaps}: expected a share in [0, 0.5)")
    plant = draw_plant(0, hidden=("coulomb",), period=1e-3, duration=args.samples * 1e-3)
    log = measure(plant, simulate([plant], args.samples * 1e-3)[0])
    best = None
    for _ in range(args.repeat):
        clock = StageClock()
        with instrumented(clock):
            start = time.perf_counter()
            with clock.stage("load"):
                ds = load_dataset(log)
            loaded = time.perf_counter()
            with clock.stage("other"):
                d = diagnose(ds, parse_spec("paper", ds.signals))
            end = time.perf_counter()
        if best is None or end - start < best[0]:
            best = (end - start, end - loaded, d, dict(clock.seconds), dict(clock.cpu))
    total, diag_s, d, stages, cpu = best
    gappy = _gappy(log, args.gaps, total) if args.gaps > 0 else None
    print(json.dumps({"samples": int(ds.n), "effects": len(effect_names()), "verdict": d.verdict,
                      "top": d.top.effect if d.top else None,
                      "diagnose_s": round(diag_s, 2), "load_and_diagnose_s": round(total, 2),
                      "cpu_s": round(sum(cpu.values()), 2),
                      "stages": {k: round(v, 2) for k, v in sorted(stages.items(), key=lambda kv: -kv[1])},
                      "stages_cpu": {k: round(v, 2) for k, v in sorted(cpu.items(), key=lambda kv: -kv[1])},
                      "target_s": TARGET_S, "met": total <= TARGET_S, "gappy": gappy}))


def _gappy(log: dict, share: float, clean_s: float) -> dict:
    """Load and diagnose ``log`` with a ``share`` of its rows dropped at random (q made NaN); seconds and the ratio
    to ``clean_s``, the log without gaps measured in the same run."""
    rng = np.random.default_rng(0)
    q = np.array(log["q"], dtype=float)
    q[rng.random(q.size) < share] = np.nan
    start = time.perf_counter()
    ds = load_dataset({**log, "q": q})
    d = diagnose(ds, parse_spec("paper", ds.signals))
    seconds = time.perf_counter() - start
    return {"samples": int(ds.n), "runs": len(ds.signals.starts), "verdict": d.verdict,
            "top": d.top.effect if d.top else None, "load_and_diagnose_s": round(seconds, 2),
            "ratio_to_without_gaps": round(seconds / clean_s, 2)}


if __name__ == "__main__":
    main()
