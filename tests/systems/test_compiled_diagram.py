"""Issue 11: the math compiled once, each Python block evaluated once per tick, the scenario
resolved once.

Counts, not timings: the number of numba specialisations before and after a run (a new one
would be a compilation inside the loop), the number of calls of every Python block's
callbacks per tick, and how often the robot file is loaded per simulation.
"""

import importlib
import inspect
import pkgutil

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import LeafSystem

import cdpm_drake.systems
from cdpm_drake.kernels import interference
from cdpm_drake.kernels import chain, kinematics
from cdpm_drake.kernels import safety_limits as limits
from cdpm_drake.kernels.plant import operators
from cdpm_drake.config import resolve as resolve_module
from cdpm_drake.kernels import force_sensor as sensor
from cdpm_drake.diagram import build_diagram
from cdpm_drake.config import ResolvedScenario, load_scenario, resolve_scenario
from cdpm_drake.runs.simulate import simulate

KERNELS = (interference.interference_tick, interference.interference_tick_stacked,
           kinematics.gauss_newton_warm, kinematics.gauss_newton_warm_stacked,
           kinematics.reel_rates, kinematics.reel_rates_stacked,
           kinematics.simulated_reel_step, limits.limit_velocity_into,
           limits.limit_velocity_stacked,
           limits.wall_force_into, sensor.clip_into, operators._spring_force_into,
           operators._interp_into, operators.operator_force_into,
           operators.operator_force_on_state, kinematics.simulated_reel_step_stacked,
           chain.put, chain.move, chain.take)


def _leaf_classes():
    for info in pkgutil.walk_packages(cdpm_drake.systems.__path__, "cdpm_drake.systems."):
        module = importlib.import_module(info.name)
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if issubclass(cls, LeafSystem) and cls.__module__ == module.__name__:
                yield cls


@pytest.mark.parametrize("name,overlay", [
    ("exp2_interaction", None), ("exp3_two_pairs", None),
    ("exp1_no_interaction", "{wall_force: {enabled: true}, operator: !ScriptedOperator "
                            "{times: [0, 1], forces: [[0, 0, 0], [1, 2, 3]]}}")])
def test_no_numba_compilation_happens_inside_the_run(name, overlay):
    # Building the diagram compiles (or loads) every kernel its blocks call; the ticks then
    # find an existing specialisation for the argument types the ports deliver.
    diagram = build_diagram(load_scenario(name, overlay))
    before = [len(k.signatures) for k in KERNELS]
    simulator = Simulator(diagram)
    simulator.Initialize()
    simulator.AdvanceTo(0.2)
    assert [len(k.signatures) for k in KERNELS] == before


def test_each_python_block_is_evaluated_once_per_tick(monkeypatch):
    # Count the calls of every output callback a cdpm_drake LeafSystem declares (closures
    # or methods alike), by wrapping them as they are declared.
    calls = {}
    classes = tuple(_leaf_classes())
    declare = LeafSystem.DeclareVectorOutputPort

    def counting_declare(self, name, size, calc, *args, **kwargs):
        if isinstance(self, classes):
            key = f"{type(self).__name__}.{name}"

            def counted(context, output, _calc=calc):
                calls[key] = calls.get(key, 0) + 1
                return _calc(context, output)
            calc = counted
        return declare(self, name, size, calc, *args, **kwargs)

    monkeypatch.setattr(LeafSystem, "DeclareVectorOutputPort", counting_declare)
    ticks = 250
    result = simulate(scenario=load_scenario("exp2_interaction"), duration=ticks * 0.002)
    assert result.error is None
    # The Python callbacks of exp2 (sensor range, FK, the simulated world's step, and one
    # for the interference block, the limits, the kinetostatic limit, the safety filter, the
    # Jacobian mapping and the model monitor: systems/fused_kernels.py), each computed once
    # per tick: ticks + 1 published rows, the first at t = 0 before any update; the world's
    # step feeds only the plant's state update, so it runs at the `ticks` updates. A second
    # evaluation per tick would double a count.
    assert len(calls) == 4 and "FusedKernelSystem.result" in calls, calls
    for key, n in calls.items():
        assert n == (ticks if key.startswith("ReelStep") else ticks + 1), (key, n)


def test_a_simulation_resolves_its_scenario_once(monkeypatch):
    loaded = load_scenario("exp2_interaction")
    count = {"robot": 0}
    real = resolve_module.scenario_robot

    def counting(s):
        count["robot"] += 1
        return real(s)

    monkeypatch.setattr(resolve_module, "scenario_robot", counting)
    result = simulate(scenario=loaded, duration=0.01)
    assert result.error is None
    assert count["robot"] == 1  # before issue 11: three times (simulate, build, log)
    # A resolved scenario is taken as it is: no further resolution at all.
    resolved = resolve_scenario(loaded)
    count["robot"] = 0
    assert simulate(scenario=resolved, duration=0.01).error is None
    assert count["robot"] == 0


def test_resolved_scenario_applies_the_robot_defaults():
    # exp2 sets no limits: both come from hardware/robots/paper_7cable.yaml; the overlay
    # sets max_velocity only, so max_acceleration still comes from the robot file.
    base = resolve_scenario(load_scenario("exp2_interaction"))
    robot_limits = base.robot.limits
    assert (base.max_velocity, base.max_acceleration) == (robot_limits.max_velocity,
                                                          robot_limits.max_acceleration)
    assert base.max_reel_speed == robot_limits.max_reel_speed
    changed = resolve_scenario(load_scenario("exp2_interaction",
                                             "{limits: {max_velocity: 0.123}}"))
    assert changed.max_velocity == 0.123
    assert changed.max_acceleration == robot_limits.max_acceleration
    # Swaps applied (exp2 swaps the attachments of cables 1 and 3), parameters per pair.
    unswapped = resolve_scenario(load_scenario("exp2_interaction", "{swaps: []}")).robot
    np.testing.assert_array_equal(base.robot.attachments[0], unswapped.attachments[2])
    assert base.interference.d_u.shape == (base.robot.num_pairs,)
    off = resolve_scenario(load_scenario("exp2_interaction",
                                         "{interference: {enabled: false}}"))
    assert off.interference is None
    assert isinstance(base, ResolvedScenario) and resolve_scenario(base) is base
