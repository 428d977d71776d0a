"""The one builder: the paper's Fig. 5 as a Drake Diagram, with the simulated or the real reels.

Like Drake's hardware station, the plant is the only thing that differs between simulation and
the robot: `build_diagram` picks it from the scenario's tagged `plant:` entry and wires it behind
the same port names (`reel_velocity_command` in; `cable_lengths`, `measured_force` out).
"""

import dataclasses

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Adder, VectorLogSink

from .scenario import (DynamicReels as DynamicReelsConfig, Scenario,
                       SimulatedReels as SimulatedReelsConfig, check_dynamic_reels,
                       check_scenario, interference_params, scenario_operator)
from .systems import (ForceSensorSource, ForwardKinematicsEstimator, InterferenceForce,
                      JacobianVelocityMapping, SafetyLimits, SensorNoise, SimulatedOperator,
                      SimulatedReels, WorkspaceWallForce, Admittance)

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
    ("reel_velocity", "jacobian_mapping", "reel_velocity_command"),
    ("lengths", "reels", "cable_lengths"),
    ("pair_distances", "interference_force", "pair_distances"),
    ("active", "interference_force", "active"),
    ("crossed", "interference_force", "crossed"),
)

PLANT_PORTS = ("reel_velocity_command", "cable_lengths", "measured_force")


@dataclasses.dataclass(frozen=True)
class BuildOptions:
    """Switches for benchmarks and tests; the defaults are the product."""

    # Add a VectorLogSink per logged signal.
    loggers: bool = True
    # Overrides scenario.interference.enabled when False (benchmark without the block).
    interference: bool = True
    # Also stream every logged signal to this file as the run goes (hardware/tick_log.py):
    # a real-time run must not lose its log if the process dies.
    tick_log: str | None = None


def build_diagram(scenario: Scenario, options: BuildOptions = BuildOptions()) -> Diagram:
    """The Fig. 5 controller around the scenario's plant, with loggers."""
    robot = check_scenario(scenario)
    T = scenario.time_step
    p0 = np.asarray(scenario.initial_position, dtype=float)
    builder = DiagramBuilder()

    plant = builder.AddNamedSystem("reels", make_plant(scenario, robot))

    sensor_cfg = scenario.sensor
    force_sensor = builder.AddNamedSystem("force_sensor", ForceSensorSource(
        axial_axis=sensor_cfg.axial_axis, axial_range=sensor_cfg.axial_range,
        transverse_range=sensor_cfg.transverse_range, window=sensor_cfg.filter_window,
        time_step=T))
    builder.Connect(plant.GetOutputPort("measured_force"),
                    force_sensor.GetInputPort("measured_force"))

    fk = builder.AddNamedSystem("forward_kinematics", ForwardKinematicsEstimator(
        robot, initial_position=p0, max_residual=_fk_residual(scenario), time_step=T))
    builder.Connect(plant.GetOutputPort("cable_lengths"), fk.GetInputPort("cable_lengths"))
    p_WP = fk.GetOutputPort("p_WP")

    # eq. 22: F_d = F_H + F_int (+ F_wall, beyond the paper).
    forces = [force_sensor.GetOutputPort("F_H")]
    if scenario.interference.enabled and options.interference and robot.num_pairs > 0:
        interference = builder.AddNamedSystem("interference_force", InterferenceForce(
            robot, interference_params(scenario, robot), time_step=T))
        builder.Connect(p_WP, interference.GetInputPort("p_WP"))
        forces.append(interference.GetOutputPort("F_int"))
    wall = scenario.wall_force
    if wall.enabled:
        wall_system = builder.AddNamedSystem("wall_force", WorkspaceWallForce(
            lower=robot.workspace.lower, upper=robot.workspace.upper, margin=wall.margin,
            max_force=wall.max_force))
        builder.Connect(p_WP, wall_system.GetInputPort("p_WP"))
        forces.append(wall_system.GetOutputPort("F_wall"))
    adder = builder.AddNamedSystem("F_d_adder", Adder(len(forces), 3))
    for k, port in enumerate(forces):
        builder.Connect(port, adder.get_input_port(k))

    admittance = builder.AddNamedSystem("admittance", Admittance(
        scenario.admittance.mass, scenario.admittance.damping, T))
    builder.Connect(adder.get_output_port(), admittance.GetInputPort("F_d"))

    limits_cfg = scenario.limits
    limits = builder.AddNamedSystem("safety_limits", SafetyLimits(
        lower=robot.workspace.lower, upper=robot.workspace.upper,
        max_velocity=_or(limits_cfg.max_velocity, robot.limits.max_velocity),
        max_acceleration=_or(limits_cfg.max_acceleration, robot.limits.max_acceleration),
        virtual_wall=limits_cfg.virtual_wall, time_step=T))
    builder.Connect(admittance.GetOutputPort("velocity"),
                    limits.GetInputPort("velocity_desired"))
    builder.Connect(p_WP, limits.GetInputPort("p_WP"))
    # Anti-windup: the admittance integrates from the velocity actually commanded.
    builder.Connect(limits.GetOutputPort("velocity_command"),
                    admittance.GetInputPort("velocity_command"))

    mapping = builder.AddNamedSystem("jacobian_mapping", JacobianVelocityMapping(robot))
    builder.Connect(p_WP, mapping.GetInputPort("p_WP"))
    builder.Connect(limits.GetOutputPort("velocity_command"),
                    mapping.GetInputPort("velocity_command"))
    builder.Connect(mapping.GetOutputPort("reel_velocity_command"),
                    plant.GetInputPort("reel_velocity_command"))

    if options.loggers:
        _add_loggers(builder, T)
    if options.tick_log is not None:
        _add_tick_log(builder, T, options.tick_log, robot, scenario)
    diagram = builder.Build()
    diagram.set_name("cdpm_controller")
    return diagram


def make_plant(scenario: Scenario, robot):
    """The scenario's reel plant, with the ports in PLANT_PORTS."""
    cfg = scenario.plant
    if isinstance(cfg, SimulatedReelsConfig):
        return build_simulated_plant(scenario, robot)
    if isinstance(cfg, DynamicReelsConfig):
        from .systems.dynamic_plant import build_dynamic_plant
        return build_dynamic_plant(scenario, robot, scenario_operator(scenario),
                                   check_dynamic_reels(scenario, robot).tensions)
    from .hardware.config import HardwareReels
    from .hardware.reels import HardwareReelsSystem

    if isinstance(cfg, HardwareReels):
        return HardwareReelsSystem(robot, cfg, time_step=scenario.time_step)
    raise TypeError(f"unknown plant {type(cfg).__name__!r}")


def build_simulated_plant(scenario: Scenario, robot) -> Diagram:
    """Simulated reels, the simulated person and sensor noise: the world, with the same ports
    as the real reels."""
    cfg = scenario.plant
    T = scenario.time_step
    builder = DiagramBuilder()
    reels = builder.AddNamedSystem("simulated_reels", SimulatedReels(
        robot, initial_position=scenario.initial_position, time_step=T,
        time_constant=cfg.time_constant, max_reel_speed=cfg.max_reel_speed))
    operator = builder.AddNamedSystem("operator", SimulatedOperator(scenario_operator(scenario)))
    builder.Connect(reels.GetOutputPort("p_WP_true"), operator.GetInputPort("p_WP_true"))
    builder.Connect(reels.GetOutputPort("v_WP_true"), operator.GetInputPort("v_WP_true"))
    builder.ExportInput(reels.GetInputPort("reel_velocity_command"), "reel_velocity_command")
    builder.ExportOutput(reels.GetOutputPort("cable_lengths"), "cable_lengths")
    force = operator.GetOutputPort("hand_force")
    if scenario.sensor.noise_std > 0:
        noise = builder.AddNamedSystem("sensor_noise", SensorNoise(
            std=scenario.sensor.noise_std, seed=scenario.random_seed, time_step=T))
        noisy = builder.AddNamedSystem("noisy_force", Adder(2, 3))
        builder.Connect(force, noisy.get_input_port(0))
        builder.Connect(noise.GetOutputPort("noise"), noisy.get_input_port(1))
        force = noisy.get_output_port()
    builder.ExportOutput(force, "measured_force")
    plant = builder.Build()
    plant.set_name("reels")
    return plant


def _add_loggers(builder, T):
    for key, port in list(_logged_ports(builder)):
        logger = builder.AddNamedSystem(f"log_{key}", VectorLogSink(port.size(), T))
        builder.Connect(port, logger.get_input_port())


def _logged_ports(builder):
    for key, system_name, port_name in LOGGED:
        if builder.HasSubsystemNamed(system_name):
            yield key, builder.GetSubsystemByName(system_name).GetOutputPort(port_name)


def _add_tick_log(builder, T, path, robot, scenario):
    from .hardware.tick_log_sink import TickLogSink

    ports = dict(_logged_ports(builder))
    sink = builder.AddNamedSystem("tick_log", TickLogSink(
        path, {key: port.size() for key, port in ports.items()}, time_step=T,
        metadata={"robot": robot.name, "scenario": scenario.name, "time_step": T}))
    for key, port in ports.items():
        builder.Connect(port, sink.GetInputPort(key))


def _or(value, default):
    return default if value is None else value


def _fk_residual(scenario) -> float:
    """How far measured lengths may disagree with the geometry (m): the simulated plant keeps
    them consistent to round-off; real encoders and cable stretch do not."""
    if isinstance(scenario.plant, SimulatedReelsConfig):
        return 1e-6
    return float(getattr(scenario.plant, "max_length_residual", 0.005))
