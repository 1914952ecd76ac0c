"""Tests of servotau.actuator.effects.saturation."""

import numpy as np
import pytest

from servotau.errors import IdentificationError


def test_saturation_holds_the_limit_with_hysteresis_and_integrates_the_command_lead():
    """The limit detector is the recursion s[k] = x[k] > (off if s[k-1] else on); the term is the change of
    q_des(t - 1) - q(t) since the onset of each saturated run, zero at the onset and below the limit."""
    from servotau.actuator.effects.saturation import saturation
    from servotau.actuator.signals import Signals, hysteresis

    x = np.array([0.0, 5.0, 11.0, 9.0, 7.0, 12.0, 3.0, 9.5, 10.5, 8.5])
    s, expected = False, []
    for v in x:
        s = v > (8.0 if s else 10.0)
        expected.append(s)
    np.testing.assert_array_equal(hysteresis(x, 10.0, 8.0), expected)
    q = np.zeros(len(x))
    q_des = np.arange(len(x)) * 1e-3  # [rad] the command runs ahead, 1 mrad per tick
    sig = Signals({"tau": x, "dq": np.zeros(len(x)), "q": q, "q_des": q_des}, 1e-3, len(x))
    phi = saturation(sig, tau_sat=10.0, beta=0.0, release=0.8)
    # saturated at 2-3, 5 and 8-9 (onsets 2, 5, 8): lead(t) - lead(onset), lead = q_des[k-1] - q[k]
    np.testing.assert_allclose(phi, [0, 0, 0, 1e-3, 0, 0, 0, 0, 0, 1e-3], atol=1e-15)
    with pytest.raises(IdentificationError, match="off"):
        hysteresis(x, 8.0, 10.0)


def test_saturation_grows_only_in_the_direction_of_the_torque():
    """Past the limit the servo asks for more torque than it gets: the error grows in the torque's direction. Where
    the lead since the onset has the other sign the servo is back in its linear range, and the term is 0 (off-line
    and on-line alike)."""
    from servotau.actuator.effects.saturation import SaturationOnline, saturation
    from servotau.actuator.signals import Signals

    tau = np.array([0.0, 12.0, 12.0, 12.0, 12.0, 0.0, -12.0, -12.0, -12.0, -12.0])
    q = np.zeros(len(tau))
    q_des = 1e-3 * np.array([0.0, 0.0, 1.0, 2.0, 1.0, 0.0, 0.0, 1.0, -1.0, -2.0])  # [rad]
    sig = Signals({"tau": tau, "dq": np.zeros(len(tau)), "q": q, "q_des": q_des}, 1e-3, len(tau))
    phi = saturation(sig, tau_sat=10.0, beta=0.0)
    # lead = q_des[k-1] - q[k]; onsets 1 and 6: the positive run grows (+1, +2 mrad), the negative run's lead
    # first grows against its torque (+1 mrad at 8: zeroed), then with it (-1 mrad at 9)
    np.testing.assert_allclose(phi, 1e-3 * np.array([0, 0, 0, 1, 2, 0, 0, 0, 0, -1]), atol=1e-15)
    online = SaturationOnline({"tau_sat": 10.0, "beta": 0.0}, 1e-3)
    ticks = []
    for k in range(len(tau)):
        x = {"tau": tau[k], "dq": 0.0, "q": q[k], "q_des": q_des[k]}
        ticks.append(online.value(x))
        online.commit(x)
    np.testing.assert_allclose(ticks, phi, atol=1e-15)
