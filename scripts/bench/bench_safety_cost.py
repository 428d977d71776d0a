"""What the hard promise costs a tick: experiment 2's diagram as shipped, each safety
block off, the paper's Fig. 5, the safety blocks' Drake cost alone and the all-C++ floor, in
instructions per tick (callgrind: exact and repeatable on a busy host) and in real-time factor
(wall clock, best of --repeats interleaved runs), all in one run, with ratios against Fig. 5
measured in the same run.

Variants (exp2_interaction; --plant dynamic runs each on `!DynamicReels {}`, --full adds the
full pose and tension control):
- shipped: the safety filter, the kinetostatic force and the model monitor on;
- no kinetostatic force: `safety_filter: {kinetostatic: false}`;
- no model monitor: `model_monitor: {enabled: false}`;
- Fig. 5: `safety_filter: {enabled: false}, model_monitor: {enabled: false}` (the reference);
- safety blocks, no math: as shipped with the three safety kernels replaced by no-ops (the
  blocks' ports, wiring, Python callbacks and log columns: what a block costs before it
  computes anything; its results are meaningless, only its cost is measured);
- all-C++ floor: as shipped with every Python block replaced by a C++ stand-in
  (bench_diagram.all_cpp; the kinematic plant only).

The goal: shipped / Fig. 5 real-time factor >= 0.65 on the kinematic plant and >= 0.80 on the
dynamic plant with the full pose and tension control.

    python scripts/bench/bench_safety_cost.py                    # ~4 min on 2 cores
    python scripts/bench/bench_safety_cost.py --plant dynamic --no-instructions
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

FIG_5 = "Fig. 5 (reference)"
VARIANTS = (
    ("shipped", ""),
    ("no kinetostatic force", "safety_filter: {kinetostatic: false}"),
    ("no model monitor", "model_monitor: {enabled: false}"),
    (FIG_5, "safety_filter: {enabled: false}, model_monitor: {enabled: false}"),
    ("safety blocks, no math", ""),
    ("all-C++ floor", ""),
)
PLANTS = {"kinematic": "", "dynamic": "plant: !DynamicReels {}"}
FULL = "controller: {pose: full, tension_control: true}"


def overlay(variant: str, plant: str, full: bool) -> str:
    parts = [p for p in (PLANTS[plant], FULL if full else "", dict(VARIANTS)[variant]) if p]
    return "{" + ", ".join(parts) + "}"


def _no_math():
    """The three safety kernels as Python no-ops returning OK (bench_diagram.Patch): a no-op
    from Python costs about what a bound kernel's call does before its first instruction."""
    from bench_diagram import Patch

    from cdpm_drake.systems import kinetostatic_force, model_monitor, safety_filter

    def bind(kernel, *example):
        through = getattr(kernel, "__name__", "") == "filter_tick"

        def no_op(*args):  # zeros out; the filter passes the velocity asked for through
            args[-1].fill(0.0)
            if through:
                args[-1][:3] = args[-2][:3]
            return 0
        return no_op
    return Patch([(m, "bind", bind) for m in (kinetostatic_force, safety_filter, model_monitor)])


def child(variant: str, plant: str, full: bool, start: float, seconds: float,
          callgrind: bool) -> float:
    """Build the variant, advance `start` s untimed, then time (or count, under callgrind)
    the next `seconds`; returns the wall time of those."""
    from pydrake.systems.analysis import Simulator

    from cdpm_drake.config import load_scenario
    from cdpm_drake.diagram import build_diagram, reserve_log

    patch = None
    if variant == "safety blocks, no math":
        patch = _no_math()
    elif variant == "all-C++ floor":
        import bench_diagram
        patch = bench_diagram.all_cpp()
    if patch is not None:
        patch.__enter__()
    diagram = build_diagram(load_scenario("exp2_interaction", overlay(variant, plant, full)))
    simulator = Simulator(diagram)
    simulator.Initialize()
    reserve_log(diagram, simulator.get_mutable_context(),
                int((start + seconds) / 0.002) + 2)
    simulator.AdvanceTo(start)
    if callgrind:
        subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=True,
                       stdout=subprocess.DEVNULL)
    t0 = time.perf_counter()
    simulator.AdvanceTo(start + seconds)
    wall = time.perf_counter() - t0
    if callgrind:
        subprocess.run(["callgrind_control", "-i", "off", str(os.getpid())], check=True,
                       stdout=subprocess.DEVNULL)
    return wall


def _child_args(variant, args, start, seconds):
    return [sys.executable, __file__, "--child", variant, "--plant", args.plant,
            "--start", str(start), "--seconds", str(seconds)] + (["--full"] if args.full
                                                                  else [])


def instructions(variant, args, out_dir) -> float:
    """Instructions per tick of `variant` (callgrind, --ticks ticks after 1 s)."""
    out = Path(out_dir) / f"{abs(hash(variant))}.out"
    subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no",
                    f"--callgrind-out-file={out}"]
                   + _child_args(variant, args, 1.0, args.ticks * 0.002) + ["--callgrind"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    from count_instructions import total

    text = subprocess.run(["callgrind_annotate", str(out)], check=True, capture_output=True,
                          text=True).stdout
    return total(text) / args.ticks


def wall(variant, args) -> float:
    """Wall seconds of --duration s simulated (after 0.1 s untimed), in a fresh process; nan
    where the run fails (a variant whose safety block is off may end on a fault: its last
    line of stderr is printed)."""
    run = subprocess.run(_child_args(variant, args, 0.1, args.duration), capture_output=True,
                         text=True)
    if run.returncode != 0:
        print(f"{variant}: the run failed: {run.stderr.strip().splitlines()[-1]}",
              file=sys.stderr)
        return float("nan")
    return float(run.stdout.strip().splitlines()[-1])


def main():
    from cdpm_drake.text import format_table

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--plant", choices=sorted(PLANTS), default="kinematic")
    parser.add_argument("--full", action="store_true", help="full pose and tension control")
    parser.add_argument("--ticks", type=int, default=500, help="ticks counted by callgrind")
    parser.add_argument("--duration", type=float, default=10.0, help="simulated s per timing")
    parser.add_argument("--repeats", type=int, default=3, help="interleaved timings per variant")
    parser.add_argument("--no-instructions", action="store_true")
    parser.add_argument("--jobs", type=int, default=2, help="valgrind processes at a time")
    parser.add_argument("--markdown", action="store_true")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--start", type=float, default=0.1, help=argparse.SUPPRESS)
    parser.add_argument("--seconds", type=float, default=1.0, help=argparse.SUPPRESS)
    parser.add_argument("--callgrind", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(child(args.child, args.plant, args.full, args.start, args.seconds,
                    args.callgrind))
        return
    if args.ticks < 1 or args.duration <= 0 or args.repeats < 1 or args.jobs < 1:
        parser.error("--ticks, --duration, --repeats and --jobs must be positive")
    names = [name for name, _ in VARIANTS]
    if args.plant != "kinematic":  # bench_diagram's C++ stand-ins cover the kinematic plant's
        names.remove("all-C++ floor")  # blocks only
    counts = {}
    if not args.no_instructions:
        with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
            counts = dict(zip(names, pool.map(lambda v: instructions(v, args, tmp), names)))
    best = dict.fromkeys(names, float("inf"))
    for _ in range(args.repeats):  # interleaved: a busy spell hits every variant alike
        for name in names:
            seconds = wall(name, args)
            best[name] = seconds if seconds != seconds else min(best[name], seconds)
    rows = []
    for name in names:
        rtf = args.duration / best[name]
        row = [name, f"{rtf:.1f}x", f"{best[FIG_5] / best[name]:.3f}"]
        if counts:
            row += [f"{counts[name] / 1000:.1f}", f"{counts[FIG_5] / counts[name]:.3f}"]
        rows.append(row)
    load = os.getloadavg()[0]
    what = f"exp2_interaction, {args.plant} plant" + (", full pose, tension control"
                                                       if args.full else "")
    print(f"{what}: real-time factor best of {args.repeats} interleaved {args.duration:g} s "
          f"runs (load average {load:.1f} on {os.cpu_count()} cores)"
          + ("" if args.no_instructions else f"; instructions per tick over {args.ticks} "
             "ticks after 1 s (callgrind)"))
    headers = ["diagram", "real-time factor", "Fig. 5 / it (wall)"]
    if counts:
        headers += ["k instructions/tick", "Fig. 5 / it (instructions)"]
    if args.markdown:
        print("| " + " | ".join(headers) + " |\n|" + "---|" * len(headers))
        print("\n".join("| " + " | ".join(row) + " |" for row in rows))
    else:
        print(format_table(headers, rows))
    goal = 0.65 if args.plant == "kinematic" else 0.80
    ratio = best[FIG_5] / best["shipped"]
    print(f"shipped / Fig. 5: {ratio:.3f} by wall clock against the goal {goal} "
          f"({'met' if ratio >= goal else 'not met'})"
          + ("" if not counts else f"; {counts[FIG_5] / counts['shipped']:.3f} in "
             "instructions"))


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    main()
