"""Helpers the blocks share: a one-tick delay in C++ to hold a block's state, and building a
block as a named sub-diagram."""

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LinearSystem, ZeroOrderHold


def unit_delay(size: int, time_step: float, initial=None):
    """x_{k+1} = u_k, y_k = x_k at period time_step (s), starting at `initial` (default 0).

    A C++ ZeroOrderHold where the start is zero (its default); otherwise a discrete
    LinearSystem (A = 0, B = C = I) whose default state is `initial`, so a default context,
    a cloned context and SetDefaultContext all start there."""
    x0 = np.zeros(size) if initial is None else np.asarray(initial, dtype=float)
    if not np.any(x0):
        return ZeroOrderHold(time_step, size)
    eye = np.eye(size)
    delay = LinearSystem(A=np.zeros((size, size)), B=eye, C=eye, D=np.zeros((size, size)),
                         time_period=time_step)
    delay.configure_default_state(x0)
    return delay


def sub_diagram(target, build) -> None:
    """Build `target` (a Diagram subclass being constructed) from `build(builder)`."""
    builder = DiagramBuilder()
    build(builder)
    builder.BuildInto(target)
