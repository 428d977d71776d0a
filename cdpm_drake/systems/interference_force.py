"""The interference-force block of Fig. 5 (section 4, eqs. 23-30)."""

import numpy as np
from pydrake.systems.framework import Diagram, LeafSystem
from pydrake.systems.primitives import Demultiplexer, Multiplexer

from ..interference import interference_tick_stacked, pair_geometry, result_layout
from ..kernel_call import bind, owned
from ._wiring import sub_diagram, unit_delay

# The ports of the block, in the order of the flat result (interference.result_layout).
OUTPUTS = ("F_int", "pair_distances", "active", "crossed", "side")


class InterferencePairs(LeafSystem):
    """Every watched pair at p, in one compiled evaluation per tick; stateless.

    The output is `interference.result_layout`'s flat vector: F_int (3), distances, active,
    crossed, the updated side memory (P each), then s, t, intensities, gradients and
    directions. The position and the previous side memory arrive stacked by a C++
    Multiplexer (one evaluation from Python, not two).

    .. pydrake_system::

        name: pairs
        input_ports:
        - inputs ([p_WP m (base frame), previous side memory (one per watched pair)])
        output_ports:
        - result (see interference.result_layout)
    """

    def __init__(self, robot, params):
        super().__init__()
        P = robot.num_pairs
        self._geo = owned(pair_geometry(robot))
        self._par = owned(params.packed)
        self._floor, self._F_max = float(params.gradient_floor), float(params.F_max)
        self._inputs = self.DeclareVectorInputPort("inputs", 3 + P)
        self.DeclareVectorOutputPort("result", 3 + 13 * P, self._calc_result,
                                     prerequisites_of_calc={self._inputs.ticket()})
        # Compiled (or loaded) now, not in the first tick.
        self._tick = bind(interference_tick_stacked, self._geo, self._par, self._floor,
                          self._F_max, np.zeros(3 + P), np.empty(3 + 13 * P))

    def _calc_result(self, context, output):
        self._tick(self._geo, self._par, self._floor, self._F_max, self._inputs.Eval(context),
                   output.get_mutable_value())


class InterferenceForce(Diagram):
    """F_int from the platform position: distances of all watched cable pairs, the repulsive
    force along each distance gradient with logistic intensity, summed and clipped.

    The crossing-side memory (one entry per pair, see `interference.update_side`: its sign is
    the side the cables started on, 0 while unknown, magnitude 2 while crossed) is held by a
    C++ one-tick delay, so that a crossing is remembered and the force pushes back towards the
    side the cables started on. It starts unknown (0): the first tick adopts the sides the
    cables are on wherever the platform really is (on the robot, the measured pose rather
    than the scenario's start); the start is assumed not crossed.

    .. pydrake_system::

        name: interference_force
        input_ports:
        - p_WP (m, base frame)
        output_ports:
        - F_int (N, base frame)
        - pair_distances (m, one per watched pair)
        - active (1 where d <= d_u)
        - crossed (1 where the pair is crossed)
    """

    def __init__(self, robot, params, *, time_step=0.002):
        super().__init__()
        sub_diagram(self, lambda builder: build_interference_force(
            builder, robot, params, time_step=time_step))


# The system a flat build (FlatBlock) names after the block.
INTERFERENCE_FORCE_MAIN = "pairs"


def build_interference_force(builder, robot, params, *, time_step=0.002):
    """InterferenceForce's systems and exported ports, into `builder` (a DiagramBuilder or
    a FlatBlock)."""
    P = robot.num_pairs
    layout = result_layout(P)
    sizes = [layout[name][1] - layout[name][0] for name in
             ("force", "distance", "active", "crossed", "side")]
    sizes.append(3 + 13 * P - sum(sizes))  # s, t, intensities, gradients, directions
    pairs = builder.AddNamedSystem("pairs", InterferencePairs(robot, params))
    split = builder.AddNamedSystem("split", Demultiplexer(sizes))
    side = builder.AddNamedSystem("side_memory", unit_delay(P, time_step))
    inputs = builder.AddNamedSystem("inputs", Multiplexer([3, P]))
    builder.Connect(pairs.GetOutputPort("result"), split.get_input_port())
    builder.Connect(split.get_output_port(OUTPUTS.index("side")), side.get_input_port())
    builder.Connect(side.get_output_port(), inputs.get_input_port(1))
    builder.Connect(inputs.get_output_port(), pairs.GetInputPort("inputs"))
    builder.ExportInput(inputs.get_input_port(0), "p_WP")
    for k, name in enumerate(OUTPUTS[:-1]):
        builder.ExportOutput(split.get_output_port(k), name)
