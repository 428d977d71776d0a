"""Benchmark of the dynamic plant (`plant: !DynamicReels`): simulation speed of a scenario's
diagram with it, at several plant time steps, against the kinematic plant (`!SimulatedReels`)
measured in the same run, which is the reference of the ratios.

Each case builds the diagram once per repeat, initialises, and advances `--duration` s of
simulated time without pacing; the table has the best of `--repeats` of the wall time and the
process CPU time, the real-time factor (simulated s per wall s) and the ratio of the CPU time to
the reference's.

Usage: python scripts/bench_dynamic_plant.py [--duration 5] [--repeats 3]
                                             [--scenario exp2_interaction]
"""

import argparse
import time

from pydrake.systems.analysis import Simulator

from cdpm_drake.diagram import build_diagram
from cdpm_drake.scenario import load_scenario
from cdpm_drake.text import format_table

CASES = (
    ("kinematic (reference)", "plant: !SimulatedReels {}"),
    ("dynamic, step 2 ms", "plant: !DynamicReels {time_step: 0.002}"),
    ("dynamic, step 1 ms (default)", "plant: !DynamicReels {}"),
    ("dynamic, step 0.5 ms", "plant: !DynamicReels {time_step: 0.0005}"),
)


def measure(scenario, duration, repeats):
    """Best (wall s, CPU s) of `repeats` runs of `duration` s."""
    best_wall = best_cpu = float("inf")
    for _ in range(repeats):
        simulator = Simulator(build_diagram(scenario))
        simulator.Initialize()
        wall, cpu = time.perf_counter(), time.process_time()
        simulator.AdvanceTo(duration)
        best_wall = min(best_wall, time.perf_counter() - wall)
        best_cpu = min(best_cpu, time.process_time() - cpu)
    return best_wall, best_cpu


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=5.0, help="simulated s per run")
    parser.add_argument("--repeats", type=int, default=3, help="runs per case (best kept)")
    parser.add_argument("--scenario", default="exp2_interaction")
    args = parser.parse_args(argv)
    rows, reference = [], None
    for label, text in CASES:
        wall, cpu = measure(load_scenario(args.scenario, text), args.duration, args.repeats)
        reference = cpu if reference is None else reference
        rows.append((label, f"{wall:.3f}", f"{cpu:.3f}", f"{args.duration / wall:.2f}",
                     f"{1000 * cpu / (args.duration / 0.002):.3f}", f"{cpu / reference:.2f}"))
    print(f"{args.scenario}, {args.duration:g} s simulated, best of {args.repeats}")
    print(format_table(["plant", "wall (s)", "CPU (s)", "real-time factor", "CPU per tick (ms)",
                        "CPU / reference"], rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
