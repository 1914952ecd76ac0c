"""The model workbench on measured servo logs, held out by recording, against the models published with the data.

Real datasets (tests/data/, each folder's README gives the source, licence and columns):

- ``xl330_pendulum``: a Dynamixel XL330 position servo driving a pendulum (0.49 kg at 0.1 m), logged at about
  190 Hz (Rhoban/bam, Apache-2.0). Two groups of three recordings (firmware P gain 100 and 200; trajectories
  ``sin_sin``, ``up_and_down``, ``sin_time_square``). Published with it: the BAM friction models M1
  (Coulomb-viscous), M2 (Stribeck) and M6 (load-dependent, directional, quadratic), with a DC-motor and
  rigid-pendulum model around them, and their coefficients for this servo.
- ``sts3215_backlash``: Feetech STS3215 servos at 10 Hz (Robonine, CC BY 4.0), servos 1 and 2, three recordings
  each. Published with it: a backlash (dead band) measurement, no fitted friction model.

For every group and every recording held out in turn: the workbench (``servotau model add`` path: paper base,
greedy ladder, least squares, its own preprocessing) fitted on the other recordings and scored on the held-out
one, and the baselines fitted by this file's own code (scipy least squares, no workbench code) on the same
training recordings and scored on the same held-out samples, in the same unit (the servo error ``q_des - q``
[rad]): RMS and fit % (``100 (1 - |y - model| / |y - mean y|)``). Also: the workbench with the library's terms for
M1's inertia and Coulomb friction named (``--effect elastic --effect coulomb``); its ``diagnose`` verdict on
each recording alone and on each group (leave-one-recording-out), and, for the XL330, the published
coefficients as they are (fitted by the authors on their logs: not held out).

The baselines are written in inverse form: the servo error the model needs to produce the measured motion
(``q``, the log's velocity ``dq``, and ``ddq``, a Savitzky-Golay second derivative of ``q`` over
``DDQ_WINDOW`` samples), not a forward simulation (BAM scores its models by simulating the trajectory).

    python bench/workbench_real.py --json [--quick]

Prints ONE JSON object; progress on stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares, lsq_linear
from scipy.signal import savgol_filter

from servotau.identification.workbench import add_effects, compare, diagnose, folds_of, load_dataset, parse_spec
from servotau.identification.workbench.model import Term, design
from servotau.identification.workbench.recordings import combine

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
G = 9.80665  # [m/s^2]
DDQ_WINDOW = 11  # [samples] SG window of the baselines' acceleration (about 58 ms at 5.3 ms)

# xl330_pendulum (the recordings' header; README): pendulum and supply, and the firmware's P law
XL_MASS, XL_LENGTH, XL_VIN = 0.49, 0.1, 7.4  # [kg], [m], [V]
XL_ERROR_GAIN = (4096 / (2 * np.pi)) / (256 * 885)  # duty per (P gain x rad): counts/rad over (P divisor x PWM limit)
XL_TRAJECTORIES = ("sin_sin", "up_and_down", "sin_time_square")
XL_ROLES = {"command": "q_des_rad", "position": "q_rad", "torque": "tau_gravity_Nm", "velocity": "dq_rad_s",
            "time": "t_s"}
STS_FILES = ("nocomp2", "comp2", "pgain_zero_db")
STS_ROLES = {"command": "q_des_rad", "position": "q_rad", "torque": "load_frac", "velocity": "dq_rad_s",
             "time": "t_s"}


@dataclass(frozen=True)
class Recording:
    """One recording of one joint: its columns (as in the CSV) and the workbench's role mapping."""

    name: str
    columns: dict
    roles: dict

    @property
    def target(self) -> np.ndarray:
        """Servo error ``q_des - q`` [rad]."""
        return self.columns[self.roles["command"]] - self.columns[self.roles["position"]]


@dataclass(frozen=True)
class Group:
    """Recordings of the same joint under the same settings: held out one by one."""

    dataset: str
    name: str
    recordings: tuple[Recording, ...]
    kp: float | None = None  # XL330 firmware P gain


def read_csv(path: Path) -> dict:
    """Columns of a CSV with a header row, as float arrays."""
    a = np.genfromtxt(path, delimiter=",", names=True)
    return {k: np.asarray(a[k], dtype=np.float64) for k in a.dtype.names}


def xl330_groups(gains: tuple[int, ...] = (100, 200)) -> list[Group]:
    """The XL330 pendulum recordings, one group per firmware P gain."""
    out = []
    for kp in gains:
        recs = tuple(Recording(f"kp{kp}_{tr}", read_csv(DATA / "xl330_pendulum" / f"kp{kp}_{tr}.csv"), XL_ROLES)
                     for tr in XL_TRAJECTORIES)
        out.append(Group("xl330_pendulum", f"kp{kp}", recs, float(kp)))
    return out


def sts3215_groups(servos: tuple[int, ...] = (1, 2)) -> list[Group]:
    """The STS3215 recordings, one group per servo under test (rows of that servo only)."""
    tables = {f: read_csv(DATA / "sts3215_backlash" / f"{f}.csv") for f in STS_FILES}
    out = []
    for s in servos:
        recs = []
        for f, cols in tables.items():
            rows = cols["servo"] == s
            recs.append(Recording(f"{f}_s{s}", {k: v[rows] for k, v in cols.items()}, STS_ROLES))
        out.append(Group("sts3215_backlash", f"servo{s}", tuple(recs)))
    return out


def scores(y: np.ndarray, model: np.ndarray) -> dict:
    """RMS [rad] and fit % of ``model`` against ``y`` (the workbench's definition of fit %)."""
    r = y - model
    spread = float(np.linalg.norm(y - y.mean()))
    return {"rms": float(np.sqrt(np.mean(r * r))), "fit_percent": 100.0 * (1.0 - float(np.linalg.norm(r)) / spread)}


# ---- baselines: the XL330 models of the BAM paper, in inverse form ----------------------------------------------
#
# Pendulum + DC motor (the source's equations): J ddq = tau_m - m g l sin(q + q_offset) - friction, with
# tau_m = (kt / R) vin duty - (kt^2 / R) dq and the firmware's duty = error_gain kp (q_des - q). Solved for the
# servo error: q_des - q = K (J ddq + m g l sin(q + q_offset) + D dq + F(.) sign(dq)), K = R / (kt vin error_gain
# kp), D = kt^2 / R + viscous friction, F the model's friction level (the source's "frictionloss").


def pendulum_signals(rec: Recording) -> dict:
    """``q``, ``dq`` (the log's), ``ddq`` (SG of q), ``y`` (servo error) of an XL330 recording."""
    c = rec.columns
    dt = float(np.median(np.diff(c["t_s"])))
    return {"q": c["q_rad"], "dq": c["dq_rad_s"], "ddq": savgol_filter(c["q_rad"], DDQ_WINDOW, 3, deriv=2, delta=dt),
            "y": rec.target}


def _stack(recs: list[Recording]) -> dict:
    parts = [pendulum_signals(r) for r in recs]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


M1_COLUMNS = ("ddq", "sin_q", "cos_q", "dq", "sign_dq")


def m1_design(s: dict) -> np.ndarray:
    """Linear regressors of M1: K J ddq + K m g l (sin q + q_offset cos q) + K D dq + K F sign(dq)."""
    return np.column_stack([s["ddq"], np.sin(s["q"]), np.cos(s["q"]), s["dq"], np.sign(s["dq"])])


def fit_m1(recs: list[Recording]) -> dict:
    """M1 (Coulomb-viscous) by bounded linear least squares: every coefficient >= 0 but the offset's."""
    s = _stack(recs)
    lo = np.array([0.0, 0.0, -np.inf, 0.0, 0.0])
    a = lsq_linear(m1_design(s), s["y"], bounds=(lo, np.full(5, np.inf))).x
    return dict(zip(M1_COLUMNS, a, strict=True))


def predict_m1(p: dict, rec: Recording) -> np.ndarray:
    return m1_design(pendulum_signals(rec)) @ np.array([p[k] for k in M1_COLUMNS])


def physical_m1(p: dict, kp: float) -> dict:
    """M1's coefficients in physical units, from the known pendulum load ``m g l``."""
    k = p["sin_q"] / (XL_MASS * G * XL_LENGTH)  # [rad/(N m)]
    return {"K_rad_per_Nm": k, "R_over_kt": k * XL_VIN * XL_ERROR_GAIN * kp, "inertia_kg_m2": p["ddq"] / k,
            "q_offset_rad": p["cos_q"] / p["sin_q"], "damping_Nm_s_per_rad": p["dq"] / k,
            "coulomb_Nm": p["sign_dq"] / k}


def _stribeck(dq: np.ndarray, v_s: float, alpha: float) -> np.ndarray:
    return np.exp(-np.abs(dq / v_s) ** alpha)


# M2 and M6 in physical parameters, fitted by nonlinear least squares (bounds as the source's): K, J, q_offset,
# D, then the friction levels [N m], Stribeck velocity [rad/s] and exponent, load-friction ratios.
M2_NAMES = ("K", "J", "q_offset", "D", "f_base", "f_stribeck", "v_stribeck", "alpha")
M6_NAMES = (*M2_NAMES, "mu_motor", "mu_external", "mu_motor_s", "mu_external_s", "quad_motor", "quad_external")


def friction_level(p: dict, s: dict) -> np.ndarray:
    """The friction level F >= 0 [N m] of M2 or M6 (M6's load terms read the pendulum's and the motor's torque)."""
    st = _stribeck(s["dq"], p["v_stribeck"], p["alpha"])
    f = p["f_base"] + p["f_stribeck"] * st
    if "mu_motor" not in p:
        return f
    tau_ext = -XL_MASS * G * XL_LENGTH * np.sin(s["q"] + p["q_offset"])  # gravity on the link [N m]
    tau_m = p["J"] * s["ddq"] - tau_ext + p["D"] * s["dq"]  # motor torque without the friction level (approximation)
    f = f + np.abs(p["mu_external"] * tau_ext - p["mu_motor"] * tau_m)
    f = f + st * np.abs(p["mu_external_s"] * tau_ext - p["mu_motor_s"] * tau_m)
    opposed = np.sign(tau_ext) != np.sign(tau_m)
    quad = np.where(np.abs(tau_ext) < np.abs(tau_m), p["quad_external"] * tau_ext ** 2, p["quad_motor"] * tau_m ** 2)
    return f + st * quad * opposed


def predict_physical(p: dict, rec: Recording | dict) -> np.ndarray:
    s = pendulum_signals(rec) if isinstance(rec, Recording) else rec
    load = XL_MASS * G * XL_LENGTH * np.sin(s["q"] + p["q_offset"])
    return p["K"] * (p["J"] * s["ddq"] + load + p["D"] * s["dq"] + friction_level(p, s) * np.sign(s["dq"]))


def _start_from_m1(m1: dict) -> dict:
    k = m1["sin_q"] / (XL_MASS * G * XL_LENGTH)
    return {"K": k, "J": max(m1["ddq"] / k, 1e-4), "q_offset": m1["cos_q"] / m1["sin_q"], "D": max(m1["dq"] / k, 1e-3),
            "f_base": max(m1["sign_dq"] / k, 1e-3)}


def fit_physical(recs: list[Recording], names: tuple[str, ...], start: dict) -> dict:
    """Nonlinear least squares of M2 or M6 on ``recs`` (bounds: the source's parameter ranges)."""
    s = _stack(recs)
    bounds = {"K": (1e-4, 100.0), "J": (0.0, 0.1), "q_offset": (-0.1, 0.1), "D": (0.0, 10.0), "f_base": (0.0, 0.2),
              "f_stribeck": (0.0, 0.2), "v_stribeck": (0.01, 3.0), "alpha": (0.5, 3.0), "mu_motor": (0.0, 0.5),
              "mu_external": (0.0, 0.5), "mu_motor_s": (0.0, 1.0), "mu_external_s": (0.0, 1.0),
              "quad_motor": (0.0, 0.01), "quad_external": (0.0, 0.01)}
    x0 = np.array([np.clip(start.get(n, 0.05 if n.startswith("f_") else 0.2 if n == "v_stribeck" else
                                     1.35 if n == "alpha" else 0.0), *bounds[n]) for n in names])
    lo, hi = np.array([bounds[n][0] for n in names]), np.array([bounds[n][1] for n in names])

    def residual(x: np.ndarray) -> np.ndarray:
        return predict_physical(dict(zip(names, x, strict=True)), s) - s["y"]

    x = least_squares(residual, np.clip(x0, lo, hi), bounds=(lo, hi), x_scale="jac", max_nfev=400).x
    return dict(zip(names, x, strict=True))


def published(model: dict, kp: float) -> dict:
    """A BAM parameter file (xl330/m*.json) in this file's parameters, with the log's nominal supply and P gain."""
    k = model["R"] / (model["kt"] * XL_VIN * XL_ERROR_GAIN * kp)
    p = {"K": k, "J": XL_MASS * XL_LENGTH ** 2 + model["armature"], "q_offset": model["q_offset"],
         "D": model["kt"] ** 2 / model["R"] + model["friction_viscous"], "f_base": model["friction_base"],
         "f_stribeck": model.get("friction_stribeck", 0.0), "v_stribeck": model.get("dtheta_stribeck", 1.0),
         "alpha": model.get("alpha", 1.0)}
    if "load_friction_motor" in model:
        p.update(mu_motor=model["load_friction_motor"], mu_external=model["load_friction_external"],
                 mu_motor_s=model["load_friction_motor_stribeck"],
                 mu_external_s=model["load_friction_external_stribeck"],
                 quad_motor=model["load_friction_motor_quad"], quad_external=model["load_friction_external_quad"])
    return p


# ---- baseline: the STS3215's published effect, a dead band (backlash) ----------------------------------------------

DEADBAND_COLUMNS = ("load", "dq", "sign_load", "one")


def deadband_design(rec: Recording) -> np.ndarray:
    """Servo error = k load + k_v dq + h sign(load) + c: a stiffness, damping and a play of 2 h taken up by the load."""
    c = rec.columns
    return np.column_stack([c["load_frac"], c["dq_rad_s"], np.sign(c["load_frac"]), np.ones(len(c["load_frac"]))])


def fit_deadband(recs: list[Recording]) -> dict:
    a = np.vstack([deadband_design(r) for r in recs])
    y = np.concatenate([r.target for r in recs])
    x = lsq_linear(a, y, bounds=(np.array([-np.inf, -np.inf, 0.0, -np.inf]), np.full(4, np.inf))).x
    return dict(zip(DEADBAND_COLUMNS, x, strict=True))


def predict_deadband(p: dict, rec: Recording) -> np.ndarray:
    return deadband_design(rec) @ np.array([p[k] for k in DEADBAND_COLUMNS])


# ---- the workbench -----------------------------------------------------------------------------------------------


def load(recs: list[Recording]) -> dict:
    """The workbench's dataset of each recording (read with its role mapping), by name."""
    return {r.name: load_dataset(r.columns, roles=r.roles) for r in recs}


def dataset(recs: list[Recording], loaded: dict | None = None):
    """The workbench's dataset of ``recs`` (one segment each), joined from ``loaded`` (:func:`load`; read here when
    None)."""
    loaded = load(recs) if loaded is None else loaded
    return combine([loaded[r.name] for r in recs])


def verdict_of(d) -> dict:
    tested = [c for c in d.ranking if c.testable][:3]
    return {"verdict": d.verdict, "base_heldout_rms": d.base.heldout.rms,
            "top": [{"effect": c.effect, "heldout_gain": round(c.heldout_gain, 3)} for c in tested],
            "untestable": [c.effect for c in d.ranking if not c.testable],
            "probes": {k: round(v, 3) for k, v in d.probes.items()}, "message": d.message}


def diagnose_recordings(recs: list[Recording], loaded: dict) -> dict:
    """``diagnose`` (paper base) on ``recs`` joined, held out by recording (blocked folds for one recording)."""
    ds = dataset(recs, loaded)
    folds = folds_of(ds, len(recs)) if len(recs) > 1 else folds_of(ds)
    return verdict_of(diagnose(ds, parse_spec("paper", ds.signals, offset=not ds.actuator), folds=folds))


M1_TERMS = ("elastic", "coulomb")  # the library's terms for M1's inertia torque and Coulomb friction


def workbench_heldout(train: list[Recording], test: Recording, max_steps: int, loaded: dict) -> dict:
    """The greedy ladder fitted on ``train``, its base and final models scored on ``test``."""
    ds = dataset(train, loaded)
    spec = parse_spec("paper", ds.signals, offset=not ds.actuator)
    ladder = add_effects(ds, spec, max_steps=max_steps, folds=folds_of(ds, max(len(train), 2)))
    ts = loaded[test.name]
    base = ladder.rungs[0].comparison.model
    final = ladder.final
    named = add_effects(ds, spec, effects=M1_TERMS, folds=folds_of(ds, max(len(train), 2)), diagnose_final=False)
    return {"model": final.spec.label(), "added": [r.added for r in ladder.rungs[1:]],
            "rejected": [r.added for r in ladder.rejected], "verdict_on_training": ladder.verdict,
            "base": scores(ts.target, compare(ts, base).prediction),
            "final": scores(ts.target, compare(ts, final).prediction),
            "coefficients": {k: float(v) for k, v in final.coefficients.items()},
            "m1_terms": {"model": named.final.spec.label(), **scores(ts.target, compare(ts, named.final).prediction)}}


JOIN_GUARD = 8  # [samples] each side of a join between two training recordings left out by join_check


def join_check(train: list[Recording], test: Recording, loaded: dict) -> dict:
    """The workbench's own columns for M1 (k_tau, k_v, elastic at the baselines' window, plain-sign coulomb), solved
    by plain least squares on the joined training recordings with and without the samples next to each join, and
    scored on ``test``: the effects filter ``q`` across the join of two recordings (their acceleration spikes there)."""
    ds = dataset(train, loaded)
    ts = loaded[test.name]
    window = DDQ_WINDOW * float(np.median(np.diff(test.columns["t_s"])))
    spec = parse_spec("paper", ds.signals).plus(Term("elastic", {"window": window, "lag": 0.0})).plus(
        Term("coulomb", {"v_eps": 0.0}))
    names, a, _ = design(ds.signals, spec, None)
    a_test = design(ts.signals, spec, None)[1]
    keep = np.ones(ds.n, dtype=bool)
    for end in np.cumsum([len(r.target) for r in train])[:-1]:
        keep[end - JOIN_GUARD:end + JOIN_GUARD] = False
    out = {}
    for label, rows in (("all_rows", np.ones(ds.n, dtype=bool)), ("without_joins", keep)):
        x = np.linalg.lstsq(a[rows], ds.target[rows], rcond=None)[0]
        out[label] = scores(ts.target, a_test @ x) | {"coefficients": dict(zip(names, x.tolist(), strict=True))}
    return out


def run_group(g: Group, max_steps: int, published_models: dict, say) -> dict:
    rows = []
    recs = list(g.recordings)
    loaded = load(recs)  # each recording read once, for every fit, score and diagnosis below
    for i, held in enumerate(recs):
        train = recs[:i] + recs[i + 1:]
        say(f"{g.dataset}/{g.name}: held out {held.name}")
        row = {"heldout": held.name, "train": [r.name for r in train], "n": len(held.target),
               "target_rms": float(np.sqrt(np.mean(held.target ** 2))),
               "workbench": workbench_heldout(train, held, max_steps, loaded)}
        base = {}
        if g.dataset == "xl330_pendulum":
            m1 = fit_m1(train)
            base["M1 coulomb-viscous"] = scores(held.target, predict_m1(m1, held)) | {"physical": physical_m1(m1, g.kp)}
            start = _start_from_m1(m1)
            m2 = fit_physical(train, M2_NAMES, start)
            base["M2 stribeck"] = scores(held.target, predict_physical(m2, held)) | {"physical": m2}
            m6 = fit_physical(train, M6_NAMES, m2)
            base["M6 load-dependent"] = scores(held.target, predict_physical(m6, held)) | {"physical": m6}
            for name, model in published_models.items():
                base[f"{name} published (not refitted)"] = scores(held.target,
                                                                  predict_physical(published(model, g.kp), held))
        else:
            p = fit_deadband(train)
            base["dead band (backlash)"] = scores(held.target, predict_deadband(p, held)) | {
                "play_rad": 2 * p["sign_load"], "k_rad_per_load": p["load"]}
        row["baselines"] = base
        row["join_check"] = join_check(train, held, loaded)
        row["diagnose"] = diagnose_recordings([held], loaded)
        rows.append(row)
    say(f"{g.dataset}/{g.name}: diagnose on all recordings (leave-one-recording-out)")
    return {"dataset": g.dataset, "group": g.name, "kp": g.kp, "recordings": [r.name for r in recs],
            "rows": rows, "diagnose_all": diagnose_recordings(recs, loaded)}


def published_xl330() -> dict:
    folder = DATA / "xl330_pendulum" / "published"
    return {p.stem.upper(): json.loads(p.read_text()) for p in sorted(folder.glob("m*.json"))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print JSON (the only output format)")
    parser.add_argument("--quick", action="store_true", help="one group per dataset, at most one effect added")
    args = parser.parse_args()
    start = time.perf_counter()
    say = lambda msg: print(f"[{time.perf_counter() - start:6.1f} s] {msg}", file=sys.stderr, flush=True)  # noqa: E731
    groups = xl330_groups((100,) if args.quick else (100, 200)) + sts3215_groups((1,) if args.quick else (1, 2))
    pub = published_xl330()
    results = [run_group(g, 1 if args.quick else 4, pub, say) for g in groups]
    print(json.dumps({"unit": "rad (servo error q_des - q)", "ddq_window_samples": DDQ_WINDOW, "groups": results,
                      "seconds": round(time.perf_counter() - start, 1)}))


if __name__ == "__main__":
    main()
