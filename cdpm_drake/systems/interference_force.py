"""The interference-force block of Fig. 5 (section 4, eqs. 23-30)."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from ..interference import interference_force
from ._tick_cache import declare_tick_cache


class InterferenceForce(LeafSystem):
    """F_int from the platform position: distances of all watched cable pairs, the repulsive
    force along each distance gradient with logistic intensity, summed and clipped.

    The crossing-side memory (one entry per pair, see `interference.update_side`: its sign is
    the side the cables started on, 0 while unknown, magnitude 2 while crossed) lives in
    discrete state, updated every tick, so that a crossing is remembered and the force pushes
    back towards the side the cables started on. It starts unknown (0): the first tick adopts
    the sides the cables are on wherever the platform really is (on the robot, the measured
    pose rather than the scenario's start); the start is assumed not crossed.

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
        self._robot = robot
        self._params = params
        P = robot.num_pairs
        self._p = self.DeclareVectorInputPort("p_WP", 3)
        self._side = self.DeclareDiscreteState(P)  # 0: unknown
        deps = {self._p.ticket(), self.discrete_state_ticket(self._side)}
        # One evaluation of the math per tick, shared by all outputs and the update.
        self._result = declare_tick_cache(self, "interference_result", self._compute_result, deps)
        self.DeclareVectorOutputPort("F_int", 3, self._calc_F_int, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("pair_distances", P, self._calc_pair_distances,
                                     prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("active", P, self._calc_active, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("crossed", P, self._calc_crossed,
                                     prerequisites_of_calc=deps)
        self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0, self._update_side)

    def _compute_result(self, context):
        side = context.get_discrete_state(self._side).get_value().astype(np.int8)
        return interference_force(self._robot, self._p.Eval(context), self._params, side=side)

    def _result_of(self, context):
        return self._result.Eval(context)

    def _calc_F_int(self, context, output):
        output.SetFromVector(self._result_of(context).force)

    def _calc_pair_distances(self, context, output):
        output.SetFromVector(self._result_of(context).distance)

    def _calc_active(self, context, output):
        output.SetFromVector(self._result_of(context).active.astype(float))

    def _calc_crossed(self, context, output):
        output.SetFromVector(self._result_of(context).crossed.astype(float))

    def _update_side(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._side).SetFromVector(
            self._result_of(context).side.astype(float))
