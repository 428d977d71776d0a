"""Loop-closure kinematics of a translating CDPM (paper eqs. 1-3). Plain numpy.

Every function takes one platform position p (3,) or a batch (N, 3), base frame, m, and
returns arrays with the same leading batch shape.
"""

from __future__ import annotations

import numpy as np

from .robot import Robot


class KinematicsError(RuntimeError):
    """Forward kinematics failed: lengths inconsistent with the robot, or no convergence."""


def cable_vectors(robot: Robot, p) -> np.ndarray:
    """rho_i = p + b_i - a_i (eq. 1), from reel exit A_i to attachment B_i; (..., m, 3), m."""
    p = np.asarray(p, dtype=float)
    return p[..., None, :] + robot.attachments - robot.reels


def cable_lengths(robot: Robot, p) -> np.ndarray:
    """||rho_i|| (eq. 2); (..., m), m."""
    return np.linalg.norm(cable_vectors(robot, p), axis=-1)


def jacobian(robot: Robot, p) -> np.ndarray:
    """J with l_dot = J @ p_dot (eq. 3): row i is rho_i^T / ||rho_i||; (..., m, 3)."""
    rho = cable_vectors(robot, p)
    return rho / np.linalg.norm(rho, axis=-1, keepdims=True)


def forward_kinematics(robot: Robot, lengths, p_guess=None, tol: float = 1e-10,
                       max_iterations: int = 50, max_residual: float = 1e-6) -> np.ndarray:
    """Platform position p (base frame, m) whose cable lengths match `lengths` (m).

    Levenberg-Marquardt on r(p) = ||p + b_i - a_i|| - l_i, started from `p_guess` (default:
    the workspace centre). Converged when the step is below `tol` m. Raises KinematicsError
    naming the residual when the lengths are inconsistent with the robot (the best fit leaves
    a residual above `max_residual` m) or the iteration does not converge.
    """
    lengths = np.asarray(lengths, dtype=float)
    single = lengths.ndim == 1
    L = np.atleast_2d(lengths)
    m = robot.num_cables
    if L.shape[-1] != m:
        raise KinematicsError(f"expected {m} cable lengths for robot {robot.name!r}, "
                              f"got {L.shape[-1]}")
    bad = ~np.isfinite(L)
    if bad.any():
        row, cable = np.argwhere(bad)[0]
        raise KinematicsError(f"cable {cable + 1} length is {L[row, cable]!r} m, "
                              "not a finite number")
    if single and p_guess is not None:
        # The control loop's case: one position, warm-started a tick away. Plain Gauss-Newton
        # converges in two or three steps; anything harder falls through to the damped solver.
        p = _gauss_newton_warm(robot.attachments - robot.reels, lengths,
                               np.asarray(p_guess, dtype=float), tol, max_residual,
                               min(8, max_iterations))
        if p is not None:
            return p
    if p_guess is None:
        p = np.broadcast_to(robot.workspace.center, (L.shape[0], 3)).copy()
    else:
        p = np.array(np.broadcast_to(np.asarray(p_guess, dtype=float), (L.shape[0], 3)))
    offsets = robot.attachments - robot.reels  # (m, 3)
    lam = np.full(L.shape[0], 1e-6)
    eye = np.eye(3)

    def residual(q):
        rho = q[:, None, :] + offsets
        n = np.linalg.norm(rho, axis=-1)
        return rho, n, n - L

    rho, n, r = residual(p)
    cost = np.einsum("ij,ij->i", r, r)
    converged = np.zeros(L.shape[0], dtype=bool)
    for _ in range(max_iterations):
        J = rho / np.maximum(n, 1e-300)[..., None]
        JtJ = np.einsum("nki,nkj->nij", J, J)
        Jtr = np.einsum("nki,nk->ni", J, r)
        A = JtJ + lam[:, None, None] * (np.einsum("nii->ni", JtJ)[:, :, None] * eye + 1e-12 * eye)
        step = -np.linalg.solve(A, Jtr[..., None])[..., 0]
        step[converged] = 0.0
        trial = p + step
        rho_t, n_t, r_t = residual(trial)
        cost_t = np.einsum("ij,ij->i", r_t, r_t)
        better = cost_t <= cost
        p = np.where(better[:, None], trial, p)
        rho = np.where(better[:, None, None], rho_t, rho)
        n = np.where(better[:, None], n_t, n)
        r = np.where(better[:, None], r_t, r)
        cost = np.where(better, cost_t, cost)
        lam = np.where(better, np.maximum(lam / 10.0, 1e-12), lam * 10.0)
        converged |= np.linalg.norm(step, axis=-1) < tol
        converged |= cost == 0.0
        if converged.all():
            break
    worst = np.max(np.abs(r), axis=-1)
    # Only a converged fit proves the lengths inconsistent; one cut short by max_iterations
    # is reported as not converging.
    failed = (worst > max_residual) & converged
    if failed.any():
        k = int(np.argmax(np.where(failed, worst, -np.inf)))
        cable = int(np.argmax(np.abs(r[k])))
        raise KinematicsError(
            f"cable lengths are inconsistent with robot {robot.name!r}: the best-fit platform "
            f"position {np.round(p[k], 6).tolist()} m leaves a residual of {worst[k]:.3g} m "
            f"on cable {cable + 1} (allowed {max_residual:g} m)")
    if not converged.all():
        k = int(np.argmin(converged))
        raise KinematicsError(
            f"forward kinematics did not converge in {max_iterations} iterations "
            f"(residual {worst[k]:.3g} m, last position {p[k].tolist()} m)")
    return p[0] if single else p


def _gauss_newton_warm(offsets, L, p, tol, max_residual, max_iterations=8):
    """Undamped Gauss-Newton from a close guess; None when it does not settle quickly."""
    for _ in range(max_iterations):
        rho = p + offsets
        n = np.sqrt(np.einsum("ij,ij->i", rho, rho))
        r = n - L
        J = rho / n[:, None]
        step = _solve_sym3(J.T @ J, J.T @ r)
        if step is None:
            return None
        p = p - step
        if step @ step < tol * tol:
            rho = p + offsets
            worst = np.max(np.abs(np.sqrt(np.einsum("ij,ij->i", rho, rho)) - L))
            return p if worst <= max_residual else None
    return None


def _solve_sym3(A, b):
    """x with A x = b for a symmetric 3x3 A, by cofactors (np.linalg.solve's call overhead is
    most of its cost at this size); None when A is singular to working precision."""
    (a, d, e), (_, c, f), (_, _, k) = A.tolist()
    c00, c01, c02 = c * k - f * f, e * f - d * k, d * f - c * e
    det = a * c00 + d * c01 + e * c02
    if not abs(det) > 1e-14 * (abs(a) + abs(c) + abs(k)) ** 3:
        return None
    c11, c12, c22 = a * k - e * e, d * e - a * f, a * c - d * d
    x, y, z = b.tolist()
    return np.array([c00 * x + c01 * y + c02 * z,
                     c01 * x + c11 * y + c12 * z,
                     c02 * x + c12 * y + c22 * z]) / det


def condition_number(robot: Robot, p) -> float:
    """2-norm condition number of J at p (how evenly cable speeds map to platform speeds)."""
    return float(np.linalg.cond(jacobian(robot, p)))
