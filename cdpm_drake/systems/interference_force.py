"""The interference-force block of Fig. 5 (section 4, eqs. 23-30)."""

import numpy as np
from pydrake.systems.framework import Diagram

from cdpm_drake.kernels.interference import interference_tick_stacked, pair_geometry, result_layout
from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.systems.kernel_system import KernelSystem
from cdpm_drake.systems.wiring import note_piece, sub_diagram, unit_delay, wiring

# The ports of the block, in the order of the flat result (interference.result_layout).
OUTPUTS = ("F_int", "pair_distances", "active", "crossed", "side")


class InterferencePairs(KernelSystem):
    """Every watched pair at p, in one compiled evaluation per tick; stateless.

    The output is `interference.result_layout`'s flat vector: F_int (3), distances, active,
    crossed, the updated side memory (P each), then s, t, intensities, gradients and
    directions. The position and the previous side memory arrive stacked by a C++
    Selector (one evaluation from Python, not two).

    .. pydrake_system::

        name: pairs
        input_ports:
        - inputs ([p_WP m (base frame), previous side memory (one per watched pair)])
        output_ports:
        - result (see interference.result_layout)
    """

    def __init__(self, robot, params):
        P = robot.num_pairs
        geo, par = owned(pair_geometry(robot)), owned(params.packed)
        floor, F_max = float(params.gradient_floor), float(params.F_max)
        # Compiled (or loaded) now, not in the first tick.
        tick = bind(interference_tick_stacked, geo, par, floor, F_max, np.zeros(3 + P),
                    np.empty(3 + 13 * P))
        super().__init__(3 + P, 3 + 13 * P, tick, (geo, par, floor, F_max))


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
    fields = dict(zip(OUTPUTS, ("force", "distance", "active", "crossed", "side")))
    pairs = builder.AddNamedSystem("pairs", InterferencePairs(robot, params))
    side = builder.AddNamedSystem("side_memory", unit_delay(P, time_step))
    # One C++ Selector stacks the position and the memory for `pairs` and splits its result.
    route = builder.AddNamedSystem("wiring", wiring(
        [("p_WP", 3), ("side_previous", P), ("result", 3 + 13 * P)],
        [("inputs", [("p_WP", 0, 3), ("side_previous", 0, P)])]
        + [(name, [("result", layout[field][0], layout[field][1] - layout[field][0])])
           for name, field in fields.items()]))
    result = pairs.GetOutputPort("result")
    builder.Connect(result, route.GetInputPort("result"))
    builder.Connect(route.GetOutputPort("side"), side.get_input_port())
    builder.Connect(side.get_output_port(), route.GetInputPort("side_previous"))
    builder.Connect(route.GetOutputPort("inputs"), pairs.GetInputPort("inputs"))
    builder.ExportInput(route.GetInputPort("p_WP"), "p_WP")
    for name in OUTPUTS[:-1]:
        builder.ExportOutput(route.GetOutputPort(name), name)
        note_piece(builder, name, result, layout[fields[name]][0])
