"""The unseen-ringing block (beyond the paper): without a tension sensor, the swing the
platform's ringing may put on each cable, predicted from the command, and the cable it may
take below the floor while its estimate says it is taut (kernels/unseen_ringing.py derives
it). It warns; it changes no command."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned, owned_scratch
from cdpm_drake.kernels.full_pose import WARMUP_TICKS
from cdpm_drake.kernels.unseen_ringing import (ringing_params, ringing_scratch, ringing_sizes,
                                               ringing_tick)
from cdpm_drake.systems.kernel_system import (KERNEL_BLOCK_MAIN, KernelSystem,
                                              build_kernel_block)
from cdpm_drake.systems.wiring import FlatBlock


class UnseenRingingSolve(KernelSystem):
    """unseen_ringing: each cable's predicted swing and the cables it may take below the
    floor."""


def build_unseen_ringing(builder, robot, *, floor, time_step, warmup=WARMUP_TICKS):
    """Inputs p_WP (3, m), R_WP (9), velocity_command (3, m/s), omega_command (3, rad/s),
    F_H (3, N: the measured hand force), tension_estimate (m, N); outputs swing (m, N: the
    swing about the estimate the ringing the command put on each cable may reach) and warned
    (m: 1 for each cable whose estimate less its swing is below `floor` N, 0 otherwise),
    from `warmup` ticks on (the estimate is fitted at the first)."""
    m = robot.num_cables
    s = ringing_sizes(m)
    reels, attachments = owned(robot.reels), owned(robot.attachments)
    params = owned(ringing_params(robot.dynamics, time_step=time_step, floor=floor,
                                  warmup=warmup))
    scratch = owned_scratch(ringing_scratch(m))  # its work arrays: none a tick
    example = np.zeros(s["x"])
    example[0:3] = robot.workspace.center
    example[3:12] = np.eye(3).ravel()
    kernel = bind(ringing_tick, reels, attachments, params, scratch, example,
                  np.empty(s["out"]))
    build_kernel_block(
        builder, UnseenRingingSolve(s["x"], s["out"], kernel,
                                    (reels, attachments, params, scratch)),
        inputs=[("p_WP", 3), ("R_WP", 9), ("velocity_command", 3), ("omega_command", 3),
                ("F_H", 3), ("tension_estimate", m)],
        memory=(s["memory"], None), outputs=[("swing", 0, m), ("warned", m, m)],
        memory_at=s["memory_at"], time_step=time_step)


def add_unseen_ringing(builder, blocks, robot, *, floor, p_WP, R_WP, velocity_command,
                       omega_command, F_H, T, warmup=WARMUP_TICKS):
    """The block as a flat block of the controller's diagram, on the estimate of the tension
    distribution block in `blocks`; floor: controller.tension_floor (N). It warns only: the
    target's floor raised to its swing slackened more cables than it saved (the adversarial
    benchmark's ramped hands without a sensor, slack ticks holdable in [2, 100] N: 114 on 5
    hands, for 80 on 3)."""
    block = blocks["unseen_ringing"] = FlatBlock(
        builder, "unseen_ringing", KERNEL_BLOCK_MAIN, lambda b: build_unseen_ringing(
            b, robot, floor=float(floor), time_step=T, warmup=warmup))
    for name, port in (("p_WP", p_WP), ("R_WP", R_WP), ("velocity_command", velocity_command),
                       ("omega_command", omega_command), ("F_H", F_H),
                       ("tension_estimate",
                        blocks["tension_distribution"].GetOutputPort("tension_estimate"))):
        block.connect_input(port, name)
