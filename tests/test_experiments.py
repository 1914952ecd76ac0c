"""Smoke tests of the paper's experiments (servotau/experiments/): short runs, every output written."""

import csv
import json

import numpy as np
import pytest

from servotau.cli import main as cli_main
from servotau.description import JOINT_NAMES, MODEL_PATH
from servotau.experiments import common, components, estimation, force, motion
from servotau.experiments.report import write_results
from servotau.hal.types import RobotInfo


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """Quick motion runs (position, K6 = 1, 0.1) and a 2-period force run, then every experiment's outputs."""
    out = tmp_path_factory.mktemp("experiments")
    runs = motion.motion_runs(quick=True, out=out)
    force_run = force.force_run(quick=True, out=out)
    summaries = {
        "motion": motion.run_motion(out, quick=True, runs=runs),
        "force": force.run_force(out, quick=True, run=force_run),
        "components": components.run_components(out, quick=True, runs={"motion K6=1": runs["K6=1"],
                                                                        "motion K6=0.1": runs["K6=0.1"],
                                                                        "force": force_run}),
        "estimation": estimation.run_estimation(out, quick=True, run=runs["K6=1"]),
    }
    doc = write_results(out, out / "results.md")
    return out, summaries, doc


@pytest.mark.slow  # the quick experiments fixture: 12 s (the CLI test below runs one in the default suite)
def test_motion_writes_tables_and_figure_with_finite_errors(outputs):
    """The motion experiment writes the mean/max tables (CSV, Markdown), Fig. 4 and finite per-joint errors."""
    out, s, _ = outputs
    m = s["motion"]
    assert m["controllers"] == ["position", "K6=1", "K6=0.1"]
    for name in ("motion_mean_mrad.csv", "motion_mean_mrad.md", "motion_max_mrad.csv", "fig4_motion_errors.png"):
        assert (out / "motion" / name).stat().st_size > 0
    for name in m["controllers"]:
        assert np.all(np.isfinite(m["mean_mrad"][name])) and len(m["mean_mrad"][name]) == 6
        assert np.all(np.asarray(m["max_mrad"][name]) >= np.asarray(m["mean_mrad"][name]))
    assert json.loads((out / "motion" / "summary.json").read_text())["controllers"] == m["controllers"]


@pytest.mark.slow  # the quick experiments fixture: 12 s (the CLI test below runs one in the default suite)
def test_force_reports_overshoot_coupling_and_delay(outputs):
    """The force experiment tracks a sinusoid on f_z without a trip and reports its metrics for both sources."""
    out, s, _ = outputs
    f = s["force"]
    assert f["tripped"] is None
    for source in ("measured", "true"):
        metrics = f["metrics"][source]
        for key in ("overshoot_pct", "apex_error_pct", "trough_error_pct", "coupling_x_pct", "coupling_y_pct",
                    "delay_ms", "amplitude_ratio"):
            assert np.isfinite(metrics[key]), (source, key)
    assert abs(f["metrics"]["measured"]["delay_ms"]) <= 200.0
    assert (out / "force" / "fig5_force_tracking.png").stat().st_size > 0


@pytest.mark.slow  # the quick experiments fixture: 12 s (the CLI test below runs one in the default suite)
def test_component_shares_sum_to_one_hundred_percent(outputs):
    """The six paper components' RMS shares sum to 100 % on every joint of every run."""
    out, s, _ = outputs
    for name, shares in s["components"]["shares_pct"].items():
        total = sum(np.asarray(shares[c]) for c in common.PAPER_COMPONENTS)
        np.testing.assert_allclose(total, 100.0, rtol=1e-9, err_msg=name)
    assert (out / "components" / "fig6_components.png").stat().st_size > 0


@pytest.mark.slow  # the quick experiments fixture: 12 s (the CLI test below runs one in the default suite)
def test_estimation_error_is_small_relative_to_the_peak(outputs):
    """The estimated torques of the motion run are finite, with an RMS error below the peak torque per joint."""
    _, s, _ = outputs
    rms, peak = np.asarray(s["estimation"]["rms_Nm"]), np.asarray(s["estimation"]["peak_Nm"])
    assert np.all(np.isfinite(rms)) and np.all(rms < peak)


@pytest.mark.slow  # the quick experiments fixture: 12 s (the CLI test below runs one in the default suite)
def test_identification_table_compares_the_motor_files_with_the_servo(outputs):
    """The estimation experiment tabulates the motor files' k_tau against the simulator's 1/kp: the knee's servo
    (config/servo.toml, kp = 19608 N m/rad) appears, and the default file's k_tau is within 25 % of it."""
    out, s, doc = outputs
    table = s["estimation"]["identification"]
    assert "## Identification against the simulator's servo" in doc and table in doc
    rows = list(csv.reader((out / "estimation" / "identification_vs_servo.csv").open()))
    knee = dict(zip(rows[0], next(r for r in rows if r[0] == "knee"), strict=True))
    assert float(knee["1/kp"]) == pytest.approx(1.0 / 19608.0)
    assert abs(float(knee["k_tau default"]) * 19608.0 - 1.0) < 0.25


@pytest.mark.slow  # the quick experiments fixture: 12 s (the CLI test below runs one in the default suite)
def test_results_document_has_every_section_and_the_paper_tables(outputs):
    """The generated results document covers the four experiments and quotes the paper's Tables 2 and 3."""
    _, _, doc = outputs
    for title in ("## Motion control", "## Force control", "## Control components", "## Torque estimation"):
        assert title in doc
    assert "Not run." not in doc
    assert "61.86" in doc and "0.115" in doc  # position control knee, Tables 3 and 2


def test_cli_runs_an_experiment_and_writes_the_document(tmp_path, capsys):
    """`servotau experiment estimation --quick` exits 0, prints its table and writes the document."""
    doc = tmp_path / "results.md"
    code = cli_main(["experiment", "estimation", "--quick", "--out", str(tmp_path / "runs"), "--doc", str(doc)])
    assert code == 0
    assert "RMS / peak" in capsys.readouterr().out
    text = doc.read_text()
    assert "## Torque estimation" in text and "Not run." in text  # the others were not run in this directory


def test_force_metrics_report_the_worst_apex_and_the_troughs():
    """On a synthetic run: overshoot is the largest apex error, apex_error the one of largest magnitude (an
    undershoot counts), trough_error the same at the negative apexes; the first period is not evaluated."""
    dt, period, a = 1e-3, 1.0 / force.FORCE_FREQUENCY, force.FORCE_AMPLITUDE
    run = common.Run("synthetic")
    apex_scale = {1: 0.90, 2: 1.02}  # positive half-waves of periods 1 and 2: -10 %, +2 % of A
    trough_scale = {1: 0.80, 2: 0.95}  # negative half-waves: the force stays 20 %, 5 % of A above the minimum
    for k in range(int(round(3 * period / dt))):
        t = k * dt
        s = np.sin(2 * np.pi * force.FORCE_FREQUENCY * t)
        p = int(t // period)
        scale = (apex_scale if s >= 0 else trough_scale).get(p, 1.0)
        run.time.append(t)
        run.f_ref.append(np.array([0.0, 0.0, 300.0 + a * s]))
        run.f_hat.append(np.array([0.0, 0.0, 300.0 + scale * a * s]))
    m = force.force_metrics(run)
    np.testing.assert_allclose(m["apex_overshoots_pct"], [-10.0, 2.0], atol=1e-6)
    assert m["overshoot_pct"] == pytest.approx(2.0, abs=1e-6)
    assert m["apex_error_pct"] == pytest.approx(-10.0, abs=1e-6)
    np.testing.assert_allclose(m["trough_errors_pct"], [20.0, 5.0], atol=1e-6)
    assert m["trough_error_pct"] == pytest.approx(20.0, abs=1e-6)


def test_control_config_overrides_change_one_setting_each():
    """The experiments' config overrides: K6 on every torque joint, k_iq = 0 switches the position integral off
    (the 'k_iq=0' runs), a k7 is a constant velocity gain (the 'k7=' runs: the same K7 at every K6), force axes
    add the force task; without them the shipped integral stays on."""
    info = RobotInfo("test-robot", JOINT_NAMES, -np.full(30, 3.0), np.full(30, 3.0), 1e-3, str(MODEL_PATH))
    shipped = common.control_config(info, 0.1, ())
    off = common.control_config(info, 0.1, common.FORCE_AXES, k_iq=0.0)
    assert shipped.joint_vector("k_iq")[:6].min() > 0 and shipped.force is None
    assert not off.joint_vector("k_iq").any() and off.force.axes == common.FORCE_AXES
    np.testing.assert_allclose(off.joint_vector("k_s"), shipped.joint_vector("k_s"))
    k_s_at_1 = common.control_config(info, 1.0, ()).joint_vector("k_s")
    np.testing.assert_allclose(k_s_at_1, 10.0 * shipped.joint_vector("k_s"))
    def k7(cfg):  # K7 = k_tau (1 + k_p) k_d [s] per torque joint (k_p may follow the margin schedule)
        return np.array([m.k_tau * (1 + cfg.gains[j].k_p) * cfg.gains[j].k_d for j, m in cfg.motors.items()])

    constant = k7(common.control_config(info, 0.1, (), k7=0.006))
    np.testing.assert_allclose(constant, 0.006)
    np.testing.assert_allclose(k7(common.control_config(info, 1.0, (), k7=0.006)), 0.006)
    assert not np.allclose(constant, k7(shipped))
