"""Measured tensions and the tension damping block on the dynamic plant with the
full pose and tension control: slack where the statics could hold the hand, per tension
sensor, with the damping on and off, and the gain at which the damping goes unstable.

The hands are the adversarial benchmark's (scripts/bench/adversarial_benchmark.py: its
overlays, its ground truth recomputed from each log, t* at the true pose):

- lift 40 N and corner 20 N on exp2 (paper_7cable, 1-3 swapped);
- 10 N pushes across the swapped pair on the robots the controller was not tuned on
  (cube_8cable 5-7 swapped, own_7cable 5-7 swapped);
- the shipped experiments themselves (their operators), for their smallest true tension
  (--duration 30 for their whole length).

    python scripts/bench/tension_damping_benchmark.py                 # the table (~4 min)
    python scripts/bench/tension_damping_benchmark.py --margin        # the stability margins
    python scripts/bench/tension_damping_benchmark.py --json out.json --jobs 2
"""

import argparse
import json
import logging
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import adversarial_benchmark as adversarial  # noqa: E402

DURATION = 10.0
SENSORS = ("none", "drive_torque", "load_cell")


def hands() -> dict:
    """{label: (scenario, hand overlay)} of the benchmark's cases."""
    from cdpm_drake.config import load_resolved_scenario

    out = {}
    resolved = load_resolved_scenario("exp2_interaction")
    robot, p0 = resolved.robot, np.asarray(resolved.scenario.initial_position, dtype=float)
    out["exp2 lift 40 N"] = ("exp2_interaction", adversarial._scripted([0, 0, 40]))
    corner = np.where(p0 - robot.workspace.lower < robot.workspace.upper - p0,
                      robot.workspace.lower, robot.workspace.upper)
    corner[2] = robot.workspace.upper[2]
    c = corner - p0
    out["exp2 corner 20 N"] = ("exp2_interaction", adversarial._scripted(20 * c / np.linalg.norm(c)))
    for label, name in (("cube_8cable push 10 N", "cube_5_7.yaml"),
                        ("own_7cable push 10 N", "own_5_7.yaml")):
        path = str(adversarial.SCENARIOS / name)
        u = adversarial._direction(load_resolved_scenario(path), (5, 7))
        out[label] = (path, adversarial._scripted(10 * u))
    for name in ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs"):
        out[f"{name[:4]} (its operator)"] = (name, "")
    return out


def overlay(hand: str, *, sensor: str, damping: bool, gain_scale: float = 1.0,
            seed: int = 0, duration: float = DURATION) -> str:
    return ("{duration: %g, random_seed: %d, controller: {pose: full, tension_control: true, "
            "tension_damping: {enabled: %s, gain_scale: %g}}, plant: !DynamicReels "
            "{tension_sensor: %s}, %s}" % (duration, seed, "true" if damping else "false",
                                           gain_scale, sensor, hand))


def measure(job) -> dict:
    """One run: (label, scenario, overlay) -> its row."""
    logging.disable(logging.WARNING)
    from cdpm_drake.config import load_resolved_scenario
    from cdpm_drake.robot.statics import posed_holding_tension
    from cdpm_drake.runs.simulate import simulate

    label, scenario, text, meta = job
    resolved = load_resolved_scenario(scenario, text)
    start = time.perf_counter()
    result = simulate(scenario=resolved)
    wall = time.perf_counter() - start
    log = result.log
    t_star = posed_holding_tension(resolved.robot, log["p_true"], log["rpy_true"],
                                   log["F_H"])
    slack = log["slack"].any(axis=1)
    T = log["tensions"]
    half = T[T.shape[0] // 2:]
    row = {"case": label, **meta, "wall": wall, "rtf": result.realtime_factor,
           "slack_holdable": int(np.sum(slack & (t_star >= adversarial.HOLDABLE))),
           "slack_ticks": int(slack.sum()), "min_tension": float(T.min()),
           "max_tension": float(T.max()),
           "tension_std": float(half.std(axis=0).mean()) if len(half) > 1 else float("nan"),
           "end": float(log["time"][-1]),
           "fault": "" if result.error is None else str(result.error).split("\n")[0][:70]}
    measured = log.get("tension_measured")
    if measured is not None and np.all(np.isfinite(measured[1:])) and len(T) > 2:
        a, b = measured[1:], T[:-1]
        row["corr"] = float(np.mean([np.corrcoef(a[:, i], b[:, i])[0, 1]
                                     for i in range(T.shape[1])]))
    return row


def table(rows) -> str:
    head = ("| case | sensor | damping | slack ticks (holdable) | min tension (N) | "
            "tension std (N) | fault |")
    lines = [head, "|" + " --- |" * 7]
    for r in rows:
        fault = "-" if not r["fault"] else f"{r['fault'][:50]} at {r['end']:.3f} s"
        lines.append(f"| {r['case']} | {r['sensor']} | {r['damping']} | {r['slack_ticks']} "
                     f"({r['slack_holdable']}) | {r['min_tension']:.2f} | "
                     f"{r['tension_std']:.2f} | {fault} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--jobs", type=int, default=max(1, multiprocessing.cpu_count()))
    parser.add_argument("--json", metavar="PATH")
    parser.add_argument("--only", metavar="TEXT", help="only the cases whose label has TEXT")
    parser.add_argument("--sensors", default=",".join(SENSORS))
    parser.add_argument("--margin", action="store_true",
                        help="the gain scales at which the damping goes unstable")
    parser.add_argument("--duration", type=float, default=DURATION)
    args = parser.parse_args(argv)
    logging.disable(logging.WARNING)
    cases = {k: v for k, v in hands().items() if not args.only or args.only in k}
    jobs = []
    if args.margin:
        for label, (scenario, hand) in cases.items():
            for scale in (1, 2, 4, 8, 16):
                jobs.append((label, scenario, overlay(hand, sensor="drive_torque", damping=True,
                                                      gain_scale=scale,
                                                      duration=args.duration),
                             {"sensor": "drive_torque", "damping": f"x{scale}"}))
    else:
        for label, (scenario, hand) in cases.items():
            for sensor in args.sensors.split(","):
                for damping in ((False, True) if sensor != "none" else (False,)):
                    jobs.append((label, scenario, overlay(hand, sensor=sensor, damping=damping,
                                                          duration=args.duration),
                                 {"sensor": sensor, "damping": "on" if damping else "off"}))
    print(f"{len(jobs)} runs ...", file=sys.stderr)
    rows = adversarial.run_parallel(measure, jobs, args.jobs)
    print(table(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
