"""Statics is part of a robot's validation (issue 18): the shipped robots hold their platform,
loading a robot says its wrench-matrix rank and the share of its box that holds the platform,
and a robot whose box is mostly unholdable gets a warning naming the share and the cause.

References: scipy's linprog (HiGHS) for t* (the largest achievable minimum tension of the
level platform: its weight at the centre, moments about the centre) on the same grids, and
numpy's SVD for the rank."""

import logging

import numpy as np
import pytest

from cdpm_drake.kernels.interference import pair_distances
from cdpm_drake.robot import STATICS_FLOOR, STATICS_GRID, load_robot, robot_statics
from cdpm_drake.kernels.tension import gravity_wrench, grid_points, step_grid, wrench_matrix

from conftest import highs_t_star, to_yaml
from helpers_robots import PRE_18



def lp_share(robot, points, floor=5.0):
    w = gravity_wrench(robot.dynamics.mass)
    return float(np.mean([highs_t_star(wrench_matrix(robot, p), w) >= floor for p in points]))


# --- the shipped 8-cable robot ---------------------------------------------------------------


def test_cube_8cable_has_full_rank_and_holds_its_platform_everywhere():
    # Issue 18: "full-rank wrench matrix everywhere in its box, platform held at >= 5 N on most
    # of the box". An 11^3 grid: rank 6 by numpy's SVD at every point, t* >= 5 N by HiGHS.
    robot = load_robot("cube_8cable")
    pts = grid_points(robot.workspace.lower, robot.workspace.upper, 11)
    sv = np.array([np.linalg.svd(wrench_matrix(robot, p), compute_uv=False) for p in pts])
    assert np.all(sv[:, -1] > 0.1)  # the file says 0.114: far from rank-deficient
    assert lp_share(robot, pts) == 1.0
    # Loading says the same (its own grid, its own solver).
    statics = robot_statics(robot)
    assert statics.rank == 6 and statics.share == 1.0 and statics.unreachable is None


def test_cube_8cable_crossed_cables_keep_clear_of_each_other():
    # The crossed layout turns the two sets 90 degrees so that a corner's two cables pass each
    # other: >= 80 mm on a 10 cm grid of the box (the file says 80 mm on a 5 cm grid).
    robot = load_robot("cube_8cable")
    d = pair_distances(robot, step_grid(robot.workspace.lower, robot.workspace.upper, 0.1))
    assert d.min() >= 0.079


def test_cube_8cable_has_the_dynamic_plants_sections():
    robot = load_robot("cube_8cable")
    d = robot.dynamics
    assert d.mass == 2.5 and d.EA == 125000.0 and d.damping == 25.0
    np.testing.assert_array_equal(d.handle, [0.0, 0.0, -0.15])


# --- validation on load ------------------------------------------------------------------------

# cube_8cable before issue 18: each cable at its own corner of a 0.2 m cube: rank 5.
CORNER_CUBE = [[x, y, z] for z in (-0.1, 0.1) for x, y in ((-0.1, -0.1), (0.1, -0.1),
                                                          (0.1, 0.1), (-0.1, 0.1))]


def _robot_file(tmp_path, name, attachments, like="paper_7cable"):
    base = load_robot(like)
    spec = {"name": name, "reels": base.reels.tolist(), "attachments": attachments,
            "workspace": {"lower": base.workspace.lower.tolist(),
                          "upper": base.workspace.upper.tolist()}}
    path = tmp_path / f"{name}.yaml"
    path.write_text(to_yaml(spec) + "\n")
    return path


def test_a_robot_whose_box_is_mostly_unholdable_is_loaded_with_a_warning(tmp_path, caplog):
    path = _robot_file(tmp_path, "pre18", PRE_18)
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="cdpm_drake.robot"):
        robot = load_robot(path)
    # The share is HiGHS's on the same grid (11^3, corners included): 22.7 % (issue 18's
    # 28 % is on a 5 cm grid).
    pts = grid_points(robot.workspace.lower, robot.workspace.upper, STATICS_GRID)
    share = lp_share(robot, pts, STATICS_FLOOR)
    assert robot_statics(robot).share == pytest.approx(share, abs=1e-12)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    (warning,) = [w for w in warnings if "workspace box" in w]
    assert f"only {100 * share:.0f} %" in warning and "(11x11x11 grid)" in warning
    # The cause: a point platform would be held almost everywhere (issue 18: 98.7 % on 5 cm).
    assert "moment balance fails" in warning and "attachment points" in warning
    point = float(warning.split("would be held on ")[1].split(" %")[0])
    assert point > 80
    infos = [r.getMessage() for r in caplog.records if r.levelno == logging.INFO]
    assert any("wrench matrix rank 6" in m and f"{100 * share:.1f} %" in m for m in infos)


def test_a_rank_deficient_robot_is_loaded_with_a_warning_naming_the_wrench(tmp_path, caplog):
    # The old cube_8cable: at the centre no tension makes a moment about x (issue 18).
    path = _robot_file(tmp_path, "corner_cube", CORNER_CUBE, like="cube_8cable")
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="cdpm_drake.robot"):
        robot = load_robot(path)
    s = np.linalg.svd(wrench_matrix(robot, robot.workspace.center), compute_uv=False)
    assert s[-1] < 1e-9 * s[0]  # rank 5 by numpy
    statics = robot_statics(robot)
    assert statics.rank == 5 and abs(statics.unreachable[3]) == pytest.approx(1.0)
    text = " ".join(r.getMessage() for r in caplog.records)
    assert "rank 5 < 6" in text and "moment about x" in text


@pytest.mark.parametrize("name", ["paper_7cable", "cube_8cable"])
def test_the_shipped_robots_load_without_a_statics_warning(name, caplog):
    with caplog.at_level(logging.WARNING, logger="cdpm_drake.robot"):
        robot = load_robot(name)
    assert not [r for r in caplog.records if "workspace box" in r.getMessage()
                or "rank" in r.getMessage()]
    assert robot_statics(robot).share > 0.5


def test_statics_are_computed_for_the_files_platform_mass(tmp_path):
    # A heavier platform needs more tension: t* at the centre scales with the mass (t* is
    # linear in the wrench when finite). The cache keys on the mass.
    light = load_robot("paper_7cable")
    path = tmp_path / "heavy.yaml"
    text = (light.source and open(light.source).read())
    path.write_text(text.replace("mass: 2.5 ", "mass: 5.0 "))
    heavy = load_robot(path)
    assert heavy.dynamics.mass == 5.0
    assert robot_statics(heavy).centre_t_star == pytest.approx(
        2 * robot_statics(light).centre_t_star, rel=1e-9)
    c = light.workspace.center
    assert robot_statics(light).centre_t_star == pytest.approx(
        highs_t_star(wrench_matrix(light, c), gravity_wrench(2.5)), abs=1e-6)


def test_a_robot_with_fewer_than_six_cables_is_told_it_can_only_translate(caplog):
    # Four cables, six equations: the warning says so once, not as a share of 0 %.
    from conftest import HAND_ROBOT

    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="cdpm_drake.robot"):
        robot = load_robot(HAND_ROBOT)
    (message,) = [r.getMessage() for r in caplog.records if "cables cannot hold" in r.getMessage()]
    assert message.startswith(f"{robot.name}: 4 cables cannot hold the platform")
    assert "rank 4" in message and "lock_rotation: true" in message
    assert not [r for r in caplog.records if "workspace box" in r.getMessage()]
