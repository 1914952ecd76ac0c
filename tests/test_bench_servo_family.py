"""bench/servo_family.py end to end on one draw (slow: a 104 s identification and four motion runs)."""

import json
import subprocess
import sys

import pytest

from servotau.config import REPO_ROOT

pytestmark = pytest.mark.slow


def test_one_draw_prints_one_json_object_with_the_scores(tmp_path):
    doc = tmp_path / "results.md"
    doc.write_text("# Results\n")
    p = subprocess.run([sys.executable, str(REPO_ROOT / "bench" / "servo_family.py"), "--json", "--tuning", "1",
                        "--held-out", "0", "--k6", "1", "--max-steps", "1", "--out", str(tmp_path / "fam"),
                        "--doc", str(doc)], capture_output=True, text=True, timeout=1800, cwd=REPO_ROOT)
    assert p.returncode == 0, p.stderr
    result = json.loads(p.stdout)
    s = result["parts"]["tuning"]["K6=1"]
    assert s["cases"] == 12 and 0 <= s["wins"] <= 12
    row = result["draws"]["tuning"][0]
    assert set(row["max_mrad"]) == {"position", "K6=1"} and len(row["choices"]) == 6
    assert "## Torque control on a family of servos" in doc.read_text()
