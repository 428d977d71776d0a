"""Benchmark one control tick of the interference block against other ways to compute it.

All rows are measured in the same run, on random platform positions of the robot's workspace,
interleaved in rounds (every row once per round) and reported as the best round's mean time
per tick:

- this package: `interference_force` (distance, gradient, side memory, logistic, force for
  every watched pair) and `pair_distances` (distances only), one position per call;
- the paper's Fig. 4 algorithm transcribed per pair in Python/numpy (nine cases, keep those
  satisfying eq. 9, take the smallest; gradient by eqs. 24-25 in case 1, the envelope formula
  otherwise; then eqs. 26-30);
- python-fcl capsule distance, distance only: each tick builds the m capsules (axis = cable,
  length = cable length, radius 1 mm) at their poses and calls fcl.distance for every pair;
- Drake SceneGraph capsule distance, distance only: m dynamic capsules of one source; each
  tick changes their lengths in the context (ChangeShape), sets their poses (FramePoseVector)
  and asks the QueryObject for ComputeSignedDistancePairwiseClosestPoints; a second row keeps
  the lengths fixed (poses only: a lower bound, its distances are not the cables');
- `pair_distances` on a batch of 1000 positions (per position);
- the full tick and fcl's for m = 4, 7, 10, 13, 16 cables (synthetic robots).

Ratios are against python-fcl's distance-only tick for the same robot. The "max |d - this|"
column checks every implementation against this package on the benchmark positions.

    python scripts/bench/bench_interference.py [--robot paper_7cable] [--ticks 300] [--repeats 7]
"""

import argparse
import math
import sys
import time

import numpy as np

from cdpm_drake.kernels.interference import (InterferenceParams, initial_side, interference_force,
                                     pair_distances)
from cdpm_drake.robot import Robot, Workspace, load_robot

RADIUS = 1e-3  # m, capsule radius for fcl and Drake (distance reported + 2 r)


# --- the paper, transcribed per pair --------------------------------------------------------


def paper_fig4(Bi, Ai, Bj, Aj):
    """Fig. 4 for one pair: the nine cases of eqs. 13-21 (rho = B - A, eq. 1), those that
    satisfy eq. 9, the smallest |d_ij| (eq. 8). Returns (distance, d_i, d_j, case)."""
    ri, rj = Bi - Ai, Bj - Aj
    bij = Bi - Bj
    cands = []
    try:  # case 1, eq. 13 (singular for parallel cables: then skipped)
        M = np.array([[ri @ ri, -ri @ rj], [-rj @ ri, rj @ rj]])
        di, dj = np.linalg.solve(M, [ri @ bij, -rj @ bij])
        cands.append((di, dj, 1))
    except np.linalg.LinAlgError:
        pass
    cands += [((ri @ rj + ri @ bij) / (ri @ ri), 1.0, 2), ((ri @ bij) / (ri @ ri), 0.0, 3),
              (1.0, (rj @ ri - rj @ bij) / (rj @ rj), 4), (0.0, (-rj @ bij) / (rj @ rj), 5),
              (1.0, 0.0, 6), (0.0, 1.0, 7), (1.0, 1.0, 8), (0.0, 0.0, 9)]
    best = None
    for di, dj, case in cands:
        if 0.0 <= di <= 1.0 and 0.0 <= dj <= 1.0:
            d = float(np.linalg.norm(di * ri - dj * rj - bij))
            if best is None or d < best[0]:
                best = (d, di, dj, case)
    return best


def paper_gradient(Bi, Ai, Bj, Aj, d, di, dj, case):
    """Eqs. 24-25 in case 1; the paper gives no other case, so elsewhere the envelope formula
    (d_j - d_i) d_ij / |d_ij| (module docstring of cdpm_drake.kernels.interference)."""
    ri, rj = Bi - Ai, Bj - Aj
    bij = Bi - Bj
    dvec = di * ri - dj * rj - bij
    if d == 0.0:
        return np.zeros(3)
    if case != 1:
        return (di - dj) * dvec / d
    I3 = np.eye(3)
    M6 = np.block([[ri @ ri * I3, -(ri @ rj) * I3], [-(rj @ ri) * I3, rj @ rj * I3]])
    gamma = np.concatenate([dj * (ri + rj) - 2 * di * ri + bij,
                            di * (ri + rj) - 2 * dj * rj - bij])
    dd = np.linalg.solve(M6, gamma)
    bvec = (di**2 / d) * ri + (dj**2 / d) * rj - (di * dj / d) * (ri + rj) + ((dj - di) / d) * bij
    return ((di * (ri @ ri) - dj * (ri @ rj) - bij @ ri) / d) * dd[:3] \
        + ((dj * (rj @ rj) - di * (ri @ rj) + bij @ rj) / d) * dd[3:] + bvec


def paper_tick(robot, p, params):
    """One tick by the paper: per-pair distance, gradient, logistic intensity, sum, clip."""
    B = p + robot.attachments
    A = robot.reels
    F = np.zeros(3)
    dists = []
    for k, (i, j) in enumerate(zip(*robot.pair_index)):
        d, di, dj, case = paper_fig4(B[i], A[i], B[j], A[j])
        dists.append(d)
        if d > params.d_u[k]:
            continue
        g = paper_gradient(B[i], A[i], B[j], A[j], d, di, dj, case)
        n = np.linalg.norm(g)
        if n == 0.0:
            continue
        b = 2 * math.log((params.F_u[k] - params.eps[k]) / params.eps[k]) \
            / (params.d_l[k] - params.d_u[k])
        alpha = params.F_u[k] / (1 + math.exp(-b * (d - 0.5 * (params.d_u[k] + params.d_l[k]))))
        F += alpha * g / n
    n = np.linalg.norm(F)
    if n > params.F_max:
        F *= params.F_max / n
    return F, np.array(dists)


# --- capsules for fcl and Drake ----------------------------------------------------------------


def capsule_frames(robot, p):
    """Per cable: rotation (m, 3, 3) whose z column is the cable direction, centre (m, 3) and
    length (m,), vectorised."""
    B = p + robot.attachments
    d = robot.reels - B
    L = np.linalg.norm(d, axis=1)
    z = d / L[:, None]
    helper = np.where(np.abs(z[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x, axis=1)[:, None]
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=2), 0.5 * (B + robot.reels), L


class FclTick:
    """python-fcl, distance only: new capsules at their poses, then every watched pair."""

    def __init__(self, robot):
        import fcl

        self.fcl, self.robot = fcl, robot
        self.pairs = list(zip(*[k.tolist() for k in robot.pair_index]))
        self.request = fcl.DistanceRequest()

    def __call__(self, p):
        fcl = self.fcl
        R, c, L = capsule_frames(self.robot, p)
        objs = [fcl.CollisionObject(fcl.Capsule(RADIUS, L[k]), fcl.Transform(R[k], c[k]))
                for k in range(len(L))]
        return np.array([fcl.distance(objs[i], objs[j], self.request, fcl.DistanceResult())
                         for i, j in self.pairs]) + 2 * RADIUS


class DrakeTick:
    """Drake SceneGraph, distance only: one dynamic capsule per cable on its own frame."""

    def __init__(self, robot, change_lengths=True):
        from pydrake.geometry import (Capsule, FramePoseVector, GeometryFrame, GeometryInstance,
                                      ProximityProperties, SceneGraph)
        from pydrake.math import RigidTransform, RotationMatrix

        self.Capsule, self.FramePoseVector = Capsule, FramePoseVector
        self.RigidTransform, self.RotationMatrix = RigidTransform, RotationMatrix
        self.robot, self.change_lengths = robot, change_lengths
        sg = SceneGraph()
        self.sg, self.source = sg, sg.RegisterSource("cables")
        _, _, L = capsule_frames(robot, robot.workspace.center)
        self.frames, self.geoms = [], []
        for k in range(robot.num_cables):
            frame = sg.RegisterFrame(self.source, GeometryFrame(f"cable_{k + 1}"))
            g = sg.RegisterGeometry(self.source, frame,
                                    GeometryInstance(RigidTransform(), Capsule(RADIUS, L[k]),
                                                     f"cable_{k + 1}"))
            sg.AssignRole(self.source, g, ProximityProperties())
            self.frames.append(frame)
            self.geoms.append(g)
        self.context = sg.CreateDefaultContext()
        self.port = sg.get_source_pose_port(self.source)
        self.index = {g: k for k, g in enumerate(self.geoms)}
        i, j = robot.pair_index
        self.slot = {(int(a), int(b)): n for n, (a, b) in enumerate(zip(i, j))}

    def __call__(self, p):
        R, c, L = capsule_frames(self.robot, p)
        poses = self.FramePoseVector()
        for k, frame in enumerate(self.frames):
            if self.change_lengths:
                self.sg.ChangeShape(self.context, self.source, self.geoms[k],
                                    self.Capsule(RADIUS, L[k]))
            poses.set_value(frame, self.RigidTransform(self.RotationMatrix(R[k]), c[k]))
        self.port.FixValue(self.context, poses)
        query = self.sg.get_query_output_port().Eval(self.context)
        out = np.full(len(self.slot), np.nan)
        for pair in query.ComputeSignedDistancePairwiseClosestPoints(math.inf):
            a, b = sorted((self.index[pair.id_A], self.index[pair.id_B]))
            if (a, b) in self.slot:
                out[self.slot[(a, b)]] = pair.distance + 2 * RADIUS
        return out


# --- synthetic robots ----------------------------------------------------------------------------


def synthetic_robot(m: int) -> Robot:
    """m reels around a 4 m x 3 m x 3 m frame (alternately high and low), each cable attached
    at 0.15 m from the platform centre towards its reel."""
    k = np.arange(m)
    ang = 2 * np.pi * k / m
    reels = np.stack([2.0 + 2.0 * np.cos(ang), 1.5 + 1.5 * np.sin(ang),
                      np.where(k % 2 == 0, 3.0, 0.0)], axis=1)
    centre = np.array([2.0, 1.5, 1.5])
    dirs = reels - centre
    att = 0.15 * dirs / np.linalg.norm(dirs, axis=1)[:, None]
    return Robot(name=f"synthetic_{m}cable", reels=reels, attachments=att,
                 workspace=Workspace(np.array([1.2, 0.9, 0.8]), np.array([2.8, 2.1, 2.2])))


# --- timing ------------------------------------------------------------------------------------


def loop_time(fun, args):
    """Mean seconds per call of fun over args."""
    t0 = time.perf_counter()
    for a in args:
        fun(a)
    return (time.perf_counter() - t0) / len(args)


def max_dev(fun, robot, positions):
    return max(float(np.max(np.abs(fun(p) - pair_distances(robot, p)))) for p in positions)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="paper_7cable", help="robot of the main rows")
    parser.add_argument("--ticks", type=int, default=300, help="positions per timing loop")
    parser.add_argument("--repeats", type=int, default=7, help="timing rounds")
    parser.add_argument("--random-seed", type=int, default=0, help="seed of the positions")
    args = parser.parse_args()
    try:
        import fcl  # noqa: F401
    except ImportError:
        print("python-fcl is missing: pip install -e .[bench]", file=sys.stderr)
        return 2

    rng = np.random.default_rng(args.random_seed)
    # Each row: (what, robot, callable, positions, reference row key, max deviation or None).
    rows, fcl_row = [], {}

    def positions(robot, n):
        return list(rng.uniform(robot.workspace.lower, robot.workspace.upper, size=(n, 3)))

    def add(what, robot, fun, pos, dev=None, per=1):
        rows.append(dict(what=what, robot=robot, fun=fun, pos=pos, dev=dev, per=per))
        return rows[-1]

    robot = load_robot(args.robot)
    pos = positions(robot, args.ticks)
    few = pos[: max(10, args.ticks // 10)]  # for the slow rows
    # The paper's unit gradient (gradient_floor 0), so that the check against the paper's
    # Fig. 4 tick below compares the same computation wherever the positions fall.
    params = InterferenceParams.uniform(robot, 0.05, 0.3, 2.0, 0.1, gradient_floor=0.0)
    side = initial_side(robot, pos[0])
    np.testing.assert_allclose(paper_tick(robot, pos[0], params)[0],
                               interference_force(robot, pos[0], params).force, atol=1e-9)
    add("this: full tick (distance, gradient, side, force)", robot,
        lambda p: interference_force(robot, p, params, side), pos)
    add("this: pair_distances, one position", robot, lambda p: pair_distances(robot, p), pos)
    add("paper Fig. 4 per pair: full tick", robot, lambda p: paper_tick(robot, p, params), few,
        max_dev(lambda p: paper_tick(robot, p, params)[1], robot, pos[:20]))
    fcl_tick = FclTick(robot)
    fcl_row[robot.name] = add("python-fcl capsules: distance only", robot, fcl_tick, pos,
                              max_dev(fcl_tick, robot, pos[:20]))
    drake = DrakeTick(robot)
    add("Drake SceneGraph capsules: distance only", robot, drake, few,
        max_dev(drake, robot, pos[:20]))
    add("Drake SceneGraph, poses only (lengths fixed)", robot,
        DrakeTick(robot, change_lengths=False), pos)
    batch = np.array(positions(robot, 1000))
    add("this: pair_distances, batch of 1000, per pose", robot,
        lambda b: pair_distances(robot, b), [batch], per=len(batch))
    for mm in (4, 7, 10, 13, 16):
        syn = synthetic_robot(mm)
        spos = positions(syn, args.ticks)
        sparams = InterferenceParams.uniform(syn, 0.05, 0.3, 2.0, 0.1)
        sside = initial_side(syn, spos[0])
        add(f"this: full tick, {syn.name}", syn,
            lambda p, syn=syn, sparams=sparams, sside=sside:
            interference_force(syn, p, sparams, sside), spos)
        ftick = FclTick(syn)
        fcl_row[syn.name] = add(f"python-fcl: distance only, {syn.name}", syn, ftick, spos,
                                max_dev(ftick, syn, spos[:20]))

    # Rounds: every row once per round, the best round kept, so that a load spike from
    # another process hits one round of every row instead of all rounds of one row.
    for row in rows:
        row["fun"](row["pos"][0])  # warm up
        row["best"] = math.inf
    for _ in range(args.repeats):
        for row in rows:
            row["best"] = min(row["best"], loop_time(row["fun"], row["pos"]) / row["per"])

    headers = ("what", "m", "pairs", "us/tick", "vs fcl", "max |d - this| (m)")
    cells = [headers]
    for row in rows:
        ref = fcl_row[row["robot"].name]["best"]
        cells.append((row["what"], str(row["robot"].num_cables), str(row["robot"].num_pairs),
                      f"{1e6 * row['best']:.1f}", f"{row['best'] / ref:.3f}",
                      "" if row["dev"] is None else f"{row['dev']:.1e}"))
    widths = [max(len(r[k]) for r in cells) for k in range(len(headers))]
    print(f"interference tick benchmark: {args.ticks} positions per loop, best of "
          f"{args.repeats} rounds; 'vs fcl' = time / python-fcl distance-only tick of the "
          f"same robot")
    for n, r in enumerate(cells):
        print("  ".join(c.ljust(w) if k == 0 else c.rjust(w)
                        for k, (c, w) in enumerate(zip(r, widths))))
        if n == 0:
            print("  ".join("-" * w for w in widths))
    return 0


if __name__ == "__main__":
    sys.exit(main())
