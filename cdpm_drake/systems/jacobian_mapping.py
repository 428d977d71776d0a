"""The Jacobian velocity mapping of Fig. 5 (eq. 3, eq. 7), with a cable-length loop."""

import numpy as np
from pydrake.systems.framework import Diagram

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.kinematics import length_loop_sizes, length_loop_tick
from cdpm_drake.systems.kernel_system import KernelSystem
from cdpm_drake.systems.wiring import note_piece, sub_diagram, unit_delay, wiring

# The cable-length loop's gain when a caller gives none, 1/s (scenario.Controller).
DEFAULT_LENGTH_GAIN = 40.0


class ReelRates(KernelSystem):
    """l_dot = J(p) v + K_l (l_d - l) (`kinematics.length_loop_tick`) in one compiled call;
    stateless: the loop's memory (commanded position, length offsets, started flag) comes
    back through a C++ one-tick delay. Its inputs arrive stacked by a C++ Selector (one
    evaluation from Python, not four).

    .. pydrake_system::

        name: map
        input_ports:
        - inputs ([p_WP m, velocity_command m/s (base frame), cable_lengths m, memory])
        output_ports:
        - result ([reel_velocity_command m/s, commanded_lengths m, next memory])
    """

    def __init__(self, robot, *, length_gain, time_step, dead_band=0.0):
        sizes = length_loop_sizes(robot.num_cables)
        offsets = owned(robot.attachments - robot.reels)
        gain, step, band = float(length_gain), float(time_step), float(dead_band)
        # Compiled (or loaded) now, not in the first tick.
        example = np.zeros(sizes["x"])
        example[:3] = robot.workspace.center
        tick = bind(length_loop_tick, offsets, gain, step, band, example,
                    np.empty(sizes["out"]))
        super().__init__(sizes["x"], sizes["out"], tick, (offsets, gain, step, band))


class JacobianVelocityMapping(Diagram):
    """Reel velocities l_dot = J(p) v (eq. 3) plus the cable-length loop K_l (l_d - l) and
    the drives' dead band made up where the loop asks for motion: m/s of cable, positive pays
    cable out. l_d, the commanded lengths, are those of the
    commanded platform position advanced by J v each tick (see
    `kinematics.length_loop_tick`); l the measured ones (encoders in simulation, the reel
    bridge's on the robot). length_gain K_l = 0 is the paper's open loop.

    .. pydrake_system::

        name: jacobian_mapping
        input_ports:
        - p_WP (m, base frame)
        - velocity_command (m/s, base frame)
        - cable_lengths (m, one per cable: measured)
        output_ports:
        - reel_velocity_command (m/s, one per cable)
        - commanded_lengths (m, one per cable: l_d)
    """

    def __init__(self, robot, *, length_gain=DEFAULT_LENGTH_GAIN, time_step=0.002,
                 dead_band=0.0):
        super().__init__()
        sub_diagram(self, lambda builder: build_jacobian_mapping(
            builder, robot, length_gain=length_gain, time_step=time_step,
            dead_band=dead_band))


# The system a flat build (FlatBlock) names after the block.
JACOBIAN_MAPPING_MAIN = "map"


def build_jacobian_mapping(builder, robot, *, length_gain=DEFAULT_LENGTH_GAIN,
                           time_step=0.002, dead_band=0.0):
    """JacobianVelocityMapping's systems and exported ports, into `builder` (a DiagramBuilder
    or a FlatBlock). dead_band: the drives' (m/s, robot.Dynamics.dead_band) that the loop
    makes up; 0: none."""
    m = robot.num_cables
    sizes = length_loop_sizes(m)
    rates = builder.AddNamedSystem("map", ReelRates(robot, length_gain=length_gain,
                                                    time_step=time_step, dead_band=dead_band))
    # Starts at zero: the started flag 0 makes the first tick latch the measured lengths.
    memory = builder.AddNamedSystem("memory", unit_delay(sizes["memory"], time_step))
    # One C++ Selector stacks the inputs and the memory for `map` and splits its result.
    route = builder.AddNamedSystem("wiring", wiring(
        [("p_WP", 3), ("velocity_command", 3), ("cable_lengths", m),
         ("memory_previous", sizes["memory"]), ("result", sizes["out"])],
        [("inputs", [("p_WP", 0, 3), ("velocity_command", 0, 3), ("cable_lengths", 0, m),
                     ("memory_previous", 0, sizes["memory"])]),
         ("reel_velocity_command", [("result", 0, m)]),
         ("commanded_lengths", [("result", m, m)]),
         ("memory", [("result", 2 * m, sizes["memory"])])]))
    result = rates.GetOutputPort("result")
    builder.Connect(result, route.GetInputPort("result"))
    builder.Connect(route.GetOutputPort("memory"), memory.get_input_port())
    builder.Connect(memory.get_output_port(), route.GetInputPort("memory_previous"))
    builder.Connect(route.GetOutputPort("inputs"), rates.GetInputPort("inputs"))
    for name in ("p_WP", "velocity_command", "cable_lengths"):
        builder.ExportInput(route.GetInputPort(name), name)
    for name, offset in (("reel_velocity_command", 0), ("commanded_lengths", m)):
        builder.ExportOutput(route.GetOutputPort(name), name)
        note_piece(builder, name, result, offset)
