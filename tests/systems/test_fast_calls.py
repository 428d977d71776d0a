"""Issue 11, second round: the per-tick calls made cheap without changing a value.

- kernel_call.bind: a block calls its kernel's compiled entry point, skipping numba's typing
  per call; safe only while every tick passes the argument types it was bound for, which is
  checked here call by call.
- kernel_call.owned: constants in numba-managed memory, same values.
- operators.operator_force_into: the shipped operator models as one kernel, ticked by the
  simulated reels; the force equals each model's own `force` exactly.
- fuse_wiring: the blocks' Selectors fused into one system; the logs are bit for bit those of
  the unfused diagram, every block port reads the same, and the overview draws the same.
The speed itself is measured by scripts/bench/bench_diagram.py and scripts/bench/count_instructions.py.
"""

import dataclasses
import importlib
import pkgutil

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

import cdpm_drake.systems
from cdpm_drake.kernels import call as kernel_call
from cdpm_drake.kernels.plant import operators
from cdpm_drake.diagram import (BuildOptions, block_output_port, build_diagram,
                                logged_ports, logged_signals)
from cdpm_drake.hardware.config import HardwareReels
from cdpm_drake.kernels.kinematics import reel_rates
from cdpm_drake.config import SimulatedReels, load_scenario
from cdpm_drake.systems.wiring import FUSED_DELAY, FUSED_WIRING
from cdpm_drake.views.diagram_graph import overview_graphviz

WALL_AND_SCRIPT = ("{wall_force: {enabled: true}, operator: !ScriptedOperator "
                   "{times: [0, 1], forces: [[0, 0, 0], [1, 2, 3]]}}")
CASES = [("exp2_interaction", None), ("exp3_two_pairs", None),
         ("exp1_no_interaction", WALL_AND_SCRIPT)]


def test_bind_returns_the_compiled_entry_with_the_dispatchers_results():
    rng = np.random.default_rng(3)
    offsets = kernel_call.owned(rng.normal(size=(7, 3)))
    p, v = rng.normal(size=3) + 2.0, rng.normal(size=3)
    entry = kernel_call.bind(reel_rates, offsets, p, v, np.empty(7))
    assert entry is not reel_rates  # numba's typing skipped
    out_entry, out_dispatch = np.empty(7), np.empty(7)
    entry(offsets, p, v, out_entry)
    reel_rates(np.array(offsets), p, v, out_dispatch)
    np.testing.assert_array_equal(out_entry, out_dispatch)
    # Reference: eq. 3 by hand, l_dot_i = rho_i . v / |rho_i|.
    rho = p + np.asarray(offsets)
    np.testing.assert_allclose(out_entry, rho @ v / np.linalg.norm(rho, axis=1), rtol=1e-14)


def test_owned_keeps_values_and_gives_writable_float_c_arrays():
    a = np.arange(6, dtype=np.int64).reshape(2, 3)[:, ::-1]  # ints, not contiguous
    b = kernel_call.owned(a)
    np.testing.assert_array_equal(b, a)
    assert b.dtype == np.float64 and b.flags.c_contiguous and b.flags.writeable
    assert kernel_call.owned([1.0, 2.0]).shape == (2,)


def _system_modules():
    for info in pkgutil.walk_packages(cdpm_drake.systems.__path__, "cdpm_drake.systems."):
        yield importlib.import_module(info.name)


def _check_every_bound_call(monkeypatch) -> dict:
    """Make every block's `bind` return an entry point that asserts, call by call, the
    argument types it was bound for; returns {kernel name: calls}, filled as the run goes."""
    real_bind, calls = kernel_call.bind, {}

    def checking_bind(kernel, *example):
        entry, expected = real_bind(kernel, *example), kernel_call.signature_of(*example)
        key = kernel.__name__

        def call(*args):
            assert kernel_call.signature_of(*args) == expected, key
            calls[key] = calls.get(key, 0) + 1
            return entry(*args)
        return call

    for module in _system_modules():
        if getattr(module, "bind", None) is real_bind:
            monkeypatch.setattr(module, "bind", checking_bind)
    return calls


@pytest.mark.parametrize("name,overlay", CASES)
def test_every_bound_call_passes_the_types_it_was_bound_for(monkeypatch, name, overlay):
    # A mismatch would not compile a new version (as the dispatcher would): the entry point
    # would read the arguments as the bound types. So check every call of every tick.
    calls = _check_every_bound_call(monkeypatch)
    simulator = Simulator(build_diagram(load_scenario(name, overlay)))
    simulator.Initialize()
    simulator.AdvanceTo(0.1)
    expected = {"clip_into", "gauss_newton_warm_stacked", "interference_tick_stacked",
                "limit_velocity_stacked", "length_loop_tick", "simulated_reel_step_stacked",
                "operator_force_on_state",
                # issue 26: the kinetostatic limit, the safety filter, the model monitor
                "kinetostatic_tick", "filter_tick", "monitor_tick",
                # the fused callback's movers of values between them (kernels/chain.py)
                "put", "move", "take"}
    expected |= {"wall_force_into"} if overlay else set()
    assert set(calls) == expected
    assert min(calls.values()) >= 50  # every tick went through the checks


@pytest.mark.parametrize("model", [
    operators.NoForce(),
    operators.ForceProfile([0.0, 0.5, 2.0], [[0, 0, 0], [1.0, -2.0, 3.0], [0.5, 0.5, -1.0]]),
    operators.SpringHand([[0.1, 0.0, 0.2], [0.3, -0.1, 0.25]], [0.0, 1.5], 40.0, 5.0, 8.0),
    operators.SpringHand([[0.1, 0.0, 0.2], [0.3, -0.1, 0.25]], [0.0, 1.5], 40.0, 5.0, 8.0,
                         release_time=1.0),
])
def test_compiled_operator_force_equals_the_models_own_force(model):
    kind, times, rows, params = model.compiled()
    rng = np.random.default_rng(7)
    out = np.empty(3)
    for t in np.concatenate([[-1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 9.0], rng.uniform(-1, 3, 40)]):
        p, v = rng.normal(scale=0.2, size=3), rng.normal(scale=0.3, size=3)
        operators.operator_force_into(kind, times, rows, params, float(t), p, v, out)
        np.testing.assert_array_equal(out, model.force(t, p, v))


def test_a_model_without_a_compiled_form_is_still_ticked_from_python():
    class Push:  # any model with force(t, p, v)
        def force(self, t, p, v):
            return np.array([0.0, 0.0, 2.0 if t > 0.05 else 0.0])

    from cdpm_drake.config import resolve_scenario
    resolved = dataclasses.replace(resolve_scenario(load_scenario("exp1_no_interaction")),
                                   operator=Push())
    diagram = build_diagram(resolved)
    simulator = Simulator(diagram)
    simulator.Initialize()
    simulator.AdvanceTo(0.2)
    _, signals = logged_signals(diagram, simulator.get_context())
    # The sensor samples the force of tick k+1 at tick k+1: 2 N in z from t = 0.052 s on, so
    # the (10-sample) average reaches 2 N once ten such samples are in.
    F_H = signals["F_H"]
    assert np.all(F_H[:26, 2] == 0.0) and F_H[-1, 2] == pytest.approx(2.0, abs=1e-12)


def _run(scenario, options, seconds):
    diagram = build_diagram(scenario, options)
    simulator = Simulator(diagram)
    simulator.Initialize()
    simulator.AdvanceTo(seconds)
    return diagram, simulator.get_context()


@pytest.mark.parametrize("name,overlay", CASES)
def test_fused_wiring_changes_no_value(name, overlay):
    scenario = load_scenario(name, overlay)
    fused, fused_context = _run(scenario, BuildOptions(), 1.0)
    plain, plain_context = _run(scenario, BuildOptions(fuse_wiring=False), 1.0)
    t_f, fused_log = logged_signals(fused, fused_context)
    t_p, plain_log = logged_signals(plain, plain_context)
    np.testing.assert_array_equal(t_f, t_p)
    assert fused_log.keys() == plain_log.keys() and len(fused_log) >= 9
    for key in fused_log:
        np.testing.assert_array_equal(fused_log[key], plain_log[key], err_msg=key)
    # Every block port the views read (block_output_port) gives the same value in both, and
    # the last logged row (the log reads some of them elsewhere: from the block's result).
    for key, system, port in logged_ports(fused):
        a = block_output_port(fused, system, port)
        b = block_output_port(plain, system, port)
        value = a.Eval(a.get_system().GetMyContextFromRoot(fused_context))
        np.testing.assert_array_equal(value, b.Eval(b.get_system().GetMyContextFromRoot(
            plain_context)), err_msg=key)
        np.testing.assert_array_equal(value, fused_log[key][-1], err_msg=key)


def test_the_fused_diagram_has_one_selector_and_no_multiplexers():
    diagram = build_diagram(load_scenario("exp2_interaction"))
    kinds = [type(s).__name__ for s in diagram.GetSystems()]
    assert kinds.count("Selector") == 1
    assert diagram.GetSubsystemByName(FUSED_WIRING).num_output_ports() >= 9
    assert "Multiplexer" not in kinds and "Demultiplexer" not in kinds
    plain = build_diagram(load_scenario("exp2_interaction"), BuildOptions(fuse_wiring=False))
    # exp2: eight blocks' wiring and the logger's become one system, and seven memories (FK
    # warm start, crossing sides, the limits' previous command, the length loop's commanded
    # position, offsets and started flag; issue 26: the kinetostatic block's hand force of
    # the last tick, the filter's barrier position, its valid flag, last twist and last
    # acceleration (its brakes for the cables give way from it), the monitor's four counters: slack, misfit, unholdable, overload) one delay.
    assert [type(s).__name__ for s in plain.GetSystems()].count("Selector") == 9
    # And the six kernels of the interference block, the limits, the kinetostatic block, the
    # filter, the mapping and the monitor one callback (systems/fused_kernels.py): five
    # systems fewer.
    assert len(list(plain.GetSystems())) - len(list(diagram.GetSystems())) == 8 + 6 + 5
    names = {s.get_name() for s in diagram.GetSystems()}
    assert FUSED_DELAY in names and not names & {
        "forward_kinematics_previous", "interference_force_side_memory",
        "safety_limits_previous", "jacobian_mapping_memory"}
    # Its start: the FK warm start at the scenario's initial position, the rest zero (the
    # length loop's started flag 0: its first tick latches the measured lengths).
    context = diagram.CreateDefaultContext()
    memory = diagram.GetSubsystemByName(FUSED_DELAY)
    state = memory.GetMyContextFromRoot(context).get_discrete_state_vector().get_value()
    scenario = load_scenario("exp2_interaction")
    np.testing.assert_array_equal(state[:3], scenario.initial_position)
    assert state.size == 3 + 21 + 3 + (3 + 7 + 1) + 3 + (3 + 1 + 6 + 3) + 4
    assert not np.any(state[3:])


@pytest.mark.parametrize("plant", [SimulatedReels(), HardwareReels()], ids=["sim", "hw"])
def test_the_overview_draws_the_fused_diagram_as_the_unfused_one(plant):
    scenario = dataclasses.replace(load_scenario("exp2_interaction"), plant=plant)
    options = BuildOptions(loggers=False)  # as `cdpm diagram` draws it
    fused = overview_graphviz(build_diagram(scenario, options))
    plain = overview_graphviz(build_diagram(
        scenario, dataclasses.replace(options, fuse_wiring=False)))
    assert fused == plain
    assert "F_int" in fused and "-> n4:i1" in fused  # F_int into the adder, through the wiring


@pytest.mark.parametrize("module_name", ["forward_kinematics", "plants.simulated_reels"])
def test_the_damped_fallback_gives_the_compiled_answer(monkeypatch, module_name):
    # When the warm Gauss-Newton does not settle, FK and the world's step finish with the
    # damped solver of kinematics.forward_kinematics. Force that path every tick (the
    # kernel runs, then reports failure): the logs agree with the compiled path to 1e-9.
    module = importlib.import_module(f"cdpm_drake.systems.{module_name}")
    scenario = load_scenario("exp2_interaction")
    _, reference = logged_signals(*_run(scenario, BuildOptions(), 0.5))
    real_bind = module.bind

    def failing_bind(kernel, *example):
        entry = real_bind(kernel, *example)
        return lambda *args: entry(*args) and False

    monkeypatch.setattr(module, "bind", failing_bind)
    _, fallback = logged_signals(*_run(scenario, BuildOptions(), 0.5))
    for key in ("p", "lengths", "F_H", "F_d", "velocity"):
        np.testing.assert_allclose(fallback[key], reference[key], atol=1e-9, rtol=0,
                                   err_msg=key)


# --- The dynamic plant (issue 21) -----------------------------------------------------------

def test_every_bound_call_of_the_dynamic_plant_passes_the_types_it_was_bound_for(monkeypatch):
    # As above, for the dynamic plant's step (cables.cable_net_step and the operator model),
    # which runs once per 1 ms plant step: the loggers read it at each tick in the same context
    # as the next step's updates, so 100 calls in 0.1 s (plus the start).
    calls = _check_every_bound_call(monkeypatch)
    simulator = Simulator(build_diagram(load_scenario("exp2_interaction",
                                                      "plant: !DynamicReels {}")))
    simulator.Initialize()
    simulator.AdvanceTo(0.1)
    assert {"cable_net_step", "operator_force_at"} <= set(calls)
    assert "simulated_reel_step_stacked" not in calls
    assert 100 <= calls["cable_net_step"] == calls["operator_force_at"] <= 101


def test_a_model_without_a_compiled_form_is_ticked_from_python_on_the_dynamic_plant():
    # The same force table as a shipped ForceProfile (compiled) and as a Python model calling
    # the table's own `force` (the branch for any model with force(t, p, v)): the plant's
    # ground truth and the controller's log are the same, bit for bit.
    from cdpm_drake.config import resolve_scenario
    from cdpm_drake.runs.simulate import simulate

    table = operators.ForceProfile([0.0, 0.05, 0.1], [[0, 0, 0], [4.0, -3.0, 5.0], [0, 0, 0]])

    class Wrapped:
        def force(self, t, p, v):
            return table.force(t, p, v)

    base = resolve_scenario(load_scenario("exp2_interaction", "plant: !DynamicReels {}"))
    logs = [simulate(scenario=dataclasses.replace(base, operator=model), duration=0.2).log
            for model in (table, Wrapped())]
    assert np.abs(logs[0]["F_H"]).max() > 0.5  # the push was measured
    for key in ("p_true", "rpy_true", "tensions", "F_H", "p", "lengths"):
        np.testing.assert_array_equal(logs[0][key], logs[1][key], err_msg=key)
