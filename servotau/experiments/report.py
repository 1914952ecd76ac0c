"""docs/results.md: the experiments' summaries (``<out>/<name>/summary.json``) in the prose of the template
``results.md.in`` (package data; its preamble describes the format)."""

from __future__ import annotations

import json
import re
from functools import cache
from importlib import resources
from pathlib import Path

import numpy as np

from servotau.control.estimator_variant import ESTIMATOR_VARIANT
from servotau.control.loop import SETTLE

from .common import HOLD, LEG_LABELS, PAPER_MODEL, SEED, TAIL, WORKBENCH_MODEL, markdown, motors_file
from .force import FORCE_AXES
from .motion import PAPER_MAX, PAPER_MEAN

TEMPLATE = "results.md.in"


@cache
def blocks() -> dict[str, list[str]]:
    """The template's blocks: name -> paragraphs (the lines of each paragraph joined with one space)."""
    text = resources.files(__package__).joinpath(TEMPLATE).read_text(encoding="utf-8")
    out = {}
    for chunk in re.split(r"^@@ ", text, flags=re.MULTILINE)[1:]:
        name, _, body = chunk.partition("\n")
        out[name.strip()] = [" ".join(line.strip() for line in para.splitlines())
                             for para in re.split(r"\n\s*\n", body.strip())]
    return out


def block(block_name: str, /, **fields) -> list[str]:
    """The paragraphs of block ``block_name`` with ``fields`` filled in."""
    return [para.format(**fields) for para in blocks()[block_name]]


def phrase(block_name: str, /, **fields) -> str:
    """A one-paragraph block as a string."""
    (text,) = block(block_name, **fields)
    return text


def _load(out: Path, name: str) -> dict | None:
    path = out / name / "summary.json"
    return json.loads(path.read_text()) if path.exists() else None


def _paper_rms(value: float) -> float:
    """Table 2 value read as a mean squared error in rad^2 * 1e3, as RMS [mrad]."""
    return 1e3 * np.sqrt(value * 1e-3)


def _verdict(ok: bool) -> str:
    return "PASS" if ok else "MISSED"


def _fails(fails: list) -> str:
    return " " + phrase("fails", fails=fails) if fails else ""


def _tripped(tripped) -> str:
    return " " + phrase("tripped") if tripped else ""


def _motion(motion: dict, shown) -> list[str]:
    quick = " " + phrase("motion_quick") if motion["quick"] else ""
    paras = block("motion", swing=motion["swing"], tail=TAIL, motors=motion.get("motors", "?"),
                  paper_model=PAPER_MODEL, workbench_model=WORKBENCH_MODEL, quick=quick,
                  mean_table=motion["tables"]["mean"], max_table=motion["tables"]["max"])
    trips = {n: m for n, m in motion["tripped"].items() if m}
    paras += block("motion_trips", trips=trips) if trips else block("motion_no_trip")
    rows = [[n] + [("pass" if p[j]["mean"] else "FAIL") + " / " + ("pass" if p[j]["max"] else "FAIL")
                   for j in LEG_LABELS] for n, p in motion["beats_position"].items()]
    paras += block("motion_beats", table=markdown(["controller"] + list(LEG_LABELS), rows))
    k1 = motion["beats_position"].get("K6=1", {})
    ok = k1 and all(v["mean"] and v["max"] for v in k1.values())
    paras += block("motion_target", verdict=_verdict(ok),
                   fails="" if ok else " " + phrase("fails", fails=[j for j, v in k1.items()
                                                                      if not (v["mean"] and v["max"])]))
    for name, what, keys in (("K6=0.25", "beats_mean_and_max", ("mean", "max")), ("K6=0.1", "matches_mean", ("mean",))):
        p = motion["beats_position"].get(name)
        if p is None:
            continue
        fails = [j for j, v in p.items() if not all(v[k] for k in keys)]
        trip = motion["tripped"].get(name)
        paras += block("motion_beyond", motors=motion.get("motors", "?"), name=name, what=phrase(what),
                       verdict=_verdict(not fails and not trip), tripped=_tripped(trip), fails=_fails(fails))
        for other in (n for n in motion["beats_position"] if n.startswith(name + " ")):
            p = motion["beats_position"][other]
            fails = [j for j, v in p.items() if not all(v[k] for k in keys)]
            trip = motion["tripped"].get(other)
            unit = " s" if " k7=" in other else ""
            paras += block("motion_same_target", change=other.split(" ", 1)[1] + unit,
                           verdict=_verdict(not fails and not trip), tripped=_tripped(trip), fails=_fails(fails))
    cols = list(PAPER_MEAN)
    paras += block(
        "motion_paper", shown=shown,
        table2=markdown(["joint"] + cols, [[j] + [PAPER_MEAN[c][j] for c in cols] for j in LEG_LABELS[1:]]),
        table2_rms=markdown(["joint"] + [f"{c} RMS [mrad]" for c in cols],
                            [[j] + [float(_paper_rms(PAPER_MEAN[c][j])) for c in cols] for j in LEG_LABELS[1:]]),
        table3=markdown(["joint"] + cols, [[j] + [PAPER_MAX[c][j] for c in cols] for j in LEG_LABELS[1:]]))
    return paras


def _force(force: dict, shown) -> list[str]:
    quick = " " + phrase("force_quick") if force["quick"] else ""
    paras = block("force", k6=force["k6"], k_f=force["k_f"], axes=", ".join(force.get("axes", FORCE_AXES)),
                  amplitude=force["amplitude_N"], frequency=force["frequency_Hz"],
                  posture=phrase(f"posture_{force.get('posture', 'start')}"), quick=quick, table=force["table"])
    if force.get("compared_posture"):
        trips = " " + phrase("force_compared_trips", trips=force["compared_tripped"]) \
            if force.get("compared_tripped") else ""
        paras += block("force_compared", posture=force["compared_posture"], trips=trips)
    if force["tripped"]:
        paras += block("force_trip", tripped=force["tripped"])
    m = force["metrics"]["measured"]
    if m:
        paras += block("force_target", verdict=_verdict(abs(m["apex_error_pct"]) <= 5.0), apex=m["apex_error_pct"],
                       apexes=[round(v, 1) for v in m["apex_overshoots_pct"]],
                       troughs=[round(v, 1) for v in m["trough_errors_pct"]])
    return paras + block("force_figure", shown=shown)


def _components(comp: dict, shown) -> list[str]:
    f = comp["findings_joint_counts"]
    return block("components", table=comp["table"], motion_counts=f["motion: ff_friction dominates"],
                 force_counts=f["force: ff_torque dominates"], dominant=comp["dominant"], shown=shown)


def _estimation(est: dict, shown) -> list[str]:
    paras = block("estimation", variant=ESTIMATOR_VARIANT, table=est["table"], shown=shown)
    if "identification" in est:
        paras += block("identification", motors=motors_file(), paper_model=PAPER_MODEL, table=est["identification"])
    return paras


SECTIONS = (("motion", _motion), ("force", _force), ("components", _components), ("estimation", _estimation))


def write_results(out: Path, doc: Path) -> str:
    """Regenerate ``doc`` from the summaries under ``out`` (experiments not run yet are listed as missing)."""
    from servotau.config import CONFIG_DIR, REPO_ROOT, load_toml

    shown = Path(out).resolve()
    shown = shown.relative_to(REPO_ROOT) if shown.is_relative_to(REPO_ROOT) else shown  # no machine path in the doc
    gains = load_toml(CONFIG_DIR / "control.toml").data["defaults"]  # the runs' gains besides K6
    scaling = gains["k7_scaling"]
    if "k7_per_k_v" in gains:  # the velocity gain as a share of each joint's identified k_v
        k7 = phrase("k7_per_k_v" + ("_inverse_sqrt_k6" if scaling == "inverse_sqrt_k6" else ""),
                    share=gains["k7_per_k_v"])
    else:
        k7 = phrase("k7_inverse_sqrt_k6" if scaling == "inverse_sqrt_k6" else "k7_constant", k7=gains["k7"])
    paras = block("header", shown=shown, seed=SEED, variant=ESTIMATOR_VARIANT, k_p=gains["k_p"], k7=k7,
                  k7_scaling=scaling, k_iq=gains["k_iq"], settle=SETTLE, hold=HOLD)
    for name, section in SECTIONS:
        summary = _load(out, name)
        paras += block(f"{name}_title")
        paras += block("not_run") if summary is None else section(summary, shown)
    text = "\n\n".join(paras) + "\n"
    doc.parent.mkdir(parents=True, exist_ok=True)
    doc.write_text(text)
    return text
