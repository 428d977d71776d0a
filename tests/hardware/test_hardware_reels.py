"""HardwareReelsSystem against the emulator thread on loopback, in real time.

Each real-time test is bounded (at most ~1 s of simulated time) and checks, from the
emulator's record of the commands it read, what actually went over the wire.
"""

import dataclasses
import math
import re
import time
import typing

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource

from cdpm_drake.hardware.config import HardwareReels, check_hardware_reels
from cdpm_drake.emulator import FaultPlan, ReelBridge, ReelBridgeServer
from cdpm_drake.hardware.protocol import FAULT_DRIVE, FAULT_ESTOP
from cdpm_drake.hardware.reels import HardwareReelsSystem, ReelFault, start_realtime
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.robot import load_robot
from helpers_scripted_link import ScriptedLink, answering, install

T = 0.002
TAU = 0.01
# Real-time tests share a 2-core host with everything else: a busy host can hold a thread
# off the CPU for several ms (measured: sleep(2 ms) overshooting by 4.5 ms with one busy
# core), long enough to trip a 3-tick watchdog on a healthy link. Tests that are not about
# the watchdog give it 50 ms.
RELAXED = dict(watchdog_ticks=25)


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


@pytest.fixture(scope="module")
def p0(robot):
    # Away from the workspace centre, where the system's placeholder state sits.
    return robot.workspace.center + np.array([0.2, -0.3, 0.1])


@pytest.fixture
def emulator(robot, p0):
    servers = []

    def start(faults=FaultPlan(), lengths=None, **options):
        lengths = cable_lengths(robot, p0) if lengths is None else lengths
        server = ReelBridgeServer(ReelBridge(robot, lengths, time_constant=TAU),
                                  faults=faults, **options).start()
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.stop()


def _diagram(robot, server, command, extra=None, **config):
    cfg = HardwareReels(port=server.address[1], **config)
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(np.asarray(command, dtype=float)))
    reels = builder.AddNamedSystem("reels", HardwareReelsSystem(robot, cfg, time_step=T))
    builder.Connect(source.get_output_port(), reels.GetInputPort("reel_velocity_command"))
    if extra is not None:
        builder.AddSystem(extra)
    return builder.Build(), reels


def _command(m=7):
    u = np.zeros(m)
    u[0], u[2], u[5] = 0.06, -0.03, 0.09
    return u


# --- configuration ---------------------------------------------------------------------------


def test_default_config_is_valid_and_loopback():
    cfg = HardwareReels()
    check_hardware_reels(cfg)
    assert cfg.local_address == "127.0.0.1" and cfg.address == "127.0.0.1"
    assert cfg.watchdog_ticks == 3
    # 15 ms: rides out the 5-15 ms holds of a virtual CPU measured on a shared VM; stays short
    # of the 20 ms a status delayed by the emulator's `--delay 0.02` takes to answer the stop.
    assert cfg.resume_within == 0.015


@pytest.mark.parametrize("change,match", [
    (dict(port=0), r"plant.port must be an integer in 1..65535 \(a UDP port\), got 0"),
    (dict(address="10.0.0.300"), r"plant.address must be an IPv4 address .* got '10.0.0.300'"),
    (dict(watchdog_ticks=0), r"plant.watchdog_ticks must be an integer in 1..1000"),
    (dict(watchdog_ticks=2.5), r"plant.watchdog_ticks .* got 2.5"),
    (dict(ramp_time=-0.1), r"plant.ramp_time must be a finite number >= 0 s, got -0.1"),
    (dict(startup_timeout=0.0), r"plant.startup_timeout must be a finite number > 0 s"),
    (dict(max_length_residual=float("nan")), r"plant.max_length_residual .* got nan"),
    (dict(resume_within=-0.001), r"plant.resume_within must be a finite number >= 0 s, got "
                                 r"-0.001"),
    (dict(resume_within=1.5), r"plant.resume_within must be at most 1 s .* got 1.5"),
])
def test_bad_config_names_the_field_and_value(change, match, robot):
    with pytest.raises(ValueError, match=match):
        HardwareReelsSystem(robot, HardwareReels(**change))


@dataclasses.dataclass
class _OtherPlant:
    gain: float = 1.0


@dataclasses.dataclass
class _Holder:
    plant: typing.Union[_OtherPlant, HardwareReels] = dataclasses.field(
        default_factory=_OtherPlant)


def test_yaml_tag_is_the_class_name():
    from pydrake.common.yaml import yaml_load_typed

    holder = yaml_load_typed(schema=_Holder, data="plant: !HardwareReels {port: 47200, "
                                                  "watchdog_ticks: 5}")
    assert holder.plant == HardwareReels(port=47200, watchdog_ticks=5)


def test_ports_match_the_simulated_plant_contract(robot):
    from cdpm_drake.diagram import PLANT_PORTS

    reels = HardwareReelsSystem(robot, HardwareReels())
    inputs = {reels.get_input_port(k).get_name(): reels.get_input_port(k).size()
              for k in range(reels.num_input_ports())}
    outputs = {reels.get_output_port(k).get_name(): reels.get_output_port(k).size()
               for k in range(reels.num_output_ports())}
    assert inputs == {"reel_velocity_command": 7}
    assert outputs == {"cable_lengths": 7, "measured_force": 3, "tension_measured": 7}
    # Issue 31: every plant that has measured tensions has this port (PLANT_PORTS gains it
    # once every plant has it).
    assert set(inputs) | set(outputs) == set(PLANT_PORTS) | {"tension_measured"}


# --- start-up --------------------------------------------------------------------------------


def test_state_starts_from_the_measured_lengths(robot, p0, emulator):
    server = emulator()
    diagram, reels = _diagram(robot, server, np.zeros(7))
    simulator = Simulator(diagram)
    try:
        simulator.Initialize()
        ctx = reels.GetMyContextFromRoot(simulator.get_context())
        # The emulator's encoders read the lengths of the platform at p0, not at the workspace
        # centre where the placeholder state was.
        np.testing.assert_allclose(reels.GetOutputPort("cable_lengths").Eval(ctx),
                                   cable_lengths(robot, p0), atol=1e-12)
        book = reels.book(ctx)
        assert book["enabled"] == 1.0 and book["ramp"] == 0.0 and book["fault"] == 0.0
    finally:
        reels.close()


def _refused_with(robot, emulator, lengths):
    """Initialise the reels against an emulator whose encoders read `lengths` (m); returns the
    ReelFault's message, after checking that no command enabled the reels or asked them to
    move."""
    server = emulator(lengths=lengths)
    diagram, reels = _diagram(robot, server, _command())
    try:
        with pytest.raises(ReelFault) as refused:
            Simulator(diagram).Initialize()
    finally:
        reels.close()
    time.sleep(0.01)
    commands = list(server.commands)
    assert commands and not any(c.enable for c in commands)
    assert all(np.all(c.velocity == 0) for c in commands)
    return str(refused.value)


def _refused_at(robot, emulator, p):
    """_refused_with the lengths of the level platform at p (m)."""
    return _refused_with(robot, emulator, cable_lengths(robot, np.asarray(p, dtype=float)))


def test_refuses_to_enable_when_lengths_do_not_fit_the_robot(robot, p0, emulator):
    lengths = cable_lengths(robot, p0)
    lengths[2] += 0.05  # cable 3 miscalibrated by 5 cm
    # The bound unset is derived from the robot's cables (robot.stretch, 12.3 mm here).
    from cdpm_drake.robot.stretch import derived_length_residual
    bound = derived_length_residual(robot)
    assert re.search(r"refusing to enable the reels: the measured cable lengths .* do not fit "
                     rf"robot 'paper_7cable' .* max_length_residual = {bound:g} m",
                     _refused_with(robot, emulator, lengths))


def test_refuses_to_enable_outside_the_workspace_box(robot, emulator):
    # Issue 27, bug 1: `cdpm emulate --start 10 10 10`, lengths that fit the robot exactly (the
    # platform 7.6 m beyond the box's upper z face), ran to the end.
    message = _refused_at(robot, emulator, [10.0, 10.0, 10.0])
    assert message.startswith("refusing to enable the reels: the platform centre p = [10.000, "
                              "10.000, 10.000] m (from the measured cable lengths) is outside "
                              "the workspace box of robot 'paper_7cable'"), message
    # The box of hardware/robots/paper_7cable.yaml; the largest excess is along z: 10 - 2.4 m.
    assert "lower [0.500, 0.800, 0.300] m, upper [3.000, 4.000, 2.400] m (7600.0 mm beyond " \
           "its z upper face)" in message, message


def _t_star_lp(robot, p, point=False):
    """t* of the level platform at p by scipy's LP (conftest.highs_t_star), with W built here
    from the cable directions u_i (attachment point to reel exit) and the moments b_i x u_i
    about the centre, independent of tension.py; `point`: the platform as a point (its
    centre; forces only, the first three rows)."""
    from conftest import highs_t_star

    b = np.zeros_like(robot.attachments) if point else robot.attachments  # a point: no b_i
    u = robot.reels - (np.asarray(p) + b)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    W = np.vstack([u.T, np.cross(b, u).T])
    weight = np.array([0.0, 0.0, -robot.dynamics.mass * 9.81, 0.0, 0.0, 0.0])
    return highs_t_star(W[:3], weight[:3]) if point else highs_t_star(W, weight)


def test_refuses_to_enable_where_the_cables_cannot_hold_the_platform(robot, emulator):
    # Inside the box (on its lower x face), where no tensions >= 0 hold the level platform.
    p = [0.5, 1.44, 1.56]
    t_star = _t_star_lp(robot, p)
    assert t_star == pytest.approx(-3.01, abs=0.01)
    message = _refused_at(robot, emulator, p)
    assert (f"the cables cannot hold the level platform (2.5 kg) at the platform centre p = "
            f"[0.500, 1.440, 1.560] m (from the measured cable lengths): its largest achievable "
            f"minimum tension t* is {t_star:.2f} N < 0 N") in message, message


def test_the_start_check_bounds(robot):
    """What start_pose_problem lets through: inside the box to within 1 mm
    (START_BOX_TOLERANCE), and held with t* >= 0 N (START_MIN_T_STAR), also where t* is below
    the 5 N floor of `cdpm info` (hardware/reels.py says why)."""
    from cdpm_drake.hardware.reels import start_pose_problem

    held = [1.0, 1.44, 0.72]  # t* 3.58 N by the LP: held, below 5 N
    assert 0.0 < _t_star_lp(robot, held) < 5.0
    assert start_pose_problem(robot, held) == ""
    upper = robot.workspace.upper
    face = np.array([upper[0], 2.4, 1.2])  # on the upper x face, t* > 0 there
    assert _t_star_lp(robot, face) > 0.0
    assert start_pose_problem(robot, face + [0.0009, 0, 0]) == ""
    out = start_pose_problem(robot, face + [0.0011, 0, 0])
    assert "outside the workspace box" in out and "(1.1 mm beyond its x upper face)" in out
    below = start_pose_problem(robot, [1.75, 0.7, 1.2])
    assert "(100.0 mm beyond its y lower face)" in below, below


def test_a_robot_that_cannot_balance_moments_is_judged_as_a_point():
    """The README's four-cable robot translates only (rank < 6): off the centre its level
    platform's moments never balance (t* = -inf), so its start is judged by the forces
    alone, the platform as a point."""
    from cdpm_drake.hardware.reels import start_pose_problem
    from cdpm_drake.robot import Robot

    reels = [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [2.0, 3.0, 0.0], [2.0, 1.5, 3.0]]
    b = [[-0.1, -0.1, 0.0], [0.1, -0.1, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]]
    four = Robot("four", reels, b, ([1.5, 1.0, 0.5], [2.5, 2.0, 2.0]))
    held = [2.1, 1.5, 1.25]
    assert _t_star_lp(four, held) == -np.inf and _t_star_lp(four, held, point=True) >= 0
    assert start_pose_problem(four, held) == ""
    corner = [2.4, 1.9, 1.9]  # inside the box; the bottom cables pull the point off balance
    t_point = _t_star_lp(four, corner, point=True)
    assert t_point < 0
    message = start_pose_problem(four, corner)
    assert ("cannot hold the platform as a point (forces only: the robot's cables cannot "
            f"balance moments) (2.5 kg) at the platform centre p = [2.400, 1.900, 1.900] m "
            f"(from the measured cable lengths): its largest achievable minimum tension t* is "
            f"{t_point:.2f} N < 0 N") in message, message


def test_refuses_to_enable_when_the_bridge_reports_a_fault(robot, emulator):
    server = emulator(faults=FaultPlan(fault_bits=FAULT_ESTOP))
    server.inject(FaultPlan(fault_bits=FAULT_ESTOP))  # from now, before any enabling command
    time.sleep(0.01)
    diagram, reels = _diagram(robot, server, _command())
    try:
        with pytest.raises(ReelFault, match=r"bridge reports fault bits 0x0001 \(ESTOP\) at "
                                            r"startup"):
            Simulator(diagram).Initialize()
    finally:
        reels.close()


def test_startup_times_out_without_a_bridge(robot):
    import socket

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()  # nothing listens there
    cfg = HardwareReels(port=port, startup_timeout=0.1)
    reels = HardwareReelsSystem(robot, cfg)
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(np.zeros(7)))
    builder.AddSystem(reels)
    builder.Connect(source.get_output_port(), reels.GetInputPort("reel_velocity_command"))
    start = time.monotonic()
    try:
        with pytest.raises(ReelFault, match=rf"no valid status from the reel bridge at "
                                            rf"127.0.0.1:{port} within startup_timeout = 0.1 s"):
            Simulator(builder.Build()).Initialize()
    finally:
        reels.close()
    assert time.monotonic() - start < 1.0


# --- real-time runs --------------------------------------------------------------------------


def test_lengths_follow_the_ramped_command(robot, p0, emulator):
    server = emulator()
    u = _command()
    ramp = 0.1
    diagram, reels = _diagram(robot, server, u, ramp_time=ramp, **RELAXED)
    simulator = Simulator(diagram)
    duration = 1.0
    try:
        start_realtime(simulator)
        simulator.AdvanceTo(duration)
        ctx = reels.GetMyContextFromRoot(simulator.get_context())
        measured = reels.GetOutputPort("cable_lengths").Eval(ctx)
        counters = reels.link.counters
    finally:
        reels.close()
    time.sleep(0.01)  # the emulator reads its socket every 2 ms
    commands = [c for c in server.commands if c.enable]
    # Every tick's command is the ramp times the input: min(1, t / ramp_time) u, where
    # t = k T is the command's own time field (the ramp steps by T / ramp_time per tick).
    for c in commands:
        np.testing.assert_allclose(c.velocity, min(1.0, c.command_time / ramp) * u,
                                   rtol=1e-9, atol=1e-15)
    times = np.array([c.command_time for c in commands])
    assert times[0] == 0.0 and np.allclose(np.diff(times), T)  # one command per tick, no gap
    assert len(commands) == round(duration / T) + 1
    # The lag is linear and every command is proportional to u, so each cable moved by the
    # same multiple of its command, in the controller's last reading (b) and in the reels
    # (a, read after the run); cables with u = 0 did not move at all.
    l0 = cable_lengths(robot, p0)
    moving = u != 0
    for lengths in (measured, server.bridge.lengths):
        np.testing.assert_array_equal(lengths[~moving], l0[~moving])
        ratio = (lengths - l0)[moving] / u[moving]
        np.testing.assert_allclose(ratio, ratio[0], rtol=1e-9)
    b = (measured - l0)[0] / u[0]
    a = (server.bridge.lengths - l0)[0] / u[0]
    # b is the run's effective duration: the run minus half the ramp, minus the lag, minus the
    # link latency of a tick or two: 1 - 0.05 - 0.01 - ~0.004 s. Allow 3 % for scheduling.
    assert b == pytest.approx(duration - ramp / 2 - TAU - 2 * T, rel=0.03)
    # After the controller's last reading the reels ran on for a few ticks until the shutdown
    # command, then coasted down the lag (tau of travel at full speed).
    assert 0 < a - b < TAU + 6 * T
    assert counters.lost == 0 and counters.foreign == 0


class _Stall(LeafSystem):
    """Blocks the simulator for `pause` s at time `at`, like a GC pause or a busy host."""

    def __init__(self, at, pause):
        super().__init__()
        self._pause = pause
        self.DeclarePeriodicPublishEvent(1.0, at, lambda context: time.sleep(self._pause))


def test_a_catch_up_burst_after_a_stall_does_not_trip_the_watchdog(robot, emulator):
    # After a 60 ms stall the simulator runs the missed ~30 ticks back to back, far faster
    # than the bridge sends; counting ticks alone would trip a 10-tick watchdog in that burst
    # (and does, with the wall-clock condition removed). 10 ticks = 20 ms rides out host
    # hiccups; the bridge's own command watchdog is widened past the stall.
    server = emulator(command_timeout=0.2)
    diagram, reels = _diagram(robot, server, _command(), extra=_Stall(at=0.1, pause=0.06),
                              watchdog_ticks=10)
    simulator = Simulator(diagram)
    try:
        start_realtime(simulator)
        simulator.AdvanceTo(0.25)
        book = reels.book(reels.GetMyContextFromRoot(simulator.get_context()))
    finally:
        reels.close()
    assert book["fault"] == 0.0


FAULTS = {
    # A busy host can add a tick or two before the wall-clock condition holds: \d+ ticks.
    "stop": (FaultPlan(stop=True), r"no valid status from the reel bridge at 127.0.0.1:\d+ for "
                                   r"\d+ ticks \(\d+ ms; watchdog_ticks = 3\)"),
    "freeze": (FaultPlan(freeze=True), r"ticks .* last rejected datagram: sequence \d+ "
                                       r"repeats the last accepted one"),
    "nan": (FaultPlan(nan=True), r"ticks .* last rejected datagram: lengths of cable 1 "
                                 r"is nan m"),
    "corrupt": (FaultPlan(corrupt=1.0), r"ticks .* rejected \{'(crc|magic|version|"
                                        r"cable_count|flags)': \d+"),
    "fault_bit": (FaultPlan(fault_bits=FAULT_DRIVE), r"the reel bridge reports fault bits "
                                                     r"0x0002 \(DRIVE\)"),
}


def _run_into_fault(robot, emulator, plan, attempts=3):
    """Run until the reels stop the run, with the fault injected 0.1 s after enabling; retry
    when a loaded host tripped the watchdog before the injection (detected exactly: the
    controller disabled the reels before the emulator's onset)."""
    early = []
    for _ in range(attempts):
        server = emulator(faults=dataclasses.replace(plan, after=0.1))
        diagram, reels = _diagram(robot, server, _command(), ramp_time=0.0)
        simulator = Simulator(diagram)
        try:
            start_realtime(simulator)
            with pytest.raises(ReelFault) as info:
                simulator.AdvanceTo(1.0)
        finally:
            reels.close()
        time.sleep(0.01)
        commands = list(server.commands)
        enabled_at = next(k for k, c in enumerate(commands) if c.enable)
        if not any(not c.enable and not c.fault_active for c in commands[enabled_at:]):
            return server, commands, info.value
        early.append(str(info.value))
    pytest.skip(f"host too busy for 500 Hz on loopback: the watchdog tripped before the "
                f"injected fault in {attempts} attempts; last: {early[-1]}")


@pytest.mark.parametrize("name", list(FAULTS))
def test_each_fault_ends_in_zero_velocity_within_three_ticks(name, robot, emulator):
    plan, message = FAULTS[name]
    server, commands, error = _run_into_fault(robot, emulator, plan)
    assert re.search(r"reel fault at t = [\d.]+ s: .*" + message, str(error)), str(error)
    assert "zero reel velocity sent" in str(error)
    after = [c for c in commands if c.fault_active]
    moving = [c for c in after if c.enable and np.any(c.velocity != 0)]
    # The emulator marks the onset on its tick before sending that tick's status; commands it
    # reads later were sent after it. A fault bit is seen by the first controller update
    # after that status arrives (+1 command when the onset falls between a publish and its
    # update, +1 for the bridge reading a command sent just before its onset a tick late).
    # A bad or missing status needs watchdog_ticks = 3 silent updates by definition, plus the
    # same two. (Typical on an idle host: 0 and 2.)
    bound = 3 if name == "fault_bit" else 3 + 2
    assert len(moving) <= bound, [(c.tick, c.sequence) for c in after]
    # It ends with zero velocity, enable off, and nothing moving after it.
    first_stop = next(k for k, c in enumerate(after) if not c.enable)
    assert all(not c.enable and np.all(c.velocity == 0) for c in after[first_stop:])
    # The stop was read within that many bridge ticks of the onset (+1: reading lags a tick).
    assert after[first_stop].tick - server.fault_onset_tick <= bound + 1


def test_a_non_finite_command_is_never_sent(robot, emulator):
    server = emulator()
    u = np.zeros(7)
    u[3] = np.nan
    diagram, reels = _diagram(robot, server, u)
    simulator = Simulator(diagram)
    try:
        with pytest.raises(ReelFault, match=r"reel_velocity_command of cable 4 is nan m/s; "
                                            r"zero reel velocity sent"):
            start_realtime(simulator)
    finally:
        reels.close()
    time.sleep(0.01)
    assert not any(c.enable for c in server.commands)


def test_shutdown_sends_zero_with_enable_off(robot, emulator):
    server = emulator()
    diagram, reels = _diagram(robot, server, _command(), ramp_time=0.0, **RELAXED)
    simulator = Simulator(diagram)
    try:
        start_realtime(simulator)
        simulator.AdvanceTo(0.05)
        reels.shutdown()
        time.sleep(0.01)
        tail = list(server.commands)[-3:]
        # shutdown_repeats = 3 copies, each with its own, newer sequence number.
        assert [c.enable for c in tail] == [False] * 3
        assert all(np.all(c.velocity == 0) for c in tail)
        assert np.all(np.diff([c.sequence for c in tail]) == 1)
        assert not server.bridge.enabled
        # The last enabled command carried the full input (ramp_time 0).
        last_on = [c for c in server.commands if c.enable][-1]
        np.testing.assert_allclose(last_on.velocity, _command())
    finally:
        reels.close()


def test_commands_above_the_reel_speed_limit_are_scaled_not_clipped(robot, emulator):
    server = emulator()
    u = _command() * 20.0  # peak 1.8 m/s against the robot's 1.0 m/s
    diagram, reels = _diagram(robot, server, u, ramp_time=0.0, **RELAXED)
    simulator = Simulator(diagram)
    try:
        start_realtime(simulator)
        simulator.AdvanceTo(0.02)
    finally:
        reels.close()
    last_on = [c for c in server.commands if c.enable][-1]
    # Scaled as a whole to the limit: the direction of the motion is kept.
    np.testing.assert_allclose(last_on.velocity, u * (1.0 / 1.8), rtol=1e-12)
    assert math.isclose(np.max(np.abs(last_on.velocity)), robot.limits.max_reel_speed)


# --- the watchdog's hold and resume, on a scripted link (no sockets, no real time) -----------

U = _command()


def _scripted(monkeypatch, robot, p0, script, **config):
    """The reels on a ScriptedLink, with a constant command U; ramp_time 0.1 s unless given
    (the ramp steps by T / 0.1 = 0.02 per tick)."""
    config.setdefault("ramp_time", 0.1)
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(U))
    reels = builder.AddNamedSystem("reels", HardwareReelsSystem(
        robot, HardwareReels(**config), time_step=T))
    builder.Connect(source.get_output_port(), reels.GetInputPort("reel_velocity_command"))
    link = ScriptedLink(cable_lengths(robot, p0), script)
    install(monkeypatch, reels, link)
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    return simulator, reels, link


def _silent(ticks, then=answering):
    """The bridge sends nothing during `ticks` (a paused bridge), `then(tick, link)` else."""
    return lambda k, link: [] if k in ticks else then(k, link)


# Ticks 50, 51, 52 silent: the watchdog (3 ticks, and 2 periods of wall time since the status
# of tick 49) stops the reels in the update of tick 52, at t = 51 T (tick k updates at
# (k - 1) T).
TRIP_TICK, TRIP_TIME = 52, 51 * T


def _book(simulator, reels):
    return reels.book(reels.GetMyContextFromRoot(simulator.get_context()))


def test_the_watchdog_stops_at_once_and_resumes_when_the_bridge_answers(monkeypatch, robot, p0):
    # The bridge pauses for 5 ticks (50..54) and answers the stop at tick 55: 3 ticks after
    # the stop, 6 ms of the default resume_within = 15 ms.
    simulator, reels, link = _scripted(monkeypatch, robot, p0, _silent(range(50, 55)))
    simulator.AdvanceTo(0.2)
    book = _book(simulator, reels)
    assert book["fault"] == 0 and book["holds"] == 1
    assert book["longest_hold"] == pytest.approx(3 * T, abs=1e-9)  # ticks 52 -> 55
    # The stop: shutdown_repeats (3) zero commands with enable off, sent by tick 52's update;
    # the command before it (tick 51's publish) still moved the reels.
    stop = link.commands_at(TRIP_TICK)
    assert len(stop) == 3 and all(not on and np.all(v == 0) for _, _, on, v in stop)
    assert link.commands_at(TRIP_TICK - 1)[-1][2]
    # Nothing while the watchdog waits (the publishes after ticks 53 and 54 send nothing).
    assert not link.commands_at(53) and not link.commands_at(54)
    # Resumed with tick 55: enabled, the ramp from rest again (T / ramp_time per tick).
    for k in range(55, 60):
        (_, _, on, v), = link.commands_at(k)
        np.testing.assert_allclose(v, (k - 54) * 0.02 * U, rtol=1e-12)
        assert on


def test_a_bridge_that_does_not_answer_the_stop_ends_the_run(monkeypatch, robot, p0):
    # Statuses keep coming during the hold, but echo the last command before the stop (the
    # one sent right before tick 52's update): the bridge never read the stop. After
    # resume_within = 15 ms (8 ticks of 2 ms after the stop; 7 ticks are 14 ms) the fault
    # latches, timed at the stop.
    before = {}

    def stale(k, link):
        if k in (50, 51, 52):
            before["echo"] = link.sequence
            return []
        return [(0, before.get("echo", link.sequence), 0)]

    simulator, reels, link = _scripted(monkeypatch, robot, p0, stale)
    with pytest.raises(ReelFault) as fault:
        simulator.AdvanceTo(0.2)
    message = str(fault.value)
    assert message.startswith(f"reel fault at t = {TRIP_TIME:.3f} s: no valid status from the "
                              "reel bridge at 127.0.0.1:47100 for 3 ticks (6 ms; "
                              "watchdog_ticks = 3), and none answered the stop within "
                              "resume_within = 15 ms; zero reel velocity sent.")
    assert fault.value.time == pytest.approx(TRIP_TIME)
    assert _book(simulator, reels)["holds"] == 0
    assert link.tick == TRIP_TICK + 8
    # One stop, nothing after it: the fault's own shutdown sends no second burst.
    assert [on for _, _, on, _ in link.sent[-4:]] == [True, False, False, False]
    assert link.sent[-1][0] == TRIP_TICK


def test_statuses_lost_during_the_silence_end_the_run(monkeypatch, robot, p0):
    # The bridge answers the stop at tick 54, but two statuses went missing on the way: a
    # lossy link, not a paused bridge.
    def lossy(k, link):
        if k in (50, 51, 52, 53):
            return []
        return [(2 if k == 54 else 0, link.sequence, 0)]

    simulator, reels, link = _scripted(monkeypatch, robot, p0, lossy)
    with pytest.raises(ReelFault, match=r"for 3 ticks \(6 ms; watchdog_ticks = 3\), and the "
                                        r"statuses that came back had skipped 2 \(lost or "
                                        r"rejected on the way: a faulty link"):
        simulator.AdvanceTo(0.2)
    assert link.tick == 54 and link.sent[-1][0] == TRIP_TICK


def test_a_fault_bit_while_the_watchdog_holds_ends_the_run(monkeypatch, robot, p0):
    def faulty(k, link):
        return [] if k in (50, 51, 52) else [(0, link.sequence, FAULT_DRIVE if k >= 53 else 0)]

    simulator, reels, link = _scripted(monkeypatch, robot, p0, faulty)
    with pytest.raises(ReelFault, match=r"fault bits 0x0002 \(DRIVE\)"):
        simulator.AdvanceTo(0.2)
    assert _book(simulator, reels)["holds"] == 0
    assert link.sent[-1][0] == TRIP_TICK  # nothing sent after the stop


def test_resume_within_zero_latches_at_the_stop(monkeypatch, robot, p0):
    # As before holds existed: the same pause of 5 ticks ends the run at the stop.
    simulator, reels, link = _scripted(monkeypatch, robot, p0, _silent(range(50, 55)),
                                       resume_within=0.0)
    with pytest.raises(ReelFault) as fault:
        simulator.AdvanceTo(0.2)
    assert ("for 3 ticks (6 ms; watchdog_ticks = 3); zero reel velocity sent."
            in str(fault.value))
    assert fault.value.time == pytest.approx(TRIP_TIME)
    assert link.tick == TRIP_TICK  # the publish right after the stop ended the run


def test_a_silence_just_short_of_the_watchdog_never_stops(monkeypatch, robot, p0):
    # Two silent ticks (watchdog_ticks = 3): the reels never stop, the ramp never restarts.
    simulator, reels, link = _scripted(monkeypatch, robot, p0, _silent(range(50, 52)))
    simulator.AdvanceTo(0.2)
    # The scripted bridge speaks version 1: two greetings (version 2, then 1) settle it.
    assert [on for _, _, on, _ in link.sent[:2]] == [False, False]
    assert all(on for _, _, on, _ in link.sent[2:])
    assert _book(simulator, reels)["holds"] == 0
