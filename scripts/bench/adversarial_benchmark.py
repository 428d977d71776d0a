"""The adversarial benchmark: hands the paper's interference force cannot hold, on the robots
and plants the controller is meant for, with the truth recomputed from each log.

Every case is a scenario (a base in scripts/bench/adversarial/ or a shipped one, with an overlay
this script writes) run through `cdpm_drake.runs.simulate.simulate`, twice: with the paper's
method (the safety filter and the model monitor off) and with the default controller. The
hands:

- push F: a steady push of F N (5, 10, 20, 40) across a swapped pair's plane (along minus the
  gradient of the pair's distance at the start), ramped in over 0.1 s as a hand does;
- step 40: the same 40 N at once, at t = 0 (no hand does that: it shows what no controller
  can prevent, the platform's first 50 ms on its elastic cables);
- spring F: a spring hand (60 N/m) pulling towards a point 1 m beyond the plane, capped at F;
- lift F: a steady upward F N; corner: 20 N towards the box's top corner nearest the start;
- noisy: a hand of 2 N rms (a sum of slow sines) with 0.5 N of sensor noise.

On the dynamic plant (mass, elastic tension-only cables, drive friction) with the full pose and
tension control; the pushes also on the kinematic plant with the default (translating)
controller. Per run, from the log: the closest approach of a watched pair against its d_l
(true distances from the plant's true pose, recomputed here with the posed segment distance;
the kinematic plant's estimate is exact), whether a pair truly crossed, the slack ticks while
the statics could hold the measured hand force (t* >= 2 N at the true pose, recomputed here),
the smallest true tension, the largest tilt, the fault and its delay after the first tick the
statics could not hold the hand (t* < 0), and how often the filter modified or held the
command.

    python scripts/bench/adversarial_benchmark.py              # the whole table (~2 min, 2 cores)
    python scripts/bench/adversarial_benchmark.py --quick      # a subset (~30 s)
    python scripts/bench/adversarial_benchmark.py --json out.json --jobs 2
    python scripts/bench/adversarial_benchmark.py --sensors none,drive_torque,load_cell
    python scripts/bench/adversarial_benchmark.py --methods default --plants dynamic  # one row per hand
    python scripts/bench/adversarial_benchmark.py --only "N/s" --duration 3  # the ramp rates

The ramp rates (--rates, default 10, 40, 100, 400 N/s): 40 N pushes across each swapped pair
and 40 N lifts ramped at each rate. Per run also: the slack ticks where the statics at the true
pose hold the measured hand with every tension in [2 N, max_tension] (the promise's bar), the
first slack tick and the first tick the controller said "hand faster than the tension path
can follow" (tension_status 5).

The dynamic plant's tension sensor (`plant: !DynamicReels {tension_sensor: ...}`,
which the tension damping block uses) is a column: the default controller's dynamic rows are
run once per sensor of --sensors (default: drive_torque, the plant's default); the paper's
method runs without one (none: the paper's robot, and no damping).
"""

import argparse
import dataclasses
import json
import logging
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SCENARIOS = HERE / "adversarial"

# (label, scenario (shipped name or file under scripts/adversarial), the swapped pairs to push
# across). The bases name the robot, the swaps, the start and the logistic.
ROBOTS = (
    ("exp2 (paper_7cable, 1-3 swapped)", "exp2_interaction", [(1, 3)]),
    ("exp3 (paper_7cable, 1-3 and 5-7 swapped)", "exp3_two_pairs", [(1, 3), (5, 7)]),
    ("cube_8cable, 5-7 swapped", str(SCENARIOS / "cube_5_7.yaml"), [(5, 7)]),
    ("own_7cable, 5-7 swapped", str(SCENARIOS / "own_5_7.yaml"), [(5, 7)]),
    ("long_8cable (ours)", str(SCENARIOS / "long_8cable_start.yaml"), [(6, 7)]),
    ("ipanema_8cable (ours), 5-7 swapped", str(SCENARIOS / "ipanema_5_7.yaml"), [(5, 7)]),
)
# The ramp rates (N/s) of the 40 N pushes and lifts beside their 0.1 s ramps: a hand at 100
# N/s or slower must leave no holdable slack; a faster one ends taut or with the controller's
# "hand faster than the tension path can follow" before the first slack tick.
RATES = (10, 40, 100, 400)
FULL = "controller: {pose: full, tension_control: true}, plant: !DynamicReels {}, "
# The same with the plant's tension sensor named.
FULL_SENSOR = ("controller: {pose: full, tension_control: true}, plant: !DynamicReels "
               "{tension_sensor: %s}, ")
SENSORS = ("drive_torque",)
PAPER = "safety_filter: {enabled: false}, model_monitor: {enabled: false}, "
DURATION = 10.0
HOLDABLE = 2.0  # N: t* at the true pose with the measured hand, above which no slack is allowed


@dataclasses.dataclass
class Case:
    robot: str
    scenario: str
    hand: str
    plant: str       # "dynamic" (full pose, tension control) or "kinematic" (default)
    method: str      # "paper" or "default"
    overlay: str
    sensor: str = "-"  # the dynamic plant's tension sensor


def _direction(resolved, pair):
    """Minus the gradient of the pair's distance at the start (unit): across its plane."""
    from cdpm_drake.kernels.interference import pair_distances

    robot, p0 = resolved.robot, np.asarray(resolved.scenario.initial_position, dtype=float)
    k = robot.pair_position(*pair)
    h = 1e-6
    g = np.array([(pair_distances(robot, p0 + h * e)[k] - pair_distances(robot, p0 - h * e)[k])
                  / (2 * h) for e in np.eye(3)])
    return -g / np.linalg.norm(g)


def _scripted(force, ramp=0.1):
    f = [round(float(x), 6) for x in force]
    if ramp <= 0:
        return "operator: !ScriptedOperator {times: [0, %g], forces: [%s, %s]}, " % (
            DURATION, f, f)
    return ("operator: !ScriptedOperator {times: [0, %g, %g], forces: [[0, 0, 0], %s, %s]}, "
            % (ramp, DURATION, f, f))


def _noisy(seed):
    """A hand of ~2 N rms: three slow sines per axis (0.3-2 Hz), scripted at 50 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, DURATION + 1e-9, 0.02)
    F = np.zeros((t.size, 3))
    for axis in range(3):
        for _ in range(3):
            F[:, axis] += rng.normal(scale=0.95) * np.sin(
                2 * np.pi * rng.uniform(0.3, 2.0) * t + rng.uniform(0, 2 * np.pi))
    return ("operator: !ScriptedOperator {times: %s, forces: %s}, sensor: {noise_std: 0.5}, "
            % (np.round(t, 4).tolist(), np.round(F, 4).tolist()))


def cases(quick: bool = False, sensors=SENSORS, methods=("paper", "default"),
          plants=("dynamic", "kinematic"), rates=RATES) -> list:
    from cdpm_drake.config import load_resolved_scenario

    out = []
    for label, scenario, pairs in ROBOTS:
        resolved = load_resolved_scenario(scenario)
        robot = resolved.robot
        p0 = np.asarray(resolved.scenario.initial_position, dtype=float)
        hands = {}
        for pair in pairs:
            u = _direction(resolved, pair)
            name = f"{pair[0]}-{pair[1]}"
            for F in ((10, 40) if quick else (5, 10, 20, 40)):
                hands[f"push {F} N across {name}"] = (_scripted(F * u), True)
            hands[f"step 40 N across {name}"] = (_scripted(40 * u, ramp=0), False)
            for rate in rates:
                hands[f"push 40 N across {name} at {rate:g} N/s"] = (
                    _scripted(40 * u, ramp=40.0 / rate), False)
            for F in ((40,) if quick else (10, 40)):
                target = (p0 + 1.0 * u).round(4).tolist()
                hands[f"spring {F} N across {name}"] = (
                    "operator: !SpringHandOperator {waypoints: [%s, %s], times: [0, 1], "
                    "stiffness: 60, damping: 6, max_force: %g}, "
                    % (p0.round(4).tolist(), target, F), False)
        if not quick:
            for F in (20, 40):
                hands[f"lift {F} N"] = (_scripted([0, 0, F]), False)
        for rate in rates:
            hands[f"lift 40 N at {rate:g} N/s"] = (_scripted([0, 0, 40], ramp=40.0 / rate),
                                                  False)
        if not quick:
            corner = np.where(p0 - robot.workspace.lower < robot.workspace.upper - p0,
                              robot.workspace.lower, robot.workspace.upper)
            corner[2] = robot.workspace.upper[2]
            c = corner - p0
            hands["corner 20 N"] = (_scripted(20 * c / np.linalg.norm(c)), False)
            hands["noisy 2 N rms"] = (_noisy(7), False)
        for hand, (overlay, kinematic_too) in hands.items():
            for plant in ("dynamic", "kinematic") if kinematic_too else ("dynamic",):
                if plant not in plants:
                    continue
                for method in methods:
                    # The paper's robot has no tension sensor (nor its method a damping).
                    for sensor in (sensors if plant == "dynamic" and method == "default"
                                   else ("none" if plant == "dynamic" else "-",)):
                        text = "{duration: %g, %s%s%s}" % (
                            DURATION, FULL_SENSOR % sensor if plant == "dynamic" else "",
                            PAPER if method == "paper" else "", overlay)
                        out.append(Case(label, scenario, hand, plant, method, text, sensor))
    return out


def measure(case: Case) -> dict:
    """Run one case and measure it (module docstring), the runs' warnings quiet and the
    logging as it was after: a test that calls it in-process must not silence the tests
    after it."""
    before = logging.root.manager.disable
    logging.disable(logging.WARNING)
    try:
        return _measure(case)
    finally:
        logging.disable(before)


def _measure(case: Case) -> dict:
    from cdpm_drake.kernels.interference import posed_pair_distances
    from cdpm_drake.kernels.rotation import rotations_from_rpy
    from cdpm_drake.config import load_resolved_scenario
    from cdpm_drake.robot.statics import posed_holding_tension
    from cdpm_drake.runs.simulate import simulate

    resolved = load_resolved_scenario(case.scenario, case.overlay)
    robot = resolved.robot
    start = time.perf_counter()
    result = simulate(scenario=resolved)
    wall = time.perf_counter() - start
    log = result.log
    d_l = np.asarray(log["d_l"], dtype=float)
    row = dataclasses.asdict(case) | {"wall": wall, "rtf": result.realtime_factor}
    if "p_true" in log:
        d, crossed = posed_pair_distances(robot, log["p_true"],
                                          rotations_from_rpy(log["rpy_true"]),
                                          np.asarray(log["d_u"], dtype=float))
        t_star = posed_holding_tension(robot, log["p_true"], log["rpy_true"], log["F_H"])
        slack = log["slack"].any(axis=1)
        holdable = slack & (t_star >= HOLDABLE)
        # The promise's bar: slack where the statics at the true pose could hold the hand
        # with every tension in [HOLDABLE, max_tension] (computed on the slack ticks only).
        ticks = np.flatnonzero(slack)
        within = np.zeros(slack.size, dtype=bool)
        if ticks.size:
            within[ticks] = posed_holding_tension(
                robot, log["p_true"][ticks], log["rpy_true"][ticks], log["F_H"][ticks],
                floor=HOLDABLE, ceiling=resolved.scenario.controller.max_tension) >= 0.0
        first = np.flatnonzero(slack)
        row |= {"slack_holdable": int(np.sum(holdable)),
                "slack_within": int(np.sum(within)),
                "slack_ticks": int(slack.sum()),
                "first_slack": float(log["time"][first[0]]) if first.size else None,
                "min_tension": float(log["tensions"].min()),
                "max_tilt_deg": float(np.degrees(np.abs(log["rpy_true"])).max())}
        unholdable = np.flatnonzero(t_star < 0.0)
        row["first_unholdable"] = (float(log["time"][unholdable[0]]) if unholdable.size
                                   else None)
    else:
        d, crossed = log["pair_distances"], log["crossed"]
        row |= {"slack_holdable": None, "slack_within": None, "slack_ticks": None,
                "first_slack": None,
                "min_tension": None,
                "max_tilt_deg": None, "first_unholdable": None}
    margin_mm = 1000 * (d - d_l[None, :])
    k = int(np.unravel_index(np.argmin(margin_mm), margin_mm.shape)[1])
    row |= {"closest_vs_d_l_mm": float(margin_mm.min()),
            "closest_pair": "%d-%d" % tuple(robot.pairs[k]),
            "crossed": bool(np.any(crossed)),
            "fault": "" if result.error is None else str(result.error),
            "fault_time": None if result.error is None else float(log["time"][-1])}
    fast = (np.flatnonzero(np.asarray(log["tension_status"]).reshape(-1) == 5)
            if "tension_status" in log else np.zeros(0, dtype=int))
    row["first_too_fast"] = float(log["time"][fast[0]]) if fast.size else None
    # Without a tension sensor: the first warning of the ringing the encoders cannot see,
    # and whether every cable that went slack was warned of at or before its first slack.
    row["first_ringing"], row["ringing_before_slack"] = None, None
    if "ringing_warned" in log:
        warned = np.asarray(log["ringing_warned"]) > 0.5
        ticks = np.flatnonzero(warned.any(axis=1))
        row["first_ringing"] = float(log["time"][ticks[0]]) if ticks.size else None
        if "slack" in log and log["slack"].any():
            slack = np.asarray(log["slack"], dtype=bool)
            row["ringing_before_slack"] = all(
                warned[:int(np.argmax(slack[:, i])) + 1, i].any()
                for i in np.flatnonzero(slack.any(axis=0)))
    status = log.get("filter_status")
    row["modified_share"] = None if status is None else float(np.mean(status[:, 0] > 0))
    row["held_share"] = None if status is None else float(np.mean(status[:, 0] >= 3))
    return row


def run_parallel(fn, todo, jobs):
    """[fn(x) for x in todo], on `jobs` spawned processes when more than one (fn a module's
    top-level function: the benchmark's measure, or the damping benchmark's)."""
    if jobs <= 1:
        return [fn(c) for c in todo]
    with multiprocessing.get_context("spawn").Pool(jobs) as pool:
        return pool.map(fn, todo, chunksize=1)


def table(rows) -> str:
    """The markdown table of the benchmark's rows."""
    head = ("| robot | hand | plant | method | sensor | closest vs d_l (mm) | crossed | slack "
            "ticks (holdable; in [2, 100] N) | first slack / 'hand too fast' / ringing warning (s) | min "
            "tension (N) | max tilt (deg) | fault | modified / held (%) |")
    lines = [head, "|" + " --- |" * 13]
    for r in rows:
        fault = "-"
        if r["fault"]:
            late = ""
            if r["first_unholdable"] is not None:
                late = f", {1000 * (r['fault_time'] - r['first_unholdable']):.0f} ms after t*<0"
            fault = f"{r['fault'].split(':')[0][:40]} at {r['fault_time']:.3f} s{late}"
        slack = ("-" if r["slack_ticks"] is None
                 else f"{r['slack_ticks']} ({r['slack_holdable']}; {r['slack_within']})")
        first = " / ".join("-" if r.get(k) is None else f"{r[k]:.3f}"
                           for k in ("first_slack", "first_too_fast", "first_ringing"))
        if r.get("ringing_before_slack") is not None:
            first += " (warned first)" if r["ringing_before_slack"] else " (NOT warned first)"
        held = ("-" if r["modified_share"] is None
                else f"{100 * r['modified_share']:.0f} / {100 * r['held_share']:.1f}")
        cells = (r["robot"], r["hand"], r["plant"], r["method"], r.get("sensor", "-"),
                 f"{r['closest_vs_d_l_mm']:+.2f} ({r['closest_pair']})",
                 "yes" if r["crossed"] else "no", slack, first,
                 "-" if r["min_tension"] is None else f"{r['min_tension']:.2f}",
                 "-" if r["max_tilt_deg"] is None else f"{r['max_tilt_deg']:.2f}", fault, held)
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(lines)


def totals(rows) -> str:
    """Per plant, method and sensor: the holdable slack ticks, the hands with any, the runs
    that ended early (a fault) and the crossings, over the rows."""
    groups = {}
    for r in rows:
        groups.setdefault((r["plant"], r["method"], r.get("sensor", "-")), []).append(r)
    lines = ["| plant | method | sensor | runs | holdable slack ticks | hands with any | "
             "in [2, 100] N: ticks, hands | ended early | crossed |", "|" + " --- |" * 9]
    for (plant, method, sensor), rs in groups.items():
        slack = [r["slack_holdable"] for r in rs if r["slack_holdable"] is not None]
        within = [r["slack_within"] for r in rs if r.get("slack_within") is not None]
        lines.append("| %s | %s | %s | %d | %s | %s | %s | %d | %d |" % (
            plant, method, sensor, len(rs), sum(slack) if slack else "-",
            sum(1 for s in slack if s > 0) if slack else "-",
            "%d, %d" % (sum(within), sum(1 for s in within if s > 0)) if within else "-",
            sum(1 for r in rs if r["fault"]), sum(1 for r in rs if r["crossed"])))
    return "\n".join(lines)


def main(argv=None) -> int:
    global DURATION
    parser = argparse.ArgumentParser(description=__doc__,
                                      formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="a subset of the hands")
    parser.add_argument("--jobs", type=int, default=max(1, multiprocessing.cpu_count()),
                        help="parallel runs (default: every core)")
    parser.add_argument("--json", metavar="PATH", help="also write every row as JSON")
    parser.add_argument("--only", metavar="TEXT", help="only the cases whose robot or hand "
                        "contains TEXT")
    parser.add_argument("--sensors", default=",".join(SENSORS),
                        help="the dynamic plant's tension sensors of the default controller's "
                        "rows, comma-separated (none, drive_torque, load_cell)")
    parser.add_argument("--methods", default="paper,default",
                        help="paper (the filter and the monitor off), default, or both")
    parser.add_argument("--plants", default="dynamic,kinematic",
                        help="dynamic, kinematic, or both")
    parser.add_argument("--duration", type=float, default=DURATION, help="s per run")
    parser.add_argument("--rates", default=",".join(str(r) for r in RATES),
                        help="ramp rates (N/s) of the 40 N pushes and lifts, comma-separated "
                        "('' for none)")
    args = parser.parse_args(argv)
    logging.disable(logging.WARNING)
    DURATION = args.duration
    todo = cases(args.quick, tuple(args.sensors.split(",")), tuple(args.methods.split(",")),
                 tuple(args.plants.split(",")),
                 tuple(float(r) for r in args.rates.split(",") if r))
    if args.only:
        todo = [c for c in todo if args.only in c.robot or args.only in c.hand]
    print(f"{len(todo)} runs of {DURATION:g} s on {args.jobs} processes ...", file=sys.stderr)
    start = time.perf_counter()
    rows = run_parallel(measure, todo, args.jobs)
    print(table(rows))
    print(f"\n{len(rows)} runs in {time.perf_counter() - start:.0f} s", file=sys.stderr)
    print(totals(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
