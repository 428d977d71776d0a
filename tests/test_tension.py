"""tension.py: the wrench matrix, the tension distribution with a floor, wrench feasibility.

References: finite differences of the cable lengths (the wrench matrix), scipy's NNLS and
linear programming and a closed form on the one-dimensional nullspace of a 7-cable robot
(the distributions), and geometry that decides feasibility by construction.
"""

import numpy as np
import pytest
from scipy.optimize import linprog, nnls as scipy_nnls

from cdpm_drake.robot import Robot, load_robot
from cdpm_drake.rotation import rotation_from_rpy, rpy_from_rotation
from cdpm_drake.tension import (GRAVITY, balancing_rotation, grid_points, gravity_wrench,
                                hand_force_directions, least_distance, nnls,
                                tension_distribution, wrench_feasibility, wrench_matrix)

PAPER = load_robot("paper_7cable")
EXP2_START = [1.56, 3.24, 1.22]   # level-feasible with cables 1 and 3 swapped
EXP1_START = [1.77, 3.65, 1.22]   # not: cables 6 and 7 would need negative tension


def _lengths(robot, p, R):
    return np.linalg.norm(robot.reels - (p + robot.attachments @ R.T), axis=1)


def test_wrench_matrix_is_minus_the_length_gradient():
    # Virtual work: a unit tension in cable i does work -dL_i under a platform twist, so
    # column i of W is -dL_i/d[p, theta]; checked by central differences in p and in a small
    # rotation exp(theta) applied to R.
    robot = PAPER.with_swapped_attachments(1, 3)
    p = np.array(EXP2_START)
    R = rotation_from_rpy([0.1, -0.05, 0.2])
    W = wrench_matrix(robot, p, R)
    eps = 1e-6
    grad = np.zeros((6, robot.num_cables))
    for k in range(3):
        dp = np.zeros(3)
        dp[k] = eps
        grad[k] = (_lengths(robot, p + dp, R) - _lengths(robot, p - dp, R)) / (2 * eps)
        rv = np.zeros(3)
        rv[k] = eps
        Rp, Rm = rotation_from_rpy(rv) @ R, rotation_from_rpy(-rv) @ R
        grad[3 + k] = (_lengths(robot, p, Rp) - _lengths(robot, p, Rm)) / (2 * eps)
    np.testing.assert_allclose(W, -grad, atol=1e-8)


def test_nnls_matches_scipy():
    rng = np.random.default_rng(3)
    for _ in range(20):
        A = rng.standard_normal((8, 5))
        b = rng.standard_normal(8)
        x = nnls(A, b)
        ref, _ = scipy_nnls(A, b)
        assert np.all(x >= 0)
        np.testing.assert_allclose(np.linalg.norm(A @ x - b), np.linalg.norm(A @ ref - b),
                                   rtol=1e-9, atol=1e-12)


def test_least_distance_on_a_half_plane_is_the_projection():
    # min |x| with g.x >= h, h > 0: x = h g / |g|^2 (the foot of the perpendicular).
    g = np.array([3.0, 4.0])
    x = least_distance(g[None, :], np.array([10.0]))
    np.testing.assert_allclose(x, 10.0 * g / 25.0, atol=1e-12)
    # An empty set: x1 >= 1 and -x1 >= 1.
    assert least_distance(np.array([[1.0], [-1.0]]), np.array([1.0, 1.0])) is None


def _one_dim_reference(W, wrench, floor):
    """The least-norm feasible T and the max-min T of a 7-cable W (1-D nullspace), in closed
    form: T = T_p + n lam with T_p perpendicular to n, so |T|^2 = |T_p|^2 + lam^2."""
    T_p = np.linalg.pinv(W) @ (-wrench)
    n = np.linalg.svd(W)[2][-1]
    lo = max([(floor - t) / c for t, c in zip(T_p, n) if c > 0], default=-np.inf)
    hi = min([(floor - t) / c for t, c in zip(T_p, n) if c < 0], default=np.inf)
    least = T_p + n * np.clip(0.0, lo, hi) if lo <= hi else None
    # max over lam of min_i (T_p,i + n_i lam): the LP max s s.t. T_p + n lam >= s.
    res = linprog(c=[0.0, -1.0], A_ub=np.column_stack([-n, np.ones(7)]), b_ub=T_p,
                  bounds=[(None, None), (None, None)], method="highs")
    if res.status == 3:  # n > 0: an internal force raises every tension at once
        return least, np.inf
    assert res.status == 0
    return least, -res.fun


def _distribution_and_reference(swaps, p, floor):
    """(W, wrench, tension_distribution, _one_dim_reference) for the paper robot with these
    attachment swaps at p, holding a 2.5 kg platform with tensions >= floor (N)."""
    robot = PAPER
    for s in swaps:
        robot = robot.with_swapped_attachments(*s)
    W = wrench_matrix(robot, p)
    wrench = gravity_wrench(2.5)
    return W, wrench, tension_distribution(W, wrench, floor), _one_dim_reference(W, wrench, floor)


@pytest.mark.parametrize("swaps,p,floor", [
    ([(1, 3)], EXP2_START, 5.0), ([(1, 3)], EXP2_START, 0.0), ([(1, 3)], EXP2_START, 8.0),
    ([], [1.5, 2.08, 1.56], 5.0), ([(1, 3), (5, 7)], [1.5, 2.72, 1.56], 2.0)])
def test_feasible_distribution_is_the_least_norm_one_with_the_floor(swaps, p, floor):
    W, wrench, d, (least, _) = _distribution_and_reference(swaps, p, floor)
    assert least is not None and d.feasible
    np.testing.assert_allclose(d.tensions, least, atol=1e-7)
    assert d.tensions.min() >= floor
    # Force and moment balance to round-off of m g.
    assert np.max(np.abs(W @ d.tensions + wrench)) < 1e-9 * 2.5 * GRAVITY


@pytest.mark.parametrize("swaps,p,floor,slack", [
    ([(1, 3)], EXP1_START, 5.0, (6, 7)),          # exp1's start, level
    ([(1, 3)], EXP1_START, 0.0, (6, 7)),
    ([(1, 3)], EXP2_START, 50.0, (6, 7)),         # feasible, but not with 50 N everywhere
    ([(1, 3), (5, 7)], [2.22, 3.22, 1.03], 1.0, (4, 5))])  # exp3's start
def test_infeasible_distribution_reports_the_best_minimum_and_its_cables(swaps, p, floor,
                                                                          slack):
    W, wrench, d, (least, best) = _distribution_and_reference(swaps, p, floor)
    assert least is None and not d.feasible
    assert d.best_min == pytest.approx(best, abs=1e-4)
    assert tuple(k + 1 for k in d.slack) == slack
    assert d.best_min < floor
    np.testing.assert_allclose(W @ d.tensions, -wrench, atol=1e-8)


def test_a_moment_no_cable_can_balance_is_infeasible_whatever_the_floor():
    # Three cables pulling up through the centre (b_i = 0) cannot hold a hand force at an
    # off-centre handle: its moment is outside W's range.
    robot = Robot(name="tripod", reels=[[0, 0, 3], [2, 0, 3], [1, 2, 3]],
                  attachments=np.zeros((3, 3)), workspace=([0.5, 0.5, 0.5], [1.5, 1.5, 2.0]))
    W = wrench_matrix(robot, [1.0, 0.7, 1.0])
    assert tension_distribution(W, gravity_wrench(1.0), 0.0).feasible
    d = tension_distribution(W, gravity_wrench(1.0, [1.0, 0, 0], [0, 0, -0.2]), 0.0)
    assert not d.feasible and d.residual > 0.1


def test_feasibility_share_of_point_platforms_decided_by_geometry():
    # Reels at the 8 corners of a cube around the workspace, a point platform: the cables
    # span every direction positively everywhere inside (and their internal force raises
    # every tension at once), so any wrench is feasible with any floor: share 1.
    corners = np.array([[x, y, z] for x in (0, 4) for y in (0, 4) for z in (0, 4)], float)
    box = Robot(name="box", reels=corners, attachments=np.zeros((8, 3)),
                workspace=([1, 1, 1], [3, 3, 3]))
    assert wrench_feasibility(box, mass=5.0, hand_force=50.0, min_tension=20.0, n=3).share == 1
    # Hung from four reels above it, a 5 kg point platform (49 N) cannot resist a 50 N push
    # up anywhere (cables do not push): share 0; a 10 N hand in any direction is held
    # somewhere but not near the box's low corners, where the cables are too flat.
    top = Robot(name="hung", reels=[[0, 0, 4], [4, 0, 4], [4, 4, 4], [0, 4, 4]],
                attachments=np.zeros((4, 3)), workspace=([0.5, 0.5, 0.5], [3.5, 3.5, 3.5]))
    assert wrench_feasibility(top, mass=5.0, hand_force=50.0, n=3).share == 0.0
    f = wrench_feasibility(top, mass=5.0, hand_force=10.0, n=3)
    assert 0.0 < f.share < 1.0
    centre = np.argmin(np.linalg.norm(f.points - [2.0, 2.0, 2.0], axis=1))
    assert f.feasible[centre]
    # Shares fall as the hand force grows (more demanded, never less).
    robot = PAPER.with_swapped_attachments(1, 3)
    shares = [wrench_feasibility(robot, mass=2.5, hand_force=h, handle=[0, 0, -0.15],
                                 n=3).share for h in (0.0, 5.0, 20.0)]
    assert shares[0] >= shares[1] >= shares[2]


def test_feasibility_grid_agrees_with_single_point_checks():
    robot = PAPER.with_swapped_attachments(1, 3)
    f = wrench_feasibility(robot, mass=2.5, hand_force=10.0, handle=[0, 0, -0.15],
                           min_tension=1.0, n=3)
    assert f.points.shape == (27, 3)
    np.testing.assert_allclose(f.points, grid_points(robot.workspace.lower,
                                                     robot.workspace.upper, 3))
    for p, ok in zip(f.points, f.feasible):
        W = wrench_matrix(robot, p)
        expected = all(tension_distribution(W, gravity_wrench(2.5, 10.0 * u, [0, 0, -0.15]),
                                            1.0).feasible for u in hand_force_directions())
        assert ok == expected
    assert 0.0 < f.share < 1.0


def test_balancing_rotation_is_a_tilt_that_holds_exp1s_start():
    robot = PAPER.with_swapped_attachments(1, 3)
    rpy = balancing_rotation(robot, EXP1_START, mass=2.5, min_tension=5.0)
    assert rpy is not None and np.linalg.norm(rpy) > 0
    d = tension_distribution(wrench_matrix(robot, EXP1_START, rotation_from_rpy(rpy)),
                             gravity_wrench(2.5), 5.0)
    assert d.feasible and d.tensions.min() >= 5.0


def test_rotation_round_trip():
    from pydrake.math import RollPitchYaw

    for rpy in ([0.1, -0.2, 0.3], [-1.0, 1.2, 2.5]):
        R = rotation_from_rpy(rpy)
        np.testing.assert_allclose(R, RollPitchYaw(rpy).ToRotationMatrix().matrix(), atol=1e-15)
        np.testing.assert_allclose(rpy_from_rotation(R), rpy, atol=1e-12)
