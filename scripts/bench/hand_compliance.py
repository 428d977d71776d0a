"""How far a hand's force moves a watched cable pair through the platform's own compliance,
with every cable taut and the reels held: the static deflection x = K^-1 dw of the hand's
wrench dw (at the handle) on the elastic cables, K = W diag(EA / L) W^T at the start, and the
pair's distance change along it, split into the position's part and the tilt's (finite
differences of the posed pair distance). A step of the hand overshoots this; the controller's
barrier, at the commanded pose with the orientation held, does not see the tilt
(docs/dynamic_plant.md, the steps at t = 0 across paper_7cable's pair 1-3).

    python scripts/bench/hand_compliance.py                 # the benchmark's 40 N pushes
    python scripts/bench/hand_compliance.py --force 10
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import adversarial_benchmark as ab  # noqa: E402


def deflection(resolved, pair, force):
    """(the pair's distance at the start m, the static displacement mm (3), the tilt deg (3),
    the pair's change by the position and by the tilt, mm) under `force` N across `pair`'s
    plane (the adversarial benchmark's push direction)."""
    from cdpm_drake.kernels.interference import posed_pair_distances
    from cdpm_drake.kernels.rotation import rotations_from_rpy
    from cdpm_drake.kernels.tension import wrench_matrix

    robot, d = resolved.robot, resolved.robot.dynamics
    p0 = np.asarray(resolved.scenario.initial_position, dtype=float)
    F = force * ab._direction(resolved, pair)
    W = wrench_matrix(robot, p0)
    L = np.linalg.norm(robot.reels - (p0 + robot.attachments), axis=1)
    K = W @ np.diag(d.EA / L) @ W.T
    x = np.linalg.solve(K, np.concatenate([F, np.cross(np.asarray(d.handle, float), F)]))
    k = robot.pair_position(*pair)

    def distance(q):
        dd, _ = posed_pair_distances(robot, q[None, :3], rotations_from_rpy(q[None, 3:]),
                                     np.zeros(len(robot.pairs)))
        return dd[0, k]

    q0 = np.concatenate([p0, np.zeros(3)])
    g = np.array([(distance(q0 + 1e-6 * e) - distance(q0 - 1e-6 * e)) / 2e-6
                  for e in np.eye(6)])
    return (distance(q0), 1000 * x[:3], np.degrees(x[3:]), 1000 * g[:3] @ x[:3],
            1000 * g[3:] @ x[3:])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--force", type=float, default=40.0, help="N")
    args = parser.parse_args(argv)
    from cdpm_drake.config import load_resolved_scenario

    print("| robot | pair | distance at the start (mm) | static displacement (mm) | tilt (deg) "
          "| pair's change: position / tilt (mm) |")
    print("|" + " --- |" * 6)
    for label, scenario, pairs in ab.ROBOTS:
        resolved = load_resolved_scenario(scenario)
        for pair in pairs:
            d0, dx, tilt, by_p, by_r = deflection(resolved, pair, args.force)
            print(f"| {label} | {pair[0]}-{pair[1]} | {1000 * d0:.2f} | "
                  f"{np.round(dx, 2).tolist()} | {np.round(tilt, 2).tolist()} | "
                  f"{by_p:+.2f} / {by_r:+.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
