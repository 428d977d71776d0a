"""The forward-kinematics block of the full pose (controller.pose: full; beyond the paper's
Fig. 5, whose platform only translates): the pose fitted to the stretch-corrected cable
lengths. Named forward_kinematics in the diagram, as the translating block it replaces."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.full_pose import (FK_INCONSISTENT, FK_NOT_SETTLED, FK_OK, START_ITERATIONS,
                                          pose_fk_tick, sizes)
from cdpm_drake.kernels.kinematics import KinematicsError
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block, owned_geometry


class PoseSolve(KernelSystem):
    """forward_kinematics (pose: full): the pose fitted to the stretch-corrected lengths."""


def build_pose_forward_kinematics(builder, robot, *, initial_position, max_residual, EA,
                                  time_step):
    """The pose (p, R) from the encoders' lengths corrected for the stretch under the tension
    estimate of the previous tick (EA <= 0: no correction; at the first tick the fit and the
    estimate are iterated to agreement, see full_pose.pose_fk_tick). Inputs cable_lengths
    (m), tension_estimate (m: N); outputs p_WP (3, m), R_WP (9: R_WB row-major), rpy_WP (3,
    rad), residual (m, m), tension_assumed (m, N: what the lengths were corrected for).
    Warm-started from the previous estimate (memory: [p, R, started], starting at the
    scenario's start, level). Lengths no pose explains within max_residual (m) raise
    KinematicsError, as the translating forward kinematics does."""
    m = robot.num_cables
    s = sizes(m)
    reels, attachments = owned_geometry(robot)
    d = robot.dynamics
    params = owned(np.array([EA, max_residual, d.mass, *d.handle, START_ITERATIONS],
                            dtype=float))
    max_residual = float(max_residual)
    example = np.zeros(s["fk_x"])
    example[:m] = np.linalg.norm(robot.reels - robot.workspace.center - robot.attachments,
                                 axis=1)
    example[2 * m:2 * m + 3] = robot.workspace.center
    example[2 * m + 3:2 * m + 12] = np.eye(3).ravel()
    example[2 * m + 12] = 1.0
    fk = bind(pose_fk_tick, reels, attachments, params, example, np.empty(s["fk_out"]))

    def failed(status, x, out):
        if status == FK_NOT_SETTLED:
            raise KinematicsError(f"full-pose forward kinematics of robot {robot.name!r} did "
                                  f"not settle from {x[2 * m:2 * m + 3].tolist()} m")
        if status == FK_INCONSISTENT:
            r = out[16:16 + m]
            i = int(np.argmax(np.abs(r)))
            raise KinematicsError(
                f"cable lengths are inconsistent with robot {robot.name!r}: the best-fit pose "
                f"(p = {np.round(out[:3], 6).tolist()} m, rpy = "
                f"{np.round(out[13:16], 5).tolist()} rad) leaves a residual of "
                f"{1000 * abs(r[i]):.3f} mm on cable {i + 1} (allowed "
                f"{1000 * max_residual:.3f} mm)")

    start = np.concatenate([np.asarray(initial_position, dtype=float), np.eye(3).ravel(),
                            [0.0]])
    build_kernel_block(
        builder, PoseSolve(s["fk_x"], s["fk_out"], fk, (reels, attachments, params),
                           ok=FK_OK, failed=failed),
        inputs=[("cable_lengths", m), ("tension_estimate", m)],
        memory=(s["fk_memory"], start),
        outputs=[("p_WP", 0, 3), ("R_WP", 3, 9), ("rpy_WP", 13, 3), ("residual", 16, m),
                 ("tension_assumed", 16 + m, m)],
        memory_at=0, time_step=time_step)
