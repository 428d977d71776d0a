"""Per-call cost of the tension distribution and of t* (the largest achievable minimum
tension), against scipy's linprog (HiGHS) measured in the same run as the reference of the
ratios, and against the hand-written NNLS/LDP solver this package had before the closed forms
(read from git at OLD_COMMIT, when the checkout has it).

Cases, each on the same `--poses` random poses of paper_7cable (1-3 swapped, in its box,
2.5 kg platform, floor 5 N) cycled for `--calls` calls, best of `--repeats`:
- the compiled kernel bound once (kernel_call.bind), as a 2 ms control tick would call it;
- tension_distribution and max_min_tension through their Python entry points (W given);
- the old solver's tension_distribution (feasible poses are cheap for it, the infeasible
  ones bisect);
- scipy's linprog (HiGHS) for t* (the reference, 1.00);
- 8 cables (a two-dimensional nullspace), on a suspended 8-cable robot: tension_distribution
  (Drake's MathematicalProgram with Clarabel: an LP and a QP), max_min_tension (the closed
  form over cable triples) and t* by Clarabel's LP alone;
- holding_tension on a grid (per point, the wrench matrix included);
- the full-pose controller's tension_distribution kernel (pose_control.tension_tick: the
  estimate and the target, bound as the block calls it) for 7, 8 and 9 cables, on random
  tilted poses, hand forces up to 40 N and ceilings of 100, 40 and 20 N, grouped by the status
  the target ends in (beyond 7 cables, statuses 0 and 1 take three small QPs, 3 and 4 four):
  per pose the best of the repeats of 50 calls, its mean over the group and the slowest.

Usage: python scripts/bench/bench_tension.py [--calls 2000] [--poses 200] [--repeats 3]
"""

import argparse
import dataclasses
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.optimize import linprog

from cdpm_drake.kernels import full_pose as pose_control
from cdpm_drake.kernels.call import bind
from cdpm_drake.kernels.pose import pose_lengths
from cdpm_drake.robot import Robot, load_robot
from cdpm_drake.kernels.rotation import rotation_from_rpy
from cdpm_drake.kernels.nullspace import nullspace_form
from cdpm_drake.kernels.tension import (distribution_kernel, gravity_wrench, step_grid,
                                        wrench_matrix)
from cdpm_drake.robot.statics import holding_tension
from cdpm_drake.robot.tension_program import (max_min_general, max_min_tension,
                                              tension_distribution)
from cdpm_drake.text import format_table

ROOT = Path(__file__).resolve().parents[2]
OLD_COMMIT = "b28eace"  # the NNLS/LDP solver, with a bisection for t*
FLOOR = 5.0


def highs_t_star(W, w):
    m = W.shape[1]
    res = linprog(np.r_[np.zeros(m), -1.0], A_ub=np.hstack([-np.eye(m), np.ones((m, 1))]),
                  b_ub=np.zeros(m), A_eq=np.hstack([W, np.zeros((W.shape[0], 1))]), b_eq=-w,
                  bounds=[(None, None)] * (m + 1), method="highs")
    return np.inf if res.status == 3 else -res.fun


def old_solver():
    """The old tension module (NNLS/LDP), from git; None when the checkout lacks it."""
    try:
        text = subprocess.run(["git", "-C", str(ROOT), "show",
                               f"{OLD_COMMIT}:cdpm_drake/kernels/tension.py"], check=True,
                              capture_output=True, text=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    path = Path(tempfile.mkdtemp()) / "old_tension.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("old_tension", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["old_tension"] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def per_call(fn, cases, calls, repeats) -> float:
    """Best over repeats of the mean wall time (s) of fn(*case), cases cycled."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for k in range(calls):
            fn(*cases[k % len(cases)])
        best = min(best, (time.perf_counter() - start) / calls)
    return best


def clarabel_t_star(W, w):
    """t* by the Clarabel LP that robot/tension_program.py uses for nullspaces of 3+ dimensions."""
    T_p, N, _ = nullspace_form(W, w)
    return max_min_general(T_p, N)[0]


def suspended8():
    return Robot(
        name="suspended8",
        reels=[[0, 0, 3], [0.1, 0, 3], [4, 0, 3], [4, 0.1, 3], [4, 3, 3], [3.9, 3, 3],
               [0, 3, 3], [0, 2.9, 3]],
        attachments=[[x, y, z] for x, y in ((-0.1, -0.1), (0.1, -0.1), (0.1, 0.1), (-0.1, 0.1))
                     for z in (0.1, -0.1)],
        workspace=([0.5, 0.5, 0.5], [3.5, 2.5, 2.5]))


def with_cables(robot, reels, attachments, name):
    """`robot` with more cables (reels and attachment points, m)."""
    return dataclasses.replace(robot, name=name, reels=np.vstack([robot.reels, reels]),
                               attachments=np.vstack([robot.attachments, attachments]))


def tension_tick_cases(robot, count, rng):
    """(status, (reels, attachments, params, x, out)) for `count` random poses of `robot`:
    tilted up to 0.1 rad, a hand force up to 40 N, ceiling 100, 40 or 20 N, at rest."""
    m = robot.num_cables
    d = robot.dynamics
    reels = np.ascontiguousarray(robot.reels)
    attachments = np.ascontiguousarray(robot.attachments)
    lo, hi = robot.workspace.lower, robot.workspace.upper
    cases = []
    for _ in range(count):
        p = lo + (hi - lo) * rng.uniform(size=3)
        R = rotation_from_rpy(rng.uniform(-0.1, 0.1, 3))
        F = rng.normal(size=3)
        F *= rng.uniform(0.0, 40.0) / np.linalg.norm(F)
        ceiling = float(rng.choice([100.0, 40.0, 20.0]))
        params = np.array([d.mass, *d.handle, d.EA, 10.0, ceiling, 0.002, 50.0, 25.0, 3.0])
        x = np.concatenate([p, R.ravel(), F, np.zeros(3), np.zeros(m),
                            pose_lengths(robot, p, R), np.full(m, 20.0), np.zeros(m),
                            np.zeros(3), [30.0], np.full(m, 20.0)])
        out = np.empty(pose_control.sizes(m)["tension_out"])
        status = pose_control.tension_tick(reels, attachments, params, x, out)
        cases.append((int(status), (reels, attachments, params, x, out)))
    return cases


def tension_tick_rows(count, calls, repeats, rng):
    """Rows (case, mean over the poses us, slowest pose us) of the tension_distribution
    kernel: per pose the best of `repeats` means of `calls` calls."""
    paper = load_robot("paper_7cable")
    eight = with_cables(paper, [[1.7, 4.6, 2.9]], [[0.1, 0.05, 0.15]], "paper_8cable")
    nine = with_cables(eight, [[1.7, 0.1, 0.8]], [[0.05, -0.1, -0.1]], "paper_9cable")
    rows = []
    for robot in (paper, load_robot("cube_8cable"), eight, nine):
        cases = tension_tick_cases(robot, count, rng)
        tick = bind(pose_control.tension_tick, *cases[0][1])
        for status in sorted({s for s, _ in cases}):
            group = [c for s, c in cases if s == status]
            times = [per_call(tick, [c], calls, repeats) for c in group]
            rows.append((f"tension_tick, {robot.name} ({robot.num_cables} cables), status "
                         f"{status} ({len(group)} poses)", f"{1e6 * np.mean(times):.2f}",
                         f"{1e6 * max(times):.2f}"))
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=2000, help="calls per case and repeat")
    parser.add_argument("--poses", type=int, default=200, help="random poses, cycled")
    parser.add_argument("--repeats", type=int, default=3, help="repeats (best kept)")
    parser.add_argument("--random-seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.random_seed)
    robot = load_robot("paper_7cable").with_swapped_attachments(1, 3)
    w = gravity_wrench(robot.dynamics.mass)
    pts = rng.uniform(robot.workspace.lower, robot.workspace.upper, size=(args.poses, 3))
    Ws = [wrench_matrix(robot, p) for p in pts]
    T = np.empty(robot.num_cables)
    kernel = bind(distribution_kernel, Ws[0], w, FLOOR, T)
    held = np.mean([max_min_tension(W, w) >= FLOOR for W in Ws])
    eight = suspended8()
    Ws8 = [wrench_matrix(eight, p) for p in
           rng.uniform(eight.workspace.lower, eight.workspace.upper, size=(args.poses, 3))]
    few = max(1, args.calls // 10)  # the slow cases: fewer calls
    cases = [
        ("7 cables: compiled kernel, bound", lambda W: kernel(W, w, FLOOR, T), Ws, args.calls),
        ("7 cables: tension_distribution", lambda W: tension_distribution(W, w, FLOOR), Ws,
         args.calls),
        ("7 cables: max_min_tension", lambda W: max_min_tension(W, w), Ws, args.calls),
    ]
    old = old_solver()
    if old is not None:
        cases.append((f"7 cables: old NNLS/LDP ({OLD_COMMIT})",
                      lambda W: old.tension_distribution(W, w, FLOOR), Ws, few))
    cases += [
        ("7 cables: scipy linprog HiGHS t* (reference)", lambda W: highs_t_star(W, w), Ws, few),
        ("8 cables: tension_distribution (Clarabel)", lambda W: tension_distribution(W, w, 1.0),
         Ws8, few),
        ("8 cables: max_min_tension (closed form, cable triples)",
         lambda W: max_min_tension(W, w), Ws8, args.calls),
        ("8 cables: t* by Clarabel's LP", lambda W: clarabel_t_star(W, w), Ws8, few),
        ("8 cables: scipy linprog HiGHS t*", lambda W: highs_t_star(W, w), Ws8, few),
    ]
    grid = step_grid(robot.workspace.lower, robot.workspace.upper, 0.1)
    holding_tension(robot, grid[:2])  # compile / load outside the timing
    for _, fn, cs, _ in cases:  # first calls (compilation, imports) outside the timing
        fn(cs[0])
    times = {label: per_call(fn, [(c,) for c in cs], calls, args.repeats)
             for label, fn, cs, calls in cases}
    start = time.perf_counter()
    for _ in range(args.repeats):
        holding_tension(robot, grid)
    grid_time = (time.perf_counter() - start) / args.repeats / len(grid)
    times[f"holding_tension on a 10 cm grid, per point ({len(grid)} points)"] = grid_time
    reference = times["7 cables: scipy linprog HiGHS t* (reference)"]
    rows = [(label, f"{1e6 * t:.2f}", f"{t / reference:.4f}") for label, t in times.items()]
    print(f"paper_7cable (1-3 swapped), {args.poses} random poses in its box "
          f"({100 * held:.0f}% held at >= {FLOOR:g} N), floor {FLOOR:g} N; "
          f"best of {args.repeats}")
    print(format_table(["case", "per call (us)", "/ HiGHS"], rows))
    if old is None:
        print(f"(the old solver was not found at git commit {OLD_COMMIT})")
    print()
    print(f"the full-pose controller's tension_distribution kernel, {args.poses} random poses "
          f"per robot (floor 10 N, hard floor 3 N), best of {args.repeats}")
    print(format_table(["case", "mean over the poses (us)", "slowest pose (us)"],
                       tension_tick_rows(args.poses, 50, args.repeats, rng)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
