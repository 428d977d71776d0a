"""Why a pair's true closest approach goes below d_l without a tension sensor: per tick, the
controller's pose estimate against the dynamic plant's true pose, the watched pair's true and
estimated distance, how much of the gap is the position and how much the tilt, the commanded
and true velocity, the safety filter's status and binding barriers, the slack cables, and
each cable's length residual at the TRUE pose: the true geometric length less the reeled
length stretched by the true tension, l (1 + T / EA) (a taut cable sits at its encoder's
offset, ~0.5 mm; a slack one goes negative by how much cable hangs loose), beside the same at
the ESTIMATED pose with the estimated tension (what the pose fit explains).

    python scripts/bench/unseen_slack_pose.py                         # exp3's 40 N push, 400 N/s
    python scripts/bench/unseen_slack_pose.py --sensor drive_torque --every 4
    python scripts/bench/unseen_slack_pose.py --only "corner" --pair 1-3

The cases are tension_path_cases.py's (full pose and tension control, dynamic plant).
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import adversarial_benchmark as ab  # noqa: E402
import tension_path_cases as tpc  # noqa: E402


def length_residuals(robot, p, R, lengths, tensions):
    """Per tick and cable (N, m), mm: |a_i - (p + R b_i)| - l_i (1 + T_i / EA)."""
    a = np.asarray(robot.reels, dtype=float)
    b = np.asarray(robot.attachments, dtype=float)
    geom = np.linalg.norm(a[None] - (p[:, None, :] + np.einsum("nij,mj->nmi", R, b)), axis=2)
    return 1000.0 * (geom - lengths * (1.0 + tensions / float(robot.dynamics.EA)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", default="exp3 push 40 N across 1-3, 400 N/s",
                        help="the first tension_path_cases.py case whose label contains this")
    parser.add_argument("--sensor", default="none")
    parser.add_argument("--pair", default="1-3", help="the watched pair, 1-based: i-j")
    parser.add_argument("--duration", type=float, default=1.0, help="s")
    parser.add_argument("--every", type=int, default=4, help="print every this many ticks")
    args = parser.parse_args(argv)
    from cdpm_drake.config import load_resolved_scenario
    from cdpm_drake.kernels.interference import posed_pair_distances
    from cdpm_drake.kernels.rotation import rotations_from_rpy
    from cdpm_drake.runs.simulate import simulate

    label, scenario, overlay = next(c for c in tpc.hands(args.duration) if args.only in c[0])
    text = "{duration: %g, %s%s}" % (args.duration, ab.FULL_SENSOR % args.sensor, overlay)
    resolved = load_resolved_scenario(scenario, text)
    robot = resolved.robot
    result = simulate(scenario=resolved)
    log = result.log
    i, j = (int(s) for s in args.pair.split("-"))
    k = [tuple(int(c) for c in q) for q in robot.pairs].index((i, j))
    t = np.asarray(log["time"])
    Rt, Re = rotations_from_rpy(log["rpy_true"]), rotations_from_rpy(log["rpy"])
    d_u = np.asarray(log["d_u"], dtype=float)
    d_true = posed_pair_distances(robot, log["p_true"], Rt, d_u)[0][:, k]
    d_est = np.asarray(log["pair_distances"])[:, k]
    # The gap split: the true position at the estimated orientation, and the reverse.
    d_pos = posed_pair_distances(robot, log["p_true"], Re, d_u)[0][:, k]
    d_l = float(np.asarray(log["d_l"])[k])
    res_true = length_residuals(robot, log["p_true"], Rt, log["lengths"], log["tensions"])
    res_est = length_residuals(robot, log["p"], Re, log["lengths"], log["tension_estimate"])
    v_true = np.gradient(log["p_true"], t, axis=0)
    print(f"{label}, sensor {args.sensor}, pair {i}-{j}, d_l {1000 * d_l:.2f} mm; ended "
          f"{'at a fault, t = %.3f s: %s' % (t[-1], result.error) if result.error else 'normally'}")
    worst = int(np.argmin(d_true))
    print(f"closest true approach {1000 * (d_true[worst] - d_l):+.2f} mm vs d_l at "
          f"t = {t[worst]:.3f} s (estimated there {1000 * (d_est[worst] - d_l):+.2f} mm)")
    # Which cables pin the pose: the smallest singular value of the Jacobian (m/rad: how much
    # the lengths move per radian of the weakest twist) with every cable, and without each
    # cable that went slack: where it is small, the other cables' stretch errors (~0.1-0.4 mm)
    # leave the pose free along that twist, and the encoders cannot tell a tilt from the slack.
    from cdpm_drake.kernels.pose import pose_jacobian
    J = pose_jacobian(robot, log["p"][worst], Re[worst])
    sv = np.linalg.svd(J, compute_uv=False)[-1]
    parts = ["all %d cables: %.4f m/rad" % (J.shape[0], sv)]
    for c in np.flatnonzero(np.asarray(log["slack"]).any(axis=0)):
        keep = np.arange(J.shape[0]) != c
        parts.append("without cable %d: %.4f" % (c + 1, np.linalg.svd(J[keep],
                                                                       compute_uv=False)[-1]))
    print("smallest singular value of the length Jacobian at the estimate there: "
          + ", ".join(parts))
    print("| t (s) | true / est distance - d_l (mm) | of the gap: position / tilt (mm) | "
          "p_true - p (mm) | tilt true / est (deg) | |v| cmd / true (mm/s) | filter status, "
          "binding | slack | length residual at the true pose (mm) | at the estimate (mm) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for n in range(0, t.size, args.every):
        tilt_t = np.degrees(np.abs(log["rpy_true"][n, :2])).max()
        tilt_e = np.degrees(np.abs(log["rpy"][n, :2])).max()
        gap = d_est[n] - d_true[n]
        pos = d_est[n] - d_pos[n]
        print("| %.3f | %+.2f / %+.2f | %.2f / %.2f | %s | %.2f / %.2f | %.0f / %.0f | %d, %d "
              "| %s | %s | %s |" % (
                  t[n], 1000 * (d_true[n] - d_l), 1000 * (d_est[n] - d_l), 1000 * pos,
                  1000 * (gap - pos), np.round(1000 * (log["p_true"][n] - log["p"][n]), 2),
                  tilt_t, tilt_e, 1000 * np.linalg.norm(log["velocity"][n]),
                  1000 * np.linalg.norm(v_true[n]), int(np.ravel(log["filter_status"][n])[0]),
                  int(np.ravel(log["filter_binding"][n])[0]),
                  ",".join(str(c + 1) for c in np.flatnonzero(log["slack"][n])) or "-",
                  np.round(res_true[n], 1), np.round(res_est[n], 1)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
