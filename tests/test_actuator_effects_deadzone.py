"""Tests of servotau.actuator.effects.deadzone: the effect, and the dead band measured on holds (its feedforward
term)."""

import numpy as np
import pytest

from servotau.actuator import EffectTerm, MotorModel
from servotau.actuator.effects.deadzone import BAND, rest_dead_band, with_dead_band
from servotau.control.config import JointGains
from servotau.control.torque import JointTorqueController
from servotau.errors import IdentificationError

K_TAU = 2e-4  # [rad/(N m)]


def _holds(d=4e-4, offset=0.0, n=2000, noise=2e-5, seed=0):
    """Samples at rest with torques of both signs: dq_err = k_tau tau + d sign(tau) + offset + noise."""
    rng = np.random.default_rng(seed)
    tau = np.concatenate([rng.uniform(1.5, 20.0, n), rng.uniform(-20.0, -1.5, n)])
    dq_err = K_TAU * tau + d * np.sign(tau) + offset + noise * rng.standard_normal(2 * n)
    return dq_err, tau, np.zeros(2 * n)


def test_rest_dead_band_recovers_the_band_and_the_offset():
    """Half the jump of the rest residual at the torque reversal is d; the mean of both sides is the offset."""
    db = rest_dead_band(*_holds(d=4e-4, offset=3e-5), K_TAU)
    assert db.d == pytest.approx(4e-4, abs=3e-6)
    assert db.offset == pytest.approx(3e-5, abs=3e-6)
    assert db.n_positive == db.n_negative == 2000
    assert 0 < db.spread < 3e-5


def test_rest_dead_band_ignores_moving_and_small_torque_samples():
    """Samples with |dq| >= dq_rest or |tau| <= tau_min (friction, noise around zero torque) do not change d."""
    dq_err, tau, dq = _holds(d=2e-4)
    moving = np.full(500, 0.3), np.full(500, 5.0), np.full(500, 1.0)  # a large residual, but moving
    small = np.full(500, -1e-3), np.full(500, 0.5), np.zeros(500)  # at rest, below tau_min
    args = [np.concatenate(x) for x in zip((dq_err, tau, dq), moving, small, strict=True)]
    assert rest_dead_band(*args, K_TAU).d == pytest.approx(2e-4, abs=3e-6)


def test_rest_dead_band_needs_both_torque_signs_at_rest():
    """A log without holds on one side of the torque reversal raises IdentificationError saying what to do."""
    dq_err, tau, dq = _holds()
    keep = tau > 0
    with pytest.raises(IdentificationError, match="pushed through zero"):
        rest_dead_band(dq_err[keep], tau[keep], dq[keep], K_TAU)


def test_with_dead_band_replaces_the_deadzone_term_and_keeps_the_others():
    """The model's deadzone term becomes (d, band, damping_share 0), first; the other terms are unchanged."""
    m = MotorModel(k_tau=K_TAU, k_v=0.01, extra={"coulomb": EffectTerm(1e-4, {"v_eps": 0.01}),
                                                 "deadzone": EffectTerm(9e-5, {"band": 1e-4, "damping_share": 0.67})},
                   provenance="test")
    out = with_dead_band(m, 4e-4)
    assert list(out.extra) == ["deadzone", "coulomb"]
    assert out.extra["deadzone"].coefficient == 4e-4
    assert dict(out.extra["deadzone"].shape) == {"band": BAND, "damping_share": 0.0}
    assert out.extra["coulomb"] == m.extra["coulomb"] and out.k_tau == m.k_tau and out.provenance == "test"


def test_dead_band_term_is_a_sign_smoothed_over_the_band():
    """At rest the model with the dead band predicts k_tau tau + d clip(u / band, -1, 1), u = k_tau tau: +-d beyond
    the band, linear inside (the workbench's deadzone term with damping_share 0)."""
    d = 4e-4
    m = with_dead_band(MotorModel(k_tau=K_TAU, k_v=0.01, provenance="test"), d)
    u = np.array([-1e-3, -BAND / 2, 0.0, BAND, 1e-3])
    tau = u / K_TAU
    np.testing.assert_allclose(m.predict(tau, np.zeros_like(tau)) - u, d * np.array([-1, -0.5, 0, 1, 1]),
                               rtol=0, atol=1e-15)


@pytest.mark.parametrize("tau", [10.0, -10.0])
def test_controller_adds_the_dead_band_in_the_direction_of_the_command(tau):
    """At rest the eq. 10 feedforward with the dead-band term commands k_tau tau* + d sign(tau*): the error
    the servo needs before its driver passes any current."""
    d = 4e-4
    model = with_dead_band(MotorModel(k_tau=K_TAU, k_v=0.01, provenance="test"), d)
    ctl = JointTorqueController(["J"], {"J": model}, {"J": JointGains(k_p=0.0)}, period=1e-3)
    dq_err = ctl.update(np.array([tau]), np.array([tau]), np.zeros(1), q_hat=np.zeros(1), ddq_hat=np.zeros(1))
    assert dq_err[0] == pytest.approx(K_TAU * tau + d * np.sign(tau))
    assert ctl.extra[0] == pytest.approx(d * np.sign(tau))


def test_deadzone_crossing_form_follows_the_command_lead_inside_the_band():
    """Crossing form: sign(m) outside the band; inside, the sign of the last effort outside plus the command's
    lead since the entry over the width (the joint crosses the band freely from the edge it entered at); it
    enters at |m| <= band and leaves at |m| > 1.5 band."""
    from servotau.actuator.effects.deadzone import columns as _deadzone_columns
    from servotau.actuator.effects.deadzone import deadzone
    from servotau.actuator.effects.deadzone import fold as _deadzone_fold
    from servotau.actuator.signals import Signals

    # [rad] band 1 mrad: inside from 2 (|u| <= 1 mrad) to 4 (hysteresis: 1.2 mrad is not beyond 1.5 band), and 6-7
    u = np.array([2.0, 1.5, 0.5, -1.2, 0.2, -2.0, -0.4, 0.3]) * 1e-3
    n = len(u)
    q_des = np.arange(n) * 1e-4  # lead = q_des[k-1] - q[k]: 0, 0, 0.1, 0.2, ... mrad
    sig = Signals({"u": u, "u_v": np.zeros(n), "tau": u, "dq": np.zeros(n), "q": np.zeros(n), "q_des": q_des}, 1e-3, n)
    phi = deadzone(sig, band=1e-3, crossing=1.0, width=2e-3)
    np.testing.assert_allclose(phi, [1, 1, 1, 1.05, 1.1, -1, -1, -0.95], atol=1e-12)
    # fitted as two columns (edge, lead since the entry): width = c_edge / c_lead reproduces their sum
    cols = _deadzone_columns(sig, band=1e-3, crossing=1.0)
    c, shape = _deadzone_fold(np.array([3e-3, 1.5]), {"band": 1e-3, "crossing": 1.0})
    assert shape["width"] == pytest.approx(2e-3)
    np.testing.assert_allclose(c * deadzone(sig, **shape), cols @ [3e-3, 1.5], atol=1e-15)
    assert _deadzone_fold(np.array([3e-3]), {"band": 1e-3, "v_th": 0.0}) == (3e-3, {"band": 1e-3, "v_th": 0.0})
