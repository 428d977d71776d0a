"""The full-pose controller's blocks (controller.pose: full; beyond the paper's Fig. 5, whose
platform only translates): forward kinematics of the pose, the tension distribution, the
orientation hold, and the pose versions of the Jacobian mapping and the interference force.

Each block is built like the paper's blocks (systems/__init__.py): one stateless Python
LeafSystem calling its compiled kernel (pose_control.py) once per tick on one stacked input,
its memory a C++ one-tick delay, its inputs stacked and its result split by one C++ Selector.
`build_kernel_block` is that shape, once.
"""

import numpy as np
from pydrake.systems.framework import LeafSystem

from cdpm_drake.kernels.interference import result_layout
from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.kinematics import KinematicsError
from cdpm_drake.kernels.full_pose import (FK_INCONSISTENT, FK_NOT_SETTLED, START_ITERATIONS, WARMUP_TICKS,
                            interference_posed_tick,
                            orientation_tick, pose_fk_tick, pose_rates_tick, sizes,
                            tension_tick)
from cdpm_drake.systems.wiring import note_piece, unit_delay, wiring


class KernelSystem(LeafSystem):
    """result = tick(inputs): one compiled call per tick; stateless.

    .. pydrake_system::

        name: solve
        input_ports:
        - inputs (the block's inputs and memory, stacked)
        output_ports:
        - result (the block's outputs and next memory)
    """

    def __init__(self, x_size: int, out_size: int, tick):
        super().__init__()
        self._inputs = self.DeclareVectorInputPort("inputs", x_size)
        inputs = self._inputs.Eval

        def calc_result(context, output):
            tick(inputs(context), output.get_mutable_value())

        self.DeclareVectorOutputPort("result", out_size, calc_result,
                                     prerequisites_of_calc={self._inputs.ticket()})


class PoseSolve(KernelSystem):
    """forward_kinematics (pose: full): the pose fitted to the stretch-corrected lengths."""


class TensionSolve(KernelSystem):
    """tension_distribution: the target tensions at the pose, and their estimate."""


class OrientationSolve(KernelSystem):
    """orientation_hold: the angular velocity back to the orientation held."""


class PoseRates(KernelSystem):
    """jacobian_mapping (pose: full): l_dot = J(p, R) [v; w] + K_l (l_d - l)."""


class PosedInterference(KernelSystem):
    """interference_force (pose: full): the interference tick on the cables of the pose."""


def build_kernel_block(builder, system, *, inputs, memory, outputs, memory_at, time_step,
                       memory_outputs=(), exported=True):
    """Add `system` (a KernelSystem) as "solve", a one-tick delay "memory" (`memory`: its size
    and initial value, None for zeros; or None for a block without memory) and a Selector
    "wiring" to `builder` (a DiagramBuilder or a FlatBlock). inputs: [(port name, size)]
    exported, stacked in this order and then the memory; outputs: [(port name, offset, size)]
    pieces of the result exported; the next memory is the result from `memory_at` on;
    memory_outputs: [(port name, offset, size)] pieces of the memory (last tick's) exported.
    Returns the Selector (the caller connects its inputs itself with exported=False)."""
    solve = builder.AddNamedSystem("solve", system)
    result_size = system.get_output_port(0).size()
    ins = list(inputs)
    pieces = [(name, 0, size) for name, size in inputs]
    outs = [(name, [("result", offset, size)]) for name, offset, size in outputs]
    if memory is not None:
        size, initial = memory
        ins.append(("memory_previous", size))
        pieces.append(("memory_previous", 0, size))
        outs.append(("memory", [("result", memory_at, size)]))
        outs += [(name, [("memory_previous", offset, count)])
                 for name, offset, count in memory_outputs]
    ins.append(("result", result_size))
    route = builder.AddNamedSystem("wiring", wiring(ins, [("inputs", pieces)] + outs))
    result = solve.GetOutputPort("result")
    builder.Connect(result, route.GetInputPort("result"))
    builder.Connect(route.GetOutputPort("inputs"), solve.GetInputPort("inputs"))
    if memory is not None:
        delay = builder.AddNamedSystem("memory", unit_delay(memory[0], time_step, memory[1]))
        builder.Connect(route.GetOutputPort("memory"), delay.get_input_port())
        builder.Connect(delay.get_output_port(), route.GetInputPort("memory_previous"))
    if exported:  # else the caller exports (or connects) the inputs itself
        for name, _ in inputs:
            builder.ExportInput(route.GetInputPort(name), name)
    for name, offset, _ in outputs:
        builder.ExportOutput(route.GetOutputPort(name), name)
        note_piece(builder, name, result, offset)
    for name, _, _ in memory_outputs:
        builder.ExportOutput(route.GetOutputPort(name), name)
    return route


def _constants(robot):
    return (owned(robot.reels), owned(robot.attachments))


# --- forward kinematics of the pose -------------------------------------------------------------


# The system a flat build (FlatBlock) names after the block, for every block here.
MAIN = "solve"


def build_pose_forward_kinematics(builder, robot, *, initial_position, max_residual, EA,
                                  time_step):
    """The pose (p, R) from the encoders' lengths corrected for the stretch under the tension
    estimate of the previous tick (EA <= 0: no correction; at the first tick the fit and the
    estimate are iterated to agreement, see pose_control.pose_fk_tick). Inputs cable_lengths
    (m), tension_estimate (m: N); outputs p_WP (3, m), R_WP (9: R_WB row-major), rpy_WP (3,
    rad), residual (m, m), tension_assumed (m, N: what the lengths were corrected for).
    Warm-started from the previous estimate (memory: [p, R, started], starting at the
    scenario's start, level). Lengths no pose explains within max_residual (m) raise
    KinematicsError, as the translating forward kinematics does."""
    m = robot.num_cables
    s = sizes(m)
    reels, attachments = _constants(robot)
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

    def tick(x, out):
        status = fk(reels, attachments, params, x, out)
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
        builder, PoseSolve(s["fk_x"], s["fk_out"], tick),
        inputs=[("cable_lengths", m), ("tension_estimate", m)],
        memory=(s["fk_memory"], start),
        outputs=[("p_WP", 0, 3), ("R_WP", 3, 9), ("rpy_WP", 13, 3), ("residual", 16, m),
                 ("tension_assumed", 16 + m, m)],
        memory_at=0, time_step=time_step)


# --- tension distribution ----------------------------------------------------------------------


def build_tension_distribution(builder, robot, *, min_tension, max_tension, tension_floor,
                               slew_rate, initial_tensions, time_step, fall_rate=None):
    """The tension estimate and the target tensions at the estimated pose
    (pose_control.tension_tick). Inputs p_WP, R_WP, F_H (N), velocity_command (m/s),
    residual (m), cable_lengths (m), tension_assumed (N: the forward kinematics'); outputs
    tension_command (m, N: what the Jacobian block stretches the cables for: the target, at
    most slew_rate N/s from the last), tension_estimate (m, N), tension_target (m, N: the
    distribution, never below tension_floor), t_star (N: the largest achievable minimum
    tension at the pose, inf where an internal force raises every tension), status (0: the
    floor holds, 1: lowered, 2: W rank-deficient, nothing chosen, 3: the ceiling exceeded
    for the hard floor, 4: the hard floor unreachable, weak cables raised to it), cable (the
    1-based cable the status names: the weakest for 1, the one above the ceiling for 3, the
    one raised most for 2 and 4; 0: none), and tension_estimate_previous (the memory's, for
    the forward kinematics)."""
    m = robot.num_cables
    s = sizes(m)
    d = robot.dynamics
    reels, attachments = _constants(robot)
    fall_rate = slew_rate if fall_rate is None else fall_rate
    params = owned(np.array([d.mass, *d.handle, d.EA, float(min_tension), float(max_tension),
                             float(time_step), float(slew_rate), float(WARMUP_TICKS),
                             float(tension_floor), float(fall_rate)]))
    example = np.zeros(s["tension_x"])
    example[:3] = robot.workspace.center
    example[3:12] = np.eye(3).ravel()
    example[18 + m:18 + 2 * m] = 1.0
    solve = bind(tension_tick, reels, attachments, params, example,
                 np.empty(s["tension_out"]))

    def tick(x, out):
        solve(reels, attachments, params, x, out)

    start = np.concatenate([np.asarray(initial_tensions, dtype=float), np.zeros(4 + m)])
    # The hand force of the previous tick: a plant may compute its force sample in the same
    # step as it takes the reel command (the dynamic plant does), and this block's result
    # feeds that command, so the force is taken a tick old (2 ms, inside the sensor's
    # filter) rather than through an algebraic loop.
    force = builder.AddNamedSystem("force_memory", unit_delay(3, time_step))
    names = ("p_WP", "R_WP", "velocity_command", "residual", "cable_lengths",
             "tension_assumed")
    route = build_kernel_block(
        builder, TensionSolve(s["tension_x"], s["tension_out"], tick),
        inputs=[("p_WP", 3), ("R_WP", 9), ("F_H_previous", 3), ("velocity_command", 3),
                ("residual", m), ("cable_lengths", m), ("tension_assumed", m)],
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


# --- orientation hold ------------------------------------------------------------------------------


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

    def tick(x, out):
        hold(gain, warmup, x, out)

    build_kernel_block(
        builder, OrientationSolve(s["orientation_x"], s["orientation_out"], tick),
        inputs=[("R_WP", 9)], memory=(s["orientation_memory"], None),
        outputs=[("omega_command", 0, 3), ("R_WP_held", 3, 9)], memory_at=12,
        time_step=time_step)


# --- the Jacobian mapping of a pose ------------------------------------------------------------------


def build_pose_jacobian_mapping(builder, robot, *, length_gain, integral_gain, tension,
                                time_step, dead_band=0.0):
    """l_dot = J(p, R) [v; w] + K_l (l_d - l) (pose_control.pose_rates_tick). Inputs p_WP,
    R_WP, velocity_command, omega_command, R_WP_held, cable_lengths and, with `tension`,
    tension_command; outputs reel_velocity_command, commanded_lengths."""
    m = robot.num_cables
    s = sizes(m)
    reels, attachments = _constants(robot)
    params = owned(np.array([length_gain, integral_gain, time_step,
                             robot.dynamics.EA if tension else 0.0, 1.0 if tension else 0.0,
                             dead_band, WARMUP_TICKS], dtype=float))
    example = np.zeros(s["rates_x"])
    example[:3] = robot.workspace.center
    example[3:12] = example[18:27] = np.eye(3).ravel()
    rates = bind(pose_rates_tick, reels, attachments, params, example,
                 np.empty(s["rates_out"]))

    def tick(x, out):
        rates(reels, attachments, params, x, out)

    # Without tension control the kernel ignores its tensions: the lengths fill the slot
    # (a Selector can only route inputs; a constant source would be a system more a tick).
    inputs = [("p_WP", 3), ("R_WP", 9), ("velocity_command", 3), ("omega_command", 3),
              ("R_WP_held", 9), ("cable_lengths", m)]
    route = build_kernel_block(
        builder, PoseRates(s["rates_x"], s["rates_out"], tick),
        inputs=inputs + ([("tension_command", m)] if tension else [("tension_slot", m)]),
        memory=(s["rates_memory"], None),
        outputs=[("reel_velocity_command", 0, m), ("commanded_lengths", m, m)],
        memory_at=2 * m, time_step=time_step)
    return route


# --- interference on the cables of a pose -------------------------------------------------------


def build_posed_interference_force(builder, robot, params, *, time_step):
    """The interference block (systems.interference_force) on the cables of the estimated
    pose: inputs p_WP and R_WP; the same outputs."""
    from cdpm_drake.systems.interference_force import OUTPUTS

    P = robot.num_pairs
    layout = result_layout(P)
    reels, attachments = _constants(robot)
    i, j = robot.pair_index
    pi = np.ascontiguousarray(i, dtype=np.int64)
    pj = np.ascontiguousarray(j, dtype=np.int64)
    par = owned(params.packed)
    floor, F_max = float(params.gradient_floor), float(params.F_max)
    geo = owned(np.zeros((P, 12)))
    example = np.zeros(12 + P)
    example[:3] = robot.workspace.center
    example[3:12] = np.eye(3).ravel()
    solve = bind(interference_posed_tick, reels, attachments, pi, pj, par, floor, F_max,
                 example, geo, np.empty(3 + 13 * P))

    def tick(x, out):
        solve(reels, attachments, pi, pj, par, floor, F_max, x, geo, out)

    fields = dict(zip(OUTPUTS, ("force", "distance", "active", "crossed", "side")))
    side_at = layout["side"][0]
    build_kernel_block(
        builder, PosedInterference(12 + P, 3 + 13 * P, tick),
        inputs=[("p_WP", 3), ("R_WP", 9)], memory=(P, None),
        outputs=[(name, layout[field][0], layout[field][1] - layout[field][0])
                 for name, field in fields.items() if name != "side"],
        memory_at=side_at, time_step=time_step)
