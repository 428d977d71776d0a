"""What the two emulators (`cdpm emulate`, emulator/main.py, and `cdpm emulate --canopen`,
emulator/canopen_drives.py) build alike: the dynamic plant's scenario and the handle's
network force sensor. Neither of them imports the other; both import this.
"""

from cdpm_drake.emulator.netft import NetFTServer


def dynamic_scenario(args, robot, start):
    """The resolved scenario of `--plant dynamic`: the scenario's (or, with --robot, a
    scenario of that robot), at `start`, with --force as its operator, and a !DynamicReels
    plant (the scenario's own when it has one)."""
    import dataclasses as dc

    from cdpm_drake.config import DynamicReels, Scenario, load_scenario, resolve_scenario
    from cdpm_drake.kernels.plant.operators import NoOperator, ScriptedOperator

    if args.scenario:
        scenario = load_scenario(args.scenario, args.scenario_text)
    else:
        scenario = Scenario(robot=args.robot or "paper_7cable", swaps=[],
                            operator=NoOperator())
    plant = scenario.plant if isinstance(scenario.plant, DynamicReels) else DynamicReels()
    if args.scenario and getattr(args, "robot", None):
        # The robot as built (--robot) under the scenario's file: the plant plays it.
        plant = dc.replace(plant, robot=command_line_robot(args.robot))
    operator = scenario.operator
    if getattr(args, "force", None) is not None:
        operator = ScriptedOperator(times=[0.0], forces=[[float(f) for f in args.force]])
    scenario = dc.replace(scenario, plant=plant, operator=operator,
                          initial_position=[float(x) for x in start])
    resolved = resolve_scenario(scenario)
    if resolved.robot.num_cables != robot.num_cables:  # pragma: no cover - same robot
        raise ValueError("the scenario's robot changed under --plant dynamic")
    return resolved


def netft_server(plant_config, bridge, log=None):
    """A started NetFTServer playing the `force_sensor: !NetFT {...}` of a scenario's plant
    config (its address and port, counts and axes) with `bridge`'s hand force, or None when
    the plant has no Net F/T."""
    from cdpm_drake.hardware.force_config import NetFT

    sensor = getattr(plant_config, "force_sensor", None)
    if not isinstance(sensor, NetFT):
        return None
    return NetFTServer(bridge, address=(sensor.address, sensor.port),
                       counts_per_force=sensor.counts_per_force, axes=sensor.axes,
                       log=log).start()


def robot_as_built(args, scenario, robot):
    """The robot the emulator plays for `--scenario` with `--robot`: the robot as built (the
    scenario's swaps applied), whose encoders are homed on the scenario's file (`robot`, the
    controller's) at the start pose (`homing_offset`); `robot` itself without --robot.
    ValueError naming --robot."""
    from cdpm_drake.config import ScenarioError, scenario_robot

    if not (args.scenario and getattr(args, "robot", None)):
        return robot
    try:
        true = scenario_robot(scenario, command_line_robot(args.robot), field="--robot")
    except ScenarioError as e:
        raise ValueError(str(e)) from None
    if true.num_cables != robot.num_cables:
        raise ValueError(f"--robot {args.robot!r} has {true.num_cables} cables; the "
                         f"scenario's robot {robot.name!r} has {robot.num_cables}: --robot is "
                         "the same robot as built")
    return true


def homing_offset(file_robot, robot, start):
    """What a homing at `start` on `file_robot`'s geometry adds to `robot`'s encoder
    readings, m (None where the two are the same robot): the file's rigid lengths there less
    the played robot's."""
    import numpy as np

    from cdpm_drake.kernels.kinematics import cable_lengths

    if robot is file_robot:
        return None
    start = np.asarray(start, dtype=float)
    return cable_lengths(file_robot, start) - cable_lengths(robot, start)


def command_line_robot(ref: str) -> str:
    """A --robot given on the command line: a built-in name as it is, a path made absolute
    from the current folder (a scenario's own paths count from the scenario's folder)."""
    from pathlib import Path

    from cdpm_drake.robot import is_path_like

    return str(Path(ref).resolve()) if is_path_like(ref) else ref
