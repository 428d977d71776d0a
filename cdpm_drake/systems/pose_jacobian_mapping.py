"""The Jacobian-mapping block of the full pose (controller.pose: full; beyond the paper's
Fig. 5): l_dot = J(p, R) [v; w] + K_l (l_d - l). Named jacobian_mapping in the diagram, as
the translating block it replaces."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.full_pose import WARMUP_TICKS, pose_rates_tick, sizes
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block, owned_geometry


class PoseRates(KernelSystem):
    """jacobian_mapping (pose: full): l_dot = J(p, R) [v; w] + K_l (l_d - l)."""


def build_pose_jacobian_mapping(builder, robot, *, length_gain, integral_gain, tension,
                                time_step, dead_band=0.0):
    """l_dot = J(p, R) [v; w] + K_l (l_d - l) (full_pose.pose_rates_tick). Inputs p_WP,
    R_WP, velocity_command, omega_command, R_WP_held, cable_lengths and, with `tension`,
    tension_command; outputs reel_velocity_command, commanded_lengths."""
    m = robot.num_cables
    s = sizes(m)
    reels, attachments = owned_geometry(robot)
    params = owned(np.array([length_gain, integral_gain, time_step,
                             robot.dynamics.EA if tension else 0.0, 1.0 if tension else 0.0,
                             dead_band, WARMUP_TICKS], dtype=float))
    example = np.zeros(s["rates_x"])
    example[:3] = robot.workspace.center
    example[3:12] = example[18:27] = np.eye(3).ravel()
    rates = bind(pose_rates_tick, reels, attachments, params, example,
                 np.empty(s["rates_out"]))

    # Without tension control the kernel ignores its tensions: the lengths fill the slot
    # (a Selector can only route inputs; a constant source would be a system more a tick).
    inputs = [("p_WP", 3), ("R_WP", 9), ("velocity_command", 3), ("omega_command", 3),
              ("R_WP_held", 9), ("cable_lengths", m)]
    route = build_kernel_block(
        builder, PoseRates(s["rates_x"], s["rates_out"], rates, (reels, attachments, params)),
        inputs=inputs + ([("tension_command", m)] if tension else [("tension_slot", m)]),
        memory=(s["rates_memory"], None),
        outputs=[("reel_velocity_command", 0, m), ("commanded_lengths", m, m)],
        memory_at=2 * m, time_step=time_step)
    return route
