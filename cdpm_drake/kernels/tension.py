"""Cable tensions of a platform in static equilibrium, compiled: the wrench matrix, t* and the
tension distribution with a floor tension where W's nullspace has one or two dimensions, and
the max-min of any number of lines. numpy and numba, no Drake: larger nullspaces go to
robot/tension_program.py (Clarabel), wrench feasibility over a robot's workspace is
robot/statics.py.

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
(robot/statics.py's `holding_tension`: the robot file's platform mass, its weight at the
centre) t* says by how much its cables can all stay taut.

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
the same nullspace coordinates (robot/tension_program.py: `max_min_tension`,
`tension_distribution`). The QR and the nullspace vectors are kernels/nullspace.py.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cdpm_drake.kernels.nullspace import (RANK_TOL, lam_interval, null_vector,
                                          particular_solution, pivoted_qr)
from cdpm_drake.kernels.qp import QP_INFEASIBLE, solve_qp

GRAVITY = 9.81  # m/s^2, along -z of the base frame
# distribution_kernel's status codes.
FEASIBLE, BELOW_FLOOR, GENERAL = 0, 1, 2

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


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


# --- the compiled one- and two-dimensional cases -----------------------------------------------


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
def max_min_grid(reels, attachments, points, wrenches, out):
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


# --- grids of points, the cables' stretch and the plant's time step -------------------------


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
