"""The kinetostatic limit: the max-min of lines (tension.max_min_lines) against scipy's HiGHS,
the margin of a pose against a linear program, its gradient against finite differences, and
the felt cue's logistic."""

import numpy as np
import pytest
from scipy.optimize import linprog

from cdpm_drake.kernels.tension import max_min_lines
from conftest import highs_margin, highs_margin_distribution, highs_t_star


def _highs_max_min(a, C):
    """max t s.t. t <= a_j + C_j . lam, by HiGHS: (t, status) with status 3 = unbounded."""
    K, k = C.shape
    res = linprog(np.r_[np.zeros(k), -1.0], A_ub=np.hstack([-C, np.ones((K, 1))]), b_ub=a,
                  bounds=[(None, None)] * (k + 1), method="highs")
    return (-res.fun if res.status == 0 else None), res.status


@pytest.mark.parametrize("k", [0, 1, 2, 3, 4])
def test_max_min_lines_equals_the_linear_program(k):
    rng = np.random.default_rng(k)
    unbounded = 0
    for trial in range(200):
        K = int(rng.integers(1, 12))
        a = rng.normal(size=K) * 50.0
        C = rng.normal(size=(K, k))
        if trial % 2 == 0:  # floor and ceiling lines, as in a tension margin: bounded
            a, C = np.r_[a - 10.0, 100.0 - a], np.vstack([C, -C])
        lam = np.empty(k)
        t = max_min_lines(a, C, lam)
        ref, status = _highs_max_min(a, C)
        if status == 3:
            assert t == np.inf
            unbounded += 1
            continue
        assert status == 0
        # Exact for k <= 1; the QP form of k >= 2 is within 1e-8 relative (LINES_WEIGHT).
        assert t == pytest.approx(ref, rel=1e-7, abs=1e-7)
        if k:  # the maximiser returned attains it
            assert np.min(a + C @ lam) == pytest.approx(t, rel=1e-9, abs=1e-9)
    assert k == 0 or unbounded > 0


# --- the margin of a pose ------------------------------------------------------------------------


def _robot(name, swaps=()):
    from cdpm_drake.robot import load_robot, resolve_robot_path

    robot = load_robot(resolve_robot_path(name))
    for i, j in swaps:
        robot = robot.swapped(i, j) if hasattr(robot, "swapped") else robot
    return robot


@pytest.mark.parametrize("name", ["paper_7cable", "cube_8cable"])
def test_margin_equals_the_linear_program(name):
    from cdpm_drake.kernels.kinetostatics import (MARGIN_BOTH, MARGIN_KAPPA, MARGIN_T_STAR,
                                                  margin, margin_in, margin_scratch,
                                                  scratch_views)
    from cdpm_drake.kernels.rotation import rotation_from_rpy
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix

    robot = _robot(name)
    scratch = margin_scratch(robot.num_cables)
    rng = np.random.default_rng(3)
    finite = 0
    for _ in range(150):
        p = rng.uniform(robot.workspace.lower, robot.workspace.upper)
        R = rotation_from_rpy(rng.normal(size=3) * 0.1)
        F = rng.normal(size=3) * 15.0
        w = gravity_wrench(robot.dynamics.mass, F, R @ robot.dynamics.handle)
        kappa, t_star = margin(robot.reels, robot.attachments, 6, p, R, w, 3.0, 100.0, scratch)
        W = wrench_matrix(robot, p, R)
        ref = highs_margin(W, w, 3.0, 100.0)
        if np.isfinite(ref):
            finite += 1
            assert kappa == pytest.approx(ref, abs=1e-6)
        else:
            assert kappa < -1e3 or kappa == -np.inf
        # t* (no ceiling) against the statics tests' HiGHS reference.
        assert t_star == pytest.approx(highs_t_star(W, w), abs=1e-6)
        # What the look ahead (kappa alone) and the monitor (t* alone) ask for: the same
        # numbers bit for bit, the other left nan; the soft margin too.
        views = scratch_views(scratch)
        for soft in (0.0, 2.0):
            both = margin_in(robot.reels, robot.attachments, 6, p, R, w, 3.0, 100.0, views,
                             soft, MARGIN_BOTH)
            alone = margin_in(robot.reels, robot.attachments, 6, p, R, w, 3.0, 100.0, views,
                              soft, MARGIN_KAPPA)
            assert alone[0] == both[0] or (np.isnan(alone[0]) and np.isnan(both[0]))
            assert np.isnan(alone[1]) or not np.isfinite(both[0])
            alone = margin_in(robot.reels, robot.attachments, 6, p, R, w, 3.0, 100.0, views,
                              soft, MARGIN_T_STAR)
            assert alone[1] == both[1] and (np.isnan(alone[0]) or not np.isfinite(both[0]))
    assert finite > 100


# --- the kinetostatic block's tick: gradient and look ahead ---------------------------------------


def _tick(robot, p, F, v, floor=3.0, a_brake=1.0, T=0.002):
    """kinetostatic_tick at p (level) with the hand force F and the last command v; returns
    its output and the parameters (cue off: the gradient is still computed for the barrier)."""
    from cdpm_drake.kernels.kinetostatics import (KIN_OUT, kinetostatic_params, kinetostatic_tick,
                                          margin_scratch)

    params = kinetostatic_params(robot, floor=floor, ceiling=100.0, rows=6, barrier=True,
                                 t_l=4.0, t_u=8.0, F_u=2.0, eps=0.1, force=False,
                                 a_brake=a_brake, time_step=T)
    out = np.empty(KIN_OUT)
    # x = [p, F, the filter's memory: p_c (3), valid 0 (the first tick: at p itself), v].
    kinetostatic_tick(robot.reels, robot.attachments, params,
                      margin_scratch(robot.num_cables), np.r_[p, F, np.zeros(4), v], out)
    return out


def _highs_kappa(robot, p, F, floor=3.0):
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix

    w = gravity_wrench(robot.dynamics.mass, F, robot.dynamics.handle)
    return highs_margin(wrench_matrix(robot, np.asarray(p, dtype=float)), w, floor, 100.0)


def test_the_block_s_margin_gradient_is_the_linear_program_s_forward_difference():
    # kappa's gradient (N/m) against the same forward difference (kinetostatics.FD_STEP_P) of
    # HiGHS's margin: the LP's kappa is good to ~1e-8 N, so the two agree to ~1e-4 N/m; the
    # gradients here are 1-100 N/m.
    from cdpm_drake.kernels.kinetostatics import FD_STEP_P

    robot = _robot("paper_7cable")
    rng = np.random.default_rng(11)
    for _ in range(12):
        p = rng.uniform(robot.workspace.lower + 0.2, robot.workspace.upper - 0.2)
        F = rng.normal(size=3) * 5.0
        out = _tick(robot, p, F, np.zeros(3))
        k0 = _highs_kappa(robot, p, F)
        assert out[3] == pytest.approx(k0, abs=1e-6)
        ref = [(_highs_kappa(robot, p + FD_STEP_P * e, F) - k0) / FD_STEP_P for e in np.eye(3)]
        np.testing.assert_allclose(out[4:7], ref, atol=0.02)
        assert np.linalg.norm(ref) > 0.5


def test_the_look_ahead_ends_where_the_margin_is_lost_along_the_command():
    """At (2.8, 2.4, 1.3) m with 5 N along +x, kappa is 7.6 N and falls to zero ~95 mm further
    along +x (HiGHS), and below -RAY_TOLERANCE (a drop) within the look ahead's reach. Moving
    +x at 0.5 m/s the look ahead covers the stopping distance at a_brake 1 m/s^2 plus two
    ticks and 5 mm (132 mm): it reports the last point it found with kappa >= 0, within its
    resolution (a quarter of that distance halved five times) below the root of HiGHS's
    margin along the ray (scipy's brentq). Away from the loss, or at rest, it sees none
    (inf)."""
    from scipy.optimize import brentq

    from cdpm_drake.kernels.kinetostatics import RAY_TOLERANCE

    robot = _robot("paper_7cable")
    p, F, speed = np.array([2.8, 2.4, 1.3]), np.array([5.0, 0.0, 0.0]), 0.5
    reach = speed ** 2 / 2.0 + 2 * speed * 0.002 + 0.005
    root = brentq(lambda s: _highs_kappa(robot, p + [s, 0, 0], F), 0.0, reach, xtol=1e-9)
    assert 0.09 < root < 0.1
    assert _highs_kappa(robot, p + [reach, 0, 0], F) < -RAY_TOLERANCE
    ray = _tick(robot, p, F, [speed, 0.0, 0.0])[10]
    assert root - reach / 4 / 2 ** 5 - 1e-9 <= ray <= root + 1e-9
    assert _tick(robot, p, F, [-speed, 0.0, 0.0])[10] == np.inf
    assert _tick(robot, p, F, [0.0, 0.0, 0.0])[10] == np.inf


def test_the_look_ahead_does_not_flip_with_the_sign_of_a_margin_at_the_limit():
    """A platform sliding along the kinetostatic limit has kappa = +-1e-5 N from tick to
    tick. Tangent to the limit (the curved limit falls 0.005 N in 50 mm here, HiGHS) the look
    ahead must see the same on both sides of zero: no drop (inf). Looking for kappa < 0 only
    where kappa >= 0 it saw a drop right ahead (the first sample already below 0) on the
    ticks with kappa >= 0 and nothing on the others, so the filter braked and sped up in
    turn: a 5 Hz cycle of 5-135 mm/s that rang the dynamic plant (a 20 N lift on exp2). A
    real drop is still seen, and the look ahead still ends where the margin is lost."""
    from scipy.optimize import brentq

    from cdpm_drake.kernels.kinetostatics import RAY_TOLERANCE

    robot = _robot("paper_7cable")
    p, F, speed = np.array([2.8, 2.4, 1.3]), np.array([5.0, 0.0, 0.0]), 0.5
    limit = p + [brentq(lambda s: _highs_kappa(robot, p + [s, 0, 0], F), 0.0, 0.2,
                        xtol=1e-12), 0.0, 0.0]
    g = _tick(robot, limit - [1e-3, 0, 0], F, np.zeros(3))[4:7]
    normal = g / np.linalg.norm(g)
    tangent = np.cross(normal, [0.0, 0.0, 1.0])
    tangent /= np.linalg.norm(tangent)
    for side in (+1e-7, -1e-7):
        q = limit + side * normal
        for v in (speed * tangent, -speed * tangent):
            along = [_highs_kappa(robot, q + s * v / speed, F) for s in (0.01, 0.05, 0.13)]
            assert min(along) > -RAY_TOLERANCE and along[-1] < -1e-3  # curved, not flat
            out = _tick(robot, q, F, v)
            assert abs(out[3]) < 2e-5 and np.sign(out[3]) == np.sign(side)
            assert out[10] == np.inf, (side, v, out[10], along)
    # Just inside the limit, straight down the gradient: a drop within millimetres, and the
    # margin is lost right away: the look ahead ends before 1e-7 m.
    inside = limit + 1e-7 * normal
    assert _highs_kappa(robot, inside - 0.02 * normal, F) < -RAY_TOLERANCE
    assert _tick(robot, inside, F, -speed * normal)[10] <= 1e-7 + 1e-9


# --- the soft margin (a robot with mass) --------------------------------------------------------


def _soft_reference(W, w, floor, ceiling, mu, T0):
    """The soft margin by an independent route: max over the tensions T with W T + w = 0 of
    the soft minimum -mu logsumexp(-lines / mu) of the 2m lines T_i - floor, ceiling - T_i:
    T = T0 + N lam with N scipy's SVD nullspace of W and T0 HiGHS's distribution (not the
    kernel's pivoted QR), maximised by BFGS on its exact gradient (the problem is concave)."""
    from scipy.linalg import null_space
    from scipy.optimize import minimize
    from scipy.special import logsumexp, softmax

    N = null_space(W)

    def neg(lam):
        T = T0 + N @ lam
        z = -np.r_[T - floor, ceiling - T] / mu
        p = softmax(z)
        m = T.size
        dT = -(p[:m] - p[m:])  # d neg / dT
        return mu * logsumexp(z), N.T @ dT

    res = minimize(neg, np.zeros(N.shape[1]), jac=True, method="BFGS",
                   options={"gtol": 1e-11, "maxiter": 2000})
    assert np.linalg.norm(res.jac) < 1e-7
    return -res.fun


@pytest.mark.parametrize("name", ["paper_7cable", "cube_8cable"])
def test_the_soft_margin_equals_an_independent_optimisation(name):
    from cdpm_drake.kernels.kinetostatics import margin, margin_scratch
    from cdpm_drake.kernels.rotation import rotation_from_rpy
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix

    robot = _robot(name)
    m = robot.num_cables
    scratch = margin_scratch(m)
    rng = np.random.default_rng(5)
    checked = 0
    for mu in (0.5, 3.0):
        for _ in range(25):
            p = rng.uniform(robot.workspace.lower + 0.1, robot.workspace.upper - 0.1)
            R = rotation_from_rpy(rng.normal(size=3) * 0.05)
            F = rng.normal(size=3) * 10.0
            w = gravity_wrench(robot.dynamics.mass, F, R @ robot.dynamics.handle)
            hard, _ = margin(robot.reels, robot.attachments, 6, p, R, w, 3.0, 100.0, scratch)
            soft, t_star = margin(robot.reels, robot.attachments, 6, p, R, w, 3.0, 100.0,
                                  scratch, mu)
            W = wrench_matrix(robot, p, R)
            _, T0 = highs_margin_distribution(W, w, 3.0, 100.0)
            if T0 is None:
                assert not np.isfinite(hard) or hard < -1e3
                continue
            checked += 1
            assert soft == pytest.approx(_soft_reference(W, w, 3.0, 100.0, mu, T0), abs=2e-6)
            # Below the hard margin, by at most mu log 2m (the soft minimum's bounds).
            assert hard - mu * np.log(2 * m) - 1e-9 <= soft <= hard + 1e-9
            # t* keeps its hard definition (the statics' measure, no softening).
            assert t_star == pytest.approx(highs_t_star(W, w), abs=1e-6)
    assert checked > 30


def test_the_soft_margin_turns_its_slope_smoothly_where_the_hard_one_kinks():
    """Along 60 cm paths through paper_7cable's workspace centre under a 20 N lift, the hard
    margin has kinks (the binding cable changes: its slope jumps by 20-90 N/m within one 1 mm
    step); the soft margin (mu 3 N, the shipped temperature on that robot) has none: its
    slope changes by at most a tenth of the hard one's jump in any step (measured: 0.7 and
    3.3 N/m against 42 and 90). The filter's barrier and the
    cue follow that slope (the module docstring: a jump of it rang cables slack)."""
    from cdpm_drake.kernels.kinetostatics import margin, margin_scratch
    from cdpm_drake.kernels.tension import gravity_wrench

    robot = _robot("paper_7cable")
    scratch = margin_scratch(robot.num_cables)
    w = gravity_wrench(robot.dynamics.mass, np.array([0.0, 0.0, 20.0]), robot.dynamics.handle)
    c = np.asarray(robot.workspace.center, dtype=float)
    found = False
    for direction in np.eye(3):
        s = np.arange(-0.3, 0.3 + 1e-9, 0.001)
        hard = np.array([margin(robot.reels, robot.attachments, 6, c + t * direction, np.eye(3),
                                w, 3.0, 100.0, scratch)[0] for t in s])
        soft = np.array([margin(robot.reels, robot.attachments, 6, c + t * direction, np.eye(3),
                                w, 3.0, 100.0, scratch, 3.0)[0] for t in s])
        jump_hard = np.abs(np.diff(np.diff(hard) / 0.001))
        jump_soft = np.abs(np.diff(np.diff(soft) / 0.001))
        if jump_hard.max() > 20.0:
            found = True
            assert jump_soft.max() < jump_hard.max() / 10.0, (direction, jump_soft.max(),
                                                              jump_hard.max())
    assert found  # the path has a kink to smooth


def test_the_geometry_tension_error_bounds_the_tensions_change():
    """kinetostatics.geometry_tension_error against the change itself: moving every cable's
    reel exit by up to sigma (random directions) changes the wrench matrix, and the
    tensions that balance the same wrench (minimum-norm change from a distribution at the
    ceiling) move by no more than the bound, and by a good part of it in the worst draw."""
    from cdpm_drake.kernels.kinetostatics import geometry_tension_error, wrench_rows
    from cdpm_drake.kernels.tension import wrench_matrix
    from cdpm_drake.robot import load_robot
    import dataclasses

    robot = load_robot("cube_8cable")
    p = robot.workspace.center
    rows = wrench_rows(robot)
    sigma = np.full(robot.num_cables, 1e-3)
    ceiling = 100.0
    bound = geometry_tension_error(robot, p, rows, sigma, ceiling)
    W = wrench_matrix(robot, p)[:rows]
    T = np.full(robot.num_cables, ceiling)
    w = W @ T
    rng = np.random.default_rng(4)
    worst = 0.0
    for _ in range(200):
        d = rng.normal(size=(robot.num_cables, 3))
        d *= (sigma / np.linalg.norm(d, axis=1))[:, None]
        moved = dataclasses.replace(robot, reels=robot.reels + d)
        W2 = wrench_matrix(moved, p)[:rows]
        dT = np.linalg.pinv(W2) @ (w - W2 @ T)  # the smallest change that balances w again
        worst = max(worst, np.abs(dT).max())
    assert worst <= bound, (worst, bound)
    assert worst >= 0.1 * bound, (worst, bound)  # a bound, not a wild overestimate
