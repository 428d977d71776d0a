"""Benchmark of the Fig. 5 diagram: real-time factor of a scenario
(experiment 2 by default, 60 s of simulated time) for the full diagram, without the
interference block and without the loggers, and the share of the full diagram's time spent in
each block, in one table measured in one run. Ratios are against the full diagram.

Block shares come from a separate, instrumented run of the full diagram: every `_calc_*` and
`_update_*` callback of the LeafSystems in `cdpm_drake/systems/` is wrapped by a timer that
charges each block its exclusive time (time in nested callbacks of other blocks, pulled through
input ports, is charged to those). The rest is Drake's own work: event dispatch, caching, the
C++ blocks (admittance, adder, loggers). The wrappers cost about a microsecond per call, so the
instrumented run is a little slower than the plain one.

A last row measures the floor of this architecture: the same diagram with every block's numpy
math replaced by a constant (the LeafSystems, ports, caches, events and loggers all still run).
No optimisation of the math can make the full diagram faster than that row.

With --repeat N the variants run N times, interleaved, and each keeps its fastest run (the
least disturbed by other load on the machine).

Usage: python scripts/bench_diagram.py [--duration 60] [--repeat 1] [--scenario exp2_interaction]
"""

import argparse
import importlib
import inspect
import pkgutil
import time
from collections import defaultdict

from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import LeafSystem

import cdpm_drake.systems
from cdpm_drake.diagram import BuildOptions, build_diagram
from cdpm_drake.scenario import load_scenario
from cdpm_drake.text import format_table

GOAL = 100.0  # the target: >= 100x real time for the full diagram on one core

VARIANTS = (
    ("full diagram", BuildOptions()),
    ("without interference block", BuildOptions(interference=False)),
    ("without loggers", BuildOptions(loggers=False)),
)


def run_once(scenario, options, duration):
    """Wall-clock seconds of Simulator.AdvanceTo(duration) (building not included)."""
    diagram = build_diagram(scenario, options)
    simulator = Simulator(diagram)
    diagram.SetRandomContext(simulator.get_mutable_context(),
                             RandomGenerator(scenario.random_seed))
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(duration)
    return time.perf_counter() - start


class BlockTimer:
    """Exclusive time per LeafSystem class of cdpm_drake.systems, by wrapping callbacks."""

    def __init__(self):
        self.exclusive = defaultdict(float)
        self.calls = defaultdict(int)
        self._stack = []  # time spent in nested timed callbacks, per open callback
        self._patched = []

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

    def install(self):
        """Wrap the callbacks; systems built afterwards are timed (bound at Declare time)."""
        for info in pkgutil.iter_modules(cdpm_drake.systems.__path__):
            module = importlib.import_module(f"cdpm_drake.systems.{info.name}")
            for cls_name, cls in inspect.getmembers(module, inspect.isclass):
                if not (issubclass(cls, LeafSystem) and cls.__module__ == module.__name__):
                    continue
                for name, function in list(vars(cls).items()):
                    if callable(function) and name.startswith(("_calc_", "_update_")):
                        self._patched.append((cls, name, function))
                        setattr(cls, name, self._wrap(f"{info.name}.{cls_name}", function))

    def uninstall(self):
        for cls, name, function in reversed(self._patched):
            setattr(cls, name, function)
        self._patched.clear()


def run_without_math(scenario, duration):
    """Wall time of the full diagram whose blocks call constant stand-ins for their math."""
    import numpy as np

    import cdpm_drake.systems.force_sensor as force_sensor
    import cdpm_drake.systems.forward_kinematics as forward_kinematics
    import cdpm_drake.systems.interference_force as interference_force
    import cdpm_drake.systems.jacobian_mapping as jacobian_mapping
    import cdpm_drake.systems.safety_limits as safety_limits
    import cdpm_drake.systems.simulated_reels as simulated_reels
    from cdpm_drake.interference import interference_force as real_interference_force
    from cdpm_drake.kinematics import cable_lengths, jacobian
    from cdpm_drake.scenario import interference_params, scenario_robot

    robot = scenario_robot(scenario)
    p0 = np.array(scenario.initial_position)
    result = real_interference_force(robot, p0, interference_params(scenario, robot))
    lengths, J = cable_lengths(robot, p0), jacobian(robot, p0)
    stand_ins = [
        (interference_force, "interference_force", lambda *a, **k: result),
        (forward_kinematics, "forward_kinematics", lambda r, l, p_guess=None, **k: p_guess),
        (simulated_reels, "forward_kinematics", lambda r, l, p_guess=None, **k: p_guess),
        (simulated_reels, "cable_lengths", lambda *a: lengths),
        (safety_limits, "limit_velocity", lambda v, *a, **k: v),
        (jacobian_mapping, "jacobian", lambda *a: J),
        (force_sensor, "clip_to_sensor_range", lambda f, *a: f),
    ]
    saved = [(module, name, getattr(module, name)) for module, name, _ in stand_ins]
    try:
        for module, name, fake in stand_ins:
            setattr(module, name, fake)
        return run_once(scenario, BuildOptions(), duration)
    finally:
        for module, name, original in saved:
            setattr(module, name, original)


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=60.0,
                        help="simulated time per run, s (default 60)")
    parser.add_argument("--repeat", type=int, default=1,
                        help="runs per variant, interleaved; the fastest counts (default 1)")
    parser.add_argument("--scenario", default="exp2_interaction",
                        help="scenario name or path (default exp2_interaction)")
    args = parser.parse_args()
    if not args.duration > 0:
        parser.error(f"--duration must be > 0 s, got {args.duration!r}")
    if args.repeat < 1:
        parser.error(f"--repeat must be >= 1, got {args.repeat!r}")
    scenario = load_scenario(args.scenario)
    duration = args.duration

    rows = []
    walls = {}
    for _ in range(args.repeat):
        for label, options in VARIANTS:
            wall = run_once(scenario, options, duration)
            walls[label] = min(wall, walls.get(label, wall))
    full = walls["full diagram"]
    for label, _ in VARIANTS:
        wall = walls[label]
        rows.append([label, f"{wall:.2f}", f"{duration / wall:.1f}x", f"{wall / full:.2f}",
                     ""])

    timer = BlockTimer()
    timer.install()
    try:  # one instrumented run: its shares, not its speed, are the point
        instrumented = run_once(scenario, BuildOptions(), duration)
    finally:
        timer.uninstall()
    rows.append(["full diagram, instrumented", f"{instrumented:.2f}",
                 f"{duration / instrumented:.1f}x", f"{instrumented / full:.2f}", "100.0 %"])
    blocks = sorted(timer.exclusive.items(), key=lambda kv: -kv[1])
    for label, seconds in blocks:
        rows.append([f"  {label} ({timer.calls[label]} calls)", f"{seconds:.2f}", "",
                     f"{seconds / full:.2f}", f"{100 * seconds / instrumented:.1f} %"])
    rest = instrumented - sum(timer.exclusive.values())
    rows.append(["  Drake framework and C++ blocks", f"{rest:.2f}", "", f"{rest / full:.2f}",
                 f"{100 * rest / instrumented:.1f} %"])

    floor = run_without_math(scenario, duration)
    rows.append(["floor: same blocks, math replaced by constants", f"{floor:.2f}",
                 f"{duration / floor:.1f}x", f"{floor / full:.2f}", ""])

    ticks = round(duration / scenario.time_step)
    print(f"scenario {scenario.name!r}, {duration:g} s simulated ({ticks} ticks of "
          f"{1000 * scenario.time_step:g} ms), best of {args.repeat}; ratios are wall time / "
          "full diagram's")
    print(format_table(["run / block", "wall (s)", "real-time factor", "vs full", "share"], rows))
    print(f"per tick, full diagram: {1e6 * full / ticks:.0f} us; goal {GOAL:g}x real time "
          f"({1e6 * scenario.time_step / GOAL:.0f} us per tick): "
          f"{'met' if duration / full >= GOAL else 'not met'}")


if __name__ == "__main__":
    main()
