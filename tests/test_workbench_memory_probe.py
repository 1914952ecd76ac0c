"""The memory probe's candidates (identification/workbench/probes.py, verdict.py): a state no term models is named
as pre-sliding friction hysteresis or a dead band crossed freely, with what their effects did."""

import numpy as np
from support.friction_state import dahl_euler
from support.synthetic import K_TAU, K_V

from servotau.actuator import builtin_effects
from servotau.identification.workbench import diagnose, load_dataset, parse_spec
from servotau.identification.workbench.probes import memory_candidates
from servotau.identification.workbench.verdict import Candidate


def _hysteresis_log(x0=2e-3, c=3e-4, amp=0.1, seconds=8.0):
    """Slow back-and-forth motion (strokes of about 50 mrad) with a Dahl friction of pre-sliding length ``x0`` [rad]
    (fine-step Euler of its ODE) and Coulomb level ``c`` [rad], 1 urad of encoder noise."""
    rng = np.random.default_rng(0)
    dt = 1e-3
    t = np.arange(int(seconds / dt)) * dt
    dq = amp * (np.sin(2 * np.pi * 0.4 * t) + 0.5 * np.sin(2 * np.pi * 0.92 * t + 1.0))
    q = 0.5 + np.cumsum(dq) * dt
    tau = 30 * np.sin(2 * np.pi * 0.23 * t + 1.0) + 8 * np.sin(2 * np.pi * 0.71 * t)
    y = K_TAU * tau + K_V * dq + c * dahl_euler(dq, dt, x0)
    return {"t": t, "q": q + 1e-6 * rng.standard_normal(len(t)), "q_des": q + y, "tau": tau, "dq": dq,
            "segment": np.floor(t / (seconds / 4))}


def test_hidden_hysteresis_without_dahl_and_lugre_names_pre_sliding_friction():
    """With the friction effects of the library but dahl and lugre, a hidden Dahl friction is unexplained: the
    residual's own past predicts it, and the verdict names pre-sliding friction hysteresis, not tried; with dahl
    and lugre in the library, dahl is named."""
    ds = load_dataset(_hysteresis_log())
    spec = parse_spec("coulomb", ds.signals)
    friction = [e.name for e in builtin_effects() if e.family == "velocity" and e.name not in ("dahl", "lugre")]
    d = diagnose(ds, spec, effects=friction)
    assert d.verdict == "unexplained" and d.probes["memory"] > 0.5, d.message
    assert "pre-sliding friction hysteresis (dahl/lugre: not in the library tested)" in d.message, d.message
    assert "dead band" in d.message
    d2 = diagnose(ds, spec, effects=[*friction, "dahl", "lugre"])
    assert d2.verdict == "missing_effect" and d2.top.effect in ("dahl", "lugre"), d2.message
    assert d2.top.heldout_gain > 0.5, d2.top.heldout_gain  # 0.79 measured (x0 between two grid values)


def test_the_candidates_say_how_much_their_effects_removed_or_why_untested():
    """Tried effects with their held-out gain, untestable ones with the reason."""
    def cand(name, gain, testable=True, reason=None):
        return Candidate(name, gain, 0.0, 0.0, (), True, {}, 0.0, False, testable, reason, "velocity")

    ranking = [cand("dahl", 0.04), cand("lugre", float("nan"), False, "only 0 velocity reversals: expected >= 2")]
    text = memory_candidates(ranking, 0.1)
    assert text[0] == ("pre-sliding friction hysteresis (dahl tried, removes 4 %; lugre untestable: only 0 velocity "
                       "reversals: expected >= 2; 10 % names an effect)")
    assert text[1].startswith("a dead band crossed freely") and "deadzone: not in the library tested" in text[1]
