"""Recordings joined end to end (recordings.combine) and logs with gaps: every effect's columns restart at each
run, so a joined log gives the same columns as its recordings processed alone and concatenated."""

from __future__ import annotations

import numpy as np
import pytest

from servotau.actuator import builtin_effects
from servotau.identification.workbench import load_dataset
from servotau.identification.workbench.checks import faster_derivative
from servotau.identification.workbench.recordings import combine

DT = 2e-3  # [s]


def _log(seed: int, n: int, t0: float = 0.0, noise: float = 2e-5) -> dict[str, np.ndarray]:
    """A servo log: a random smooth command, the joint following it with an error that grows with the torque;
    encoder noise ``noise`` [rad]."""
    rng = np.random.default_rng(seed)
    t = t0 + np.arange(n) * DT
    f = rng.uniform(0.3, 1.5, 3)
    q_des = sum(rng.uniform(0.1, 0.4) * np.sin(2 * np.pi * fk * t + rng.uniform(0, 6)) for fk in f)
    tau = 20.0 * np.gradient(np.gradient(q_des, DT), DT) * 0.05 + 3.0 * np.sin(q_des)
    q = q_des - 1e-3 * tau - 2e-3 * np.gradient(q_des, DT) + rng.normal(0, noise, n)
    return {"t": t, "q": q, "q_des": q_des, "tau": tau + rng.normal(0, 0.05, n)}


def _columns(ds, shapes=None):
    """Every builtin effect's columns on ``ds`` (``u`` = the target), at ``shapes`` (default: its grid on ``ds``)."""
    sig = ds.signals.with_columns(u=ds.target.copy(), u_v=np.zeros(ds.n), u_tau=ds.target.copy())
    out, grids = {}, {}
    for eff in builtin_effects():
        grid = shapes[eff.name] if shapes is not None else eff.grid_for(sig)
        grids[eff.name] = grid
        for shape in grid:
            out[(eff.name, tuple(sorted(shape.items())))] = eff.columns(sig, shape)
    return out, grids


def test_a_joined_log_gives_the_columns_of_its_recordings_processed_alone():
    """Two recordings at the same period: each effect (every shape of the joined log's grid) on the joined log is
    its columns on each recording, concatenated; without the runs, the join shows (the delay, the acceleration)."""
    parts = [load_dataset(_log(seed, n)) for seed, n in ((1, 1500), (2, 1100))]
    ds = combine(parts)
    assert ds.signals.starts == (0, 1500)
    joined, grids = _columns(ds)
    alone = [_columns(p, grids)[0] for p in parts]
    for key, col in joined.items():
        np.testing.assert_allclose(col, np.concatenate([a[key] for a in alone]), rtol=1e-9, atol=1e-12,
                                   err_msg=str(key))
    crossed = ds.signals.__class__(dict(ds.signals), ds.dt, ds.n)  # the same columns as one run
    delay = next(e for e in builtin_effects() if e.name == "delay")
    shape = grids["delay"][-1]
    assert np.max(np.abs(delay.columns(crossed, shape)[1500])) > 10 * np.max(np.abs(joined[
        ("delay", tuple(sorted(shape.items())))][1500]))


def test_combine_keeps_each_recordings_runs_and_load_dataset_hands_its_gaps_to_the_signals():
    a = _log(3, 900)
    keep = np.ones(900, dtype=bool)
    keep[400:410] = False  # a gap of 10 samples: a second run
    gap = load_dataset({k: v[keep] for k, v in a.items()})
    assert gap.signals.starts == (0, 400)
    nan = dict(a)
    nan["tau"] = a["tau"].copy()
    nan["tau"][600] = np.nan  # a dropped row ends a run too
    dropped = load_dataset(nan)
    assert dropped.n_dropped == 1 and dropped.signals.starts == (0, 600)
    ds = combine([gap, load_dataset(_log(4, 700)), dropped])
    assert ds.signals.starts == (0, 400, 890, 1590, 2190)
    assert ds.signals.with_columns(u=np.zeros(ds.n)).runs()[-1] == (2190, ds.n)
    one = load_dataset(a)
    assert one.signals.starts == (0,)


@pytest.mark.parametrize("effect", ["delay", "motor_lag", "dahl", "saturation"])
def test_a_gap_in_one_log_restarts_the_effects_filters(effect):
    """A log with a gap gives, on each side of it, the columns of that side alone (at the same shapes; the same
    preprocessing windows, which each side alone would choose from its own samples)."""
    a = _log(5, 1200)
    keep = np.ones(1200, dtype=bool)
    keep[500:520] = False
    opts = {"dq_window": 9, "smooth_torque_s": 0.014}
    ds = load_dataset({k: v[keep] for k, v in a.items()}, **opts)
    left = load_dataset({k: v[:500] for k, v in a.items()}, **opts)
    right = load_dataset({k: v[520:] for k, v in a.items()}, **opts)
    eff = next(e for e in builtin_effects() if e.name == effect)
    sig = ds.signals.with_columns(u=ds.target.copy(), u_tau=ds.signals["tau"].copy())
    for shape in eff.grid_for(sig):
        parts = [eff.columns(p.signals.with_columns(u=p.target.copy(), u_tau=p.signals["tau"].copy()), shape)
                 for p in (left, right)]
        np.testing.assert_allclose(eff.columns(sig, shape), np.concatenate(parts), rtol=1e-9, atol=1e-12)


def test_the_dynamics_probe_reads_no_sample_of_another_recording():
    """The dynamics probe's lagged and led columns on a joined log are each recording's own, concatenated."""
    from servotau.identification.workbench.probes import probe_columns

    parts = [load_dataset(_log(seed, n)) for seed, n in ((4, 1200), (5, 1000))]
    ds = combine(parts)
    joined = probe_columns(ds.signals, ds.target, "dynamics")["dynamics"]
    alone = [probe_columns(p.signals, p.target, "dynamics")["dynamics"] for p in parts]
    np.testing.assert_allclose(joined, np.vstack(alone), rtol=1e-12, atol=1e-15)


def test_a_joined_log_differentiates_each_recording_faster_with_half_its_own_window():
    """Two recordings with different encoder noise choose different velocity windows; the joined log keeps each
    (its preprocessing and notes say both), and its faster derivative is each recording's own, row for row."""
    parts = [load_dataset(_log(6, 1500, noise=1e-6)), load_dataset(_log(7, 1200, noise=3e-4))]
    windows = [p.preprocessing["dq"]["window"] for p in parts]
    assert windows[0] < windows[1]
    ds = combine(parts)
    dq = ds.preprocessing["dq"]
    assert dq["source"] == "derivative of q" and dq["window"] == f"{windows[0]} and {windows[1]}"
    assert [(a, w) for a, w, _dt in dq["windows"]] == [(0, windows[0]), (1500, windows[1])]
    own = [p.filter_parts()[0] for p in parts]  # each recording alone: one part, its rows, window and order
    assert [(o.first, o.end, o.window) for o in own] == [(0, 1500, windows[0]), (0, 1200, windows[1])]
    assert [(p.first, p.end, p.window, p.period, p.order) for p in ds.filter_parts()] == \
        [(0, 1500, windows[0], own[0].period, own[0].order), (1500, 2700, windows[1], own[1].period, own[1].order)]
    assert own[0].period == pytest.approx(DT)
    assert any(f"own window: {windows[0]} and {windows[1]} samples" in n for n in ds.notes)
    fast, w = faster_derivative(ds)
    alone = [faster_derivative(p) for p in parts]
    assert w == f"{alone[0][1]} and {alone[1][1]}" and alone[0][1] < windows[0] and alone[1][1] < windows[1]
    for col in ("dq", "ddq"):
        np.testing.assert_array_equal(fast.signals[col], np.concatenate([a[0].signals[col] for a in alone]), col)


def test_a_joined_log_with_one_window_keeps_it_and_the_log_velocity_is_never_redifferentiated():
    opts = {"dq_window": 9, "smooth_torque_s": 0.014}
    ds = combine([load_dataset(_log(8, 900), **opts), load_dataset(_log(9, 800), **opts)])
    assert ds.preprocessing["dq"]["window"] == 9
    assert [(a, w) for a, w, _dt in ds.preprocessing["dq"]["windows"]] == [(0, 9), (900, 9)]
    assert ds.preprocessing["tau"]["window"] == 7 and ds.preprocessing["tau"]["source"] == "smoothed"
    assert faster_derivative(ds)[1] == 5
    with_dq = [load_dataset({**c, "dq": np.gradient(c["q"], DT)}) for c in (_log(8, 900), _log(9, 800))]
    joined = combine(with_dq)
    assert joined.preprocessing["dq"] == {"source": "log", "column": "dq"} and faster_derivative(joined) is None


def test_a_signal_derived_in_some_recordings_only_is_said_and_not_checked():
    ds = combine([load_dataset(_log(8, 900)), load_dataset(_log(9, 800), smooth_torque_s=0)])
    assert ds.preprocessing["tau"] == {"source": "mixed", "sources": ("smoothed", "not derived")}
    assert any(n.startswith("tau: the recordings differ: 0: smoothed, 1: not derived") for n in ds.notes)


def test_the_coarsest_encoder_of_the_recordings_sets_the_rounding_floor():
    """A quantised recording joined with an unquantised one: the joined log keeps the quantised one's resolution
    (the floor no effect is named within) and says that the recordings differ."""
    coarse, fine = _log(4, 1200), _log(5, 1000)
    res = 2 * np.pi / 2**13
    coarse = {**coarse, "q": np.round(coarse["q"] / res) * res}
    ds = combine([load_dataset(coarse), load_dataset(fine)])
    assert ds.preprocessing["q"] == {"source": "log", "resolution": pytest.approx(res)}
    assert any(n.startswith("q: the recordings' encoder resolutions differ") for n in ds.notes)
