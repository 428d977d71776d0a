"""A smoke run of scripts/bench/bench_safety_filter.py --quick: it records the filter's QPs from real
runs (its replay of the filter's Python code must match the compiled ticks, or it exits 1),
and prints every table; the compiled QP agrees with an independent solver on them."""

import re
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "bench" / "bench_safety_filter.py"


def cells(line):
    return re.split(r"\s{2,}", line.strip())


def test_quick_run_prints_every_table_and_the_compiled_qp_agrees():
    out = subprocess.run([sys.executable, str(SCRIPT), "--quick"], capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    rows = {cells(line)[0]: cells(line) for line in lines if len(cells(line)) >= 5}

    # 1. Every solver that the test environment always has, on every problem.
    for label in ("cdpm_drake.kernels.qp.solve_qp, bound, from Python",
                  "cdpm_drake.kernels.qp.solve_qp, compiled loop (as filter_tick)",
                  "Drake MathematicalProgram, Clarabel", "scipy SLSQP (ftol 1e-12)"):
        assert rows[label][5] == "60/60", rows[label]
    assert rows["Drake MathematicalProgram, Clarabel"][4] == "1.000"  # the ratios' reference
    # The compiled QP against the reference solver, an independent implementation that ends
    # on the same active set (quadprog, or scipy's SLSQP where quadprog is not installed):
    # the same solution to round-off (measured: 3e-15 m/s against either).
    reference = re.search(r"z_ref: (.*?)\. ", out.stdout).group(1)
    assert reference.startswith(("quadprog", "scipy SLSQP")), reference
    for label in ("cdpm_drake.kernels.qp.solve_qp, bound, from Python",
                  "cdpm_drake.kernels.qp.solve_qp, compiled loop (as filter_tick)"):
        assert float(rows[label][6]) <= 1e-10, (reference, rows[label])
        assert float(rows[label][7]) <= 1e-12
    # Its KKT certificate (stationarity, multipliers, violation, complementarity) is exact.
    kkt = re.search(r"stationarity (\S+), multipliers >= (\S+), violation (\S+), "
                    r"complementarity (\S+)", out.stdout).groups()
    assert float(kkt[0]) < 1e-12 and float(kkt[1]) > -1e-12 and float(kkt[2]) < 1e-12 \
        and float(kkt[3]) < 1e-12, kkt

    # 2. Per run, every kernel, the interference kernel the reference; the safety kernels'
    # sum per tick is at least each of its parts in every tick, so in its p50 and p99 too.
    kernels = [cells(line) for line in lines if len(cells(line)) == 8
               and line.startswith(("exp2", "exp3"))]
    runs = {k[0] for k in kernels}
    assert len(runs) == 3, runs
    for run in runs:
        mine = {k[1]: k for k in kernels if k[0] == run}
        assert {"kinetostatic_tick", "filter_tick", "monitor_tick",
                "safety kernels summed per tick"} <= set(mine), mine
        ref = next(k for name, k in mine.items() if name.startswith("interference"))
        assert ref[7] == "1.00"
        summed = mine["safety kernels summed per tick"]
        for part in ("kinetostatic_tick", "filter_tick", "monitor_tick"):
            assert float(summed[3]) >= float(mine[part][3])
            assert float(summed[4]) >= float(mine[part][4])
    assert re.search(r"the safety blocks' kernels summed, p99 [\d.]+ us against the 0\.5 ms",
                     out.stdout)

    # 3. The four diagram variants, the paper's Fig. 5 the reference.
    variants = [cells(line) for line in lines if len(cells(line)) == 5
                and cells(line)[2].endswith("x")]
    assert [v[0] for v in variants] == [
        "shipped (filter and monitor on)", "model monitor off", "safety filter off",
        "both off: the paper's Fig. 5 (reference)"]
    assert variants[-1][4] == "1.00"
