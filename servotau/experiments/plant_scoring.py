"""Score the model workbench on the independent plant family (:mod:`.plant_family`) as a confusion matrix.

Per log: the hidden effect(s) (from the side dict), the workbench's verdict and its first two effects to add
(``Diagnosis.shortlist``: the first testable effect, then the next to add over the model with it when the first is
named, else the runner-up; ``diagnose`` with the paper's base model, as ``servotau model diagnose LOG.csv`` runs
it). Scores:

- per hidden effect, ``top1`` / ``top2``: an accepted name of the effect is first / first or second of the
  shortlist (each effect of a pair is scored on its own);
- ``named``: the verdict is ``missing_effect`` and the named effect is accepted;
- ``steps2``: the effect is named, or it is the next to add once the named one is in the model
  (``Diagnosis.then``): the first two effects the workbench tells the user to add, in order;
- on clean logs, ``false_alarm``: the verdict is ``missing_effect`` (a missing effect is named where none is
  hidden); ``unexplained`` is counted separately;
- per hidden effect, its *oracle gain* (:mod:`.plant_oracle`: the held-out gain over the paper model of the
  exact error the effect adds, the most any term could remove); the effect is *detectable* on that log when it
  reaches the workbench's materiality threshold ``MIN_GAIN``. The ``detectable`` section repeats the scores on
  the detectable effects only, counts the undetectable ones per effect, and lists the detectable misses (not
  ranked first or second): the workbench's own failures. The raw scores count every hidden effect;
- everything per part (``PARTS``, fixed seed ranges: ``tuning`` 0-49, tuned on; ``held_out`` 50-99, not tuned on
  but looked at per seed; ``unseen`` 100-999, which nobody tunes on or looks at per seed) and per sample-period
  band.

The ``unseen`` part stays unseen: :func:`run_family` reports its logs only as a counter, and its scores carry no
per-seed detail (its ``detectable`` section counts the misses instead of listing them; :func:`reveal` says
whether a row may be shown).
"""

from __future__ import annotations

import logging
import time
import warnings
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor

from .plant_family import EFFECTS, draw_plant, measure, simulate
from .plant_oracle import effect_residuals, oracle_gain, paper_fit, singles

# The workbench's names that count as finding each hidden effect: its own name; for the power-law viscous friction
# any name that mentions viscous or power (the library's is viscous_power; a user's variant counts too).
ACCEPT: dict[str, tuple[str, ...]] = {e: (e,) for e in EFFECTS}
BANDS = ((1, 2, "1-2 ms"), (3, 6, "3-6 ms"), (7, 16, "7-16 ms"))
PARTS = (("tuning", 0, 50), ("held_out", 50, 100), ("unseen", 100, 1000), ("tests", 1000, None))
"""[first seed, end) of each part; the tests draw their plants from 1000 up (looked at per seed)."""
UNSEEN = "unseen"  # the part nobody tunes on or looks at per seed
BATCH = 32  # plants simulated side by side


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


def part_of(seed: int) -> str:
    return next(name for name, lo, hi in PARTS if lo <= seed and (hi is None or seed < hi))


def reveal(row: dict) -> bool:
    """Whether ``row`` may be shown per seed (not a row of the unseen part)."""
    return row["part"] != UNSEEN


def diagnose_log(ds) -> dict:
    """The workbench's diagnosis of one log's dataset (the library call of ``servotau model diagnose``)."""
    from servotau.identification.workbench import diagnose, parse_spec

    start = time.perf_counter()
    try:
        d = diagnose(ds, parse_spec("paper", ds.signals))
    except Exception as exc:  # a crash is a result, recorded
        return {"verdict": f"error: {type(exc).__name__}: {exc}"[:200], "ranked": [], "gains": [],
                "seconds": time.perf_counter() - start}
    top = d.shortlist
    named = d.top.effect if d.verdict == "missing_effect" else None  # what the verdict names (may be ranked second)
    return {"verdict": d.verdict, "named": named, "then": d.then.effect if d.then is not None else None,
            "ranked": [c.effect for c in top],
            "gains": [round(float(c.heldout_gain), 4) for c in top], "seconds": time.perf_counter() - start}


def oracle_of(ds, t_true, residuals: dict) -> dict:
    """``oracle_gain`` per hidden effect and ``oracle_gain_all`` (every hidden effect at once) of one log's dataset;
    for a pair, ``oracle_gain_alone``: each effect's gain from its own column only (without the interaction)."""
    try:
        base = paper_fit(ds)  # the paper model's folds and held-out error, once per log
        gains = {e: round(float(oracle_gain(ds, t_true, rs, base)), 4) for e, rs in residuals.items()}
        alone = {e: round(float(oracle_gain(ds, t_true, rs[:1], base)), 4) for e, rs in residuals.items()
                 if len(rs) > 1}
    except Exception as exc:  # a crash is a result, recorded
        return {"oracle_error": f"{type(exc).__name__}: {exc}"[:200]}
    out = {"oracle_gain": {e: g for e, g in gains.items() if e != "all"}, "oracle_gain_all": gains["all"]}
    return {**out, "oracle_gain_alone": alone} if alone else out


def row_of(truth: dict, result: dict) -> dict:
    return {"seed": truth["seed"], "part": part_of(truth["seed"]), "period_ms": truth["period_ms"],
            "band": band_of(truth["period_ms"]), "hidden": list(truth["hidden"]), **result}


def _job(item):
    """One log read once (:func:`load_dataset`), diagnosed, and scored by the oracle when it hides an effect."""
    log, truth, t_true, residuals = item
    if part_of(truth["seed"]) == UNSEEN:  # no warning names anything about an unseen log
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            quiet = logging.getLogger("servotau")
            level = quiet.level
            quiet.setLevel(logging.CRITICAL + 1)
            try:
                return _scored(log, truth, t_true, residuals)
            finally:
                quiet.setLevel(level)
    return _scored(log, truth, t_true, residuals)


def _scored(log, truth: dict, t_true, residuals: dict):
    from servotau.identification.workbench import load_dataset

    start = time.perf_counter()
    try:
        ds = load_dataset(dict(log))
    except Exception as exc:  # a crash is a result, recorded (by the diagnosis and the oracle, as each read it)
        crash = f"{type(exc).__name__}: {exc}"
        return truth, {"verdict": f"error: {crash}"[:200], "ranked": [], "gains": [],
                       "seconds": time.perf_counter() - start, **({"oracle_error": crash[:200]} if truth["hidden"]
                                                                   else {})}
    read = time.perf_counter() - start
    oracle = oracle_of(ds, t_true, residuals) if truth["hidden"] else {}
    result = diagnose_log(ds)
    result["seconds"] += read  # as `servotau model diagnose` times it: reading the log, then the diagnosis
    return truth, {**result, **oracle}


def _batch(plants: list, duration: float, pool) -> list[tuple]:
    """The ``_job`` items of ``plants``: simulated side by side; the plants of each pair's effects alone (for the
    oracle) simulated meanwhile in ``pool`` (here without one)."""
    pairs = singles(plants)
    alone = pool.submit(simulate, [p for _, _, p in pairs], duration) if pool is not None and pairs else None
    trues = simulate(plants, duration)
    residuals = effect_residuals(plants, trues, alone.result() if alone is not None else None)
    return [(measure(p, tr), p.truth(), tr["t"], res) for p, tr, res in zip(plants, trues, residuals, strict=True)]


def run_family(seeds, *, workers: int = 2, duration: float = 20.0, progress=None) -> list[dict]:
    """Simulate the plants of ``seeds`` and diagnose each log; one row per log, with the oracle gains of its
    hidden effects (from the true signals, which the log does not carry). The plants are simulated ``BATCH`` at a
    time; ``workers`` processes (one pool for the run; none for 1) diagnose a batch while the next is simulated.
    ``progress`` gets a line per log, and for the unseen part only a counter ("unseen: 12/50 done")."""
    rows: list[dict] = []
    seeds = list(seeds)
    unseen = sum(part_of(s) == UNSEEN for s in seeds)
    pool = ProcessPoolExecutor(workers) if workers > 1 else None

    def collect(results) -> None:
        for truth, res in results:
            rows.append(row_of(truth, res))
            if not progress:
                continue
            if not reveal(rows[-1]):
                progress(f"{UNSEEN}: {sum(not reveal(r) for r in rows)}/{unseen} done")
                continue
            progress(f"seed {truth['seed']:4d} {truth['period_ms']:2d} ms hidden {truth['hidden'] or 'none'}: "
                     f"{res['verdict']} {res['ranked']} oracle {res.get('oracle_gain', '-')}")

    try:
        pending = None
        for b in range(0, len(seeds), BATCH):
            plants = [draw_plant(s, duration=duration) for s in seeds[b:b + BATCH]]
            if progress:
                progress(f"simulating plants {plants[0].seed}..{plants[-1].seed}")
            items = _batch(plants, duration, pool)
            if pending is not None:
                collect(pending)
            pending = pool.map(_job, items) if pool is not None else map(_job, items)
        if pending is not None:
            collect(pending)
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    return rows


def _rate(hits: int, n: int) -> float | None:
    return round(hits / n, 3) if n else None


def _score_rows(rows: list[dict]) -> dict:
    per = defaultdict(lambda: Counter())
    clean = Counter()
    for r in rows:
        if not r["hidden"]:
            clean["n"] += 1
            clean["false_alarm"] += r["verdict"] == "missing_effect"
            clean["unexplained"] += r["verdict"] == "unexplained"
            clean["error"] += r["verdict"].startswith("error")
            continue
        for e in r["hidden"]:
            c = per[e]
            c["n"] += 1
            top1, top2, named, steps = _hits(r, e)
            c["top1"] += top1
            c["top2"] += top2
            c["named"] += named
            c["steps2"] += steps
    effects = {e: {"n": c["n"], "top1": _rate(c["top1"], c["n"]), "top2": _rate(c["top2"], c["n"]),
                   "named": _rate(c["named"], c["n"]), "steps2": _rate(c["steps2"], c["n"])}
               for e, c in sorted(per.items())}
    n_eff = sum(c["n"] for c in per.values())
    return {"n_logs": len(rows), "effects": effects,
            "top1": _rate(sum(c["top1"] for c in per.values()), n_eff),
            "top2": _rate(sum(c["top2"] for c in per.values()), n_eff),
            "named": _rate(sum(c["named"] for c in per.values()), n_eff),
            "steps2": _rate(sum(c["steps2"] for c in per.values()), n_eff),
            "clean": {"n": clean["n"], "false_alarm": _rate(clean["false_alarm"], clean["n"]),
                      "unexplained": _rate(clean["unexplained"], clean["n"]), "errors": clean["error"]}}


def _named(r: dict) -> str | None:
    """The effect the row's verdict names (rows written before ``named`` was recorded: the first ranked)."""
    if r["verdict"] != "missing_effect":
        return None
    return r.get("named") or (r["ranked"][0] if r["ranked"] else None)


def _hits(r: dict, e: str) -> tuple[bool, bool, bool, bool]:
    """(top1, top2, named, steps2) of hidden effect ``e`` in row ``r``; ``steps2``: named, or the next to add once the
    named one is in the model (``Diagnosis.then``): the first two effects the workbench tells the user to add."""
    top = r["ranked"]
    named = accepted(e, _named(r))
    return (bool(top) and accepted(e, top[0]), any(accepted(e, x) for x in top[:2]), named,
            named or accepted(e, r.get("then")))


def detectable(rows: list[dict], min_gain: float) -> dict:
    """The scores restricted to the hidden effects whose oracle gain reaches ``min_gain``; the undetectable (and
    unknown: no oracle gain in the row) counted per effect; the detectable misses (not in the top two): counted
    (``n_misses``) and listed, but for the rows of the unseen part (:func:`reveal`)."""
    per = defaultdict(lambda: Counter())
    misses, n_misses = [], 0
    for r in rows:
        for e in r["hidden"]:
            c = per[e]
            g = r.get("oracle_gain", {}).get(e)
            if g is None:
                c["unknown"] += 1
                continue
            if g < min_gain:
                c["undetectable"] += 1
                continue
            top1, top2, named, steps = _hits(r, e)
            c["n"] += 1
            c["top1"] += top1
            c["top2"] += top2
            c["named"] += named
            c["steps2"] += steps
            n_misses += not top2
            if not top2 and reveal(r):
                misses.append({"seed": r["seed"], "period_ms": r["period_ms"], "hidden": r["hidden"], "effect": e,
                               "oracle_gain": g, "oracle_gain_alone": r.get("oracle_gain_alone", {}).get(e),
                               "verdict": r["verdict"], "ranked": r["ranked"], "gains": r["gains"],
                               "then": r.get("then")})
    total = Counter()
    for c in per.values():
        total.update(c)
    effects = {e: {"n": c["n"], "top1": _rate(c["top1"], c["n"]), "top2": _rate(c["top2"], c["n"]),
                   "named": _rate(c["named"], c["n"]), "steps2": _rate(c["steps2"], c["n"]),
                   "undetectable": c["undetectable"], "unknown": c["unknown"]}
               for e, c in sorted(per.items())}
    return {"min_gain": min_gain, "n": total["n"], "top1": _rate(total["top1"], total["n"]),
            "top2": _rate(total["top2"], total["n"]), "named": _rate(total["named"], total["n"]),
            "steps2": _rate(total["steps2"], total["n"]),
            "undetectable": total["undetectable"], "unknown": total["unknown"], "effects": effects,
            "n_misses": n_misses, "misses": misses}


def confusion(rows: list[dict]) -> dict:
    """Rows: hidden effect ('none' for clean); columns: the named effect, or the verdict when none is named."""
    m: dict[str, Counter] = defaultdict(Counter)
    for r in rows:
        col = _named(r) or r["verdict"]
        for e in r["hidden"] or ["none"]:
            m[e][col] += 1
    return {e: dict(sorted(c.items())) for e, c in sorted(m.items())}


def score(rows: list[dict], min_gain: float | None = None) -> dict:
    """Hit rates and false alarms per part (tuning and held out, and the unseen part when ``rows`` has some), and
    per sample-period band inside each part; the confusion matrix; the scores on the detectable effects (oracle gain
    at least ``min_gain``, default the workbench's ``MIN_GAIN``)."""
    if min_gain is None:
        from servotau.identification.workbench import MIN_GAIN as min_gain
    out = {}
    shown = [name for name, _lo, _hi in PARTS if name in ("tuning", "held_out") or any(r["part"] == name for r in rows)]
    for part in shown:
        sub = [r for r in rows if r["part"] == part]
        s = _score_rows(sub)
        s["detectable"] = detectable(sub, min_gain)
        s["bands"] = {name: _score_rows([r for r in sub if r["band"] == name]) for _lo, _hi, name in BANDS}
        s["confusion"] = confusion(sub)
        out[part] = s
    return out
