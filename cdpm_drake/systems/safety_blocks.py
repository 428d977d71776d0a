"""The blocks that make the promise hard (beyond the paper's Fig. 5): the safety filter
between the limits and the Jacobian mapping, the kinetostatic limit (its margin for the
filter and its felt cue beside F_int), and the model monitor.

Each is built like the full-pose blocks (pose_blocks.build_kernel_block): one stateless
Python LeafSystem calling its compiled kernel once per tick on one stacked input, its memory a
C++ one-tick delay, its inputs stacked and its result split by one C++ Selector.
"""

import numpy as np

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.kinetostatics import KIN_OUT, X_R, kinetostatic_tick, margin_scratch
from cdpm_drake.kernels.model_monitor import ModelFault, OK, fault_message, monitor_sizes, monitor_tick
from cdpm_drake.kernels.safety_filter import BARRIER_STATE, OUT_MEMORY, OUT_V_D, filter_sizes, filter_tick
from cdpm_drake.systems.wiring import unit_delay
from cdpm_drake.systems.pose_blocks import KernelSystem, build_kernel_block

# The system a flat build (FlatBlock) names after the block, for every block here.
MAIN = "solve"


class SafetyFilterSolve(KernelSystem):
    """safety_filter: the twist closest to the commanded one that the barriers allow."""


class KinetostaticSolve(KernelSystem):
    """kinetostatic_force: the kinetostatic margin, its gradient and the felt cue."""


class ModelMonitorSolve(KernelSystem):
    """model_monitor: slack cables, lengths that no longer fit, unholdable hand forces."""


def build_safety_filter(builder, robot, *, d_min, params, full_pose, time_step):
    """safety_filter.filter_tick as a block. Inputs velocity_desired (3, m/s), p_WP (3, m),
    crossed (P, 0/1: the interference block's; absent for a robot without watched pairs),
    kappa (1, N), kappa_gradient (3, N/m), kappa_ray (1, m: the kinetostatic block's look
    ahead), and for the full pose omega_desired (3, rad/s) and R_WP (9: the orientation
    held); outputs velocity_command (3, m/s), omega_command (3, rad/s; the full pose),
    status (1), binding (1), pair_margin (1, m: the smallest watched pair's distance above its
    d_min), barriers (1), velocity_desired (3, m/s: the input, for the log),
    barrier_state_previous (7: its memory's [p_c, valid, v_prev], for the kinetostatic
    block). Its memory: the position its barriers were evaluated at and the twist it
    commanded last (for the acceleration limit)."""
    P = robot.num_pairs
    s = filter_sizes(P, full_pose)
    reels, attachments = owned(robot.reels), owned(robot.attachments)
    i, j = robot.pair_index
    pi = np.ascontiguousarray(i, dtype=np.int64)
    pj = np.ascontiguousarray(j, dtype=np.int64)
    dmin = owned(np.asarray(d_min, dtype=float).reshape(P))
    bounds = owned(np.array([robot.workspace.lower, robot.workspace.upper]))
    par = owned(params)
    example = np.zeros(s["x"])
    example[3:6] = robot.workspace.center
    if full_pose:
        example[14 + P:23 + P] = np.eye(3).ravel()
    solve = bind(filter_tick, reels, attachments, pi, pj, dmin, bounds, par, example,
                 np.empty(s["out"]))

    def tick(x, out):
        solve(reels, attachments, pi, pj, dmin, bounds, par, x, out)

    inputs = [("velocity_desired", 3), ("p_WP", 3)]
    if P:
        inputs.append(("crossed", P))
    inputs += [("kappa", 1), ("kappa_gradient", 3), ("kappa_ray", 1)]
    if full_pose:
        inputs += [("omega_desired", 3), ("R_WP", 9)]
    outputs = [("velocity_command", 0, 3)] + ([("omega_command", 3, 3)] if full_pose else [])
    build_kernel_block(
        builder, SafetyFilterSolve(s["x"], s["out"], tick), inputs=inputs,
        memory=(s["memory"], None),
        outputs=outputs + [("status", 6, 1), ("binding", 7, 1), ("pair_margin", 8, 1),
                           ("barriers", 10, 1), ("velocity_desired", OUT_V_D, 3)],
        memory_at=OUT_MEMORY, time_step=time_step,
        memory_outputs=[("barrier_state_previous", 0, BARRIER_STATE)])


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
    scratch = margin_scratch(robot.num_cables)
    x_size = X_R + (9 if full_pose else 0)
    example = np.zeros(x_size)
    example[:3] = robot.workspace.center
    if full_pose:
        example[X_R:X_R + 9] = np.eye(3).ravel()
    solve = bind(kinetostatic_tick, reels, attachments, par, scratch, example,
                 np.empty(KIN_OUT))

    def tick(x, out):
        solve(reels, attachments, par, scratch, x, out)

    force = builder.AddNamedSystem("force_memory", unit_delay(3, time_step))
    inputs = ([("p_WP", 3), ("F_H_previous", 3), ("barrier_state_previous", BARRIER_STATE)]
              + ([("R_WP", 9)] if full_pose else []))
    route = build_kernel_block(
        builder, KinetostaticSolve(x_size, KIN_OUT, tick), inputs=inputs, memory=None,
        outputs=[("F_kin", 0, 3), ("kappa", 3, 1), ("kappa_gradient", 4, 3), ("t_c", 7, 1),
                 ("t_star", 8, 1), ("status", 9, 1), ("kappa_ray", 10, 1)],
        memory_at=0, time_step=time_step, exported=False)
    builder.Connect(force.get_output_port(), route.GetInputPort("F_H_previous"))
    builder.ExportInput(force.get_input_port(), "F_H")
    for name, _ in inputs:
        if name != "F_H_previous":
            builder.ExportInput(route.GetInputPort(name), name)


def build_model_monitor(builder, robot, *, params, full_pose, estimate, time_step):
    """model_monitor.monitor_tick as a block; it raises ModelFault (naming the cable, the
    reason and the numbers) when a condition has lasted its ticks. Inputs cable_lengths (m,
    m), p_WP (3, m), F_H (3, N), and for the full pose R_WP (9), with a tension estimate
    tension_estimate (m, N); outputs status (1), cable (1, 1-based, 0 none), t_star (1, N: at
    the estimated pose with the measured hand force), residual (m, m: each cable's length
    residual at the estimated pose)."""
    m = robot.num_cables
    s = monitor_sizes(m, full_pose, estimate)
    reels, attachments = owned(robot.reels), owned(robot.attachments)
    par = owned(params)
    scratch = margin_scratch(m)
    example = np.zeros(s["x"])
    example[:m] = np.linalg.norm(robot.reels - robot.workspace.center - robot.attachments,
                                 axis=1)
    example[m:m + 3] = robot.workspace.center
    if full_pose:
        example[m + 6:m + 15] = np.eye(3).ravel()
    check = bind(monitor_tick, reels, attachments, par, scratch, example, np.empty(s["out"]))
    at = s["memory_at"]

    def tick(x, out):
        status = check(reels, attachments, par, scratch, x, out)
        if status != OK:
            raise ModelFault(fault_message(
                int(status), int(out[1]), float(out[2]), ticks=int(out[at + int(status) - 1]),
                time_step=time_step, estimate=estimate, p=x[m:m + 3], F_H=x[m + 3:m + 6]))

    inputs = [("cable_lengths", m), ("p_WP", 3), ("F_H", 3)]
    if full_pose:
        inputs.append(("R_WP", 9))
    if estimate:
        inputs.append(("tension_estimate", m))
    build_kernel_block(
        builder, ModelMonitorSolve(s["x"], s["out"], tick), inputs=inputs,
        memory=(s["memory"], None),
        outputs=[("status", 0, 1), ("cable", 1, 1), ("t_star", 3, 1), ("residual", 4, m)],
        memory_at=at, time_step=time_step)
