"""servotau control after a safety trip (exit code 3, log closed) and servotau ctl, the operator's commands over
Zenoh (loopback, a FakeRobot server; the controller's side of the query served on the backend's session)."""

from __future__ import annotations

import json
import threading

import pytest
from support.hal import endpoint, free_port, robot_server

from servotau.apps import ctl
from servotau.apps.control import main as control_main
from servotau.apps.control import serve_operator
from servotau.cli import build_parser
from servotau.control.operator import OperatorChannel
from servotau.hal import LogReader, ZenohBackend
from servotau.hal.log import parts_dir


def test_a_trip_holds_then_releases_with_code_3_and_a_closed_log(tmp_path, capsys):
    """servotau control in process: the injected trip is printed once with the operator's commands; the hold
    answers every frame for --hold-timeout of robot time; then exit code 3, the log closed with every tick."""
    log = tmp_path / "ctl.parquet"
    args = build_parser("control").parse_args(
        ["control", "--backend", "inprocess", "--duration", "3.0", "--trip-at", "0.02", "--hold-timeout", "0.2",
         "--log", str(log)])
    assert control_main(args) == 3
    out, err = capsys.readouterr()
    assert out.count("SAFETY TRIP") == 1 and "[command_error] RLEG_JOINT3" in out
    assert "releasing by itself after 0.2 s" in out and "released after --hold-timeout" in err
    assert log.exists() and not parts_dir(log).exists()
    t = LogReader(log).columns["t"]
    assert len(t) == 500 + 20 + 200 + 1  # settle, until the trip, the hold, the tripping tick


@pytest.fixture
def served(tmp_path):
    """A robot server, a controller backend serving the operator query, and a stand-in control loop that latches
    (state "tripped"), refuses the first reset and accepts the second, then releases."""
    port = free_port()
    with robot_server(tmp_path, port):
        backend = ZenohBackend("fake", connect=[endpoint(port)], truth=False)
        channel = OperatorChannel()
        key = serve_operator(backend, channel)
        channel.publish("tripped", "safety trip [command_error] J03")
        stop = threading.Event()
        resets = []

        def loop():
            while not stop.wait(0.002):
                p = channel.take()
                if p is None:
                    continue
                if p.action == "release":
                    channel.answer(p, True, "released")
                    channel.close("released")
                    return
                resets.append(p)
                ok = len(resets) > 1
                channel.answer(p, ok, "holding" if ok else "tripped", None if ok else "the trip condition still holds")

        t = threading.Thread(target=loop, daemon=True)
        t.start()
        try:
            yield port, key
        finally:
            stop.set()
            t.join(5.0)
            backend.close()


def _ctl(port, *argv):
    args = build_parser("ctl").parse_args(["ctl", *argv, "--robot", "fake", "--port", str(port), "--timeout", "5"])
    return ctl.main(args)


def test_ctl_status_reset_release_over_zenoh(served, capsys):
    """status, a refused reset (exit 1, the reason), an accepted one, release; the JSON answers are printed."""
    port, key = served
    assert key == "servotau/v1/fake/controller/operator" == ctl.operator_key("fake")
    codes = [_ctl(port, a) for a in ("status", "reset", "reset", "release")]
    out, err = capsys.readouterr()
    answers = [json.loads(line) for line in out.splitlines()]
    assert codes == [0, 1, 0, 0]
    assert [a["state"] for a in answers] == ["tripped", "tripped", "holding", "released"]
    assert answers[0]["report"] == "safety trip [command_error] J03"
    assert "reset refused: the trip condition still holds" in err


def test_ctl_without_an_answer_is_a_clear_error_and_the_robot_answers_its_own_reset(tmp_path, capsys):
    """No controller runs: ``ctl reset`` exits 2 naming the controller's key; ``--robot-side`` is answered by the
    robot process itself (hal/robot/operator.py) with its firmware state."""
    port = free_port()
    with robot_server(tmp_path, port):
        args = build_parser("ctl").parse_args(["ctl", "reset", "--robot", "fake", "--port", str(port),
                                               "--timeout", "0.3"])
        assert ctl.main(args) == 2
        err = capsys.readouterr().err
        assert 'no controller of robot "fake" answered servotau/v1/fake/controller/operator within 0.3 s' in err
        args = build_parser("ctl").parse_args(["ctl", "reset", "--robot-side", "--robot", "fake", "--port", str(port),
                                               "--timeout", "5"])
        code = ctl.main(args)
    out = capsys.readouterr().out
    assert code == 0 and '"state": "WAITING"' in out, out  # not latched: ok, nothing changes
    args = build_parser("ctl").parse_args(["ctl", "release", "--robot-side", "--port", "1"])
    assert ctl.main(args) == 2 and "--robot-side release: expected reset" in capsys.readouterr().err


def test_the_exit_waits_for_the_threads_the_command_started():
    """quiesce_threads joins the threads started since the snapshot (so none is in native code when the
    interpreter finalizes) and names those that outlive the timeout; older threads are left alone."""
    from servotau.apps.control import quiesce_threads

    old_stop = threading.Event()
    old = threading.Thread(target=old_stop.wait, daemon=True, name="older")
    old.start()
    before = {t.ident for t in threading.enumerate()}
    quick = threading.Thread(target=lambda: threading.Event().wait(0.05), daemon=True, name="closing")
    stuck_stop = threading.Event()
    stuck = threading.Thread(target=stuck_stop.wait, daemon=True, name="stuck")
    quick.start()
    stuck.start()
    try:
        assert quiesce_threads(before, timeout=1.0) == ["stuck"]
        assert not quick.is_alive() and old.is_alive()
    finally:
        stuck_stop.set()
        old_stop.set()


def test_ctl_switches_the_mode_and_starts_or_stops_a_task_over_zenoh(tmp_path, capsys):
    """``ctl torque``, ``ctl start TASK`` (the task travels in the request) and ``ctl stop`` reach the controller's
    channel with their arguments; ``start`` without a task, or another action with one, is bad input (exit 2)."""
    port = free_port()
    seen = []
    with robot_server(tmp_path, port):
        backend = ZenohBackend("fake", connect=[endpoint(port)], truth=False)
        channel = OperatorChannel()
        serve_operator(backend, channel)
        channel.publish("running", None, {"time": 1.5, "mode": "position"})
        stop = threading.Event()

        def loop():
            while not stop.wait(0.002):
                p = channel.take()
                if p is not None:
                    seen.append((p.action, p.args))
                    channel.answer(p, True, "stopping" if p.action == "stop" else "running")

        t = threading.Thread(target=loop, daemon=True)
        t.start()
        try:
            codes = [_ctl(port, *a) for a in (("status",), ("torque",), ("start", "swing"), ("stop",))]
        finally:
            stop.set()
            t.join(5.0)
            backend.close()
    out = capsys.readouterr().out
    assert codes == [0, 0, 0, 0]
    assert json.loads(out.splitlines()[0])["detail"] == {"time": 1.5, "mode": "position"}
    assert seen == [("torque", {}), ("start", {"task": "swing"}), ("stop", {})]
    assert _ctl(port, "start") == 2 and "expected a task: servotau ctl start TASK" in capsys.readouterr().err
    assert _ctl(port, "stop", "swing") == 2 and "only start takes a task" in capsys.readouterr().err
