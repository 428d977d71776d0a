"""Shared test helpers: robot files written from Python data, and paths to test data."""

import copy
import json
import math
from pathlib import Path

import pytest

DATA_DIR = Path(__file__).resolve().parent / "data"
HAND_ROBOT = DATA_DIR / "robots" / "hand_4cable.yaml"
SHIPPED_ROBOTS = ("paper_7cable", "cube_8cable")

# A small valid robot as Python data; tests break one thing in a copy and write it out.
_VALID_SPEC = {
    "name": "tetra_4cable",
    "reels": [[0.0, 0.0, 3.0], [4.0, 0.0, 3.0], [4.0, 3.0, 3.0], [2.0, 1.5, 0.0]],
    "attachments": [[-0.1, -0.1, 0.1], [0.1, -0.1, 0.1], [0.1, 0.1, 0.1], [0.0, 0.0, -0.1]],
    "workspace": {"lower": [1.0, 0.5, 0.5], "upper": [3.0, 2.5, 2.5]},
}


def to_yaml(value, indent: int = 0) -> str:
    """YAML text for dicts, lists, numbers and strings; NaN and infinities in YAML spelling
    (.nan, .inf), which json.dumps cannot write."""
    pad = "  " * indent
    if isinstance(value, dict):
        lines = []
        for k, v in value.items():
            if isinstance(v, dict):
                lines.append(f"{pad}{k}:\n{to_yaml(v, indent + 1)}")
            else:
                lines.append(f"{pad}{k}: {_flow(v)}")
        return "\n".join(lines)
    return pad + _flow(value)


def _flow(v) -> str:
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_flow(c) for c in v) + "]"
    if isinstance(v, float) and not math.isfinite(v):
        return ".nan" if math.isnan(v) else (".inf" if v > 0 else "-.inf")
    return json.dumps(v)


@pytest.fixture
def valid_spec():
    """A fresh deep copy of a valid 4-cable robot description (Python data)."""
    return copy.deepcopy(_VALID_SPEC)


@pytest.fixture
def write_robot(tmp_path):
    """write_robot(spec_or_text, name="robot.yaml") -> Path of a robot file in tmp_path."""

    def write(spec, name: str = "robot.yaml") -> Path:
        path = tmp_path / name
        path.write_text(spec if isinstance(spec, str) else to_yaml(spec) + "\n")
        return path

    return write


def case_registry(cases: dict):
    """A `covers(*keys)` decorator that registers the keys a test checks in `cases` ({key:
    test name}), refusing a key registered twice (the wiring walks then find every key's
    case)."""

    def covers(*keys):
        def mark(fn):
            for key in keys:
                assert key not in cases, f"{key} registered twice"
                cases[key] = fn.__name__
            return fn

        return mark

    return covers


def highs_t_star(W, w):
    """The independent statics reference: t* = max t s.t. W T + w = 0, T_i >= t (all free),
    by scipy's linprog (HiGHS). +inf where t is unbounded (an internal force exists), -inf
    where no T balances w at all."""
    import numpy as np
    from scipy.optimize import linprog

    m = W.shape[1]
    res = linprog(np.r_[np.zeros(m), -1.0], A_ub=np.hstack([-np.eye(m), np.ones((m, 1))]),
                  b_ub=np.zeros(m), A_eq=np.hstack([W, np.zeros((W.shape[0], 1))]), b_eq=-w,
                  bounds=[(None, None)] * (m + 1), method="highs")
    if res.status == 3:
        return np.inf
    if res.status == 2:
        return -np.inf
    assert res.status == 0, res.message
    return -res.fun


def highs_margin(W, w, floor, ceiling):
    """kappa = max s s.t. W T + w = 0, floor + s <= T_i <= ceiling - s, by HiGHS (-inf when
    infeasible for every s)."""
    return highs_margin_distribution(W, w, floor, ceiling)[0]


def highs_margin_distribution(W, w, floor, ceiling):
    """(kappa, T): `highs_margin` and the tensions HiGHS attains it with ((-inf, None) when
    infeasible for every s)."""
    import numpy as np
    from scipy.optimize import linprog

    m = W.shape[1]
    A_ub = np.vstack([np.hstack([-np.eye(m), np.ones((m, 1))]),
                      np.hstack([np.eye(m), np.ones((m, 1))])])
    b_ub = np.r_[-floor * np.ones(m), ceiling * np.ones(m)]
    res = linprog(np.r_[np.zeros(m), -1.0], A_ub=A_ub, b_ub=b_ub,
                  A_eq=np.hstack([W, np.zeros((W.shape[0], 1))]), b_eq=-w,
                  bounds=[(None, None)] * (m + 1), method="highs")
    return (-res.fun, res.x[:m]) if res.status == 0 else (-np.inf, None)


def default_signals():
    """For a child process, before exec: SIGINT and SIGTERM at their defaults. A pytest
    started in the background by a shell without job control has SIGINT ignored; its children
    would inherit that and (as Unix programs do) keep ignoring Ctrl-C."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


# The suite runs on two workers (pytest-xdist, `-n 2` in the README's command): each module is
# one unit of work (the scheduler below), so its module-scoped fixtures (a wheel's fresh
# install, shared simulations) are made once, not once per worker. These modules run a
# controller against an emulator on the wall clock (two processes each, some under
# SCHED_FIFO) or load every core on purpose (test_lockstep's CPU hogs): they are one unit, so
# no two of them share the host's two cores at once; the other worker's tests are the host
# load they already allow for (stalls, repeated attempts).
WALL_CLOCK_MODULES = frozenset({
    "test_canopen_run.py", "test_emulator_tensions.py", "test_lockstep.py",
    "test_canopen_independent.py", "test_realtime_run.py", "test_soak_script.py"})
# On the workers, units that take minutes go first (--no-loadscope-reorder keeps it), the
# rest by their number of tests, most first: the two workers then end close together. The
# wall-clock unit starts third, once the first kernels of a fresh clone are compiled.
FIRST_UNITS = ("tests/test_wheel_install.py", "tests/scripts/test_interference_scripts.py",
               "wall_clock")


def unit_of(nodeid: str) -> str:
    """The unit of work a test belongs to: its module's path, or "wall_clock"."""
    path = nodeid.split("::", 1)[0]
    return "wall_clock" if path.rsplit("/", 1)[-1] in WALL_CLOCK_MODULES else path


def pytest_collection_modifyitems(config, items):
    import os

    if not os.environ.get("PYTEST_XDIST_WORKER"):  # one process: the files' own order
        return
    units = {}
    for item in items:
        units.setdefault(unit_of(item.nodeid), []).append(item)
    order = sorted(units, key=lambda u: (FIRST_UNITS.index(u) if u in FIRST_UNITS
                                         else len(FIRST_UNITS), -len(units[u])))
    items[:] = [item for unit in order for item in units[unit]]


# xdist's own loadgroup cannot be used: it renames node ids through an attribute pytest 9 no
# longer reads, so its xdist_group marks group nothing. A file scheduler with our units does.
@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    if config.getvalue("dist") not in ("load", "loadfile"):
        return None  # --dist each, worksteal, ...: as asked
    from xdist.scheduler import LoadFileScheduling

    class ModuleUnits(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return unit_of(nodeid)

    return ModuleUnits(config, log)


@pytest.fixture(autouse=True)
def _logging_as_it_was():
    """A script called in-process that quiets the logging (logging.disable) must not silence
    the tests after it on the same worker (the CLI's `warning:` lines are asserted)."""
    import logging

    before = logging.root.manager.disable
    yield
    logging.disable(before)
