"""Instructions per tick of the Fig. 5 diagram, by callgrind (they repeat exactly, unlike
wall time on a shared machine): where the time goes, and before/after comparisons.

Each variant runs in its own `valgrind --tool=callgrind --instr-atstart=no` process, which
builds exp2's diagram, advances 0.1 s untimed (start-up, first evaluations), then counts only
the next --ticks ticks (collection switched on and off around that AdvanceTo with
callgrind_control). Variants as in scripts/bench/bench_diagram.py: the product, without loggers,
the Python-block floor (math replaced by no-ops) and the all-C++ floor. --code-root DIR
measures the product of another checkout too (e.g. `git archive <commit> | tar -x -C DIR`),
in the same run. --by-library adds the product's split by shared object.

Usage: python scripts/bench/count_instructions.py [--ticks 500] [--jobs 2] [--code-root DIR]
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import os, subprocess, sys
sys.path.insert(0, {code_root!r})
sys.path.insert(1, {scripts!r})
from pydrake.systems.analysis import Simulator
try:  # a checkout from before the package's layer folders (--code-root): its own module
    from cdpm_drake.scenario import load_scenario
except ImportError:
    from cdpm_drake.config import load_scenario
from cdpm_drake import diagram as d
variant, seconds = {variant!r}, {seconds!r}
patch = None
options = d.BuildOptions(loggers=variant != "without loggers") if hasattr(d, "BuildOptions") else None
if variant.startswith("floor"):
    import bench_diagram as b
    patch = (b.all_cpp if "all C++" in variant else b.without_math)()
    patch.__enter__()
scenario = load_scenario("exp2_interaction")
diagram = d.build_diagram(scenario, options) if options is not None else d.build_diagram(scenario)
simulator = Simulator(diagram)
simulator.Initialize()
simulator.AdvanceTo(0.1)
subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=True,
               stdout=subprocess.DEVNULL)
simulator.AdvanceTo(0.1 + seconds)
subprocess.run(["callgrind_control", "-i", "off", str(os.getpid())], check=True,
               stdout=subprocess.DEVNULL)
"""

VARIANTS = ("product (loggers on)", "without loggers",
            "floor, Python blocks: math replaced by no-ops",
            "floor, all C++: Python blocks replaced by C++ stand-ins")


def count(variant, code_root, ticks, out_dir):
    out = Path(out_dir) / f"{abs(hash((variant, code_root)))}.out"
    code = CHILD.format(code_root=str(code_root), scripts=str(ROOT / "scripts" / "bench"),
                        variant=variant, seconds=ticks * 0.002)
    subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no",
                    f"--callgrind-out-file={out}", sys.executable, "-c", code],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    text = subprocess.run(["callgrind_annotate", "--threshold=100", str(out)], check=True,
                          capture_output=True, text=True).stdout
    return text


def total(text):
    return int(re.search(r"([\d,]+) \(100\.0%\)\s+PROGRAM TOTALS", text).group(1)
               .replace(",", ""))


LIBRARIES = (("Drake C++ (libdrake)", "libdrake"), ("pydrake bindings", "/pydrake/"),
             ("Python interpreter", "libpython"), ("numpy", "numpy"),
             ("C++ runtime (casts, hashing)", "libstdc++"), ("libc (malloc/free)", "libc.so"),
             ("numba dispatcher and runtime", "numba"))


def by_library(text):
    shares = dict.fromkeys([name for name, _ in LIBRARIES] + ["compiled kernels and other"], 0)
    for line in text.splitlines():
        m = re.match(r"\s*([\d,]+) \(\s*[\d.]+%\)\s+(.*)", line)
        if not m or "PROGRAM TOTALS" in line:
            continue
        n, where = int(m.group(1).replace(",", "")), m.group(2)
        for name, needle in LIBRARIES:
            if needle in where or (needle == "libpython" and "Python-3" in where):
                shares[name] += n
                break
        else:
            shares["compiled kernels and other"] += n
    return shares


def main():
    from cdpm_drake.text import format_table

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ticks", type=int, default=500, help="ticks counted (default 500)")
    parser.add_argument("--jobs", type=int, default=2, help="valgrind processes at a time")
    parser.add_argument("--code-root", type=Path, help="another checkout to count too")
    parser.add_argument("--by-library", action="store_true")
    args = parser.parse_args()
    if args.ticks < 1 or args.jobs < 1:
        parser.error("--ticks and --jobs must be >= 1")
    runs = [(v, ROOT) for v in VARIANTS]
    if args.code_root is not None:
        runs.insert(0, (VARIANTS[0], args.code_root.resolve()))
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
        texts = list(pool.map(lambda r: count(r[0], r[1], args.ticks, tmp), runs))
    product = total(texts[runs.index((VARIANTS[0], ROOT))])
    rows = []
    for (variant, root), text in zip(runs, texts):
        n = total(text) / args.ticks
        label = variant if root == ROOT else f"{variant}, {root}"
        rows.append([label, f"{n / 1000:.1f}", f"{n / (product / args.ticks):.2f}"])
    print(f"exp2_interaction, {args.ticks} ticks counted after 0.1 s; instructions per tick "
          "(callgrind Ir); ratio to the product of this checkout")
    print(format_table(["diagram", "k instructions/tick", "vs product"], rows))
    if args.by_library:
        text = texts[runs.index((VARIANTS[0], ROOT))]
        rows = [[name, f"{n / args.ticks / 1000:.1f}", f"{100 * n / product:.1f} %"]
                for name, n in by_library(text).items()]
        print()
        print(format_table(["product, by library", "k instructions/tick", "share"], rows))


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    main()
