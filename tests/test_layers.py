"""Layers at run time, and the size of the modules.

Who imports whom (the layers, no cycles, no simulator or Zenoh in the libraries) is checked statically by the
import contracts in pyproject.toml ([tool.importlinter], run by .ci/lint-imports in `make test`). What a static
graph cannot show is checked here, in fresh interpreters: what importing a library loads at run time (its
package's lazy attributes, the effects the actuator registry finds, anything imported through importlib).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

# Loaded by no library: the simulator, MuJoCo, the Rerun viewer and the applications; Zenoh only by the HAL
# modules that talk it (the contracts name the same three).
HEAVY = ("zenoh", "mujoco", "rerun", "servotau.simrobot", "servotau.apps", "servotau.cli")
ZENOH_MODULES = ("servotau.hal.wire.session", "servotau.hal.backends.zenoh", "servotau.hal.robot.server",
                 "servotau.hal.robot.cli")
LIBRARIES = ("servotau.signal", "servotau.description", "servotau.actuator", "servotau.hal", "servotau.estimation",
             "servotau.control", "servotau.identification")
# Imports each module named on the command line, then prints which HEAVY modules that import added.
_LOADED = """
import importlib, json, sys
heavy = tuple(json.loads(sys.argv[1]))
def loaded():  # a third-party package by its top-level name, a servotau module by its full name
    return {m if m.startswith("servotau.") else m.split(".")[0]
            for m in sys.modules if any(m == h or m.startswith(h + ".") for h in heavy)}
out = {}
for name in sys.argv[2:]:
    before = loaded()
    importlib.import_module(name)
    out[name] = sorted(loaded() - before)
print(json.dumps(out))
"""

# Every module of the given packages, sub-packages included (a package's __main__ runs a program: not imported).
_WALK = """
import importlib, json, pkgutil, sys
names = []
for package in sys.argv[1:]:
    names.append(package)
    for info in pkgutil.walk_packages(importlib.import_module(package).__path__, package + "."):
        if info.name.rsplit(".", 1)[-1] != "__main__":
            names.append(info.name)
print(json.dumps(names))
"""


def _run(code: str, *args: str) -> object:
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout)


def _heavy_loaded_by(*modules: str) -> dict[str, list[str]]:
    """For each module, imported in turn in one fresh interpreter, the HEAVY modules its import added."""
    return _run(_LOADED, json.dumps(HEAVY), *modules)


@pytest.mark.parametrize("module", ["servotau.hal.types", "servotau.hal", *LIBRARIES[:3], *LIBRARIES[4:],
                                    "servotau.identification.workbench"])
def test_import_loads_neither_zenoh_nor_mujoco_nor_the_simulator(module):
    """A controller for a real robot needs neither the simulator nor (until it opens a backend) Zenoh:
    ``import`` of a library leaves zenoh, mujoco, rerun, servotau.simrobot and the applications unloaded."""
    assert _heavy_loaded_by(module) == {module: []}


def test_every_library_module_loads_neither_the_simulator_nor_the_applications():
    """Each module of each library, imported in turn, adds none of HEAVY (Zenoh: but for the HAL's three
    Zenoh modules, imported last so that they hide no other module's import of it)."""
    names = [n for n in _run(_WALK, *LIBRARIES)]
    assert "servotau.actuator.effects.coulomb" in names and "servotau.hal.wire.protocol" in names
    names = [n for n in names if n not in ZENOH_MODULES] + list(ZENOH_MODULES)
    bad = {m: heavy for m, heavy in _heavy_loaded_by(*names).items()
           if [h for h in heavy if not (h == "zenoh" and m in ZENOH_MODULES)]}
    assert bad == {}


def test_importing_the_libraries_leaves_scipy_signal_unloaded():
    """Importing scipy.signal takes about a second (half of a controller's start): the libraries import it only
    inside the functions that filter a whole recording (centred filters, the first-order lag, a task's lag check),
    so that a process which filters causally, such as the controller, never loads it."""
    code = "import importlib, json, sys\nfor n in sys.argv[1:]: importlib.import_module(n)\n" \
           "print(json.dumps('scipy.signal' in sys.modules))"
    assert _run(code, *LIBRARIES, "servotau.control.tasks", "servotau.identification.workbench") is False


# -- module size ---------------------------------------------------------------------------------------------
MAX_LINES = 500

def _package_folders() -> list[Path]:
    package_dir = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    return [REPO / folder for folder in sorted(set(package_dir.values()))]


def test_no_module_is_over_500_lines():
    """Every module of the packages holds at most MAX_LINES lines (pink, mink and upkie keep modules short)."""
    folders = _package_folders()
    assert REPO / "hal" in folders and REPO / "servotau" in folders
    lengths = {str(p.relative_to(REPO)): len(p.read_text().splitlines())
               for folder in folders for p in sorted(folder.rglob("*.py"))}
    assert len(lengths) > 100
    too_long = {p: n for p, n in lengths.items() if n > MAX_LINES}
    assert too_long == {}
