"""The tension damping block (beyond the paper's Fig. 5, issue 31): between the Jacobian
mapping and the reels, each reel a damper in series with its cable, driven by the plant's
measured tensions (kernels/tension_damping.py derives the law and its gains)."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.tension_damping import (damping_gains, damping_params, damping_tick,
                                                platform_modes)
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block


class TensionDampingSolve(KernelSystem):
    """tension_damping: the mapping's reel command plus each reel's damping."""


def tension_damping_gains(robot, initial_position, *, time_step, sensor_lag, gain_scale):
    """(kd 1/s, low-pass time constant s) for the robot at its start position (m)."""
    d = robot.dynamics
    modes = platform_modes(robot.reels, robot.attachments, initial_position, d.EA, d.mass,
                           d.inertia)
    return damping_gains(modes, time_step=time_step, sensor_lag=sensor_lag,
                         drive_bandwidth=d.bandwidth, gain_scale=gain_scale)


def build_tension_damping(builder, robot, *, kd, tau, max_reel_speed, estimate, time_step,
                          loop_gain=0.0):
    """Inputs reel_velocity_desired (m) m/s (the mapping's reel_velocity_command),
    tension_measured (m) N, tension_expected (m) N (the controller's estimate; ignored
    without one, `estimate` False), cable_lengths (m) m; outputs reel_velocity_command (m)
    m/s (to the reels), damping (m) m/s (its part of it) and ringing_previous (m) N^2 (last tick's
    variance of the damped tension, for the tension target's floor). loop_gain: the mapping's
    length-loop gain 1/s, against which the damper's payout is held (damping_tick)."""
    m = robot.num_cables
    params = owned(damping_params(kd, tau, time_step=time_step, EA=robot.dynamics.EA,
                                  max_reel_speed=max_reel_speed, estimate=estimate,
                                  loop_gain=loop_gain))
    x = np.zeros(7 * m + 1)
    kernel = bind(damping_tick, params, x, np.empty(5 * m + 1))
    build_kernel_block(
        builder, TensionDampingSolve(7 * m + 1, 5 * m + 1, kernel, (params,)),
        inputs=[("reel_velocity_desired", m), ("tension_measured", m),
                ("tension_expected", m), ("cable_lengths", m)],
        memory=(3 * m + 1, None),
        outputs=[("reel_velocity_command", 0, m), ("damping", m, m)], memory_at=2 * m,
        time_step=time_step, memory_outputs=[("ringing_previous", 2 * m + 1, m)])
