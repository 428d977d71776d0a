"""A non-editable install works: build a wheel, install it into a fresh virtual environment and
run `cdpm` from a directory outside the source tree (issue 10, point 1).

Offline and fast: the wheel is built without build isolation and installed without its
dependencies; the fresh environment then reaches the test environment's packages (drake,
numpy, ...) through a .pth line, which does not process the test environment's own .pth files,
so its editable install of cdpm_drake stays invisible.
"""

import importlib.metadata
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(the fresh venv's bin directory, the wheel) with the package installed from a wheel."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, src / name)
    shutil.copytree(REPO / "cdpm_drake", src / "cdpm_drake",
                    ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    dist = tmp / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps",
                    "--no-build-isolation", "-w", str(dist), str(src)],
                   check=True, capture_output=True, text=True, timeout=120)
    (wheel,) = dist.glob("cdpm_drake-*.whl")
    venv = tmp / "venv"
    bin_dir = venv / ("Scripts" if os.name == "nt" else "bin")
    # Installed before the fresh venv can see the test environment (its pip would otherwise
    # find the editable cdpm_drake there and uninstall it): by this pip into that venv
    # (--python, pip >= 22.3: seconds), or by the venv's own pip (ensurepip: slower).
    pip_version = tuple(int(x) for x in importlib.metadata.version("pip").split(".")[:2])
    if pip_version >= (22, 3):
        subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True,
                       timeout=120)
        installer = [sys.executable, "-m", "pip", "--python", str(bin_dir / "python")]
    else:
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
        installer = [str(bin_dir / "python"), "-m", "pip"]
    subprocess.run(installer + ["install", "-q", "--no-deps", "--no-index", str(wheel)],
                   check=True, capture_output=True, text=True, timeout=120)
    purelib = subprocess.run(
        [str(bin_dir / "python"), "-c",
         "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True, capture_output=True, text=True).stdout.strip()
    Path(purelib, "outer_env.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return bin_dir, wheel


def test_the_wheel_ships_the_built_in_robots_and_scenarios(installed):
    _, wheel = installed
    names = zipfile.ZipFile(wheel).namelist()
    for shipped in ("cdpm_drake/data/robots/paper_7cable.yaml",
                    "cdpm_drake/data/robots/cube_8cable.yaml",
                    "cdpm_drake/data/scenarios/exp2_interaction.yaml",
                    "cdpm_drake/data/sweeps/exp2_du_Fu.yaml"):
        assert shipped in names, names


def test_a_wheel_install_simulates_from_another_directory(installed, tmp_path):
    bin_dir, _ = installed
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    where = subprocess.run([str(bin_dir / "python"), "-c",
                            "import cdpm_drake; print(cdpm_drake.__file__)"], cwd=tmp_path,
                           env=env, check=True, capture_output=True, text=True).stdout
    # The installed copy, not the source tree's.
    assert str(REPO / "cdpm_drake") not in where and str(bin_dir.parent) in where, where
    info = subprocess.run([str(bin_dir / "cdpm"), "info"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)
    assert info.returncode == 0, info.stderr
    assert "robot 'paper_7cable'" in info.stdout and "7 cables" in info.stdout
    sim = subprocess.run([str(bin_dir / "cdpm"), "simulate", "--duration", "0.1",
                          "--no-progress"], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=120)
    assert sim.returncode == 0, sim.stderr
    # 0.1 s at 500 Hz: ticks 0..50.
    assert "51 ticks" in sim.stdout, sim.stdout
    assert (tmp_path / "runs" / "exp2_interaction" / "latest" / "log.npz").is_file()
