"""Several blocks' kernels in one Drake callback (systems/fused_kernels.py): the blocks keep
their ports and values, a result one of them needs from an earlier one is passed inside the
callback, and the order must follow the data flow. (The product's logs as built and fused
are compared bit for bit in test_fast_calls.py, its references in
tests/runs/test_reference_logs.py.)"""

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from cdpm_drake.config import load_scenario
from cdpm_drake.diagram import block_output_port, build_diagram, has_block, logged_ports
from cdpm_drake.systems.fused_kernels import (FUSED_KERNELS, FusedKernelSystem, fuse_kernels,
                                              safety_chain)
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block
from cdpm_drake.systems.wiring import FlatBlock, fuse_wiring


def _double(x, out):  # out = 2 u, the memory: the sum of the inputs so far
    out[0] = 2.0 * x[0]
    out[1] = x[1] + x[0]


def _affine(gain, x, out):  # out = gain a + b, a from the first block
    out[0] = gain * x[0] + x[1]


def _two_blocks(order, fuse):
    """u = 3 (a constant) -> block "a" (2 u, with a memory of the sum of u) -> "b" (5 a + 1);
    `order`: the blocks' order for fuse_kernels; returns (b's output value at the start and
    after 2 ticks, a's memory output then, the built diagram)."""
    from pydrake.systems.analysis import Simulator

    builder = DiagramBuilder()
    u = builder.AddNamedSystem("u", ConstantVectorSource([3.0]))
    one = builder.AddNamedSystem("one", ConstantVectorSource([1.0]))
    a = FlatBlock(builder, "a", "solve", lambda b: build_kernel_block(
        b, KernelSystem(2, 2, _double), inputs=[("u", 1)], memory=(1, None),
        outputs=[("y", 0, 1)], memory_at=1, time_step=0.1,
        memory_outputs=[("sum_previous", 0, 1)]))
    b = FlatBlock(builder, "b", "solve", lambda b: build_kernel_block(
        b, KernelSystem(2, 1, _affine, before=(5.0,)), inputs=[("a", 1), ("c", 1)],
        memory=None, outputs=[("y", 0, 1)], memory_at=0, time_step=0.1))
    a.connect_input(u.get_output_port(), "u")
    b.connect_input(a.GetOutputPort("y"), "a")
    b.connect_input(one.get_output_port(), "c")
    blocks = {"a": a, "b": b}
    if fuse:
        wirings = {**a.wirings, **b.wirings}
        specs, results = fuse_kernels(builder, [blocks[n] for n in order], wirings)
        wirings.update(specs)
        for member, (split, k) in results.items():
            for block in blocks.values():
                block.relocate((member, 0), split.get_output_port(k))
        moved, _ = fuse_wiring(builder, wirings, keep={
            at for block in blocks.values() for at in block.layout()["outputs"].values()})
    else:
        moved = {}

    def port(block, name):  # where the block's output is (after the fusion: in the wiring)
        system, k = block.layout(moved)["outputs"][name]
        return builder.GetSubsystemByName(system).get_output_port(k)

    for name, block in blocks.items():
        builder.ExportOutput(port(block, "y"), name)
    builder.ExportOutput(port(a, "sum_previous"), "sum_previous")
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.Initialize()
    start = diagram.get_output_port(1).Eval(simulator.get_context()).copy()
    simulator.AdvanceTo(0.2)  # two ticks of the memory
    context = simulator.get_context()
    return (start, diagram.get_output_port(1).Eval(context),
            diagram.get_output_port(2).Eval(context), diagram)


def test_a_fused_pair_gives_what_the_blocks_give_apart():
    # b = 5 (2 u) + 1 = 31 whether a and b are one callback or two; a's memory (the sum of
    # u, 3 per tick) is still a's: 6 after two ticks.
    for fuse in (False, True):
        start, end, memory, diagram = _two_blocks(["a", "b"], fuse)
        np.testing.assert_array_equal(start, [31.0])
        np.testing.assert_array_equal(end, [31.0])
        np.testing.assert_array_equal(memory, [6.0])
        kinds = [type(s).__name__ for s in diagram.GetSystems()]
        assert kinds.count("KernelSystem") == (0 if fuse else 2)
        assert kinds.count("FusedKernelSystem") == (1 if fuse else 0)


def test_fusing_against_the_data_flow_is_an_error_naming_the_block():
    with pytest.raises(ValueError, match="'b' reads 'a'"):
        _two_blocks(["b", "a"], True)


def test_exp2_computes_its_safety_blocks_in_one_callback_and_keeps_their_ports():
    diagram = build_diagram(load_scenario("exp2_interaction"))
    names = {s.get_name() for s in diagram.GetSystems()}
    chain = ["interference_force", "safety_limits", "kinetostatic_force", "safety_filter",
             "jacobian_mapping", "model_monitor"]
    assert diagram.fused_kernels == {"system": FUSED_KERNELS, "blocks": chain}
    assert isinstance(diagram.GetSubsystemByName(FUSED_KERNELS), FusedKernelSystem)
    assert not names & set(chain)
    # Still blocks of the diagram (the real-time status line asks for the interference one).
    assert all(has_block(diagram, block) for block in chain)
    # Python callbacks left: the force sensor's range, the forward kinematics and the fused
    # one (eight before).
    python = [s for s in diagram.GetSystems()
              if isinstance(s, (KernelSystem, FusedKernelSystem))]
    assert len(python) == 3
    # Each block still has its named ports, logged from them.
    logged = {(block, port) for _, block, port in logged_ports(diagram)}
    assert {("kinetostatic_force", "kappa"), ("safety_filter", "velocity_command"),
            ("model_monitor", "t_star"), ("safety_filter", "velocity_desired")} <= logged
    for block in chain:
        assert set(diagram.flat_blocks[block]["outputs"]) and not diagram.flat_blocks[block][
            "systems"]
    context = diagram.CreateDefaultContext()
    # The filter's velocity_desired is the limits' command, passed inside the callback.
    np.testing.assert_array_equal(
        block_output_port(diagram, "safety_filter", "velocity_desired").Eval(
            diagram.GetSubsystemByName("wiring").GetMyContextFromRoot(context)),
        block_output_port(diagram, "safety_limits", "velocity_command").Eval(
            diagram.GetSubsystemByName("wiring").GetMyContextFromRoot(context)))


def test_the_monitor_stays_apart_where_the_hand_force_feeds_through_the_plant():
    # The dynamic plant samples the hand in the step that takes the reel command (its
    # measured_force has direct feedthrough): the monitor reads that hand of the same tick,
    # which the reel command of the fused callback feeds, so it keeps its own.
    from cdpm_drake.diagram import make_plant

    scenario = load_scenario("exp2_interaction", "{plant: !DynamicReels {}, controller: "
                             "{pose: full, tension_control: true}}")
    plant = make_plant(scenario)
    command = plant.GetInputPort("reel_velocity_command").get_index()
    assert plant.HasDirectFeedthrough(command, plant.GetOutputPort("measured_force").get_index())
    diagram = build_diagram(scenario)
    assert diagram.fused_kernels["blocks"] == [
        "interference_force", "orientation_hold", "safety_limits", "kinetostatic_force",
        "safety_filter", "tension_distribution", "jacobian_mapping", "tension_damping"]
    assert diagram.HasSubsystemNamed("model_monitor")
    # The paper's Fig. 5 (no safety block) is built alike: its blocks on the path of the
    # command in one callback; a single block is not fused.
    fig5 = load_scenario("exp2_interaction", "{safety_filter: {enabled: false}, "
                         "model_monitor: {enabled: false}}")
    assert build_diagram(fig5).fused_kernels["blocks"] == [
        "interference_force", "safety_limits", "jacobian_mapping"]
    assert safety_chain({"safety_limits": None}, plant) == []
