"""Layers around the HAL: what each package loads on import and which packages its modules import."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
HEAVY = ("zenoh", "mujoco", "servotau.simrobot")


def _loaded(module: str) -> set[str]:
    """Which of HEAVY a fresh interpreter has loaded after ``import module``."""
    code = f"import json, sys, {module}; print(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, timeout=120)
    return set(json.loads(out.stdout))


@pytest.mark.parametrize("module", ["servotau.hal.types", "servotau.hal", "servotau.description",
                                    "servotau.estimation", "servotau.control"])
def test_import_loads_neither_zenoh_nor_mujoco_nor_the_simulator(module):
    """A controller for a real robot needs neither the simulator nor (until it opens a backend) Zenoh."""
    assert _loaded(module) == set()


def _imports(path: Path) -> set[str]:
    """Absolute names of the modules ``path`` imports (relative imports resolved against its package)."""
    package = "servotau." + ".".join(path.relative_to(REPO).with_suffix("").parts[:-1])
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""
            out.add(".".join(p for p in (base, node.module or "") if p))
    return out


# An application inside control/ (it runs the simulator), moved to the application layer by issue 17's
# control-loop part.
_APPLICATIONS: set[str] = set()


@pytest.mark.parametrize("folder,forbidden", [
    ("hal", ("servotau.simrobot", "mujoco")),
    ("description", ("servotau.simrobot", "servotau.hal", "mujoco", "zenoh")),
    ("estimation", ("servotau.simrobot", "mujoco", "zenoh")),
    ("control", ("servotau.simrobot", "mujoco", "zenoh")),
])
def test_no_module_imports_a_layer_above_it(folder, forbidden):
    """hal never imports the simulator; estimation and control import neither it, MuJoCo nor Zenoh."""
    bad = {}
    for path in sorted((REPO / folder).rglob("*.py")):
        if str(path.relative_to(REPO)) in _APPLICATIONS:
            continue
        hits = sorted(m for m in _imports(path) if any(m == f or m.startswith(f + ".") for f in forbidden))
        if hits:
            bad[str(path.relative_to(REPO))] = hits
    assert bad == {}


def test_only_the_zenoh_modules_import_zenoh():
    """Zenoh is imported by the wire session, the zenoh backend and the robot server only."""
    users = {str(p.relative_to(REPO)) for p in (REPO / "hal").rglob("*.py") if "zenoh" in _imports(p)}
    assert users == {"hal/wire/session.py", "hal/backends/zenoh.py", "hal/robot/server.py"}
