"""Full runs of the paper's experiments (`make experiments`): outputs under runs/experiments, docs/results.md.

The targets are the paper's claims; a failing assertion is a result to report, not a test to relax.
"""

from pathlib import Path

import pytest

from servotau.control import experiments as ex

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "runs" / "experiments"
DOC = ROOT / "docs" / "results.md"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def summaries():
    """Every experiment, full length, then the regenerated docs/results.md."""
    out = {name: run(OUT) for name, run in ex.EXPERIMENTS.items()}
    ex.write_results(OUT, DOC)
    return out


def test_results_document_is_regenerated(summaries):
    """docs/results.md is written from the full runs (no quick run, no missing section)."""
    text = DOC.read_text()
    assert "Not run." not in text and "QUICK" not in text


@pytest.mark.xfail(strict=True, reason="measured with the motor model refitted on estimated torques (2026-11-24): "
                   "K6 = 1 "
                   "beats position control on every joint but hip yaw (RMS 0.484 vs 0.471 mrad, max 0.5533 vs 0.5528): "
                   "its model is the paper's (the workbench's effects raised its held-out error), without the servo's "
                   "dead band (0.43 mrad of command), which the position feedback then carries as a static error. The "
                   "dead-band feedforward ('K6=1 dead band') passes (hip yaw 0.082 / 0.148 mrad); so does the paper's "
                   "model of `servotau identify fit` ('K6=1 paper model', 0.469 / 0.544 mrad). The 2026-11-22 model, "
                   "fitted on the simulator's true torques, passed (0.437 / 0.509)")
def test_motion_torque_control_at_k6_1_beats_position_control_on_every_joint(summaries):
    """Paper 5.3: K6 = 1 has a lower mean and max error than the position servo on every right-leg joint."""
    passes = summaries["motion"]["beats_position"]["K6=1"]
    failing = {j: v for j, v in passes.items() if not (v["mean"] and v["max"])}
    assert not failing, failing


@pytest.mark.xfail(strict=True, reason="measured: with k7 = 0.001 s / sqrt(K6) (config k7_scaling) K6 = 0.25 runs "
                   "without a trip and beats position control on every joint but hip yaw (RMS 1.86 vs 0.471 mrad, max "
                   "2.08 vs 0.553: the servo's dead band, 0.43 mrad of command, over K6) and the ankle roll's max "
                   "(3.86 vs 2.09 mrad; RMS 1.11 vs 1.17). The dead-band feedforward (motors/hrp2_sim_deadband.toml, "
                   "'K6=0.25 dead band') fixes hip yaw (0.315 / 0.464 mrad) but misses ankle roll (1.70 / 4.67 mrad) "
                   "and makes the force task unstable, so it is not the default")
def test_motion_k6_quarter_beats_position_control_on_every_joint(summaries):
    """Beyond the paper, with the improved motor model: K6 = 0.25 runs without a trip and has a lower mean and max
    error than the position servo on every right-leg joint."""
    m = summaries["motion"]
    assert not m["tripped"]["K6=0.25"], m["tripped"]["K6=0.25"]
    failing = {j: v for j, v in m["beats_position"]["K6=0.25"].items() if not (v["mean"] and v["max"])}
    assert not failing, failing


@pytest.mark.xfail(strict=True, reason="measured: K6 = 0.1 (k7 = 0.0032 s) is above position control on hip yaw, "
                   "hip roll, ankle pitch and ankle roll (RMS 3.20, 1.11, 5.35, 2.16 vs 0.471, 0.721, 4.00, 1.17 "
                   "mrad): model error over K6; with the dead-band feedforward ('K6=0.1 dead band', not the default: "
                   "it destabilises the force task) hip yaw and hip roll stay above (0.737 and 0.738 vs 0.471 and "
                   "0.721 mrad)")
def test_motion_k6_tenth_matches_position_control_on_mean_error(summaries):
    """Beyond the paper, with the improved motor model: K6 = 0.1 runs without a trip and its RMS error is not
    above the position servo's on any right-leg joint."""
    m = summaries["motion"]
    assert not m["tripped"]["K6=0.1"], m["tripped"]["K6=0.1"]
    failing = {j: v for j, v in m["beats_position"]["K6=0.1"].items() if not v["mean"]}
    assert not failing, failing


@pytest.mark.xfail(strict=True, reason="measured with the motor model refitted on estimated torques (2026-11-24): apex "
                   "error -7.2 % (undershoot; apexes -7.2, -11.2 %; true sole force -6.8 %), amplitude 1.06, delay "
                   "32 ms, f_z RMS error 7.7 N. The 2026-11-22 model, fitted on the simulator's true torques, gave "
                   "+4.0 % (7 ms)")
def test_force_apex_error_is_within_five_percent(summaries):
    """Paper 5.4: the f_z apex overshoots by at most 5 % of the amplitude (paper ~10 %), undershoot counted too."""
    m = summaries["force"]["metrics"]["measured"]
    assert m is not None, summaries["force"]["tripped"]
    assert abs(m["overshoot_pct"]) <= 5.0, m


def test_components_match_the_papers_findings(summaries):
    """Paper 5.5: ff_friction dominates motion control, ff_torque dominates force control (majority of joints)."""
    counts = summaries["components"]["findings_joint_counts"]
    assert all(n >= 4 for n in counts["motion: ff_friction dominates"].values()), counts
    assert counts["force: ff_torque dominates"]["force"] >= 4, counts
