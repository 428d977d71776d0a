"""t* and tension distributions of any nullspace (robot/statics.py and the builder's start
check use them): the compiled closed forms of kernels/tension.py where W's nullspace has one or
two dimensions, and beyond, Drake's MathematicalProgram solved by Clarabel (an LP for t*, a QP
for the least-norm distribution), in the same nullspace coordinates T = T_p + N lam. Tensions
N, wrenches N and N m about the platform centre (kernels/tension.py's module docstring)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from cdpm_drake.kernels.nullspace import nullspace_form
from cdpm_drake.kernels.tension import (BELOW_FLOOR, FEASIBLE, GENERAL, distribution_1d,
                                        distribution_kernel, max_min_1d, max_min_2d)


class TensionError(ValueError):
    """The solver of a nullspace of two or more dimensions failed (neither an optimum nor
    a proof of unboundedness)."""


@dataclasses.dataclass(frozen=True)
class Distribution:
    """The outcome of `tension_distribution`: `tensions` (m,) N, the least-norm distribution
    with every cable >= the floor when `feasible`; otherwise a distribution that keeps the
    smallest tension largest (its minimum `best_min` N) and the 0-based cables at that
    minimum (`slack`: the ones that would go slack, or stay below the floor, first).
    `t_star` is the largest achievable minimum tension (N; +inf with an internal force that
    raises every tension, -inf when no tension balances the wrench)."""

    feasible: bool
    tensions: np.ndarray
    best_min: float
    slack: tuple[int, ...] = ()
    # Largest |W T + w| the solution leaves, N or N m (round-off when the wrench is reachable).
    residual: float = 0.0
    t_star: float = math.nan


def _out_of_range(residual, w) -> bool:
    return residual > 1e-9 * max(1.0, float(np.max(np.abs(w), initial=0.0)))


def _clarabel(prog):
    from pydrake.solvers import ClarabelSolver, SolverOptions

    options = SolverOptions()
    # Tighter than Clarabel's defaults (1e-8): t* is asked to 1e-6 N of an exact LP (it
    # comes within 1e-9 N of HiGHS, tests/kernels/test_tension.py).
    for name in ("tol_gap_abs", "tol_gap_rel", "tol_feas"):
        options.SetOption(ClarabelSolver.id(), name, 1e-10)
    return ClarabelSolver().Solve(prog, None, options)


def max_min_general(T_p, N):
    """(t*, lam*) of max over lam of min_i (T_p + N lam)_i for k = N.shape[1] >= 2, an LP in
    (lam, t) solved by Clarabel through Drake's MathematicalProgram; t* = +inf (lam* of
    nans) when the LP is unbounded."""
    from pydrake.solvers import MathematicalProgram, SolutionResult

    m, k = N.shape
    prog = MathematicalProgram()
    x = prog.NewContinuousVariables(k + 1, "x")  # lam, t
    prog.AddLinearConstraint(np.hstack([N, -np.ones((m, 1))]), -T_p, np.full(m, np.inf), x)
    prog.AddLinearCost(np.r_[np.zeros(k), -1.0], 0.0, x)
    result = _clarabel(prog)
    status = result.get_solution_result()
    if status == SolutionResult.kDualInfeasible:
        return math.inf, np.full(k, np.nan)
    if not result.is_success():
        raise TensionError(f"Clarabel found no largest minimum tension ({status}) for a "
                           f"{k}-dimensional nullspace")
    lam = result.GetSolution(x)[:k]
    return float(np.min(T_p + N @ lam)), lam


def _least_norm_general(T_p, N, floor):
    """lam of least norm with T_p + N lam >= floor (|T|^2 = |T_p|^2 + |lam|^2): a QP solved
    by Clarabel; None when Clarabel finds none."""
    from pydrake.solvers import MathematicalProgram

    m, k = N.shape
    prog = MathematicalProgram()
    lam = prog.NewContinuousVariables(k, "lam")
    prog.AddLinearConstraint(N, floor - T_p, np.full(m, np.inf), lam)
    prog.AddQuadraticCost(np.eye(k), np.zeros(k), lam, is_convex=True)
    result = _clarabel(prog)
    return result.GetSolution(lam) if result.is_success() else None


def _slack(T, t_star, scale) -> tuple[int, ...]:
    """The cables at the minimum of a max-min distribution."""
    return tuple(int(i) for i in np.flatnonzero(T <= t_star + 1e-6 * scale))


def max_min_tension(W, wrench) -> float:
    """t* (N): max t with W T + wrench = 0, T_i >= t (kernels/tension.py's docstring); +inf with an
    internal force that raises every tension, -inf when no T balances the wrench."""
    W = np.ascontiguousarray(W, dtype=float)
    w = np.ascontiguousarray(wrench, dtype=float)
    status, t = distribution_kernel(W, w, 0.0, np.empty(W.shape[1]))
    if status != GENERAL:
        return float(t)
    T_p, N, residual = nullspace_form(W, w)
    if _out_of_range(residual, w):
        return -math.inf
    if N.shape[1] == 0:
        return float(np.min(T_p))
    if N.shape[1] == 1:
        return float(max_min_1d(T_p, np.ascontiguousarray(N[:, 0]))[0])
    if N.shape[1] == 2:
        return float(max_min_2d(T_p, np.ascontiguousarray(N)))
    return max_min_general(T_p, N)[0]


def tension_distribution(W, wrench, min_tension: float = 0.0) -> Distribution:
    """Tensions T (m,) N with W T + wrench = 0 and every T_i >= min_tension, of least norm
    (`Distribution`). When t* < min_tension it is not feasible and the distribution returned
    keeps the smallest tension largest. A one-dimensional nullspace (7 cables, 6 DoF) is
    solved exactly by `distribution_kernel`; larger ones by Clarabel (an LP and a QP)."""
    W = np.ascontiguousarray(W, dtype=float)
    w = np.ascontiguousarray(wrench, dtype=float)
    floor = float(min_tension)
    m = W.shape[1]
    T = np.empty(m)
    status, t = distribution_kernel(W, w, floor, T)
    if status == GENERAL:
        T_p, N, residual = nullspace_form(W, w)
        if _out_of_range(residual, w):
            return Distribution(False, T_p, float(np.min(T_p)), tuple(range(m)), residual,
                                -math.inf)
        k = N.shape[1]
        if k == 1:
            n = np.ascontiguousarray(N[:, 0])
            status, t = distribution_1d(T_p, n, floor, T)
        else:
            if k == 0:
                t, lam = float(np.min(T_p)), np.zeros(0)
            else:
                t, lam = max_min_general(T_p, N)
            status = FEASIBLE if t >= floor - 1e-9 * max(1.0, abs(floor)) else BELOW_FLOOR
            if status == FEASIBLE:
                lam = np.zeros(0) if k == 0 else _least_norm_general(T_p, N, floor)
                if lam is None:  # Clarabel's QP failed where its LP succeeded: keep the LP's
                    lam = max_min_general(T_p, N)[1]
                T = np.maximum(T_p + N @ lam, floor)  # the max only removes round-off
            else:
                T = T_p + N @ lam
    t = float(t)
    residual = float(np.max(np.abs(W @ T + w)))
    if status == FEASIBLE:
        return Distribution(True, T, float(T.min()), (), residual, t)
    scale = max(1.0, float(np.max(np.abs(w))))
    return Distribution(False, T, t, _slack(T, t, scale), residual, t)
