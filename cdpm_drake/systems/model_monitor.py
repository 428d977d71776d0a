"""The model-monitor block (beyond the paper's Fig. 5): slack cables, lengths that no
longer fit the estimated pose, and hand forces no tension holds, raised as ModelFault."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned, owned_scratch
from cdpm_drake.kernels.kinetostatics import margin_scratch
from cdpm_drake.kernels.model_monitor import (M_MEASURED, M_OVERLOAD, ModelFault, OK, SLACK,
                                              fault_message, monitor_sizes, monitor_tick)
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block


class ModelMonitorSolve(KernelSystem):
    """model_monitor: slack cables, lengths that no longer fit, unholdable hand forces."""


def build_model_monitor(builder, robot, *, params, full_pose, estimate, time_step,
                        measured=False, reconciling=False):
    """model_monitor.monitor_tick as a block; it raises ModelFault (naming the cable, the
    reason and the numbers) when a condition has lasted its ticks. Inputs cable_lengths (m,
    m), p_WP (3, m), F_H (3, N), and for the full pose R_WP (9), with a tension estimate
    tension_estimate (m, N); outputs status (1), cable (1, 1-based, 0 none), t_star (1, N: at
    the estimated pose with the measured hand force), residual (m, m: each cable's length
    residual at the estimated pose). measured: an input tension_measured (m, N; NaN where
    a cable has no reading), read where params says (model_monitor.monitor_params).
    reconciling: an input reconciled (1: the encoder zero's flag; params must say so too)."""
    m = robot.num_cables
    s = monitor_sizes(m, full_pose, estimate, measured, reconciling)
    measured_at = s["x"] - s["memory"] - m - (1 if reconciling else 0)
    reels, attachments = owned(robot.reels), owned(robot.attachments)
    par = owned(params)
    scratch = owned_scratch(margin_scratch(m))
    example = np.zeros(s["x"])
    example[:m] = np.linalg.norm(robot.reels - robot.workspace.center - robot.attachments,
                                 axis=1)
    example[m:m + 3] = robot.workspace.center
    if full_pose:
        example[m + 6:m + 15] = np.eye(3).ravel()
    check = bind(monitor_tick, reels, attachments, par, scratch, example, np.empty(s["out"]))
    at = s["memory_at"]

    def failed(status, x, out):
        cable = int(out[1])
        # A slack cable's value is its measured tension where the monitor reads slack from
        # them (an overload alone wires them in too).
        reading = (measured and params[M_MEASURED] > 0 and status == SLACK
                   and np.isfinite(x[measured_at + cable - 1]))
        raise ModelFault(fault_message(
            int(status), cable, float(out[2]), ticks=int(out[at + int(status) - 1]),
            time_step=time_step, estimate=estimate, p=x[m:m + 3], F_H=x[m + 3:m + 6],
            measured=bool(reading), overload=float(params[M_OVERLOAD])))

    inputs = [("cable_lengths", m), ("p_WP", 3), ("F_H", 3)]
    if full_pose:
        inputs.append(("R_WP", 9))
    if estimate:
        inputs.append(("tension_estimate", m))
    if measured:
        inputs.append(("tension_measured", m))
    if reconciling:
        inputs.append(("reconciled", 1))
    build_kernel_block(
        builder, ModelMonitorSolve(s["x"], s["out"], check, (reels, attachments, par, scratch),
                                   ok=OK, failed=failed),
        inputs=inputs, memory=(s["memory"], None),
        outputs=[("status", 0, 1), ("cable", 1, 1), ("t_star", 3, 1), ("residual", 4, m)],
        memory_at=at, time_step=time_step)
