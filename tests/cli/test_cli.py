"""The `cdpm` command line: --help, `cdpm info` on built-in and user robots, errors."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdpm_drake import cli
from cdpm_drake.cli.compile_notice import (COMPILE_NOTICE, COMPILE_NOTICE_SAID,
                                           compile_notice)
from cdpm_drake.cli.listing import list_main
from cdpm_drake.kernels.kinematics import cable_lengths, jacobian
from cdpm_drake.robot import load_robot

from conftest import HAND_ROBOT

# One table row of `cdpm info`: cable number, reel [..], attachment [..], length at centre.
ROW = re.compile(r"^\s*(\d+)\s+\[([^\]]*)\]\s+\[([^\]]*)\]\s+([0-9.]+)\s*$", re.MULTILINE)


def run_info(capsys, *args):
    """cdpm info ARGS in-process: (exit code, stdout, stderr)."""
    code = cli.main(["info", *args])
    out, err = capsys.readouterr()
    return code, out, err


def cable_rows(out: str):
    """(cable numbers, reels (m, 3), attachments (m, 3), lengths (m,)) parsed from the table."""
    rows = ROW.findall(out)
    numbers = [int(r[0]) for r in rows]
    reels = np.array([[float(x) for x in r[1].split(",")] for r in rows])
    attachments = np.array([[float(x) for x in r[2].split(",")] for r in rows])
    lengths = np.array([float(r[3]) for r in rows])
    return numbers, reels, attachments, lengths


def test_help_lists_subcommands(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "usage: cdpm" in out
    assert re.search(r"^\s+info\s+print a robot description", out, re.MULTILINE), out


def test_no_subcommand_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main([])
    assert info.value.code == 2
    assert "COMMAND" in capsys.readouterr().err


@pytest.mark.parametrize("args, name", [((), "paper_7cable"), (("cube_8cable",), "cube_8cable")])
def test_info_builtin_robot(capsys, args, name):
    code, out, err = run_info(capsys, *args)
    assert code == 0, err
    robot = load_robot(name)
    m = robot.num_cables
    numbers, reels, attachments, lengths = cable_rows(out)
    # One row per cable, numbered from 1 as users count them.
    assert numbers == list(range(1, m + 1))
    np.testing.assert_allclose(reels, robot.reels, atol=5e-4)  # printed to 3 decimals
    np.testing.assert_allclose(attachments, robot.attachments, atol=5e-4)
    # Printed to 4 decimals: the lengths at the workspace centre from eq. 2.
    np.testing.assert_allclose(lengths, cable_lengths(robot, robot.workspace.center),
                               rtol=0, atol=5e-5)
    assert f"'{name}'" in out and f"{m} cables" in out
    lo, hi = robot.workspace.lower, robot.workspace.upper
    assert f"lower [{lo[0]:.3f}, {lo[1]:.3f}, {lo[2]:.3f}] m" in out
    assert f"upper [{hi[0]:.3f}, {hi[1]:.3f}, {hi[2]:.3f}] m" in out
    # Condition number of J at the centre: ratio of its extreme singular values.
    s = np.linalg.svd(jacobian(robot, robot.workspace.center), compute_uv=False)
    found = re.search(r"condition number at the centre: ([0-9.]+)", out)
    assert found, out
    assert float(found.group(1)) == pytest.approx(s[0] / s[-1], abs=5e-4)


def test_info_robot_file_by_path(capsys):
    code, out, err = run_info(capsys, str(HAND_ROBOT))
    assert code == 0, err
    numbers, _, _, lengths = cable_rows(out)
    assert numbers == [1, 2, 3, 4]
    # Worked by hand in tests/robot/test_robot.py: rho = (3,2,-6), (-2,1,-2), (-3,-2,-6), (4,-4,2).
    np.testing.assert_array_equal(lengths, [7.0, 3.0, 7.0, 6.0])
    assert str(HAND_ROBOT) in out and "'garage_4cable'" in out


def test_info_unknown_robot_exits_1_listing_builtins(capsys):
    # 1, an error (the robot cannot be loaded); 2 is kept for a malformed command line.
    code, out, err = run_info(capsys, "nonexistent")
    assert code == 1
    assert out == ""
    assert err.startswith("cdpm info: error:")
    for part in ("'nonexistent'", "paper_7cable", "cube_8cable"):
        assert part in err
    assert "Traceback" not in err


def test_info_invalid_robot_file_exits_1_naming_the_field(capsys, write_robot, valid_spec):
    valid_spec["reels"][1][2] = float("nan")
    path = write_robot(valid_spec)
    code, out, err = run_info(capsys, str(path))
    assert code == 1
    assert str(path) in err and "reels of cable 2" in err and "nan" in err


def test_installed_console_script():
    # The `cdpm` entry point installed next to this interpreter (the venv's bin/).
    exe = Path(sys.executable).parent / "cdpm"
    assert exe.is_file(), f"console script not installed at {exe}"
    done = subprocess.run([str(exe), "info", "cube_8cable"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    numbers, _, _, _ = cable_rows(done.stdout)
    assert numbers == list(range(1, 9))
    bad = subprocess.run([str(exe), "info", "nonexistent"], capture_output=True, text=True,
                         timeout=120)
    assert bad.returncode == 1 and "'nonexistent'" in bad.stderr


# --- the command line as a whole (issue 10, points 8 and 10) ----------------------------------


def test_a_wrong_flag_shows_the_subcommands_usage(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["simulate", "--bogus"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: cdpm simulate ")
    assert "cdpm simulate: error: unrecognized arguments: --bogus" in err


def test_version(capsys):
    from cdpm_drake import __version__

    with pytest.raises(SystemExit) as info:
        cli.main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"cdpm {__version__}"


def test_help_documents_the_exit_codes(capsys):
    with pytest.raises(SystemExit):
        cli.main(["--help"])
    out = capsys.readouterr().out
    for code in ("0    done", "1    error", "2    bad usage", "130  interrupted by Ctrl-C",
                 "143  stopped by SIGTERM"):
        assert code in out


def test_list_shows_the_built_in_robots_scenarios_and_sweeps(capsys, tmp_path, monkeypatch):
    from cdpm_drake.robot import robot_names
    from cdpm_drake.config import scenario_names

    monkeypatch.chdir(tmp_path)  # by name from any directory
    assert cli.main(["list"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    for name in robot_names() + scenario_names():
        (line,) = [x for x in lines if x.split()[:1] == [name]]
        assert len(line.split()) > 1, line  # a one-line description follows the name
    # A scenario's line is its description's first sentence.
    exp2 = next(x for x in lines if x.split()[:1] == ["exp2_interaction"])
    assert "Section 5.2: a hand moves the platform" in exp2
    paper = next(x for x in lines if x.split()[:1] == ["paper_7cable"])
    assert paper.split(None, 1)[1] == ("The seven-cable CDPM of Meziane, Cardou and Otis "
                                       "(section 5, Fig. 7).")


def test_list_includes_sweeps_when_the_package_ships_them(capsys, tmp_path, monkeypatch):
    # The sweeps live in cdpm_drake/data/sweeps/; a stand-in folder here.
    from cdpm_drake import data

    fake = tmp_path / "sweeps"
    fake.mkdir(parents=True)
    (fake / "d_u_grid.yaml").write_text(
        "# Sweep d_u over five values. More text here.\nname: d_u_grid\n")
    monkeypatch.setattr(data, "SWEEPS_DIR", fake)
    assert list_main() == 0
    out = capsys.readouterr().out
    assert "sweeps (" in out and "d_u_grid  Sweep d_u over five values." in out


def test_warnings_start_with_warning(capsys, tmp_path):
    code = cli.main(["simulate", "exp1_no_interaction", "--duration", "0.02", "--no-progress",
                     "--out", str(tmp_path), "--scenario-text", "{limits: {max_velocity: 5}}"])
    assert code == 0
    err = capsys.readouterr().err
    # Each value says where it comes from: the reel speed is the robot file's (issue 22).
    assert ("warning: the platform speed limit 5 m/s (limits.max_velocity) is above the reel "
            "speed limit 1 m/s (default: the robot file's limits.max_reel_speed)"
            in err), err


def test_the_run_report_counts_rejected_packets():
    from cdpm_drake.runs.realtime import RunResult, count_by_reason, report_lines

    assert count_by_reason({}) == "0"
    assert count_by_reason({"value": 3, "crc": 0, "sequence": 1}) == "4 (value 3, sequence 1)"
    result = RunResult(log={}, timing={}, link={"sent": 10, "rejected": {"value": 3, "crc": 0}},
                       error=None, ending="completed", log_path=None, tick_log_path=None)
    (packets,) = [x for x in report_lines(result) if x.startswith("packets:")]
    assert "rejected 3 (value 3)," in packets and "{" not in packets


def test_a_first_compilation_is_announced_once(capsys):
    # Issue 22, point 11: numba's compile event (a cache miss) prints one line, however many
    # kernels compile; a function compiled already says nothing.
    import io

    import numba

    @numba.njit
    def twice(x):
        return 2.0 * x

    @numba.njit
    def thrice(x):
        return 3.0 * x

    stream = io.StringIO()
    with compile_notice(stream) as notice:
        assert twice(1.0) == 2.0 and thrice(1.0) == 3.0
    assert stream.getvalue() == COMPILE_NOTICE + "\n" and notice.said
    stream = io.StringIO()
    with compile_notice(stream):
        assert twice(2.0) == 4.0  # compiled for float already: no event
    assert stream.getvalue() == ""
    assert thrice(1) == 3  # an int signature compiles again, outside the block: not said


def test_a_process_started_after_the_notice_does_not_say_it_again(monkeypatch):
    # Issue 27: the notice showed several times in one command. Once said, it is in the
    # environment of what the command starts (an emulator, a worker), and gone after it.
    import io
    import os

    import numba

    monkeypatch.delenv(COMPILE_NOTICE_SAID, raising=False)

    @numba.njit
    def once(x):
        return x + 1.0

    @numba.njit
    def again(x):
        return x + 2.0

    stream = io.StringIO()
    with compile_notice(stream):
        assert once(1.0) == 2.0
        assert os.environ[COMPILE_NOTICE_SAID] == "1"
        child = subprocess.run([sys.executable, "-c", "import os, sys; from cdpm_drake.cli."
                                "compile_notice import compile_notice; "
                                "n = compile_notice(sys.stderr); print(n.said)"],
                               capture_output=True, text=True, timeout=120)
        assert child.stdout.strip() == "True", child.stderr
    assert stream.getvalue().count(COMPILE_NOTICE) == 1
    assert COMPILE_NOTICE_SAID not in os.environ
    stream = io.StringIO()
    with compile_notice(stream):  # the next command in this process: said again
        assert again(1.0) == 3.0
    assert stream.getvalue() == COMPILE_NOTICE + "\n"


def test_the_first_run_after_installing_says_it_compiles_and_the_next_does_not(tmp_path):
    # A numba cache (NUMBA_CACHE_DIR) without the kinematics module's kernels is a fresh
    # install's as far as those go: the suite's own cache copied with their files left out
    # (an empty one would compile every kernel of the run, a minute of CPU, to show the same).
    # The first run compiles several kernels and must say so once; the second loads them.
    import os
    import shutil

    from cdpm_drake import numba_cache_dir

    cache = tmp_path / "numba_cache"
    if numba_cache_dir().is_dir():  # not yet in a fresh clone: then the cache starts empty
        shutil.copytree(numba_cache_dir(), cache, ignore=shutil.ignore_patterns("kinematics.*"))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    runs = []
    for k in range(2):
        runs.append(subprocess.run(
            [str(Path(sys.executable).parent / "cdpm"), "simulate", "exp1_no_interaction",
             "--duration", "0.01", "--no-progress", "--out", str(tmp_path / f"run{k}")],
            capture_output=True, text=True, env=env, timeout=600))
    assert [r.returncode for r in runs] == [0, 0], runs[0].stderr + runs[1].stderr
    assert runs[0].stderr.count(COMPILE_NOTICE) == 1, runs[0].stderr
    assert COMPILE_NOTICE not in runs[1].stderr, runs[1].stderr
    # Several kernels were compiled (a notice per kernel would have shown more than once).
    assert len(list(cache.rglob("kinematics.*.nbi"))) >= 2
