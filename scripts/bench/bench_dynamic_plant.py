"""Benchmark of the dynamic plant (`plant: !DynamicReels`) beside the kinematic plant
(`!SimulatedReels`), in one run: the kinematic plant is the reference of every ratio.

1. Wall clock: experiment 2 (exp2_interaction), `--duration` s simulated after building and
   initialising (loggers on, the log's rows reserved, as `cdpm simulate` does), best of
   `--repeats` runs interleaved across the rows:
   - kinematic plant (the reference), dynamic plant at its default 1 ms step (the product),
     at 2 ms and at 0.5 ms;
   - floor, Python math as no-ops: the product's diagram with every compiled kernel (the
     controller's blocks and the plant's step) replaced by a no-op: the Python callbacks,
     ports, C++ delays, Selectors, the MultibodyPlant and the loggers all still run;
   - floor, MultibodyPlant alone: one free body with constant generalized forces, stepped at
     1 ms (two steps per 2 ms tick): Drake's own cost of the rigid body;
   - with `--before DIR` (a checkout of older code, e.g. `git archive <commit> | tar -x -C
     DIR`): that code's dynamic plant, in a process of its own, same conditions.
   Columns: real-time factor (simulated s per wall s), us per 2 ms tick, us per plant step.
2. `--instructions`: the same rows counted by callgrind (instructions per tick over `--ticks`
   ticks after 0.1 s, each in its own valgrind process): exact and repeatable on a busy host.
3. `--sweep N`: sweep throughput: the first N variants of the shipped sweep
   exp2_dynamic_du_Fu on the local workers (`cdpm sweep`'s runner), against the same variants
   of exp2_du_Fu on the kinematic plant; worker start-up is paid in a warm-up and left out.

Usage: python scripts/bench/bench_dynamic_plant.py [--duration 10] [--repeats 3] [--instructions]
           [--ticks 500] [--sweep 8] [--before DIR]
"""

import argparse
import contextlib
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts" / "bench"

GOAL = 25.0  # x real time for exp2 on the dynamic plant, 1 ms step, loggers on
SCENARIO = "exp2_interaction"
# (row label, plant overlay or None for the MultibodyPlant alone, patch of the kernels)
ROWS = (
    ("kinematic plant (reference)", "plant: !SimulatedReels {}", None),
    ("dynamic plant, 1 ms step (product)", "plant: !DynamicReels {}", None),
    ("dynamic plant, 2 ms step", "plant: !DynamicReels {time_step: 0.002}", None),
    ("dynamic plant, 0.5 ms step", "plant: !DynamicReels {time_step: 0.0005}", None),
    ("floor: dynamic, Python math as no-ops", "plant: !DynamicReels {}", "no-ops"),
    ("floor: MultibodyPlant alone, 1 ms", None, None),
)

# Code that measures one row in any checkout (used for --before and for callgrind): builds,
# initialises, runs 0.1 s, then `seconds` more, timed (or counted).
CHILD = r"""
import os, subprocess, sys, time
sys.path.insert(0, {code_root!r})
sys.path.insert(1, {scripts!r})
from pydrake.systems.analysis import Simulator
import bench_dynamic_plant as bench
diagram = bench.build_row({label!r}, {overlay!r}, {patch!r})
simulator = Simulator(diagram)
simulator.Initialize()
bench.reserve(diagram, simulator, {seconds!r} + 0.1)
simulator.AdvanceTo(0.1)
count = {count!r}
if count:
    subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=True,
                   stdout=subprocess.DEVNULL)
start = time.perf_counter()
simulator.AdvanceTo(0.1 + {seconds!r})
wall = time.perf_counter() - start
if count:
    subprocess.run(["callgrind_control", "-i", "off", str(os.getpid())], check=True,
                   stdout=subprocess.DEVNULL)
print("WALL", wall)
"""


def mbp_alone():
    """One free rigid body (the platform's mass and inertia) in a discrete MultibodyPlant at
    1 ms, its weight held by a constant generalized force: the rigid body's floor."""
    from pydrake.multibody.plant import DiscreteContactApproximation, MultibodyPlant
    from pydrake.multibody.tree import RotationalInertia, SpatialInertia
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    builder = DiagramBuilder()
    mbp = builder.AddSystem(MultibodyPlant(time_step=0.001))
    if hasattr(DiscreteContactApproximation, "kTamsi"):
        mbp.set_discrete_contact_approximation(DiscreteContactApproximation.kTamsi)
    mbp.AddRigidBody("platform", SpatialInertia.MakeFromCentralInertia(
        2.5, np.zeros(3), RotationalInertia(0.0525, 0.0525, 0.0525)))
    mbp.Finalize()
    hold = builder.AddSystem(ConstantVectorSource([0.0, 0.0, 0.0, 0.0, 0.0, 2.5 * 9.81]))
    builder.Connect(hold.get_output_port(), mbp.get_applied_generalized_force_input_port())
    return builder.Build()


@contextlib.contextmanager
def no_op_math():
    """Every compiled kernel a block or the dynamic plant calls, replaced by a no-op (the
    plant's step writes zeros: the MultibodyPlant refuses a NaN force)."""
    import numba

    import bench_diagram
    from cdpm_drake.systems.plants import dynamic_plant

    @numba.njit(cache=True)
    def zero_step(reels, attachments, handle, params, R, x, out):
        out[:] = 0.0

    @numba.njit(cache=True)
    def no_person(kind, times, rows, params, t, x, ip, iv, out, io):
        pass

    patch = bench_diagram.Patch([(dynamic_plant, "cable_net_step", zero_step),
                                 (dynamic_plant, "operator_force_at", no_person)])
    with bench_diagram.without_math(), patch:
        yield


def build_row(label, overlay, patch):
    """The diagram of one row (see ROWS)."""
    if overlay is None:
        return mbp_alone()
    from cdpm_drake.diagram import build_diagram
    from cdpm_drake.config import load_scenario

    scenario = load_scenario(SCENARIO, overlay)
    if patch == "no-ops":
        with no_op_math():
            return build_diagram(scenario)
    return build_diagram(scenario)


def reserve(diagram, simulator, seconds):
    try:
        from cdpm_drake.diagram import reserve_log
    except ImportError:  # an older checkout
        return
    reserve_log(diagram, simulator.get_mutable_context(), int(seconds / 0.002) + 2)


def run_row(label, overlay, patch, seconds):
    """Wall-clock seconds of `seconds` simulated (after 0.1 s untimed), in this process."""
    from pydrake.systems.analysis import Simulator

    diagram = build_row(label, overlay, patch)
    simulator = Simulator(diagram)
    simulator.Initialize()
    reserve(diagram, simulator, seconds + 0.1)
    simulator.AdvanceTo(0.1)
    start = time.perf_counter()
    simulator.AdvanceTo(0.1 + seconds)
    return time.perf_counter() - start


def run_child(code_root, label, overlay, patch, seconds, count_file=None):
    """The same as run_row in a process of its own with `code_root` first on the path; with
    count_file, under callgrind (instructions counted over the timed part only)."""
    code = CHILD.format(code_root=str(code_root), scripts=str(SCRIPTS), label=label,
                        overlay=overlay, patch=patch, seconds=seconds,
                        count=count_file is not None)
    command = [sys.executable, "-c", code]
    if count_file is not None:
        command = ["valgrind", "--tool=callgrind", "--instr-atstart=no",
                   f"--callgrind-out-file={count_file}"] + command
    env = dict(os.environ, PYTHONHASHSEED="0")
    out = subprocess.run(command, check=True, capture_output=True, text=True, env=env).stdout
    return float(re.search(r"WALL ([\d.eE+-]+)", out).group(1))


def instructions(count_file) -> int:
    text = subprocess.run(["callgrind_annotate", "--threshold=100", str(count_file)],
                          check=True, capture_output=True, text=True).stdout
    return int(re.search(r"([\d,]+) \(100\.0%\)\s+PROGRAM TOTALS", text).group(1)
               .replace(",", ""))


def plant_steps_per_tick(overlay):
    if overlay is None:
        return 2
    step = re.search(r"time_step: ([\d.]+)", overlay)
    return 1 if "SimulatedReels" in overlay else round(0.002 / float(step.group(1))
                                                        if step else 2)


def sweep_rows(n):
    """Throughput of the first n variants of exp2_dynamic_du_Fu and of exp2_du_Fu."""
    from cdpm_drake.runs import sweep as sw

    rows = []
    workers = sw.default_workers()
    for name in ("exp2_du_Fu", "exp2_dynamic_du_Fu"):
        variants = sw.load_sweep(name).variants[:n]
        tasks = sw.tasks_for(variants)
        seconds = sum(v.scenario.duration for v in variants)
        runner = sw.LocalRunner(workers)
        try:
            warm = sw.tasks_for([v for v in sw.load_sweep(name).variants[:workers]])
            for t in warm:  # 0.05 s each: worker start-up and the first build, untimed
                t.scenario_yaml = re.sub(r"duration: [\d.]+", "duration: 0.05", t.scenario_yaml)
            runner.run(warm, lambda row: None, lambda: False)
            done = []
            start = time.perf_counter()
            runner.run(tasks, done.append, lambda: False)
            wall = time.perf_counter() - start
        finally:
            runner.close()
        bad = [r for r in done if r["status"] != "ok"]
        if bad:
            raise SystemExit(f"bench_dynamic_plant: a sweep run failed: {bad[0]['error']}")
        rows.append([name, f"{len(tasks)} x {seconds / len(tasks):g} s", str(workers),
                     f"{wall:.2f}", f"{seconds / wall:.1f}", f"{60 * len(tasks) / wall:.0f}",
                     f"{1000 * (seconds / len(tasks)) / (seconds / wall) / 60:.1f}"])
    return rows


def main(argv=None) -> int:
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(SCRIPTS))
    from cdpm_drake.text import format_table

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=10.0, help="simulated s per run")
    parser.add_argument("--repeats", type=int, default=3, help="runs per row (best kept)")
    parser.add_argument("--instructions", action="store_true",
                        help="also count instructions per tick with callgrind (slow)")
    parser.add_argument("--ticks", type=int, default=500, help="ticks counted by callgrind")
    parser.add_argument("--sweep", type=int, default=0, metavar="N",
                        help="also measure the sweep throughput on N variants (e.g. 8)")
    parser.add_argument("--before", type=Path, metavar="DIR",
                        help="a checkout of older code: its dynamic plant as one more row")
    args = parser.parse_args(argv)
    if not args.duration > 0 or args.repeats < 1 or args.ticks < 1:
        parser.error("--duration must be > 0, --repeats and --ticks >= 1")
    rows = list(ROWS)
    if args.before is not None:
        rows.append((f"before: dynamic plant of {args.before}", "plant: !DynamicReels {}",
                     None))
    walls = {}
    for _ in range(args.repeats):  # interleaved: the host's load moves every row alike
        for label, overlay, patch in rows:
            if label.startswith("before:"):
                wall = run_child(args.before.resolve(), label, overlay, patch, args.duration)
            else:
                wall = run_row(label, overlay, patch, args.duration)
            walls[label] = min(wall, walls.get(label, np.inf))
    ticks = args.duration / 0.002
    reference = walls[rows[0][0]]
    table = []
    for label, overlay, _ in rows:
        wall = walls[label]
        per_tick = 1e6 * wall / ticks
        table.append([label, f"{args.duration / wall:.1f}x", f"{per_tick:.1f}",
                      f"{per_tick / plant_steps_per_tick(overlay):.1f}",
                      f"{wall / reference:.2f}"])
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"{SCENARIO}, {args.duration:g} s simulated after 0.1 s, best of {args.repeats} "
          f"interleaved runs; load average {load:.1f} on {os.cpu_count()} cores")
    print(format_table(["run", "real-time factor", "us per 2 ms tick", "us per plant step",
                        "wall vs kinematic"], table))
    product = args.duration / walls[rows[1][0]]
    print(f"goal >= {GOAL:g}x real time for the product: {'met' if product >= GOAL else 'not met'}"
          f" ({product:.1f}x)")

    if args.instructions:
        seconds = args.ticks * 0.002
        counted = []
        with tempfile.TemporaryDirectory() as tmp:
            for k, (label, overlay, patch) in enumerate(rows):
                root = args.before.resolve() if label.startswith("before:") else ROOT
                out = Path(tmp) / f"{k}.out"
                run_child(root, label, overlay, patch, seconds, count_file=out)
                counted.append(instructions(out) / args.ticks)
        table = [[label, f"{n / 1000:.1f}", f"{n / 1000 / plant_steps_per_tick(overlay):.1f}",
                  f"{n / counted[0]:.2f}"]
                 for (label, overlay, _), n in zip(rows, counted)]
        print()
        print(f"instructions (callgrind Ir) per 2 ms tick over {args.ticks} ticks after 0.1 s")
        print(format_table(["run", "k instructions/tick", "k per plant step",
                            "vs kinematic"], table))

    if args.sweep:
        print()
        print(f"sweep throughput: the first {args.sweep} variants of each sweep, local "
              "workers, after a warm-up")
        print(format_table(["sweep", "runs", "workers", "wall (s)", "sim s / wall s",
                            "runs / min", "1000 runs (min)"], sweep_rows(args.sweep)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
