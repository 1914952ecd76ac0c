"""Tests of identification/pipeline.py, plan.py, session.py and operator_script.py on a short simulated
collection (in process): log -> non-causal estimates -> aligned samples -> fits, and their bad inputs."""

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from servotau.apps.identify import hal_for_collection
from servotau.apps.operator_script import check_timing, write_sim_setup
from servotau.config import CONFIG_DIR
from servotau.errors import ConfigError, IdentificationError
from servotau.hal.log import LogReader
from servotau.hal.registry import open_backend
from servotau.identification.collect import HoldPlan, SweepPlan
from servotau.identification.data import load_aligned
from servotau.identification.pipeline import fit_log
from servotau.identification.plan import PHASES, CollectionPlan, FitSettings, load_plan
from servotau.identification.session import run_collection
from servotau.simrobot.scenario import Scenario

JOINTS = ["RLEG_JOINT2", "RLEG_JOINT3"]  # hip pitch, knee


def short_plan() -> CollectionPlan:
    base, _ = load_plan()
    return CollectionPlan(sweeps=tuple(SweepPlan(j, a=0.1, duration=5.0) for j in JOINTS),
                          holds=HoldPlan(base.holds.configurations[:2], move=1.0, hold=4.0), settle=1.0,
                          holds_start=13.5)  # the sweeps end at 13 s: 0.5 s of wait


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A 23.5 s collection of 2 sweeps, a wait and 2 holds with matching operator pushes, and its default fit."""
    folder = tmp_path_factory.mktemp("ident")
    plan = short_plan()
    section, name = hal_for_collection("hal.toml", "inprocess", str(write_sim_setup(plan, folder)))
    log = folder / "log.parquet"
    with open_backend(section, backend=name) as backend:
        p = backend.robot.servo.p  # evaluation only: the servo's linear part
        idx = [backend.info.joint_index(j) for j in JOINTS]
        nominal = {j: (p.k_tau_nominal()[i], p.k_v_nominal()[i]) for j, i in zip(JOINTS, idx, strict=True)}
        result = run_collection(backend, plan, log, source=name, progress=lambda _m: None)
    return {"plan": plan, "log": log, "result": result, "nominal": nominal, "folder": folder,
            "report": fit_log(log, settings=FitSettings())}


def _copy(src, dst, edit):
    table = pq.read_table(src)
    pq.write_table(edit(table), dst)
    return dst


def test_collection_records_the_plan_phases_commands_and_pushes(run):
    """The log holds every tick, finite commands, the plan's phases, and the operator pushes only while holding."""
    plan, log = run["plan"], LogReader(run["log"])
    assert run["result"].completed and run["result"].truth
    assert len(log) == round(plan.duration / log.info.period)
    assert np.isfinite(log.joints("q_des")).all()
    phase = log.columns["ident/phase"]
    assert set(np.unique(phase).astype(int)) == {PHASES.index(p) for p in PHASES}
    assert np.count_nonzero(phase == PHASES.index("wait")) == 500
    t = log.columns["t"]
    for a, b in plan.hold_windows():
        inside = (t >= a) & (t < b - 1e-9)
        assert (phase[inside] == PHASES.index("hold")).all()
    pushed = np.abs(log.matrix([f"true/external_wrench/{a}" for a in ("fx", "fy", "fz", "tx", "ty", "tz")])).sum(1) > 0
    assert pushed.any() and (phase[pushed] == PHASES.index("hold")).all()
    swept = log.columns["ident/joint"][phase == PHASES.index("sweep")]
    assert set(swept.astype(int)) == {log.info.joint_index(j) for j in JOINTS}
    assert json.loads(log.metadata["servotau.identification.joints"]) == JOINTS


def test_fit_recovers_k_tau_and_k_v_of_the_simulated_servo(run):
    """LS matches the LS fit on the true tau, dq within 10 %; every fit is within a factor 1.3 of 1/kp, (kd+b)/kp."""
    for j in JOINTS:
        r = run["report"].joints[j]
        ref = r.reference["least_squares"]
        ls = r.variants["least_squares"].coefficients
        for k in ("k_tau", "k_v"):
            assert ls[k] == pytest.approx(ref[k], rel=0.10), (j, k)
        k_tau, k_v = run["nominal"][j]
        for name in ("least_squares", "asymmetric", "two_stage"):
            c = r.variants[name].coefficients
            assert 1 / 1.3 < c["k_tau"] / k_tau < 1.3, (j, name, c, k_tau)
            assert 1 / 1.3 < c["k_v"] / k_v < 1.3, (j, name, c, k_v)


def test_asymmetric_fit_over_estimates_less_often_than_least_squares_on_held_out_samples(run):
    """On held-out blocks, the asymmetric fit (w = 100) over-estimates |dq_err| rarely and far less than LS."""
    for j in JOINTS:
        v = run["report"].joints[j].variants
        assert v["asymmetric"].n_heldout > 500
        assert v["asymmetric"].heldout_overestimation < 0.1
        assert v["asymmetric"].heldout_overestimation < 0.5 * v["least_squares"].heldout_overestimation


def test_fit_never_reads_the_ground_truth(run, tmp_path):
    """Scrambling the log's true/ columns changes the evaluation reference but not one identified value."""
    def scramble(table):
        for i, name in enumerate(table.column_names):
            if name.startswith("true/"):
                table = table.set_column(i, name, pa.array(table.column(name).to_numpy() * -3.0 + 1.0))
        return table

    report = fit_log(_copy(run["log"], tmp_path / "scrambled.parquet", scramble), settings=FitSettings())
    for j in JOINTS:
        a, b = run["report"].joints[j], report.joints[j]
        for name in a.variants:
            assert a.variants[name].coefficients == b.variants[name].coefficients
        assert a.reference != b.reference


def test_split_is_disjoint_blocks_and_downsampled(run):
    """Training and held-out samples never share a block, and each set keeps every n-th valid sample."""
    settings = FitSettings(downsample=5)
    s = load_aligned(run["log"], ["RLEG_JOINT3"], settings).samples["RLEG_JOINT3"]
    block = np.floor((s.t - s.t[0]) / settings.holdout_block).astype(int)
    assert not set(block[s.train]) & set(block[s.held_out])
    assert set(block[s.held_out]) <= {b for b in set(block) if b % 3 == 2}
    assert np.all(np.diff(np.flatnonzero(s.train)) >= 5)
    assert np.isfinite(s.tau[s.train]).all() and np.isfinite(s.dq_err[s.held_out]).all()


def test_bad_logs_are_clear_errors(run, tmp_path):
    """Missing file, no q_des column, NaN-only q_des, unknown joint and too short logs name the problem."""
    with pytest.raises(IdentificationError, match=r"nothere\.parquet: no such log file"):
        load_aligned(tmp_path / "nothere.parquet")
    no_qdes = _copy(run["log"], tmp_path / "no_qdes.parquet",
                    lambda t: t.drop_columns([c for c in t.column_names if c.startswith("q_des/")]))
    with pytest.raises(IdentificationError, match=r"no column 'q_des/RLEG_JOINT0': expected the commanded angles"):
        load_aligned(no_qdes)

    def nan_knee(t):
        i = t.column_names.index("q_des/RLEG_JOINT3")
        return t.set_column(i, "q_des/RLEG_JOINT3", pa.array(np.full(t.num_rows, np.nan)))

    with pytest.raises(IdentificationError, match=r"'q_des/RLEG_JOINT3' is NaN in every row"):
        load_aligned(_copy(run["log"], tmp_path / "nan.parquet", nan_knee))
    with pytest.raises(IdentificationError, match=r'joint "RLEG_JOINT9" is unknown: expected one of'):
        load_aligned(run["log"], ["RLEG_JOINT9"])
    short = _copy(run["log"], tmp_path / "short.parquet", lambda t: t.slice(0, 600))
    with pytest.raises(IdentificationError, match=r"600 rows \(0\.600 s\): expected at least 1081 rows"):
        load_aligned(short)
    not_parquet = tmp_path / "text.parquet"
    not_parquet.write_text("hello")
    with pytest.raises(IdentificationError, match="text.parquet"):
        load_aligned(not_parquet)


def test_shipped_scenario_pushes_fall_in_the_shipped_plan_hold_windows():
    """config/scenarios/identification.toml agrees with config/identification.toml; a shifted plan does not."""
    plan, settings = load_plan()
    pushes = Scenario.from_toml(CONFIG_DIR / "scenarios" / "identification.toml").operator
    assert check_timing(plan, pushes) == []
    assert len(plan.joints) == 6 and settings.loss.w == 100.0
    from dataclasses import replace

    shifted = replace(plan, holds_start=plan.holds_start + 3.0)
    assert any("outside every hold window" in p for p in check_timing(shifted, pushes))
    # Fewer sweeps keep the timing: the holds still start at holds_start.
    assert plan.with_joints(["RLEG_JOINT3"]).hold_windows() == plan.hold_windows()


def test_plan_errors_name_the_field(tmp_path):
    """A plan whose sweeps overrun holds_start, an unknown field, or w <= 1 is refused with the field named."""
    base, _ = load_plan()
    with pytest.raises(IdentificationError, match=r"end at 81 s, after holds_start = 80 s"):
        CollectionPlan(sweeps=base.sweeps, holds=base.holds, settle=3.0, holds_start=80.0)
    bad = tmp_path / "plan.toml"
    bad.write_text('[collect]\njoints = ["RLEG_JOINT3"]\n[fit]\nloss = "asymmetric"\nw = 1.0\n')
    with pytest.raises(ConfigError, match=r"field 'fit.w' = 1.0: expected a finite number > 1"):
        load_plan(bad)
    bad.write_text('[collect]\njoints = ["RLEG_JOINT3"]\n[collect.sweep]\nfreq = 1.0\n')
    with pytest.raises(ConfigError, match=r"field 'collect.sweep.freq'"):
        load_plan(bad)


def test_plan_defaults_are_the_dataclasses_defaults(tmp_path):
    """A plan naming only its joints loads to the dataclasses' own defaults (declared once, by setting())."""
    minimal = tmp_path / "plan.toml"
    minimal.write_text('[collect]\njoints = ["RLEG_JOINT3"]\n')
    plan, settings = load_plan(minimal)
    assert plan == CollectionPlan(sweeps=(SweepPlan("RLEG_JOINT3"),), source=str(minimal))
    assert settings == FitSettings() and settings.loss.kind == "asymmetric" and settings.loss.w == 100.0
    with pytest.raises(IdentificationError, match=r"FitSettings.downsample = 0: expected an integer >= 1"):
        FitSettings(downsample=0)
    settle = r"<code>: CollectionPlan.settle = -1.0: expected a finite number >= 0 \[s\]"
    with pytest.raises(IdentificationError, match=settle):
        CollectionPlan(sweeps=(), settle=-1.0)
