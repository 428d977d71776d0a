"""Benchmark of the safety filter, in one run: its QP against well-kept solvers on the
filter's own problems, its compiled tick beside the other kernels of a tick, and experiment
2's real-time factor with the filter on and off.

The inputs are recorded, not made up. Three simulations run with every call of the compiled
kernels of the interference, kinetostatic, safety-filter and model-monitor blocks recorded
(their stacked inputs x, which hold their memories too, so that each call replays exactly):

- exp2 as shipped (kinematic plant, the translating controller: 3 unknowns);
- exp2 and exp3 on the dynamic plant with the full pose and tension control (6 unknowns), a
  hand pushing steadily 20 N across exp2's pair 1-3, and 40 N across exp3's pair 5-7 (as
  scripts/bench/adversarial_benchmark.py pushes): the pair, kinetostatic, speed and acceleration
  barriers bind.

1. The filter's QPs. Every recorded filter tick is replayed by the filter's Python code
   (`filter_tick.py_func`, checked to give the compiled tick's output bit for bit) with its
   `solve_qp` calls recorded: the (w, z0, C, d) of every QP it solves, cutting planes
   included. --problems of them (a seeded draw, a third from each run, among those with a
   row) are solved by cdpm_drake.kernels.qp.solve_qp (bound, from Python; and in a compiled loop, as
   filter_tick calls it), by Drake's MathematicalProgram with Clarabel and OSQP (the program
   built beforehand, the least a block would pay; Clarabel once more building it for every
   solve), by DAQP and quadprog where installed (pip install -e .[bench]) and by scipy's
   SLSQP. Per solver: per-solve time p50, p99 and max over the problems (each problem's best
   of --rounds, rounds interleaved across the solvers), the p50 against Clarabel's, the
   problems solved, the largest difference of its solution from the reference z_ref
   (quadprog's exact active set, else SLSQP's) and its largest violation of C z >= d. Under the table, solve_qp's own certificate: its KKT residuals from its multipliers.
2. The kernels per tick on the recorded ticks, bound as the blocks bind them: p50, p99 and
   max per run and kernel (each tick's best of --rounds), the p99 as a share of the 2 ms
   tick, the p50 against the run's interference kernel (the paper's own compute), and the
   safety blocks' kernels summed per tick (filter + kinetostatic + monitor), against the
   0.5 ms the real-time path allows.
3. exp2_interaction's real-time factor (loggers on, --duration s, best of --repeats
   interleaved runs) as shipped, with the model monitor off, with the safety filter off, and
   with both off (the paper's Fig. 5: the reference of the ratios).
4. --instructions: callgrind's instruction counts (exact and repeatable on a busy host) per
   solve on the same problems, per kernel call on every 10th recorded tick, and per tick of
   the diagrams of 3., in one valgrind process (counters zeroed before and dumped after each
   row's loop, less the cost of that measured on an empty row).

Prints the three (four) tables; --markdown prints them as markdown.

    python scripts/bench/bench_safety_filter.py               # ~1 min on 2 cores
    python scripts/bench/bench_safety_filter.py --quick       # shorter runs, 60 problems (~15 s)
    python scripts/bench/bench_safety_filter.py --instructions --markdown   # + ~1 min
"""
import argparse
import contextlib
import math
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from cdpm_drake.kernels.qp import QP_OPTIMAL, solve_qp, solve_qp_in

HERE = Path(__file__).resolve().parent
TICK = 0.002  # s
BUDGET = 0.5e-3  # s: the real-time path's share for the safety blocks' compute per tick
SCENARIO = "exp2_interaction"
# (label, scenario, pair pushed across, push N, seconds, seconds with --quick)
RUNS = (
    ("exp2 shipped, kinematic, 3 unknowns", "exp2_interaction", None, 0.0, 30.0, 5.0),
    ("exp2, dynamic, full pose, 20 N across 1-3", "exp2_interaction", (1, 3), 20.0, 5.0, 2.0),
    ("exp3, dynamic, full pose, 40 N across 5-7", "exp3_two_pairs", (5, 7), 40.0, 5.0, 2.0),
)
# The kernels recorded: name -> (the block's module, the position of x in its arguments).
KERNELS = {
    "interference_tick_stacked": ("interference_force", 4),
    "interference_posed_tick": ("posed_interference_force", 7),
    "kinetostatic_tick": ("kinetostatic_force", 4),
    "filter_tick": ("safety_filter", 8),
    "monitor_tick": ("model_monitor", 4),
}
SAFETY = ("filter_tick", "kinetostatic_tick", "monitor_tick")
# Diagram variants of 3.: (label, overlay)
VARIANTS = (
    ("shipped (filter and monitor on)", None),
    ("model monitor off", "{model_monitor: {enabled: false}}"),
    ("safety filter off", "{safety_filter: {enabled: false}}"),
    ("both off: the paper's Fig. 5 (reference)",
     "{safety_filter: {enabled: false}, model_monitor: {enabled: false}}"),
)
REPEAT = 20  # solves per call of the compiled loop


# --- recording ---------------------------------------------------------------------------------


class Recording:
    """The calls of one kernel in one run: its first call's arguments (copies) and every
    call's x and output (copies)."""

    def __init__(self, kernel, x_at, args):
        self.kernel, self.x_at = kernel, x_at
        self.args = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
        self.xs, self.outs = [], []

    def state(self) -> dict:
        """Plain data for the valgrind child (`restore`): the kernel by module and name."""
        return dict(self.__dict__, kernel=(self.kernel.py_func.__module__,
                                           self.kernel.__name__))

    @classmethod
    def restore(cls, state):
        import importlib

        rec = cls.__new__(cls)
        module, name = state["kernel"]
        rec.__dict__.update(state, kernel=getattr(importlib.import_module(module), name))
        return rec

    def replay_args(self):
        """Argument tuples that replay every call as the block makes it: the float constants
        in numba-owned memory (kernel_call.owned), one output buffer."""
        from cdpm_drake.kernels.call import owned

        base = [owned(a) if isinstance(a, np.ndarray) and a.dtype == float else a
                for a in self.args]
        return [tuple(x if k == self.x_at else a for k, a in enumerate(base))
                for x in self.xs]


def record_run(scenario_name, pair, force, seconds):
    """Simulate `seconds` of the run with the kernels of KERNELS recorded; returns
    ({kernel: Recording}, the simulated time reached, the fault that ended it or '')."""
    import importlib

    from bench_diagram import Patch
    from pydrake.systems.analysis import Simulator

    from cdpm_drake.kernels import call as kernel_call
    from cdpm_drake.diagram import build_diagram
    from cdpm_drake.kernels.model_monitor import ModelFault
    from cdpm_drake.config import load_resolved_scenario, load_scenario

    overlay = None
    if pair is not None:
        import adversarial_benchmark as adversarial

        u = adversarial._direction(load_resolved_scenario(scenario_name), pair)
        overlay = "{%s%s}" % (adversarial.FULL, adversarial._scripted(force * u))
    recordings = {}

    def recording_bind(kernel, *example):
        bound = kernel_call.bind(kernel, *example)
        name = getattr(kernel, "__name__", "")
        if name not in KERNELS:
            return bound
        x_at = KERNELS[name][1]

        def call(*args):
            status = bound(*args)
            rec = recordings.get(name)
            if rec is None:
                rec = recordings[name] = Recording(kernel, x_at, args)
            rec.xs.append(args[x_at].copy())
            rec.outs.append(args[-1].copy())
            return status
        return call

    modules = {importlib.import_module(f"cdpm_drake.systems.{m}") for m, _ in KERNELS.values()}
    with Patch([(m, "bind", recording_bind) for m in modules]):
        diagram = build_diagram(load_scenario(scenario_name, overlay))
    simulator = Simulator(diagram)
    simulator.Initialize()
    fault = ""
    try:
        simulator.AdvanceTo(seconds)
    except ModelFault as e:  # the run ends; what was recorded stays
        fault = str(e).splitlines()[0]
    return recordings, simulator.get_context().get_time(), fault


def capture_problems(rec):
    """Every QP the recorded filter ticks solve: the ticks replayed by filter_tick's Python
    code with its solve_qp calls recorded, each tick checked against the compiled output.
    Returns ([(w, z0, C, d)] of those with a solution, how many had none): a QP without one
    (the filter then gives up a return or holds) is no race between solvers."""
    from bench_diagram import Patch

    from cdpm_drake.kernels import safety_filter

    problems, infeasible = [], [0]

    def recording_solve(w, z0, C, d, count, z, u, max_iterations, work):
        problem = (w.copy(), z0.copy(), C[:count].copy(), d[:count].copy())
        result = solve_qp_in(w, z0, C, d, count, z, u, max_iterations, work)
        if result[0] == QP_OPTIMAL:
            problems.append(problem)
        else:
            infeasible[0] += 1
        return result

    out = np.empty_like(rec.outs[0])
    with Patch([(safety_filter, "solve_qp_in", recording_solve)]):
        for x, compiled in zip(rec.xs, rec.outs):
            args = list(rec.args)
            args[rec.x_at], args[-1] = x, out
            safety_filter.filter_tick.py_func(*args)
            if not np.array_equal(out, compiled, equal_nan=True):
                raise SystemExit("bench_safety_filter: error: filter_tick's Python code "
                                 "replayed a recorded tick differently from the compiled "
                                 "one; the captured QPs would not be the filter's")
    return problems, infeasible[0]


# --- the solvers -------------------------------------------------------------------------------
# Each is a `prepare(problem)` that returns a callable solving it: () -> (solved, z).


@numba.njit(cache=True)
def _solve_repeatedly(w, z0, C, d, z, u, times):
    status = 0
    for _ in range(times):
        status = solve_qp(w, z0, C, d, C.shape[0], z, u, 200)[0]
    return status


def this_bound(problem):
    from cdpm_drake.kernels.call import bind

    w, z0, C, d = problem
    z, u = np.empty(w.size), np.empty(d.size)
    solve = bind(solve_qp, w, z0, C, d, d.size, z, u, 200)
    return lambda: (solve(w, z0, C, d, d.size, z, u, 200)[0] == QP_OPTIMAL, z)


def this_compiled(problem):
    w, z0, C, d = problem
    z, u = np.empty(w.size), np.empty(d.size)
    return lambda: (_solve_repeatedly(w, z0, C, d, z, u, REPEAT) == QP_OPTIMAL, z)


def drake_prepare(solver_class, options=None, build_each=False):
    """A MathematicalProgram for the problem solved by solver_class; built beforehand, or
    (build_each) built again for every solve."""
    from pydrake.solvers import MathematicalProgram, SolverOptions

    solver = solver_class()
    opts = SolverOptions()
    for key, value in (options or {}).items():
        opts.SetOption(solver_class.id(), key, value)

    def build(problem):
        w, z0, C, d = problem
        prog = MathematicalProgram()
        z = prog.NewContinuousVariables(w.size, "z")
        prog.AddQuadraticCost(np.diag(w), -w * z0, z, is_convex=True)
        prog.AddLinearConstraint(C, d, np.full(d.size, np.inf), z)
        return prog, z

    def prepare(problem):
        if build_each:
            def solve():
                prog, z = build(problem)
                result = solver.Solve(prog, None, opts)
                return result.is_success(), result.GetSolution(z)
            return solve
        prog, z = build(problem)

        def solve():
            result = solver.Solve(prog, None, opts)
            return result.is_success(), result.GetSolution(z)
        return solve
    return prepare


def daqp_prepare(problem):
    import daqp

    w, z0, C, d = problem
    H, f = np.diag(w), -w * z0
    A, upper = np.ascontiguousarray(C), np.full(d.size, 1e30)

    def solve():
        z, _, flag, _ = daqp.solve(H, f, A, upper, d)
        return flag >= 1, z
    return solve


def quadprog_prepare(problem):
    import quadprog

    w, z0, C, d = problem
    G, a, Ct = np.diag(w), w * z0, np.ascontiguousarray(C.T)

    def solve():
        try:
            return True, quadprog.solve_qp(G, a, Ct, d, 0)[0]
        except ValueError:  # "constraints are inconsistent, no solution"
            return False, None
    return solve


def slsqp_prepare(problem):
    from scipy.optimize import minimize

    w, z0, C, d = problem
    cons = [{"type": "ineq", "fun": lambda z: C @ z - d, "jac": lambda z: C}]

    def solve():
        r = minimize(lambda z: 0.5 * np.sum(w * (z - z0) ** 2), z0, jac=lambda z: w * (z - z0),
                     constraints=cons, method="SLSQP", options={"ftol": 1e-12, "maxiter": 500})
        return bool(r.success), r.x
    return solve


def solver_rows():
    """(label, prepare, solves per call) of every solver available here."""
    rows = [("cdpm_drake.kernels.qp.solve_qp, bound, from Python", this_bound, 1),
            ("cdpm_drake.kernels.qp.solve_qp, compiled loop (as filter_tick)", this_compiled, REPEAT)]
    try:
        from pydrake.solvers import ClarabelSolver, OsqpSolver
    except ImportError:
        ClarabelSolver = OsqpSolver = None
    if ClarabelSolver is not None and ClarabelSolver().available():
        rows += [("Drake MathematicalProgram, Clarabel", drake_prepare(ClarabelSolver), 1),
                 ("Drake MathematicalProgram, Clarabel, program built each solve",
                  drake_prepare(ClarabelSolver, build_each=True), 1)]
    if OsqpSolver is not None and OsqpSolver().available():
        rows += [("Drake MathematicalProgram, OSQP (Drake's defaults)",
                  drake_prepare(OsqpSolver), 1),
                 ("Drake MathematicalProgram, OSQP, eps_abs = eps_rel = 1e-9",
                  drake_prepare(OsqpSolver, {"eps_abs": 1e-9, "eps_rel": 1e-9,
                                             "max_iter": 100000}), 1)]
    for module, label, prepare in (("daqp", "DAQP (dual active set, C; its defaults)", daqp_prepare),
                                   ("quadprog", "quadprog (Goldfarb-Idnani, Fortran)",
                                    quadprog_prepare)):
        try:
            __import__(module)
        except ImportError:
            continue
        rows.append((label, prepare, 1))
    rows.append(("scipy SLSQP (ftol 1e-12)", slsqp_prepare, 1))
    return rows


def reference_label(labels):
    """The accuracy reference: quadprog (an exact active set) where installed, else scipy's
    SLSQP (at ftol 1e-12 it ends on these QPs' active set too), else Clarabel (interior
    point, to its tolerances). Not DAQP: its defaults accept a violation of 1e-6."""
    for prefix in ("quadprog", "scipy SLSQP", "Drake MathematicalProgram, Clarabel"):
        for label in labels:
            if label.startswith(prefix):
                return label
    return labels[0]


def certificate(problems):
    """solve_qp's KKT residuals over the problems it solved (independent of every other
    solver): stationarity |w (z - z0) - C^T u|, the most negative multiplier, the largest
    violation of C z >= d and the largest |u (C z - d)| (complementarity)."""
    worst = np.zeros(4)
    for w, z0, C, d in problems:
        z, u = np.empty(w.size), np.empty(d.size)
        if solve_qp(w, z0, C, d, d.size, z, u, 200)[0] != QP_OPTIMAL:
            continue
        slack = C @ z - d
        worst = np.maximum(worst, [np.max(np.abs(w * (z - z0) - C.T @ u)), max(0.0, -u.min()),
                                   max(0.0, -slack.min()), np.max(np.abs(u * slack))])
    return worst


# --- timing ------------------------------------------------------------------------------------


def best_times(rows, rounds):
    """rows: [(calls, per)]: per row, each call's best wall time (s) over `rounds` rounds,
    divided by `per` (the solves a call makes); rounds interleave the rows, so that a load
    spike of the host hits one round of every row, not every round of one."""
    best = [np.full(len(calls), np.inf) for calls, _ in rows]
    clock = time.perf_counter_ns
    for _ in range(rounds):
        for (calls, per), times in zip(rows, best):
            for k, call in enumerate(calls):
                start = clock()
                call()
                elapsed = clock() - start
                if elapsed < times[k]:
                    times[k] = elapsed
    return [1e-9 * t / per for t, (_, per) in zip(best, rows)]


def us(seconds):
    return f"{1e6 * seconds:.1f}" if seconds < 1e-4 else f"{1e6 * seconds:.0f}"


def stats(times):
    return np.percentile(times, 50), np.percentile(times, 99), np.max(times)


# --- the three parts ---------------------------------------------------------------------------


@contextlib.contextmanager
def c_stdout_silenced():
    """File descriptor 1 to /dev/null: OSQP prints "Polishing not needed" from C whatever
    its verbose option says."""
    sys.stdout.flush()
    saved = os.dup(1)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


def solver_table(problems, rounds):
    rows = solver_rows()
    with c_stdout_silenced():
        prepared = [[prepare(p) for p in problems] for _, prepare, _ in rows]
        answers = [[call() for call in calls] for calls in prepared]  # also the warm-up
        times = best_times([(calls, per) for calls, (_, _, per) in zip(prepared, rows)],
                           rounds)
    labels = [label for label, _, _ in rows]
    ref = labels.index(reference_label(labels))
    clarabel = next((k for k, label in enumerate(labels) if label.endswith("Clarabel")), ref)
    table = []
    for (label, _, _), got, t in zip(rows, answers, times):
        p50, p99, worst = stats(t)
        dev = viol = 0.0
        for (ok, z), (ref_ok, z_ref), (_, _, C, d) in zip(got, answers[ref], problems):
            if ok:
                viol = max(viol, float(np.max(d - C @ z, initial=0.0)))
            if ok and ref_ok:
                dev = max(dev, float(np.max(np.abs(z - z_ref))))
        solved = sum(ok for ok, _ in got)
        table.append([label, us(p50), us(p99), us(worst),
                      f"{p50 / np.percentile(times[clarabel], 50):.3f}",
                      f"{solved}/{len(problems)}", f"{dev:.1e}", f"{viol:.1e}"])
    headers = ["solver", "p50 (us)", "p99 (us)", "max (us)", "p50 / Clarabel's",
               "solved", "max |z - z_ref| (m/s, rad/s)", "max violation"]
    return headers, table, labels[ref]


def kernel_rows(runs):
    """(run label, kernel name, [calls]) of every recorded kernel, bound as its block binds
    it, each call replaying one recorded tick."""
    from cdpm_drake.kernels.call import bind

    rows = []
    for run_label, recordings in runs:
        for name in KERNELS:
            if name in recordings:
                args = recordings[name].replay_args()
                bound = bind(recordings[name].kernel, *args[0])
                rows.append((run_label, name, [lambda b=bound, a=a: b(*a) for a in args]))
    return rows


def kernel_table(runs, rounds):
    """Per run: the recorded kernels' per-tick times and the safety kernels' sum per tick;
    also the largest p99 of that sum over the runs."""
    rows = kernel_rows(runs)
    for _, _, calls in rows:
        calls[0]()
    times = {(r, n): t for (r, n, _), t in zip(rows, best_times([(c, 1) for _, _, c in rows],
                                                                 rounds))}
    table, safety_p99 = [], 0.0
    for run_label, _ in runs:
        here = [n for n in KERNELS if (run_label, n) in times]
        ref = np.percentile(times[(run_label, next(n for n in here
                                                   if n.startswith("interference")))], 50)
        summed = sum(times[(run_label, n)] for n in SAFETY if n in here)
        safety_p99 = max(safety_p99, np.percentile(summed, 99))
        for name, t in [(n, times[(run_label, n)]) for n in here] + [
                ("safety kernels summed per tick", summed)]:
            p50, p99, worst = stats(t)
            table.append([run_label, name, str(len(t)), us(p50), us(p99), us(worst),
                          f"{100 * p99 / TICK:.2f} %", f"{p50 / ref:.2f}"])
    headers = ["run", "kernel", "ticks", "p50 (us)", "p99 (us)", "max (us)", "p99 / 2 ms tick",
               "p50 / interference"]
    return headers, table, safety_p99


def diagram_table(duration, repeats):
    from bench_diagram import run_once

    from cdpm_drake.diagram import BuildOptions
    from cdpm_drake.config import load_scenario

    scenarios = [(label, load_scenario(SCENARIO, overlay)) for label, overlay in VARIANTS]
    walls = {}
    for _ in range(repeats):
        for label, scenario in scenarios:
            walls[label] = min(walls.get(label, math.inf),
                               run_once(scenario, BuildOptions(), duration))
    ref = walls[VARIANTS[-1][0]]
    ticks = round(duration / TICK)
    table = [[label, f"{walls[label]:.2f}", f"{duration / walls[label]:.1f}x",
              f"{1e6 * walls[label] / ticks:.1f}", f"{walls[label] / ref:.2f}"]
             for label, _ in VARIANTS]
    return ["exp2_interaction", "wall (s)", "real-time factor", "us per tick",
            "wall / Fig. 5"], table


# --- instruction counts ------------------------------------------------------------------------

CHILD = r"""
import os, pickle, subprocess, sys
sys.path.insert(0, {scripts!r})
import bench_safety_filter as bench
bench.count_rows({data!r}, {rows!r}, {ticks!r})
"""


def _callgrind(*args):
    subprocess.run(["callgrind_control", *args, str(os.getpid())], check=True,
                   stdout=subprocess.DEVNULL)


def count_rows(data_path, rows_path, ticks):
    """In the valgrind child: everything prepared and the diagrams built first; then, with
    the instrumentation on, per row one call untimed, the counters zeroed, the row's loop,
    a dump. A line 'label<TAB>calls' per dump into rows_path (stdout is OSQP's)."""
    from pydrake.systems.analysis import Simulator

    from cdpm_drake.diagram import build_diagram
    from cdpm_drake.config import load_scenario

    with open(data_path, "rb") as f:
        problems, runs = pickle.load(f)
    runs = [(label, {n: Recording.restore(r) for n, r in recordings.items()})
            for label, recordings in runs]
    todo = [("(switching the collection on and off)", [lambda: None], 1)]
    todo += [(label, [prepare(p) for p in problems], per)
             for label, prepare, per in solver_rows()]
    todo += [(f"{run_label}: {name}", calls, 1) for run_label, name, calls in kernel_rows(runs)]
    for label, overlay in VARIANTS:
        simulator = Simulator(build_diagram(load_scenario(SCENARIO, overlay)))
        simulator.Initialize()
        simulator.AdvanceTo(0.1)
        todo.append((f"diagram: {label}",
                     [lambda s=simulator: s.AdvanceTo(s.get_context().get_time() + TICK)
                      for _ in range(ticks)], 1))
    _callgrind("-i", "on")
    with open(rows_path, "w") as done:
        for label, calls, per in todo:
            calls[0]()  # imports, first calls
            _callgrind("-z")
            for call in calls:
                call()
            _callgrind("-d")
            done.write(f"{label}\t{len(calls) * per}\n")


def instruction_table(problems, runs, ticks, stride):
    """Instructions per call of every solver, kernel and diagram variant (module docstring,
    4.), in one valgrind process; ratios against Clarabel, the run's interference kernel and
    the paper's Fig. 5 diagram."""
    from bench_dynamic_plant import instructions

    for _, recordings in runs:
        for rec in recordings.values():
            rec.xs, rec.outs = rec.xs[::stride], rec.outs[::stride]
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data.pkl"
        with open(data, "wb") as f:
            pickle.dump((problems, [(label, {n: r.state() for n, r in recordings.items()})
                                    for label, recordings in runs]), f)
        out, listed = Path(tmp) / "cg.out", Path(tmp) / "rows.txt"
        code = CHILD.format(scripts=str(HERE), data=str(data), rows=str(listed), ticks=ticks)
        done = subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no",
                               f"--callgrind-out-file={out}", sys.executable, "-c", code],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                              env=dict(os.environ, PYTHONHASHSEED="0"))
        if done.returncode != 0:
            raise SystemExit("bench_safety_filter: error: the callgrind run failed:\n"
                             + done.stderr[-2000:])
        rows = [line.split("\t") for line in listed.read_text().splitlines()]
        counts = [instructions(f"{out}.{k + 1}") for k in range(len(rows))]
    switch = counts[0]  # the cost of switching the collection, in every dump
    per = {label: (n - switch) / int(calls) for (label, calls), n in zip(rows[1:], counts[1:])}

    def reference(label):
        if label.startswith("diagram: "):
            return "diagram: " + VARIANTS[-1][0]
        if ": " in label:  # a kernel: its run's interference kernel
            run = label.split(": ")[0]
            return next(k for k in per if k.startswith(f"{run}: interference"))
        return next((k for k in per if k.endswith("Clarabel")), label)

    table = [[label, calls, f"{per[label] / 1000:.2f}", f"{per[label] / per[reference(label)]:.3f}"]
             for label, calls in rows[1:]]
    return ["row", "calls", "k instructions per call", "ratio"], table


# --- output ------------------------------------------------------------------------------------


def show(headers, rows, markdown):
    if markdown:
        def line(cells):  # a | inside a cell would end it
            return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"
        print(line(headers))
        print("|" + "|".join("---" if k == 0 else "---:" for k in range(len(headers))) + "|")
        for row in rows:
            print(line(row))
    else:
        from cdpm_drake.text import format_table

        print(format_table(headers, rows))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="shorter recorded runs, 60 problems, 2 rounds, 2 s of exp2, "
                        "1 repeat, 100 ticks counted")
    parser.add_argument("--problems", type=int, default=300, help="QPs solved by every solver")
    parser.add_argument("--rounds", type=int, default=5, help="timing rounds (best kept)")
    parser.add_argument("--duration", type=float, default=30.0,
                        help="simulated s of exp2 per real-time-factor run")
    parser.add_argument("--repeats", type=int, default=3, help="runs per diagram variant")
    parser.add_argument("--random-seed", type=int, default=0, help="seed of the QP draw")
    parser.add_argument("--instructions", action="store_true",
                        help="also count instructions per call with callgrind (slow)")
    parser.add_argument("--ticks", type=int, default=500,
                        help="diagram ticks counted by callgrind")
    parser.add_argument("--markdown", action="store_true", help="tables in markdown")
    args = parser.parse_args(argv)
    if args.quick:
        args.problems, args.rounds, args.duration, args.repeats = 60, 2, 2.0, 1
        args.ticks = min(args.ticks, 100)
    if args.problems < 3 or args.rounds < 1 or args.repeats < 1 or args.ticks < 1 \
            or not args.duration > 0:
        parser.error("--problems must be >= 3, --rounds, --repeats and --ticks >= 1, "
                     "--duration > 0")
    sys.path.insert(0, str(HERE))
    rng = np.random.default_rng(args.random_seed)

    runs, problems, notes = [], [], []
    for label, scenario, pair, force, seconds, quick_seconds in RUNS:
        seconds = quick_seconds if args.quick else seconds
        recordings, reached, fault = record_run(scenario, pair, force, seconds)
        if fault:
            notes.append(f"{label}: ended at {reached:.3f} s by a fault: {fault}")
        runs.append((label, recordings))
        captured, unsolvable = capture_problems(recordings["filter_tick"])
        pool = [p for p in captured if p[3].size > 0]
        take = args.problems // len(RUNS)
        chosen = rng.choice(len(pool), size=min(take, len(pool)), replace=False)
        problems += [pool[k] for k in sorted(chosen)]
        outs = np.array(recordings["filter_tick"].outs)
        notes.append(f"{label}: {len(outs)} ticks, {len(pool)} QPs with rows and a solution "
                     f"({unsolvable} without one, left out); filter status "
                     f"passed/modified/no return/hold {np.bincount(outs[:, 6].astype(int), minlength=4).tolist()}")

    sizes = np.array([p[3].size for p in problems])
    print(f"1. the safety filter's QPs: {len(problems)} recorded problems "
          f"({sum(p[0].size == 3 for p in problems)} with 3 unknowns, "
          f"{sum(p[0].size == 6 for p in problems)} with 6; rows {sizes.min()}-{sizes.max()}, "
          f"median {np.median(sizes):g}); per solve, each problem's best of {args.rounds} "
          "rounds")
    for note in notes:
        print(f"   {note}")
    headers, table, reference = solver_table(problems, args.rounds)
    show(headers, table, args.markdown)
    kkt = certificate(problems)
    print(f"z_ref: {reference}. solve_qp's KKT certificate over the problems: stationarity "
          f"{kkt[0]:.1e}, multipliers >= {-kkt[1]:.1e}, violation {kkt[2]:.1e}, "
          f"complementarity {kkt[3]:.1e}")
    print()

    headers, table, safety_p99 = kernel_table(runs, args.rounds)
    print(f"2. the kernels per tick on the recorded ticks, bound as the blocks call them; each "
          f"tick's best of {args.rounds} rounds")
    show(headers, table, args.markdown)
    print(f"the safety blocks' kernels summed, p99 {us(safety_p99)} us against the "
          f"{1e3 * BUDGET:g} ms allowed: {'met' if safety_p99 < BUDGET else 'NOT met'}")
    print()

    headers, table = diagram_table(args.duration, args.repeats)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"3. {SCENARIO}, {args.duration:g} s simulated, loggers on, best of {args.repeats} "
          f"interleaved runs; load average {load:.1f} on {os.cpu_count()} cores")
    show(headers, table, args.markdown)

    if args.instructions:
        stride = 10 if not args.quick else 20
        headers, table = instruction_table(problems, runs, args.ticks, stride)
        print()
        print(f"4. instructions (callgrind Ir) per call: the same problems, every {stride}th "
              f"recorded tick, {args.ticks} ticks of each diagram after 0.1 s (per tick); "
              "ratios against Clarabel, the run's interference kernel and the Fig. 5 diagram")
        show(headers, table, args.markdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())
