"""The threshold block of Fig. 5: velocity, acceleration and the virtual wall."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from ..limits import limit_velocity
from ._tick_cache import declare_tick_cache


class SafetyLimits(LeafSystem):
    """Caps the admittance velocity (see `limits.limit_velocity`). The previous command lives in
    discrete state (for the acceleration limit).

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
        self._lower = np.asarray(lower, dtype=float)
        self._upper = np.asarray(upper, dtype=float)
        self._vmax = float(max_velocity)
        self._amax = float(max_acceleration)
        self._wall = bool(virtual_wall)
        self._T = float(time_step)
        self._v_desired = self.DeclareVectorInputPort("velocity_desired", 3)
        self._p = self.DeclareVectorInputPort("p_WP", 3)
        self._previous = self.DeclareDiscreteState(3)
        deps = {self._v_desired.ticket(), self._p.ticket(),
                self.discrete_state_ticket(self._previous)}
        # Computed once per tick, for the output and the update alike.
        self._command = declare_tick_cache(self, "velocity_command", self._compute_command, deps)
        self.DeclareVectorOutputPort("velocity_command", 3, self._calc_velocity_command,
                                     prerequisites_of_calc=deps)
        self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0, self._update_previous)

    def _compute_command(self, context):
        return limit_velocity(
            self._v_desired.Eval(context),
            context.get_discrete_state(self._previous).get_value(),
            self._p.Eval(context), self._lower, self._upper, max_velocity=self._vmax,
            max_acceleration=self._amax, time_step=self._T, virtual_wall=self._wall)

    def _calc_velocity_command(self, context, output):
        output.SetFromVector(self._command.Eval(context))

    def _update_previous(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._previous).SetFromVector(
            self._command.Eval(context))
