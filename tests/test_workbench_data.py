"""Tests of log loading (identification/workbench/data.py): layouts, column roles, bad input."""

import numpy as np
import pytest
from support.synthetic import synthetic_table

from servotau.errors import IdentificationError
from servotau.identification.data import shift as shift_signal
from servotau.identification.data import write_table
from servotau.identification.workbench import diagnose, load_dataset, parse_spec
from servotau.identification.workbench.data import align_torque


def test_single_joint_table_from_parquet_and_csv_without_velocity(tmp_path):
    """t, q, q_des, tau work as they are; dq is the centred SG derivative of q; both formats agree."""
    cols = synthetic_table(seconds=3.0)
    true_dq = cols.pop("dq")
    for suffix in (".parquet", ".csv"):
        ds = load_dataset(write_table(cols, tmp_path / f"log{suffix}"))
        assert ds.roles["position"] == "q" and ds.roles["torque"] == "tau" and "velocity" not in ds.roles
        np.testing.assert_allclose(ds.target, cols["q_des"] - cols["q"], atol=1e-12)
        inner = slice(100, -100)
        err = ds.signals["dq"][inner] - true_dq[inner]
        assert np.sqrt(np.mean(err**2)) < 0.01 * np.sqrt(np.mean(true_dq**2))  # q is a cumulative sum of dq
        assert ds.dt == pytest.approx(1e-3) and any("Savitzky-Golay derivative" in n for n in ds.notes)


def test_servotau_log_layout_needs_a_joint_and_prefers_the_estimate():
    """q/<joint>, q_des/<joint>, est/tau/<joint> (over true/tau), est/dq/<joint>; --joint picks one."""
    c = synthetic_table(seconds=2.0)
    log = {"t": c["t"]}
    for j, k in (("RLEG_JOINT3", 1.0), ("RLEG_JOINT2", 2.0)):
        log |= {f"q/{j}": k * c["q"], f"q_des/{j}": k * c["q_des"], f"est/tau/{j}": c["tau"],
                f"true/tau/{j}": 2 * c["tau"], f"est/dq/{j}": k * c["dq"]}
    with pytest.raises(IdentificationError, match=r"joints \['RLEG_JOINT3', 'RLEG_JOINT2'\]: expected --joint"):
        load_dataset(log)
    with pytest.raises(IdentificationError, match="joint 'LLEG_JOINT3': not in the log"):
        load_dataset(log, joint="LLEG_JOINT3")
    ds = load_dataset(log, joint="RLEG_JOINT2")
    assert ds.roles["torque"] == "est/tau/RLEG_JOINT2" and ds.roles["velocity"] == "est/dq/RLEG_JOINT2"
    np.testing.assert_allclose(ds.target, 2 * (c["q_des"] - c["q"]))
    truth = load_dataset(log, joint="RLEG_JOINT3", roles={"torque": "true/tau/RLEG_JOINT3"})
    np.testing.assert_allclose(truth.signals["tau"][50:-50], 2 * c["tau"][50:-50], rtol=1e-3, atol=1e-3)


def test_role_mapping_brings_another_robots_friction_table():
    """A friction torque against velocity (other names, no torque, no command) is diagnosed as it is."""
    rng = np.random.default_rng(1)
    v = np.concatenate([np.linspace(-1, 1, 2000), np.linspace(1, -1, 2000)])
    friction = 0.8 * v + 2.0 * np.tanh(v / 0.01) + 0.01 * rng.standard_normal(len(v))  # [N m]
    ds = load_dataset({"speed": v, "friction": friction, "block": np.repeat(np.arange(4), 1000)},
                      roles={"target": "friction", "velocity": "speed", "segment": "block"})
    assert not ds.has_torque and not ds.actuator
    d = diagnose(ds, parse_spec("paper", ds.signals), effects=["coulomb", "stribeck", "cogging"])
    assert d.top.effect == "coulomb" and d.top.heldout_gain > 0.9
    assert not d.candidate("cogging").testable  # no position column: untestable, not absent


def test_nan_rows_are_dropped_and_counted():
    """Rows with NaN in a used column are dropped; the count is reported; unused columns do not matter."""
    cols = synthetic_table(seconds=2.0)
    cols["tau"][[10, 500, 900]] = np.nan
    cols["q"][1500] = np.inf
    cols["notes"] = np.full(len(cols["t"]), np.nan)
    ds = load_dataset(cols)
    assert ds.n_dropped == 4 and ds.n == len(cols["t"]) - 4
    assert any("dropped 4 of 2000 rows" in n and "'q'" in n and "'tau'" in n for n in ds.notes)


def test_bad_input_names_the_column_and_the_expected_value(tmp_path):
    """Missing column, unknown role or column, too few samples, non-increasing time: clear errors."""
    cols = synthetic_table(seconds=2.0)
    with pytest.raises(IdentificationError, match=r"missing column\(s\) \['q_des'\].*t, q, q_des, tau"):
        load_dataset({k: v for k, v in cols.items() if k != "q_des"})
    with pytest.raises(IdentificationError, match="column role 'torq': expected one of"):
        load_dataset(cols, roles={"torq": "tau"})
    with pytest.raises(IdentificationError, match="column 'force' \\(role torque\\): not in the table"):
        load_dataset(cols, roles={"torque": "force"})
    with pytest.raises(IdentificationError, match="50 valid samples.*expected at least 200"):
        load_dataset({k: v[:50] for k, v in cols.items()})
    bad = dict(cols)
    bad["t"] = cols["t"].copy()
    bad["t"][100] = bad["t"][99]
    with pytest.raises(IdentificationError, match="column 't' \\(role time\\): not increasing at row 100.*several"):
        load_dataset(bad)  # the same time twice: two servos logged in one file, say
    bad["t"][100] = bad["t"][99] - 1e-3
    with pytest.raises(IdentificationError, match="not increasing at row 100") as backwards:
        load_dataset(bad)
    assert "several joints" not in str(backwards.value)
    allnan = dict(cols, tau=np.full(len(cols["t"]), np.nan))
    with pytest.raises(IdentificationError, match="column 'tau' \\(role torque\\): all 2000 values are NaN"):
        load_dataset(allnan)
    for window in (-0.01, float("nan")):  # a negative window ran as 5 samples; NaN raised a ValueError
        with pytest.raises(IdentificationError, match="smooth_torque_s = .*: expected a window >= 0 s"):
            load_dataset(cols, smooth_torque_s=window)
    huge = dict(cols, tau=cols["tau"] * 1e200)  # a trial's file: "condition number inf" before this check
    with pytest.raises(IdentificationError, match="column 'tau' \\(role torque\\): values up to .*e\\+2.*: expected"):
        load_dataset(huge)
    with pytest.raises(IdentificationError, match="not found"):
        load_dataset(tmp_path / "missing.parquet")
    (tmp_path / "log.json").write_text("{}")
    with pytest.raises(IdentificationError, match="unknown format '.json'"):
        load_dataset(tmp_path / "log.json")


def test_torque_alignment_finds_an_estimator_delay():
    """A torque column late by 8 ms is re-timed from the holds (where the command is still)."""
    cols = synthetic_table(seconds=8.0)
    still = np.abs(np.gradient(cols["q_des"])) < 1e-12
    assert still.mean() < 0.1  # the synthetic command never holds: nothing is shifted
    ds, shift = align_torque(load_dataset(cols))
    assert shift == 0.0
    # the command holds still while a push moves the torque: the joint deflects, dq_err = k_tau tau
    t = cols["t"]
    tau = 30 * np.sin(2 * np.pi * 0.5 * t) + 10 * np.sin(2 * np.pi * 1.7 * t)
    q = 0.3 - 5e-5 * tau
    static = {"t": t, "q": q, "q_des": np.full(len(t), 0.3), "tau": shift_signal(tau, -8, fill="hold")}
    ds2, shift2 = align_torque(load_dataset(static, smooth_torque_s=0.0))
    assert shift2 == pytest.approx(0.008)
    assert any("advanced by 8 ms" in n for n in ds2.notes)
    smoothed, _ = align_torque(load_dataset(static, smooth_torque_s=0.021))  # the raw torque is re-timed too
    raw = smoothed.signals["tau_raw"]
    assert np.max(np.abs(raw[20:-20] - tau[20:-20])) < 1e-9  # the torque check re-smooths it (checks.smoothing_check)


def test_servotau_log_with_only_the_ground_truth_torque_is_an_error_not_a_silent_fallback():
    """The simulator's true/tau is taken only when mapped explicitly: a real robot has none."""
    c = synthetic_table(seconds=2.0)
    log = {"t": c["t"], "q/J": c["q"], "q_des/J": c["q_des"], "true/tau/J": c["tau"]}
    with pytest.raises(IdentificationError, match="no torque column: expected 'est/tau/J'"):
        load_dataset(log)
    assert load_dataset(log, roles={"torque": "true/tau/J"}).roles["torque"] == "true/tau/J"


@pytest.fixture(scope="module")
def collected_log(tmp_path_factory):
    """A 7 s simulated identification collection of the knee (sensors and ground truth, no estimate)."""
    from servotau.apps.identify import hal_for_collection
    from servotau.apps.operator_script import write_sim_setup
    from servotau.hal.registry import open_backend
    from servotau.identification.collect import HoldPlan, SweepPlan
    from servotau.identification.plan import CollectionPlan, load_plan
    from servotau.identification.session import run_collection

    folder = tmp_path_factory.mktemp("wb_ident")
    base, _ = load_plan()
    plan = CollectionPlan(sweeps=(SweepPlan("RLEG_JOINT3", a=0.1, duration=3.0),),
                          holds=HoldPlan(base.holds.configurations[:1], move=1.0, hold=1.0), settle=1.0,
                          holds_start=5.0)
    section, name = hal_for_collection("hal.toml", "inprocess", str(write_sim_setup(plan, folder)))
    log = folder / "log.parquet"
    with open_backend(section, backend=name) as backend:
        run_collection(backend, plan, log, source=name, progress=lambda _m: None)
    return log


def test_collected_log_gets_the_off_line_estimate_and_never_reads_the_ground_truth(collected_log, tmp_path):
    """A servotau Parquet log without est/tau: the estimated torque, unchanged when the true/ columns are scrambled."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from servotau.identification.data import read_table

    assert not any(c.startswith("est/") for c in read_table(collected_log))
    ds = load_dataset(collected_log, joint="RLEG_JOINT3")
    assert ds.roles["torque"] == "est/tau/RLEG_JOINT3" and ds.roles["velocity"] == "est/dq/RLEG_JOINT3"
    assert any("not the simulator's ground truth" in n for n in ds.notes)
    table = pq.read_table(collected_log)
    for i, name in enumerate(table.column_names):
        if name.startswith("true/"):
            table = table.set_column(i, name, pa.array(table.column(name).to_numpy() * -3.0 + 1.0))
    scrambled = tmp_path / "scrambled.parquet"
    pq.write_table(table, scrambled)
    again = load_dataset(scrambled, joint="RLEG_JOINT3")
    np.testing.assert_array_equal(again.signals["tau"], ds.signals["tau"])
    np.testing.assert_array_equal(again.target, ds.target)
    true_tau = ds.signals["true/tau/RLEG_JOINT3"]  # evaluation only: the estimate is close to the truth
    assert np.sqrt(np.mean((ds.signals["tau"] - true_tau) ** 2)) < 0.2 * np.sqrt(np.mean(true_tau**2))


def test_a_model_saved_from_an_estimated_log_says_so_in_its_provenance(collected_log, tmp_path, capsys):
    """`model add --save` on a log without est/tau: the motor file's provenance names the estimated column."""
    import json

    from servotau.cli import main
    from servotau.identification import MotorParameters

    path = tmp_path / "motors.toml"
    code = main(["model", "add", str(collected_log), "--joint", "RLEG_JOINT3", "--effect", "coulomb", "--json",
                 "--quiet", "--save", str(path)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert json.loads(out)["saved"]["joint"] == "RLEG_JOINT3"
    provenance = MotorParameters.load_toml(path)["RLEG_JOINT3"].provenance
    assert provenance.endswith("; tau: est/tau/RLEG_JOINT3 (off-line estimates from the log's sensors)"), provenance
