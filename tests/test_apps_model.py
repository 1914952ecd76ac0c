"""Tests of ``servotau model compare|diagnose|add`` (servotau/apps/model.py), report and Rerun."""

import json

import numpy as np
import pytest
from support.synthetic import cogging_truth, friction_recording, synthetic_table

from servotau.cli import main
from servotau.identification import MotorParameters
from servotau.identification.data import write_table


@pytest.fixture(scope="module")
def cogging_log(tmp_path_factory):
    return write_table(synthetic_table(cogging_truth, seconds=6.0), tmp_path_factory.mktemp("logs") / "cog.parquet")


def run_json(capsys, argv):
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out), err


def test_diagnose_json_is_one_object_with_verdict_and_ranking(capsys, cogging_log):
    """--json prints exactly one JSON object: verdict, shortlist, ranking entries with effect and heldout_gain."""
    out, err = run_json(capsys, ["model", "diagnose", str(cogging_log), "--base", "coulomb", "--json"])
    assert out["verdict"] == "missing_effect" and out["ranking"][0]["effect"] == "cogging"
    assert out["shortlist"][0] == "cogging" and len(out["shortlist"]) <= 2  # the first two effects to add
    assert all({"effect", "heldout_gain"} <= set(r) for r in out["ranking"])
    assert out["ranking"][0]["heldout_gain"] > 0.8 and "[" in err and "cogging" in err  # progress on stderr


def test_add_prints_the_ladder_and_saves_the_motor_model(capsys, cogging_log, tmp_path):
    """add --json: a ladder of models with held-out RMS falling; --save writes a loadable motor file."""
    path = tmp_path / "motors.toml"
    out, _ = run_json(capsys, ["model", "add", str(cogging_log), "--base", "coulomb", "--json", "--save", str(path),
                               "--quiet"])
    ladder = out["ladder"]
    assert [r["added"] for r in ladder] == [None, "cogging"] and out["verdict"] == "no_missing_effect"
    assert ladder[1]["heldout_rms"] < 0.2 * ladder[0]["heldout_rms"] and all("model" in r for r in ladder)
    m = MotorParameters.load_toml(path)["joint"]
    assert "cogging" in m.extra and m.extra["cogging"].shape["period"] == pytest.approx(0.08)
    assert m.provenance.endswith("; tau: tau") and out["rejected"] == []  # the table's own torque column


def test_add_named_effect_with_the_asymmetric_loss(capsys, cogging_log):
    """--effect adds that effect (same loss: asymmetric); unknown effect names fail cleanly."""
    out, _ = run_json(capsys, ["model", "add", str(cogging_log), "--base", "coulomb", "--effect", "cogging",
                               "--loss", "asymmetric", "--w", "10", "--effects", "stribeck,cogging,deadzone",
                               "--json", "--quiet"])
    assert out["ladder"][-1]["added"] == "cogging" and "asymmetric" in out["loss"]
    assert main(["model", "add", str(cogging_log), "--effect", "cogs", "--quiet"]) == 2
    assert "unknown effect(s) ['cogs']" in capsys.readouterr().err


def test_compare_writes_the_html_report_and_a_rerun_recording(capsys, cogging_log, tmp_path):
    """compare --report DIR --rerun save:FILE: an HTML page with its PNG plots, and an .rrd file."""
    rrd = tmp_path / "wb.rrd"
    out, _ = run_json(capsys, ["model", "compare", str(cogging_log), "--base", "coulomb", "--report",
                               str(tmp_path / "rep"), "--rerun", f"save:{rrd}", "--json", "--quiet"])
    html = (tmp_path / "rep" / "index.html").read_text()
    for png in ("timeseries", "residual_velocity", "residual_torque", "residual_position", "residual_time",
                "heatmap", "correlation", "ranking"):
        assert (tmp_path / "rep" / f"{png}.png").stat().st_size > 1000 and f"{png}.png" in html
    assert rrd.stat().st_size > 10_000
    assert out["heldout"]["fit_percent"] < out["train"]["fit_percent"] + 1.0 and "verdict" in out


def test_compare_a_saved_model_file(capsys, cogging_log, tmp_path):
    """compare --model evaluates a motor-parameter file as it is (no refit, nothing held out)."""
    path = tmp_path / "m.toml"
    run_json(capsys, ["model", "add", str(cogging_log), "--base", "coulomb", "--effect", "cogging", "--save",
                      str(path), "--json", "--quiet"])
    out, _ = run_json(capsys, ["model", "compare", str(cogging_log), "--model", str(path), "--json", "--quiet"])
    assert out["heldout"] is None and out["train"]["fit_percent"] > 99.0


def test_plugin_effect_and_column_mapping(capsys, tmp_path):
    """--plugin registers a user effect; --map brings a table with other column names."""
    cols = synthetic_table(lambda t, q, dq, tau: 3e-4 * np.exp(-(((tau - 12.0) / 3.0) ** 2)), seconds=6.0)
    log = write_table({"time": cols["t"], "angle": cols["q"], "cmd": cols["q_des"], "torque": cols["tau"]},
                      tmp_path / "other.csv")
    plugin = tmp_path / "bump.py"
    plugin.write_text(
        "import numpy as np\n"
        "from servotau.identification.workbench import register_effect\n"
        "register_effect('bump', lambda s, c: np.exp(-((s['tau'] - c) / 3.0) ** 2),"
        " grid=[{'c': 6.0}, {'c': 12.0}], signals=('tau',), family='torque', replace=True)\n"
    )
    out, _ = run_json(capsys, ["model", "diagnose", str(log), "--map", "time=time", "--map", "position=angle",
                               "--map", "command=cmd", "--map", "torque=torque", "--plugin", str(plugin),
                               "--base", "coulomb", "--json", "--quiet"])
    assert out["ranking"][0]["effect"] == "bump" and out["ranking"][0]["shape"] == {"c": 12.0}
    from servotau.identification.workbench import unregister_effect

    unregister_effect("bump")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--map", "torque=force"], "column 'force' (role torque): not in the table"),
        (["--map", "torque"], "--map 'torque': expected ROLE=COLUMN"),
        (["--base", "coulomb+magic"], "unknown effect 'magic'"),
        (["--effects", "cogging,magic"], "--effects: unknown effect(s) ['magic']"),
        (["--folds", "1"], "--folds 1: expected 2 to 100"),
        (["--folds", "1000"], "--folds 1000: expected 2 to 100"),
        (["--rerun", "save:{log}"], "expected save:FILE.rrd"),
        (["--rerun", "save:/nonexistent/x.rrd"], "folder /nonexistent does not exist"),
        (["--report", "{log}"], "is a file: expected a folder"),
        (["--plugin", "/nonexistent.py"], "--plugin /nonexistent.py: file not found"),
        (["--rerun", "nowhere"], "--rerun 'nowhere': expected save:FILE"),
        (["--map", "torque=tau", "--map", "torque=q"], "role torque is already mapped to column 'tau'"),
        (["--smooth-torque", "-0.01"], "--smooth-torque -0.01: expected a window >= 0 s"),
        (["--smooth-torque", "inf"], "--smooth-torque inf: expected a window >= 0 s"),
        (["--align-torque", "-1"], "--align-torque -1.0: expected a search range >= 0 s"),
        (["--align-torque", "nan"], "--align-torque nan: expected a search range >= 0 s"),
        (["--test", "{log}"], "cog.parquet: the same file as log "),
        (["--unit", "mrad"], "--unit mrad: the target of"),
    ],
)
def test_bad_input_is_a_clean_error(capsys, cogging_log, argv, message):
    """Bad options and columns end with exit code 2 and a message naming the field, never a traceback; no output
    replaces the log (``{log}``: the input's own path)."""
    before = cogging_log.read_bytes()
    argv = [a.format(log=cogging_log) for a in argv]
    assert main(["model", "diagnose", str(cogging_log), "--quiet", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert cogging_log.read_bytes() == before


def test_the_same_recording_twice_is_refused(capsys, cogging_log):
    """Two names of one file would count as two recordings, one held out against its own copy."""
    assert main(["model", "diagnose", str(cogging_log), str(cogging_log.parent / ".." / cogging_log.parent.name
                                                              / cogging_log.name), "--quiet"]) == 2
    assert f"the same file as log {cogging_log}: expected each recording once" in capsys.readouterr().err


@pytest.mark.parametrize(("argv", "message"), [
    (["--save", "{log}"], "is an input of this command: expected another file"),
    (["--save", "{tmp}/missing/m.toml"], "missing does not exist: expected an existing folder"),
    (["--max-steps", "0"], "--max-steps 0: expected at least 1"),
])
def test_add_refuses_bad_outputs_before_fitting(capsys, cogging_log, tmp_path, argv, message):
    before = cogging_log.read_bytes()
    argv = [a.format(log=cogging_log, tmp=tmp_path) for a in argv]
    assert main(["model", "add", str(cogging_log), "--quiet", *argv]) == 2
    assert message in capsys.readouterr().err
    assert cogging_log.read_bytes() == before and not (tmp_path / "missing").exists()


def test_missing_column_and_nan_rows(capsys, tmp_path):
    """A table without q_des is refused naming it; NaN rows are dropped and counted in the JSON."""
    cols = synthetic_table(seconds=3.0)
    bad = write_table({k: v for k, v in cols.items() if k != "q_des"}, tmp_path / "bad.csv")
    assert main(["model", "compare", str(bad), "--quiet"]) == 2
    assert "missing column(s) ['q_des']" in capsys.readouterr().err
    cols["tau"][[5, 50, 500]] = np.nan
    nan = write_table(cols, tmp_path / "nan.parquet")
    out, _ = run_json(capsys, ["model", "diagnose", str(nan), "--base", "coulomb", "--json", "--quiet",
                               "--effects", "cogging"])
    assert out["data"]["dropped_rows"] == 3 and "dropped 3 of 3000 rows" in out["data"]["notes"][0]


def test_a_joint_that_never_moved_is_cannot_tell_with_its_fit_shown_as_not_available(capsys, tmp_path):
    """q and q_des constant (the servo error is zero everywhere, its fit percentage undefined): the diagnosis
    says it cannot tell, and the text output prints the fit as n/a."""
    cols = synthetic_table(seconds=3.0)
    cols.pop("dq")
    cols["q"] = cols["q_des"] = np.full_like(cols["q"], 0.1)
    path = write_table(cols, tmp_path / "still.csv")
    assert main(["model", "diagnose", str(path), "--quiet", "--effects", "coulomb,delay"]) == 0
    out = capsys.readouterr().out
    assert "fit n/a" in out and "verdict: cannot_tell: cannot tell which effect: the position never changes" in out


def _friction_csvs(tmp_path, k=3):
    """``k`` recordings of one joint's friction torque [N m] = 0.2 + 1.5 sign(v) + 3 v + noise (no torque)."""
    return [str(write_table(friction_recording(i, seconds=4.0, f0=0.25), tmp_path / f"rec{i}.csv")) for i in range(k)]


FRICTION = ["--map", "time=t", "--map", "velocity=v", "--map", "target=friction", "--base", "coulomb", "--json",
            "--quiet"]


def test_a_friction_model_fitted_on_two_files_is_saved_and_scored_on_a_third(capsys, tmp_path):
    """add a.csv b.csv --save m.toml (held out: each recording from the other), then compare c.csv --model m.toml:
    the model (k_v + offset + coulomb, no k_tau) is scored on c without refitting; on a servo log it is refused
    (naming both targets) unless --any-target."""
    a, b, c = _friction_csvs(tmp_path)
    saved = tmp_path / "m.toml"
    out, _ = run_json(capsys, ["model", "add", a, b, *FRICTION, "--effects", "stribeck", "--save", str(saved)])
    assert out["data"]["heldout_blocks"] == ["segment 0", "segment 1"] and out["heldout"]["rms"] < 0.03
    assert out["saved"] == {"file": str(saved), "joint": "joint", "target": "torque", "unit": "N m"}
    m = MotorParameters.load_toml(saved)["joint"]
    assert (m.k_tau, m.target, m.unit) == (None, "torque", "N m") and m.offset == pytest.approx(0.2, abs=0.01)
    out, _ = run_json(capsys, ["model", "compare", c, *FRICTION, "--model", str(saved)])
    assert out["given"]["target"] == "torque" and out["model"] == "k_v + offset + coulomb"
    assert out["train"]["rms"] < 0.03 and out["coefficients"]["offset"] == pytest.approx(m.offset, rel=1e-5)
    servo = str(write_table(synthetic_table(seconds=2.0), tmp_path / "servo.csv"))
    assert main(["model", "compare", servo, "--model", str(saved), "--quiet"]) == 2
    assert (f"--model {saved} [joint] predicts torque [N m], {servo}'s target is servo error [rad]"
            in capsys.readouterr().err)
    out, _ = run_json(capsys, ["model", "compare", servo, "--model", str(saved), "--any-target", "--json",
                               "--quiet"])
    assert out["unit"]["si"] == "rad" and out["given"]["unit"] == "N m"


def test_a_servo_model_without_k_tau_is_saved_and_reloaded(capsys, tmp_path):
    """--base k_v+coulomb on a servo log with a torque column: the model has no k_tau, the file none either;
    compare --model reads it back and predicts the same; naming k_tau on a table without torque is refused."""
    log = str(write_table(synthetic_table(seconds=3.0), tmp_path / "servo.csv"))
    saved = tmp_path / "s.toml"
    out, _ = run_json(capsys, ["model", "add", log, "--base", "k_v+coulomb", "--effect", "coulomb_asym",
                               "--effects", "stribeck", "--save", str(saved), "--json", "--quiet"])
    assert out["model"] == "k_v + coulomb + coulomb_asym" and "k_tau" not in out["coefficients"]
    m = MotorParameters.load_toml(saved)["joint"]
    assert m.k_tau is None and m.is_servo_error and "k_tau" not in saved.read_text().split("version")[1]
    again, _ = run_json(capsys, ["model", "compare", log, "--model", str(saved), "--json", "--quiet"])
    assert again["model"] == out["model"] and again["train"]["rms"] == pytest.approx(out["train"]["rms"], rel=1e-6)
    a, *_ = _friction_csvs(tmp_path, 1)
    assert main(["model", "compare", a, "--map", "time=t", "--map", "velocity=v", "--map", "target=friction",
                 "--base", "k_tau+coulomb", "--quiet"]) == 2
    assert "['k_tau'] named, but the log has no torque" in capsys.readouterr().err


def test_simulate_refuses_an_unknown_output_format_before_simulating(capsys, tmp_path, monkeypatch):
    from servotau.apps import simlog

    def no_simulation(*args, **kwargs):
        raise AssertionError("simulated before the output was checked")

    monkeypatch.setattr(simlog, "simulate_log", no_simulation)
    assert main(["model", "simulate", str(tmp_path / "x.txt"), "--quiet"]) == 2
    assert "unknown format '.txt': expected .parquet or .csv" in capsys.readouterr().err


def test_the_torque_smoothing_can_be_given_or_turned_off(capsys, tmp_path):
    """--smooth-torque S: the torque's window is the one given (0: not smoothed) instead of the one chosen by
    cross-validation, and the notes say which (the window chosen for a Coulomb plant's torque noise blurred its
    reversals in a black-box trial, with no way to change it)."""
    log = str(write_table(synthetic_table(seconds=3.0), tmp_path / "servo.csv"))
    base = ["model", "compare", log, "--json", "--quiet"]
    notes = {}
    for option in ([], ["--smooth-torque", "0.021"], ["--smooth-torque", "0"]):
        out, _ = run_json(capsys, base + option)
        notes[tuple(option)] = [n for n in out["data"]["notes"] if n.startswith("tau:")]
    assert "chosen by cross-validation" in notes[()][0]
    assert notes[("--smooth-torque", "0.021")] == [
        "tau: centred Savitzky-Golay smoothing (21 samples = 21 ms, order 2, no delay, given)"]
    assert notes[("--smooth-torque", "0")] == []
