"""servotau model compare|diagnose|add|simulate: the model workbench on the command line.

    servotau model compare  LOG... [--joint J] [--base paper|coulomb|EFFECT+...] [--model motors.toml [--any-target]]
    servotau model diagnose LOG... [--joint J] [--base ...] [--effects a,b] [--min-gain 0.1]
    servotau model add      LOG... [--joint J] [--base ...] [--effect NAME ...] [--save motors.toml [--dead-band holds]]
    servotau model simulate OUT.parquet [--hidden EFFECT ...] [--cycles 4] [--seed 0]

Several LOGs: one segment each (held out: leave-one-recording-out; --folds defaults to their number);
LOG... is one or more logs; --test LOG scores the final model on a recording it was not fitted on.
--save writes what the model predicts (servo error [rad], torque [N m], a column in --unit), its offset, and
no k_tau if it has none; compare --model refuses a model of another target unless --any-target.
Common options: --map ROLE=COLUMN (column roles for other tables), --unit U (the target's unit when its
role does not say it: a servo log's error is in rad, a torque or friction target in N m),
--offset auto|on|off (a constant term in the base; auto: on unless the target is a servo error),
--loss least_squares|asymmetric with --w, --folds, --plugin FILE.py (registers user effects), --report DIR (HTML + PNG),
--rerun save:FILE.rrd|connect:ADDR|spawn, --json (one JSON object on stdout). Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import runpy
import sys
import time
from pathlib import Path

from servotau.actuator import Loss, effect_names
from servotau.actuator.terms import K_TAU, K_V, OFFSET
from servotau.apps.config_args import ESTIMATION, add_config_args, config_files, hanging_sim
from servotau.errors import IdentificationError
from servotau.identification.data import ROLES
from servotau.identification.data.folds import DEFAULT_FOLDS, folds_of
from servotau.identification.workbench.data import OFFLINE_ESTIMATE, align_torque, describe, load_dataset
from servotau.identification.workbench.diagnose import MIN_GAIN, diagnose
from servotau.identification.workbench.evaluate import compare
from servotau.identification.workbench.ladder import add_effects, save_model
from servotau.identification.workbench.model import FittedModel, ModelSpec, parse_spec
from servotau.identification.workbench.recordings import combine
from servotau.identification.workbench.units import unit_of


def register(subparsers) -> None:
    p = subparsers.add_parser("model", help="model workbench: compare, diagnose, add effects",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="model_command", required=True, metavar="SUBCOMMAND")
    for name, text in (("compare", "model against measurement, residual views"),
                       ("diagnose", "rank the missing effects by held-out gain"),
                       ("add", "add effects (named, or greedily) and show the ladder")):
        sp = sub.add_parser(name, help=text)
        _common(sp)
        if name == "compare":
            sp.add_argument("--model", metavar="TOML", help="evaluate this motor-parameter file (no refit)")
            sp.add_argument("--any-target", action="store_true",
                            help="with --model: score it even if it was fitted on another target or unit (e.g. a "
                                 "friction-torque model on a servo-error log)")
        if name in ("diagnose", "add"):
            sp.add_argument("--effects", metavar="A,B", help="effects to rank (default: all registered)")
            sp.add_argument("--min-gain", type=float, default=MIN_GAIN, help="held-out gain that names an effect")
        if name == "add":
            sp.add_argument("--effect", action="append", metavar="NAME",
                            help="add this effect (repeatable, in order); default: greedy by diagnosis")
            sp.add_argument("--max-steps", type=int, default=4, help="most effects the greedy search adds")
            sp.add_argument("--save", metavar="TOML", help="write the final model into this motor-parameter file")
            sp.add_argument("--dead-band", choices=("holds",),
                            help="with --save, on a servotau log: replace the saved joint's deadzone term by the "
                                 "dead band measured on the log's holds (identification/deadband.py)")
        sp.set_defaults(func=run)
    sim = sub.add_parser("simulate", help="a log of the simulated HRP-2 with hidden effects (to try the workbench)")
    sim.add_argument("out", help="output table (.parquet or .csv)")
    sim.add_argument("--hidden", action="append", default=[], metavar="EFFECT",
                     help="hidden effect of the simulator (simrobot/servo_config.py EFFECT_PARAMS), repeatable")
    sim.add_argument("--joint", default="RLEG_JOINT3")
    sim.add_argument("--cycles", type=int, default=4, help="excitation cycles of 4 s")
    sim.add_argument("--seed", type=int, default=0)
    sim.add_argument("--quiet", action="store_true")
    add_config_args(sim)  # scenarios/hanging.toml, servo.toml and sensors.toml of the simulated robot
    sim.set_defaults(func=run_simulate)


def run_simulate(args: argparse.Namespace) -> int:
    from servotau.identification.data import write_table
    from servotau.identification.data.tables import table_format
    from servotau.simrobot.servo import EFFECTS

    from .simlog import ExcitationPlan, simulate_log

    unknown = [e for e in args.hidden if e not in EFFECTS]
    if unknown:
        raise IdentificationError(f"--hidden: unknown simulator effect(s) {unknown}: expected some of {list(EFFECTS)}")
    if args.cycles < 1:
        raise IdentificationError(f"--cycles {args.cycles}: expected at least 1")
    table_format(args.out)  # an unknown format is refused before the simulation, not after
    say = None if args.quiet else (lambda msg: print(msg, file=sys.stderr, flush=True))
    cols = simulate_log({e: {} for e in args.hidden}, joint=args.joint, plan=ExcitationPlan(cycles=args.cycles),
                        seed=args.seed, progress=say, base=hanging_sim(config_files(args)))
    path = write_table(cols, args.out)
    print(f"{path}: {len(cols['t'])} rows, hidden effects {args.hidden or 'none'} on {args.joint}")
    return 0


def _common(sp: argparse.ArgumentParser) -> None:
    sp.add_argument("log", nargs="+", help="log table(s) (.parquet or .csv); several: one segment each, held out "
                                           "by recording")
    sp.add_argument("--test", action="append", default=[], metavar="LOG",
                    help="score the final model (fitted on the LOGs) on this recording too, not fitted on it "
                         "(repeatable)")
    sp.add_argument("--joint", help="joint of a servotau log (q/<joint>, q_des/<joint>, est/tau/<joint>)")
    sp.add_argument("--map", action="append", default=[], metavar="ROLE=COLUMN",
                    help=f"column of a role, one of {', '.join(ROLES)} (repeatable)")
    sp.add_argument("--unit", metavar="U",
                    help="unit of the target when its role does not say it (rad and 'N m' choose a prefix); "
                         "default: rad for a servo log, N m for a torque or friction column")
    sp.add_argument("--offset", choices=("auto", "on", "off"), default="auto",
                    help="a constant term in the base model (auto: on for a table whose target is not a servo "
                         "error, off for servo logs)")
    sp.add_argument("--base", default="paper", help="base model: paper (k_tau, k_v), coulomb, or effects joined by +; "
                                                     "naming k_tau or k_v keeps only those named (k_v+coulomb)")
    sp.add_argument("--loss", default="least_squares", choices=("least_squares", "asymmetric"))
    sp.add_argument("--w", type=float, default=10.0, help="over-estimation weight of the asymmetric loss")
    sp.add_argument("--folds", type=int, default=DEFAULT_FOLDS, help="held-out blocks (or the log's segments)")
    sp.add_argument("--smooth-torque", type=float, default=None, metavar="S",
                    help="window [s] of the torque's centred smoothing (0: none; default: chosen from the torque's "
                         "noise by cross-validation)")
    sp.add_argument("--align-torque", type=float, default=0.0, metavar="S",
                    help="re-time the torque against the encoders, searching +/- S seconds (0: off)")
    sp.add_argument("--plugin", action="append", default=[], metavar="FILE.py",
                    help="Python file that registers user effects (register_effect)")
    sp.add_argument("--report", metavar="DIR", help="write an HTML report with PNG plots into DIR")
    sp.add_argument("--rerun", metavar="TARGET", help="save:FILE.rrd, connect:ADDR or spawn")
    sp.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    sp.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_config_args(sp, ESTIMATION)  # the off-line estimator of a servotau log without an estimate


def _base_spec(text: str, signals, offset: bool) -> ModelSpec:
    """``--base``: :func:`parse_spec`, except that naming ``k_tau`` or ``k_v`` gives exactly the linear terms
    named (``k_v+coulomb``: no ``k_tau`` even with a torque column)."""
    names = [n.strip() for n in text.replace(",", "+").split("+") if n.strip()]
    linear = [n for n in names if n in (K_TAU, K_V)]
    spec = parse_spec([n for n in names if n not in linear], signals, offset=offset)
    if not linear:
        return spec
    missing = [k for k in linear if k not in spec.linear]
    if missing:
        raise IdentificationError(f"--base {text}: {missing} named, but the log has no "
                                  f"{'torque' if K_TAU in missing else 'velocity'}: expected a column of that role")
    return ModelSpec(tuple(k for k in spec.linear if k in linear or k == OFFSET), spec.terms)


def _roles(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        role, sep, col = item.partition("=")
        if not sep or not role or not col:
            raise IdentificationError(f"--map {item!r}: expected ROLE=COLUMN with ROLE one of {list(ROLES)}")
        role, col = role.strip(), col.strip()
        if role in out and out[role] != col:
            raise IdentificationError(f"--map {role}={col}: role {role} is already mapped to column '{out[role]}': "
                                      "expected one column per role")
        out[role] = col
    return out


def _plugins(paths: list[str]) -> None:
    for p in paths:
        if not Path(p).is_file():
            raise IdentificationError(f"--plugin {p}: file not found: expected a Python file calling register_effect")
        try:
            runpy.run_path(p, run_name="servotau_workbench_plugin")
        except IdentificationError:
            raise
        except Exception as exc:
            raise IdentificationError(f"--plugin {p}: failed ({type(exc).__name__}: {exc})") from exc


MAX_FOLDS = 100  # held-out blocks: more leave blocks shorter than the filters and the guard bands around them


def _check_options(args: argparse.Namespace) -> None:
    """Refuse, before anything is read or fitted, an output that would overwrite an input or could not be written
    (no folder is created but the report's own), and a count out of range."""
    inputs = {Path(p).resolve() for p in [*args.log, *getattr(args, "test", []), getattr(args, "model", None)] if p}

    def output(option: str, value: str, path: Path) -> None:
        if path.resolve() in inputs:
            raise IdentificationError(f"{option} {value}: is an input of this command: expected another file")
        if path.is_dir():
            raise IdentificationError(f"{option} {value}: is a folder: expected a file")
        if not path.parent.is_dir():
            raise IdentificationError(f"{option} {value}: folder {path.parent} does not exist: expected an existing "
                                      "folder")

    if args.rerun and args.rerun.startswith("save:"):
        target = Path(args.rerun[len("save:"):])
        if target.suffix != ".rrd":
            raise IdentificationError(f"--rerun {args.rerun}: expected save:FILE.rrd (a Rerun recording)")
        output("--rerun", args.rerun, target)
    if getattr(args, "save", None):
        output("--save", args.save, Path(args.save))
    if args.report and Path(args.report).exists() and not Path(args.report).is_dir():
        raise IdentificationError(f"--report {args.report}: is a file: expected a folder (created if missing)")
    if not 2 <= args.folds <= MAX_FOLDS:
        raise IdentificationError(f"--folds {args.folds}: expected 2 to {MAX_FOLDS}")
    if getattr(args, "max_steps", 1) < 1:
        raise IdentificationError(f"--max-steps {args.max_steps}: expected at least 1")
    if args.smooth_torque is not None and not (math.isfinite(args.smooth_torque) and args.smooth_torque >= 0):
        raise IdentificationError(f"--smooth-torque {args.smooth_torque}: expected a window >= 0 s (0: no smoothing)")
    if not (math.isfinite(args.align_torque) and args.align_torque >= 0):
        raise IdentificationError(f"--align-torque {args.align_torque}: expected a search range >= 0 s (0: off)")
    seen: dict[Path, str] = {}
    for option, p in [("log", p) for p in args.log] + [("--test", p) for p in getattr(args, "test", [])]:
        key = Path(p).resolve()
        if key in seen:
            raise IdentificationError(f"{option} {p}: the same file as {seen[key]}: expected each recording once "
                                      "(a recording fitted on is not held out)")
        seen[key] = f"{option} {p}"


def run(args: argparse.Namespace) -> int:
    start = time.perf_counter()

    def say(msg: str) -> None:
        if not args.quiet:
            print(f"[{time.perf_counter() - start:6.1f} s] {msg}", file=sys.stderr, flush=True)

    _plugins(args.plugin)
    _check_options(args)
    loss = Loss.asymmetric(args.w) if args.loss == "asymmetric" else Loss.least_squares()
    dead_band = getattr(args, "dead_band", None)
    if dead_band and not args.save:
        raise IdentificationError(f"--dead-band {dead_band}: expected --save FILE (the dead band goes into the saved "
                                  "motor file)")
    say(f"reading {', '.join(args.log)}")
    roles = _roles(args.map)
    from servotau.estimation.config import EstimatorConfig

    estimation = EstimatorConfig.from_toml(config_files(args, ESTIMATION).path(ESTIMATION.name))
    read = {"joint": args.joint, "roles": roles, "estimator_config": estimation, "smooth_torque_s": args.smooth_torque}
    ds = combine([load_dataset(p, **read) for p in args.log])
    if len(args.log) > 1 and args.folds == DEFAULT_FOLDS:
        args.folds = len(args.log)
    if dead_band and ds.joint is None:
        raise IdentificationError(f"--dead-band {dead_band}: {ds.source} names no joint: expected a servotau log "
                                  "(its holds are read per joint, --joint J)")
    if args.align_torque > 0:
        ds, shift = align_torque(ds, args.align_torque)
        say(f"torque re-timed by {1e3 * shift:.0f} ms")
    for line in describe(ds):
        say(line)
    if args.unit and ds.actuator and args.unit.strip().lower() != "rad":
        raise IdentificationError(f"--unit {args.unit}: the target of {ds.source} is the servo error q_des - q, in "
                                  "[rad] by its role: expected no --unit (convert q and q_des to rad)")
    unit = unit_of(ds, args.unit)
    say(f"error: {unit.quantity} [{unit.si}], shown in {unit.symbol}")
    offset = args.offset == "on" or (args.offset == "auto" and not ds.actuator)
    spec = _base_spec(args.base, ds.signals, offset)
    folds = folds_of(ds, args.folds)
    effects = None
    if getattr(args, "effects", None):
        effects = [e.strip() for e in args.effects.split(",") if e.strip()]
        unknown = [e for e in effects if e not in effect_names()]
        if unknown:
            raise IdentificationError(f"--effects: unknown effect(s) {unknown}: expected names among {effect_names()}")
    out: dict = {"command": args.model_command, "data": {"source": ds.source, "joint": ds.joint, "n": ds.n,
                                                         "dropped_rows": ds.n_dropped, "notes": list(ds.notes),
                                                         "heldout_blocks": [f.label for f in folds]},
                 "unit": unit.to_dict()}
    comparison = diagnosis = ladder = None
    if args.model_command == "compare":
        if args.model:
            from servotau.actuator import MotorParameters

            params = MotorParameters.load_toml(args.model)
            joint = ds.joint or (next(iter(params)) if len(params) == 1 else None)
            if joint is None:
                raise IdentificationError(f"--model {args.model}: several joints {list(params)}: expected --joint")
            motor = params[joint]
            if not args.any_target:
                _same_target((motor.target, motor.unit), unit, f"--model {args.model} [{joint}]", ds.source)
            given = FittedModel.from_motor_model(motor)
            _has_signals(given, ds, f"--model {args.model} [{joint}]")
            comparison = compare(ds, given, loss)
            spec = given.spec
            out["given"] = {"file": args.model, "joint": joint, "target": motor.target, "unit": motor.unit,
                            "provenance": motor.provenance}
            say(f"model {spec.label()} from {args.model} [{joint}], fitted on {motor.provenance.split(';')[0]}: "
                "scored on this log without refitting (train = this log)")
        else:
            say(f"fitting {spec.label()} ({loss})")
            comparison = compare(ds, spec, loss, folds=folds)
        say("ranking the missing effects")
        diagnosis = diagnose(ds, spec, loss, folds=folds, progress=say if not args.quiet else None)
        out.update(_comparison_dict(comparison))
        out.update(_diagnosis_dict(diagnosis))
    elif args.model_command == "diagnose":
        diagnosis = diagnose(ds, spec, loss, effects=effects, folds=folds, min_gain=args.min_gain,
                             progress=say if not args.quiet else None)
        out.update(_comparison_dict(diagnosis.base))
        out.update(_diagnosis_dict(diagnosis))
    else:
        if args.effect:
            unknown = [e for e in args.effect if e not in effect_names()]
            if unknown:
                raise IdentificationError(f"--effect: unknown effect(s) {unknown}: expected one of {effect_names()}")
        ladder = add_effects(ds, spec, loss, effects=args.effect, candidates=effects, max_steps=args.max_steps,
                             min_gain=args.min_gain, folds=folds, progress=say if not args.quiet else None)
        diagnosis = ladder.diagnoses[-1]
        out.update(_comparison_dict(ladder.rungs[-1].comparison))
        out.update(_diagnosis_dict(diagnosis))
        out.update(ladder.to_dict())
        if args.save:
            joint = ds.joint or "joint"
            tau = ds.roles.get("torque", "no torque")
            if any(OFFLINE_ESTIMATE in note for note in ds.notes):
                tau += f" ({OFFLINE_ESTIMATE})"
            path = save_model(ladder, args.save, joint,
                              provenance=f"{ds.source}; servotau model add; {loss}; tau: {tau}",
                              dead_band_log=args.log[0] if dead_band else None, target=unit.quantity, unit=unit.si)
            out["saved"] = {"file": str(path), "joint": joint, "target": unit.quantity, "unit": unit.si}
            say(f"saved {ladder.final.spec.label()} to {path} [{joint}]")
            if dead_band:
                from servotau.actuator import MotorParameters

                d = MotorParameters.load_toml(path)[joint].extra["deadzone"].coefficient
                out["saved"]["dead_band"] = d
                say(f"deadzone: d = {1e3 * d:.3f} mrad on the holds of {args.log[0]}")
    test_row = None  # (label, metrics) of the recordings scored but not fitted on
    if args.test:
        final = (ladder.final if ladder is not None
                 else comparison.model if comparison is not None else diagnosis.base.model)
        test = combine([load_dataset(p, **read) for p in args.test])
        _has_signals(final, test, f"the model fitted on {ds.source}")
        tested = compare(test, final, loss)
        out["test"] = {"source": test.source, "n": test.n, "model": final.spec.label(),
                       **_clean(tested.train.to_dict())}
        say(f"scored on {test.source} (not fitted on it)")
        test_row = (f"{final.spec.label()} (test: {test.source}, not fitted on it)", tested.train)
    if args.report:
        page = _report(args.report, ds, comparison, diagnosis, ladder, out, unit, test_row)
        out["report"] = str(page)
        say(f"report: {page}")
    if args.rerun:
        _rerun(args.rerun, ds, comparison, diagnosis, ladder, unit)
        out["rerun"] = args.rerun
    if args.json:
        print(json.dumps(out, allow_nan=False, default=_jsonable))
    else:
        _print_human(out, ladder, unit)
    return 0


def _same_target(fitted: tuple[str, str], unit, model: str, log: str) -> None:
    """Refuse to score a model of one target (``(quantity, unit)``) on a log of another."""
    if fitted != (unit.quantity, unit.si):
        raise IdentificationError(
            f"{model} predicts {fitted[0]} [{fitted[1]}], {log}'s target is {unit.quantity} [{unit.si}]: expected "
            "a log of the same target and unit (--map target=..., --unit U; --any-target to score it anyway)")


def _has_signals(model: FittedModel, ds, name: str) -> None:
    """Refuse a model that reads the torque on a log without one (its other signals are checked when evaluated)."""
    if "k_tau" in model.spec.linear and "tau" not in ds.signals:
        raise IdentificationError(f"{name} has k_tau: expected a torque column in {ds.source} (--map torque=COLUMN)")


def _jsonable(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return str(x)


def _comparison_dict(c) -> dict:
    coefs = {k: float(f"{v:.6g}") for k, v in c.model.coefficients.items()}
    return {"model": c.model.spec.label(), "coefficients": coefs, "train": _clean(c.train.to_dict()),
            "heldout": _clean(c.heldout.to_dict()) if c.heldout else None}


def _diagnosis_dict(d) -> dict:
    full = d.to_dict()
    keep = ("verdict", "message", "min_gain", "shortlist", "ranking", "runner_up", "probes", "confusion", "untestable",
            "experiments", "tail_share", "excitation")
    out = {k: full[k] for k in keep}
    out["diagnosed_model"] = full["model"]
    return _clean(out)


def _clean(x):
    """NaN and inf to None (strict JSON)."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, float) and x != x or x in (float("inf"), float("-inf")):
        return None
    return x


def _report(out_dir, ds, comparison, diagnosis, ladder, summary, unit, test_row=None):
    from servotau.identification.workbench.report import write_report

    return write_report(out_dir, ds, comparison=comparison, diagnosis=diagnosis, ladder=ladder, summary=summary,
                        unit=unit, test=test_row)


def _rerun(target: str, ds, comparison, diagnosis, ladder, unit) -> None:
    from .model_rerun import log_to_rerun
    from .viewer import open_recording

    rec = open_recording(target, app_id="servotau_model")
    log_to_rerun(rec, ds, comparison=comparison, diagnosis=diagnosis, ladder=ladder, unit=unit)


def _percent(x: float | None, scale: float) -> str:
    """``x * scale`` in percent, or "n/a" (the JSON's null: e.g. the fit of a target that never varies)."""
    return "n/a" if x is None else f"{scale * x:.1f} %"


def _print_human(out: dict, ladder, unit) -> None:
    print(f"model {out['model']}  (error: {unit.quantity} [{unit.symbol}])")
    for part in ("train", "heldout", "test"):
        m = out.get(part)
        if m:
            print(f"  {part:8s} fit {_percent(m['fit_percent'], 1)}  RMS {unit.show(m['rms'])}  "
                  f"over-estimation {_percent(m['overestimation_rate'], 100)}")
    if "verdict" in out:
        print(f"verdict: {out['verdict']}: {out['message']}")
        for i, c in enumerate(r for r in out["ranking"] if r["testable"]):
            if i >= 5:
                break
            print(f"  {i + 1}. {c['effect']:15s} held-out gain {100 * (c['heldout_gain'] or 0):5.1f} %")
    if ladder is not None:
        print("ladder:")
        for r in out["ladder"]:
            print(f"  {r['model']:60s} train {unit.show(r['train_rms']):>12s}  "
                  f"held-out {unit.show(r['heldout_rms']):>12s}")
