"""The threshold block of Fig. 5: velocity, acceleration and the virtual wall."""

import numpy as np
from pydrake.systems.framework import Diagram

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.safety_limits import limit_velocity_stacked
from cdpm_drake.systems.kernel_system import KernelSystem
from cdpm_drake.systems.wiring import stack, sub_diagram, unit_delay


class VelocityLimit(KernelSystem):
    """`limits.limit_velocity` of the desired velocity, given the previous command; stateless.
    Its inputs arrive stacked by a C++ Selector (one evaluation from Python, not three).

    .. pydrake_system::

        name: limit
        input_ports:
        - inputs ([velocity_desired m/s, p_WP m, velocity_previous m/s], base frame)
        output_ports:
        - velocity_command (m/s, base frame)
    """

    def __init__(self, *, lower, upper, max_velocity, max_acceleration, virtual_wall,
                 time_step):
        bounds = owned([np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)])
        args = (float(max_velocity), float(max_acceleration), float(time_step),
                bool(virtual_wall))
        # Compiled (or loaded) now, not in the first tick.
        limit = bind(limit_velocity_stacked, np.zeros(9), bounds, *args, np.empty(3))
        super().__init__(9, 3, limit, after=(bounds, *args),
                         output_name="velocity_command")


class SafetyLimits(Diagram):
    """Caps the admittance velocity (see `limits.limit_velocity`). The previous command, for
    the acceleration limit, is held by a C++ one-tick delay (zero at the start).

    .. pydrake_system::

        name: safety_limits
        input_ports:
        - velocity_desired (m/s, base frame)
        - p_WP (m, base frame)
        output_ports:
        - velocity_command (m/s, base frame)
    """

    def __init__(self, *, lower, upper, max_velocity, max_acceleration, virtual_wall=True,
                 time_step=0.002):
        super().__init__()
        sub_diagram(self, lambda builder: build_safety_limits(
            builder, lower=lower, upper=upper, max_velocity=max_velocity,
            max_acceleration=max_acceleration, virtual_wall=virtual_wall,
            time_step=time_step))


# The system a flat build (FlatBlock) names after the block.
SAFETY_LIMITS_MAIN = "limit"


def build_safety_limits(builder, *, lower, upper, max_velocity, max_acceleration,
                        virtual_wall=True, time_step=0.002):
    """SafetyLimits' systems and exported ports, into `builder` (a DiagramBuilder or a
    FlatBlock)."""
    limit = builder.AddNamedSystem("limit", VelocityLimit(
        lower=lower, upper=upper, max_velocity=max_velocity,
        max_acceleration=max_acceleration, virtual_wall=virtual_wall, time_step=time_step))
    previous = builder.AddNamedSystem("previous", unit_delay(3, time_step))
    inputs = builder.AddNamedSystem("inputs", stack([3, 3, 3]))
    command = limit.GetOutputPort("velocity_command")
    builder.Connect(command, previous.get_input_port())
    builder.Connect(previous.get_output_port(), inputs.get_input_port(2))
    builder.Connect(inputs.get_output_port(), limit.GetInputPort("inputs"))
    builder.ExportInput(inputs.get_input_port(0), "velocity_desired")
    builder.ExportInput(inputs.get_input_port(1), "p_WP")
    builder.ExportOutput(command, "velocity_command")
