"""The admittance 1 / (M s + C) of eqs. 5-7, per axis, at the control rate."""

import numpy as np
from pydrake.systems.analysis import DiscreteTimeApproximation
from pydrake.systems.primitives import LinearSystem


def make_admittance(mass: float, damping: float, time_step: float):
    """A discrete LinearSystem: input F_d (3,) N, output platform velocity (3,) m/s.

    pydrake has no TransferFunction: 1/(M s + C) is x' = -C/M x + F/M, y = x, discretised by
    DiscreteTimeApproximation (exact zero-order hold), so a constant force gives
    v_k = F/C (1 - exp(-k T C / M)). The output has no direct feedthrough, which breaks the
    Fig. 5 loop without an algebraic loop.

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
