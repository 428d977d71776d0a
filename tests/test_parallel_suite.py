"""The suite runs on two workers (pytest-xdist): the README's test command and CI's (.ci/run,
which runs it verbatim) are the same line, the worker plugin comes with the `test` extra, and
the modules kept on one worker (tests/conftest.py) are still there to keep."""

import re
from pathlib import Path

from conftest import FIRST_UNITS, WALL_CLOCK_MODULES

try:
    import tomllib
except ImportError:  # Python 3.10
    import pytest

    tomllib = pytest.importorskip("tomli")

REPO = Path(__file__).resolve().parent.parent
TESTS = REPO / "tests"


def _readme_test_command() -> str:
    lines = [l for l in (REPO / "README.md").read_text().splitlines()
             if l.startswith("python3 -m venv") and "pytest" in l]
    assert len(lines) == 1, lines
    return lines[0]


def test_ci_runs_the_readme_s_test_command_verbatim():
    command = _readme_test_command()
    ci = [l for l in (REPO / ".ci" / "run").read_text().splitlines()
          if not l.startswith("#") and "pytest" in l]
    assert ci == [command], (ci, command)
    assert re.search(r"pytest -q -n 2\b", command), command


def test_the_test_extra_brings_the_worker_plugin_and_groups_stay_together():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert any(r.startswith("pytest-xdist") for r in
               project["project"]["optional-dependencies"]["test"])
    # Without loadgroup, xdist ignores the xdist_group marks conftest gives every test; with
    # loadscope's reorder, it would not keep conftest's order of the groups.
    addopts = project["tool"]["pytest"]["ini_options"]["addopts"]
    assert "--dist loadgroup" in addopts and "--no-loadscope-reorder" in addopts, addopts


def test_every_module_named_exists():
    present = {p.name for p in TESTS.rglob("test_*.py")}
    assert WALL_CLOCK_MODULES <= present, WALL_CLOCK_MODULES - present
    for unit in FIRST_UNITS:
        assert unit == "wall_clock" or (REPO / unit).is_file(), unit
