"""The admittance 1 / (M s + C) of eqs. 5-7, per axis, at the control rate."""

import numpy as np
from pydrake.systems.analysis import DiscreteTimeApproximation
from pydrake.systems.framework import LeafSystem
from pydrake.systems.primitives import LinearSystem


def make_admittance(mass: float, damping: float, time_step: float):
    """A discrete LinearSystem: input F_d (3,) N, output platform velocity (3,) m/s.

    pydrake has no TransferFunction: 1/(M s + C) is x' = -C/M x + F/M, y = x, discretised by
    DiscreteTimeApproximation (exact zero-order hold), so a constant force gives
    v_k = F/C (1 - exp(-k T C / M)). The output has no direct feedthrough.

    .. pydrake_system::

        name: admittance
        input_ports:
        - u0 (F_d, N)
        output_ports:
        - y0 (velocity, m/s)
    """
    eye = np.eye(3)
    continuous = LinearSystem(A=-damping / mass * eye, B=eye / mass, C=eye, D=np.zeros((3, 3)))
    return DiscreteTimeApproximation(continuous, time_step)


class Admittance(LeafSystem):
    """The admittance of Fig. 5 with anti-windup: v_{k+1} = A_d u_k + B_d F_d,k, where A_d,
    B_d are `make_admittance`'s zero-order-hold matrices and u_k is the velocity actually
    commanded at tick k (after the safety limits).

    While no limit acts, u_k = v_k and this is exactly 1/(M s + C). When a limit holds the
    command below the admittance's velocity (speed cap, virtual wall), integrating from v_k
    would wind the state up towards F/C: the platform would then stick to the wall for a while
    after the operator pulls away, and coast twice as far after a release. Integrating from
    the commanded velocity (back-calculation) keeps the admittance where the platform is.
    The output is the state, so there is no direct feedthrough and no algebraic loop.

    .. pydrake_system::

        name: admittance
        input_ports:
        - F_d (N, base frame)
        - velocity_command (m/s, base frame; the limited command fed back)
        output_ports:
        - velocity (m/s, base frame)
    """

    def __init__(self, mass: float, damping: float, time_step: float):
        super().__init__()
        zoh = make_admittance(mass, damping, time_step)
        self._Ad, self._Bd = zoh.A().copy(), zoh.B().copy()
        self._F_d = self.DeclareVectorInputPort("F_d", 3)
        self._command = self.DeclareVectorInputPort("velocity_command", 3)
        self._velocity = self.DeclareDiscreteState(3)
        self.DeclareStateOutputPort("velocity", self._velocity)
        self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0, self._update_velocity)

    def _update_velocity(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._velocity).SetFromVector(
            self._Ad @ self._command.Eval(context) + self._Bd @ self._F_d.Eval(context))
