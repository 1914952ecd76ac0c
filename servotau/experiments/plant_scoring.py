"""Score the model workbench on the independent plant family (:mod:`.plant_family`) as a confusion matrix.

Per log: the hidden effect(s) (from the side dict), the workbench's verdict and its two best testable effects
(``diagnose`` with the paper's base model, as ``servotau model diagnose LOG.csv`` runs it). Scores:

- per hidden effect, ``top1`` / ``top2``: an accepted name of the effect is ranked first / first or second
  (each effect of a pair is scored on its own);
- ``named``: the verdict is ``missing_effect`` and the named effect is accepted;
- on clean logs, ``false_alarm``: the verdict is ``missing_effect`` (a missing effect is named where none is
  hidden); ``unexplained`` is counted separately;
- everything per part (``tuning``: seeds below the split; ``held_out``: the rest, which nobody tunes on) and per
  sample-period band.
"""

from __future__ import annotations

import time
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor

from .plant_family import EFFECTS, make_family

# The workbench's names that count as finding each hidden effect. The workbench has no power-law viscous term
# yet (issue 18, item 4): any effect whose name mentions viscous or power counts.
ACCEPT: dict[str, tuple[str, ...]] = {e: (e,) for e in EFFECTS}
BANDS = ((1, 2, "1-2 ms"), (3, 6, "3-6 ms"), (7, 16, "7-16 ms"))
SPLIT = 50  # seeds below: tuning part; at or above: held-out part


def accepted(hidden: str, name: str | None) -> bool:
    if name is None:
        return False
    if hidden == "viscous_power":
        return "viscous" in name or "power" in name
    return name in ACCEPT[hidden]


def band_of(period_ms: int) -> str:
    for lo, hi, name in BANDS:
        if lo <= period_ms <= hi:
            return name
    return f"{period_ms} ms"


def part_of(seed: int, split: int = SPLIT) -> str:
    return "tuning" if seed < split else "held_out"


def diagnose_log(log: dict) -> dict:
    """The workbench's diagnosis of one log (the library call of ``servotau model diagnose``)."""
    from servotau.identification.workbench import diagnose, load_dataset, parse_spec

    start = time.perf_counter()
    try:
        ds = load_dataset(dict(log))
        d = diagnose(ds, parse_spec("paper", ds.signals))
    except Exception as exc:  # a crash is a result, recorded
        return {"verdict": f"error: {type(exc).__name__}: {exc}"[:200], "ranked": [], "gains": [],
                "seconds": time.perf_counter() - start}
    top = [c for c in d.ranking if c.testable][:2]
    return {"verdict": d.verdict, "ranked": [c.effect for c in top],
            "gains": [round(float(c.heldout_gain), 4) for c in top], "seconds": time.perf_counter() - start}


def row_of(truth: dict, result: dict, split: int = SPLIT) -> dict:
    return {"seed": truth["seed"], "part": part_of(truth["seed"], split), "period_ms": truth["period_ms"],
            "band": band_of(truth["period_ms"]), "hidden": list(truth["hidden"]), **result}


def _job(item):
    log, truth = item
    return truth, diagnose_log(log)


def run_family(seeds, *, workers: int = 2, duration: float = 20.0, split: int = SPLIT, progress=None) -> list[dict]:
    """Simulate the plants of ``seeds`` and diagnose each log; one row per log."""
    rows = []
    seeds = list(seeds)
    for b in range(0, len(seeds), 32):
        family = make_family(seeds[b:b + 32], duration=duration, progress=progress)
        if workers > 1:
            with ProcessPoolExecutor(workers) as pool:
                results = list(pool.map(_job, family))
        else:
            results = [_job(item) for item in family]
        for truth, res in results:
            rows.append(row_of(truth, res, split))
            if progress:
                progress(f"seed {truth['seed']:4d} {truth['period_ms']:2d} ms hidden {truth['hidden'] or 'none'}: "
                         f"{res['verdict']} {res['ranked']}")
    return rows


def _rate(hits: int, n: int) -> float | None:
    return round(hits / n, 3) if n else None


def _score_rows(rows: list[dict]) -> dict:
    per = defaultdict(lambda: Counter())
    clean = Counter()
    for r in rows:
        top = r["ranked"]
        named = top[0] if r["verdict"] == "missing_effect" and top else None
        if not r["hidden"]:
            clean["n"] += 1
            clean["false_alarm"] += r["verdict"] == "missing_effect"
            clean["unexplained"] += r["verdict"] == "unexplained"
            clean["error"] += r["verdict"].startswith("error")
            continue
        for e in r["hidden"]:
            c = per[e]
            c["n"] += 1
            c["top1"] += bool(top) and accepted(e, top[0])
            c["top2"] += any(accepted(e, x) for x in top[:2])
            c["named"] += accepted(e, named)
    effects = {e: {"n": c["n"], "top1": _rate(c["top1"], c["n"]), "top2": _rate(c["top2"], c["n"]),
                   "named": _rate(c["named"], c["n"])} for e, c in sorted(per.items())}
    n_eff = sum(c["n"] for c in per.values())
    return {"n_logs": len(rows), "effects": effects,
            "top1": _rate(sum(c["top1"] for c in per.values()), n_eff),
            "top2": _rate(sum(c["top2"] for c in per.values()), n_eff),
            "clean": {"n": clean["n"], "false_alarm": _rate(clean["false_alarm"], clean["n"]),
                      "unexplained": _rate(clean["unexplained"], clean["n"]), "errors": clean["error"]}}


def confusion(rows: list[dict]) -> dict:
    """Rows: hidden effect ('none' for clean); columns: the named effect, or the verdict when none is named."""
    m: dict[str, Counter] = defaultdict(Counter)
    for r in rows:
        col = r["ranked"][0] if r["verdict"] == "missing_effect" and r["ranked"] else r["verdict"]
        for e in r["hidden"] or ["none"]:
            m[e][col] += 1
    return {e: dict(sorted(c.items())) for e, c in sorted(m.items())}


def score(rows: list[dict]) -> dict:
    """Hit rates and false alarms per part, and per sample-period band inside each part; the confusion matrix."""
    out = {}
    for part in ("tuning", "held_out"):
        sub = [r for r in rows if r["part"] == part]
        s = _score_rows(sub)
        s["bands"] = {name: _score_rows([r for r in sub if r["band"] == name]) for _lo, _hi, name in BANDS}
        s["confusion"] = confusion(sub)
        out[part] = s
    return out
