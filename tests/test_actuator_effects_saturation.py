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
