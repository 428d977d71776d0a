"""cdpm-reel-emulator: play the reel bridge on loopback, to rehearse a run before the robot.

Two plants behind the bridge. `--plant kinematic` (the default): the reels follow the
commanded velocities with a first-order lag, the encoders report what each reel paid out, the
force sensor the operator's force at the best-fit platform pose. `--plant dynamic`: the
scenario's robot with mass, elastic cables, drive friction and the operator, the dynamic plant
of `plant: !DynamicReels` (systems/dynamic_plant.py) stepped in real time; the encoders report
each reel's payout, zeroed at the start pose as a homing would (they read the rigid cable
lengths there), the force sensor the operator's force on the true platform; the closing
summary adds the cables' tensions, their slack ticks and the platform's tilt.
Fault-injection flags impair the link (drop, delay, duplicate, reorder, corrupt) or break the
bridge (freeze, NaN, stop, fault bits) from `--fault-after` seconds after the controller first
enables the reels. The protocol is hardware/PROTOCOL.md.

Each controller session (a `cdpm run`) after the first starts where the first did: the plant is
reset to the start, as a homing between two runs would (its fault bits stay), and the operator's
clock starts again at the session's first enabling command; the session's line says where the
last one left the platform. With the dynamic plant, each session's close reports what the
cables went through in it (tensions, when each went slack, the largest tilt and when, on the
plant's clock), while the controller drove the reels and, apart, after they were stopped.

Protocol version 2 (the default; `--protocol-version 1` plays a version-1 bridge, to rehearse
one): each status also carries each drive's force at the cable, the reels' speeds and load
cells. The kinematic plant has no cable tensions: it sends NaN ("no reading") for the drive
forces and load cells. The dynamic plant measures with the simulated plant's own sensors
(the scenario's plant.drive_torque and plant.load_cell): each drive's force as its current
reads it and, with `--load-cells`, load cells; `--truth-log FILE.npz` keeps what each status
carried beside the plant's truth (true tensions, pose, pair distances), to judge the
controller's log on it.

`--lockstep`: no clock of its own; each command read steps the plant one period and is
answered by one status, so a rehearsal with `cdpm run --lockstep` is deterministic on any
host (docs/on_the_robot.md, "Rehearse in lockstep").

Examples:
  cdpm-reel-emulator --robot paper_7cable --start 1.77 3.65 1.22
  cdpm-reel-emulator --scenario exp2_interaction --drop 0.01 --seed 3
  cdpm-reel-emulator --scenario exp2_interaction --plant dynamic
  cdpm-reel-emulator --scenario exp2_interaction --plant dynamic --truth-log truth.npz
  cdpm-reel-emulator --scenario exp2_interaction --plant dynamic --lockstep
  cdpm-reel-emulator --scenario exp2_interaction --protocol-version 1
  cdpm-reel-emulator --stop --fault-after 2.0

`--canopen` plays CiA 402 drives on a CAN bus instead (emulator/canopen_drives.py; `cdpm
emulate --canopen --help` lists its options).

A scenario whose plant has `force_sensor: !NetFT {address, port, ...}` gets its Net F/T
played too (emulator/netft.py): the hand force streamed over RDT at that address, one record
per plant step.
"""

import argparse
import gc
import math
import sys
import time

import numpy as np

from cdpm_drake.emulator.bridges import DynamicBridge, ReelBridge
from cdpm_drake.emulator.faults import FaultPlan
from cdpm_drake.emulator.plant_setup import (dynamic_scenario, homing_offset, netft_server,
                                             robot_as_built)
from cdpm_drake.emulator.server import ReelBridgeServer, count_by_reason, vector_text
from cdpm_drake.hardware.config import DEFAULT_BRIDGE_PORT
from cdpm_drake.hardware.priority import set_realtime_priority
from cdpm_drake.kernels.interference import posed_pair_distances
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.kernels.rotation import rotations_from_rpy


def _port_number(text: str) -> int:
    """--port's type: a UDP port, 0-65535, 0 picking a free one (argparse turns the error
    into exit code 2)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer 0-65535, got {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"must be a UDP port 0-65535 (0: any free one), "
                                         f"got {port}")
    return port


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cdpm-reel-emulator", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="exit codes: 0 done (--duration), 1 error (robot, "
                                       "scenario, cannot listen), 2 bad usage, 130 after "
                                       "Ctrl-C, 143 after SIGTERM (the summary is printed "
                                       "first)")
    g = p.add_argument_group("robot and operator")
    g.add_argument("--scenario", help="take robot, cable swaps, start position, operator and "
                   "bridge address/port from this scenario (name or path)")
    g.add_argument("--scenario-text", help="YAML overlay applied to --scenario")
    g.add_argument("--robot", help="built-in robot name or robot YAML path (default: "
                   "paper_7cable, or the scenario's); with --scenario: the robot as built, "
                   "played under the scenario's file (its encoders homed on the file at the "
                   "start: a rehearsal of a robot that differs from its file)")
    g.add_argument("--start", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="platform start position, base frame, m (default: workspace centre, "
                   "or the scenario's); the reels' initial lengths follow by inverse kinematics")
    g.add_argument("--length-offset", nargs=2, action="append", default=[],
                   metavar=("CABLE", "METRES"),
                   help="add METRES to cable CABLE's (1-based) initial length, to rehearse the "
                   "controller's refusal to enable on lengths that do not fit the robot")
    g.add_argument("--force", nargs=3, type=float, metavar=("FX", "FY", "FZ"),
                   help="constant operator force, base frame, N (overrides the scenario's)")
    g.add_argument("--plant", choices=("kinematic", "dynamic"), default="kinematic",
                   help="kinematic: reels with a first-order lag (default); dynamic: the "
                   "scenario's robot with mass, elastic cables, drive friction and the "
                   "operator (plant: !DynamicReels; its settings from the scenario's plant "
                   "when that is one)")
    g.add_argument("--time-constant", type=float, default=None,
                   help="reel velocity lag, s (default: 0.02; kinematic plant only)")
    g.add_argument("--load-cells", action="store_true",
                   help="dynamic plant only: report load cells, the simulated plant's (the "
                   "scenario's plant.load_cell: bias, noise, bandwidth; default: none, NaN)")
    g.add_argument("--truth-log", metavar="FILE.npz",
                   help="dynamic plant only: write, when the emulator stops, each version-2 "
                   "status's bridge time, plant time, the true tensions, the drive forces, "
                   "reel speeds and load cells it carried, the platform's true pose and every "
                   "watched pair's true distance (keys time, plant_time, tensions, drive_force, "
                   "reel_speed, load_cell, p_true, rpy_true, pair_distances_true, pairs; the "
                   "last 10 minutes at 500 Hz)")
    n = p.add_argument_group("network")
    n.add_argument("--address", default=None,
                   help="address to listen on (default: 127.0.0.1, or the scenario's)")
    n.add_argument("--port", type=_port_number, default=None,
                   help=f"UDP port to listen on (default: {DEFAULT_BRIDGE_PORT}, or the "
                   "scenario's)")
    n.add_argument("--controller", metavar="ADDRESS:PORT",
                   help="send statuses only there and ignore commands from anyone else "
                   "(default: answer the sender of the latest valid command)")
    n.add_argument("--period", type=float, default=0.002, help="status period, s (default 0.002)")
    n.add_argument("--protocol-version", type=int, choices=(1, 2), default=2,
                   help="newest protocol version spoken (default 2: statuses carry the drives' "
                   "forces, reel speeds and load cells to a controller that asks for them; "
                   "1: a version-1 bridge, which refuses version-2 commands)")
    n.add_argument("--command-timeout", type=float, default=0.05,
                   help="raise COMMAND_TIMEOUT when enabled and no command came for this "
                   "long, s (default 0.05)")
    n.add_argument("--lockstep", action="store_true",
                   help="no clock of its own: each command read steps the plant one --period "
                   "and is answered by one status, so a rehearsal with `cdpm run --lockstep` "
                   "is deterministic on any host, at whatever speed it allows (--duration then "
                   "counts the bridge's ticks x period)")
    n.add_argument("--duration", type=float, default=None, help="stop after this long, s")
    n.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="run under SCHED_FIFO at priority N (1..99; needs root or "
                   "CAP_SYS_NICE), as a real bridge's firmware would; default 0: normal")
    f = p.add_argument_group("fault injection (from --fault-after s after the first enable)")
    f.add_argument("--seed", type=int, default=0, help="random seed of the impairments")
    f.add_argument("--drop", type=float, default=0.0, help="share of datagrams dropped")
    f.add_argument("--delay", type=float, default=0.0, help="extra status latency, s")
    f.add_argument("--duplicate", type=float, default=0.0, help="share of statuses sent twice")
    f.add_argument("--reorder", type=float, default=0.0, help="share of statuses reordered")
    f.add_argument("--corrupt", type=float, default=0.0, help="share of statuses corrupted")
    f.add_argument("--freeze", action="store_true", help="repeat the last status forever")
    f.add_argument("--nan", action="store_true", help="report cable 1's length as NaN")
    f.add_argument("--stop", action="store_true", help="stop sending statuses")
    f.add_argument("--fault-bits", type=lambda s: int(s, 0), default=0,
                   help="raise these fault bits, e.g. 0x1 for ESTOP (see PROTOCOL.md)")
    f.add_argument("--fault-after", type=float, default=0.0,
                   help="seconds after the first enabling command before faults start")
    return p


def build_server(args, log=None) -> ReelBridgeServer:
    """The server described by parsed command-line arguments; `log` as ReelBridgeServer's."""
    from cdpm_drake.robot import load_robot

    force = None
    address, port = "127.0.0.1", DEFAULT_BRIDGE_PORT
    if args.scenario:
        from cdpm_drake.config import load_scenario, scenario_operator, scenario_robot

        scenario = load_scenario(args.scenario, args.scenario_text)
        robot = scenario_robot(scenario)
        start = scenario.initial_position
        force = scenario_operator(scenario).force
        address = getattr(scenario.plant, "address", address)
        port = getattr(scenario.plant, "port", port)
    else:
        robot = load_robot(args.robot or "paper_7cable")
        start = robot.workspace.center
    file_robot = robot
    if args.scenario and args.robot:
        # The robot as built: the scenario's file is the controller's; the emulator plays
        # --robot, its encoders homed on the file (plant_setup.robot_as_built).
        robot = robot_as_built(args, scenario, file_robot)
    if args.start is not None:
        start = args.start
        box = robot.workspace
        if not box.contains(start):
            # The controller refuses to enable there (hardware.reels.start_pose_problem): a
            # rehearsal from such a start rehearses nothing else.
            raise ValueError(f"--start {[float(x) for x in start]!r} m is outside the workspace "
                             f"box of robot {robot.name!r} (lower {box.lower.tolist()!r}, "
                             f"upper {box.upper.tolist()!r} m); give a start inside it")
    lengths = cable_lengths(robot, np.asarray(start, dtype=float))
    for cable, metres in args.length_offset:
        k = int(cable)
        if not 1 <= k <= robot.num_cables:
            raise ValueError(f"--length-offset cable {cable!r}: cables are numbered "
                             f"1..{robot.num_cables}")
        lengths[k - 1] += float(metres)
    if args.force is not None:
        constant = np.asarray(args.force, dtype=float)
        force = lambda t, p, v: constant  # noqa: E731
    controller = None
    if args.controller:
        host, _, cport = args.controller.rpartition(":")
        if not host or not cport.isdigit():
            raise ValueError(f"--controller must be ADDRESS:PORT, got {args.controller!r}")
        controller = (host, int(cport))
    faults = FaultPlan(drop=args.drop, delay=args.delay, duplicate=args.duplicate,
                       reorder=args.reorder, corrupt=args.corrupt, freeze=args.freeze,
                       nan=args.nan, stop=args.stop, fault_bits=args.fault_bits,
                       after=args.fault_after)
    if args.plant == "dynamic":
        if args.time_constant is not None:
            raise ValueError("--time-constant sets the kinematic plant's lag; the dynamic "
                             "plant's drives come from the robot file's reel_drives section")
        bridge = DynamicBridge(dynamic_scenario(args, file_robot, start),
                               length_offset=lengths - cable_lengths(robot, np.asarray(
                                   start, dtype=float)), load_cells=args.load_cells)
    else:
        for flag, given in (("--load-cells", args.load_cells),
                            ("--truth-log", args.truth_log)):
            if given:
                raise ValueError(f"{flag} needs --plant dynamic: the kinematic plant's cables "
                                 "are rigid and carry no tension")
        bridge = ReelBridge(robot, lengths, force=force, time_constant=0.02
                            if args.time_constant is None else args.time_constant,
                            encoder_offset=homing_offset(file_robot, robot, start))
    return ReelBridgeServer(bridge, address=(args.address or address,
                                             args.port if args.port is not None else port),
                            faults=faults, period=args.period, seed=args.seed,
                            controller=controller, command_timeout=args.command_timeout,
                            record=0, log=log, protocol_version=args.protocol_version,
                            truth=TRUTH_ROWS if args.truth_log else 0,
                            lockstep=args.lockstep)


def start_netft(args, bridge, log=None):
    """The Net F/T of the scenario's plant (`force_sensor: !NetFT {...}`), served at its
    address with `bridge`'s hand force (a NetFTServer, to stop), or None."""
    if not args.scenario:
        return None
    from cdpm_drake.config import load_scenario

    return netft_server(load_scenario(args.scenario, args.scenario_text).plant, bridge, log)


# Statuses the truth log keeps: the last 10 minutes at 500 Hz.
TRUTH_ROWS = 300_000


def write_truth_log(server, path) -> int:
    """The server's truth record as an npz at `path`, one row per version-2 status sent:
    time, plant_time s; tensions (true), drive_force, load_cell (sent) N; reel_speed (sent)
    m/s; p_true m and rpy_true rad (the platform's true pose); pair_distances_true m, every
    watched pair's distance on the true, rotated platform (robot.pairs order, cables
    numbered from 1 in `pairs`). Returns the rows."""
    rows = list(server.truth or ())
    robot = server.bridge.robot
    m = robot.num_cables
    columns = list(zip(*rows)) if rows else [[]] * 8
    n = len(rows)
    data = {key: np.array(columns[k], dtype=float).reshape(n, width) for k, key, width in
            ((2, "tensions", m), (3, "drive_force", m), (4, "reel_speed", m),
             (5, "p_true", 3), (6, "rpy_true", 3), (7, "load_cell", m))}
    distances = np.zeros((n, robot.num_pairs))
    if n and robot.num_pairs:
        distances, _ = posed_pair_distances(robot, data["p_true"],
                                            rotations_from_rpy(data["rpy_true"]))
    np.savez(path, time=np.array(columns[0], dtype=float),
             plant_time=np.array(columns[1], dtype=float), pair_distances_true=distances,
             pairs=np.asarray(robot.pairs, dtype=int).reshape(-1, 2) + 1, **data)
    return n


def main(argv=None) -> int:
    """Exit codes as `cdpm`'s: 0 done (--duration), 1 error (robot, scenario, cannot bind),
    2 bad usage, 130 / 143 after Ctrl-C / SIGTERM (the summary is printed first)."""
    from cdpm_drake.text import prefixed_log_records

    argv = list(sys.argv[1:] if argv is None else argv)
    with prefixed_log_records():
        return _main(argv)


def _main(argv) -> int:
    from cdpm_drake.runs.interrupt import exit_code, terminate_raises
    from cdpm_drake.robot import RobotError
    from cdpm_drake.config import ScenarioError

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        parser.error(f"--duration must be a number of seconds > 0, got {args.duration!r}")

    def say(text):
        print(f"cdpm-reel-emulator: {text}", flush=True)

    try:
        set_realtime_priority(args.rt_priority)
        server = build_server(args, log=say)
        netft = start_netft(args, server.bridge, log=say)  # the handle's Net F/T, if any
    except (RobotError, ScenarioError, OSError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else e
        print(f"cdpm-reel-emulator: error: {why}", file=sys.stderr)
        return 1
    except ValueError as e:  # a flag's value
        print(f"cdpm-reel-emulator: error: {e}", file=sys.stderr)
        return 2
    # A full garbage collection scans every object alive, modules included (19 ms measured
    # with pydrake loaded), long enough to trip the controller's watchdog; what exists now
    # lives for the whole run, so take it out of the collector's sight.
    gc.freeze()
    host, port = server.address
    robot = server.bridge.robot
    say(f"robot {robot.name!r} ({robot.num_cables} cables) on {host}:{port}, period "
        f"{server.period * 1e3:g} ms, {server.bridge.describe()}, start "
        f"{vector_text(server.bridge.platform())} m, protocol version "
        f"{server.protocol_version}"
        + (", lockstep (one plant period per command)" if server.lockstep else "")
        + (f", faults {server.faults.describe()} from {server.faults.after:g} s after the "
           "first enable (one session)" if server.faults.any else ""))
    code = 0
    with terminate_raises():
        try:
            server.run(duration=args.duration)
        except KeyboardInterrupt as e:
            code = exit_code(e)
        finally:
            server.stop()
            now = server.now()
            if server.session_open:
                server.close_session(now, "the emulator stopped")
            c = server.counters
            rejected = {r: n for r, n in c["rejected"].items() if n}
            say(f"{c['commands_received']} commands received ({server.session} controller "
                f"session(s)), rejected {count_by_reason(rejected)}, {c['statuses_sent']} "
                f"statuses sent, commands lost {server.commands_lost}, faults "
                f"{server.bridge.faults:#06x}")
            say(server.compute_summary())
            if args.truth_log:
                say(f"truth log: {write_truth_log(server, args.truth_log)} statuses written to "
                    f"{args.truth_log}")
            if netft is not None:
                netft.stop()
    return code
