"""What one block costs a tick before it computes anything: an empty KernelSystem (a compiled
no-op kernel, bound as the blocks bind theirs) against a C++ primitive (PassThrough), bare and
inside build_kernel_block's wiring (its Selector and one-tick memory), and what each port
the block exports and the log reads costs; in instructions per tick (callgrind: exact on a
busy host) and wall time per tick (best of --repeats).

Each variant is a chain of --blocks blocks between a constant source and a periodic
VectorLogSink (the tick: 2 ms, as the controller's), so every tick evaluates the whole chain
once, as the controller's log does; the cost of a block is (variant - no blocks) / blocks.

    python scripts/bench/bench_block_cost.py [--blocks 20] [--ticks 2000] [--markdown]
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
sys.path.insert(0, str(HERE))

T = 0.002
VARIANTS = ("no blocks", "PassThrough (C++)", "KernelSystem, no-op kernel",
            "KernelSystem in build_kernel_block (Selector, memory), 1 output",
            "KernelSystem in build_kernel_block, 4 more outputs, each logged")


def build(variant: str, blocks: int):
    import numba
    import numpy as np
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, PassThrough

    from cdpm_drake.kernels.call import bind
    from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block

    @numba.njit(cache=False)
    def no_op(x, out):
        out[0] = x[0]

    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(np.ones(3)))
    port = source.get_output_port()
    logged = []
    for b in range(blocks if variant != "no blocks" else 0):
        if variant.startswith("PassThrough"):
            s = builder.AddSystem(PassThrough(3))
            builder.Connect(port, s.get_input_port())
            port = s.get_output_port()
        elif variant.startswith("KernelSystem, no-op"):
            s = builder.AddSystem(KernelSystem(3, 3, bind(no_op, np.zeros(3), np.zeros(3))))
            builder.Connect(port, s.get_input_port())
            port = s.get_output_port()
        else:
            many = "each logged" in variant
            sub = DiagramBuilder()
            outputs = [("y", 0, 3)] + ([(f"z{k}", 3 + k, 1) for k in range(4)] if many else [])
            build_kernel_block(sub, KernelSystem(10, 7, bind(no_op, np.zeros(10), np.zeros(7))),
                               inputs=[("x", 3)], memory=(7, None), outputs=outputs,
                               memory_at=0, time_step=T)
            block = builder.AddNamedSystem(f"block{b}", sub.Build())
            builder.Connect(port, block.GetInputPort("x"))
            port = block.GetOutputPort("y")
            if many:
                logged += [block.GetOutputPort(f"z{k}") for k in range(4)]
    LogVectorOutput(port, builder, T)
    for p in logged:
        LogVectorOutput(p, builder, T)
    return builder.Build()


def child(variant, blocks, ticks, callgrind):
    from pydrake.systems.analysis import Simulator

    simulator = Simulator(build(variant, blocks))
    simulator.Initialize()
    simulator.AdvanceTo(0.1)
    if callgrind:
        subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=True,
                       stdout=subprocess.DEVNULL)
    t0 = time.perf_counter()
    simulator.AdvanceTo(0.1 + ticks * T)
    wall = time.perf_counter() - t0
    if callgrind:
        subprocess.run(["callgrind_control", "-i", "off", str(os.getpid())], check=True,
                       stdout=subprocess.DEVNULL)
    return wall


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--blocks", type=int, default=20)
    parser.add_argument("--ticks", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--markdown", action="store_true")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--callgrind", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(child(args.child, args.blocks, args.ticks, args.callgrind))
        return
    from count_instructions import total

    base = [sys.executable, __file__, "--blocks", str(args.blocks)]
    counts, walls = {}, dict.fromkeys(VARIANTS, float("inf"))
    with tempfile.TemporaryDirectory() as tmp:
        for v in VARIANTS:
            out = Path(tmp) / f"{VARIANTS.index(v)}.out"
            subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no",
                            f"--callgrind-out-file={out}"] + base
                           + ["--ticks", "200", "--child", v, "--callgrind"], check=True,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            text = subprocess.run(["callgrind_annotate", str(out)], check=True,
                                  capture_output=True, text=True).stdout
            counts[v] = total(text) / 200
    for _ in range(args.repeats):
        for v in VARIANTS:
            text = subprocess.run(base + ["--ticks", str(args.ticks), "--child", v],
                                  check=True, capture_output=True, text=True).stdout
            walls[v] = min(walls[v], float(text.strip().splitlines()[-1]) / args.ticks)
    n = args.blocks
    rows = []
    for v in VARIANTS[1:]:
        rows.append([v, f"{(counts[v] - counts[VARIANTS[0]]) / n:,.0f}",
                     f"{(walls[v] - walls[VARIANTS[0]]) / n * 1e6:.1f}"])
    headers = ["one block (of a chain of %d), per tick" % n, "instructions", "wall (us)"]
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; no blocks: "
          f"{counts[VARIANTS[0]]:,.0f} instructions, {walls[VARIANTS[0]] * 1e6:.1f} us a tick")
    if args.markdown:
        print("| " + " | ".join(headers) + " |\n|---|---:|---:|")
        print("\n".join("| " + " | ".join(r) + " |" for r in rows))
    else:
        for r in rows:
            print("  ".join(r))


if __name__ == "__main__":
    main()
