"""The safety-filter block (beyond the paper's Fig. 5), between the safety limits and the
Jacobian mapping: the twist closest to the commanded one that the barriers allow."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned, owned_scratch
from cdpm_drake.kernels.safety_filter import (BARRIER_STATE, OUT_MEMORY, OUT_V_D, filter_scratch,
                                              filter_sizes, filter_tick)
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block


class SafetyFilterSolve(KernelSystem):
    """safety_filter: the twist closest to the commanded one that the barriers allow."""


def build_safety_filter(builder, robot, *, d_min, params, full_pose, time_step):
    """safety_filter.filter_tick as a block. Inputs velocity_desired (3, m/s), p_WP (3, m),
    crossed (P, 0/1: the interference block's; absent for a robot without watched pairs),
    kappa (1, N), kappa_gradient (3, N/m), kappa_ray (1, m: the kinetostatic block's look
    ahead), and for the full pose omega_desired (3, rad/s) and R_WP (9: the orientation
    held); outputs velocity_command (3, m/s), omega_command (3, rad/s; the full pose),
    status (1), binding (1), pair_margin (1, m: the smallest watched pair's distance above its
    d_min), barriers (1), velocity_desired (3, m/s: the input, for the log),
    barrier_state_previous (7: its memory's [p_c, valid, v_prev], for the kinetostatic
    block). Its memory: the position its barriers were evaluated at, the twist it commanded
    last (for the acceleration limit) and that command's acceleration (for the give-way)."""
    P = robot.num_pairs
    s = filter_sizes(P, full_pose)
    reels, attachments = owned(robot.reels), owned(robot.attachments)
    i, j = robot.pair_index
    pi = np.ascontiguousarray(i, dtype=np.int64)
    pj = np.ascontiguousarray(j, dtype=np.int64)
    dmin = owned(np.asarray(d_min, dtype=float).reshape(P))
    bounds = owned(np.array([robot.workspace.lower, robot.workspace.upper]))
    par = owned(params)
    scratch = owned_scratch(filter_scratch(P, full_pose))  # its work arrays: none a tick
    example = np.zeros(s["x"])
    example[3:6] = robot.workspace.center
    if full_pose:
        example[14 + P:23 + P] = np.eye(3).ravel()
    solve = bind(filter_tick, reels, attachments, pi, pj, dmin, bounds, par, scratch, example,
                 np.empty(s["out"]))

    inputs = [("velocity_desired", 3), ("p_WP", 3)]
    if P:
        inputs.append(("crossed", P))
    inputs += [("kappa", 1), ("kappa_gradient", 3), ("kappa_ray", 1)]
    if full_pose:
        inputs += [("omega_desired", 3), ("R_WP", 9)]
    outputs = [("velocity_command", 0, 3)] + ([("omega_command", 3, 3)] if full_pose else [])
    build_kernel_block(
        builder, SafetyFilterSolve(s["x"], s["out"], solve,
                                   (reels, attachments, pi, pj, dmin, bounds, par, scratch)),
        inputs=inputs, memory=(s["memory"], None),
        outputs=outputs + [("status", 6, 1), ("binding", 7, 1), ("pair_margin", 8, 1),
                           ("barriers", 10, 1), ("velocity_desired", OUT_V_D, 3)],
        memory_at=OUT_MEMORY, time_step=time_step,
        memory_outputs=[("barrier_state_previous", 0, BARRIER_STATE)])
