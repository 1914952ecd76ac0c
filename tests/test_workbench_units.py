"""Units follow the target's role (identification/workbench/units.py): text, JSON, HTML and Rerun."""

import json

import numpy as np
import pytest
from support.synthetic import cogging_truth, friction_recording, synthetic_table

from servotau.cli import main
from servotau.identification.data import write_table
from servotau.identification.workbench.data import load_dataset
from servotau.identification.workbench.units import unit_for, unit_of


def _friction_table(path, column="friction", scale=1.0):
    """A friction torque [N m] against velocity: Coulomb-viscous plus noise, 0.2 N m off zero."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 20.0, 0.004)
    v = 0.5 * np.sin(2 * np.pi * 0.25 * t) + 0.2 * np.sin(2 * np.pi * 0.9 * t)
    f = 0.2 + 1.5 * np.tanh(v / 0.01) + 3.0 * v + 0.02 * rng.standard_normal(t.size)
    return write_table({"t": t, "v": v, column: scale * f}, path)


def _friction_args(path, column="friction"):
    return [str(path), "--map", "time=t", "--map", "velocity=v", "--map", f"target={column}", "--base", "coulomb"]


@pytest.mark.parametrize(("si", "rms", "symbol", "scale"), [
    ("rad", 1e-4, "urad", 1e6), ("rad", 0.5, "mrad", 1e3), ("N m", 0.3, "mN m", 1e3), ("Nm", 2.0, "N m", 1.0),
    ("A", 2.0, "A", 1.0), ("", 2.0, "?", 1.0)])
def test_prefix_follows_the_unit_and_the_size(si, rms, symbol, scale):
    u = unit_for(si, rms, "q", "q")
    assert (u.symbol, u.scale) == (symbol, scale)


def test_unit_follows_the_role(tmp_path):
    """A servo log: rad (urad); a friction column: N m; another column: the table's unit, or --unit."""
    log = write_table(synthetic_table(cogging_truth, seconds=2.0), tmp_path / "servo.parquet")
    u = unit_of(load_dataset(log))
    assert (u.si, u.symbol, u.name) == ("rad", "urad", "dq_err")
    roles = {"time": "t", "velocity": "v", "target": "friction"}
    ds = load_dataset(_friction_table(tmp_path / "f.csv"), roles=roles)
    assert (unit_of(ds).si, unit_of(ds).symbol, unit_of(ds).quantity) == ("N m", "N m", "torque")
    ds = load_dataset(_friction_table(tmp_path / "g.csv", "y", scale=1e-3), roles={**roles, "target": "y"})
    assert (unit_of(ds).si, unit_of(ds).symbol) == ("?", "?")
    assert (unit_of(ds, "N m").si, unit_of(ds, "N m").symbol) == ("N m", "mN m")
    assert unit_of(ds, "A").symbol == "A"


def test_friction_table_is_shown_in_newton_metres(capsys, tmp_path):
    """Text, JSON and the HTML report of a friction table say N m, never urad."""
    path = _friction_table(tmp_path / "f.csv")
    assert main(["model", "compare", *_friction_args(path), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "N m" in text and "urad" not in text
    assert main(["model", "diagnose", *_friction_args(path), "--json", "--quiet", "--report",
                 str(tmp_path / "rep")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["unit"]["si"] == "N m" and out["unit"]["symbol"] == "N m" and out["unit"]["quantity"] == "torque"
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "RMS [N m]" in page and "urad" not in page


def test_unit_option_names_the_unit_of_another_target(capsys, tmp_path):
    """--unit: a target whose column name says nothing is shown in the user's unit."""
    path = _friction_table(tmp_path / "g.csv", "y")
    assert main(["model", "diagnose", *_friction_args(path, "y"), "--unit", "A", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert " A " in text and "urad" not in text


def test_servo_log_stays_in_microradians(capsys, tmp_path):
    """A servo log: the text and the JSON say urad / rad, as before."""
    log = write_table(synthetic_table(cogging_truth, seconds=4.0), tmp_path / "servo.parquet")
    assert main(["model", "diagnose", str(log), "--base", "coulomb", "--quiet"]) == 0
    assert "urad" in capsys.readouterr().out
    assert main(["model", "diagnose", str(log), "--base", "coulomb", "--quiet", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["unit"] == {"quantity": "servo error", "name": "dq_err", "si": "rad",
                                                           "symbol": "urad", "scale": 1e6}


def test_offset_term_stands_for_the_mean_off_zero(capsys, tmp_path):
    """A friction table 0.2 N m off zero: with the offset (default for a non-servo target) the base holds it
    and coulomb_asym is not added to stand in for it; --offset off leaves it to the effects."""
    path = _friction_table(tmp_path / "f.csv")
    assert main(["model", "diagnose", *_friction_args(path), "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert "offset" in out["model"] and out["coefficients"]["offset"] == pytest.approx(0.2, abs=0.02)
    assert out["verdict"] == "no_missing_effect"  # coulomb_asym first, but gains nothing (measured -0.0 %)
    assert main(["model", "diagnose", *_friction_args(path), "--offset", "off", "--json", "--quiet"]) == 0
    off = json.loads(capsys.readouterr().out)
    assert "offset" not in off["model"] and off["ranking"][0]["effect"] == "coulomb_asym"
    assert out["heldout"]["rms"] < 0.5 * off["heldout"]["rms"]


@pytest.mark.slow  # 15 s: the asymmetric loss over the whole library (least squares: the tests above)
def test_offset_with_the_asymmetric_loss_and_off_on_servo_logs(capsys, tmp_path):
    """The asymmetric loss fits the offset too; a servo log has none by default (its results unchanged)."""
    path = _friction_table(tmp_path / "f.csv")
    assert main(["model", "compare", *_friction_args(path), "--loss", "asymmetric", "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["coefficients"]["offset"] == pytest.approx(0.2, abs=0.05)
    log = write_table(synthetic_table(cogging_truth, seconds=4.0), tmp_path / "servo.parquet")
    assert main(["model", "compare", str(log), "--base", "coulomb", "--json", "--quiet"]) == 0
    assert "offset" not in json.loads(capsys.readouterr().out)["coefficients"]


def _friction_recordings(tmp_path, k=3):
    """``k`` friction recordings of the same joint (different noise seeds and velocity profiles)."""
    return [write_table(friction_recording(i, seconds=8.0, f0=0.2), tmp_path / f"rec{i}.csv") for i in range(k)]


def test_several_recordings_are_held_out_one_by_one(capsys, tmp_path):
    """model diagnose a.csv b.csv c.csv: one segment per recording, the held-out blocks are the recordings."""
    from servotau.identification.workbench.recordings import combine

    paths = _friction_recordings(tmp_path)
    roles = {"time": "t", "velocity": "v", "target": "friction"}
    ds = combine([load_dataset(p, roles=roles) for p in paths])
    assert ds.n == 3 * 2000 and list(np.unique(ds.segment)) == [0.0, 1.0, 2.0]
    assert np.all(np.diff(ds.time) > 0)  # time continues across recordings
    argv = [*map(str, paths), "--map", "time=t", "--map", "velocity=v", "--map", "target=friction", "--base",
            "coulomb", "--json", "--quiet"]
    assert main(["model", "diagnose", *argv]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["data"]["n"] == 6000 and "3 recordings" in out["data"]["notes"][0]
    assert out["heldout"]["fit_percent"] > 95.0 and out["verdict"] == "no_missing_effect"


def test_a_model_fitted_on_some_recordings_is_scored_on_another(capsys, tmp_path):
    """--test LOG: the final model, fitted on the other recordings, scored on it (no refit); the report's table
    has its row."""
    a, b, c = _friction_recordings(tmp_path)
    assert main(["model", "add", str(a), str(b), "--test", str(c), "--map", "time=t", "--map", "velocity=v",
                 "--map", "target=friction", "--base", "coulomb", "--json", "--quiet", "--report",
                 str(tmp_path / "report")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["test"]["source"].endswith("rec2.csv") and out["test"]["n"] == 2000
    assert out["test"]["rms"] < 0.03 and out["test"]["model"] == out["model"]
    page = (tmp_path / "report" / "index.html").read_text()
    assert f"{out['model']} (test: {out['test']['source']}, not fitted on it)" in page
    assert main(["model", "compare", str(a), "--test", str(c), "--map", "time=t", "--map", "velocity=v",
                 "--map", "target=friction", "--quiet"]) == 0
    assert "test " in capsys.readouterr().out
    bad = write_table({"t": np.arange(0.0, 8.0, 0.008), "v": np.sin(np.arange(1000.0)), "friction": np.ones(1000)},
                      tmp_path / "slow.csv")
    assert main(["model", "diagnose", str(a), str(bad), "--map", "time=t", "--map", "velocity=v",
                 "--map", "target=friction", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "slow.csv: sample period 8 ms differs from" in err and "'s 4 ms: expected recordings at the same rate" in err
