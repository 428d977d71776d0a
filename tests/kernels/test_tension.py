"""tension.py: the wrench matrix, t* (the largest achievable minimum tension), the tension
distribution with a floor, wrench feasibility.

References: finite differences of the cable lengths (the wrench matrix); scipy's linprog
(HiGHS) for t* and for floor feasibility, on thousands of random poses and on poses a hair from
force closure; the KKT conditions of the least-norm distribution; the numbers issue 18
measured with an independent solver on the attachment points before its recalibration.
"""

import numpy as np
import pytest
from scipy.optimize import linprog

from conftest import highs_t_star

from cdpm_drake.kernels.call import bind
from cdpm_drake.robot import Robot, load_robot
from cdpm_drake.kernels.rotation import rotation_from_rpy, rpy_from_rotation
from cdpm_drake.kernels.tension import (FEASIBLE, GENERAL, GRAVITY, distribution_kernel,
                                        gravity_wrench, grid_points, hand_force_directions,
                                        step_grid, wrench_matrix)
from cdpm_drake.robot.statics import (balancing_rotation, holding_tension, max_min_tensions,
                                      wrench_feasibility)
from cdpm_drake.robot.tension_program import max_min_tension, tension_distribution

PAPER = load_robot("paper_7cable")
# paper_7cable's attachment points before issue 18 recalibrated them with statics (commit
# b28eace): the robot on which issue 18 measured t* with an independent LP. Test data only.
PRE_18 = Robot(name="paper_7cable_pre18", reels=PAPER.reels, workspace=PAPER.workspace,
               attachments=[[-0.0664, 0.0862, 0.1365], [0.15, 0.15, 0.15],
                            [-0.0942, 0.1334, -0.15], [0.15, 0.15, -0.15],
                            [-0.1473, -0.1367, -0.15], [0.15, -0.15, -0.15],
                            [-0.0025, -0.15, 0.15]])
EXP1_START = [1.77, 3.65, 1.22]
EXP2_START = [1.56, 3.24, 1.22]
FIG12A, FIG12B, EXP3_START = [1.87, 3.68, 0.53], [1.30, 3.68, 1.05], [2.22, 3.22, 1.03]
# A suspended 8-cable robot (every reel above the box, in pairs at the corners, cables to
# the platform's corners): gravity keeps its t* finite, so Clarabel's LP has an optimum.
SUSPENDED8 = Robot(
    name="suspended8",
    reels=[[0, 0, 3], [0.1, 0, 3], [4, 0, 3], [4, 0.1, 3], [4, 3, 3], [3.9, 3, 3], [0, 3, 3],
           [0, 2.9, 3]],
    attachments=[[x, y, z] for x, y in ((-0.1, -0.1), (0.1, -0.1), (0.1, 0.1), (-0.1, 0.1))
                 for z in (0.1, -0.1)],
    workspace=([0.5, 0.5, 0.5], [3.5, 2.5, 2.5]))


def _swapped(robot, swaps):
    for s in swaps:
        robot = robot.with_swapped_attachments(*s)
    return robot



def _highs_feasible(W, w, floor):
    """Is there T with W T = -w and every T_i >= floor (HiGHS)?"""
    res = linprog(np.zeros(W.shape[1]), A_eq=W, b_eq=-w, bounds=[(floor, None)] * W.shape[1],
                  method="highs")
    assert res.status in (0, 2), res.message
    return res.status == 0


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


# --- t* against HiGHS ----------------------------------------------------------------------


def _random_cases(count, seed):
    """(W, wrench) of the paper robot (current and pre-18 attachments; unswapped, 1-3 and
    1-3 + 5-7 swapped) at random poses in and 0.3 m around the box, half of them tilted up to
    ~0.3 rad, under the 2.5 kg weight plus a random hand force (~5 N) at the handle."""
    rng = np.random.default_rng(seed)
    robots = [_swapped(r, s) for r in (PAPER, PRE_18) for s in ([], [(1, 3)],
                                                              [(1, 3), (5, 7)])]
    lo, hi = PAPER.workspace.lower - 0.3, PAPER.workspace.upper + 0.3
    for k in range(count):
        robot = robots[k % len(robots)]
        R = rotation_from_rpy(rng.normal(scale=0.15, size=3)) if k % 2 else None
        W = wrench_matrix(robot, rng.uniform(lo, hi), R)
        yield W, gravity_wrench(2.5, rng.normal(scale=5.0, size=3), [0.0, 0.0, -0.15])


def _same_t_star(t, ref):
    """Assert t* equals HiGHS's: within 1e-6 N where finite, the same infinity elsewhere;
    returns whether it is finite."""
    if np.isfinite(ref):
        assert t == pytest.approx(ref, abs=1e-6)
        return True
    assert t == ref
    return False


def test_t_star_equals_highs_on_2000_random_poses_of_the_paper_robot():
    # The closed form for 7 cables (a one-dimensional nullspace) against HiGHS's LP: the same
    # t* within 1e-6 N where finite, the same +inf (force closure) elsewhere, and the same
    # answer to "can every cable stay >= 0 / >= 5 N".
    finite = closure = 0
    for W, w in _random_cases(2000, seed=1):
        status, _ = distribution_kernel(W, w, 0.0, np.empty(7))
        assert status != GENERAL  # the compiled closed form answered, not the fallback
        t, ref = max_min_tension(W, w), highs_t_star(W, w)
        if _same_t_star(t, ref):
            finite += 1
        else:
            closure += 1
        for floor in (0.0, 5.0):
            assert tension_distribution(W, w, floor).feasible == (ref >= floor), (t, ref)
    # Both kinds are well represented (the counts depend only on the seed).
    assert finite > 1000 and closure > 100


def _closure_margin(W):
    """The smallest component of W's unit null vector, signed so that its sum is positive:
    > 0 exactly when an internal force raises every tension (t* = +inf). By numpy's SVD,
    independent of the QR the solver uses."""
    n = np.linalg.svd(W)[2][-1]
    return (n if n.sum() > 0 else -n).min()


def test_near_closure_poses_give_no_false_infeasible():
    # Poses bisected to within 1e-15 m of the force-closure boundary, then stepped off it
    # by 1e-7..1e-3 m to either side: t* jumps there from a finite value to +inf, and the old
    # NNLS/LDP said "infeasible" where huge internal forces hold the platform. Where the
    # null vector's smallest component is >= 1e-6 HiGHS decides reliably: same t*, same
    # floor feasibility. Closer than that HiGHS's own tolerances (1e-7, and its dropping of
    # coefficients below 1e-9) decide instead of the LP, so the reference there is the sign
    # of the null vector itself: +inf exactly when it is positive.
    rng = np.random.default_rng(5)
    robot, w = PRE_18, gravity_wrench(2.5)
    pts = rng.uniform(robot.workspace.lower, robot.workspace.upper, size=(400, 3))
    margins = np.array([_closure_margin(wrench_matrix(robot, p)) for p in pts])
    inside, outside = pts[margins > 0], pts[margins < 0]
    assert len(inside) > 20 and len(outside) > 20
    checked = 0
    for k in range(60):
        a, b = inside[k % len(inside)], outside[k]
        for _ in range(60):
            mid = 0.5 * (a + b)
            a, b = (mid, b) if _closure_margin(wrench_matrix(robot, mid)) > 0 else (a, mid)
        d = (a - b) / np.linalg.norm(a - b)
        for step in (1e-7, 1e-6, 1e-5, 1e-4, 1e-3):
            for sign in (1.0, -1.0):
                W = wrench_matrix(robot, 0.5 * (a + b) + sign * step * d)
                t, margin = max_min_tension(W, w), _closure_margin(W)
                assert (t == np.inf) == (margin > 0), (t, margin)
                if abs(margin) < 1e-6:
                    continue
                checked += 1
                ref = highs_t_star(W, w)
                assert t == ref or t == pytest.approx(ref, abs=1e-6), (t, ref, margin)
                assert (t >= 5.0) == _highs_feasible(W, w, 5.0), (t, margin)
    assert checked > 200


def test_t_star_equals_highs_where_the_nullspace_has_two_or_more_dimensions():
    # 8 cables (2-D nullspace): the closed form over cable triples, on a suspended robot
    # (finite t*) and the shipped cube_8cable (force closure: +inf). A 7-cable robot whose
    # cables all meet at the centre (rank 3, 4-D nullspace): Clarabel's LP (finite t* for a
    # force; -inf for a wrench with a moment, outside W's range).
    rng = np.random.default_rng(2)
    point7 = Robot(name="point7", reels=PAPER.reels, attachments=np.zeros((7, 3)),
                   workspace=PAPER.workspace)
    finite = 0
    for k in range(300):
        robot = (SUSPENDED8, load_robot("cube_8cable"), point7)[k % 3]
        W = wrench_matrix(robot, rng.uniform(robot.workspace.lower, robot.workspace.upper))
        handle = [0.0, 0.0, -0.1] if k % 6 == 5 else [0.0, 0.0, 0.0]
        w = gravity_wrench(2.5, rng.normal(scale=3.0, size=3), handle)
        assert distribution_kernel(W, w, 0.0, np.empty(W.shape[1]))[0] == GENERAL
        if _same_t_star(max_min_tension(W, w), highs_t_star(W, w)):
            finite += 1
    assert finite > 50


def test_the_compiled_kernel_bound_once_gives_the_dispatchers_answer():
    # The control loop binds the kernel (kernel_call.bind); same result, and it writes T.
    W = wrench_matrix(PAPER.with_swapped_attachments(1, 3), EXP2_START)
    w = gravity_wrench(2.5)
    T1, T2 = np.empty(7), np.empty(7)
    kernel = bind(distribution_kernel, W, w, 5.0, T1)
    status, t = kernel(W, w, 5.0, T2)
    assert (status, t) == distribution_kernel(W, w, 5.0, T1)
    np.testing.assert_array_equal(T1, T2)
    assert status == FEASIBLE and t == pytest.approx(highs_t_star(W, w), abs=1e-9)


# --- the distribution ------------------------------------------------------------------------


def _assert_least_norm(W, w, floor, T):
    """KKT of min |T|^2 s.t. W T = -w, T >= floor: T = W^T nu + mu with mu >= 0 on the
    cables at the floor and 0 elsewhere; nu from the cables above the floor."""
    assert np.max(np.abs(W @ T + w)) < 1e-9 * max(1.0, np.abs(T).max())
    assert T.min() >= floor - 1e-12
    free = T > floor + 1e-7 * max(1.0, np.abs(T).max())
    nu = np.linalg.lstsq(W[:, free].T, T[free], rcond=None)[0]
    mu = T - W.T @ nu
    np.testing.assert_allclose(mu[free], 0.0, atol=1e-6 * max(1.0, np.abs(T).max()))
    assert np.all(mu[~free] >= -1e-6 * max(1.0, np.abs(T).max())), mu


@pytest.mark.parametrize("robot,swaps,p,floor", [
    (PRE_18, [(1, 3)], EXP2_START, 5.0), (PRE_18, [(1, 3)], EXP2_START, 0.0),
    (PRE_18, [(1, 3)], EXP2_START, 8.0), (PRE_18, [], [1.5, 2.08, 1.56], 5.0),
    (SUSPENDED8, [], [2.0, 1.5, 1.5], 1.0), (SUSPENDED8, [], [1.0, 0.7, 2.2], 0.0)])
def test_a_feasible_distribution_is_the_least_norm_one_with_the_floor(robot, swaps, p, floor):
    W = wrench_matrix(_swapped(robot, swaps), p)
    w = gravity_wrench(2.5)
    d = tension_distribution(W, w, floor)
    assert d.feasible and d.t_star == pytest.approx(highs_t_star(W, w), abs=1e-6)
    assert d.t_star >= floor
    _assert_least_norm(W, w, floor, d.tensions)
    assert d.best_min == d.tensions.min()
    # Force and moment balance to round-off of m g.
    assert d.residual < 1e-9 * 2.5 * GRAVITY


# Issue 18's independent LP on the pre-18 attachment points, level platform, 2.5 kg: t* (N)
# at each reported pose with its swaps. The slack cables are the two the 1-D optimum ties.
ISSUE_18 = [
    ([(1, 3)], EXP1_START, -8.65, (6, 7)),
    ([(1, 3)], EXP2_START, 8.35, None),
    ([(1, 3)], FIG12A, -16.64, (2, 7)),
    ([(1, 3)], FIG12B, -3.56, (6, 7)),
    ([(1, 3), (5, 7)], EXP3_START, -0.62, (4, 5)),
]


@pytest.mark.parametrize("swaps,p,t_star,slack", ISSUE_18)
def test_t_star_reproduces_the_measured_holding_tensions(swaps, p, t_star, slack):
    robot = _swapped(PRE_18, swaps)
    W, w = wrench_matrix(robot, p), gravity_wrench(2.5)
    assert holding_tension(robot, p) == pytest.approx(t_star, abs=0.005)
    d = tension_distribution(W, w, 5.0)
    assert d.t_star == pytest.approx(t_star, abs=0.005)
    if slack is None:
        assert d.feasible
        return
    # Infeasible: the max-min distribution, its minimum and the cables tied at it.
    assert not d.feasible and d.best_min == d.t_star
    assert tuple(k + 1 for k in d.slack) == slack
    assert d.tensions.min() == pytest.approx(t_star, abs=0.005)
    np.testing.assert_allclose(W @ d.tensions, -w, atol=1e-9)


def test_the_pose_where_the_old_solver_said_infeasible_is_held_at_any_floor():
    # Issue 18: the pre-18 robot unswapped at this pose was "infeasible" for a 5, 6 or 10 N
    # floor but feasible for 1, 2 and 4 N (the old NNLS/LDP was ill-conditioned; a solution
    # needs over a kilonewton). An internal force raises every tension here: t* = +inf, and
    # HiGHS agrees at every floor.
    W, w = wrench_matrix(PRE_18, [2.365, 1.206, 1.993]), gravity_wrench(2.5)
    assert max_min_tension(W, w) == np.inf
    for floor in (1.0, 2.0, 4.0, 5.0, 6.0, 10.0):
        d = tension_distribution(W, w, floor)
        assert d.feasible and _highs_feasible(W, w, floor)
        assert d.tensions.min() >= floor and d.tensions.max() > 1000.0
        np.testing.assert_allclose(W @ d.tensions, -w, atol=1e-9 * d.tensions.max())


def test_the_uncalibrated_robot_holds_its_platform_on_its_measured_share_of_the_box():
    # Issue 18: unswapped, >= 5 N on "only 28 %" of the box on a 5 cm grid (51 x 65 x 43).
    pts = step_grid(PRE_18.workspace.lower, PRE_18.workspace.upper, 0.05)
    assert pts.shape == (51 * 65 * 43, 3)
    t = holding_tension(PRE_18, pts)
    assert np.mean(t >= 5.0) == pytest.approx(0.28, abs=0.005)


def test_a_moment_no_cable_can_balance_is_infeasible_whatever_the_floor():
    # Three cables pulling up through the centre (b_i = 0) cannot hold a hand force at an
    # off-centre handle: its moment is outside W's range.
    robot = Robot(name="tripod", reels=[[0, 0, 3], [2, 0, 3], [1, 2, 3]],
                  attachments=np.zeros((3, 3)), workspace=([0.5, 0.5, 0.5], [1.5, 1.5, 2.0]))
    W = wrench_matrix(robot, [1.0, 0.7, 1.0])
    assert tension_distribution(W, gravity_wrench(1.0), 0.0).feasible
    d = tension_distribution(W, gravity_wrench(1.0, [1.0, 0, 0], [0, 0, -0.2]), 0.0)
    assert not d.feasible and d.residual > 0.1 and d.t_star == -np.inf


def test_a_square_wrench_matrix_has_one_distribution():
    # Six cables, full rank: T = -W^-1 w, t* = its minimum.
    robot = Robot(name="six", reels=PAPER.reels[:6], attachments=PRE_18.attachments[:6],
                  workspace=PAPER.workspace)
    W, w = wrench_matrix(robot, [1.5, 3.0, 1.2]), gravity_wrench(2.5)
    T = np.linalg.solve(W, -w)
    assert max_min_tension(W, w) == pytest.approx(T.min(), abs=1e-9)
    d = tension_distribution(W, w, min(0.0, T.min()))
    np.testing.assert_allclose(d.tensions, T, atol=1e-9)


def test_the_grid_kernel_agrees_with_point_by_point_t_star():
    # max_min_tensions (compiled for 7 cables; per point for the others) against
    # max_min_tension of each point's W, for several wrenches.
    rng = np.random.default_rng(4)
    wrenches = np.array([gravity_wrench(2.5, f, [0, 0, -0.15])
                         for f in rng.normal(scale=5.0, size=(3, 3))])
    for robot in (PAPER.with_swapped_attachments(1, 3), SUSPENDED8):
        pts = rng.uniform(robot.workspace.lower, robot.workspace.upper, size=(20, 3))
        grid = max_min_tensions(robot, pts, wrenches)
        for p, row in zip(pts, grid):
            expected = [max_min_tension(wrench_matrix(robot, p), w) for w in wrenches]
            np.testing.assert_allclose(row, expected, atol=1e-9)


def test_holding_tension_uses_the_robot_files_platform_mass():
    # t* is linear in the wrench at a fixed pose when finite: the weight of the file's
    # 2.5 kg platform, and twice that for a 5 kg one.
    p = EXP2_START
    robot = PAPER.with_swapped_attachments(1, 3)
    W = wrench_matrix(robot, p)
    assert holding_tension(robot, p) == pytest.approx(
        max_min_tension(W, gravity_wrench(robot.dynamics.mass)), abs=1e-12)
    assert holding_tension(robot, p, mass=5.0) == pytest.approx(
        2 * holding_tension(robot, p), rel=1e-9)


# --- wrench feasibility over the box ---------------------------------------------------------


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
    robot = PRE_18.with_swapped_attachments(1, 3)
    shares = [wrench_feasibility(robot, mass=2.5, hand_force=h, handle=[0, 0, -0.15],
                                 n=3).share for h in (0.0, 5.0, 20.0)]
    assert shares[0] >= shares[1] >= shares[2]


def test_feasibility_grid_agrees_with_single_point_checks():
    robot = PRE_18.with_swapped_attachments(1, 3)
    f = wrench_feasibility(robot, mass=2.5, hand_force=10.0, handle=[0, 0, -0.15],
                           min_tension=1.0, n=3)
    assert f.points.shape == (27, 3)
    np.testing.assert_allclose(f.points, grid_points(robot.workspace.lower,
                                                     robot.workspace.upper, 3))
    for p, ok in zip(f.points, f.feasible):
        W = wrench_matrix(robot, p)
        expected = all(_highs_feasible(W, gravity_wrench(2.5, 10.0 * u, [0, 0, -0.15]), 1.0)
                       for u in hand_force_directions())
        assert ok == expected
    assert 0.0 < f.share < 1.0


def test_balancing_rotation_is_a_tilt_that_holds_exp1s_start():
    # The pre-18 robot cannot hold exp1's start level (t* -8.65 N); tilted it can.
    robot = PRE_18.with_swapped_attachments(1, 3)
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


def test_the_benchmark_prints_every_row():
    # scripts/bench/bench_tension.py, a smoke run: its table has every case, each with a cost.
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[2] / "scripts" / "bench" / "bench_tension.py"
    out = subprocess.run([sys.executable, str(script), "--calls", "20", "--poses", "5",
                          "--repeats", "1"], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    rows = [line for line in out.stdout.splitlines() if line[:1] in "78h"]
    for what in ("7 cables: compiled kernel, bound", "7 cables: scipy linprog HiGHS t*",
                 "8 cables: t* by Clarabel's LP", "holding_tension on a 10 cm grid"):
        row = next(r for r in rows if r.startswith(what))
        assert float(row.split()[-2]) > 0.0
