"""Bad input (issue 18): jittered or jumping time stamps, gaps, constant columns, velocities that never cross zero,
tables in other units. Each gets a note in the dataset (and so in the report) and an honest "cannot tell" where
the log cannot decide, never a crash and never a confident wrong verdict. Small generated logs."""

from __future__ import annotations

import numpy as np
import pytest
from support.synthetic import K_TAU, friction_recording, synthetic_table

from servotau.actuator import excitation_report, get_effect
from servotau.errors import IdentificationError
from servotau.identification.workbench import diagnose, load_dataset, parse_spec
from servotau.identification.workbench.data import describe
from servotau.identification.workbench.verdict import VERDICTS

FRICTION = ["coulomb", "stribeck", "delay", "motor_lag"]  # a few effects keep the tests fast


def _table(seconds=6.0, **kw):
    return synthetic_table(seconds=seconds, **kw)


def _diagnose(ds, effects=FRICTION):
    d = diagnose(ds, parse_spec("paper", ds.signals), effects=effects)
    assert d.verdict in VERDICTS and d.message
    return d


def _note(ds, text):
    return next((n for n in ds.notes if text in n), None)


def test_jittered_time_stamps_are_treated_as_uniform_and_said():
    cols = _table()
    rng = np.random.default_rng(1)
    cols["t"] = cols["t"] + rng.uniform(-0.2e-3, 0.2e-3, len(cols["t"]))  # +-20 % of the 1 ms period
    ds = load_dataset(cols)
    note = _note(ds, "jitter")
    assert note is not None and "treated as uniform" in note and "cannot be told" not in note
    d = _diagnose(ds)
    # the truth is paper + coulomb: the jitter of the stamps does not turn into a lag
    assert d.verdict == "missing_effect" and d.top.effect == "coulomb"


def test_large_jitter_leaves_lags_untold():
    cols = _table()
    rng = np.random.default_rng(2)
    cols["t"] = cols["t"] + rng.uniform(-0.45e-3, 0.45e-3, len(cols["t"]))
    ds = load_dataset(cols)
    assert "cannot be told" in _note(ds, "jitter")
    e = excitation_report(ds.signals)
    for name in ("delay", "motor_lag", "elastic"):
        reason = get_effect(name).needs(e)
        assert reason is not None and reason.startswith("cannot tell") and "jitter" in reason


def test_period_that_jumps_is_resampled_and_said():
    cols = _table()
    t = cols["t"]
    keep = (t < 3.0) | (np.arange(len(t)) % 2 == 0)  # 1 ms, then 2 ms
    cols = {k: v[keep] for k, v in cols.items()}
    ds = load_dataset(cols)
    note = _note(ds, "period jumps")
    assert note is not None and "resampled onto a uniform 2 ms grid" in note
    assert ds.dt == pytest.approx(2e-3)
    assert set(np.unique(ds.segment)) <= set(np.unique(cols["segment"]))  # labels are not interpolated
    _diagnose(ds)


def test_gaps_restart_the_filters_and_the_diagnosis_runs():
    cols = _table()
    cols["t"] = cols["t"].copy()
    cols["t"][2000:] += 0.2
    cols["t"][4000:] += 0.5
    ds = load_dataset(cols)
    assert _note(ds, "2 steps longer") is not None
    assert np.all(np.isfinite(ds.signals["dq"]))
    _diagnose(ds)


def test_constant_torque_is_not_used_and_said():
    cols = _table()
    cols["q_des"] = cols["q_des"] - K_TAU * cols["tau"]  # a servo without load ...
    cols["tau"] = np.zeros_like(cols["tau"])  # ... and a torque sensor that reads its zero
    ds = load_dataset(cols)
    note = _note(ds, "constant")
    assert note is not None and "'tau' (role torque)" in note and "not used" in note
    assert "tau" not in ds.signals
    d = _diagnose(ds, ["coulomb", "backlash", "load_friction"])
    assert "not in the log" in d.candidate("backlash").reason
    assert d.verdict == "missing_effect" and d.top.effect == "coulomb"  # K_TAU tau is 0: coulomb is the truth
    assert "the log has no torque" in d.message and "may stand for the servo's load" in d.message, d.message


def test_a_servo_log_without_torque_says_an_effect_may_stand_for_the_load():
    """A log without its torque column (a clean servo under load): the model has no k_tau tau, so whatever it names
    may be the load's part (a black-box trial's plant named elastic with no warning); the caveat is in the message and
    the checks, and a log with torque has none."""
    cols = _table()
    no_tau = load_dataset({k: v for k, v in cols.items() if k != "tau"})
    d = _diagnose(no_tau)
    assert "the log has no torque" in d.message and any("the log has no torque" in c for c in d.checks)
    assert "the log has no torque" not in _diagnose(load_dataset(cols)).message


def test_constant_velocity_column_is_replaced_by_the_derivative_of_q():
    cols = _table()
    cols["dq"] = np.full_like(cols["dq"], 0.25)
    ds = load_dataset(cols)
    assert "'dq' (role velocity)" in _note(ds, "constant")
    assert ds.preprocessing["dq"]["source"] == "derivative of q"
    assert np.std(ds.signals["dq"]) > 0.05


def test_constant_command_is_said_and_the_diagnosis_runs():
    cols = _table()
    cols["q_des"] = np.full_like(cols["q_des"], 0.5)
    ds = load_dataset(cols)
    assert "effects that read it cannot be told" in _note(ds, "'q_des' (role command)")
    _diagnose(ds, ["coulomb", "delay"])


def test_velocity_that_never_crosses_zero_says_so():
    ds = load_dataset(_table(reversals=False))
    d = _diagnose(ds, ["coulomb", "stribeck", "coulomb_asym"])
    for name in ("coulomb", "stribeck", "coulomb_asym"):
        c = d.candidate(name)
        assert not c.testable and "never crosses zero" in c.reason
    assert d.verdict != "missing_effect"


def _big_motion(seconds=6.0):
    cols = _table(seconds)
    t = cols["t"]
    q = 1.5 * np.sin(2 * np.pi * 0.3 * t)  # +-1.5 rad: +-86 degrees
    dq = 1.5 * 2 * np.pi * 0.3 * np.cos(2 * np.pi * 0.3 * t)
    err = cols["q_des"] - (cols["q"] - 0.0)  # the synthetic servo error [rad]
    return {**cols, "q": q, "q_des": q + err, "dq": dq}


def test_table_in_degrees_cannot_tell():
    cols = _big_motion()
    deg = {**cols, "q": np.degrees(cols["q"]), "q_des": np.degrees(cols["q_des"]), "dq": np.degrees(cols["dq"])}
    ds = load_dataset(deg)
    note = _note(ds, "units:")
    assert note is not None and "degrees?" in note
    d = _diagnose(ds)
    assert d.verdict == "cannot_tell" and d.message.startswith("cannot tell which effect: units doubted")
    assert all(not c.testable and c.reason.startswith("cannot tell: units doubted") for c in d.ranking)
    assert any("degrees?" in line for line in describe(ds))  # the report's header lines carry the note


def test_torque_in_millinewton_metres_cannot_tell():
    cols = _table()
    ds = load_dataset({**cols, "tau": 1e3 * cols["tau"]})
    assert "mN m?" in _note(ds, "units:")
    d = _diagnose(ds, ["coulomb"])
    assert d.verdict == "cannot_tell" and "mN m?" in d.message


def test_time_in_milliseconds_cannot_tell():
    """A time column in ms (or a sample index) makes a 1 ms log look like one sampled every second: the velocities
    are then 1000 times too small, and a friction fitted to them would be named with a wrong shape."""
    cols = _table()
    ds = load_dataset({**cols, "t": 1e3 * cols["t"]})
    assert "milliseconds" in _note(ds, "units:")
    d = _diagnose(ds)
    assert d.verdict == "cannot_tell" and "the sample period is 1 s (more than 0.5 s)" in d.message
    assert all(not c.testable for c in d.ranking)


def test_friction_table_in_millinewton_metres_and_degrees_per_second_cannot_tell():
    cols = friction_recording(0, seconds=8.0, f0=0.3)
    roles = {"target": "friction", "velocity": "v", "time": "t"}
    plain = _diagnose(load_dataset(cols, roles=roles), ["coulomb"])
    assert plain.verdict == "missing_effect" and not plain.excitation.unit_doubts  # the SI table is named
    other = load_dataset({**cols, "v": np.degrees(25.0 * cols["v"]), "friction": 1e3 * cols["friction"]},
                         roles=roles)
    d = _diagnose(other, ["coulomb"])
    assert d.verdict == "cannot_tell"
    assert "deg/s?" in d.message and "the torque target reaches" in d.message and "mN m?" in d.message


def test_position_that_is_noise_cannot_tell():
    """A position column of white noise (a wrong column, or a joint that only jitters): the servo error then holds
    the command's own noise, which a delay term (q_des now minus q_des before) fits without any physics."""
    rng = np.random.default_rng(3)
    cols = _table(4.0)
    cols.pop("dq")
    n = len(cols["t"])
    cols.update(q=rng.normal(0, 0.1, n), q_des=rng.normal(0, 0.1, n), tau=rng.normal(0, 5, n))
    d = _diagnose(load_dataset(cols))
    assert d.verdict == "cannot_tell" and "the position is mostly noise" in d.message
    assert all(not c.testable for c in d.ranking)


def test_one_way_motion_with_a_constant_error_says_rerun_with_the_offset():
    """A joint turning one way: Coulomb friction is a constant error there. A function of the position (cogging)
    fits part of it as the position follows time, and a free function of the velocity most of it; neither is
    named, and the message says to rerun with the offset."""
    ds = load_dataset(_table(reversals=False))
    d = _diagnose(ds, ["coulomb", "cogging"])
    assert d.verdict == "cannot_tell" and "--offset on" in d.message
    assert not d.candidate("cogging").testable or d.candidate("cogging").heldout_gain < d.min_gain
    with_offset = diagnose(ds, parse_spec("paper+offset", ds.signals), effects=["coulomb", "cogging"])
    assert with_offset.verdict == "no_missing_effect"


def test_plausible_log_has_no_unit_note():
    ds = load_dataset(_big_motion())
    assert _note(ds, "units:") is None and not excitation_report(ds.signals).unit_doubts


def test_constant_position_cannot_tell():
    cols = _table(4.0)
    cols.pop("dq")
    cols["q"] = np.full_like(cols["q"], 0.3)
    ds = load_dataset(cols)
    assert "effects that read it cannot be told" in _note(ds, "'q' (role position)")
    d = _diagnose(ds, ["coulomb", "delay"])
    assert d.verdict == "cannot_tell"
    assert d.message.startswith("cannot tell which effect: the position never changes")
    assert all(not c.testable for c in d.ranking)


def test_a_command_logged_as_a_copy_of_the_position_cannot_tell():
    """q_des == q on a moving joint (a logging slip): the servo error is zero everywhere, so nothing can be
    named; the message says the target never changes."""
    cols = _table(4.0)
    cols["q_des"] = cols["q"].copy()
    d = _diagnose(load_dataset(cols), ["coulomb", "delay"])
    assert d.verdict == "cannot_tell"
    assert d.message.startswith("cannot tell which effect: the target never changes (= 0)"), d.message


def test_a_table_with_a_header_and_no_rows_says_so(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("t,q,q_des,tau\n")
    with pytest.raises(IdentificationError, match=r"have no rows: expected a table of samples"):
        load_dataset(path)
