"""The kinetostatic margin's analytic gradient (kinetostatics.margin_gradient) against central
differences of the margin and, for the soft margin, against Drake's AutoDiffXd through an
independent formulation, at random poses and hands on the built-in robots and two of the
benchmarks' own (frame_8cable: eight cables, six wrench rows; crane_4cable: four cables to
one point, three rows)."""


import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.special import logsumexp

from cdpm_drake.kernels.kinetostatics import (margin, margin_gradient, margin_scratch,
                                              scratch_views, wrench_rows)
from cdpm_drake.kernels.rotation import rotation_from_rpy
from cdpm_drake.kernels.tension import gravity_wrench
from helpers_robots import bench_or_builtin_robot

ROBOTS = ["paper_7cable", "cube_8cable", "frame_8cable", "crane_4cable"]
FLOOR, CEILING = 3.0, 100.0


def _cases(robot, seed, n):
    """n random poses (small rotations where the robot has six rows) and hands: (p, R, w)."""
    rng = np.random.default_rng(seed)
    rows = wrench_rows(robot)
    for _ in range(n):
        p = rng.uniform(robot.workspace.lower + 0.1, robot.workspace.upper - 0.1)
        R = rotation_from_rpy(rng.normal(size=3) * 0.05) if rows == 6 else np.eye(3)
        F = rng.normal(size=3) * 10.0
        yield p, R, gravity_wrench(robot.dynamics.mass, F, R @ robot.dynamics.handle)


def _kappa(robot, rows, scratch, p, R, w, soft):
    return margin(robot.reels, robot.attachments, rows, np.asarray(p, dtype=float), R, w,
                  FLOOR, CEILING, scratch, soft)[0]


def _differences(robot, rows, scratch, p, R, w, soft, h):
    """Central, forward and backward differences of the margin in p, step h (m)."""
    k0 = _kappa(robot, rows, scratch, p, R, w, soft)
    up = np.array([_kappa(robot, rows, scratch, p + h * e, R, w, soft) for e in np.eye(3)])
    down = np.array([_kappa(robot, rows, scratch, p - h * e, R, w, soft) for e in np.eye(3)])
    return (up - down) / (2 * h), (up - k0) / h, (k0 - down) / h


def _binding(robot, rows, scratch, p, R, w):
    """The lines (0-based: floor i, ceiling m + i) within 1e-6 relative of the hard margin at
    its maximiser."""
    kappa = _kappa(robot, rows, scratch, p, R, w, 0.0)
    k = robot.num_cables - rows
    views = scratch_views(scratch)
    lines = views[12] + views[13][:, :k] @ views[14][:k]
    return frozenset(np.flatnonzero(lines - kappa <= 1e-6 * (1 + abs(kappa))))


def _analytic(robot, rows, scratch, p, R, w, soft):
    kappa = _kappa(robot, rows, scratch, p, R, w, soft)
    g = np.full(3, np.nan)
    ok = margin_gradient(scratch, rows, kappa, soft, g) if np.isfinite(kappa) else False
    return kappa, g, ok


def _wrench_ad(robot, rows, p_ad, R):
    """W(p) (rows, m) with AutoDiffXd entries: columns [u_i; R b_i x u_i]."""
    from pydrake.math import sqrt

    cols = []
    for reel, b in zip(robot.reels, robot.attachments):
        Rb = R @ b
        d = reel - p_ad - Rb
        u = d / sqrt(d @ d)
        cols.append(np.r_[u, np.cross(Rb, u)][:rows])
    return np.array(cols).T


def _soft_autodiff(robot, rows, p, R, w, mu):
    """The soft margin and its gradient in p by AutoDiffXd, formulated independently of the
    kernel: T = T_p(p) + N(p) lam, T_p the minimum-norm solution of W T = -w, N the
    projection onto W's nullspace of a fixed basis (both smooth in p); lam* the soft
    maximiser at p (BFGS); then the soft minimum at lam* held fixed (the envelope theorem:
    lam's own derivative does not enter)."""
    from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
    from pydrake.math import exp, inv, log

    m = robot.num_cables
    p_ad = InitializeAutoDiff(np.asarray(p, dtype=float)).ravel()
    W = _wrench_ad(robot, rows, p_ad, R)
    pinv = W.T @ inv(W @ W.T)
    T_p = pinv @ (-w[:rows])
    W0 = ExtractValue(W).reshape(rows, m)
    E = np.linalg.svd(W0)[2][rows:].T  # W0's nullspace at p: a fixed basis (m, k)
    N = (np.eye(m) - pinv @ W) @ E
    T_p0 = ExtractValue(T_p).ravel()
    N0 = ExtractValue(N).reshape(m, -1)

    def neg(lam):
        z = -np.r_[T_p0 + N0 @ lam - FLOOR, CEILING - T_p0 - N0 @ lam] / mu
        s = np.exp(z - logsumexp(z))
        return mu * logsumexp(z), -N0.T @ (s[:m] - s[m:])

    res = minimize(neg, np.zeros(N0.shape[1]), jac=True, method="BFGS",
                   options={"gtol": 1e-12, "maxiter": 5000})
    T = T_p + N @ res.x
    lines = np.r_[T - FLOOR, CEILING - T]
    low = min(x.value() for x in lines)
    total = sum(exp(-(x - low) / mu) for x in lines)
    kappa = low - mu * log(total)
    return float(kappa.value()), ExtractGradient(np.array([kappa])).ravel()


@pytest.mark.parametrize("name", ROBOTS)
def test_the_soft_margin_s_gradient_is_autodiff_s_and_the_central_difference(name):
    # Relative error <= 1e-6 against both references: AutoDiffXd (exact derivatives of an
    # independent formulation, at an optimiser good to ~1e-10) and central differences
    # (Richardson's extrapolation of h = 2e-5 and 1e-5 m: the soft margin at mu = 0.5 N bends
    # on a scale of ~mu / |grad|, ~1 cm, where h = 1e-4 alone was 5e-5 N/m off; round-off of
    # the Newton-converged soft margin ~1e-13 N / h).
    robot = bench_or_builtin_robot(name)
    rows, scratch = wrench_rows(robot), margin_scratch(robot.num_cables)
    checked = 0
    for mu in (0.5, 3.0):
        for p, R, w in _cases(robot, 7, 12):
            kappa, g, ok = _analytic(robot, rows, scratch, p, R, w, mu)
            if not np.isfinite(kappa) or kappa < -50.0:
                continue  # a pose no tensions hold, or one far outside
            assert ok  # the soft margin is smooth wherever it is finite
            ref_kappa, ref = _soft_autodiff(robot, rows, p, R, w, mu)
            assert kappa == pytest.approx(ref_kappa, abs=1e-8 * (1 + abs(kappa)))
            scale = max(np.linalg.norm(ref), 1.0)
            assert np.linalg.norm(g - ref) <= 1e-6 * scale, (p, g, ref)
            coarse, _, _ = _differences(robot, rows, scratch, p, R, w, mu, 2e-5)
            fine, _, _ = _differences(robot, rows, scratch, p, R, w, mu, 1e-5)
            central = (4.0 * fine - coarse) / 3.0  # Richardson: O(h^4)
            assert np.linalg.norm(g - central) <= 1e-6 * scale, (p, g, central)
            checked += 1
    assert checked >= 16


@pytest.mark.parametrize("name", ROBOTS)
def test_the_hard_margin_s_gradient_is_the_central_difference_where_it_is_smooth(name):
    # The hard margin kinks where its binding cables change; "smooth here" is when the same
    # lines bind at p and at p +- h along each axis (one formula on the segment). There the
    # active set's multipliers give the exact gradient: against central differences to 1e-6
    # relative where the max-min is exact (k <= 1, one internal force), to 1e-4 where it is
    # the QP form (k >= 2: the margin's round-off ~1e-8 relative over h = 1e-3 m).
    robot = bench_or_builtin_robot(name)
    rows, scratch = wrench_rows(robot), margin_scratch(robot.num_cables)
    k = robot.num_cables - rows
    h, tol = (1e-5, 1e-6) if k <= 1 else (1e-3, 1e-4)
    checked = kinks = 0
    for p, R, w in _cases(robot, 3, 40):
        kappa, g, ok = _analytic(robot, rows, scratch, p, R, w, 0.0)
        if not np.isfinite(kappa) or kappa < -50.0:
            continue
        binding = _binding(robot, rows, scratch, p, R, w)
        if any(_binding(robot, rows, scratch, p + s * h * e, R, w) != binding
               for e in np.eye(3) for s in (-1, 1)):
            kinks += 1
            continue
        central, _, _ = _differences(robot, rows, scratch, p, R, w, 0.0, h)
        scale = max(np.linalg.norm(central), 1.0)
        assert ok, p
        assert np.linalg.norm(g - central) <= tol * scale, (p, g, central)
        checked += 1
    assert checked >= 15 and kinks < checked


def test_a_kink_is_refused_not_guessed():
    # At a pose where two lines tie beyond the one internal force's k + 1 = 2 (three active:
    # a kink of paper_7cable's hard margin), margin_gradient says so rather than returning a
    # one-sided slope. The kink is found by bisection along x between two poses whose
    # binding lines differ.
    robot = bench_or_builtin_robot("paper_7cable")
    rows, scratch = 6, margin_scratch(robot.num_cables)
    w = gravity_wrench(robot.dynamics.mass, np.zeros(3), robot.dynamics.handle)
    R = np.eye(3)

    def active(p):
        kappa = _kappa(robot, rows, scratch, p, R, w, 0.0)
        views = scratch_views(scratch)
        lines = views[12] + views[13][:, 0] * views[14][0]
        return frozenset(np.flatnonzero(lines - kappa <= 1e-9 * (1 + abs(kappa))))

    c = robot.workspace.center
    xs = np.linspace(robot.workspace.lower[0] + 0.05, robot.workspace.upper[0] - 0.05, 60)
    sets = [active(np.r_[x, c[1:]]) for x in xs]
    i = next(i for i in range(len(xs) - 1) if sets[i] != sets[i + 1])
    lo, hi = xs[i], xs[i + 1]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if active(np.r_[mid, c[1:]]) == sets[i]:
            lo = mid
        else:
            hi = mid
    kappa = _kappa(robot, rows, scratch, np.r_[lo, c[1:]], R, w, 0.0)
    g = np.empty(3)
    assert not margin_gradient(scratch, rows, kappa, 0.0, g)


def test_the_look_ahead_s_margin_by_elimination_is_the_qr_s():
    # The look ahead's samples take the hard margin of a robot with one internal force by
    # Gaussian elimination (margin_by_elimination); the reference is margin's pivoted QR on
    # the same pose and wrench: the same max-min over the same line of tensions, so equal to
    # round-off, and -inf (no tension holds) at the same poses. Poses across and beyond the
    # workspace box, tilted, hands up to 40 N: most margins finite, some lost.
    from cdpm_drake.kernels.kinetostatics import (MARGIN_KAPPA, margin_by_elimination,
                                                  margin_in, margin_scratch, scratch_views)
    from cdpm_drake.kernels.rotation import rotation_from_rpy
    from cdpm_drake.kernels.tension import gravity_wrench
    from cdpm_drake.robot import load_robot, resolve_robot_path

    robot = load_robot(resolve_robot_path("paper_7cable"))
    views = scratch_views(margin_scratch(robot.num_cables))
    rng = np.random.default_rng(43)
    lo, hi = robot.workspace.lower, robot.workspace.upper
    finite = lost = 0
    for trial in range(600):
        p = rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo))
        R = rotation_from_rpy(rng.normal(size=3) * (0.0 if trial % 3 == 0 else 0.15))
        w = gravity_wrench(robot.dynamics.mass, rng.normal(size=3) * 20.0,
                           R @ robot.dynamics.handle)
        floor, ceiling = rng.uniform(0.0, 5.0), rng.uniform(50.0, 400.0)
        qr = margin_in(robot.reels, robot.attachments, 6, p, R, w, floor, ceiling, views,
                       0.0, MARGIN_KAPPA)[0]
        ge = margin_by_elimination(robot.reels, robot.attachments, 6, p, R, w, floor,
                                   ceiling, views)
        if np.isfinite(qr):
            finite += 1
            lost += qr < 0.0
            assert ge == pytest.approx(qr, rel=1e-9, abs=1e-9), (p, qr, ge)
        else:
            assert ge == qr
    assert finite == 600 and 50 < lost < 550, (finite, lost)
