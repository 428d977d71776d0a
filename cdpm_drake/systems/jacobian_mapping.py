"""The Jacobian velocity mapping of Fig. 5 (eq. 3, eq. 7)."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from ..kinematics import reel_rates


class JacobianVelocityMapping(LeafSystem):
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
        self._offsets = np.ascontiguousarray(robot.attachments - robot.reels)
        self._p = self.DeclareVectorInputPort("p_WP", 3)
        self._v = self.DeclareVectorInputPort("velocity_command", 3)
        self.DeclareVectorOutputPort(
            "reel_velocity_command", robot.num_cables, self._calc_reel_velocity_command,
            prerequisites_of_calc={self._p.ticket(), self._v.ticket()})
        # Compile (or load) the kernel now, not in the first tick.
        reel_rates(self._offsets, np.ones(3), np.zeros(3), np.empty(robot.num_cables))

    def _calc_reel_velocity_command(self, context, output):
        reel_rates(self._offsets, self._p.Eval(context), self._v.Eval(context),
                   output.get_mutable_value())
