"""The forward-kinematics block of Fig. 5: cable lengths back to the platform position."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from ..kinematics import forward_kinematics
from ._tick_cache import declare_tick_cache


class ForwardKinematicsEstimator(LeafSystem):
    """p from the measured cable lengths, warm-started from the previous estimate (discrete
    state), so one or two Levenberg-Marquardt steps suffice at 500 Hz.

    Lengths that no platform position explains within `max_residual` (m) raise
    KinematicsError: on the robot that is a fault (slack or broken cable, bad encoder).

    .. pydrake_system::

        name: forward_kinematics
        input_ports:
        - cable_lengths (m, one per cable)
        output_ports:
        - p_WP (m, base frame)
    """

    def __init__(self, robot, *, initial_position, max_residual=1e-6, time_step=0.002):
        super().__init__()
        self._robot = robot
        self._max_residual = float(max_residual)
        self._lengths = self.DeclareVectorInputPort("cable_lengths", robot.num_cables)
        self._previous = self.DeclareDiscreteState(np.asarray(initial_position, dtype=float))
        deps = {self._lengths.ticket(), self.discrete_state_ticket(self._previous)}
        self._estimate = declare_tick_cache(self, "p_WP_estimate", self._compute_estimate, deps)
        self.DeclareVectorOutputPort("p_WP", 3, self._calc_p_WP, prerequisites_of_calc=deps)
        self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0, self._update_previous)

    def _compute_estimate(self, context):
        return forward_kinematics(
            self._robot, self._lengths.Eval(context),
            p_guess=context.get_discrete_state(self._previous).get_value(),
            max_residual=self._max_residual)

    def _calc_p_WP(self, context, output):
        output.SetFromVector(self._estimate.Eval(context))

    def _update_previous(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._previous).SetFromVector(
            self._estimate.Eval(context))

