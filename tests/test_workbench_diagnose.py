"""Tests of the diagnosis on synthetic tables (identification/workbench/diagnose.py): fast, known truth."""

import numpy as np
import pytest

from servotau.errors import IdentificationError
from servotau.identification import Loss
from servotau.identification.workbench import (
    diagnose,
    effect_names,
    load_dataset,
    parse_spec,
    register_effect,
    unregister_effect,
)

K_TAU, K_V, K_C = 5e-5, 6e-3, 1.3e-4  # [rad/(N m)], [rad/(rad/s)], [rad]


def synthetic_table(extra=None, *, seconds=12.0, seed=0, noise=1e-5, reversals=True) -> dict[str, np.ndarray]:
    """A single-joint log ``t, q, q_des, tau, dq, segment`` of ``dq_err = k_tau tau + k_v dq + k_c sign + extra``
    plus white encoder noise.

    ``extra(t, q, dq, tau) -> [rad]`` is the hidden effect. Motion: sines with reversals and holds (or a
    one-way ramp without reversals); torque: slow sines of +/- 30 N m.
    """
    rng = np.random.default_rng(seed)
    dt = 1e-3
    t = np.arange(int(seconds / dt)) * dt
    if reversals:
        dq = 0.6 * np.sin(2 * np.pi * 0.45 * t) + 0.25 * np.sin(2 * np.pi * 1.3 * t + 1.0)
        dq *= np.clip(np.sin(2 * np.pi * t / 4.0) * 3, -1, 1) ** 2  # holds between bursts
    else:
        dq = 0.2 + 0.1 * np.sin(2 * np.pi * 0.3 * t)
    q = 0.5 + np.cumsum(dq) * dt
    tau = 30 * np.sin(2 * np.pi * 0.23 * t + rng.uniform(0, 6)) + 8 * np.sin(2 * np.pi * 0.71 * t)
    y = K_TAU * tau + K_V * dq + K_C * np.tanh(dq / 0.005)
    if extra is not None:
        y = y + extra(t, q, dq, tau)
    q_meas = q + noise * rng.standard_normal(len(t))  # the encoder is noisy, the command is not
    return {"t": t, "q": q_meas, "q_des": q + y, "tau": tau, "dq": dq, "segment": np.floor(t / (seconds / 4))}


def cogging_truth(t, q, dq, tau):
    return 2e-4 * np.sin(2 * np.pi * q / 0.08 + 0.3)


def test_injected_cogging_ranks_first_and_is_named():
    """A position ripple hidden in the data is named, with its period, and removes most of the error."""
    ds = load_dataset(synthetic_table(cogging_truth))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "missing_effect" and d.top.effect == "cogging"
    assert d.top.shape["period"] == pytest.approx(0.08, rel=0.01) and d.top.heldout_gain > 0.8
    assert not d.top.partial


def test_clean_synthetic_data_give_no_missing_effect():
    """Data that follow the base model exactly (plus white noise) name nothing."""
    ds = load_dataset(synthetic_table())
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "no_missing_effect", d.message
    assert all(c.heldout_gain < 0.1 for c in d.ranking if c.testable)


def test_stribeck_velocity_outside_the_grid_is_partially_explained():
    """A Stribeck velocity above the grid (1 rad/s, grid max 0.32) is named but partially explained; the same
    Stribeck friction inside the grid (0.16 rad/s) is fully explained."""
    def stribeck(v_s):
        return lambda t, q, dq, tau: 1e-3 * np.tanh(dq / 0.005) * np.exp(-((dq / v_s) ** 2))

    ds = load_dataset(synthetic_table(stribeck(1.0), noise=2e-6))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "missing_effect" and d.top.effect == "stribeck", d.message
    assert d.top.partial and d.top.remaining > 0.1 and "partially explained" in d.message
    inside = load_dataset(synthetic_table(stribeck(0.16), noise=2e-6))
    d2 = diagnose(inside, parse_spec("coulomb", inside.signals))
    assert d2.top.effect == "stribeck" and not d2.top.partial, d2.message
    assert d2.top.shape["v_s"] == 0.16


def test_structure_no_effect_explains_is_unexplained():
    """A bump of the error at one torque level (no effect of the library) gives the verdict unexplained."""
    ds = load_dataset(synthetic_table(lambda t, q, dq, tau: 3e-4 * np.exp(-(((tau - 12.0) / 3.0) ** 2))))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "unexplained", d.message
    assert max(d.probes, key=d.probes.get) in ("torque", "servo_error")


def test_user_effect_registered_without_editing_the_library():
    """A user effect (a function of the log columns) is ranked like a built-in one, and can be removed."""
    bump = lambda t, q, dq, tau: 3e-4 * np.exp(-(((tau - 12.0) / 3.0) ** 2))  # noqa: E731
    ds = load_dataset(synthetic_table(bump))
    register_effect("torque_bump", lambda s, centre, width: np.exp(-(((s["tau"] - centre) / width) ** 2)),
                    grid=[{"centre": c, "width": 3.0} for c in (0.0, 6.0, 12.0, 18.0)], signals=("tau",),
                    signature="residual against torque: a bump", family="torque")
    try:
        d = diagnose(ds, parse_spec("coulomb", ds.signals))
        assert d.top.effect == "torque_bump" and d.top.shape["centre"] == 12.0 and d.verdict == "missing_effect"
        with pytest.raises(IdentificationError, match="already registered"):
            register_effect("torque_bump", lambda s: s["tau"])
    finally:
        unregister_effect("torque_bump")
    assert "torque_bump" not in effect_names()


def test_unexcited_effect_is_untestable_not_absent():
    """Without velocity reversals, direction-dependent effects are reported untestable, with the reason."""
    ds = load_dataset(synthetic_table(reversals=False))
    d = diagnose(ds, parse_spec("paper", ds.signals), effects=["coulomb", "coulomb_asym", "cogging"])
    c = d.candidate("coulomb")
    assert not c.testable and "reversals" in c.reason
    assert d.to_dict()["untestable"]["coulomb"] == c.reason
    assert d.rank_of("coulomb") == 0


def test_asymmetric_loss_names_the_same_effect():
    """With the asymmetric loss of eq. 8 the ranking still puts the hidden ripple first."""
    ds = load_dataset(synthetic_table(cogging_truth, seconds=8.0))
    d = diagnose(ds, parse_spec("coulomb", ds.signals), Loss.asymmetric(10.0),
                 effects=["cogging", "stribeck", "coulomb_asym", "deadzone"])
    assert d.top.effect == "cogging" and d.verdict == "missing_effect"
    assert d.base.heldout.w == 10.0


def test_unknown_effect_and_bad_threshold_are_refused():
    """Unknown effect names and thresholds outside (0, 1) raise naming the field."""
    ds = load_dataset(synthetic_table(seconds=4.0))
    with pytest.raises(IdentificationError, match="unknown effect 'cogs'.*expected one of"):
        diagnose(ds, parse_spec("coulomb", ds.signals), effects=["cogs"])
    with pytest.raises(IdentificationError, match="unknown effect 'frobnicate'"):
        parse_spec("coulomb+frobnicate", ds.signals)
    with pytest.raises(IdentificationError, match="min_gain"):
        diagnose(ds, parse_spec("coulomb", ds.signals), min_gain=1.5)


def test_a_coefficient_outside_the_physical_range_is_not_chosen():
    """An effect whose physics allows only positive coefficients is not named for a ripple it fits with a
    negative one (that block keeps the base model: gain 0), and is named when the range admits it."""
    ds = load_dataset(synthetic_table(lambda t, q, dq, tau: -2e-4 * np.sin(2 * np.pi * q / 0.08)))
    ripple = lambda s: np.sin(2 * np.pi * s["q"] / 0.08)  # noqa: E731
    with pytest.raises(IdentificationError, match="coefficient_range"):
        register_effect("ripple_bad", ripple, coefficient_range=(1.0, 0.0))
    register_effect("ripple_positive", ripple, signals=("q",), coefficient_range=(0.0, 1.0))
    register_effect("ripple_negative", ripple, signals=("q",), coefficient_range=(-1.0, 0.0))
    try:
        d = diagnose(ds, parse_spec("coulomb", ds.signals), effects=["ripple_positive", "ripple_negative"])
        assert d.candidate("ripple_positive").heldout_gain == 0.0
        assert d.candidate("ripple_negative").heldout_gain > 0.9 and d.top.effect == "ripple_negative"
    finally:
        unregister_effect("ripple_positive")
        unregister_effect("ripple_negative")
