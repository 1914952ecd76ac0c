"""Full runs of the paper's experiments (`make experiments`): outputs under runs/experiments, docs/results.md.

The targets are the paper's claims; a failing assertion is a result to report, not a test to relax.
"""

from pathlib import Path

import pytest

from servotau import experiments as ex

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


def test_motion_torque_control_at_k6_1_beats_position_control_on_every_joint(summaries):
    """Paper 5.3: K6 = 1 has a lower mean and max error than the position servo on every right-leg joint."""
    passes = summaries["motion"]["beats_position"]["K6=1"]
    failing = {j: v for j, v in passes.items() if not (v["mean"] and v["max"])}
    assert not failing, failing


def test_motion_k6_quarter_beats_position_control_on_every_joint(summaries):
    """Beyond the paper, with the improved motor model: K6 = 0.25 runs without a trip and has a lower mean and max
    error than the position servo on every right-leg joint."""
    m = summaries["motion"]
    assert not m["tripped"]["K6=0.25"], m["tripped"]["K6=0.25"]
    failing = {j: v for j, v in m["beats_position"]["K6=0.25"].items() if not (v["mean"] and v["max"])}
    assert not failing, failing


def test_motion_k6_tenth_matches_position_control_on_mean_error(summaries):
    """Beyond the paper, with the improved motor model (hip roll by least squares) and the position integral at
    rest: K6 = 0.1 runs without a trip and its RMS error is not above the position servo's on any right-leg joint.
    Without the integral hip yaw stays above it (column 'K6=0.1 k_iq=0', docs/control.md)."""
    m = summaries["motion"]
    assert not m["tripped"]["K6=0.1"], m["tripped"]["K6=0.1"]
    failing = {j: v for j, v in m["beats_position"]["K6=0.1"].items() if not v["mean"]}
    assert not failing, failing


def test_force_apex_error_is_within_five_percent(summaries):
    """Paper 5.4: the f_z apex overshoots by at most 5 % of the amplitude (paper ~10 %), undershoot counted too, at
    every apex after the first period."""
    m = summaries["force"]["metrics"]["measured"]
    assert m is not None, summaries["force"]["tripped"]
    assert abs(m["apex_error_pct"]) <= 5.0, m


def test_components_match_the_papers_findings_in_motion(summaries):
    """Paper 5.5: ff_friction dominates motion control (majority of joints)."""
    counts = summaries["components"]["findings_joint_counts"]
    assert all(n >= 4 for n in counts["motion: ff_friction dominates"].values()), counts


def test_components_match_the_papers_findings_in_force(summaries):
    """Paper 5.5: ff_torque dominates force control (majority of joints)."""
    counts = summaries["components"]["findings_joint_counts"]
    assert counts["force: ff_torque dominates"]["force"] >= 4, counts
