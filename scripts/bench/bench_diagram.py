"""Benchmark of the Fig. 5 diagram: real-time factor of experiment 2 with loggers
on, against two floors of the same diagram shape, and the start-up times, in one run.

Rows (best of --repeat interleaved runs each; ratios are against the product's wall time):
- product: the diagram as `cdpm simulate` builds it (120 s of exp2 by default, loggers on);
- without loggers: the same, BuildOptions(loggers=False);
- floor, Python blocks: the same diagram with every Python block's compiled math replaced by
  a Python no-op (the LeafSystems, ports, C++ delays, Selectors, LinearSystems and
  loggers all still run): no optimisation of the math can beat it;
- floor, all C++: the same shape with every Python block replaced by a C++ stand-in with
  the same ports (a Multiplexer and a zero MatrixGain in a sub-diagram): Drake's own floor
  for this many systems, ports and events.

Then where the product's time goes: one instrumented run charges each Python block's
output callbacks their exclusive wall time (the wrapper costs ~0.3 us a call, so the
instrumented run is a little slower); the rest is Drake (event dispatch, caching, the C++
blocks).

Start-up (separate processes, --startup-repeat each, best): `import cdpm_drake.runs.simulate`;
building the exp2 diagram with an empty numba cache (every kernel compiled: a cold start
after install) and with the cache filled (a warm start); and a whole warm
`cdpm simulate --duration 0.002` (process start to exit).

Usage: python scripts/bench/bench_diagram.py [--duration 120] [--repeat 3] [--startup-repeat 3]
                                       [--scenario exp2_interaction]
"""

import argparse
import importlib
import inspect
import os
import pkgutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import MatrixGain, Multiplexer

import cdpm_drake.systems
from cdpm_drake.diagram import BuildOptions, build_diagram, reserve_log
from cdpm_drake.config import load_scenario
from cdpm_drake.text import format_table

GOAL = 50.0  # the target: >= 50x real time for exp2 with loggers on, on the 2-core machine


def run_once(scenario, options, duration):
    """Wall-clock seconds of Simulator.AdvanceTo(duration) (building not included)."""
    diagram = build_diagram(scenario, options)
    simulator = Simulator(diagram)
    simulator.Initialize()
    # As `cdpm simulate` does (simulation.simulate): the log's rows reserved before the run.
    reserve_log(diagram, simulator.get_mutable_context(), int(duration / 0.002) + 2)
    start = time.perf_counter()
    simulator.AdvanceTo(duration)
    return time.perf_counter() - start


def _python_leaves():
    """(module, class name, class) of every LeafSystem defined in cdpm_drake.systems."""
    for info in pkgutil.walk_packages(cdpm_drake.systems.__path__, "cdpm_drake.systems."):
        module = importlib.import_module(info.name)
        for name, cls in inspect.getmembers(module, inspect.isclass):
            if issubclass(cls, LeafSystem) and cls.__module__ == module.__name__:
                yield module, name, cls


class Patch:
    """Set attributes for the duration of a with-block."""

    def __init__(self, changes):
        self._changes = changes  # [(object, attribute, value)]
        self._saved = []

    def __enter__(self):
        for obj, name, value in self._changes:
            self._saved.append((obj, name, getattr(obj, name)))
            setattr(obj, name, value)

    def __exit__(self, *exc):
        for obj, name, value in reversed(self._saved):
            setattr(obj, name, value)
        self._saved.clear()


def _no_op(*args, **kwargs):
    return True  # the kernels that report success (FK, reel step) see one


def without_math():
    """Every compiled kernel a block calls, replaced by a Python no-op."""
    from cdpm_drake.systems import (force_sensor, forward_kinematics, interference_force,
                                    jacobian_mapping, safety_limits)
    from cdpm_drake.systems.plants import simulated_reels
    from cdpm_drake.kernels.plant import operators

    return Patch([
        (force_sensor, "clip_into", _no_op),
        (forward_kinematics, "gauss_newton_warm_stacked", _no_op),
        (interference_force, "interference_tick_stacked", _no_op),
        (safety_limits, "limit_velocity_stacked", _no_op),
        (jacobian_mapping, "length_loop_tick", _no_op),
        (simulated_reels, "simulated_reel_step_stacked", _no_op),
        (simulated_reels, "operator_force_on_state", _no_op),
        (operators.SpringHand, "force_into", _no_op),
        (operators.ForceProfile, "force_into", _no_op),
        (operators.NoForce, "force_into", _no_op),
    ])


class CppStandIn(Diagram):
    """A C++ stand-in for a Python block: its input and output ports (names and sizes), each
    output a zero MatrixGain of all inputs multiplexed."""

    def __init__(self, leaf):
        super().__init__()
        builder = DiagramBuilder()
        inputs = [leaf.get_input_port(k) for k in range(leaf.num_input_ports())]
        mux = builder.AddSystem(Multiplexer([port.size() for port in inputs] or [1]))
        for k, port in enumerate(inputs):
            builder.ExportInput(mux.get_input_port(k), port.get_name())
        width = mux.get_output_port().size()
        for k in range(leaf.num_output_ports()):
            port = leaf.get_output_port(k)
            gain = builder.AddSystem(MatrixGain(np.zeros((port.size(), width))))
            builder.Connect(mux.get_output_port(), gain.get_input_port())
            builder.ExportOutput(gain.get_output_port(), port.get_name())
        builder.BuildInto(self)


def all_cpp():
    """Every Python LeafSystem class of cdpm_drake.systems (where the builders find it)
    replaced by a factory of its C++ stand-in."""
    import cdpm_drake.diagram as diagram_module

    changes = []
    for module, name, cls in _python_leaves():
        def factory(*args, _cls=cls, **kwargs):
            return CppStandIn(_cls(*args, **kwargs))
        changes.append((module, name, factory))
        if hasattr(diagram_module, name):
            changes.append((diagram_module, name, factory))
    return Patch(changes)


class BlockTimer:
    """Exclusive wall time per Python block class, by wrapping its `_calc_*` callbacks."""

    def __init__(self):
        self.exclusive = defaultdict(float)
        self.calls = defaultdict(int)
        self._stack = []

    def _wrap(self, label, function):
        def timed(*args, **kwargs):
            start = time.perf_counter()
            self._stack.append(0.0)
            try:
                return function(*args, **kwargs)
            finally:
                nested = self._stack.pop()
                elapsed = time.perf_counter() - start
                self.exclusive[label] += elapsed - nested
                self.calls[label] += 1
                if self._stack:
                    self._stack[-1] += elapsed
        return timed

    def patch(self):
        """Wrap every output callback a block declares (closures or methods alike)."""
        leaves = {cls: f"{module.__name__.rsplit('.', 1)[-1]}.{name}"
                  for module, name, cls in _python_leaves()}
        declare = LeafSystem.DeclareVectorOutputPort

        def timed_declare(system, name, size, calc, *args, **kwargs):
            label = leaves.get(type(system))
            if label is not None:
                calc = self._wrap(label, calc)
            return declare(system, name, size, calc, *args, **kwargs)
        return Patch([(LeafSystem, "DeclareVectorOutputPort", timed_declare)])


def _subprocess_seconds(code, env=None, repeat=1):
    """Best wall time (s) of `python -c code` over `repeat` runs."""
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True, env=env,
                       stdout=subprocess.DEVNULL)
        best = min(best, time.perf_counter() - start)
    return best


def startup_rows(scenario_name, repeat):
    rows = []
    bare = _subprocess_seconds("pass", repeat=repeat)
    rows.append(["python -c pass (interpreter only)", f"{bare:.2f}"])
    rows.append(["import cdpm_drake.runs.simulate",
                 f"{_subprocess_seconds('import cdpm_drake.runs.simulate', repeat=repeat):.2f}"])
    build = ("import time; t = time.perf_counter(); "
             "from cdpm_drake.config import load_scenario; "
             "from cdpm_drake.diagram import build_diagram; "
             f"build_diagram(load_scenario({scenario_name!r}))")
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        cold = _subprocess_seconds(build, env=env)  # empty cache: compiles every kernel
        warm = _subprocess_seconds(build, env=env, repeat=repeat)
    rows.append(["import + load + build, numba cache empty (cold)", f"{cold:.2f}"])
    rows.append(["import + load + build, numba cache filled (warm)", f"{warm:.2f}"])
    with tempfile.TemporaryDirectory() as out:
        cli = ("import sys; from cdpm_drake.cli import main; "
               f"sys.exit(main(['simulate', {scenario_name!r}, '--duration', '0.002', "
               f"'--no-progress', '--force', '--out', {out!r}]))")
        rows.append(["warm `cdpm simulate --duration 0.002` (whole process)",
                     f"{_subprocess_seconds(cli, repeat=repeat):.2f}"])
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=120.0,
                        help="simulated time per run, s (default 120)")
    parser.add_argument("--repeat", type=int, default=3,
                        help="runs per variant, interleaved; the fastest counts (default 3)")
    parser.add_argument("--startup-repeat", type=int, default=3,
                        help="processes per start-up row; the fastest counts (default 3)")
    parser.add_argument("--scenario", default="exp2_interaction",
                        help="scenario name or path (default exp2_interaction)")
    args = parser.parse_args()
    if not args.duration > 0:
        parser.error(f"--duration must be > 0 s, got {args.duration!r}")
    if args.repeat < 1 or args.startup_repeat < 1:
        parser.error("--repeat and --startup-repeat must be >= 1")
    scenario = load_scenario(args.scenario)
    duration = args.duration

    variants = (
        ("product (loggers on)", BuildOptions(), None),
        ("without loggers", BuildOptions(loggers=False), None),
        ("floor, Python blocks: math replaced by no-ops", BuildOptions(), without_math),
        ("floor, all C++: Python blocks replaced by C++ stand-ins", BuildOptions(), all_cpp),
    )
    walls = {}
    for _ in range(args.repeat):
        for label, options, patch in variants:
            if patch is None:
                wall = run_once(scenario, options, duration)
            else:
                with patch():
                    wall = run_once(scenario, options, duration)
            walls[label] = min(wall, walls.get(label, np.inf))
    product = walls[variants[0][0]]
    ticks = round(duration / scenario.time_step)
    rows = []
    for label, _, _ in variants:
        wall = walls[label]
        rows.append([label, f"{wall:.2f}", f"{duration / wall:.1f}x",
                     f"{1e6 * wall / ticks:.1f}", f"{wall / product:.2f}", ""])

    timer = BlockTimer()
    with timer.patch():  # one instrumented run: its shares, not its speed, are the point
        instrumented = run_once(scenario, BuildOptions(), duration)
    rows.append(["product, instrumented", f"{instrumented:.2f}",
                 f"{duration / instrumented:.1f}x", f"{1e6 * instrumented / ticks:.1f}",
                 f"{instrumented / product:.2f}", "100.0 %"])
    for label, seconds in sorted(timer.exclusive.items(), key=lambda kv: -kv[1]):
        rows.append([f"  {label} ({timer.calls[label] / ticks:.2f} calls/tick)",
                     f"{seconds:.2f}", "", f"{1e6 * seconds / ticks:.1f}", "",
                     f"{100 * seconds / instrumented:.1f} %"])
    rest = instrumented - sum(timer.exclusive.values())
    rows.append(["  Drake: events, caching, C++ blocks, loggers", f"{rest:.2f}", "",
                 f"{1e6 * rest / ticks:.1f}", "", f"{100 * rest / instrumented:.1f} %"])

    print(f"scenario {scenario.name!r}, {duration:g} s simulated ({ticks} ticks of "
          f"{1000 * scenario.time_step:g} ms), best of {args.repeat} interleaved runs; "
          "ratios are wall time / the product's")
    print(format_table(["run / block", "wall (s)", "real-time factor", "us/tick",
                        "vs product", "share"], rows))
    rtf = duration / product
    print(f"goal >= {GOAL:g}x real time ({1e6 * scenario.time_step / GOAL:.0f} us per tick): "
          f"{'met' if rtf >= GOAL else 'not met'} ({rtf:.1f}x)")
    print()
    print(format_table(["start-up (separate processes)", "wall (s)"],
                       startup_rows(args.scenario, args.startup_repeat)))


if __name__ == "__main__":
    main()
