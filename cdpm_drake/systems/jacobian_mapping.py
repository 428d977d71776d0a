"""The Jacobian velocity mapping of Fig. 5 (eq. 3, eq. 7)."""

import numpy as np
from pydrake.systems.framework import Diagram, LeafSystem

from ..kernel_call import bind, owned
from ..kinematics import reel_rates_stacked
from ._wiring import stack, sub_diagram


class ReelRates(LeafSystem):
    """l_dot = J(p) v (eq. 3) in one compiled call; stateless. Its inputs arrive stacked by a
    C++ Selector (one evaluation from Python, not two).

    .. pydrake_system::

        name: map
        input_ports:
        - inputs ([p_WP m, velocity_command m/s], base frame)
        output_ports:
        - reel_velocity_command (m/s, one per cable)
    """

    def __init__(self, robot):
        super().__init__()
        self._offsets = owned(robot.attachments - robot.reels)
        self._inputs = self.DeclareVectorInputPort("inputs", 6)
        # Compiled (or loaded) now, not in the first tick.
        rates = bind(reel_rates_stacked, self._offsets, np.ones(6), np.empty(robot.num_cables))
        # The tick's callback is a closure over locals, not a method reading self: attribute
        # lookups on a pybind LeafSystem cost ~0.2 us each (scripts/count_instructions.py).
        offsets, inputs = self._offsets, self._inputs.Eval

        def calc_reel_velocity_command(context, output):
            rates(offsets, inputs(context), output.get_mutable_value())

        self.DeclareVectorOutputPort(
            "reel_velocity_command", robot.num_cables, calc_reel_velocity_command,
            prerequisites_of_calc={self._inputs.ticket()})


class JacobianVelocityMapping(Diagram):
    """Reel velocities l_dot = J(p) v (eq. 3): m/s of cable, positive pays cable out.

    .. pydrake_system::

        name: jacobian_mapping
        input_ports:
        - p_WP (m, base frame)
        - velocity_command (m/s, base frame)
        output_ports:
        - reel_velocity_command (m/s, one per cable)
    """

    def __init__(self, robot):
        super().__init__()
        sub_diagram(self, lambda builder: build_jacobian_mapping(builder, robot))


# The system a flat build (FlatBlock) names after the block.
JACOBIAN_MAPPING_MAIN = "map"


def build_jacobian_mapping(builder, robot):
    """JacobianVelocityMapping's systems and exported ports, into `builder` (a DiagramBuilder
    or a FlatBlock)."""
    rates = builder.AddNamedSystem("map", ReelRates(robot))
    inputs = builder.AddNamedSystem("inputs", stack([3, 3]))
    builder.Connect(inputs.get_output_port(), rates.GetInputPort("inputs"))
    builder.ExportInput(inputs.get_input_port(0), "p_WP")
    builder.ExportInput(inputs.get_input_port(1), "velocity_command")
    builder.ExportOutput(rates.GetOutputPort("reel_velocity_command"), "reel_velocity_command")
