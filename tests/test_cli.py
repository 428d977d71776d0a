"""The `cdpm` command line: --help, `cdpm info` on built-in and user robots, errors."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdpm_drake import cli
from cdpm_drake.kinematics import cable_lengths, jacobian
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
    # Worked by hand in tests/test_robot.py: rho = (3,2,-6), (-2,1,-2), (-3,-2,-6), (4,-4,2).
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
