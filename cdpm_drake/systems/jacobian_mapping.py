"""The Jacobian velocity mapping of Fig. 5 (eq. 3, eq. 7)."""

from pydrake.systems.framework import LeafSystem

from ..kinematics import jacobian


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
        self._robot = robot
        self._p = self.DeclareVectorInputPort("p_WP", 3)
        self._v = self.DeclareVectorInputPort("velocity_command", 3)
        self.DeclareVectorOutputPort(
            "reel_velocity_command", robot.num_cables, self._calc_reel_velocity_command,
            prerequisites_of_calc={self._p.ticket(), self._v.ticket()})

    def _calc_reel_velocity_command(self, context, output):
        output.SetFromVector(jacobian(self._robot, self._p.Eval(context)) @ self._v.Eval(context))
