"""Cable tensions of a platform in static equilibrium: the wrench matrix, the tension
distribution with a floor tension, and wrench feasibility over the workspace. numpy and numba;
Drake's MathematicalProgram (Clarabel) only inside the solver of nullspaces of two or more
dimensions, imported there.

The platform translates (frame B parallel to the base frame A) unless a rotation R_WB is
given; moments are taken about the platform centre (B's origin). Cable i pulls the platform
with tension T_i >= 0 along u_i, the unit vector from its attachment point B_i towards its
reel exit A_i. Equilibrium under an external wrench w = [f; n] (N, N m) at the centre is

    W T + w = 0,   W = [u_1 ... u_m; b_1 x u_1 ... b_m x u_m]   (6 x m),

with b_i the attachment point relative to the centre, in the base frame.

The one measure of statics used everywhere (robot validation, `cdpm info`, the calibration,
the workspace plots): t*, the largest achievable minimum cable tension,

    t* = max t  subject to  W T + w = 0,  T_i >= t  (i = 1..m),

+inf when an internal force (a positive nullspace vector of W) raises every tension at once,
-inf when no tension vector balances w (a wrench outside W's range). A tension distribution
with every cable >= a floor exists exactly when t* >= floor. For the platform hanging level
(`holding_tension`: the robot file's platform mass, its weight at the centre) t* says by how
much its cables can all stay taut.

How t* is computed. Every T with W T = -w is T = T_p + N lam (T_p the minimum-norm solution,
N an orthonormal basis of W's nullspace, k columns). For 7 cables and 6 DoF (k = 1) the
problem is one-dimensional, t* = max over lam of min_i (T_p,i + n_i lam), and its LP dual
(min sum mu_i T_p,i, sum mu_i = 1, sum mu_i n_i = 0, mu >= 0) has vertices with two
non-zeros, one cable with n_i > 0 and one with n_j < 0: t* is the smallest of
(T_p,i |n_j| + T_p,j n_i) / (n_i + |n_j|) over those pairs, exact in O(m^2) and computed with
a pivoted Householder QR, both compiled (`distribution_kernel`, ~1 us). For 8 cables
(k = 2) the dual's vertices have three non-zeros: t* is exact over the cable triples
(`max_min_2d`, compiled, a few us), which keeps workspace grids of 8-cable robots as fast as
7-cable ones (robot validation on load, `cdpm info`, the plots). The rest, the tension
distributions of k >= 2 and t* of k >= 3 (a rank-deficient W, more cables), go to Drake's
MathematicalProgram with Clarabel (an LP for t*, a QP for the least-norm distribution), in
the same nullspace coordinates.
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np

from cdpm_drake.kernels.qp import QP_INFEASIBLE, solve_qp

GRAVITY = 9.81  # m/s^2, along -z of the base frame

# W (r x m) counts as rank-deficient when the last pivot of its pivoted QR (or its smallest
# singular value) is below this fraction of the first: the nullspace is then treated as having
# more than m - r dimensions and the general solver decides. Far above round-off of unit
# vectors and moments of a few tenths of a metre, far below any pose a robot is used at.
RANK_TOL = 1e-9
# distribution_kernel's status codes.
FEASIBLE, BELOW_FLOOR, GENERAL = 0, 1, 2

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


class TensionError(ValueError):
    """The solver of a nullspace of two or more dimensions failed (neither an optimum nor
    a proof of unboundedness)."""


def wrench_matrix(robot, p, R_WB=None) -> np.ndarray:
    """W (6, m) at platform position p (base frame, m): column i is [u_i; b_i x u_i], the
    wrench (N, N m about the centre) a unit tension in cable i puts on the platform."""
    p = np.asarray(p, dtype=float)
    b = robot.attachments if R_WB is None else robot.attachments @ np.asarray(R_WB).T
    rho = robot.reels - (p + b)  # attachment -> reel exit
    u = rho / np.linalg.norm(rho, axis=-1, keepdims=True)
    return np.vstack([u.T, np.cross(b, u).T])


def gravity_wrench(mass: float, force=(0.0, 0.0, 0.0), handle=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The wrench (6,) on the platform of its weight (kg) plus a force (N, base frame) at the
    handle point (m, from the centre, base frame), about the centre."""
    f = np.asarray(force, dtype=float)
    return np.concatenate([f + [0.0, 0.0, -mass * GRAVITY], np.cross(handle, f)])


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


# --- the compiled one-dimensional case ---------------------------------------------------------


@_jit
def pivoted_qr(W, A, V, beta, perm):
    """Householder QR with column pivoting of W^T (m x r, r = W's rows): A[:r] holds R
    (upper triangular), V[k] and beta[k] the reflections H_k = I - beta_k v_k v_k^T, perm the
    pivot order of W's rows. Returns |R_rr| / |R_11| (0 for a zero W)."""
    r, m = W.shape
    for i in range(m):
        for j in range(r):
            A[i, j] = W[j, i]
    for j in range(r):
        perm[j] = j
    for k in range(r):
        best, best_norm = k, -1.0
        for j in range(k, r):
            s = 0.0
            for i in range(k, m):
                s += A[i, j] * A[i, j]
            if s > best_norm:
                best, best_norm = j, s
        if best != k:
            for i in range(m):
                A[i, k], A[i, best] = A[i, best], A[i, k]
            perm[k], perm[best] = perm[best], perm[k]
        for i in range(m):
            V[k, i] = 0.0
        norm = math.sqrt(best_norm)
        if norm == 0.0:
            beta[k] = 0.0
            continue
        alpha = -norm if A[k, k] >= 0.0 else norm
        vv = 0.0
        for i in range(k, m):
            V[k, i] = A[i, k]
        V[k, k] -= alpha
        for i in range(k, m):
            vv += V[k, i] * V[k, i]
        beta[k] = 2.0 / vv
        for j in range(k, r):
            s = 0.0
            for i in range(k, m):
                s += V[k, i] * A[i, j]
            s *= beta[k]
            for i in range(k, m):
                A[i, j] -= s * V[k, i]
    first = abs(A[0, 0])
    return abs(A[r - 1, r - 1]) / first if first > 0.0 else 0.0


@_jit
def _apply_q(V, beta, z):
    """z <- Q z, Q = H_0 H_1 ... H_{r-1}."""
    r, m = V.shape
    for k in range(r - 1, -1, -1):
        s = 0.0
        for i in range(k, m):
            s += V[k, i] * z[i]
        s *= beta[k]
        for i in range(k, m):
            z[i] -= s * V[k, i]


@_jit
def particular_solution(A, V, beta, perm, w, T_p):
    """T_p, the minimum-norm T with W T = -w, from the QR of W^T: R^T y = -w[perm],
    T_p = Q [y; 0]."""
    r, m = V.shape
    for j in range(r):
        s = -w[perm[j]]
        for i in range(j):
            s -= A[i, j] * T_p[i]
        T_p[j] = s / A[j, j]
    for i in range(r, m):
        T_p[i] = 0.0
    _apply_q(V, beta, T_p)


@_jit
def null_vector(V, beta, n, k=0):
    """The unit vector n = Q e_(r+k), Q's column r + k: W's nullspace is spanned by columns
    r..m-1 of Q (m = r + 1: n spans it)."""
    r = V.shape[0]
    for i in range(n.size):
        n[i] = 0.0
    n[r + k] = 1.0
    _apply_q(V, beta, n)


@_jit
def max_min_1d(T_p, n):
    """t* = max over lam of min_i (T_p[i] + n[i] lam), exactly: the smallest value of the
    LP dual's vertices, (T_p[i] |n[j]| + T_p[j] n[i]) / (n[i] + |n[j]|) over the cables with
    n[i] > 0 and n[j] < 0, and T_p[i] where n[i] == 0; +inf when no vertex exists (every
    n[i] of one sign: lam raises every tension). Returns (t*, lam*) with lam* a maximiser
    (nan when t* is infinite)."""
    m = T_p.size
    t = math.inf
    for i in range(m):
        if n[i] > 0.0:
            for j in range(m):
                if n[j] < 0.0:
                    v = (T_p[i] * (-n[j]) + T_p[j] * n[i]) / (n[i] - n[j])
                    if v < t:
                        t = v
        elif n[i] == 0.0 and T_p[i] < t:
            t = T_p[i]
    if t == math.inf:
        return t, math.nan
    lo, hi = lam_interval(T_p, n, t)
    if lo == -math.inf:
        return t, hi
    if hi == math.inf:
        return t, lo
    return t, 0.5 * (lo + hi)


@_jit
def lam_interval(T_p, n, floor):
    """[lo, hi]: the lam with T_p[i] + n[i] lam >= floor for every cable with n[i] != 0."""
    lo, hi = -math.inf, math.inf
    for i in range(T_p.size):
        if n[i] > 0.0:
            lo = max(lo, (floor - T_p[i]) / n[i])
        elif n[i] < 0.0:
            hi = min(hi, (floor - T_p[i]) / n[i])
    return lo, hi


@_jit
def max_min_2d(T_p, N):
    """t* = max over lam (2,) of min_i (T_p[i] + N[i] . lam) for a two-dimensional nullspace
    (N (m, 2), 8 cables and 6 DoF), exactly: the LP dual (min sum mu_i T_p,i, sum mu_i = 1,
    sum mu_i N[i] = 0, mu >= 0) has vertices with three non-zeros, so t* is the smallest
    mu . T_p over the triples of cables whose 3 x 3 system [1; N^T] mu = e_1 has a solution
    mu >= 0 (the origin inside the triangle of their N rows); +inf when none has (an internal
    force raises every tension)."""
    m = T_p.size
    t = math.inf
    for i in range(m):
        for j in range(i + 1, m):
            for k in range(j + 1, m):
                # mu = e_1 solved by Cramer's rule on the columns (1, N[c, 0], N[c, 1]).
                xi, yi = N[i, 0], N[i, 1]
                xj, yj = N[j, 0], N[j, 1]
                xk, yk = N[k, 0], N[k, 1]
                det = (xj * yk - xk * yj) - (xi * yk - xk * yi) + (xi * yj - xj * yi)
                if det == 0.0:
                    continue
                mi = (xj * yk - xk * yj) / det
                mj = (xk * yi - xi * yk) / det
                mk = (xi * yj - xj * yi) / det
                if mi >= 0.0 and mj >= 0.0 and mk >= 0.0:
                    v = mi * T_p[i] + mj * T_p[j] + mk * T_p[k]
                    if v < t:
                        t = v
    return t


@_jit
def distribution_1d(T_p, n, floor, T):
    """The tension distribution of a one-dimensional nullspace T = T_p + n lam (T_p
    perpendicular to the unit n): into T the least-norm one with every T_i >= floor when
    t* >= floor (status FEASIBLE), else a max-min one (BELOW_FLOOR). Returns (status, t*)."""
    t, lam_star = max_min_1d(T_p, n)
    # Round-off of t* itself (a few ulp of the tensions) must not turn a floor that t*
    # reaches into "infeasible".
    scale = 1.0
    for i in range(T_p.size):
        scale = max(scale, abs(T_p[i]))
    if t >= floor - 1e-12 * max(scale, abs(floor)):
        lo, hi = lam_interval(T_p, n, floor)
        lam = lam_star if lo > hi else min(max(0.0, lo), hi)  # |T|^2 = |T_p|^2 + lam^2
        for i in range(T.size):
            T[i] = max(T_p[i] + n[i] * lam, floor)  # the max only removes round-off
        return FEASIBLE, t
    for i in range(T.size):
        T[i] = T_p[i] + n[i] * lam_star
    return BELOW_FLOOR, t


@_jit
def distribution_kernel(W, w, floor, T):
    """The per-tick tension distribution of W (r x m) under the wrench w (r,), N and N m, with
    a floor (N), written into T (m,) N. Returns (status, t*): FEASIBLE, T the least-norm
    distribution with every T_i >= floor; BELOW_FLOOR, t* < floor and T a max-min
    distribution; GENERAL (T untouched, t* nan) when W's nullspace is not one-dimensional
    (m != r + 1, or W rank-deficient): `tension_distribution` then decides. Allocates only
    its scratch arrays; bind it with kernel_call.bind for a control loop."""
    r, m = W.shape
    if m != r + 1:
        return GENERAL, math.nan
    A, V = np.empty((m, r)), np.empty((r, m))
    beta, perm = np.empty(r), np.empty(r, dtype=np.int64)
    if pivoted_qr(W, A, V, beta, perm) < RANK_TOL:
        return GENERAL, math.nan
    T_p, n = np.empty(m), np.empty(m)
    particular_solution(A, V, beta, perm, w, T_p)
    null_vector(V, beta, n)
    return distribution_1d(T_p, n, floor, T)


@_jit
def level_wrench_matrix(reels, attachments, p, W):
    """W (6, m): column i = [u_i; b_i x u_i], the wrench (N, N m about the platform's centre)
    of a unit tension in cable i of the level platform at p (m); u_i points from the
    attachment to the reel."""
    for i in range(reels.shape[0]):
        bx, by, bz = attachments[i, 0], attachments[i, 1], attachments[i, 2]
        x = reels[i, 0] - p[0] - bx
        y = reels[i, 1] - p[1] - by
        z = reels[i, 2] - p[2] - bz
        L = math.sqrt(x * x + y * y + z * z)
        x, y, z = x / L, y / L, z / L
        W[0, i], W[1, i], W[2, i] = x, y, z
        W[3, i], W[4, i], W[5, i] = by * z - bz * y, bz * x - bx * z, bx * y - by * x


@_jit
def _grid_kernel(reels, attachments, points, wrenches, out):
    """out[k, j] = t* of the level platform at points[k] under wrenches[j] (the one
    definition: W from the translated attachments), exact for 7 and 8 cables; nan where W is
    rank-deficient or the nullspace has more dimensions (the caller solves those)."""
    m = reels.shape[0]
    W = np.empty((6, m))
    A, V = np.empty((m, 6)), np.empty((6, m))
    beta, perm = np.empty(6), np.empty(6, dtype=np.int64)
    T_p, n, N = np.empty(m), np.empty(m), np.empty((m, 2))
    for k in range(points.shape[0]):
        level_wrench_matrix(reels, attachments, points[k], W)
        if (m != 7 and m != 8) or pivoted_qr(W, A, V, beta, perm) < RANK_TOL:
            for j in range(wrenches.shape[0]):
                out[k, j] = math.nan
            continue
        for c in range(m - 6):
            null_vector(V, beta, n, c)
            for i in range(m):
                N[i, c] = n[i]
        for j in range(wrenches.shape[0]):
            particular_solution(A, V, beta, perm, wrenches[j], T_p)
            out[k, j] = max_min_1d(T_p, n)[0] if m == 7 else max_min_2d(T_p, N)


# --- any nullspace -----------------------------------------------------------------------------


def nullspace_form(W, w):
    """(T_p, N, residual): the minimum-norm T with W T = -w, an orthonormal nullspace basis
    (m, k), and the largest |W T_p + w| (above round-off: w is outside W's range)."""
    U, s, Vt = np.linalg.svd(W)
    rank = int(np.sum(s > RANK_TOL * s[0])) if s.size and s[0] > 0 else 0
    T_p = Vt[:rank].T @ ((U[:, :rank].T @ -w) / s[:rank])
    return T_p, Vt[rank:].T, float(np.max(np.abs(W @ T_p + w), initial=0.0))


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
    """t* (N): max t with W T + wrench = 0, T_i >= t (module docstring); +inf with an
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


# --- over the workspace ------------------------------------------------------------------------


def max_min_tensions(robot, points, wrenches) -> np.ndarray:
    """t* (N, K) N of the level platform (translated, not rotated) at each of points (N, 3) m
    under each of wrenches (K, 6) N, N m: compiled for 7 and 8 cables (one- and
    two-dimensional nullspaces), `max_min_tension` point by point where that does not
    apply."""
    points = np.ascontiguousarray(np.reshape(points, (-1, 3)), dtype=float)
    wrenches = np.ascontiguousarray(np.reshape(wrenches, (-1, 6)), dtype=float)
    out = np.empty((len(points), len(wrenches)))
    _grid_kernel(np.ascontiguousarray(robot.reels), np.ascontiguousarray(robot.attachments),
                 points, wrenches, out)
    for k in np.flatnonzero(np.isnan(out).any(axis=1)):
        W = wrench_matrix(robot, points[k])
        out[k] = [max_min_tension(W, w) for w in wrenches]
    return out


def holding_tension(robot, points, mass: float | None = None) -> np.ndarray:
    """t* (N) of the level platform at points (..., 3) m holding its own weight: mass (kg,
    default the robot file's platform mass) at its centre, moments about the centre, no other
    force. The one measure of "the cables can hold the platform here" in this package."""
    points = np.asarray(points, dtype=float)
    mass = robot.dynamics.mass if mass is None else float(mass)
    t = max_min_tensions(robot, points, gravity_wrench(mass)[None, :])[:, 0]
    return t.reshape(points.shape[:-1])


def hand_force_directions() -> np.ndarray:
    """The 26 unit directions of a 3x3x3 cube's faces, edges and corners (a hand may push any
    way; these bracket every direction within 35 degrees)."""
    d = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                  if (i, j, k) != (0, 0, 0)], dtype=float)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def grid_points(lower, upper, n: int) -> np.ndarray:
    """n x n x n points spanning the box [lower, upper] (m), corners included; (n^3, 3)."""
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(lower, upper)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def step_grid(lower, upper, step: float) -> np.ndarray:
    """The points lower + k step (m) inside the box [lower, upper] along each axis, upper
    corner included when a whole number of steps reaches it; (N, 3), x slowest. The grid
    of the statics shares quoted in the robot files and by `cdpm info` (step 0.05 m: 51 x 65
    x 43 points for paper_7cable)."""
    axes = [np.arange(lo, hi + 1e-9, step) for lo, hi in zip(lower, upper)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


@dataclasses.dataclass(frozen=True)
class Feasibility:
    """Wrench feasibility over a grid: `points` (N, 3) m and `feasible` (N,) bool, and the
    smallest t* (N,) over the hand-force directions at each point."""

    points: np.ndarray
    feasible: np.ndarray
    t_star: np.ndarray | None = None

    @property
    def share(self) -> float:
        return float(np.mean(self.feasible)) if self.feasible.size else 0.0


def wrench_feasibility(robot, *, mass: float, hand_force: float = 0.0, handle=(0.0, 0.0, 0.0),
                       min_tension: float = 0.0, n: int = 5, directions=None,
                       points=None) -> Feasibility:
    """Where, on an n^3 grid of the robot's workspace box (or at `points` (N, 3) m), a
    tension distribution with every cable >= min_tension (N) balances the platform's weight
    (mass, kg) plus a hand force of size hand_force (N) at the handle point (m, platform
    frame) in every one of `directions` (default: hand_force_directions(); none when
    hand_force is 0)."""
    pts = (grid_points(robot.workspace.lower, robot.workspace.upper, n) if points is None
           else np.reshape(np.asarray(points, dtype=float), (-1, 3)))
    if hand_force > 0:
        dirs = hand_force_directions() if directions is None else np.asarray(directions, float)
        forces = hand_force * dirs
    else:
        forces = np.zeros((1, 3))
    wrenches = np.array([gravity_wrench(mass, f, handle) for f in forces])
    t = max_min_tensions(robot, pts, wrenches).min(axis=1)
    return Feasibility(pts, t >= min_tension, t)


def unstretched_lengths(lengths, tensions, EA):
    """L0 (m) that stretch to `lengths` (m) under `tensions` (N): T = EA (L - L0) / L0."""
    lengths = np.asarray(lengths, dtype=float)
    return lengths * EA / (EA + np.asarray(tensions, dtype=float))


def stable_time_step(robot, p, R_WB, tensions, locked: bool = False) -> float:
    """The largest plant time step (s) that keeps the explicit cable forces stable at the
    start pose (p m, R_WB): 2 / omega_max (symplectic Euler is stable for h omega < 2), with
    omega_max^2 the largest eigenvalue of M^-1 K; K = W diag(EA / L0_i + T_i / L_i) W^T is
    the cables' axial stiffness (plus a bound on the tensions' geometric stiffness) in the
    platform's twist coordinates, M its mass and inertia (only the translation when the
    rotation is `locked`)."""
    d = robot.dynamics
    lengths = np.linalg.norm(robot.reels - (p + robot.attachments @ R_WB.T), axis=1)
    L0 = unstretched_lengths(lengths, tensions, d.EA)
    W = wrench_matrix(robot, p, R_WB)
    K = W @ np.diag(d.EA / L0 + tensions / lengths) @ W.T
    M = np.zeros((6, 6))
    M[:3, :3] = d.mass * np.eye(3)
    M[3:, 3:] = d.inertia
    if locked:
        K, M = K[:3, :3], M[:3, :3]
    L_inv = np.linalg.inv(np.linalg.cholesky(M))
    omega2 = float(np.linalg.eigvalsh(L_inv @ K @ L_inv.T).max())
    return 2.0 / math.sqrt(max(omega2, 1e-300))


def balancing_rotation(robot, p, *, mass: float, min_tension: float = 0.0,
                       max_angle: float = 0.4, step: float = 0.05, handle=(0.0, 0.0, 0.0)):
    """The smallest platform tilt (roll, pitch, yaw, rad; on a grid of `step` rad within
    +-max_angle per angle) at which a tension distribution with every cable >= min_tension
    (N) holds the platform's weight at p (m); None when no grid point does. A platform whose
    cables cannot hold it level hangs tilted: this says how much."""
    from cdpm_drake.kernels.rotation import rotation_from_rpy

    k = int(round(max_angle / step))
    g = step * np.arange(-k, k + 1)  # exact zeros: a grid from arange(-max, max, step) has -1e-16
    rpys = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    rpys = rpys[np.argsort(np.linalg.norm(rpys, axis=1), kind="stable")]
    wrench = gravity_wrench(mass)
    for rpy in rpys:
        R = rotation_from_rpy(rpy)
        W = wrench_matrix(robot, p, R)
        if max_min_tension(W, wrench) >= min_tension:
            return rpy
    return None


# --- a robot's statics in one look (validation on load, `cdpm info`) --------------------------


@dataclasses.dataclass(frozen=True)
class Statics:
    """How well a robot's cables hold its level platform (`holding_tension`): the wrench
    matrix rank at the workspace centre and, if below 6, the wrench direction (unit, [force;
    moment] about the centre) no tension can produce; t* at the centre (N); the share of an
    n x n x n grid of the workspace box (corners included) held with every cable >= floor (N);
    the platform mass (kg) it was computed for."""

    rank: int
    unreachable: np.ndarray | None
    centre_t_star: float
    share: float
    floor: float
    n: int
    mass: float


def workspace_statics(robot, floor: float = 5.0, n: int = 11,
                      mass: float | None = None) -> Statics:
    """The `Statics` of a robot: a few milliseconds for 7 and 8 cables (compiled closed
    forms), Clarabel point by point otherwise."""
    mass = robot.dynamics.mass if mass is None else float(mass)
    c = robot.workspace.center
    W = wrench_matrix(robot, c)
    U, s, _ = np.linalg.svd(W)
    rank = int(np.sum(s > RANK_TOL * max(s[0], 1e-300)))
    unreachable = U[:, rank].copy() if rank < W.shape[0] else None
    t = holding_tension(robot, grid_points(robot.workspace.lower, robot.workspace.upper, n),
                        mass)
    return Statics(rank, unreachable, float(holding_tension(robot, c, mass)),
                   float(np.mean(t >= floor)), float(floor), int(n), mass)


def point_platform_share(robot, floor: float = 5.0, n: int = 5,
                         mass: float | None = None) -> float:
    """The share `workspace_statics` would find if the platform were a point (forces only,
    the attachment points ignored): where it is much larger than the real share, the moment
    balance (the attachment points) is what fails. Clarabel per point (~0.5 ms)."""
    mass = robot.dynamics.mass if mass is None else float(mass)
    w = gravity_wrench(mass)[:3]
    pts = grid_points(robot.workspace.lower, robot.workspace.upper, n)
    rho = robot.reels[None, :, :] - pts[:, None, :]  # every cable to the centre
    U = rho / np.linalg.norm(rho, axis=-1, keepdims=True)
    return float(np.mean([max_min_tension(u.T, w) >= floor for u in U]))


# --- the max-min of any number of lines, compiled (the safety filter's kinetostatic margin,
# the tension target of nullspaces of any dimension) ----------------------------------------

# max_min_lines for k >= 2 solves the LP max t s.t. a_j + C_j . lam >= t as the QP
# min 1/2 (LINES_WEIGHT |lam|^2 + (t - M)^2) with M far above any bounded optimum: it returns
# t within ~LINES_WEIGHT |lam| |dlam/dt| / (M - t) of the LP's (1e-6 N for tensions of
# hundreds of N, tests/kernels/test_kinetostatics.py against HiGHS) and a maximiser lam of small norm.
LINES_WEIGHT = 1e-6


@_jit
def max_min_lines(a, C, lam):
    """max over lam (k,) of min_j (a[j] + C[j] . lam) for K lines (a (K,), C (K, k)); +inf
    when unbounded (a direction raises every line), and a maximiser written into lam (zero
    where unbounded). k = 0: min(a); k = 1: exact (`max_min_1d`); k >= 2: the LP as a QP
    (LINES_WEIGHT), solved by qp.solve_qp."""
    K, k = C.shape
    if K == 0:
        for c in range(k):
            lam[c] = 0.0
        return math.inf
    top = a[0]
    for j in range(K):
        top = max(top, a[j])
    if k == 0:
        t = a[0]
        for j in range(K):
            t = min(t, a[j])
        return t
    if k == 1:
        t, l = max_min_1d(a, C[:, 0])
        lam[0] = l if math.isfinite(l) else 0.0
        return t
    # A bounded optimum is a convex combination of the a[j] (LP duality), so <= top.
    t = max_min_lines_subject_to(a, C, C[:0], a[:0], top, lam)
    if t > top + 1e-6 * (1.0 + abs(top)):
        for c in range(k):
            lam[c] = 0.0
        return math.inf
    return t


@_jit
def max_min_lines_subject_to(a, C, E, f, top, lam):
    """max over lam (k,) of min_j (a[j] + C[j] . lam) subject to E lam >= f (rows of E (J,
    k), f (J,)), for k >= 1, with the optimum known to be at most `top` where it is bounded:
    the LP max t s.t. a_j + C_j . lam >= t, E lam >= f as max_min_lines' QP (LINES_WEIGHT, t
    pulled towards a point far above top), solved by qp.solve_qp. Returns the maximum (-inf
    when no lam meets E lam >= f) and writes a maximiser into lam. (The tension target's
    largest minimum under a ceiling, and its smallest largest tension above a floor.)"""
    K, k = C.shape
    J = E.shape[0]
    M = top + 1e4 * (1.0 + abs(top))
    w = np.full(k + 1, LINES_WEIGHT)
    w[k] = 1.0
    z0 = np.zeros(k + 1)
    z0[k] = M
    Cq = np.empty((K + J, k + 1))
    d = np.empty(K + J)
    for j in range(K):
        for c in range(k):
            Cq[j, c] = C[j, c]
        Cq[j, k] = -1.0
        d[j] = -a[j]
    for j in range(J):
        for c in range(k):
            Cq[K + j, c] = E[j, c]
        Cq[K + j, k] = 0.0
        d[K + j] = f[j]
    z, u = np.empty(k + 1), np.empty(K + J)
    status, _ = solve_qp(w, z0, Cq, d, K + J, z, u, 100 + 4 * (K + J))
    if status == QP_INFEASIBLE:
        for c in range(k):
            lam[c] = 0.0
        return -math.inf
    t = math.inf
    for j in range(K):
        s = a[j]
        for c in range(k):
            s += C[j, c] * z[c]
        t = min(t, s)
    for c in range(k):
        lam[c] = z[c]
    return t
