"""bench/faults.py's smoke run: its cheapest parts end to end (a FakeRobot process on 127.0.0.1, peers of the
bench's own): 200 malformed commands and one takeover attempt, none applied."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent.parent / "bench" / "faults.py"
KEYS = {"takeover_commands_applied", "fuzz_applied", "stale_replayed_applied", "creep_over_velocity_limit",
        "nan_encoder_robot_alive", "hold_latency_kill_ms_max", "hold_latency_hang_ms_max", "trip_drop_mrad_max",
        "realtime_torque_runs_completed_under_load_fraction"}


def test_quick_fuzz_and_takeover_apply_nothing():
    out = subprocess.run([sys.executable, str(BENCH), "--json", "--quick", "--only", "fuzz,takeover"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert KEYS <= set(r) and set(r["targets"]) == KEYS and set(r["met"]) == KEYS
    d = r["details"]
    assert d["fuzz_counted"] == d["fuzz_sent"] == 200  # every malformed command reached the robot and was counted
    assert r["fuzz_applied"] == 0 and r["met"]["fuzz_applied"] is True
    assert d["fuzz_valid_command_then_applied"] == 1  # the channel works: a valid command is applied
    run = d["takeover_runs"]["loopback"]
    reached = run["reached_robot_not_claimer"] + sum(run["robot_rejected"].values()) + run["robot_stale"]
    assert run["claim_attempt"].startswith("refused") and run["attacker_puts"] > 0 and reached > 0
    assert r["takeover_commands_applied"] == 0 and run["commands_accepted"] == run["controller_commands"]
    assert r["stale_replayed_applied"] is None and r["met"]["hold_latency_kill_ms_max"] is None  # not run
