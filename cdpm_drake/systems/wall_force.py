"""Beyond the paper: a smooth repulsion from the workspace box, added to F_d."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.safety_limits import wall_force_into
from cdpm_drake.systems.kernel_system import KernelSystem


class WorkspaceWallForce(KernelSystem):
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
        bounds = owned([np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)])
        margin, max_force = float(margin), float(max_force)
        # Compiled (or loaded) now, not in the first tick.
        wall = bind(wall_force_into, np.zeros(3), bounds, margin, max_force, np.empty(3))
        super().__init__(3, 3, wall, after=(bounds, margin, max_force), input_name="p_WP",
                         output_name="F_wall")
