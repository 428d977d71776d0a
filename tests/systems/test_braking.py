"""The safety filter brakes no harder than the cables can take (issue 31 item 5): without a
tension sensor, the shipped experiments keep every true tension >= 1 N on the dynamic plant.

The bound (kinetostatics.ringing_deceleration) against the wrench matrix built here from the
geometry; the experiments against the plant's ground truth (the log's `tensions`)."""

import numpy as np
import pytest

from cdpm_drake.config import load_scenario
from cdpm_drake.kernels.kinetostatics import ringing_deceleration
from cdpm_drake.robot import load_robot
from cdpm_drake.runs.simulate import simulate


@pytest.mark.parametrize("name", ["paper_7cable", "cube_8cable"])
def test_the_ringing_bound_is_the_swing_over_twice_the_mass_and_the_largest_share(name):
    robot = load_robot(name)
    p = robot.workspace.center
    b = np.asarray(robot.attachments, dtype=float)
    d = np.asarray(robot.reels, dtype=float) - (p + b)
    u = d / np.linalg.norm(d, axis=1)[:, None]
    W = np.vstack([u.T, np.cross(b, u).T])  # force and moment of each unit tension
    share = np.linalg.norm(np.linalg.pinv(W)[:, :3], axis=1).max()
    expected = 3.0 / (2.0 * robot.dynamics.mass * share)
    assert ringing_deceleration(robot, p, 6, 3.0) == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("name", ["exp1_no_interaction", "exp2_interaction", "exp3_two_pairs"])
def test_without_a_tension_sensor_the_shipped_experiments_keep_every_cable_above_1_n(name):
    # Measured: exp2 dipped to 0.53 N when the filter braked at a / sqrt(3) = 1.15 m/s^2 (the
    # onset of braking rang paper_7cable's 4.2 Hz mode); with the ringing bound 1.70 N.
    scenario = load_scenario(name, "{plant: !DynamicReels {tension_sensor: none}, "
                                   "controller: {pose: full, tension_control: true}}")
    result = simulate(scenario=scenario)
    assert result.error is None, result.error
    assert result.log["time"][-1] == pytest.approx(scenario.duration)
    assert np.min(result.log["tensions"]) >= 1.0
