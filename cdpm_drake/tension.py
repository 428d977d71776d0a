"""Cable tensions of a platform in static equilibrium: the wrench matrix, the tension
distribution with a floor tension, and wrench feasibility over the workspace. Plain numpy.

The platform translates (frame B parallel to the base frame A) unless a rotation R_WB is
given; moments are taken about the platform centre (B's origin). Cable i pulls the platform
with tension T_i >= 0 along u_i, the unit vector from its attachment point B_i towards its
reel exit A_i. Equilibrium under an external wrench w = [f; n] (N, N m) at the centre is

    W T + w = 0,   W = [u_1 ... u_m; b_1 x u_1 ... b_m x u_m]   (6 x m),

with b_i the attachment point relative to the centre, in the base frame.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

GRAVITY = 9.81  # m/s^2, along -z of the base frame


class TensionError(ValueError):
    """No tension distribution with every cable at or above the floor balances the wrench."""


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
    """The outcome of `tension_distribution`: `tensions` (m,) N when `feasible`; otherwise
    the distribution that keeps the smallest tension largest (`tensions`, its minimum
    `best_min` N) and the 0-based cables at that minimum (`slack`: the ones that would go
    slack, or stay below the floor, first)."""

    feasible: bool
    tensions: np.ndarray
    best_min: float
    slack: tuple[int, ...] = ()
    # Largest |W T + w| the solution leaves, N or N m (round-off when the wrench is reachable).
    residual: float = 0.0


def nnls(A, b, max_iterations: int | None = None) -> np.ndarray:
    """x >= 0 minimising ||A x - b|| (Lawson and Hanson, Solving Least Squares Problems,
    1974, ch. 23), for the small problems here (a few dozen unknowns)."""
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    n = A.shape[1]
    x = np.zeros(n)
    passive = np.zeros(n, dtype=bool)
    tol = 10 * np.finfo(float).eps * np.linalg.norm(A, 1) * max(A.shape)
    max_iterations = 3 * n if max_iterations is None else max_iterations
    w = A.T @ (b - A @ x)
    for _ in range(max_iterations):
        if passive.all() or not np.any(w[~passive] > tol):
            break
        j = int(np.argmax(np.where(passive, -np.inf, w)))
        passive[j] = True
        while True:
            z = np.zeros(n)
            z[passive] = np.linalg.lstsq(A[:, passive], b, rcond=None)[0]
            if np.all(z[passive] > 0):
                break
            neg = passive & (z <= 0)
            alpha = np.min(x[neg] / (x[neg] - z[neg]))
            x = x + alpha * (z - x)
            passive &= x > tol
            x[~passive] = 0.0
        x = z
        w = A.T @ (b - A @ x)
    return x


def least_distance(G, h):
    """lambda of least norm with G lambda >= h, or None when no lambda satisfies it (LDP by
    NNLS: Lawson and Hanson 1974, ch. 23, alg. 23.27)."""
    G = np.atleast_2d(np.asarray(G, dtype=float))
    h = np.asarray(h, dtype=float)
    k = G.shape[1]
    if k == 0:
        return np.zeros(0) if np.all(h <= 0) else None
    E = np.vstack([G.T, h[None, :]])
    f = np.zeros(k + 1)
    f[-1] = 1.0
    u = nnls(E, f)
    r = E @ u - f
    if np.linalg.norm(r) < 1e-12 or abs(r[-1]) < 1e-12:
        return None
    lam = -r[:k] / r[-1]
    # NNLS ends on a tolerance: near the feasibility boundary it can return a lambda that
    # misses a constraint by far more than round-off, so the answer is checked.
    if np.min(G @ lam - h) < -1e-9 * max(1.0, float(np.max(np.abs(h)))):
        return None
    return lam


def tension_distribution(W, wrench, min_tension: float = 0.0, tol: float = 1e-9,
                         diagnose: bool = True) -> Distribution:
    """Tensions T (m,) N with W T + wrench = 0 and every T_i >= min_tension, of least norm.

    W T = -wrench is solved in its nullspace form T = T_p + N lambda (T_p the minimum-norm
    solution, N an orthonormal nullspace basis, so ||T||^2 = ||T_p||^2 + ||lambda||^2): the
    least-norm feasible T is a least-distance problem in lambda. When the floor cannot be met,
    the largest achievable minimum tension is found by bisection (each step one LDP) and the
    cables left below the floor are reported (`diagnose=False` skips that: the answer is then
    only `feasible`). A wrench outside W's range (a moment that the
    cables cannot balance) is infeasible whatever the floor.
    """
    W = np.asarray(W, dtype=float)
    w = -np.asarray(wrench, dtype=float)
    m = W.shape[1]
    U, s, Vt = np.linalg.svd(W)
    rank = int(np.sum(s > tol * max(1.0, s[0])))
    T_p = Vt[:rank].T @ ((U[:, :rank].T @ w) / s[:rank])
    residual = float(np.max(np.abs(W @ T_p - w)))
    N = Vt[rank:].T  # (m, m - rank)
    scale = max(1.0, float(np.max(np.abs(w))))
    if residual > 1e-9 * scale:
        return Distribution(False, T_p, float(np.min(T_p)), tuple(range(m)), residual)

    def solve(floor):
        lam = least_distance(N, floor - T_p)
        return None if lam is None else T_p + N @ lam

    T = solve(min_tension)
    if T is not None:
        T = np.maximum(T, min_tension)  # LDP round-off below the floor
        return Distribution(True, T, float(T.min()), (), float(np.max(np.abs(W @ T - w))))
    if not diagnose:
        return Distribution(False, T_p, float(np.min(T_p)), (), residual)
    # Bisection on the floor between the min-norm solution's minimum (always reachable)
    # and the requested floor (not reachable).
    lo, hi, best = float(np.min(T_p)), float(min_tension), T_p
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        T_mid = solve(mid)
        if T_mid is None:
            hi = mid
        else:
            lo, best = mid, T_mid
        if hi - lo < 1e-6 * max(1.0, abs(hi)):
            break
    # The cables that hold the minimum down: those tied at it in the max-min distribution.
    slack = tuple(int(i) for i in np.flatnonzero(best <= lo + 1e-3 * scale))
    return Distribution(False, best, lo, slack, float(np.max(np.abs(W @ best - w))))


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


@dataclasses.dataclass(frozen=True)
class Feasibility:
    """Wrench feasibility over a grid: `points` (N, 3) m and `feasible` (N,) bool."""

    points: np.ndarray
    feasible: np.ndarray

    @property
    def share(self) -> float:
        return float(np.mean(self.feasible)) if self.feasible.size else 0.0


def wrench_feasibility(robot, *, mass: float, hand_force: float = 0.0, handle=(0.0, 0.0, 0.0),
                       min_tension: float = 0.0, n: int = 5, directions=None) -> Feasibility:
    """Where, on an n^3 grid of the robot's workspace box, a tension distribution with every
    cable >= min_tension (N) balances the platform's weight (mass, kg) plus a hand force of
    size hand_force (N) at the handle point (m, platform frame) in every one of `directions`
    (default: hand_force_directions(); none when hand_force is 0)."""
    pts = grid_points(robot.workspace.lower, robot.workspace.upper, n)
    if hand_force > 0:
        dirs = hand_force_directions() if directions is None else np.asarray(directions, float)
        forces = hand_force * dirs
    else:
        forces = np.zeros((1, 3))
    feasible = np.ones(len(pts), dtype=bool)
    for k, p in enumerate(pts):
        W = wrench_matrix(robot, p)
        for f in forces:
            if not tension_distribution(W, gravity_wrench(mass, f, handle), min_tension,
                                        diagnose=False).feasible:
                feasible[k] = False
                break
    return Feasibility(pts, feasible)


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
    from .rotation import rotation_from_rpy

    g = np.arange(-max_angle, max_angle + 1e-12, step)
    rpys = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    rpys = rpys[np.argsort(np.linalg.norm(rpys, axis=1), kind="stable")]
    wrench = gravity_wrench(mass)
    for rpy in rpys:
        R = rotation_from_rpy(rpy)
        W = wrench_matrix(robot, p, R)
        if tension_distribution(W, wrench, min_tension, diagnose=False).feasible:
            return rpy
    return None
