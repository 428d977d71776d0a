"""The reel-bridge emulator: its reel physics in closed form, and its server on loopback with
every fault it can inject. A raw UDP socket plays the controller here; the Drake system
against the emulator is tested in test_hardware_reels.py."""

import math
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from cdpm_drake import emulator as E
from cdpm_drake.emulator import FaultPlan, ReelBridge, ReelBridgeServer
from cdpm_drake.emulator.server import count_by_reason, vector_text
from cdpm_drake.hardware.protocol import (FAULT_COMMAND_TIMEOUT, FAULT_DRIVE, FAULT_OVERSPEED,
                                          Command, ProtocolError, decode_status,
                                          encode_command)
from cdpm_drake.kernels.kinematics import cable_lengths, jacobian
from cdpm_drake.robot import load_robot
from cdpm_drake.config import load_scenario


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


@pytest.fixture(scope="module")
def p0(robot):
    return robot.workspace.center + np.array([0.1, -0.2, 0.05])


# --- physics ---------------------------------------------------------------------------------


def test_lag_matches_the_closed_form_from_rest(robot, p0):
    # A first-order lag from rest under a constant command c: speed c (1 - e^{-t/tau}),
    # length l0 + c t - c tau (1 - e^{-t/tau}).
    l0 = cable_lengths(robot, p0)
    c = np.linspace(-0.3, 0.3, 7)
    tau, t = 0.05, 0.137
    bridge = ReelBridge(robot, l0, time_constant=tau)
    bridge.set_command(c, enable=True)
    for _ in range(137):
        bridge.step(0.001)
    a = math.exp(-t / tau)
    np.testing.assert_allclose(bridge.speed, c * (1 - a), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(bridge.lengths, l0 + c * t - c * tau * (1 - a),
                               rtol=0, atol=1e-12)
    # The update is exact, so one big step lands on the same point.
    one = ReelBridge(robot, l0, time_constant=tau)
    one.set_command(c, enable=True)
    one.step(t)
    np.testing.assert_allclose(one.lengths, bridge.lengths, rtol=0, atol=1e-12)


def test_ideal_drives_integrate_the_command(robot, p0):
    l0 = cable_lengths(robot, p0)
    bridge = ReelBridge(robot, l0, time_constant=0.0)
    bridge.set_command(np.full(7, 0.2), enable=True)
    bridge.step(0.5)
    np.testing.assert_allclose(bridge.lengths, l0 + 0.1, rtol=0, atol=1e-14)


def test_disabled_or_faulted_reels_hold_still(robot, p0):
    l0 = cable_lengths(robot, p0)
    bridge = ReelBridge(robot, l0, time_constant=0.0)
    bridge.set_command(np.full(7, 0.2), enable=False)
    bridge.step(0.5)
    np.testing.assert_array_equal(bridge.lengths, l0)
    bridge.raise_fault(FAULT_DRIVE)
    bridge.set_command(np.full(7, 0.2), enable=True)  # a fault refuses enabling
    bridge.step(0.5)
    assert not bridge.enabled and bridge.faults == FAULT_DRIVE
    np.testing.assert_array_equal(bridge.lengths, l0)


def test_a_command_above_the_reel_speed_limit_raises_overspeed(robot, p0):
    bridge = ReelBridge(robot, cable_lengths(robot, p0))
    v = np.zeros(7)
    v[3] = robot.limits.max_reel_speed * 1.01
    bridge.set_command(v, enable=True)
    assert bridge.faults == FAULT_OVERSPEED and not bridge.enabled


def test_the_operator_sees_time_from_enable_and_the_platform_motion(robot, p0):
    # Cable speeds J v0 move the platform at v0 (eq. 3); the emulator recovers v0 and the
    # pose from the lengths alone.
    seen = []
    v0 = np.array([0.05, -0.02, 0.01])
    bridge = ReelBridge(robot, cable_lengths(robot, p0), time_constant=0.0,
                        force=lambda t, p, v: seen.append((t, p, v)) or np.array([1.0, 2, 3]))
    np.testing.assert_allclose(bridge.force(), [1, 2, 3])
    bridge.step(0.25)  # before any enabling command, operator time stays 0
    bridge.set_command(jacobian(robot, p0) @ v0, enable=True)
    bridge.step(1e-4)
    assert seen[0][0] == 0.0
    np.testing.assert_allclose(seen[0][1], p0, atol=1e-9)
    bridge.force()
    t, p, v = seen[-1]
    assert t == pytest.approx(1e-4, abs=1e-15)
    # Over 0.1 mm of travel the Jacobian barely changes: v matches to O(|dp|).
    np.testing.assert_allclose(v, v0, atol=1e-5)
    np.testing.assert_allclose(p, p0 + v0 * 1e-4, atol=1e-8)


def test_bad_inputs_are_named(robot):
    with pytest.raises(ValueError, match=r"initial_lengths must have 7 entries"):
        ReelBridge(robot, np.ones(6))
    with pytest.raises(ValueError, match=r"drop must be a share in \[0, 1\], got 1.5"):
        FaultPlan(drop=1.5)
    with pytest.raises(ValueError, match=r"after must be a finite number >= 0 s, got -1"):
        FaultPlan(after=-1)


# --- the dynamic plant behind the bridge (--plant dynamic, issue 21) ------------------------


def _dynamic_resolved(overlay="{}"):
    """exp2's scenario (cables 1 and 3 swapped, its start and hand) on the dynamic plant."""
    from cdpm_drake.config import resolve_scenario

    return resolve_scenario(load_scenario(
        "exp2_interaction", f"{{plant: !DynamicReels {{}}, operator: !ScriptedOperator "
        f"{{times: [0.0, 0.2], forces: [[0, 0, 0], [3.0, -2.0, 4.0]]}}}}"))


def _plant_alone_run(resolved, command, duration):
    """The same plant driven by a Simulator of its own (the reference): its state and
    measured force after `duration` s of a constant `command`, and its logged truth."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from cdpm_drake.diagram import make_plant
    from cdpm_drake.systems.plants.dynamic_plant import ground_truth_log, plant_state_now

    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("reels", make_plant(resolved))
    source = builder.AddSystem(ConstantVectorSource(np.asarray(command, dtype=float)))
    builder.Connect(source.get_output_port(), plant.GetInputPort("reel_velocity_command"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    force = plant.GetOutputPort("measured_force").Eval(plant.GetMyContextFromRoot(context))
    return plant_state_now(diagram, context), force, ground_truth_log(diagram, context)


def test_the_dynamic_bridge_is_the_dynamic_plant_on_the_bridges_clock():
    # Enabled at bridge time 0.3 s, then 250 ticks of 2 ms: the plant (and its operator) has
    # run 0.5 s, exactly as the same plant under its own Simulator for 0.5 s: the encoders read
    # its L0 plus the start stretch, the force sensor its measured force, bit for bit.
    resolved = _dynamic_resolved()
    bridge = E.DynamicBridge(resolved)
    robot = resolved.robot
    p0 = np.asarray(resolved.scenario.initial_position)
    start = bridge.lengths.copy()
    # Zeroed at the start pose: the rigid lengths there, which forward kinematics fits exactly.
    np.testing.assert_allclose(start, cable_lengths(robot, p0), rtol=0, atol=1e-12)
    command = np.array([0.01, -0.02, 0.005, 0.0, 0.015, -0.01, 0.02])
    for _ in range(150):  # not enabled: nothing moves, whatever the clock
        bridge.step(0.002)
    np.testing.assert_array_equal(bridge.lengths, start)
    bridge.set_command(command, enable=True)
    assert bridge.operator_start == pytest.approx(0.3)
    for _ in range(250):
        bridge.step(0.002)
    assert bridge.plant_time == 0.5
    state, force, truth = _plant_alone_run(resolved, command, 0.5)
    # The start stretch, L - L0 with L0 = L EA / (EA + T) at the start distribution T.
    from cdpm_drake.config import check_dynamic_reels

    L = cable_lengths(robot, p0)
    EA = robot.dynamics.EA
    offset = L - L * EA / (EA + check_dynamic_reels(resolved.scenario, robot).tensions)
    np.testing.assert_allclose(bridge.lengths, state["L0"] + offset, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(bridge.speed, state["reel_speeds"])
    np.testing.assert_array_equal(bridge.force(), force)
    assert np.abs(state["L0"] - (start - offset)).max() > 1e-3  # the reels did move
    assert np.linalg.norm(force) > 4.0  # and the hand pushes
    # The summary's tension range and tilt come from the plant's own truth, tick by tick (its
    # logger samples at 2 ms too).
    assert bridge.driven.min_tension == pytest.approx(truth["tensions"].min(), abs=1e-9)
    assert bridge.driven.max_tension == pytest.approx(truth["tensions"].max(), abs=1e-9)
    assert (bridge.driven.slack_ticks.tolist()
            == truth["slack"][1:].sum(axis=0).astype(int).tolist())
    assert "tensions" in bridge.summary() and "slack ticks per cable" in bridge.summary()


def test_the_dynamic_summary_keeps_what_happened_after_the_reels_stopped_apart():
    # Driven for 0.2 s, then disabled while the platform moves and the operator pushes on:
    # the drives brake and the tensions rise past anything seen while driven (a CI run's
    # summary once reported 38.8 N after a 2 s run whose tensions stayed under 26 N). The
    # summary keeps the driven ticks apart from the stopped ones; the reference is the same
    # plant alone under its own Simulator with the command dropped to zero at 0.2 s.
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial

    from cdpm_drake.diagram import make_plant
    from cdpm_drake.systems.plants.dynamic_plant import ground_truth_log

    resolved = _dynamic_resolved()
    command = np.array([0.05, -0.05, 0.05, -0.05, 0.05, -0.05, 0.0])
    bridge = E.DynamicBridge(resolved)
    bridge.set_command(command, enable=True)
    for _ in range(100):
        bridge.step(0.002)
    bridge.set_command(command, enable=False)
    for _ in range(100):
        bridge.step(0.002)
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("reels", make_plant(resolved))
    steps = PiecewisePolynomial.ZeroOrderHold(
        [0.0, 0.2, 1.0], np.column_stack([command, np.zeros(7), np.zeros(7)]))
    source = builder.AddSystem(TrajectorySource(steps))
    builder.Connect(source.get_output_port(), plant.GetInputPort("reel_velocity_command"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.4)
    truth = ground_truth_log(diagram, simulator.get_context())
    T = truth["tensions"][:201]
    driven, stopped = T[:101], T[101:]
    assert stopped.max() > driven.max() + 1.0  # the stop is what raised them
    assert bridge.stop_time == pytest.approx(0.2)
    assert bridge.driven.ticks == 101 and bridge.stopped.ticks == 100
    assert bridge.driven.max_tension == pytest.approx(driven.max(), abs=1e-9)
    assert bridge.driven.min_tension == pytest.approx(driven.min(), abs=1e-9)
    assert bridge.stopped.max_tension == pytest.approx(stopped.max(), abs=1e-9)
    assert bridge.stopped.min_tension == pytest.approx(stopped.min(), abs=1e-9)
    summary = bridge.summary()
    assert summary.startswith(f"dynamic plant over 101 ticks: tensions {driven.min():.2f}.."
                              f"{driven.max():.2f} N"), summary
    assert (f"; after the reels stopped at t = 0.200 s, 100 ticks: tensions "
            f"{stopped.min():.2f}..{stopped.max():.2f} N") in summary, summary
    assert summary.endswith("(plant time 0..0.400 s)"), summary


def _reference_truth(resolved, command, switches, duration):
    """The plant alone under its own Simulator, its command `command` or zero between the
    `switches` times (s; on from 0, off at the first, on at the second...): its logged
    ground truth to `duration` s (rows every 2 ms, the emulator's ticks)."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial

    from cdpm_drake.diagram import make_plant
    from cdpm_drake.systems.plants.dynamic_plant import ground_truth_log

    times = [0.0, *switches, duration + 1.0]
    columns = [command if k % 2 == 0 else np.zeros(7) for k in range(len(times))]
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("reels", make_plant(resolved))
    source = builder.AddSystem(TrajectorySource(PiecewisePolynomial.ZeroOrderHold(
        times, np.column_stack(columns))))
    builder.Connect(source.get_output_port(), plant.GetInputPort("reel_velocity_command"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(duration)
    return ground_truth_log(diagram, simulator.get_context())


def test_ticks_the_controller_drives_after_it_resumed_are_driven_ones_again():
    # Driven 0.2 s, stopped 0.1 s, resumed (enabled again) for 0.1 s, as the controller does
    # after a watchdog stop the bridge answered. Before, every tick after the first stop was
    # counted "after the reels stopped", the resumed driving's slack included; the reference
    # is the plant alone under its own Simulator with the same command switches. The ceiling
    # (controller.max_tension) is set between the driven and the stopped peak tensions: the
    # report names the cables above it, with their peaks and ticks, per part.
    from cdpm_drake.config import resolve_scenario

    command = np.array([0.05, -0.05, 0.05, -0.05, 0.05, -0.05, 0.0])
    truth = _reference_truth(_dynamic_resolved(), command, [0.2, 0.3], 0.4)
    T, slack = truth["tensions"][:201], truth["slack"][:201].astype(bool)
    stopped_rows = np.zeros(201, dtype=bool)
    stopped_rows[101:151] = True  # plant ticks 0.202..0.300 s
    ceiling = round(float(T[~stopped_rows].max()) - 1.0)
    resolved = resolve_scenario(load_scenario(
        "exp2_interaction", f"{{plant: !DynamicReels {{}}, operator: !ScriptedOperator "
        f"{{times: [0.0, 0.2], forces: [[0, 0, 0], [3.0, -2.0, 4.0]]}}, controller: "
        f"{{max_tension: {ceiling}}}}}"))
    bridge = E.DynamicBridge(resolved)
    for enable, ticks in ((True, 100), (False, 50), (True, 50)):
        bridge.set_command(command, enable=enable)
        for _ in range(ticks):
            bridge.step(0.002)
    assert bridge.driven.ticks == 151 and bridge.stopped.ticks == 50  # before: 101 and 100
    assert bridge.stops == 1 and bridge.resumes == 1
    assert bridge.stop_time == pytest.approx(0.2)
    for record, rows in ((bridge.driven, ~stopped_rows), (bridge.stopped, stopped_rows)):
        assert record.max_tension == pytest.approx(T[rows].max(), abs=1e-9)
        assert record.slack_ticks.tolist() == slack[rows].sum(axis=0).astype(int).tolist()
        np.testing.assert_array_equal(record.over_ticks, (T[rows] > ceiling).sum(axis=0))
    summary = bridge.summary()
    assert summary.startswith("dynamic plant over 151 ticks the controller drove (it resumed "
                              "1 time after a stop): "), summary
    assert "; while the reels were stopped (1 stop, the first at t = 0.200 s), 50 ticks: " \
        in summary, summary
    driven_part = summary.split("; while the reels")[0]
    over = np.flatnonzero((T[~stopped_rows] > ceiling).any(axis=0))
    assert over.size  # the ceiling is 1 N under the driven peak
    assert f"ABOVE the ceiling controller.max_tension = {ceiling:g} N: " in driven_part
    rows = np.flatnonzero(~stopped_rows)
    for i in over:
        k = rows[int(np.argmax(T[rows, i]))]
        n = int((T[rows, i] > ceiling).sum())
        assert (f"cable {i + 1} up to {T[k, i]:.2f} N at t = {0.002 * k:.3f} s "
                f"({n} tick{'s' if n != 1 else ''})") in driven_part, driven_part


def test_a_session_within_the_ceiling_reports_no_overload():
    bridge = E.DynamicBridge(_dynamic_resolved())
    bridge.set_command(np.zeros(7), enable=True)
    for _ in range(20):
        bridge.step(0.002)
    assert bridge.driven.max_tension < bridge.ceiling == 100.0
    assert "ABOVE" not in bridge.summary()


def test_a_faulted_dynamic_bridge_stops_its_drives_with_their_own_dynamics():
    resolved = _dynamic_resolved()
    bridge = E.DynamicBridge(resolved)
    bridge.set_command(np.full(7, 0.05), enable=True)
    for _ in range(50):
        bridge.step(0.002)
    moving = np.abs(bridge.speed).max()
    assert moving > 0.04  # bandwidth 100 rad/s: 0.1 s is 10 time constants
    bridge.raise_fault(FAULT_DRIVE)
    bridge.set_command(np.full(7, 0.05), enable=True)  # a fault refuses enabling
    assert not bridge.enabled and bridge.faults == FAULT_DRIVE
    bridge.step(0.002)
    # One 2 ms tick later the drives are slowing (a first-order loop, not a jump to zero),
    # and a few time constants later they stand still (friction holds them).
    assert 0.0 < np.abs(bridge.speed).max() < moving
    for _ in range(100):
        bridge.step(0.002)
    assert np.abs(bridge.speed).max() == 0.0
    # Overspeed, as with the kinematic bridge.
    fresh = E.DynamicBridge(resolved)
    fresh.set_command(np.full(7, 1.5), enable=True)  # the robot's limit is 1 m/s
    assert fresh.faults & FAULT_OVERSPEED and not fresh.enabled


def test_emulate_plant_dynamic_honours_the_scenarios_own_dynamic_reels(tmp_path):
    """Issue 27: `cdpm emulate --scenario FILE --plant dynamic` with a scenario whose plant is
    a !DynamicReels of its own: its time step, reel speed limit, start tilt and locked
    rotation are the bridge's, not the defaults'."""
    from cdpm_drake.kernels.rotation import rotation_from_rpy

    scenario = tmp_path / "tilted.yaml"
    scenario.write_text(
        "name: tilted\nrobot: paper_7cable\nswaps: [[1, 3]]\n"
        "initial_position: [1.56, 3.24, 1.22]\n"
        "operator: !NoOperator {}\n"
        "plant: !DynamicReels {time_step: 0.0005, max_reel_speed: 0.5, "
        "initial_rpy: [0.02, -0.01, 0.03], lock_rotation: true}\n")
    args = E.build_parser().parse_args(["--scenario", str(scenario), "--plant", "dynamic",
                                   "--port", "0"])
    server = E.build_server(args)
    try:
        bridge = server.bridge
        mbp = bridge._plant.GetSubsystemByName("platform_plant")
        assert mbp.time_step() == 0.0005 and bridge._h == 0.0005
        # The start tilt: the true orientation at the start, and the encoders zeroed at the
        # tilted pose (its rigid lengths).
        step = bridge._step_port.Eval(bridge._cables_context)
        np.testing.assert_allclose(step[bridge._rpy], [0.02, -0.01, 0.03], atol=1e-12)
        robot = bridge.robot
        R = rotation_from_rpy([0.02, -0.01, 0.03])
        rigid = np.linalg.norm(robot.reels - ([1.56, 3.24, 1.22] + robot.attachments @ R.T),
                               axis=1)
        np.testing.assert_allclose(bridge.lengths, rigid, atol=1e-12)
        # Locked rotation: reels paying out unevenly for 0.2 s turn nothing.
        bridge.set_command(np.array([0.05, -0.05, 0.04, -0.03, 0.02, 0.0, -0.04]), True)
        for _ in range(100):
            bridge.step(0.002)
        assert bridge.plant_time == pytest.approx(0.2)
        step = bridge._step_port.Eval(bridge._cables_context)
        np.testing.assert_allclose(step[bridge._rpy], [0.02, -0.01, 0.03], atol=1e-9)
        assert np.abs(bridge.speed).max() > 0.03  # the reels did move
        # The scenario's reel speed limit, 0.5 m/s (the robot file's is 1 m/s).
        bridge.set_command(np.full(7, 0.45), True)
        assert bridge.faults == 0
        bridge.set_command(np.full(7, 0.55), True)
        assert bridge.faults & FAULT_OVERSPEED
    finally:
        server.stop()


def test_a_reset_puts_the_kinematic_bridge_back_at_its_start(robot, p0):
    # Issue 27: a second rehearsal started where the last one ended. A reset (a homing) puts
    # the reels back at their start lengths, at rest, with the operator's clock stopped; a
    # fault bit the bridge raised stays.
    seen = []
    start = cable_lengths(robot, p0)
    bridge = ReelBridge(robot, start, force=lambda t, p, v: seen.append(t) or np.zeros(3),
                        time_constant=0.01)
    bridge.set_command(np.full(7, 0.05), enable=True)
    for _ in range(100):
        bridge.step(0.002)
    bridge.force()
    assert np.abs(bridge.lengths - start).min() > 0.005 and seen[-1] == pytest.approx(0.2)
    bridge.raise_fault(FAULT_DRIVE)
    bridge.reset()
    np.testing.assert_array_equal(bridge.lengths, start)
    assert not bridge.speed.any() and not bridge.command.any() and not bridge.enabled
    np.testing.assert_allclose(bridge.platform(), p0, atol=1e-9)
    assert bridge.operator_start is None and bridge.faults == FAULT_DRIVE
    bridge.faults = 0
    bridge.step(0.5)  # at rest, the operator's clock stopped: t stays 0 until enabled
    bridge.force()
    assert seen[-1] == 0.0 and np.array_equal(bridge.lengths, start)


def test_a_reset_dynamic_bridge_replays_a_fresh_one_bit_for_bit():
    # After a reset the plant is the one built at the start: the same commands give the same
    # encoders and force as a fresh bridge's, and the session's record starts again.
    resolved = _dynamic_resolved()
    command = np.array([0.01, -0.02, 0.005, 0.0, 0.015, -0.01, 0.02])

    def drive(bridge, ticks=100):
        bridge.set_command(command, enable=True)
        for _ in range(ticks):
            bridge.step(0.002)
        return bridge.lengths.copy(), bridge.force().copy()

    used = E.DynamicBridge(resolved)
    start = used.lengths.copy()
    drive(used, 150)
    assert used.driven.ticks == 151 and np.abs(used.lengths - start).max() > 1e-3
    used.reset()
    np.testing.assert_array_equal(used.lengths, start)
    assert used.plant_time == 0.0 and used.driven.ticks == 1 and used.operator_start is None
    lengths, force = drive(used)
    fresh_lengths, fresh_force = drive(E.DynamicBridge(resolved))
    np.testing.assert_array_equal(lengths, fresh_lengths)
    np.testing.assert_array_equal(force, fresh_force)


def test_the_dynamic_summary_says_when_each_cable_went_slack_and_when_it_tilted_most():
    # Cable 3 paid out at 0.2 m/s for 0.5 s goes slack; the plant's own logger (the same
    # plant under its own Simulator) says on which ticks, the bridge's summary must agree.
    from cdpm_drake.kernels.rotation import rotation_angle, rotations_from_rpy

    resolved = _dynamic_resolved()
    command = np.zeros(7)
    command[2] = 0.2
    bridge = E.DynamicBridge(resolved)
    bridge.set_command(command, enable=True)
    for _ in range(250):
        bridge.step(0.002)
    _, _, truth = _plant_alone_run(resolved, command, 0.5)
    slack = truth["slack"][:251] > 0.5
    t = 0.002 * np.arange(251)
    assert slack[:, 2].any()
    for i in range(7):
        if slack[:, i].any():
            first = t[np.argmax(slack[:, i])]
            assert bridge.driven.first_slack[i] == pytest.approx(first, abs=1e-9)
            assert f"{i + 1}:{int(slack[1:, i].sum())} (first at t = {first:.3f} s)" \
                in bridge.summary()
        else:
            assert np.isnan(bridge.driven.first_slack[i])
    tilt = rotation_angle(rotations_from_rpy(truth["rpy_true"][:251]))
    assert bridge.driven.max_tilt_time == pytest.approx(t[np.argmax(tilt)], abs=1e-9)
    assert bridge.summary().endswith(f"largest tilt {np.degrees(tilt.max()):.2f} deg at t = "
                                     f"{t[np.argmax(tilt)]:.3f} s (plant time 0..0.500 s)")


# --- the server on loopback ------------------------------------------------------------------


class Controller:
    """A raw UDP socket speaking the protocol, as the controller would."""

    def __init__(self, server):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.5)
        self.server = server
        self.seq = 0

    def send(self, velocity, enable=True):
        self.seq += 1
        self.sock.sendto(encode_command(Command(self.seq, 0.0, np.asarray(velocity, float),
                                                enable, None)), self.server.address)

    def receive(self, n):
        return [self.sock.recvfrom(4096)[0] for _ in range(n)]

    def latest(self):
        """The newest status waiting (the socket queues every one since the first command)."""
        time.sleep(0.005)
        self.sock.setblocking(False)
        data = None
        try:
            while True:
                data = self.sock.recvfrom(4096)[0]
        except BlockingIOError:
            pass
        self.sock.settimeout(0.5)
        return data

    def close(self):
        self.sock.close()


@pytest.fixture
def serve(robot, p0):
    started = []

    def start(faults=FaultPlan(), **kw):
        server = ReelBridgeServer(ReelBridge(robot, cable_lengths(robot, p0), time_constant=0),
                                  faults=faults, **kw).start()
        client = Controller(server)
        started.append((server, client))
        return server, client

    yield start
    for server, client in started:
        client.close()
        server.stop()


def test_streams_one_status_per_period_to_the_latest_commander(serve, robot, p0):
    server, ctl = serve()
    ctl.send(np.zeros(7), enable=False)  # tells the bridge where to send
    data = ctl.receive(20)
    statuses = [decode_status(d, 7) for d in data]
    seqs = [s.sequence for s in statuses]
    assert seqs == list(range(seqs[0], seqs[0] + 20))  # no gap, no repeat
    np.testing.assert_allclose(statuses[-1].lengths, cable_lengths(robot, p0), atol=1e-12)
    assert statuses[-1].echo_sequence == 1 and not statuses[-1].enabled
    # 20 statuses at 2 ms: their bridge timestamps span 19 periods (within scheduling jitter).
    span = statuses[-1].time - statuses[0].time
    assert 0.8 * 19 * 0.002 < span < 3 * 19 * 0.002


def test_commands_move_the_reels_and_are_recorded(serve, robot, p0):
    server, ctl = serve()
    v = np.zeros(7)
    v[0], v[6] = 0.1, -0.1
    for _ in range(25):
        ctl.send(v)
        time.sleep(0.002)
    last = decode_status(ctl.latest(), 7)
    moved = last.lengths - cable_lengths(robot, p0)
    # Ideal drives: cable 1 pays out what cable 7 reels in; the others do not move.
    assert moved[0] > 0.001 and moved[0] == pytest.approx(-moved[6], rel=1e-9)
    np.testing.assert_array_equal(moved[1:6], 0.0)
    assert last.enabled
    assert [c.sequence for c in server.commands] == list(range(1, 26))


def test_stop_reads_the_commands_that_arrived_since_the_last_tick(serve):
    """A controller's shutdown burst goes out just before the test (or the user) stops the
    bridge: stop() reads what is waiting instead of closing the socket on it. The commands
    are sent after the serving thread's last tick, so only stop() can read them."""
    server, ctl = serve()
    ctl.send(np.zeros(7), enable=False)
    deadline = time.monotonic() + 2.0
    while not server.commands and time.monotonic() < deadline:
        time.sleep(0.002)
    server._stop.set()  # the serving thread's last tick ...
    server._thread.join(5.0)
    for _ in range(3):  # ... is over before these arrive
        ctl.send(np.zeros(7), enable=False)
    time.sleep(0.01)  # loopback delivery
    server.stop()
    assert [c.sequence for c in server.commands] == [1, 2, 3, 4]
    assert server.counters["commands_received"] == 4


def _run_until_fault(serve, plan):
    """Enable, stream commands until the fault takes effect, drop the statuses sent before
    it (the server marks the onset before sending that tick's status), then collect ~30 ms
    worth."""
    server, ctl = serve(plan)
    deadline = time.monotonic() + 2.0
    while server.fault_onset is None and time.monotonic() < deadline:
        ctl.send(np.zeros(7))
        time.sleep(0.002)
    assert server.fault_onset is not None
    ctl.latest()
    time.sleep(0.03)
    got = []
    ctl.sock.setblocking(False)
    try:
        while True:
            got.append(ctl.sock.recvfrom(4096)[0])
    except BlockingIOError:
        pass
    return server, got


def test_stop_sends_nothing_more(serve):
    server, got = _run_until_fault(serve, FaultPlan(stop=True, after=0.02))
    assert got == []
    sent = server.counters["statuses_sent"]
    assert sent > 0  # statuses flowed until the onset
    time.sleep(0.01)
    assert server.counters["statuses_sent"] == sent


def test_freeze_repeats_one_datagram(serve):
    _, got = _run_until_fault(serve, FaultPlan(freeze=True))
    # ~15 periods in 30 ms, all the same bytes (same sequence number).
    assert len(got) >= 5 and len(set(got)) == 1


def test_nan_datagrams_have_a_valid_crc_but_are_refused(serve):
    _, got = _run_until_fault(serve, FaultPlan(nan=True))
    with pytest.raises(ProtocolError, match=r"lengths of cable 1 is nan m") as info:
        decode_status(got[-1], 7)
    assert info.value.reason == "value"


def test_corrupted_datagrams_are_refused(serve):
    _, got = _run_until_fault(serve, FaultPlan(corrupt=1.0))
    assert len(got) >= 5
    for d in got:
        with pytest.raises(ProtocolError):
            decode_status(d, 7)


def test_fault_bits_are_reported_and_stop_the_reels(serve):
    _, got = _run_until_fault(serve, FaultPlan(fault_bits=FAULT_DRIVE))
    s = decode_status(got[-1], 7)
    assert s.faults == FAULT_DRIVE and not s.enabled


def test_duplicates_and_drops_follow_the_plan(serve):
    _, got = _run_until_fault(serve, FaultPlan(duplicate=1.0))
    seqs = [decode_status(d, 7).sequence for d in got]
    # Every status twice, back to back.
    assert len(seqs) >= 10 and seqs[0::2] == seqs[1::2]
    assert len(set(seqs)) == len(seqs) // 2
    server, got = _run_until_fault(serve, FaultPlan(drop=1.0))
    assert got == [] and server.counters["statuses_dropped"] >= 5


def test_reordering_swaps_neighbours(serve):
    _, got = _run_until_fault(serve, FaultPlan(reorder=1.0))
    seqs = np.array([decode_status(d, 7).sequence for d in got])
    assert np.any(np.diff(seqs) < 0)  # some arrive after a newer one
    assert len(set(seqs.tolist())) == len(seqs)  # but none twice


def test_the_bridge_watchdog_raises_command_timeout(serve):
    server, ctl = serve(command_timeout=0.02)
    ctl.send(np.zeros(7))
    time.sleep(0.06)  # 3 timeouts' worth of silence while enabled
    s = decode_status(ctl.latest(), 7)
    assert s.faults & FAULT_COMMAND_TIMEOUT and not s.enabled


def test_a_fixed_controller_address_ignores_other_commanders(serve, robot):
    other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    other.bind(("127.0.0.1", 0))
    try:
        server, ctl = serve(controller=other.getsockname())
        ctl.send(np.zeros(7))
        deadline = time.monotonic() + 1.0
        while server.counters["commands_foreign"] == 0 and time.monotonic() < deadline:
            time.sleep(0.002)
        assert server.counters["commands_foreign"] == 1
        assert server.counters["commands_received"] == 0
    finally:
        other.close()


# --- command line ----------------------------------------------------------------------------


def test_cli_builds_the_bridge_from_its_flags(robot):
    args = E.build_parser().parse_args(["--robot", "paper_7cable", "--start", "1.5", "3.0", "1.0",
                                   "--length-offset", "2", "0.25", "--port", "0",
                                   "--drop", "0.1", "--fault-after", "2", "--seed", "7"])
    server = E.build_server(args)
    try:
        expected = cable_lengths(robot, np.array([1.5, 3.0, 1.0]))
        expected[1] += 0.25  # cable 2 is index 1
        np.testing.assert_allclose(server.bridge.lengths, expected, atol=1e-12)
        assert server.faults == FaultPlan(drop=0.1, after=2.0)
        assert server.address[0] == "127.0.0.1"
    finally:
        server.stop()


def test_cli_takes_robot_start_and_operator_from_a_scenario():
    from cdpm_drake.config import load_scenario, scenario_robot

    args = E.build_parser().parse_args(["--scenario", "exp2_interaction", "--port", "0"])
    server = E.build_server(args)
    try:
        scenario = load_scenario("exp2_interaction")
        r = scenario_robot(scenario)  # with the scenario's cable swaps
        assert server.bridge.robot.name == r.name
        np.testing.assert_allclose(server.bridge.lengths,
                                   cable_lengths(r, np.array(scenario.initial_position)),
                                   atol=1e-12)
        assert server.bridge.force_fn is not None
    finally:
        server.stop()


def test_cli_errors_name_the_flag(capsys):
    assert E.main(["--robot", "paper_7cable", "--length-offset", "9", "0.1", "--port", "0"]) == 2
    assert "--length-offset cable '9': cables are numbered 1..7" in capsys.readouterr().err
    assert E.main(["--robot", "no_such_robot", "--port", "0"]) == 1  # an error, not usage
    assert "unknown robot 'no_such_robot'" in capsys.readouterr().err


def test_cli_refuses_a_start_outside_the_robots_box(capsys):
    # Issue 27, bug 1: the controller would refuse to enable there; the emulator says so at
    # once (bad usage, exit 2), naming the start and the box (the scenario's robot's).
    assert E.main(["--scenario", "exp2_interaction", "--start", "10", "10", "10", "--port",
                   "0", "--duration", "0.05"]) == 2
    err = capsys.readouterr().err
    assert ("cdpm-reel-emulator: error: --start [10.0, 10.0, 10.0] m is outside the workspace "
            "box of robot 'paper_7cable_swap13' (lower [0.5, 0.8, 0.3], upper [3.0, 4.0, 2.4] "
            "m)") in err, err
    # Just inside the upper corner: accepted.
    args = E.build_parser().parse_args(["--robot", "paper_7cable", "--start", "3.0", "4.0", "2.4",
                                   "--port", "0"])
    E.build_server(args).stop()


def test_cli_runs_as_a_process_for_a_bounded_time():
    out = subprocess.run([sys.executable, "-m", "cdpm_drake.emulator", "--port", "0",
                          "--duration", "0.1"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "robot 'paper_7cable' (7 cables) on 127.0.0.1:" in out.stdout
    # Issue 27: the first line says which plant it plays, and where the platform starts.
    assert (", period 2 ms, plant: kinematic (reels following their commands with a 20 ms "
            "first-order lag, speed limit 1 m/s), start [1.750, 2.400, 1.350] m") in out.stdout
    assert "0 commands received" in out.stdout


def test_rt_priority_flag_sets_sched_fifo_or_says_why_not():
    code = ("import os, sys\n"
            "from cdpm_drake.hardware.priority import PriorityError, set_realtime_priority\n"
            "try:\n"
            "    set_realtime_priority(1)\n"
            "except PriorityError as e:\n"
            "    print('refused', e); sys.exit(0)\n"
            "print('fifo', os.sched_getscheduler(0) == os.SCHED_FIFO)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith(("fifo True", "refused cannot set SCHED_FIFO priority 1: run "
                                               "as root, grant CAP_SYS_NICE"))
    with pytest.raises(ValueError, match=r"rt_priority must be an integer in 0..99 .* got 100"):
        from cdpm_drake.hardware.priority import set_realtime_priority
        set_realtime_priority(100)


def test_a_new_session_is_accepted_only_with_enable_clear_and_the_reels_at_rest():
    """hardware/PROTOCOL.md, check 8: the bridge takes an out-of-order command as a new
    controller session only if it is enable-clear while its reels are at rest; an out-of-order
    enabling command is always dropped (a replayed command must never move the reels)."""
    import socket

    from cdpm_drake.hardware.protocol import Command, encode_command
    from cdpm_drake.robot import load_robot

    robot = load_robot("paper_7cable")
    server = ReelBridgeServer(ReelBridge(robot, cable_lengths(robot, robot.workspace.center),
                                         time_constant=0.0))
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))

    def send(sequence, enable):
        client.sendto(encode_command(Command(sequence, 0.0, np.zeros(7), enable, None)),
                      server.address)
        time.sleep(0.01)
        newest = server._drain(0.0)
        if newest is not None:
            server.bridge.set_command(newest.velocity, newest.enable)
        return newest

    try:
        assert send(5, enable=True) is not None and server.bridge.enabled
        assert send(3, enable=False) is None  # out of order while enabled: dropped
        assert send(6, enable=False) is not None and not server.bridge.enabled
        assert send(2, enable=True) is None  # an old enabling command: never accepted
        assert server.counters["rejected"]["sequence"] == 2
        assert send(1, enable=False) is not None  # at rest, enable-clear from 1: new session
        assert server.counters["sessions"] == 1
        assert send(2, enable=True) is not None and server.bridge.enabled
    finally:
        client.close()
        server.stop()


# --- what the emulator says (issue 10, point 9) ----------------------------------------------


def _wait(condition, timeout=2.0):
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def test_sessions_are_reported_as_they_open_and_close(robot, p0):
    said = []
    server = ReelBridgeServer(ReelBridge(robot, cable_lengths(robot, p0), time_constant=0),
                              log=said.append, session_timeout=0.1).start()
    first, second = Controller(server), Controller(server)
    try:
        for _ in range(5):
            first.send(np.zeros(7), enable=False)
        assert _wait(lambda: any("session 1 closed" in s for s in said))
        second.send(np.zeros(7), enable=False)  # a new controller, from sequence 1 again
        assert _wait(lambda: any("session 2 opened" in s for s in said))
    finally:
        first.close()
        second.close()
        server.stop()
    opened = [s for s in said if "opened" in s]
    assert opened[0].startswith("session 1 opened by 127.0.0.1:")
    closed = next(s for s in said if s.startswith("session 1 closed"))
    assert "no command for 0.1 s" in closed and "5 commands accepted" in closed
    assert server.session == 2


def test_a_new_session_starts_at_the_scenarios_start_and_says_so(robot, p0):
    # Issue 27: the second rehearsal against one emulator started 0.46 m from the scenario's
    # start. The bridge is reset as a new session opens, and the session line says from where.
    from cdpm_drake.kernels.kinematics import forward_kinematics

    said = []
    server = ReelBridgeServer(ReelBridge(robot, cable_lengths(robot, p0), time_constant=0),
                              log=said.append, session_timeout=0.1,
                              command_timeout=10.0).start()
    first, second = Controller(server), Controller(server)
    try:
        for _ in range(50):  # 0.1 m/s on cable 1 for a while
            first.send(np.r_[0.1, np.zeros(6)], enable=True)
            time.sleep(0.004)
        first.send(np.zeros(7), enable=False)
        assert _wait(lambda: any("session 1 closed" in s for s in said))
        with server._lock:
            left = forward_kinematics(robot, server.bridge.lengths.copy(), max_residual=np.inf)
        second.send(np.zeros(7), enable=False)
        assert _wait(lambda: any("session 2: the platform is back" in s for s in said))
        with server._lock:
            np.testing.assert_array_equal(server.bridge.lengths, cable_lengths(robot, p0))
    finally:
        first.close()
        second.close()
        server.stop()
    line = next(s for s in said if s.startswith("session 2: the platform is back"))
    away = np.linalg.norm(left - p0)
    assert away > 0.005
    assert line == (f"session 2: the platform is back at its start {vector_text(p0)} m (reset, "
                    f"as a homing would; the last session left it at {vector_text(left)} m, "
                    f"{away:.3f} m away), the operator's clock at 0"), line


def test_rejected_commands_are_reported_by_reason(capsys):
    # A 7-cable controller talking to an 8-cable emulator: every command has the wrong size.
    said = []
    robot8 = load_robot("cube_8cable")
    server = ReelBridgeServer(ReelBridge(robot8, cable_lengths(robot8, robot8.workspace.center),
                                         time_constant=0), log=said.append).start()
    ctl = Controller(server)
    try:
        for _ in range(5):
            ctl.send(np.zeros(7), enable=False)
        assert _wait(lambda: sum(server.counters["rejected"].values()) == 5)
    finally:
        ctl.close()
        server.stop()
    rejected = {r: n for r, n in server.counters["rejected"].items() if n}
    (reason,) = rejected  # one reason, counted 5 times, said once
    assert rejected[reason] == 5
    lines = [s for s in said if s.startswith("rejected a command")]
    assert len(lines) == 1 and f"({reason})" in lines[0], said
    assert count_by_reason(rejected) == f"5 ({reason} 5)"


def test_a_port_in_use_is_named(capsys):
    holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    holder.bind(("127.0.0.1", 0))
    port = holder.getsockname()[1]
    try:
        assert E.main(["--robot", "paper_7cable", "--port", str(port), "--duration", "0.1"]) == 1
    finally:
        holder.close()
    err = capsys.readouterr().err
    assert f"cannot listen on UDP 127.0.0.1:{port}" in err and "--port" in err


def test_a_fault_plan_applies_to_one_session(robot, p0):
    # --stop --fault-after 0: the first session that enables loses its statuses; the next
    # controller session gets a working bridge again.
    said = []
    # A long command timeout: this test sends single commands, not a 500 Hz stream.
    server = ReelBridgeServer(ReelBridge(robot, cable_lengths(robot, p0), time_constant=0),
                              faults=FaultPlan(stop=True), log=said.append,
                              command_timeout=10.0).start()
    first = Controller(server)
    try:
        first.send(np.zeros(7), enable=True)
        assert _wait(lambda: server.fault_onset is not None)
        for _ in range(3):
            first.send(np.zeros(7), enable=False)  # the controller's shutdown burst
        time.sleep(0.05)
        first.latest()  # drop what came before the onset
        time.sleep(0.05)
        first.sock.setblocking(False)
        with pytest.raises(BlockingIOError):
            first.sock.recvfrom(4096)  # stopped: nothing more
        second = Controller(server)
        try:
            second.send(np.zeros(7), enable=False)
            assert _wait(lambda: server.session == 2)
            status = decode_status(second.receive(1)[0], 7)
            assert status.faults == 0
            second.send(np.zeros(7), enable=True)
            time.sleep(0.05)
            assert server.fault_onset is None and server.bridge.enabled
        finally:
            second.close()
    finally:
        first.close()
        server.stop()
    assert any("session 2: no faults injected (the fault plan applied to session 1)" in s
               for s in said), said
