"""The interference-force block of the full pose (controller.pose: full; beyond the paper's
Fig. 5): section 4's interference on the cables of the estimated pose. Named
interference_force in the diagram, as the translating block it replaces."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.full_pose import interference_posed_tick
from cdpm_drake.kernels.interference import result_layout
from cdpm_drake.systems.interference_force import OUTPUTS
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block, owned_geometry


class PosedInterference(KernelSystem):
    """interference_force (pose: full): the interference tick on the cables of the pose."""


def build_posed_interference_force(builder, robot, params, *, time_step):
    """The interference block (systems.interference_force) on the cables of the estimated
    pose: inputs p_WP and R_WP; the same outputs."""
    P = robot.num_pairs
    layout = result_layout(P)
    reels, attachments = owned_geometry(robot)
    i, j = robot.pair_index
    pi = np.ascontiguousarray(i, dtype=np.int64)
    pj = np.ascontiguousarray(j, dtype=np.int64)
    par = owned(params.packed)
    floor, F_max = float(params.gradient_floor), float(params.F_max)
    geo = owned(np.zeros((P, 12)))
    example = np.zeros(12 + P)
    example[:3] = robot.workspace.center
    example[3:12] = np.eye(3).ravel()
    solve = bind(interference_posed_tick, reels, attachments, pi, pj, par, floor, F_max,
                 example, geo, np.empty(3 + 13 * P))

    fields = dict(zip(OUTPUTS, ("force", "distance", "active", "crossed", "side")))
    side_at = layout["side"][0]
    build_kernel_block(
        builder, PosedInterference(12 + P, 3 + 13 * P, solve,
                                   (reels, attachments, pi, pj, par, floor, F_max), (geo,)),
        inputs=[("p_WP", 3), ("R_WP", 9)], memory=(P, None),
        outputs=[(name, layout[field][0], layout[field][1] - layout[field][0])
                 for name, field in fields.items() if name != "side"],
        memory_at=side_at, time_step=time_step)
