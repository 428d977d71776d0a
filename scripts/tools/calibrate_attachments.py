"""Calibrate the platform attachment points b_i of paper_7cable: the paper's cable-cable
distances, the swapped pairs' separation, and statics (the cables must hold the platform).

The paper (Meziane, Cardou, Otis) gives the reels (Table 1) but not the attachment points. It
reports cable-cable distances with cables 1 and 3 swapped (and also 5 and 7 in experiment 3):
d13 = 57 mm at p = [1.77, 3.65, 1.22], 61 mm at [1.56, 3.24, 1.22], 59 mm at [1.87, 3.68, 0.53],
60 mm at [1.30, 3.68, 1.05], and d13 = 59 mm, d57 = 61 mm at [2.22, 3.22, 1.03] (both swaps).
The real robot held its platform in every experiment, and the paper's platform is designed so
that the unswapped cables do not interfere. So a design must (REQUIRED, checked after rounding
the points to 0.1 mm):
- reproduce the six distances within 1 mm, with the experiments' swaps;
- let the swapped pairs separate by translation beyond the experiments' d_u = 62 mm:
  translation bound g >= 64 mm (interference.translation_distance_bound);
- hold the level platform at every reported pose with its swaps: t* >= 5 N, t* being the
  largest achievable minimum cable tension of the platform's weight (statics.holding_tension:
  the robot file's 2.5 kg at the centre, moments about the centre);
- keep the unswapped cables >= 80 mm apart everywhere in the workspace box;
- keep every point in the 0.3 m cube, |b_i| <= 0.15 m per coordinate;
and, of the designs that do, should hold the unswapped platform at t* >= 5 N on as much of
the workspace box as it can (the share, measured on a 5 cm grid).

The optimisation keeps margins over those requirements (the *_TARGET constants below) and also
asks for the shipped experiments' paths to be held: t* >= PATH_TARGET in a tube of +-4 cm
around each shipped scenario's start and hand waypoints (with its swaps). Three stages, each a
fixed computation from fixed starts:
1. Statics: from PRIOR (each point at a corner or edge of the cube on the side of its reel; a
   seeded perturbation of it for starts after the first), SLSQP maximises a smooth share, the
   mean over a 20 cm grid of a logistic of t* around 5 N (t* computed with a 300 N ceiling so
   it stays continuous where an internal force would raise the tensions without bound), with
   the spacing as the only constraint.
2. Restore: least squares on the violated constraints (distances, g, t* at the poses and
   paths, spacing) from there.
3. Optimise: SLSQP, the same objective under every constraint.
Stages 2 and 3 run first with the targets eased a little (LOOSEN), then as asked.
The best start that meets every requirement after rounding is kept (the most share); see
STARTS for where the shipped design came from.

Checks and report: the six distances, g, t* at each reported pose (package functions on the
rounded points), the unswapped spacing on a 5 cm grid refined by local minimisation, the share
on the 5 cm grid (also what a point platform would have), and t* along each shipped
experiment's simulated path (the kinematic plant, every logged tick, with its swaps).
`--sweep` prints the trade-offs: each row re-optimises from the result with one target
changed.

    python scripts/tools/calibrate_attachments.py              # the search: 6 starts, ~25 min
    python scripts/tools/calibrate_attachments.py --from-file  # polish and check the file's points
    python scripts/tools/calibrate_attachments.py --write      # also sweep, rewrite the attachments
    python scripts/tools/calibrate_attachments.py --sweep      # the trade-off table
"""

import argparse
import dataclasses
import math
import re
import sys
import tempfile
import textwrap
from pathlib import Path

import numba
import numpy as np
from scipy.optimize import least_squares, minimize

from cdpm_drake.kernels.interference import pairs_kernel, pair_distances, translation_distance_bound
from cdpm_drake.robot import ROBOTS_DIR, load_robot
from cdpm_drake.kernels.nullspace import RANK_TOL, null_vector, particular_solution, pivoted_qr
from cdpm_drake.kernels.tension import gravity_wrench, level_wrench_matrix, step_grid
from cdpm_drake.robot.statics import holding_tension, max_min_tensions

# (swaps, p in m, {pair: reported distance in m}); swaps are 1-based cable pairs.
EXPERIMENTS = (
    (((1, 3),), (1.77, 3.65, 1.22), {(1, 3): 0.057}),  # section 5.1
    (((1, 3),), (1.56, 3.24, 1.22), {(1, 3): 0.061}),  # section 5.2, start
    (((1, 3),), (1.87, 3.68, 0.53), {(1, 3): 0.059}),  # section 5.2, Fig. 12 (a)
    (((1, 3),), (1.30, 3.68, 1.05), {(1, 3): 0.060}),  # section 5.2, Fig. 12 (b)
    (((1, 3), (5, 7)), (2.22, 3.22, 1.03), {(1, 3): 0.059, (5, 7): 0.061}),  # section 5.3
)
POSE_NAMES = ("5.1", "5.2 start", "Fig. 12 (a)", "Fig. 12 (b)", "5.3")
# The shipped scenarios whose paths the design must hold (their starts, swaps, waypoints).
SCENARIOS = ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs")
HALF_SIZE = 0.15     # m, |b| components bound (a 0.3 m platform)
# The prior design, fixed here (not read from the robot file, which holds the last result):
# each point at the corner or edge midpoint of the 0.3 m cube on the side of its reel.
PRIOR = np.array([
    [-0.15, 0.15, 0.15],    # B1, reel A1 high, at x-, y+
    [0.15, 0.15, 0.15],     # B2, reel A2 high, at x+, y+
    [-0.15, 0.15, -0.15],   # B3, reel A3 low, at x-, y+
    [0.15, 0.15, -0.15],    # B4, reel A4 low, at x+, y+
    [-0.15, -0.15, -0.15],  # B5, reel A5 low, at x-, y-
    [0.15, -0.15, -0.15],   # B6, reel A6 low, at x+, y-
    [0.0, -0.15, 0.15],     # B7, reel A7 high, at mid x, y-
])
ROUND = 4            # decimals (0.1 mm) of the written points
# (swaps, pair): the pairs whose translation bound g must reach G_MIN, in the swapped robots of
# experiments 2 (1-3) and 3 (1-3 and 5-7).
SEPARATED = (
    (((1, 3),), (1, 3)),
    (((1, 3), (5, 7)), (1, 3)),
    (((1, 3), (5, 7)), (5, 7)),
)

# Requirements, checked on the rounded points.
TOLERANCE = 1e-3     # m, agreement with every reported distance
G_MIN = 0.064        # m, translation bound: the experiments' d_u = 62 mm plus 2 mm
FLOOR = 5.0          # N, t* at every reported pose; the share counts t* >= FLOOR
SPACING_MIN = 0.080  # m, unswapped cable-cable distance anywhere in the box

# Targets of the optimisation: the requirements plus margins for the rounding (0.05 mm per
# coordinate moves a distance by up to ~0.1 mm) and for the grids between their points.
@dataclasses.dataclass(frozen=True)
class Targets:
    band: float = 0.85e-3       # m, largest distance residual
    g: float = 0.0641           # m, translation bound of the SEPARATED pairs
    pose: float = 5.8           # N, t* at each reported pose
    path: float = 5.6           # N, t* in the tubes around the shipped experiments' paths
    spacing: float = 0.095      # m, unswapped spacing on the 20 cm search grid


TARGETS = Targets()
# Starts of the search: the prior, then seeded perturbations of it. The shipped design is
# start 5 of seed 0 (shares of starts 0..5 after rounding: 58.6, 61.4, 67.8, 61.4, 63.0,
# 69.4 %; every one meets the requirements).
STARTS = 6
# How stage 2 and 3 first ease the targets (continuation): band +0.05 mm, t* -0.2 N.
LOOSEN = {"band": 0.05e-3, "pose": -0.2, "path": -0.2}
CEILING = 300.0      # N, the tension ceiling of the smooth t* the optimiser sees
SHARE_WIDTH = 1.0    # N, width of the logistic of the smooth share
SEARCH_STEP = 0.2    # m, grid of the search (objective and spacing)
CHECK_STEP = 0.05    # m, grid of the checks (the grid of the statics numbers quoted)
POINT_STEP = 0.1     # m, grid of the point platform's share (Clarabel per point)
TUBE = 0.04          # m, half-width of the tube around the experiments' paths
PATH_STEP = 0.02     # m, sample spacing along the paths
# Each row of --sweep: the target changed from the result (continuation).
SWEEP = (("pose, path >= 5.5 N", dict(pose=5.5, path=5.5)),
         ("pose, path >= 6.5 N", dict(pose=6.5, path=6.5)),
         ("pose, path >= 7.5 N", dict(pose=7.5, path=7.5)),
         ("spacing >= 85 mm", dict(spacing=0.085)),
         ("spacing >= 110 mm", dict(spacing=0.110)),
         ("residual <= 0.6 mm", dict(band=0.6e-3)))

_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def _ceiling_kernel(reels, attachments, points, w, ceiling, out):
    """out[k] = max t s.t. W T + w = 0, t <= T_i <= ceiling at points[k] (7 cables, level
    platform); -ceiling where no T within the ceiling balances w. Continuous in the geometry
    (t* itself jumps to +inf where an internal force appears): the optimiser's t*."""
    m = reels.shape[0]
    W, A, V = np.empty((6, m)), np.empty((m, 6)), np.empty((6, m))
    beta, perm = np.empty(6), np.empty(6, dtype=np.int64)
    a, n = np.empty(m), np.empty(m)
    for k in range(points.shape[0]):
        level_wrench_matrix(reels, attachments, points[k], W)
        if pivoted_qr(W, A, V, beta, perm) < RANK_TOL:
            out[k] = -ceiling
            continue
        null_vector(V, beta, n)
        particular_solution(A, V, beta, perm, w, a)
        lo, hi = -math.inf, math.inf  # lam keeping every T_i <= ceiling
        for i in range(m):
            if n[i] > 0.0:
                hi = min(hi, (ceiling - a[i]) / n[i])
            elif n[i] < 0.0:
                lo = max(lo, (ceiling - a[i]) / n[i])
        if lo > hi:
            out[k] = -ceiling
            continue
        t, lam = math.inf, hi if n[0] > 0.0 else lo  # all n of one sign: up to the ceiling
        for i in range(m):
            if n[i] > 0.0:
                for j in range(m):
                    if n[j] < 0.0:
                        v = (a[i] * (-n[j]) + a[j] * n[i]) / (n[i] - n[j])
                        if v < t:
                            t, lam = v, (a[j] - a[i]) / (n[i] - n[j])
        lam = min(max(lam, lo), hi)
        f = math.inf
        for i in range(m):
            f = min(f, a[i] + n[i] * lam)
        out[k] = f


def _swapped_points(b, swaps):
    b = np.array(b, dtype=float).reshape(-1, 3)
    for i, j in swaps:
        b[[i - 1, j - 1]] = b[[j - 1, i - 1]]
    return b


def _swapped(robot, swaps):
    for i, j in swaps:
        robot = robot.with_swapped_attachments(i, j)
    return robot


def with_attachments(robot, b):
    return dataclasses.replace(robot, attachments=np.asarray(b, dtype=float).reshape(-1, 3))


def targets() -> np.ndarray:
    return np.array([d for _, _, tg in EXPERIMENTS for d in tg.values()])


class Model:
    """The quantities of a candidate b (21,) m, fast enough for the optimiser: the same
    formulas as the package's (interference's pair kernel and translation bound, tension's
    QR), without building a Robot per call. `check` recomputes them with the package."""

    def __init__(self, robot, targets_=TARGETS):
        self.robot = robot
        self.targets = targets_
        self.reels = np.ascontiguousarray(robot.reels)
        self.weight = gravity_wrench(robot.dynamics.mass)
        self.goal = targets()
        self.search = step_grid(robot.workspace.lower, robot.workspace.upper, SEARCH_STEP)
        self.pair_i, self.pair_j = np.triu_indices(robot.num_cables, k=1)
        self.tubes = path_tubes(robot)

    def distances(self, b, points, i, j):
        """(N, P) distances of cable pairs (i, j) (0-based arrays) at points (N, 3)."""
        U, V, Wd = self.reels[i] - b[i], self.reels[j] - b[j], b[i] - b[j]
        geo = np.ascontiguousarray(np.hstack([U, V, Wd, np.cross(U - V, Wd)]))
        q = np.ascontiguousarray(np.atleast_2d(points), dtype=float)
        d = np.empty((len(q), len(i)))
        pairs_kernel(geo, q, d, np.empty((len(q), len(i)), dtype=np.int8))
        return d

    def residuals(self, b):
        out = []
        for swaps, p, tg in EXPERIMENTS:
            bs = _swapped_points(b, swaps)
            for i, j in tg:
                out.append(self.distances(bs, p, np.array([i - 1]), np.array([j - 1]))[0, 0])
        return np.array(out) - self.goal

    def bounds(self, b):
        out = []
        for swaps, (i, j) in SEPARATED:
            bs = _swapped_points(b, swaps)
            W0 = bs[i - 1] - bs[j - 1]
            D = (self.reels[i - 1] - self.reels[j - 1]) - W0
            s = min(max(-(W0 @ D) / (D @ D), 0.0), 1.0)
            out.append(float(np.linalg.norm(W0 + s * D)))
        return np.array(out)

    def smooth_t(self, b, points):
        q = np.ascontiguousarray(np.atleast_2d(points), dtype=float)
        out = np.empty(len(q))
        _ceiling_kernel(self.reels, np.ascontiguousarray(b), q, self.weight, CEILING, out)
        return out

    def objective(self, x):
        t = self.smooth_t(x.reshape(-1, 3), self.search)
        return -float(np.mean(1.0 / (1.0 + np.exp(-np.clip((t - FLOOR) / SHARE_WIDTH,
                                                            -50, 50)))))

    def spacing(self, x):
        """Per unswapped pair, its smallest distance on the search grid minus the target (mm)."""
        d = self.distances(x.reshape(-1, 3), self.search, self.pair_i, self.pair_j)
        return 1e3 * (d.min(axis=0) - self.targets.spacing)

    def constraints(self, x):
        """Every constraint as a value >= 0 when met: residual band (mm), g (mm), t* at the
        poses and in the tubes (N), spacing (mm)."""
        b, tg = x.reshape(-1, 3), self.targets
        e = self.residuals(b)
        pose = [self.smooth_t(_swapped_points(b, sw), p)[0] for sw, p, _ in EXPERIMENTS]
        tube = [self.smooth_t(_swapped_points(b, sw), pts) for sw, pts in self.tubes.values()]
        return np.concatenate([1e3 * (tg.band - e), 1e3 * (tg.band + e),
                               1e3 * (self.bounds(b) - tg.g), np.array(pose) - tg.pose,
                               np.concatenate(tube) - tg.path, self.spacing(x)])


def path_tubes(robot) -> dict:
    """{scenario name: (swaps, points)}: each shipped scenario's start and hand waypoints as a
    polyline sampled every PATH_STEP, widened by +-TUBE along every axis and diagonal."""
    from cdpm_drake.config import load_scenario

    offsets = TUBE * np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1)
                               for k in (-1, 0, 1)], dtype=float)
    tubes = {}
    for name in SCENARIOS:
        scenario = load_scenario(name)
        corners = [scenario.initial_position] + list(getattr(scenario.operator, "waypoints", []))
        corners = np.array(corners, dtype=float)
        line = [corners[:1]]
        for a, c in zip(corners[:-1], corners[1:]):
            steps = int(np.ceil(np.linalg.norm(c - a) / PATH_STEP))
            if steps:
                line.append(a + (c - a) * np.linspace(0, 1, steps + 1)[1:, None])
        line = np.vstack(line)
        tubes[name] = (tuple(tuple(s) for s in scenario.swaps),
                       (line[:, None, :] + offsets[None]).reshape(-1, 3))
    return tubes


def _statics_start(model, x0):
    """Stage 1: the smooth share under the spacing constraint alone."""
    sol = minimize(model.objective, x0, method="SLSQP",
                   bounds=[(-HALF_SIZE, HALF_SIZE)] * x0.size,
                   constraints=[{"type": "ineq", "fun": model.spacing}],
                   options={"maxiter": 500, "ftol": 1e-12})
    return sol.x


def _restore(model, x, margin=0.02):
    """Stage 2: least squares on the violated constraints (each counted from a small margin)."""
    sol = least_squares(lambda y: np.minimum(model.constraints(y) - margin, 0.0), x,
                        bounds=(-HALF_SIZE, HALF_SIZE), max_nfev=300)
    return sol.x


def _optimise(model, x):
    """Stage 3: the smooth share under every constraint."""
    sol = minimize(model.objective, x, method="SLSQP", bounds=[(-HALF_SIZE, HALF_SIZE)] * x.size,
                   constraints=[{"type": "ineq", "fun": model.constraints}],
                   options={"maxiter": 500, "ftol": 1e-12})
    return sol.x


def _solve(robot, targets_, x0):
    """Stages 1-3, the last two first with every target eased (LOOSEN), then as asked (the
    restoration finds a feasible point of the eased problem far more often), and once more
    if the answer still misses a constraint."""
    eased = Model(robot, dataclasses.replace(
        targets_, **{k: getattr(targets_, k) + v for k, v in LOOSEN.items()}))
    x = _optimise(eased, _restore(eased, _statics_start(eased, x0)))
    model = Model(robot, targets_)
    for _ in range(2):
        x = _optimise(model, _restore(model, x))
        if model.constraints(x).min() > -1e-3:
            break
    return x


# --- checks with the package's own functions ---------------------------------------------------


def model_distances(robot) -> np.ndarray:
    """The reported distances as modelled for `robot` (its attachments unswapped), m."""
    out = []
    for swaps, p, tg in EXPERIMENTS:
        swapped = _swapped(robot, swaps)
        d = pair_distances(swapped, np.array(p))
        out.extend(d[swapped.pair_position(i, j)] for (i, j) in tg)
    return np.array(out)


def separation_bounds(robot) -> np.ndarray:
    """g (m) of each SEPARATED pair of `robot` (attachments unswapped), in SEPARATED order."""
    out = []
    for swaps, (i, j) in SEPARATED:
        swapped = _swapped(robot, swaps)
        out.append(translation_distance_bound(swapped)[swapped.pair_position(i, j)])
    return np.array(out)


def pose_tensions(robot) -> np.ndarray:
    """t* (N) of the level platform at each reported pose with its swaps."""
    return np.array([float(holding_tension(_swapped(robot, sw), p)) for sw, p, _ in EXPERIMENTS])


def spacing_minimum(robot, step: float = CHECK_STEP):
    """(smallest unswapped cable-cable distance in the box (m), p, pair): on a `step` grid,
    then minimised locally (bounded) from the ten lowest grid (point, pair) combinations."""
    lo, hi = robot.workspace.lower, robot.workspace.upper
    grid = step_grid(lo, hi, step)
    d = pair_distances(robot, grid)
    flat = np.argsort(d, axis=None)[:10]
    best = (float(d.min()), grid[np.unravel_index(flat[0], d.shape)[0]],
            robot.pairs[np.unravel_index(flat[0], d.shape)[1]])
    for f in flat:
        n, k = np.unravel_index(f, d.shape)
        sol = minimize(lambda p: pair_distances(robot, p)[k], grid[n], method="L-BFGS-B",
                       bounds=list(zip(lo, hi)))
        if sol.fun < best[0]:
            best = (float(sol.fun), sol.x, robot.pairs[k])
    return best


def box_share(robot, step: float = CHECK_STEP, point: bool = False) -> float:
    """Share of the box (a `step` grid) where the unswapped level platform has t* >= FLOOR;
    `point`: what a point platform (forces only: a 4-D nullspace, Clarabel, ~0.3 ms a point)
    would have there."""
    grid = step_grid(robot.workspace.lower, robot.workspace.upper, step)
    if point:
        from cdpm_drake.robot.tension_program import max_min_tension
        from cdpm_drake.kernels.kinematics import jacobian

        w = gravity_wrench(robot.dynamics.mass)[:3]
        return float(np.mean([max_min_tension(-J.T, w) >= FLOOR
                              for J in jacobian(robot, grid)]))
    return float(np.mean(holding_tension(robot, grid) >= FLOOR))


def path_tensions(robot) -> dict:
    """{scenario: (min t* over its logged path, p there, time there)}: each shipped experiment
    simulated on the kinematic plant with `robot` (written to a temporary file), t* of every
    logged position with the experiment's swaps."""
    from cdpm_drake.config import load_scenario
    from cdpm_drake.runs.simulate import simulate

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "candidate.yaml"
        text = (ROBOTS_DIR / "paper_7cable.yaml").read_text()
        write_block(path, text, attachments_block(robot.attachments, ["candidate"]))
        for name in SCENARIOS:
            scenario = load_scenario(name, f"robot: {path}")
            log = simulate(scenario=scenario).log
            t = holding_tension(_swapped(robot, scenario.swaps), log["p"])
            k = int(np.argmin(t))
            out[name] = (float(t[k]), log["p"][k], float(log["time"][k]))
    return out


@dataclasses.dataclass
class Report:
    b: np.ndarray
    residuals: np.ndarray
    g: np.ndarray
    poses: np.ndarray
    spacing: tuple
    share: float
    paths: dict | None = None

    @property
    def failures(self) -> list[str]:
        out = []
        if np.max(np.abs(self.residuals)) > TOLERANCE:
            out.append(f"worst distance residual {1e3 * np.max(np.abs(self.residuals)):.3f} mm "
                       f"exceeds {1e3 * TOLERANCE:.0f} mm")
        if np.min(self.g) < G_MIN:
            out.append(f"translation bound {1e3 * np.min(self.g):.3f} mm is below "
                       f"{1e3 * G_MIN:.0f} mm")
        if np.min(self.poses) < FLOOR:
            out.append(f"t* {np.min(self.poses):.2f} N at a reported pose is below {FLOOR:g} N")
        if self.spacing[0] < SPACING_MIN:
            out.append(f"unswapped cables {1e3 * self.spacing[0]:.1f} mm apart, below "
                       f"{1e3 * SPACING_MIN:.0f} mm")
        if np.max(np.abs(self.b)) > HALF_SIZE + 1e-12:
            out.append("a point leaves the 0.3 m cube")
        if self.paths is not None and min(v[0] for v in self.paths.values()) < FLOOR:
            out.append(f"an experiment's path has t* below {FLOOR:g} N")
        return out


def check(robot, b, paths: bool = True) -> Report:
    r = with_attachments(robot, b)
    return Report(np.asarray(b).reshape(-1, 3), model_distances(r) - targets(),
                  separation_bounds(r), pose_tensions(r), spacing_minimum(r), box_share(r),
                  path_tensions(r) if paths else None)


# --- the calibration ---------------------------------------------------------------------------


def _polish(robot, targets_, x0):
    """Stage 3 only, with the targets as asked, from a design at its optimum up to the
    rounding (the file's points, which SLSQP takes as they are). Restoring first would push
    every active constraint 0.02 inside and SLSQP would take ~140 iterations back to the same
    points: 110 s of CPU instead of 33 s, for the same rounded points."""
    return _optimise(Model(robot, targets_), np.asarray(x0, dtype=float).ravel())


def calibrate(*, robot_name: str = "paper_7cable", starts: int = STARTS, random_seed: int = 0,
              targets_: Targets = TARGETS, paths: bool = True, from_file: bool = False):
    """(robot, Report of the rounded best design, the reports of every start). `from_file`:
    no search, only stage 3 from the robot file's points (they come back within the
    rounding when the file holds this script's result)."""
    robot = load_robot(robot_name)
    if robot.num_cables != len(PRIOR):
        raise SystemExit(f"robot {robot_name!r} has {robot.num_cables} cables; the prior "
                         f"design here is for {len(PRIOR)}")
    rng = np.random.default_rng(random_seed)
    inner = np.clip(PRIOR.ravel(), -HALF_SIZE * 0.99, HALF_SIZE * 0.99)
    x0s = [inner] + [np.clip(inner + rng.normal(scale=0.03, size=inner.size),
                             -HALF_SIZE, HALF_SIZE) for _ in range(starts - 1)]
    reports = []
    for x0 in ([robot.attachments.ravel()] if from_file else x0s):
        x = _polish(robot, targets_, x0) if from_file else _solve(robot, targets_, x0)
        b = np.round(x, ROUND).reshape(-1, 3)
        reports.append(check(robot, b, paths=False))
    # Designs that meet every requirement first, then the largest share.
    best = min(reports, key=lambda r: (bool(r.failures), -r.share))
    if paths:
        best.paths = path_tensions(with_attachments(robot, best.b))
    return robot, best, reports


def sweep(robot_name: str, b, targets_: Targets = TARGETS):
    """Rows (label, Report) of the design re-optimised from b with one target changed."""
    robot = load_robot(robot_name)
    rows = []
    for label, change in SWEEP:
        model = Model(robot, dataclasses.replace(targets_, **change))
        x = _optimise(model, _restore(model, np.asarray(b, dtype=float).ravel()))
        rows.append((label, check(robot, np.round(x, ROUND).reshape(-1, 3), paths=False)))
    return rows


def sweep_lines(rows, base: Report) -> list[str]:
    head = (f"{'change':<22} {'share (%)':>9} {'min pose t* (N)':>15} {'spacing (mm)':>12} "
            f"{'worst residual (mm)':>19}")
    lines = [head]
    for label, r in [("(the design)", base)] + list(rows):
        ok = "" if not r.failures else "  fails: " + "; ".join(r.failures)
        lines.append(f"{label:<22} {100 * r.share:>9.1f} {np.min(r.poses):>15.2f} "
                     f"{1e3 * r.spacing[0]:>12.1f} {1e3 * np.max(np.abs(r.residuals)):>19.3f}"
                     + ok)
    return lines


def attachments_block(b, comments: list[str]) -> str:
    """The robot file's attachments block: the comments (each wrapped to the file's width;
    lines starting with two spaces are table rows, kept as they are) and the points."""
    lines = []
    for c in comments:
        if c.startswith("  "):
            lines.append("#" + c)
        else:
            lines += ["# " + w for w in textwrap.wrap(c, 92)] or ["#"]
    lines.append("attachments:")
    for k, row in enumerate(np.reshape(b, (-1, 3))):
        lines.append("  - [" + ", ".join(f"{x:.{ROUND}f}" for x in row) + f"]   # B{k + 1}")
    return "\n".join(lines) + "\n"


def _newtons(t) -> str:
    return f"{t:.2f}" if np.isfinite(t) else "+inf"


def design_comments(rep: Report, point_share: float, sweep_text: list[str] | None) -> list[str]:
    res = ", ".join(f"{1e3 * e:+.2f}" for e in rep.residuals)
    poses = ", ".join(f"{n} {_newtons(t)}" for n, t in zip(POSE_NAMES, rep.poses))
    out = [
        "b_i in the platform frame (origin at the platform centre), m.",
        "CALIBRATED by scripts/tools/calibrate_attachments.py (the paper does not give them) to the "
        "paper's cable-cable distances AND to statics: the real robot held its platform in "
        "every experiment. t* below is the largest achievable minimum cable tension of the "
        "level platform (platform.mass at its centre, moments about the centre; "
        "tension.holding_tension); +inf: an internal force raises every tension (any "
        "pretension holds).",
        "Distance residuals (model - paper, mm): d13 at 5.1, 5.2 start, Fig. 12a, Fig. 12b, "
        f"5.3 and d57 at 5.3: {res} (required within {1e3 * TOLERANCE:.0f} mm).",
        f"Translation bound g (mm): pair 1-3 with 1-3 swapped {1e3 * rep.g[0]:.2f}; with 1-3 and "
        f"5-7 swapped, 1-3 {1e3 * rep.g[1]:.2f}, 5-7 {1e3 * rep.g[2]:.2f} (required >= "
        f"{1e3 * G_MIN:.0f}).",
        f"t* at the reported poses with their swaps (N): {poses} (required >= {FLOOR:g}).",
        "The design is start 5 of the script's search (STARTS): its points sit on the +x half "
        "of the cube, which gave the largest share; start 0, from the prior's corner points "
        "(each on its reel's side), reaches 58.6 %.",
    ]
    if rep.paths is not None:
        out.append("Smallest t* along each shipped experiment's path (kinematic plant, every tick,"
                   " N): " + ", ".join(f"{n.split('_')[0]} {v[0]:.2f}"
                                       for n, v in rep.paths.items()) + ".")
    out += [
        f"Unswapped: cables >= {1e3 * rep.spacing[0]:.1f} mm apart anywhere in the workspace box "
        f"(pair {rep.spacing[2]}; required >= {1e3 * SPACING_MIN:.0f}); the platform is held at "
        f"t* >= {FLOOR:g} N on {100 * rep.share:.1f} % of the box (5 cm grid; a point platform:",
        f"{100 * point_share:.1f} % on a {100 * POINT_STEP:.0f} cm grid).",
    ]
    if sweep_text:
        out += ["Trade-offs (scripts/tools/calibrate_attachments.py --sweep: re-optimised from this "
                "design with one target changed; the design's targets: pose t* >= "
                f"{TARGETS.pose:g} N, path >= {TARGETS.path:g} N, spacing >= "
                f"{1e3 * TARGETS.spacing:.0f} mm on a 20 cm grid, residuals <= "
                f"{1e3 * TARGETS.band:.2f} mm):"] + ["  " + s for s in sweep_text]
    return out


def write_block(path: Path, text: str, block: str) -> None:
    """Write `text` with its attachments block (leading comment lines and the list) replaced."""
    pattern = re.compile(r"(?:^#[^\n]*\n)*^attachments:\n(?:^  - [^\n]*\n)+", re.MULTILINE)
    if len(pattern.findall(text)) != 1:
        raise SystemExit(f"{path}: cannot find exactly one attachments block to replace")
    Path(path).write_text(pattern.sub(lambda _: block, text))


def print_report(rep: Report, out=sys.stdout) -> None:
    print(f"{'experiment':<34} {'pair':>6} {'paper (mm)':>10} {'model (mm)':>10} "
          f"{'residual (mm)':>13}", file=out)
    k = 0
    for swaps, p, tg in EXPERIMENTS:
        for pair, d in tg.items():
            print(f"{'swap ' + '+'.join(f'{i}{j}' for i, j in swaps) + f' p={list(p)}':<34} "
                  f"{str(pair):>6} {1e3 * d:>10.1f} {1e3 * (d + rep.residuals[k]):>10.2f} "
                  f"{1e3 * rep.residuals[k]:>+13.2f}", file=out)
            k += 1
    print(f"worst residual {1e3 * np.max(np.abs(rep.residuals)):.3f} mm (required <= "
          f"{1e3 * TOLERANCE:.0f} mm)", file=out)
    for (swaps, pair), gk in zip(SEPARATED, rep.g):
        print(f"translation bound g of pair {pair} with swaps "
              f"{'+'.join(f'{i}{j}' for i, j in swaps)}: {1e3 * gk:.2f} mm "
              f"(required >= {1e3 * G_MIN:.0f} mm)", file=out)
    for name, t in zip(POSE_NAMES, rep.poses):
        print(f"t* at {name} with its swaps: {_newtons(t)} N (required >= {FLOOR:g} N)",
              file=out)
    d, p, pair = rep.spacing
    print(f"unswapped: smallest cable-cable distance in the box {1e3 * d:.1f} mm, pair {pair} at "
          f"p = {np.round(p, 3).tolist()} (5 cm grid, refined; required >= "
          f"{1e3 * SPACING_MIN:.0f} mm)", file=out)
    print(f"unswapped: t* >= {FLOOR:g} N on {100 * rep.share:.1f} % of the box (5 cm grid)",
          file=out)
    for name, (t, p, time) in (rep.paths or {}).items():
        print(f"{name}: smallest t* along the simulated path {t:.2f} N at t = {time:.3f} s, "
              f"p = {np.round(p, 3).tolist()}", file=out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="paper_7cable", help="robot to calibrate")
    parser.add_argument("--starts", type=int, default=STARTS,
                        help=f"starts: the prior, then seeded perturbations of it (default "
                             f"{STARTS}; about 4 min each on a loaded 2-core machine)")
    parser.add_argument("--from-file", action="store_true",
                        help="no search: polish the robot file's points (stage 3) and "
                             "report; a file holding this script's result comes back unchanged")
    parser.add_argument("--random-seed", type=int, default=0, help="seed of the perturbed starts")
    parser.add_argument("--write", action="store_true",
                        help="also run the sweep and rewrite the attachments block of the "
                             "robot's YAML file")
    parser.add_argument("--sweep", action="store_true",
                        help="also print the trade-offs (each row a re-optimisation)")
    args = parser.parse_args()
    if args.starts < 1:
        parser.error(f"--starts must be >= 1, got {args.starts!r}")
    robot, rep, reports = calibrate(robot_name=args.robot, starts=args.starts,
                                    random_seed=args.random_seed, from_file=args.from_file)
    if len(reports) > 1:
        for k, r in enumerate(reports):
            print(f"start {k}: share {100 * r.share:.1f} %, "
                  + ("meets every requirement" if not r.failures else "; ".join(r.failures)))
    print_report(rep)
    point_share = box_share(with_attachments(robot, rep.b), step=POINT_STEP, point=True)
    print(f"a point platform (forces only) would be held at >= {FLOOR:g} N on "
          f"{100 * point_share:.1f} % of the box ({100 * POINT_STEP:.0f} cm grid)")
    sweep_text = None
    if args.sweep or args.write:
        sweep_text = sweep_lines(sweep(args.robot, rep.b), rep)
        print("trade-offs (each row re-optimised from the design with one target changed):")
        print("\n".join(sweep_text))
    block = attachments_block(rep.b, design_comments(rep, point_share, sweep_text))
    print(block, end="")
    if rep.failures:
        print("FAILED: " + "; ".join(rep.failures), file=sys.stderr)
        return 1
    if args.write:
        path = ROBOTS_DIR / f"{args.robot}.yaml"
        write_block(path, path.read_text(), block)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
