"""Full-pose kinematics of a CDPM whose platform also rotates (beyond the paper, which assumes
pure translation): forward kinematics of position AND orientation from m >= 6 cable lengths,
the m x 6 Jacobian, rotation vectors. numpy and numba, no Drake.

Base frame A, SI units. The pose is (p, R): p the platform centre (m), R = R_WB the platform's
orientation; attachment point i is at B_i = p + R b_i, cable i runs from B_i to the reel exit
a_i, its rigid length is L_i = |a_i - B_i| and u_i = (a_i - B_i) / L_i. A twist (v, w) (m/s,
rad/s, base frame, about the centre) changes the lengths at

    L_dot_i = -u_i . (v + w x R b_i) = -[u_i ; R b_i x u_i] . [v ; w],

so the m x 6 Jacobian is J = -W^T with W the wrench matrix (tension.wrench_matrix): a length
residual along W's nullspace is one no pose change can remove. Orientation increments are
rotation vectors in the base frame: R <- exp([phi]x) R.
"""

import math

import numba
import numpy as np
from numpy.lib.stride_tricks import as_strided

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def rotation_exp(phx, phy, phz, out):
    """exp([phi]x) (Rodrigues) into out (3, 3); phi a rotation vector, rad."""
    th2 = phx * phx + phy * phy + phz * phz
    th = math.sqrt(th2)
    if th < 1e-8:  # second order: exact to round-off below 1e-8 rad
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    out[0, 0] = 1.0 - b * (phy * phy + phz * phz)
    out[1, 1] = 1.0 - b * (phx * phx + phz * phz)
    out[2, 2] = 1.0 - b * (phx * phx + phy * phy)
    out[0, 1] = b * phx * phy - a * phz
    out[1, 0] = b * phx * phy + a * phz
    out[0, 2] = b * phx * phz + a * phy
    out[2, 0] = b * phx * phz - a * phy
    out[1, 2] = b * phy * phz - a * phx
    out[2, 1] = b * phy * phz + a * phx


@_jit
def rotation_log(R):
    """The rotation vector phi (3 floats, rad, |phi| <= pi) with exp([phi]x) = R."""
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    c = min(1.0, max(-1.0, c))
    th = math.acos(c)
    wx, wy, wz = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    if th < 1e-6:
        k = 0.5 + th * th / 12.0
        return wx * k, wy * k, wz * k
    if th < math.pi - 1e-6:
        k = th / (2.0 * math.sin(th))
        return wx * k, wy * k, wz * k
    # Near pi: from the diagonal (the axis up to sign), the sign from the skew part.
    x = math.sqrt(max(0.0, (R[0, 0] + 1.0) / 2.0))
    y = math.sqrt(max(0.0, (R[1, 1] + 1.0) / 2.0))
    z = math.sqrt(max(0.0, (R[2, 2] + 1.0) / 2.0))
    if x >= y and x >= z:
        y, z = math.copysign(y, R[0, 1] + R[1, 0]), math.copysign(z, R[0, 2] + R[2, 0])
    elif y >= z:
        x, z = math.copysign(x, R[0, 1] + R[1, 0]), math.copysign(z, R[1, 2] + R[2, 1])
    else:
        x, y = math.copysign(x, R[0, 2] + R[2, 0]), math.copysign(y, R[1, 2] + R[2, 1])
    n = math.sqrt(x * x + y * y + z * z)
    return th * x / n, th * y / n, th * z / n


@_jit
def _orthonormalize(R):
    """R <- the nearest rotation to first order (Gram-Schmidt on the rows), so a rotation
    carried through many small updates stays one."""
    n = math.sqrt(R[0, 0] ** 2 + R[0, 1] ** 2 + R[0, 2] ** 2)
    for j in range(3):
        R[0, j] /= n
    d = R[1, 0] * R[0, 0] + R[1, 1] * R[0, 1] + R[1, 2] * R[0, 2]
    for j in range(3):
        R[1, j] -= d * R[0, j]
    n = math.sqrt(R[1, 0] ** 2 + R[1, 1] ** 2 + R[1, 2] ** 2)
    for j in range(3):
        R[1, j] /= n
    R[2, 0] = R[0, 1] * R[1, 2] - R[0, 2] * R[1, 1]
    R[2, 1] = R[0, 2] * R[1, 0] - R[0, 0] * R[1, 2]
    R[2, 2] = R[0, 0] * R[1, 1] - R[0, 1] * R[1, 0]


@_jit
def posed_cables(reels, attachments, p, R, u, Rb, L):
    """For pose (p, R): unit vectors u (m, 3) from B_i to a_i, R b_i (m, 3), rigid lengths
    L (m,)."""
    for i in range(reels.shape[0]):
        for r in range(3):
            Rb[i, r] = (R[r, 0] * attachments[i, 0] + R[r, 1] * attachments[i, 1]
                        + R[r, 2] * attachments[i, 2])
        x = reels[i, 0] - p[0] - Rb[i, 0]
        y = reels[i, 1] - p[1] - Rb[i, 1]
        z = reels[i, 2] - p[2] - Rb[i, 2]
        n = math.sqrt(x * x + y * y + z * z)
        L[i] = n
        u[i, 0], u[i, 1], u[i, 2] = x / n, y / n, z / n


@_jit
def wrench_columns(u, Rb, W):
    """W (6, m): column i = [u_i; R b_i x u_i], the wrench (N, N m about the centre) of a
    unit tension in cable i."""
    for i in range(u.shape[0]):
        W[0, i], W[1, i], W[2, i] = u[i, 0], u[i, 1], u[i, 2]
        W[3, i] = Rb[i, 1] * u[i, 2] - Rb[i, 2] * u[i, 1]
        W[4, i] = Rb[i, 2] * u[i, 0] - Rb[i, 0] * u[i, 2]
        W[5, i] = Rb[i, 0] * u[i, 1] - Rb[i, 1] * u[i, 0]


@_jit
def matrix_view(buf, o, r, c):
    """buf[o:o + r c] as an r x c matrix (C order, the same floats): as_strided, not numba's
    general reshape, which costs ~25 ns a view on a kernel's per-tick work arrays."""
    return as_strided(buf[o:o + r * c], shape=(r, c), strides=(c * buf.itemsize, buf.itemsize))


@_jit
def cholesky(A):
    """A (n, n) symmetric positive definite overwritten by its Cholesky factor (lower triangle
    and diagonal; the strict upper triangle is left as it was). False when A is not positive
    definite to working precision (A is then partly overwritten)."""
    n = A.shape[0]
    scale = 0.0
    for i in range(n):
        scale = max(scale, A[i, i])
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= A[j, k] * A[j, k]
        if not s > 1e-13 * scale:
            return False
        A[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / A[j, j]
    return True


@_jit
def cholesky_solve(F, g, x):
    """x = A^-1 g from A's factor F (`cholesky`): forward then back substitution. g is read
    only; x may not alias it. A factor solves any number of right-hand sides."""
    n = F.shape[0]
    for i in range(n):
        s = g[i]
        for k in range(i):
            s -= F[i, k] * x[k]
        x[i] = s / F[i, i]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, n):
            s -= F[k, i] * x[k]
        x[i] = s / F[i, i]


@_jit
def solve_spd(A, g, x):
    """x = A^-1 g for a symmetric positive definite A (n, n) by Cholesky (A is overwritten
    by its factor: `cholesky`, then `cholesky_solve`). False when A is not positive definite
    to working precision (x then untouched)."""
    if not cholesky(A):
        return False
    cholesky_solve(A, g, x)
    return True


@_jit
def pose_fk(reels, attachments, lengths, p_guess, R_guess, tol, max_iterations, p, R,
            residual):
    """Gauss-Newton for the pose (p, R) whose rigid lengths best fit `lengths` (m,) in least
    squares, from (p_guess, R_guess); writes p (3,), R (3, 3) and the residual lengths(p, R) -
    lengths (m,) m. True when the step settles below tol (m and rad) within max_iterations.
    The guess may be the output arrays."""
    m = reels.shape[0]
    for r in range(3):
        p[r] = p_guess[r]
        for c in range(3):
            R[r, c] = R_guess[r, c]
    u, Rb, L = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    A, g, x = np.empty((6, 6)), np.empty(6), np.empty(6)
    dR, tmp = np.empty((3, 3)), np.empty((3, 3))
    J = np.empty(6)
    for _ in range(max_iterations):
        posed_cables(reels, attachments, p, R, u, Rb, L)
        for a in range(6):
            g[a] = 0.0
            for b in range(6):
                A[a, b] = 0.0
        for i in range(m):
            # dL_i / d(p, phi) = -[u_i ; R b_i x u_i]; r_i = L_i - l_i.
            J[0], J[1], J[2] = -u[i, 0], -u[i, 1], -u[i, 2]
            J[3] = -(Rb[i, 1] * u[i, 2] - Rb[i, 2] * u[i, 1])
            J[4] = -(Rb[i, 2] * u[i, 0] - Rb[i, 0] * u[i, 2])
            J[5] = -(Rb[i, 0] * u[i, 1] - Rb[i, 1] * u[i, 0])
            r = L[i] - lengths[i]
            residual[i] = r
            for a in range(6):
                g[a] -= J[a] * r
                for b in range(a, 6):
                    A[a, b] += J[a] * J[b]
        for a in range(6):
            for b in range(a):
                A[a, b] = A[b, a]
        if not solve_spd(A, g, x):
            return False
        for r in range(3):
            p[r] += x[r]
        rotation_exp(x[3], x[4], x[5], dR)
        for r in range(3):
            for c in range(3):
                tmp[r, c] = dR[r, 0] * R[0, c] + dR[r, 1] * R[1, c] + dR[r, 2] * R[2, c]
        for r in range(3):
            for c in range(3):
                R[r, c] = tmp[r, c]
        _orthonormalize(R)
        step = 0.0
        for a in range(6):
            step += x[a] * x[a]
        if step < tol * tol:
            posed_cables(reels, attachments, p, R, u, Rb, L)
            for i in range(m):
                residual[i] = L[i] - lengths[i]
            return True
    return False


def pose_lengths(robot, p, R) -> np.ndarray:
    """Rigid cable lengths (m,) m of the platform at p (3,) m with orientation R (3, 3)."""
    B = np.asarray(p, dtype=float) + robot.attachments @ np.asarray(R, dtype=float).T
    return np.linalg.norm(robot.reels - B, axis=1)


def pose_jacobian(robot, p, R) -> np.ndarray:
    """J (m, 6) with L_dot = J [v; w] (m/s, rad/s, base frame, about the centre)."""
    m = robot.num_cables
    u, Rb, L = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    posed_cables(np.ascontiguousarray(robot.reels, dtype=float),
                 np.ascontiguousarray(robot.attachments, dtype=float),
                 np.asarray(p, dtype=float), np.asarray(R, dtype=float), u, Rb, L)
    return -np.hstack([u, np.cross(Rb, u)])


class PoseError(RuntimeError):
    """Full-pose forward kinematics failed to settle."""


def forward_pose(robot, lengths, p_guess=None, R_guess=None, tol: float = 1e-12,
                 max_iterations: int = 50):
    """(p (3,) m, R (3, 3), residual (m,) m) of the pose whose rigid lengths best fit
    `lengths` (m,) m, from a guess (default: the workspace centre, level). Needs m >= 6."""
    m = robot.num_cables
    if m < 6:
        raise PoseError(f"a full pose needs at least 6 cables; robot {robot.name!r} has {m}")
    p_guess = robot.workspace.center if p_guess is None else p_guess
    R_guess = np.eye(3) if R_guess is None else R_guess
    p, R, r = np.empty(3), np.empty((3, 3)), np.empty(m)
    ok = pose_fk(np.ascontiguousarray(robot.reels, dtype=float),
                 np.ascontiguousarray(robot.attachments, dtype=float),
                 np.ascontiguousarray(lengths, dtype=float),
                 np.asarray(p_guess, dtype=float), np.ascontiguousarray(R_guess, dtype=float),
                 tol, max_iterations, p, R, r)
    if not ok:
        raise PoseError(f"full-pose forward kinematics of robot {robot.name!r} did not settle "
                        f"in {max_iterations} iterations")
    return p, R, r
