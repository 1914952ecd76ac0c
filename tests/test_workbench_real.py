"""The workbench on measured servo logs (tests/data/xl330_pendulum, tests/data/sts3215_backlash), and the baselines
of bench/workbench_real.py: the logs load with their documented mapping, the workbench and the held-out evaluation
run, and the physics the logs must obey holds independently of the workbench."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from servotau.identification.workbench import add_effects, compare, load_dataset, parse_spec

ROOT = Path(__file__).resolve().parent.parent
XL = ROOT / "tests" / "data" / "xl330_pendulum"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("workbench_real", ROOT / "bench" / "workbench_real.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


@pytest.fixture(scope="module")
def kp100(bench):
    return bench.xl330_groups((100,))[0]


def test_the_xl330_logs_load_with_the_documented_mapping(bench):
    for kp in (100, 200):
        for tr in bench.XL_TRAJECTORIES:
            path = XL / f"kp{kp}_{tr}.csv"
            ds = load_dataset(path, roles=bench.XL_ROLES)
            cols = bench.read_csv(path)
            assert ds.n == len(cols["t_s"]) > 1000 and ds.n_dropped == 0
            assert ds.actuator and 5.2e-3 < ds.dt < 5.4e-3  # about 190 Hz (README)
            np.testing.assert_allclose(ds.target, cols["q_des_rad"] - cols["q_rad"])
            assert ds.preprocessing["dq"]["source"] == "log"
            # the derived torque is the pendulum's gravity torque of the header's mass and length
            np.testing.assert_allclose(cols["tau_gravity_Nm"], 0.49 * 9.80665 * 0.1 * np.sin(cols["q_rad"]), atol=1e-5)
            # the encoder's quantum: 2 pi / 4096
            counts = cols["q_rad"] / (2 * np.pi / 4096)
            assert np.max(np.abs(counts - np.round(counts))) < 1e-2


def test_the_measured_logs_raise_no_unit_doubt_and_no_fault(bench):
    """The units check reads plausibility: every measured recording (the XL330 at 190 Hz, the STS3215 at 10 Hz, its
    servo error up to 1.3 rad) passes it, so that no real log is refused as "milliseconds?" or "deg/s?"."""
    from servotau.identification.workbench.data import excitation_of

    for g in [*bench.xl330_groups(), *bench.sts3215_groups()]:
        for r in g.recordings:
            e = excitation_of(load_dataset(r.columns, roles=r.roles))
            assert e.unit_doubts == () and e.faults == (), (r.name, e.unit_doubts, e.faults)


def test_the_servo_error_is_the_firmwares_pwm_command(bench):
    """The XL330's P law, read from its own PWM register: duty = error_gain kp (q_des - q), no limit reached."""
    for kp in (100, 200):
        for tr in bench.XL_TRAJECTORIES:
            c = bench.read_csv(XL / f"kp{kp}_{tr}.csv")
            err = c["q_des_rad"] - c["q_rad"]
            slope = float(err @ c["duty"] / (err @ err))
            assert slope == pytest.approx(bench.XL_ERROR_GAIN * kp, rel=0.03)
            assert np.corrcoef(err, c["duty"])[0, 1] > 0.999
            assert np.max(np.abs(c["duty"])) < 0.9


def test_the_coulomb_viscous_baseline_has_the_pendulums_physics(bench, kp100):
    """M1 in inverse form, fitted on two recordings: the inertia is the pendulum's m l^2 plus a rotor's armature
    (more, within a factor 2), the motor's R / kt is of the published model's order, friction levels are positive,
    and the encoder's offset is small."""
    published = json.loads((XL / "published" / "m1.json").read_text())
    for i in range(3):
        train = [r for j, r in enumerate(kp100.recordings) if j != i]
        phys = bench.physical_m1(bench.fit_m1(train), 100.0)
        link = 0.49 * 0.1 ** 2
        assert link < phys["inertia_kg_m2"] < 2 * link
        assert 0.5 < phys["R_over_kt"] / (published["R"] / published["kt"]) < 2
        assert phys["damping_Nm_s_per_rad"] > 0 and phys["coulomb_Nm"] > 0
        assert abs(phys["q_offset_rad"]) < 0.1


def test_held_out_by_recording_the_workbench_and_the_baseline_are_scored(bench, kp100):
    """Fitted on sin_sin and up_and_down, scored on sin_time_square (the fastest: accelerations the training
    recordings never reach). The paper's model has no inertia torque and the gravity column holds none: it
    extrapolates worse than the baseline, which has it; the workbench's acceleration term (`elastic`) closes most
    of that gap."""
    train, held = list(kp100.recordings[:2]), kp100.recordings[2]
    ds = bench.dataset(train)
    assert ds.segment is not None and set(np.unique(ds.segment)) == {0.0, 1.0}
    test = load_dataset(held.columns, roles=held.roles)
    spec = parse_spec("paper", ds.signals, offset=not ds.actuator)
    base = compare(ds, spec).model
    base_rms = bench.scores(test.target, compare(test, base).prediction)["rms"]
    m1_rms = bench.scores(held.target, bench.predict_m1(bench.fit_m1(train), held))["rms"]
    assert np.isfinite(base_rms) and m1_rms < base_rms
    ladder = add_effects(ds, spec, effects=["elastic"], diagnose_final=False)
    with_inertia = bench.scores(test.target, compare(test, ladder.final).prediction)["rms"]
    assert with_inertia < base_rms


def test_the_sts3215_logs_split_by_servo_and_are_held_out_by_recording(bench):
    g = bench.sts3215_groups((1,))[0]
    assert [r.name for r in g.recordings] == ["nocomp2_s1", "comp2_s1", "pgain_zero_db_s1"]
    for i, held in enumerate(g.recordings):
        assert np.all(held.columns["servo"] == 1) and np.all(np.diff(held.columns["t_s"]) > 0)
        train = [r for j, r in enumerate(g.recordings) if j != i]
        p = bench.fit_deadband(train)
        assert p["sign_load"] >= 0  # half the play: a dead band is never negative
        s = bench.scores(held.target, bench.predict_deadband(p, held))
        ds = bench.dataset(train)
        test = load_dataset(held.columns, roles=held.roles)
        w = bench.scores(test.target, compare(test, compare(ds, parse_spec("paper", ds.signals)).model).prediction)
        assert np.isfinite(s["rms"]) and np.isfinite(w["rms"]) and test.n == len(held.target)


def test_the_acceleration_term_does_not_run_across_the_join_of_two_recordings(bench, kp100):
    """recordings.combine joins the recordings end to end; the acceleration (an SG fit of q) is fitted on each
    recording, one-sided at its edges: next to the join it is no larger than elsewhere (across the join it reached
    645 rad/s^2 on these two, at most 59 elsewhere), and it is each recording's own acceleration."""
    from servotau.identification.workbench.model import Term, design
    from servotau.signal.savgol import savgol_centred

    train = list(kp100.recordings[1:])
    ds = bench.dataset(train)
    spec = parse_spec("paper", ds.signals).plus(Term("elastic", {"window": 0.058, "lag": 0.0}))
    acc = design(ds.signals, spec, None)[1][:, -1]
    join = len(train[0].target)
    assert ds.signals.starts == (0, join)
    near = np.abs(acc[join - 8:join + 8]).max()
    away = np.abs(np.concatenate([acc[:join - 8], acc[join + 8:]])).max()
    assert near <= away
    w = max(5, int(round(0.058 / ds.dt)) | 1)
    alone = [savgol_centred(r.columns[r.roles["position"]], w, 3, ds.dt, deriv=2) for r in train]
    np.testing.assert_allclose(acc, np.concatenate(alone), rtol=1e-12, atol=1e-9)
