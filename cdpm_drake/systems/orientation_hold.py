"""The orientation-hold block of the full pose (beyond the paper's Fig. 5): the angular
velocity back to the orientation held."""

import numpy as np

from cdpm_drake.kernels.call import bind
from cdpm_drake.kernels.full_pose import orientation_tick, sizes
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block


class OrientationSolve(KernelSystem):
    """orientation_hold: the angular velocity back to the orientation held."""


def build_orientation_hold(builder, *, gain, time_step):
    """w = gain log(R_ref R^T): the angular velocity (rad/s, base frame) back to the
    orientation of the first tick. Input R_WP (9); outputs omega_command (3), R_WP_held (9)."""
    s = sizes(7)
    gain = float(gain)
    example = np.zeros(s["orientation_x"])
    example[:9] = np.eye(3).ravel()
    # The orientation held is the first tick's estimate (its fit of pose and pretension is
    # iterated to agreement, pose_fk_tick), the platform's at rest as the run starts: an
    # orientation latched later (after the tensions' warm-up) took in the tilt of a hand that
    # pushed from the start, ~1 deg under 40 N, and held the platform there.
    warmup = 1.0
    hold = bind(orientation_tick, gain, warmup, example, np.empty(s["orientation_out"]))

    build_kernel_block(
        builder, OrientationSolve(s["orientation_x"], s["orientation_out"], hold,
                                  (gain, warmup)),
        inputs=[("R_WP", 9)], memory=(s["orientation_memory"], None),
        outputs=[("omega_command", 0, 3), ("R_WP_held", 3, 9)], memory_at=12,
        time_step=time_step)
