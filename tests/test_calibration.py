"""The shipped paper_7cable robot reproduces the cable-cable distances the paper reports
(section 5), its attachment points being calibrated by scripts/calibrate_attachments.py."""

import numpy as np
import pytest

from cdpm_drake.interference import pair_distances
from cdpm_drake.robot import load_robot

# Paper, section 5: swaps (1-based cable pairs), platform position p (m), reported distances
# (m). These numbers are typed from the paper, not from the calibration script.
REPORTED = [
    ([(1, 3)], [1.77, 3.65, 1.22], {(1, 3): 0.057}),            # 5.1
    ([(1, 3)], [1.56, 3.24, 1.22], {(1, 3): 0.061}),            # 5.2, start
    ([(1, 3)], [1.87, 3.68, 0.53], {(1, 3): 0.059}),            # 5.2, Fig. 12 (a)
    ([(1, 3)], [1.30, 3.68, 1.05], {(1, 3): 0.060}),            # 5.2, Fig. 12 (b)
    ([(1, 3), (5, 7)], [2.22, 3.22, 1.03], {(1, 3): 0.059, (5, 7): 0.061}),  # 5.3
]


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


@pytest.mark.parametrize("swaps, p, reported", REPORTED)
def test_reported_distances_within_1_mm(robot, swaps, p, reported):
    r = robot
    for i, j in swaps:
        r = r.with_swapped_attachments(i, j)
    d = pair_distances(r, np.array(p))
    for (i, j), expected in reported.items():
        assert abs(d[r.pair_position(i, j)] - expected) <= 1e-3, ((i, j), p, d)


def test_attachments_lie_on_a_0_3_m_platform(robot):
    assert np.all(np.abs(robot.attachments) <= 0.15)


def test_unswapped_cables_stay_apart_over_the_workspace(robot):
    # The paper's platform is designed so that the unswapped cables do not meet in
    # translation; a 10 cm grid of the workspace box (the script reports 181 mm on 5 cm).
    lo, hi = robot.workspace.lower, robot.workspace.upper
    axes = [np.arange(lo[k], hi[k] + 1e-9, 0.1) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    assert pair_distances(robot, grid).min() > 0.15
