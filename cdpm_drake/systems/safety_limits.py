"""The threshold block of Fig. 5: velocity, acceleration and the virtual wall."""

import numpy as np
from pydrake.systems.framework import Diagram, LeafSystem

from ..limits import limit_velocity_into
from ._wiring import sub_diagram, unit_delay


class VelocityLimit(LeafSystem):
    """`limits.limit_velocity` of the desired velocity, given the previous command (an
    input); stateless.

    .. pydrake_system::

        name: limit
        input_ports:
        - velocity_desired (m/s, base frame)
        - p_WP (m, base frame)
        - velocity_previous (m/s, base frame)
        output_ports:
        - velocity_command (m/s, base frame)
    """

    def __init__(self, *, lower, upper, max_velocity, max_acceleration, virtual_wall,
                 time_step):
        super().__init__()
        self._bounds = np.array([np.asarray(lower, dtype=float),
                                 np.asarray(upper, dtype=float)])
        self._args = (float(max_velocity), float(max_acceleration), float(time_step),
                      bool(virtual_wall))
        self._v_desired = self.DeclareVectorInputPort("velocity_desired", 3)
        self._p = self.DeclareVectorInputPort("p_WP", 3)
        self._previous = self.DeclareVectorInputPort("velocity_previous", 3)
        self.DeclareVectorOutputPort(
            "velocity_command", 3, self._calc_velocity_command,
            prerequisites_of_calc={self._v_desired.ticket(), self._p.ticket(),
                                   self._previous.ticket()})
        z = np.zeros(3)  # compile (or load) the kernel now, not in the first tick
        limit_velocity_into(z, z, z, self._bounds, *self._args, np.empty(3))

    def _calc_velocity_command(self, context, output):
        limit_velocity_into(self._v_desired.Eval(context), self._previous.Eval(context),
                            self._p.Eval(context), self._bounds, *self._args,
                            output.get_mutable_value())


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

        def build(builder):
            limit = builder.AddNamedSystem("limit", VelocityLimit(
                lower=lower, upper=upper, max_velocity=max_velocity,
                max_acceleration=max_acceleration, virtual_wall=virtual_wall,
                time_step=time_step))
            previous = builder.AddNamedSystem("previous", unit_delay(3, time_step))
            command = limit.GetOutputPort("velocity_command")
            builder.Connect(command, previous.get_input_port())
            builder.Connect(previous.get_output_port(), limit.GetInputPort("velocity_previous"))
            builder.ExportInput(limit.GetInputPort("velocity_desired"), "velocity_desired")
            builder.ExportInput(limit.GetInputPort("p_WP"), "p_WP")
            builder.ExportOutput(command, "velocity_command")

        sub_diagram(self, build)
