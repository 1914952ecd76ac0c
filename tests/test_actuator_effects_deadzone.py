"""Tests of servotau.actuator.effects.deadzone."""

import numpy as np
import pytest


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
