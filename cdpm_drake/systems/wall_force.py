"""Beyond the paper: a smooth repulsion from the workspace box, added to F_d."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.safety_limits import wall_force_into


class WorkspaceWallForce(LeafSystem):
    """F_wall (see `limits.wall_force`), so F_int cannot quietly park the platform on the
    virtual wall (the problem the paper's section 5.4 names).

    .. pydrake_system::

        name: wall_force
        input_ports:
        - p_WP (m, base frame)
        output_ports:
        - F_wall (N, base frame)
    """

    def __init__(self, *, lower, upper, margin, max_force):
        super().__init__()
        self._bounds = owned([np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)])
        self._margin, self._max_force = float(margin), float(max_force)
        self._p = self.DeclareVectorInputPort("p_WP", 3)
        # Compiled (or loaded) now, not in the first tick.
        wall = bind(wall_force_into, np.zeros(3), self._bounds, self._margin, self._max_force,
                    np.empty(3))
        # The tick's callback is a closure over locals, not a method reading self: attribute
        # lookups on a pybind LeafSystem cost ~0.2 us each (scripts/bench/count_instructions.py).
        bounds, margin, max_force, p = self._bounds, self._margin, self._max_force, self._p.Eval

        def calc_F_wall(context, output):
            wall(p(context), bounds, margin, max_force, output.get_mutable_value())

        self.DeclareVectorOutputPort("F_wall", 3, calc_F_wall,
                                     prerequisites_of_calc={self._p.ticket()})
