"""The reel plants' forward-kinematics bound, unset, is derived from the robot's cables: 5 mm
of geometry and encoder error plus the stretch the controller's tension ceiling gives the
longest cable in the workspace box. A constant (5 mm) stopped a robot of softer cables on its
own stretch; `cdpm run` against `cdpm emulate --plant dynamic` needed it set by hand."""

import itertools

import numpy as np
import pytest

from cdpm_drake.config import load_resolved_scenario
from cdpm_drake.kernels.kinematics import KinematicsError, cable_lengths, forward_kinematics
from cdpm_drake.robot import load_robot
from cdpm_drake.robot.stretch import LENGTH_TOLERANCE, derived_length_residual


def _longest_by_grid(robot, n=21):
    """The longest cable over an n^3 grid of the box (corners included), by brute force."""
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(robot.workspace.lower,
                                                     robot.workspace.upper)]
    points = np.array(list(itertools.product(*axes)))
    return max(float(cable_lengths(robot, p).max()) for p in points)


@pytest.mark.parametrize("name", ["paper_7cable", "cube_8cable"])
def test_the_bound_is_the_tolerance_plus_the_longest_cables_stretch(name):
    robot = load_robot(name)
    # Closed form: 5 mm + T L_max / EA, L_max by brute force over the box.
    expected = LENGTH_TOLERANCE + 100.0 * _longest_by_grid(robot) / robot.dynamics.EA
    assert derived_length_residual(robot) == pytest.approx(expected, rel=1e-12)
    assert derived_length_residual(robot, 50.0) == pytest.approx(
        LENGTH_TOLERANCE + 50.0 * _longest_by_grid(robot) / robot.dynamics.EA, rel=1e-12)


@pytest.mark.parametrize("plant", ["!HardwareReels {}", "!CanopenReels {}"])
def test_a_scenario_without_a_bound_gets_its_robots(plant):
    resolved = load_resolved_scenario("exp2_interaction", f"plant: {plant}")
    robot = resolved.robot  # exp2's swapped robot: its own longest cable
    expected = LENGTH_TOLERANCE + 100.0 * _longest_by_grid(robot) / robot.dynamics.EA
    assert resolved.fk_max_residual == pytest.approx(expected, rel=1e-12)
    assert resolved.scenario.plant.max_length_residual == resolved.fk_max_residual
    # The controller's own ceiling is the tension the stretch is taken at.
    lower = load_resolved_scenario("exp2_interaction",
                                   f"{{plant: {plant}, controller: {{max_tension: 40.0}}}}")
    assert lower.fk_max_residual == pytest.approx(
        LENGTH_TOLERANCE + 40.0 * _longest_by_grid(robot) / robot.dynamics.EA, rel=1e-12)


def test_a_bound_given_is_kept():
    resolved = load_resolved_scenario("exp2_interaction",
                                      "plant: !HardwareReels {max_length_residual: 0.004}")
    assert resolved.fk_max_residual == 0.004


def test_softer_cables_get_room_for_their_stretch():
    # paper_7cable with cables four times softer (17.5 kN), at the box corner where cable 1
    # is longest: cable 1 at the ceiling (100 N), the others at 10 N, each stretched by
    # T L / EA. The translating fit of those lengths misses by more than the former 5 mm, and
    # stays within the derived bound.
    import dataclasses

    robot = load_robot("paper_7cable")
    soft = dataclasses.replace(robot, dynamics=dataclasses.replace(robot.dynamics,
                                                                   EA=17500.0))
    corner = max(itertools.product(*zip(robot.workspace.lower, robot.workspace.upper)),
                 key=lambda c: cable_lengths(robot, np.array(c))[0])
    p = np.array(corner)
    rigid = cable_lengths(soft, p)
    T = np.full(soft.num_cables, 10.0)
    T[0] = 100.0
    stretched = rigid * (1.0 + T / soft.dynamics.EA)
    with pytest.raises(KinematicsError, match="allowed 5.000 mm"):
        forward_kinematics(soft, stretched, p_guess=p, max_residual=LENGTH_TOLERANCE)
    fitted = forward_kinematics(soft, stretched, p_guess=p,
                                max_residual=derived_length_residual(soft))
    assert np.linalg.norm(fitted - p) < 0.05
