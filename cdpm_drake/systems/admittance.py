"""The admittance 1 / (M s + C) of eqs. 5-7, per axis, at the control rate."""

import numpy as np
from pydrake.systems.analysis import DiscreteTimeApproximation
from pydrake.systems.framework import Diagram
from pydrake.systems.primitives import LinearSystem

from cdpm_drake.systems.wiring import stack, sub_diagram


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


def make_anti_windup_admittance(mass: float, damping: float, time_step: float):
    """The discrete LinearSystem v_{k+1} = A_d u_k + B_d F_d,k, y = v, input [F_d; u] (6,):
    `make_admittance`'s zero-order-hold matrices, integrating from the commanded u_k."""
    zoh = make_admittance(mass, damping, time_step)
    return LinearSystem(A=np.zeros((3, 3)), B=np.hstack([zoh.B(), zoh.A()]), C=np.eye(3),
                        D=np.zeros((3, 6)), time_period=time_step)


class AdmittanceSystem(Diagram):
    """The admittance of Fig. 5 with anti-windup: v_{k+1} = A_d u_k + B_d F_d,k, where A_d,
    B_d are `make_admittance`'s zero-order-hold matrices and u_k is the velocity actually
    commanded at tick k (after the safety limits). All C++: a Selector and a discrete
    LinearSystem.

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
        sub_diagram(self, lambda builder: build_admittance(builder, mass, damping, time_step))


# The system a flat build (FlatBlock) names after the block.
ADMITTANCE_MAIN = "dynamics"


def build_admittance(builder, mass: float, damping: float, time_step: float):
    """AdmittanceSystem's systems and exported ports, into `builder` (a DiagramBuilder or a
    FlatBlock)."""
    inputs = builder.AddNamedSystem("inputs", stack([3, 3]))
    dynamics = builder.AddNamedSystem("dynamics", make_anti_windup_admittance(
        mass, damping, time_step))
    builder.Connect(inputs.get_output_port(), dynamics.get_input_port())
    builder.ExportInput(inputs.get_input_port(0), "F_d")
    builder.ExportInput(inputs.get_input_port(1), "velocity_command")
    builder.ExportOutput(dynamics.get_output_port(), "velocity")
