"""The kinetostatic-force block (beyond the paper's Fig. 5): the kinetostatic margin and its
gradient for the safety filter's barrier, and the felt cue F_kin added beside F_int."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned, owned_scratch
from cdpm_drake.kernels.kinetostatics import KIN_OUT, X_R, kinetostatic_tick, margin_scratch
from cdpm_drake.kernels.safety_filter import BARRIER_STATE
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block
from cdpm_drake.systems.wiring import unit_delay


class KinetostaticSolve(KernelSystem):
    """kinetostatic_force: the kinetostatic margin, its gradient and the felt cue."""


def build_kinetostatic_force(builder, robot, *, params, full_pose, time_step):
    """kinetostatics.kinetostatic_tick as a block. Inputs p_WP (3, m), F_H (3, N: taken a
    tick old, as the tension distribution takes it: a plant may sample the hand in the step
    that takes the reel command, which this block's result feeds), barrier_state_previous
    (7: the safety filter's memory, its barrier position and last command, for the pose and
    the look ahead), and for the full pose R_WP (9: the
    orientation held); outputs F_kin (3, N), kappa (1, N), kappa_gradient (3, N/m), t_c (1,
    N), t_star (1, N), status (1: 1 where no tension holds the pose at all), kappa_ray (1,
    m)."""
    reels, attachments = owned(robot.reels), owned(robot.attachments)
    par = owned(params)
    scratch = owned_scratch(margin_scratch(robot.num_cables))
    x_size = X_R + (9 if full_pose else 0)
    example = np.zeros(x_size)
    example[:3] = robot.workspace.center
    if full_pose:
        example[X_R:X_R + 9] = np.eye(3).ravel()
    solve = bind(kinetostatic_tick, reels, attachments, par, scratch, example,
                 np.empty(KIN_OUT))

    force = builder.AddNamedSystem("force_memory", unit_delay(3, time_step))
    inputs = ([("p_WP", 3), ("F_H_previous", 3), ("barrier_state_previous", BARRIER_STATE)]
              + ([("R_WP", 9)] if full_pose else []))
    route = build_kernel_block(
        builder, KinetostaticSolve(x_size, KIN_OUT, solve, (reels, attachments, par, scratch)),
        inputs=inputs, memory=None,
        outputs=[("F_kin", 0, 3), ("kappa", 3, 1), ("kappa_gradient", 4, 3), ("t_c", 7, 1),
                 ("t_star", 8, 1), ("status", 9, 1), ("kappa_ray", 10, 1)],
        memory_at=0, time_step=time_step, exported=False)
    builder.Connect(force.get_output_port(), route.GetInputPort("F_H_previous"))
    builder.ExportInput(force.get_input_port(), "F_H")
    for name, _ in inputs:
        if name != "F_H_previous":
            builder.ExportInput(route.GetInputPort(name), name)
