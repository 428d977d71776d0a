"""A robot's statics over its workspace: t* (kernels/tension.py's module docstring) of the
level platform on grids of points and wrenches, the holding tension, wrench feasibility, the
tilt at which the cables hold the platform, and `Statics`, the one look at a robot the
validation on load and `cdpm info` print. Positions m in the base frame, forces N, masses kg;
compiled for 7 and 8 cables, Clarabel point by point otherwise (robot/tension_program.py)."""

from __future__ import annotations

import dataclasses

import numpy as np

from cdpm_drake.kernels.nullspace import RANK_TOL
from cdpm_drake.kernels.tension import (grid_points, gravity_wrench, hand_force_directions,
                                        max_min_grid, wrench_matrix)
from cdpm_drake.robot.tension_program import max_min_tension


def max_min_tensions(robot, points, wrenches) -> np.ndarray:
    """t* (N, K) N of the level platform (translated, not rotated) at each of points (N, 3) m
    under each of wrenches (K, 6) N, N m: compiled for 7 and 8 cables (one- and
    two-dimensional nullspaces), `max_min_tension` point by point where that does not
    apply."""
    points = np.ascontiguousarray(np.reshape(points, (-1, 3)), dtype=float)
    wrenches = np.ascontiguousarray(np.reshape(wrenches, (-1, 6)), dtype=float)
    out = np.empty((len(points), len(wrenches)))
    max_min_grid(np.ascontiguousarray(robot.reels), np.ascontiguousarray(robot.attachments),
                 points, wrenches, out)
    for k in np.flatnonzero(np.isnan(out).any(axis=1)):
        W = wrench_matrix(robot, points[k])
        out[k] = [max_min_tension(W, w) for w in wrenches]
    return out


def solver_points(robot, points) -> np.ndarray:
    """A bool per point of points (N, 3) m: True where t* of the level platform needs
    Clarabel (`max_min_tension`'s LP, milliseconds a point) rather than the compiled closed
    forms (about a microsecond): a nullspace of three or more dimensions, e.g. more than
    eight cables, or a wrench matrix of low rank (every attachment at one point: rank 3). A
    grid of a hundred thousand such points takes minutes."""
    points = np.ascontiguousarray(np.reshape(points, (-1, 3)), dtype=float)
    if not len(points):
        return np.zeros(0, dtype=bool)
    out = np.empty((len(points), 1))
    max_min_grid(np.ascontiguousarray(robot.reels), np.ascontiguousarray(robot.attachments),
                 points, gravity_wrench(robot.dynamics.mass)[None, :], out)
    unsolved = np.isnan(out[:, 0])
    # Where the closed forms do not apply, a nullspace of 0-2 dimensions is quick anyway.
    if not unsolved.any():
        return unsolved
    sv = np.linalg.svd(wrench_matrix(robot, points[int(np.argmax(unsolved))]),
                       compute_uv=False)
    rank = int(np.sum(sv > RANK_TOL * sv[0])) if sv[0] > 0 else 0  # nullspace_form's rank
    return unsolved if robot.num_cables - rank >= 3 else np.zeros(len(points), dtype=bool)


def holding_tension(robot, points, mass: float | None = None) -> np.ndarray:
    """t* (N) of the level platform at points (..., 3) m holding its own weight: mass (kg,
    default the robot file's platform mass) at its centre, moments about the centre, no other
    force. The one measure of "the cables can hold the platform here" in this package."""
    points = np.asarray(points, dtype=float)
    mass = robot.dynamics.mass if mass is None else float(mass)
    t = max_min_tensions(robot, points, gravity_wrench(mass)[None, :])[:, 0]
    return t.reshape(points.shape[:-1])


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


def posed_holding_tension(robot, p, rpy, hand_force, floor: float = 0.0,
                          ceiling: float | None = None) -> np.ndarray:
    """t* (N) of each posed platform: positions p (T, 3) m, orientations rpy (T, 3) rad,
    the platform's weight and the hand force (T, 3) N at its handle, moments about the
    centre (kinetostatics.margin without floor or ceiling: the statics' one measure; +inf
    where an internal force raises every tension). The ground truth's counterpart of the
    monitor's t*: a dynamic log's p_true, rpy_true and F_H give whether the cables could
    hold the hand where the platform truly was. With a ceiling (N): the margin s instead,
    the largest with every tension between floor + s and ceiling - s (>= 0: the hand is
    held with every tension in [floor, ceiling])."""
    import math

    from cdpm_drake.kernels.kinetostatics import margin, margin_scratch, wrench_rows
    from cdpm_drake.kernels.rotation import rotations_from_rpy

    rows, scratch = wrench_rows(robot), margin_scratch(robot.num_cables)
    Rs = rotations_from_rpy(np.asarray(rpy, dtype=float))
    p, F = np.asarray(p, dtype=float), np.asarray(hand_force, dtype=float)
    out = np.empty(len(p))
    for k in range(out.size):
        R = np.ascontiguousarray(Rs[k])
        w = gravity_wrench(robot.dynamics.mass, F[k], R @ robot.dynamics.handle)
        out[k] = margin(robot.reels, robot.attachments, rows, np.ascontiguousarray(p[k]), R,
                        w, float(floor), math.inf if ceiling is None else float(ceiling),
                        scratch)[1 if ceiling is None else 0]
    return out


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
