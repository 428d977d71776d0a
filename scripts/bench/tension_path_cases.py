"""The tension path's hard cases, short: hands ramped faster or harder than the tension path
was built for, on paper_7cable (exp2, exp3) and an IPAnema-like robot of our own, on the
dynamic plant with full pose and tension control, per tension sensor. Per run (the
adversarial benchmark's `measure`, truth recomputed from the log): holdable slack ticks (a
slack tick where t* >= 2 N at the true pose with the measured hand), the smallest true
tension, the first slack tick's time, the controller's first "hand faster than the tension
path" status, and the fault.

    python scripts/bench/tension_path_cases.py                     # every case, 3 sensors
    python scripts/bench/tension_path_cases.py --sensors drive_torque --only lift --duration 2
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import adversarial_benchmark as ab  # noqa: E402


def _ramp(force, seconds, duration):
    f = [round(float(x), 6) for x in force]
    return ("operator: !ScriptedOperator {times: [0, %g, %g], forces: [[0, 0, 0], %s, %s]}, "
            % (seconds, duration, f, f))


def hands(duration):
    """(label, scenario, overlay) of every case."""
    from cdpm_drake.config import load_resolved_scenario

    out = []
    exp3 = load_resolved_scenario("exp3_two_pairs")
    p0 = np.asarray(exp3.scenario.initial_position, dtype=float)
    lo, hi = exp3.robot.workspace.lower, exp3.robot.workspace.upper
    corner = np.where(p0 - lo < hi - p0, lo, hi)
    corner[2] = hi[2]
    c = (corner - p0) / np.linalg.norm(corner - p0)
    across = ab._direction(exp3, (1, 3))
    ipa = str(ab.SCENARIOS / "ipanema_5_7.yaml")
    ipa_across = ab._direction(load_resolved_scenario(ipa), (5, 7))
    out += [("exp2 lift 40 N, 400 N/s", "exp2_interaction", _ramp([0, 0, 40], 0.1, duration)),
            ("exp2 lift 40 N, 100 N/s", "exp2_interaction", _ramp([0, 0, 40], 0.4, duration)),
            ("exp2 lift 30 N, 300 N/s", "exp2_interaction", _ramp([0, 0, 30], 0.1, duration)),
            ("exp3 corner 40 N, 400 N/s", "exp3_two_pairs", _ramp(40 * c, 0.1, duration)),
            ("exp3 push 40 N across 1-3, 400 N/s", "exp3_two_pairs",
             _ramp(40 * across, 0.1, duration)),
            ("exp3 push 40 N across 1-3, 100 N/s", "exp3_two_pairs",
             _ramp(40 * across, 0.4, duration)),
            ("ipanema push 10 N across 5-7, 100 N/s", ipa, _ramp(10 * ipa_across, 0.1,
                                                                 duration)),
            ("exp2 step 40 N up, 1000 N/s", "exp2_interaction",
             _ramp([0, 0, 40], 0.04, duration))]
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sensors", default="none,drive_torque,load_cell")
    parser.add_argument("--duration", type=float, default=3.0, help="s per run")
    parser.add_argument("--only", help="only the cases whose label contains this")
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args(argv)
    todo = []
    for label, scenario, overlay in hands(args.duration):
        if args.only and args.only not in label:
            continue
        for sensor in args.sensors.split(","):
            text = "{duration: %g, %s%s}" % (args.duration, ab.FULL_SENSOR % sensor, overlay)
            todo.append(ab.Case(label, scenario, label, "dynamic", "default", text, sensor))
    rows = ab.run_parallel(ab.measure, todo, args.jobs)
    print("| case | sensor | holdable slack (t* >= 2 N) | holdable in [2, 100] N | slack | min true T (N) | first slack (s) | "
          "first 'hand too fast' (s) | fault |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        fs = "-" if r["first_slack"] is None else "%.3f" % r["first_slack"]
        fast = "-" if r.get("first_too_fast") is None else "%.3f" % r["first_too_fast"]
        if r.get("first_ringing") is not None:  # no tension sensor: the ringing warning
            fast += " / ringing %.3f%s" % (r["first_ringing"], {True: " (each slack cable "
                                           "warned first)", False: " (NOT each warned first)",
                                           None: ""}[r["ringing_before_slack"]])
        fault = "-" if not r["fault"] else "%s at %.3f s" % (r["fault"][:60], r["fault_time"])
        print(f"| {r['robot']} | {r['sensor']} | {r['slack_holdable']} | {r['slack_within']} | "
              f"{r['slack_ticks']} | "
              f"{r['min_tension']:.2f} | {fs} | {fast} | {fault} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
