"""The compiled dual active-set QP (cdpm_drake.kernels.qp) against independent references: the KKT
conditions (sufficient for a convex QP), Drake's Clarabel on the same problems, scipy's HiGHS
for feasibility, and closed forms."""

import numpy as np
import pytest
from scipy.optimize import linprog

from cdpm_drake.kernels.qp import QP_INFEASIBLE, QP_OPTIMAL, solve_qp


def _solve(w, z0, C, d):
    n, m = len(w), len(d)
    z, u = np.empty(n), np.empty(max(m, 1))
    C = np.asarray(C, dtype=float).reshape(m, n) if m else np.zeros((1, n))
    d = np.asarray(d, dtype=float) if m else np.zeros(1)
    status, active = solve_qp(np.asarray(w, float), np.asarray(z0, float), C, d, m, z, u, 200)
    return status, active, z, u[:m]


def _clarabel(w, z0, C, d):
    from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions

    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(len(w))
    prog.AddQuadraticCost(np.diag(w), -np.diag(w) @ z0, z, is_convex=True)
    if len(d):
        prog.AddLinearConstraint(C, d, np.full(len(d), np.inf), z)
    options = SolverOptions()
    for name in ("tol_gap_abs", "tol_gap_rel", "tol_feas"):
        options.SetOption(ClarabelSolver.id(), name, 1e-11)
    result = ClarabelSolver().Solve(prog, None, options)
    return result.is_success(), result.GetSolution(z)


def test_the_projection_onto_one_halfspace_is_the_closed_form():
    # min 1/2 |z - z0|^2 s.t. a.z >= b with a.z0 < b: z = z0 + (b - a.z0) a / |a|^2, and the
    # multiplier (b - a.z0) / |a|^2.
    a, b, z0 = np.array([1.0, 2.0, -2.0]), 3.0, np.array([0.5, -0.5, 0.25])
    status, active, z, u = _solve(np.ones(3), z0, a[None, :], [b])
    assert status == QP_OPTIMAL and active == 1
    gap = b - a @ z0
    np.testing.assert_allclose(z, z0 + gap * a / (a @ a), atol=1e-14)
    assert u[0] == pytest.approx(gap / (a @ a), rel=1e-12)


def test_weights_scale_the_move_per_coordinate():
    # min 1/2 (w1 x^2 + w2 y^2) s.t. x + y >= 1: x = w2 / (w1 + w2), y = w1 / (w1 + w2).
    w1, w2 = 1.0, 9.0
    status, _, z, _ = _solve([w1, w2], [0.0, 0.0], [[1.0, 1.0]], [1.0])
    assert status == QP_OPTIMAL
    np.testing.assert_allclose(z, [w2 / (w1 + w2), w1 / (w1 + w2)], atol=1e-14)


def test_a_met_constraint_leaves_the_target_alone():
    status, active, z, u = _solve(np.ones(2), [1.0, 1.0], [[1.0, 0.0]], [0.0])
    assert status == QP_OPTIMAL and active == 0
    np.testing.assert_array_equal(z, [1.0, 1.0])
    assert u[0] == 0.0


def test_contradicting_constraints_are_infeasible():
    # x >= 1 and -x >= 0 (x <= 0).
    status, _, _, _ = _solve([1.0], [0.0], [[1.0], [-1.0]], [1.0, 0.0])
    assert status == QP_INFEASIBLE


@pytest.mark.parametrize("seed", range(4))
def test_random_problems_meet_kkt_and_agree_with_clarabel(seed):
    rng = np.random.default_rng(seed)
    checked = infeasible = 0
    for trial in range(150):
        n = int(rng.integers(1, 7))
        m = int(rng.integers(0, 25))
        w = rng.uniform(0.1, 10.0, n)
        z0 = rng.normal(size=n)
        C = rng.normal(size=(m, n))
        d = rng.normal(size=m)
        if m > 2 and trial % 3 == 0:  # a repeated constraint (degenerate active sets)
            C[m // 2], d[m // 2] = C[0], d[0]
        status, _, z, u = _solve(w, z0, C, d)
        feasible = m == 0 or linprog(np.zeros(n), A_ub=-C, b_ub=-d,
                                     bounds=[(None, None)] * n, method="highs").status == 0
        if not feasible:
            assert status == QP_INFEASIBLE, (seed, trial)
            infeasible += 1
            continue
        assert status == QP_OPTIMAL, (seed, trial)
        scale = 1.0 + np.abs(u).max(initial=0.0) + np.abs(d).max(initial=0.0)
        # Stationarity, primal and dual feasibility, complementarity.
        stationarity = w * (z - z0) - (C.T @ u if m else 0.0)
        assert np.abs(stationarity).max() <= 1e-8 * scale
        if m:
            slack = C @ z - d
            assert slack.min() >= -1e-9 * scale
            assert u.min() >= 0.0
            assert np.abs(u * slack).max() <= 1e-8 * scale * scale
        ok, z_ref = _clarabel(w, z0, C, d)
        if ok:
            np.testing.assert_allclose(z, z_ref, atol=1e-6 * (1 + np.abs(z_ref).max()))
            checked += 1
    assert checked > 30 and infeasible > 0  # Clarabel gives up on some nearly infeasible ones
