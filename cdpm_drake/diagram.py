"""The one builder: the paper's Fig. 5 as a Drake Diagram, with the simulated or the real reels.

Like Drake's hardware station, the plant is the only thing that differs between simulation and
the robot: `build_diagram` picks it from the scenario's tagged `plant:` entry and wires it behind
the same port names (`reel_velocity_command` in; `cable_lengths`, `measured_force` out).
"""

import dataclasses

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Adder, ConstantVectorSource, VectorLogSink

from cdpm_drake.config import (DynamicReels as DynamicReelsConfig, ResolvedScenario, Scenario,
                       SimulatedReels as SimulatedReelsConfig, check_dynamic_reels,
                       homing_tensions, resolve_scenario)
from cdpm_drake.systems.admittance import ADMITTANCE_MAIN, build_admittance
from cdpm_drake.systems.encoder_zero import build_encoder_zero
from cdpm_drake.systems.force_sensor import FORCE_SENSOR_MAIN, build_force_sensor
from cdpm_drake.systems.forward_kinematics import FORWARD_KINEMATICS_MAIN, build_forward_kinematics
from cdpm_drake.systems.interference_force import INTERFERENCE_FORCE_MAIN, build_interference_force
from cdpm_drake.systems.jacobian_mapping import JACOBIAN_MAPPING_MAIN, build_jacobian_mapping
from cdpm_drake.systems.kernel_system import KERNEL_BLOCK_MAIN
from cdpm_drake.systems.kinetostatic_force import build_kinetostatic_force
from cdpm_drake.systems.model_monitor import build_model_monitor
from cdpm_drake.systems.orientation_hold import build_orientation_hold
from cdpm_drake.systems.plants.simulated_reels import (add_encoder_offset, add_measured_force,
                                                       add_simulated_world)
from cdpm_drake.systems.pose_forward_kinematics import build_pose_forward_kinematics
from cdpm_drake.systems.pose_jacobian_mapping import build_pose_jacobian_mapping
from cdpm_drake.systems.posed_interference_force import build_posed_interference_force
from cdpm_drake.systems.safety_filter import build_safety_filter
from cdpm_drake.systems.safety_limits import SAFETY_LIMITS_MAIN, build_safety_limits
from cdpm_drake.systems.tension_distribution import build_tension_distribution, tension_path_params
from cdpm_drake.systems.unseen_ringing import add_unseen_ringing
from cdpm_drake.systems.wall_force import WorkspaceWallForce
from cdpm_drake.systems.fused_kernels import assemble
from cdpm_drake.systems.wiring import FlatBlock, wiring

# Logged signals: (logger name suffix, system name, output port name). Every signal of the
# paper's Figs. 10, 11, 13, 14 and 16, and what the limits and reels did with them.
LOGGED = (
    ("p", "forward_kinematics", "p_WP"),
    ("F_H", "force_sensor", "F_H"),
    ("F_int", "interference_force", "F_int"),
    ("F_wall", "wall_force", "F_wall"),
    ("F_d", "F_d_adder", "sum"),
    ("velocity_admittance", "admittance", "velocity"),
    ("velocity", "safety_limits", "velocity_command"),
    # With the safety filter, what the reels follow is its command (a key logged by several
    # blocks is the last one's the diagram has: `logged_ports`) and the limits' is kept beside.
    ("velocity", "safety_filter", "velocity_command"),
    ("velocity_limited", "safety_filter", "velocity_desired"),
    ("filter_status", "safety_filter", "status"),
    ("filter_binding", "safety_filter", "binding"),
    ("pair_margin", "safety_filter", "pair_margin"),
    ("F_kin", "kinetostatic_force", "F_kin"),
    ("kappa", "kinetostatic_force", "kappa"),
    ("t_c", "kinetostatic_force", "t_c"),
    ("t_star_hand", "model_monitor", "t_star"),
    ("model_status", "model_monitor", "status"),
    ("model_residual", "model_monitor", "residual"),
    ("reel_velocity", "jacobian_mapping", "reel_velocity_command"),
    # With the tension damping (a plant with a tension sensor), the reels follow its command;
    # its part of it beside.
    ("reel_velocity", "tension_damping", "reel_velocity_command"),
    ("reel_velocity_damping", "tension_damping", "damping"),
    ("lengths_commanded", "jacobian_mapping", "commanded_lengths"),
    # controller.pose: full, and its tension control (each only where the block has it).
    ("rpy", "forward_kinematics", "rpy_WP"),
    ("omega", "orientation_hold", "omega_command"),
    ("omega", "safety_filter", "omega_command"),
    ("tension_command", "tension_distribution", "tension_command"),
    ("tension_estimate", "tension_distribution", "tension_estimate"),
    ("tension_target", "tension_distribution", "tension_target"),
    ("t_star", "tension_distribution", "t_star"),
    ("tension_status", "tension_distribution", "status"),
    ("tension_cable", "tension_distribution", "cable"),
    ("ringing_swing", "unseen_ringing", "swing"),
    ("ringing_warned", "unseen_ringing", "warned"),
    ("lengths", "reels", "cable_lengths"),
    ("F_measured", "reels", "measured_force"),
    ("tension_measured", "reels", "tension_measured"),
    ("pair_distances", "interference_force", "pair_distances"),
    ("active", "interference_force", "active"),
    ("crossed", "interference_force", "crossed"),
)

PLANT_PORTS = ("reel_velocity_command", "cable_lengths", "measured_force")
# The simulated plants' too (N per cable, NaN where the plant has no tension sensor); the
# real reels have it where their protocol carries the drives' torques.
TENSION_PORT = "tension_measured"

# The logger: every logged signal of the diagram, in LOGGED order, multiplexed into one C++
# VectorLogSink (one publish event per tick instead of one per signal); `logged_signals`
# splits its rows again.
LOG_SINK = "log"


@dataclasses.dataclass(frozen=True)
class BuildOptions:
    """Switches for benchmarks and tests; the defaults are the product."""

    # Log every signal of LOGGED (one VectorLogSink of them all, see LOG_SINK).
    loggers: bool = True
    # Overrides scenario.interference.enabled when False (benchmark without the block).
    interference: bool = True
    # Also stream every logged signal to this file as the run goes (hardware/tick_log.py):
    # a real-time run must not lose its log if the process dies.
    tick_log: str | None = None
    # Fuse the blocks' and the logger's C++ wiring (Selectors) into one system (systems/
    # wiring.py), and the safety blocks' kernels into one callback (systems/
    # fused_kernels.py): the same connections and values, less time a tick; False: as built.
    fuse_wiring: bool = True


def build_diagram(scenario: Scenario | ResolvedScenario,
                  options: BuildOptions = BuildOptions()) -> Diagram:
    """The Fig. 5 controller around the scenario's plant, with loggers. Takes a scenario or,
    to resolve it only once, its `resolve_scenario`; the builder only wires."""
    resolved = resolve_scenario(scenario)
    scenario, robot = resolved.scenario, resolved.robot
    T = scenario.time_step
    p0 = np.asarray(scenario.initial_position, dtype=float)
    builder = DiagramBuilder()
    # The blocks that are several systems are added flat (FlatBlock: named `block` and
    # `block_<part>` in this diagram, not nested sub-diagrams): a level of diagram less per
    # tick. {block name: the block's ports} for the wiring and the loggers.
    blocks = {}

    plant = blocks["reels"] = builder.AddNamedSystem("reels", make_plant(resolved))

    sensor_cfg = scenario.sensor
    force_sensor = blocks["force_sensor"] = FlatBlock(
        builder, "force_sensor", FORCE_SENSOR_MAIN, lambda b: build_force_sensor(
            b, axial_axis=sensor_cfg.axial_axis, axial_range=sensor_cfg.axial_range,
            transverse_range=sensor_cfg.transverse_range, window=sensor_cfg.filter_window,
            time_step=T))
    force_sensor.connect_input(plant.GetOutputPort("measured_force"), "measured_force")

    controller = scenario.controller
    full = controller.pose == "full"
    tension_control = full and controller.tension_control
    lengths, reconciled = _add_encoder_zero(builder, blocks, resolved, plant, tension_control)
    if full:
        fk = blocks["forward_kinematics"] = FlatBlock(
            builder, "forward_kinematics", KERNEL_BLOCK_MAIN,
            lambda b: build_pose_forward_kinematics(
                b, robot, initial_position=p0, max_residual=resolved.fk_max_residual,
                EA=robot.dynamics.EA if tension_control else 0.0, time_step=T))
        R_WP = fk.GetOutputPort("R_WP")
    else:
        fk = blocks["forward_kinematics"] = FlatBlock(
            builder, "forward_kinematics", FORWARD_KINEMATICS_MAIN,
            lambda b: build_forward_kinematics(b, robot, initial_position=p0,
                                               max_residual=resolved.fk_max_residual,
                                               time_step=T))
    fk.connect_input(lengths, "cable_lengths")
    p_WP = fk.GetOutputPort("p_WP")

    # eq. 22: F_d = F_H + F_int (+ F_wall, beyond the paper).
    forces = [force_sensor.GetOutputPort("F_H")]
    if resolved.interference is not None and options.interference:
        if full:
            interference = blocks["interference_force"] = FlatBlock(
                builder, "interference_force", KERNEL_BLOCK_MAIN,
                lambda b: build_posed_interference_force(b, robot, resolved.interference,
                                                         time_step=T))
            interference.connect_input(R_WP, "R_WP")
        else:
            interference = blocks["interference_force"] = FlatBlock(
                builder, "interference_force", INTERFERENCE_FORCE_MAIN,
                lambda b: build_interference_force(b, robot, resolved.interference,
                                                   time_step=T))
        interference.connect_input(p_WP, "p_WP")
        forces.append(interference.GetOutputPort("F_int"))
    hold = None
    if full:
        hold = blocks["orientation_hold"] = FlatBlock(
            builder, "orientation_hold", KERNEL_BLOCK_MAIN, lambda b: build_orientation_hold(
                b, gain=controller.orientation_gain, time_step=T))
        hold.connect_input(R_WP, "R_WP")
    # Beyond the paper: the kinetostatic limit, for the safety filter's barrier and its felt
    # cue.
    safety = scenario.safety_filter
    filter_on = safety.enabled
    kinetostatic_on = filter_on and safety.kinetostatic
    monitor_on = scenario.model_monitor.enabled
    kinetostatic = None
    if kinetostatic_on:
        kinetostatic = blocks["kinetostatic_force"] = FlatBlock(
            builder, "kinetostatic_force", KERNEL_BLOCK_MAIN, lambda b: build_kinetostatic_force(
                b, robot, params=kinetostatic_block_params(resolved),
                full_pose=full, time_step=T))
        kinetostatic.connect_input(p_WP, "p_WP")
        kinetostatic.connect_input(force_sensor.GetOutputPort("F_H"), "F_H")
        if full:  # at the commanded orientation (safety_filter.py says why)
            kinetostatic.connect_input(hold.GetOutputPort("R_WP_held"), "R_WP")
        if safety.kinetostatic_force.enabled:
            forces.append(kinetostatic.GetOutputPort("F_kin"))
    wall = scenario.wall_force
    if wall.enabled:
        wall_system = blocks["wall_force"] = builder.AddNamedSystem(
            "wall_force", WorkspaceWallForce(
                lower=robot.workspace.lower, upper=robot.workspace.upper, margin=wall.margin,
                max_force=wall.max_force))
        builder.Connect(p_WP, wall_system.GetInputPort("p_WP"))
        forces.append(wall_system.GetOutputPort("F_wall"))
    adder = blocks["F_d_adder"] = builder.AddNamedSystem("F_d_adder", Adder(len(forces), 3))
    for k, port in enumerate(forces):
        builder.Connect(port, adder.get_input_port(k))

    admittance = blocks["admittance"] = FlatBlock(
        builder, "admittance", ADMITTANCE_MAIN, lambda b: build_admittance(
            b, scenario.admittance.mass, scenario.admittance.damping, T))
    admittance.connect_input(adder.get_output_port(), "F_d")

    limits = blocks["safety_limits"] = FlatBlock(
        builder, "safety_limits", SAFETY_LIMITS_MAIN, lambda b: build_safety_limits(
            b, lower=robot.workspace.lower, upper=robot.workspace.upper,
            max_velocity=resolved.max_velocity, max_acceleration=resolved.max_acceleration,
            virtual_wall=scenario.limits.virtual_wall, time_step=T))
    limits.connect_input(admittance.GetOutputPort("velocity"), "velocity_desired")
    limits.connect_input(p_WP, "p_WP")

    velocity_command = limits.GetOutputPort("velocity_command")
    omega_command = hold.GetOutputPort("omega_command") if full else None
    if filter_on:
        velocity_command, omega_command = _add_safety_filter(
            builder, blocks, resolved, velocity_command, omega_command, p_WP,
            hold.GetOutputPort("R_WP_held") if full else None,
            kinetostatic if kinetostatic_on else None, T)
    # Anti-windup: the admittance integrates from the velocity actually commanded.
    admittance.connect_input(velocity_command, "velocity_command")
    damped = controller.tension_damping.enabled and _senses_tensions(scenario.plant, plant)
    if full:
        mapping = _add_pose_blocks(builder, blocks, resolved, fk, force_sensor, lengths,
                                   velocity_command, omega_command, hold, T, damped)
    else:
        mapping = blocks["jacobian_mapping"] = FlatBlock(
            builder, "jacobian_mapping", JACOBIAN_MAPPING_MAIN,
            lambda b: build_jacobian_mapping(b, robot, length_gain=controller.length_gain,
                                             time_step=T, dead_band=resolved.dead_band))
        mapping.connect_input(lengths, "cable_lengths")
    mapping.connect_input(p_WP, "p_WP")
    mapping.connect_input(velocity_command, "velocity_command")
    command = mapping.GetOutputPort("reel_velocity_command")
    if damped:
        command = _add_tension_damping(builder, blocks, resolved, command, lengths,
                                       plant.GetOutputPort("tension_measured"), T)
    if "tension_distribution" in blocks:
        # The floor clears the ringing the damping measures; without it, the lengths fill
        # the ignored slot (its factor 0).
        blocks["tension_distribution"].connect_input(
            blocks["tension_damping"].GetOutputPort("ringing_previous") if damped else lengths,
            "tension_ringing")
    builder.Connect(command, plant.GetInputPort("reel_velocity_command"))
    # Without a tension sensor, a model of the platform's modes sees what the encoders cannot.
    if "tension_distribution" in blocks and getattr(scenario.plant, "tension_sensor", "") == "none":
        add_unseen_ringing(builder, blocks, robot, floor=controller.tension_floor, p_WP=p_WP,
                           R_WP=R_WP, velocity_command=velocity_command,
                           omega_command=omega_command, F_H=force_sensor.GetOutputPort("F_H"),
                           T=T, warmup=TENSION_WARMUP_TICKS)
    if monitor_on:
        _add_model_monitor(builder, blocks, resolved, lengths, p_WP, R_WP if full else None,
                           force_sensor.GetOutputPort("F_H"), T,
                           plant.GetOutputPort(TENSION_PORT)
                           if _senses_tensions(scenario.plant, plant) else None,
                           slack_from_tensions=damped, reconciled=reconciled)

    wirings = {}
    if options.loggers:
        wirings.update(_add_loggers(builder, blocks, T))
    if options.tick_log is not None:
        _add_tick_log(builder, blocks, T, options.tick_log, robot, scenario)
    # The blocks' kernels, memories and wiring fused (BuildOptions.fuse_wiring), and built.
    diagram = assemble(builder, blocks, wirings, fuse=options.fuse_wiring, plant=plant)
    diagram.set_name("cdpm_controller")
    return diagram


# How fast the commanded tensions may rise and fall, N/s per cable (pose_control.tension_tick
# says why they differ). Up: a hand ramped to 40 N in 0.1 s from the start takes the weak
# cable of paper_7cable down at ~0.5 N per N, and the internal force that keeps it taut
# loads the others 2-15 times that; at 500 N/s three such hands of the adversarial
# benchmark slackened a cable in their first 0.1 s (exp2's 40 N push across 1-3, exp3's 40 N
# push across 5-7, exp3's 20 N corner pull; none at 2000; drive torque sensor).
TENSION_SLEW_RATE = 2000.0
# Ticks the tension command follows the estimate before it slews: the estimate is fitted at
# the first tick (0.4^5 of its first error left after 5), and a hand that comes at once must
# not find the internal force frozen for the pose blocks' 50 ms warm-up (WARMUP_TICKS).
TENSION_WARMUP_TICKS = 5
# The tension target's hard floor is at least this many standard deviations of the ringing
# the tension sensors measure (full_pose.tension_tick): 2.5 sigma of a swing about the
# target stays above zero 99.4 % of the time; the sensor's own noise (0.3 N) alone asks for
# ~1 N, below the 4 N floor.
RINGING_FLOOR = 2.5
TENSION_FALL_RATE = 50.0
RIPPLE = 0.1
# The full-pose length loop's integral gain, 1/s^2 (pose_control.pose_rates_tick).
LENGTH_INTEGRAL_GAIN = 100.0


def kinetostatic_block_params(resolved):
    """The kinetostatic block's parameters (kinetostatics.kinetostatic_params) for the
    scenario: the barrier's floor, the controller's ceiling, the robot's wrench rows, the
    cue's logistic."""
    from cdpm_drake.kernels.kinetostatics import kinetostatic_params, wrench_rows

    scenario, robot = resolved.scenario, resolved.robot
    c, f = scenario.controller, scenario.safety_filter.kinetostatic_force
    return kinetostatic_params(
        # A calibrated file's stated uncertainty raises the floor (resolve.py).
        robot, floor=float(scenario.safety_filter.kinetostatic_floor)
        + resolved.kinetostatic_margin, ceiling=float(c.max_tension),
        rows=wrench_rows(robot), barrier=True, t_l=f.t_l, t_u=f.t_u, F_u=f.F_u, eps=f.eps,
        force=f.enabled, a_brake=filter_braking(resolved),
        time_step=resolved.time_step, ripple=RIPPLE,
        smoothing=float(scenario.safety_filter.position_smoothing),
        soft=_soft_margin(resolved))


def _soft_margin(resolved) -> float:
    """The kinetostatic margin's soft-min temperature, N: on a robot with mass (the full pose
    with tension control) the tension swing of the filter's braking onset at the start
    (kinetostatics.braking_swing; the kinetostatics module docstring says why); 0, the hard
    margin, otherwise (nothing rings on the kinematic plant, and the paper's experiments keep
    their margin)."""
    from cdpm_drake.kernels.kinetostatics import braking_swing, wrench_rows

    scenario, robot = resolved.scenario, resolved.robot
    if not _robot_with_mass(resolved):
        return 0.0
    return braking_swing(robot, np.asarray(scenario.initial_position, dtype=float),
                         wrench_rows(robot), filter_braking(resolved))


def _robot_with_mass(resolved) -> bool:
    """The controller for a robot with mass and elastic cables: the full pose with tension
    control (controller.pose full, controller.tension_control)."""
    return bool(resolved.scenario.controller.tension_control)


def filter_braking(resolved) -> float:
    """The deceleration the safety filter's barriers brake with, m/s^2: per axis as the
    virtual wall does (limits._wall_caps), a / sqrt(3), which keeps the braking within the
    acceleration limit where three barriers meet; and no harder than the cables can take
    without ringing a cable slack (kinetostatics.ringing_deceleration: the onset of braking
    is a step of the platform's acceleration, which its cables answer with up to twice the
    static change of their tensions; kept within the kinetostatic floor)."""
    from cdpm_drake.kernels.kinetostatics import ringing_deceleration, wrench_rows

    scenario, robot = resolved.scenario, resolved.robot
    ringing = ringing_deceleration(robot, np.asarray(scenario.initial_position, dtype=float),
                                   wrench_rows(robot),
                                   float(scenario.safety_filter.kinetostatic_floor))
    return min(resolved.max_acceleration / np.sqrt(3.0), ringing)


def safety_filter_params(resolved, *, full: bool, kinetostatic: bool):
    """The safety filter's parameters (safety_filter.filter_params) for the scenario; on a
    robot with mass the lost-margin slowdown brakes at a_brake, and the brakes for the cables
    give way to the platform's acceleration at give_way_rate."""
    from cdpm_drake.kernels.safety_filter import filter_params, give_way_rate
    from cdpm_drake.kernels.tension_path import lead_time

    scenario = resolved.scenario
    f = scenario.safety_filter
    a_brake, mass = filter_braking(resolved), _robot_with_mass(resolved)
    lead = lead_time(resolved.time_step, resolved.robot.dynamics.bandwidth)
    return filter_params(
        time_step=resolved.time_step, gamma=f.gamma, a_brake=a_brake,
        max_velocity=resolved.max_velocity,
        max_acceleration=resolved.max_acceleration,
        return_speed=f.return_speed, full_pose=full, kinetostatic=kinetostatic,
        box=scenario.limits.virtual_wall, smoothing=float(f.position_smoothing),
        cable_brake=a_brake if mass else None,
        give_way=give_way_rate(a_brake, lead) if mass else np.inf)


def _add_safety_filter(builder, blocks, resolved, velocity_desired, omega_desired, p_WP, R_WP,
                       kinetostatic, T):
    """The safety filter between the limits and the Jacobian mapping, its barriers at the
    commanded pose (p_WP and, for the full pose, the held orientation R_WP); returns its
    velocity and angular velocity commands (None without a full pose)."""
    robot = resolved.robot
    full = R_WP is not None
    params = safety_filter_params(resolved, full=full, kinetostatic=kinetostatic is not None)
    block = blocks["safety_filter"] = FlatBlock(
        builder, "safety_filter", KERNEL_BLOCK_MAIN, lambda b: build_safety_filter(
            b, robot, d_min=resolved.d_min, params=params, full_pose=full, time_step=T))
    block.connect_input(velocity_desired, "velocity_desired")
    block.connect_input(p_WP, "p_WP")
    if robot.num_pairs:
        if "interference_force" in blocks:
            block.connect_input(blocks["interference_force"].GetOutputPort("crossed"),
                                "crossed")
        else:  # no interference block: no pair is known to be crossed
            none = builder.AddNamedSystem("safety_filter_no_crossing",
                                          ConstantVectorSource(np.zeros(robot.num_pairs)))
            block.connect_input(none.get_output_port(), "crossed")
    if kinetostatic is not None:
        for name in ("kappa", "kappa_gradient", "kappa_ray"):
            block.connect_input(kinetostatic.GetOutputPort(name), name)
        kinetostatic.connect_input(block.GetOutputPort("barrier_state_previous"),
                                   "barrier_state_previous")
    else:  # the barrier is off (the filter's parameter says so): zeros fill its inputs
        for name, size in (("kappa", 1), ("kappa_gradient", 3), ("kappa_ray", 1)):
            none = builder.AddNamedSystem(f"safety_filter_no_{name}",
                                          ConstantVectorSource(np.zeros(size)))
            block.connect_input(none.get_output_port(), name)
    if full:
        block.connect_input(omega_desired, "omega_desired")
        block.connect_input(R_WP, "R_WP")
        return block.GetOutputPort("velocity_command"), block.GetOutputPort("omega_command")
    return block.GetOutputPort("velocity_command"), None


def _senses_tensions(cfg, plant) -> bool:
    """The plant has a tension_measured port and may measure: not the kinematic plant (no
    tensions at all: the block would cost 12 % of the paper's Fig. 5 run for nothing).
    Where a sensor reads NaN (`tension_sensor: none`, a reel bridge that sends no torque)
    the block passes the command through unchanged, bit for bit."""
    return not isinstance(cfg, SimulatedReelsConfig) and plant.HasOutputPort(TENSION_PORT)


def _sensor_lag(cfg) -> float:
    """The tension sensor's lag, s: the dynamic plant's current filter or load cell
    bandwidth; 0 for real reels (their drives' filters are not known here)."""
    if isinstance(cfg, DynamicReelsConfig):
        return (1.0 / (2.0 * np.pi * cfg.load_cell.bandwidth) if cfg.tension_sensor ==
                "load_cell" else float(cfg.drive_torque.filter_time_constant))
    return 0.0


# The damper's payout held against the length loop (kernels/tension_damping.damping_tick): 1,
# or 0 for the loop to reel it back. With tension control only (where it was measured: the
# translating controller damps the whole tension, T - 0, and its reels would follow the
# sensor's noise uncorrected).
DAMPING_HOLD = 1.0


def _add_tension_damping(builder, blocks, resolved, command, lengths, tensions, T):
    """The tension damping block between the mapping's reel command and the reels
    (systems/tension_damping.py); returns its reel command."""
    from cdpm_drake.systems.tension_damping import build_tension_damping, tension_damping_gains

    scenario, robot = resolved.scenario, resolved.robot
    cfg = scenario.controller.tension_damping
    kd, tau = tension_damping_gains(
        robot, np.asarray(scenario.initial_position, dtype=float), time_step=T,
        sensor_lag=_sensor_lag(scenario.plant), gain_scale=float(cfg.gain_scale))
    block = blocks["tension_damping"] = FlatBlock(
        builder, "tension_damping", KERNEL_BLOCK_MAIN, lambda b: build_tension_damping(
            b, robot, kd=kd, tau=tau, max_reel_speed=resolved.max_reel_speed,
            estimate="tension_distribution" in blocks, time_step=T,
            loop_gain=float(scenario.controller.length_gain) * DAMPING_HOLD
            if "tension_distribution" in blocks else 0.0))
    block.connect_input(command, "reel_velocity_desired")
    block.connect_input(tensions, "tension_measured")
    block.connect_input(lengths, "cable_lengths")
    # No estimate (no tension control): the slot takes the lengths, which the kernel then
    # ignores (estimate=False; a source of zeros would cost a system).
    estimate = "tension_distribution" in blocks
    block.connect_input(blocks["tension_distribution"].GetOutputPort("tension_estimate")
                        if estimate else lengths, "tension_expected")
    return block.GetOutputPort("reel_velocity_command")


def overload_tension(scenario) -> float:
    """The measured tension above which the model monitor calls a cable overloaded, N:
    model_monitor.overload x controller.max_tension (0: off)."""
    return float(scenario.model_monitor.overload) * float(scenario.controller.max_tension)


# Ticks the encoder zero waits for a first measured tension of every cable before it takes
# the statics where one is missing (a plant that measures tensions): the reel bridge's drive
# torque needs two statuses (an acceleration), CANopen's two TPDOs after a speed; a reading
# the drives never give must not hold the start up.
RECONCILE_WINDOW = 10


def _add_encoder_zero(builder, blocks, resolved, plant, tension_control):
    """The encoder zero (systems/encoder_zero.py) after a plant whose encoders are homed
    (config.homing_tensions), for the controller that models the cables' stretch (the full
    pose with tension control: its fit, estimate and length targets take unstretched
    lengths); returns the lengths the controller reads and the block's reconciled flag. The
    other controllers take the cables as rigid, and homed encoders read rigid lengths: they
    read the plant's own (None for the flag)."""
    scenario, robot = resolved.scenario, resolved.robot
    home = homing_tensions(scenario, robot) if tension_control else None
    if home is None:
        return plant.GetOutputPort("cable_lengths"), None
    measures = (_senses_tensions(scenario.plant, plant)
                and getattr(scenario.plant, "tension_sensor", "none") != "none")
    block = blocks["encoder_zero"] = FlatBlock(
        builder, "encoder_zero", KERNEL_BLOCK_MAIN, lambda b: build_encoder_zero(
            b, robot, home_tensions=home, time_step=resolved.time_step,
            window=RECONCILE_WINDOW if measures else 1))
    block.connect_input(plant.GetOutputPort("cable_lengths"), "encoder_lengths")
    block.connect_input(plant.GetOutputPort(TENSION_PORT), "tension_measured")
    return block.GetOutputPort("cable_lengths"), block.GetOutputPort("reconciled")


def _add_model_monitor(builder, blocks, resolved, lengths, p_WP, R_WP, F_H, T,
                       tensions=None, slack_from_tensions=True, reconciled=None):
    """The model monitor (model_monitor.py) on the measurements and the estimates; tensions:
    the plant's measured tensions, where it may have some: an overload there is a fault, and
    with slack_from_tensions (the tension damping on) a slack reading too; reconciled: the
    encoder zero's flag, where there is one."""
    from cdpm_drake.kernels.kinetostatics import wrench_rows
    from cdpm_drake.kernels.model_monitor import monitor_params

    scenario, robot = resolved.scenario, resolved.robot
    mon = scenario.model_monitor
    estimate = "tension_distribution" in blocks
    slacks = tensions is not None and slack_from_tensions and estimate
    params = monitor_params(
        robot, EA=robot.dynamics.EA if estimate else 0.0, slack_tension=mon.slack_tension,
        # A calibrated file's geometry uncertainty widens the length bounds it judges by.
        slack_length=mon.slack_length + resolved.length_margin,
        fit_tolerance=mon.fit_tolerance + resolved.length_margin,
        unholdable=mon.unholdable, ticks=mon.ticks, estimate=estimate,
        full_pose=R_WP is not None, rows=wrench_rows(robot),
        holdable=float(mon.holdable), slack_ticks=mon.slack_ticks,
        measured_slack=float(mon.measured_slack) if slacks else 0.0,
        overload=overload_tension(scenario) if tensions is not None else 0.0,
        reconciling=reconciled is not None)
    # Slack from measured tensions with tension control only: its target keeps every cable
    # at tension_floor (4 N) or more, so a reading under measured_slack (1 N) is a slack
    # cable; the translating controller keeps no floor (a cable may hold 0.6 N, taut). An
    # overload is one whatever the controller.
    measured = tensions is not None and ((slacks and mon.measured_slack > 0.0)
                                         or overload_tension(scenario) > 0.0)
    block = blocks["model_monitor"] = FlatBlock(
        builder, "model_monitor", KERNEL_BLOCK_MAIN, lambda b: build_model_monitor(
            b, robot, params=params, full_pose=R_WP is not None, estimate=estimate,
            time_step=T, measured=measured, reconciling=reconciled is not None))
    block.connect_input(lengths, "cable_lengths")
    block.connect_input(p_WP, "p_WP")
    block.connect_input(F_H, "F_H")
    if R_WP is not None:
        block.connect_input(R_WP, "R_WP")
    if estimate:
        block.connect_input(blocks["tension_distribution"].GetOutputPort("tension_estimate"),
                            "tension_estimate")
    if measured:
        block.connect_input(tensions, "tension_measured")
    if reconciled is not None:
        block.connect_input(reconciled, "reconciled")


def _add_pose_blocks(builder, blocks, resolved, fk, force_sensor, lengths, velocity_command,
                     omega_command, hold, T, damped=False):
    """controller.pose: full: the tension distribution (with tension_control) and the
    Jacobian mapping of the pose, fed the orientation hold's reference and the (filtered)
    angular velocity command; returns the mapping (its p_WP and velocity_command inputs still
    to connect)."""
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix
    from cdpm_drake.robot.tension_program import tension_distribution

    scenario, robot = resolved.scenario, resolved.robot
    controller = scenario.controller
    R_WP = fk.GetOutputPort("R_WP")
    tension_control = controller.tension_control
    mapping = blocks["jacobian_mapping"] = FlatBlock(
        builder, "jacobian_mapping", KERNEL_BLOCK_MAIN, lambda b: build_pose_jacobian_mapping(
            b, robot, length_gain=controller.length_gain,
            integral_gain=LENGTH_INTEGRAL_GAIN, tension=tension_control, time_step=T,
            dead_band=resolved.dead_band))
    for name, port in (("R_WP", R_WP), ("omega_command", omega_command),
                       ("R_WP_held", hold.GetOutputPort("R_WP_held")),
                       ("cable_lengths", lengths)):
        mapping.connect_input(port, name)
    if not tension_control:
        # The blocks ignore the tensions then (EA off): the lengths fill their slots.
        fk.connect_input(lengths, "tension_estimate")
        mapping.connect_input(lengths, "tension_slot")
        return mapping
    # The estimate starts at the target of the start, level and unpushed.
    p0 = np.asarray(scenario.initial_position, dtype=float)
    # (The estimate closes in on the robot's real pretension during the warm-up ticks.)
    start = tension_distribution(wrench_matrix(robot, p0), gravity_wrench(robot.dynamics.mass),
                                 float(controller.min_tension)).tensions
    tension = blocks["tension_distribution"] = FlatBlock(
        builder, "tension_distribution", KERNEL_BLOCK_MAIN, lambda b: build_tension_distribution(
            b, robot, min_tension=controller.min_tension,
            max_tension=controller.max_tension, tension_floor=controller.tension_floor,
            slew_rate=TENSION_SLEW_RATE, fall_rate=TENSION_FALL_RATE,
            initial_tensions=start, time_step=T, warmup_ticks=TENSION_WARMUP_TICKS,
            ringing_factor=RINGING_FLOOR if damped else 0.0,
            **tension_path_params(robot, T, p0, scenario.sensor.filter_window)))
    for name, port in (("p_WP", fk.GetOutputPort("p_WP")), ("R_WP", R_WP),
                       ("F_H", force_sensor.GetOutputPort("F_H")),
                       ("velocity_command", velocity_command),
                       ("residual", fk.GetOutputPort("residual")), ("cable_lengths", lengths),
                       ("tension_assumed", fk.GetOutputPort("tension_assumed"))):
        tension.connect_input(port, name)
    fk.connect_input(tension.GetOutputPort("tension_estimate_previous"), "tension_estimate")
    mapping.connect_input(tension.GetOutputPort("tension_command"), "tension_command")
    return mapping


def block_output_port(diagram, block: str, port_name: str):
    """The output port `port_name` of the Fig. 5 block `block` of a diagram build_diagram
    made, whether the block is one system, a sub-diagram or flat (FlatBlock)."""
    flat = getattr(diagram, "flat_blocks", {}).get(block)
    if flat is not None:
        system_name, index = flat["outputs"][port_name]
        return diagram.GetSubsystemByName(system_name).get_output_port(index)
    return diagram.GetSubsystemByName(block).GetOutputPort(port_name)


def has_block(diagram, block: str) -> bool:
    """Whether a diagram build_diagram made has the Fig. 5 block `block` (one system, or a
    flat block, whose kernel may be in the fused callback: systems/fused_kernels.py)."""
    return block in getattr(diagram, "flat_blocks", {}) or diagram.HasSubsystemNamed(block)


def logged_ports(diagram):
    """(key, block, port name) of every LOGGED signal the diagram has (its block, and the port:
    the full-pose blocks have ports the paper's do not), in LOGGED order; a key several blocks
    log is the last one's the diagram has (`_available`)."""
    yield from _available(lambda block, port_name: _block_has_output(diagram, block, port_name))


def _available(has):
    """(key, block, port name) of LOGGED where has(block, port name), one per key: the last
    such entry of a key (the safety filter's velocity over the limits'), at the place of the
    key's first entry."""
    chosen, order = {}, []
    for key, block, port_name in LOGGED:
        if key not in order:
            order.append(key)
        if has(block, port_name):
            chosen[key] = (block, port_name)
    for key in order:
        if key in chosen:
            yield (key, *chosen[key])


def logged_source(diagram, key: str):
    """The output port that logs `key` in a diagram build_diagram made, or None."""
    for k, block, port_name in logged_ports(diagram):
        if k == key:
            return block_output_port(diagram, block, port_name)
    return None


def _block_has_output(diagram, block: str, port_name: str) -> bool:
    flat = getattr(diagram, "flat_blocks", {}).get(block)
    if flat is not None:  # (a flat block may have no system of its own left: fused_kernels)
        return port_name in flat["outputs"]
    return diagram.HasSubsystemNamed(block) and diagram.GetSubsystemByName(block).HasOutputPort(
        port_name)


def make_plant(scenario: Scenario | ResolvedScenario, robot=None):
    """The scenario's reel plant, with the ports in PLANT_PORTS. (`robot`: unused, the
    resolved scenario's robot is taken; kept for callers that pass one.)"""
    resolved = resolve_scenario(scenario)
    cfg = resolved.scenario.plant
    if isinstance(cfg, SimulatedReelsConfig):
        return build_simulated_plant(resolved)
    if isinstance(cfg, DynamicReelsConfig):
        from cdpm_drake.systems.plants.dynamic_plant import build_dynamic_plant
        true = resolved.plant_robot
        return build_dynamic_plant(resolved.scenario, true, resolved.operator,
                                   check_dynamic_reels(resolved.scenario, true).tensions,
                                   homing_offset=resolved.homing_offset)
    from cdpm_drake.hardware.config import HardwareReels
    from cdpm_drake.hardware.reels import HardwareReelsSystem

    if isinstance(cfg, HardwareReels):
        return HardwareReelsSystem(resolved.robot, cfg, time_step=resolved.time_step)
    from cdpm_drake.hardware.canopen_config import CanopenReels
    if isinstance(cfg, CanopenReels):
        from cdpm_drake.hardware.canopen_reels import CanopenReelsSystem
        return CanopenReelsSystem(resolved.robot, cfg, time_step=resolved.time_step)
    raise TypeError(f"unknown plant {type(cfg).__name__!r}")


def build_simulated_plant(scenario: Scenario | ResolvedScenario, robot=None) -> Diagram:
    """Simulated reels, the simulated person and sensor noise: the world, with the same ports
    as the real reels."""
    resolved = resolve_scenario(scenario)
    scenario, robot = resolved.scenario, resolved.plant_robot
    cfg = scenario.plant
    T = scenario.time_step
    builder = DiagramBuilder()
    # The reels and the person added here directly (not as a nested diagram): one level of
    # diagram less per tick.
    command, world = add_simulated_world(
        builder, robot, resolved.operator, initial_position=scenario.initial_position,
        time_step=T, time_constant=cfg.time_constant, max_reel_speed=resolved.max_reel_speed)
    builder.ExportInput(command, "reel_velocity_command")
    builder.ExportOutput(add_encoder_offset(builder, world["cable_lengths"],
                                            resolved.homing_offset), "cable_lengths")
    if resolved.true_robot is not None:
        # The controller's estimate is no longer the truth: log the true pose (the
        # translating platform's, level) as the dynamic plant does.
        from cdpm_drake.systems.plants.dynamic_plant import add_pose_truth_log
        add_pose_truth_log(builder, world["p_WP_true"], T)
    force = world["hand_force"]
    add_measured_force(builder, force, scenario, T)
    # Kinematic reels have no tensions: the sensor reads NaN.
    none = builder.AddNamedSystem("tension_sensor", ConstantVectorSource(
        np.full(robot.num_cables, np.nan)))
    builder.ExportOutput(none.get_output_port(), TENSION_PORT)
    plant = builder.Build()
    plant.set_name("reels")
    return plant


def _add_loggers(builder, blocks, T):
    # Every logged signal, read where it is computed: a block output that is a piece of
    # another port (FlatBlock.pieces, e.g. the interference block's result) is selected
    # from that port, so the logger evaluates no splitting of its own.
    sources, pieces = {}, []
    for _, block, port_name, port in _logged_ports(blocks):
        source, offset = getattr(block, "pieces", {}).get(port_name, (port, 0))
        name = f"{source.get_system().get_name()}.{source.get_name()}"
        sources.setdefault(name, source)
        pieces.append((name, offset, port.size()))
    signals = wiring([(name, port.size()) for name, port in sources.items()], [("y0", pieces)])
    spec = signals.wiring_spec
    signals = builder.AddNamedSystem("log_signals", signals)
    for name, port in sources.items():
        builder.Connect(port, signals.GetInputPort(name))
    sink = builder.AddNamedSystem(LOG_SINK, VectorLogSink(signals.get_output_port().size(), T))
    builder.Connect(signals.get_output_port(), sink.get_input_port())
    return {"log_signals": spec}


def reserve_log(diagram, context, ticks: int) -> None:
    """Make room in the logger (and the dynamic plant's ground-truth logger) for `ticks` rows
    before a run (no-op without a logger): a growing log is copied at each doubling (2 % of a
    120 s run of exp2)."""
    if diagram.HasSubsystemNamed(LOG_SINK):
        diagram.GetSubsystemByName(LOG_SINK).FindMutableLog(context).Reserve(int(ticks))
    from cdpm_drake.systems.plants.dynamic_plant import reserve_ground_truth
    reserve_ground_truth(diagram, context, ticks)


def logged_signals(diagram, context) -> tuple[np.ndarray, dict]:
    """The logger's rows as (sample times (T,) s, {LOGGED key: (T, width)}) for the signals
    the diagram logs; (empty, {}) for a diagram built without loggers."""
    if not diagram.HasSubsystemNamed(LOG_SINK):
        return np.zeros(0), {}
    log = diagram.GetSubsystemByName(LOG_SINK).FindLog(context)
    rows = log.data().T
    signals, k = {}, 0
    for key, system_name, port_name in logged_ports(diagram):
        width = block_output_port(diagram, system_name, port_name).size()
        signals[key] = rows[:, k:k + width].copy()
        k += width
    return log.sample_times().copy(), signals


def _logged_ports(blocks):
    """(key, block, port name, port) of every LOGGED signal whose block the diagram has (one
    per key, as `logged_ports`)."""
    for key, system_name, port_name in _available(
            lambda name, port_name: name in blocks and _has_output(blocks[name], port_name)):
        block = blocks[system_name]
        yield key, block, port_name, block.GetOutputPort(port_name)


def _has_output(block, port_name: str) -> bool:
    """A block (FlatBlock or system) has an output port of that name."""
    return (port_name in block.outputs if isinstance(block, FlatBlock)
            else block.HasOutputPort(port_name))


def _add_tick_log(builder, blocks, T, path, robot, scenario):
    from cdpm_drake.hardware.tick_log_sink import TickLogSink

    ports = {key: port for key, _, _, port in _logged_ports(blocks)}
    sink = builder.AddNamedSystem("tick_log", TickLogSink(
        path, {key: port.size() for key, port in ports.items()}, time_step=T,
        metadata={"robot": robot.name, "scenario": scenario.name, "time_step": T}))
    for key, port in ports.items():
        builder.Connect(port, sink.GetInputPort(key))
