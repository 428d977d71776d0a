"""The tension-distribution block of the full pose with tension control (beyond the paper's
Fig. 5): the target tensions at the estimated pose, and the tension estimate."""

import numpy as np

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.full_pose import WARMUP_TICKS, sizes, tension_tick
from cdpm_drake.systems.kernel_system import KernelSystem, build_kernel_block, owned_geometry
from cdpm_drake.systems.wiring import unit_delay


def tension_path_params(robot, time_step, position=None, filter_window=1) -> dict:
    """build_tension_distribution's lead, rate_time, stretch_speed, settle_time and modes (at
    `position`, m; default the workspace's centre) and hand_lag (the force sensor's sliding
    average of `filter_window` samples), derived from the robot (kernels/tension_path.py)."""
    from cdpm_drake.kernels import tension_path

    d, limits = robot.dynamics, robot.limits
    p = robot.workspace.center if position is None else position
    return {"lead": tension_path.lead_time(time_step, d.bandwidth),
            "rate_time": tension_path.rate_time(d.bandwidth),
            "stretch_speed": tension_path.stretch_speed(limits.max_reel_speed,
                                                        limits.max_velocity),
            "settle_time": tension_path.settle_time(robot, np.asarray(p, dtype=float)),
            "hand_lag": tension_path.hand_lag(filter_window, time_step),
            "modes": tension_path.modal_params(robot, np.asarray(p, dtype=float))}


class TensionSolve(KernelSystem):
    """tension_distribution: the target tensions at the pose, and their estimate."""


def build_tension_distribution(builder, robot, *, min_tension, max_tension, tension_floor,
                               slew_rate, initial_tensions, time_step, fall_rate=None,
                               warmup_ticks=WARMUP_TICKS, ringing_factor=0.0, lead=0.0,
                               rate_time=0.0, stretch_speed=0.0, settle_time=0.0,
                               hand_lag=0.0, modes=None):
    """The tension estimate and the target tensions at the estimated pose
    (full_pose.tension_tick). Inputs p_WP, R_WP, F_H (N), velocity_command (m/s),
    residual (m), cable_lengths (m), tension_assumed (N: the forward kinematics'); outputs
    tension_command (m, N: what the Jacobian block stretches the cables for: the target, at
    most slew_rate N/s from the last), tension_estimate (m, N), tension_target (m, N: the
    distribution, never below tension_floor), t_star (N: the largest achievable minimum
    tension at the pose, inf where an internal force raises every tension), status (0: the
    floor holds, 1: lowered, 2: W rank-deficient, nothing chosen, 3: the ceiling exceeded
    for the hard floor, 4: the hard floor unreachable, weak cables raised to it), cable (the
    1-based cable the status names: the weakest for 1, the one above the ceiling for 3, the
    one raised most for 2 and 4; 0: none), and tension_estimate_previous (the memory's, for
    the forward kinematics). The command follows the estimate for `warmup_ticks`, then
    slews from it. Input tension_ringing (m, N^2: the measured tensions' variance about the
    estimate; with ringing_factor 0 any m-vector, ignored): the hard floor is at least
    ringing_factor standard deviations of the largest. lead (s): the target is the
    distribution for the hand force led by its rate (low-passed over rate_time, s) times
    lead; stretch_speed (m/s, 0: none): each cable's internal force rises at most EA / L0
    times it; settle_time (s, 0: off), hand_lag (s) and modes (42, the platform's:
    tension_path.modal_params; None: none): the status names a cable the hand's part the
    platform has not settled to may ring slack (full_pose.tension_tick; their values:
    kernels/tension_path.py)."""
    m = robot.num_cables
    s = sizes(m)
    d = robot.dynamics
    reels, attachments = owned_geometry(robot)
    fall_rate = slew_rate if fall_rate is None else fall_rate
    params = owned(np.array([d.mass, *d.handle, d.EA, float(min_tension), float(max_tension),
                             float(time_step), float(slew_rate), float(warmup_ticks),
                             float(tension_floor), float(fall_rate),
                             float(ringing_factor), float(lead), float(rate_time),
                             float(stretch_speed), float(settle_time), float(hand_lag),
                             *(np.zeros(42) if modes is None else modes)]))
    example = np.zeros(s["tension_x"])
    example[:3] = robot.workspace.center
    example[3:12] = np.eye(3).ravel()
    example[18 + m:18 + 2 * m] = 1.0
    solve = bind(tension_tick, reels, attachments, params, example,
                 np.empty(s["tension_out"]))

    start = np.concatenate([np.asarray(initial_tensions, dtype=float), np.zeros(13 + m)])
    # The hand force of the previous tick: a plant may compute its force sample in the same
    # step as it takes the reel command (the dynamic plant does), and this block's result
    # feeds that command, so the force is taken a tick old (2 ms, inside the sensor's
    # filter) rather than through an algebraic loop.
    force = builder.AddNamedSystem("force_memory", unit_delay(3, time_step))
    names = ("p_WP", "R_WP", "velocity_command", "residual", "cable_lengths",
             "tension_assumed", "tension_ringing")
    route = build_kernel_block(
        builder, TensionSolve(s["tension_x"], s["tension_out"], solve,
                              (reels, attachments, params)),
        inputs=[("p_WP", 3), ("R_WP", 9), ("F_H_previous", 3), ("velocity_command", 3),
                ("residual", m), ("cable_lengths", m), ("tension_assumed", m),
                ("tension_ringing", m)],
        memory=(s["tension_memory"], start),
        outputs=[("tension_command", 0, m), ("tension_estimate", m, m),
                 ("tension_target", 2 * m, m), ("t_star", 3 * m, 1),
                 ("status", 3 * m + 1, 1), ("cable", 3 * m + 2, 1)],
        memory_at=3 * m + 3, time_step=time_step,
        memory_outputs=[("tension_estimate_previous", 0, m)], exported=False)
    builder.Connect(force.get_output_port(), route.GetInputPort("F_H_previous"))
    builder.ExportInput(force.get_input_port(), "F_H")
    for name in names:
        builder.ExportInput(route.GetInputPort(name), name)
