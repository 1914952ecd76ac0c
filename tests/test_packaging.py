"""The wheel: config and robot model inside; installed in a fresh venv it runs from an empty folder.

The wheel is built from a copy of the package's folders (only what pyproject.toml maps) without build isolation,
so nothing is downloaded and no stale build output of the checkout gets in. The fresh venv has no pip and no
servotau of its own until the wheel is installed; it borrows the dependencies (numpy, mujoco, ...) from the
test's venv: its folders on sys.path, listed in a .pth file (a folder listed there is not itself scanned for
.pth files, so the checkout's editable install stays out).
"""

import os
import shutil
import subprocess
import sys
import sysconfig
import time
import tomllib
import zipfile
from pathlib import Path

import pytest

from servotau.config import CONFIG_DIR, REPO_ROOT

PYPROJECT = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())


def _source_tree(dest: Path) -> Path:
    """A copy of what the wheel is built from: pyproject.toml, README.md, LICENSE and the mapped folders."""
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(REPO_ROOT / name, dest / name)
    folders = set(PYPROJECT["tool"]["setuptools"]["package-dir"].values())
    for folder in folders:
        shutil.copytree(REPO_ROOT / folder, dest / folder, ignore=shutil.ignore_patterns("__pycache__"))
    return dest


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    src = _source_tree(tmp_path_factory.mktemp("src"))
    out = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
                           "--wheel-dir", str(out), str(src)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (whl,) = out.glob("servotau-*.whl")
    return whl


def test_the_wheel_holds_the_config_the_model_the_license_and_the_typing_marker(wheel):
    """Every default config file (toml, csv; motors/, scenarios/, tasks/), the robot model, py.typed, LICENSE and the
    servotau console script are in the wheel."""
    names = set(zipfile.ZipFile(wheel).namelist())
    config = sorted(p.relative_to(CONFIG_DIR) for pattern in ("*.toml", "*.csv") for p in CONFIG_DIR.rglob(pattern))
    assert config and Path("motors/example.toml") in config
    missing = [str(p) for p in config if f"servotau/defaults/{p.as_posix()}" not in names]
    assert not missing, missing
    for name in ("servotau/description/hrp2.xml", "servotau/py.typed", "servotau/defaults/__init__.py",
                 "servotau/cli.py", "servotau/hal/robot/cli.py"):
        assert name in names, name
    dist_info = {n.split("/", 1)[1] for n in names if n.startswith("servotau-") and ".dist-info/" in n}
    assert "licenses/LICENSE" in dist_info
    entry_points = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    assert "servotau = servotau.cli:main" in entry_points


@pytest.mark.slow
def test_the_installed_wheel_runs_the_demo_and_the_workbench_from_an_empty_folder(wheel, tmp_path):
    """pip installs the wheel into a fresh venv; from an empty folder `servotau --version`, `config init`, `demo`
    (robot and controller processes, 2 s swing) and the workbench (`model simulate`, `model compare`) run, reading
    the packaged config (the wall time of install + demo is printed)."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    fresh_site = Path(subprocess.run([str(venv / "bin" / "python"), "-c",
                                      "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                     capture_output=True, text=True, check=True).stdout.strip())
    borrowed = [p for p in sys.path if p and Path(p).is_dir() and Path(p).resolve().is_relative_to(Path(sys.prefix))]
    assert sysconfig.get_paths()["purelib"] in borrowed
    (fresh_site / "borrowed_dependencies.pth").write_text("".join(f"{p}\n" for p in borrowed))
    start = time.monotonic()
    subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "--no-deps",
                    "--no-index", "--quiet", str(wheel)], check=True, timeout=300)
    installed = time.monotonic() - start
    work = tmp_path / "empty"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}

    def run(*argv: str, timeout: float = 300) -> subprocess.CompletedProcess:
        proc = subprocess.run([str(venv / "bin" / "servotau"), *argv], cwd=work, env=env, capture_output=True,
                              text=True, timeout=timeout)
        assert proc.returncode == 0, (argv, proc.stdout[-2000:], proc.stderr[-3000:])
        return proc

    where = subprocess.run([str(venv / "bin" / "python"), "-c", "import servotau.config as c; print(c.CONFIG_DIR)"],
                           cwd=work, env=env, capture_output=True, text=True, check=True).stdout.strip()
    assert Path(where) == fresh_site / "servotau" / "defaults"
    assert run("--version").stdout.startswith("servotau ")
    demo_start = time.monotonic()
    demo = run("demo", "--out", "demo", "--duration", "2.0", "--mode", "position")
    demo_seconds = time.monotonic() - demo_start
    assert "[demo] done" in demo.stdout and (work / "demo" / "log.parquet").is_file()
    assert f"config: read {fresh_site / 'servotau' / 'defaults' / 'control.toml'} (packaged default)" in demo.stderr
    run("model", "simulate", "sim.parquet", "--cycles", "2", "--quiet")
    assert "k_v" in run("model", "compare", "sim.parquet", "--json").stdout
    run("config", "init", "cfg")
    assert (work / "cfg" / "control.toml").is_file()
    print(f"\nwheel install {installed:.1f} s, demo from an empty folder {demo_seconds:.1f} s (wall)")
