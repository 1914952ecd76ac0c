"""Layers: the identification library loads neither the simulator, nor the wire, nor the applications."""

import json
import subprocess
import sys

import pytest

# Top-level modules and servotau packages, each loaded or not (a fresh interpreter per check).
_LOADED = """
import importlib, json, pkgutil, sys
for name in sys.argv[2:]:
    module = importlib.import_module(name)
    if sys.argv[1] == "walk":
        for info in pkgutil.iter_modules(module.__path__, name + "."):
            importlib.import_module(info.name)
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in ("mujoco", "zenoh")
                        or m.startswith(("servotau.simrobot", "servotau.control", "servotau.apps")))))
"""


def loaded(mode: str, *modules: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", _LOADED, mode, *modules], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return {m.split(".")[0] if m.split(".")[0] in ("mujoco", "zenoh") else m for m in json.loads(out.stdout)}


@pytest.mark.parametrize("package", ["servotau.identification", "servotau.identification.workbench"])
def test_identification_packages_load_neither_mujoco_nor_zenoh_nor_the_simulator(package):
    """`import servotau.identification[.workbench]` leaves mujoco, zenoh and servotau.simrobot unloaded."""
    mods = loaded("import", package)
    assert not mods & {"mujoco", "zenoh"}, sorted(mods)
    assert not any(m.startswith("servotau.simrobot") for m in mods), sorted(mods)


def test_every_identification_module_is_free_of_the_simulator_and_the_applications():
    """Each module of servotau.identification and its workbench imports without mujoco, servotau.simrobot,
    servotau.control or servotau.apps (zenoh is not checked here: identification.collect reads hal.types,
    which loads the hal package)."""
    mods = loaded("walk", "servotau.identification", "servotau.identification.workbench")
    assert "mujoco" not in mods, sorted(mods)
    assert not [m for m in mods if m.startswith(("servotau.simrobot", "servotau.control", "servotau.apps"))], \
        sorted(mods)
