"""`cdpm diagram`: a scenario's Fig. 5 diagram written as graphviz (.dot, .svg), with each
plant and as a full-pose controller, at full depth and as an overview."""

import sys

from cdpm_drake.cli.arguments import check_writable_dir, load_scenario_arg
from cdpm_drake.cli.errors import CliError


# The diagrams `cdpm diagram` writes, each at full depth (NAME) and as an overview
# (NAME_overview), as .dot and .svg (README, "Look at it").
DIAGRAMS = ("controller_simulated", "controller_hardware", "controller_dynamic",
            "plant_dynamic", "controller_full_pose")


def diagram_main(*, scenario, out_dir, depth=None, svg=True, out=None) -> int:
    """Write the controller diagram, with the simulated, the hardware and the dynamic plant,
    the dynamic plant alone and the full-pose controller (DIAGRAMS); `depth` levels of
    sub-diagrams in the full-depth pictures (None: every level)."""
    import dataclasses

    from cdpm_drake.diagram import BuildOptions, build_diagram
    from cdpm_drake.hardware.config import HardwareReels
    from cdpm_drake.config import DynamicReels, ScenarioError, SimulatedReels
    from cdpm_drake.views.diagram_graph import write_diagrams

    out = sys.stdout if out is None else out
    options = BuildOptions(loggers=False)  # loggers only clutter the picture
    diagrams = {
        "controller_simulated": build_diagram(
            dataclasses.replace(scenario, plant=SimulatedReels()), options),
        "controller_hardware": build_diagram(
            dataclasses.replace(scenario, plant=HardwareReels()), options),
    }
    dynamic = scenario.plant if isinstance(scenario.plant, DynamicReels) else DynamicReels()
    try:
        diagrams["controller_dynamic"] = build_diagram(
            dataclasses.replace(scenario, plant=dynamic), options)
        # Inside the dynamic plant: the MultibodyPlant, drives, encoders, cables, loggers.
        diagrams["plant_dynamic"] = diagrams["controller_dynamic"].GetSubsystemByName("reels")
    except ScenarioError as e:  # a start the cables cannot hold level: say so, draw the rest
        print(f"skipped controller_dynamic: {e}", file=out)
    # The full-pose controller with its tension control (controller.pose: full), on the
    # dynamic plant: the pose forward kinematics, the tension distribution, the orientation
    # hold.
    from cdpm_drake.config import check_scenario
    full = dataclasses.replace(
        scenario, plant=dynamic, controller=dataclasses.replace(
            scenario.controller, pose="full", tension_control=True))
    try:
        check_scenario(full)
        diagrams["controller_full_pose"] = build_diagram(full, options)
    except ScenarioError as e:
        print(f"skipped controller_full_pose: {e}", file=out)
    for path in write_diagrams(diagrams, out_dir, svg=svg, max_depth=depth,
                               caption=diagram_caption(scenario)):
        print(f"wrote {path}", file=out)
    return 0


def diagram_caption(scenario) -> str:
    """The line under each overview: the scenario and robot it was built for (the blocks are
    the same for many scenarios; their parameters are not drawn)."""
    from cdpm_drake.config import scenario_robot

    robot = scenario_robot(scenario)
    swaps = ", ".join(f"{i}-{j}" for i, j in scenario.swaps)
    return (f"scenario {scenario.name}: robot {robot.name}, {robot.num_cables} cables"
            + (f", swapped {swaps}" if swaps else "") + f", method {scenario.method}")


def _scenario_or_robot(args):
    """The scenario argument's scenario, or for a robot's name (or robot file) a scenario of
    that robot with the defaults (the diagram of a robot alone)."""
    from cdpm_drake.config import Scenario, resolve_scenario, scenario_names
    from cdpm_drake.robot import robot_names

    if args.scenario in robot_names() and args.scenario not in scenario_names():
        if args.scenario_text:
            raise CliError("--scenario-text overlays a scenario; give a scenario, not the "
                           f"robot {args.scenario!r}")
        return resolve_scenario(Scenario(name=args.scenario, robot=args.scenario,
                                         method=args.method or "promise")).scenario
    return load_scenario_arg(args).scenario


def cmd_diagram(args) -> int:
    """`cdpm diagram`: --depth checked, then diagram_main."""
    if args.depth is not None and args.depth < 1:
        raise CliError(f"--depth must be an integer >= 1, got {args.depth!r}")
    scenario = _scenario_or_robot(args)  # a bad scenario leaves no folder behind
    check_writable_dir(args.out, "--out")  # before the diagrams are built, not after
    return diagram_main(scenario=scenario, out_dir=args.out,
                        depth=args.depth, svg=not args.no_svg)
