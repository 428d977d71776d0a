"""The suite runs on two workers (pytest-xdist): the README's test command and CI's (.ci/run,
which runs it verbatim) are the same line, the worker plugin comes with the `test` extra, and
the modules kept on one worker (tests/conftest.py) are still there to keep."""

import re
from pathlib import Path
from types import SimpleNamespace

from conftest import FIRST_UNITS, WALL_CLOCK_MODULES, unit_of

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


def test_the_test_extra_brings_the_worker_plugin_and_the_units_keep_their_order():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert any(r.startswith("pytest-xdist") for r in
               project["project"]["optional-dependencies"]["test"])
    # With loadscope's reorder, xdist would sort the units by size, not keep conftest's order.
    addopts = project["tool"]["pytest"]["ini_options"]["addopts"]
    assert "--no-loadscope-reorder" in addopts, addopts


def test_every_module_named_exists():
    present = {p.name for p in TESTS.rglob("test_*.py")}
    assert WALL_CLOCK_MODULES <= present, WALL_CLOCK_MODULES - present
    for unit in FIRST_UNITS:
        assert unit == "wall_clock" or (REPO / unit).is_file(), unit


def test_each_module_is_one_unit_of_work_and_the_wall_clock_modules_one_together():
    assert unit_of("tests/cli/test_cli.py::test_a[x::y]") == "tests/cli/test_cli.py"
    assert unit_of("tests/runs/test_realtime_run.py::test_b") == "wall_clock"
    assert unit_of("tests/emulator/test_lockstep.py::test_c") == "wall_clock"
    # The scheduler xdist gets from conftest (the hook it calls) splits by these units.
    import conftest

    options = {"dist": "load", "tx": ["2*popen"], "loadscopereorder": False}
    config = SimpleNamespace(getvalue=options.__getitem__, option=SimpleNamespace(**options))
    scheduler = conftest.pytest_xdist_make_scheduler(config, None)
    for nodeid in ("tests/cli/test_cli.py::test_a", "tests/runs/test_realtime_run.py::test_b"):
        assert scheduler._split_scope(nodeid) == unit_of(nodeid)
