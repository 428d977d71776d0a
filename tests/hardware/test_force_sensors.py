"""The handle's force sensor as a component of its own on the CANopen plant: a force-torque
node on the drives' bus, or a Net F/T streaming ATI's RDT records over loopback; both played
by the emulator from its plant's hand force, with a bias of the sensor's own that the tare at
start-up must remove. And a CANopen run without a force sensor refuses to enable.

Ground truth: the emulator's hand force (a constant set by the test) and the sensor's bias;
the expected measured_force is that force, exactly (the scale factors below make every value
a whole number of counts: no rounding)."""

import re

import numpy as np
import pytest

can = pytest.importorskip("can", reason="the canopen extra (python-can) is not installed")
pytest.importorskip("canopen", reason="the canopen extra is not installed")

from cdpm_drake.config import load_scenario
from cdpm_drake.emulator.bridges import ReelBridge
from cdpm_drake.emulator.netft import NetFTServer
from cdpm_drake.hardware.canopen_config import CanopenReels, bus_load, check_canopen_reels
from cdpm_drake.hardware.canopen_reels import CanopenReelsSystem
from cdpm_drake.hardware.force_config import (CanopenForceSensor, NetFT, axes_matrix,
                                              check_force_sensor)
from cdpm_drake.hardware.force_sources import parse_rdt, rdt_record, rdt_request
from cdpm_drake.hardware.reels import ReelFault, start_realtime
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.robot import load_robot
from helpers_canopen import T, bus_sensor, close, fresh_channel, lockstep, rig

# The hand: nothing for the tare and the first 0.1 s of the run, then this (base frame, N).
HAND = np.array([3.0, -4.0, 10.0])
# The sensor's own zero offset in its axes, N: what the tare removes.
BIAS = np.array([2.0, -1.5, 0.8])
# The sensor's x measures the base frame's -y, its y the base's +z, its z the base's +x.
AXES = ["-y", "+z", "+x"]
# BIAS in the base frame through AXES: base x = sensor z, base y = -sensor x, base z =
# sensor y.
BIAS_BASE = np.array([0.8, -2.0, -1.5])


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


def _hand(t, p, v):
    return HAND if t >= 0.1 else np.zeros(3)


def _bridge(robot):
    return ReelBridge(robot, cable_lengths(robot, robot.workspace.center), force=_hand,
                      time_constant=0.0)


def _measured(sim, reels):
    return reels.GetOutputPort("measured_force").Eval(
        reels.GetMyContextFromRoot(sim.get_context())).copy()


def test_axes_rdt_bytes_and_refusals_name_the_field():
    # F_base = R F_sensor: the sensor's x (column 0) along the base's -y.
    np.testing.assert_array_equal(axes_matrix(AXES) @ BIAS, BIAS_BASE)
    for axes, match in ((["+x", "+x", "+z"], r"each of x, y, z once"),
                        (["+x", "y", "+z"], r"\[1\] must be one of"),
                        (["+x", "+y"], r"must list 3 axes")):
        with pytest.raises(ValueError, match=r"plant.force_sensor.axes.*" + match):
            axes_matrix(axes, "plant.force_sensor.axes")
    # ATI's RDT request: header 0x1234, command 2 (high-speed real-time), count 0, big-endian.
    assert rdt_request() == bytes.fromhex("1234000200000000")
    record = rdt_record(7, 9, 0, [1, -2, 3, 0, 0, -4])
    assert len(record) == 36 and record[:4] == bytes.fromhex("00000007")
    assert parse_rdt(record) == (7, 9, 0, (1, -2, 3, 0, 0, -4))
    with pytest.raises(ValueError, match=r"plant.force_sensor.node_id 3 is also a drive's"):
        check_force_sensor(CanopenForceSensor(node_id=3), drive_ids=[1, 2, 3])
    with pytest.raises(ValueError, match=r"counts_per_force must be a finite non-zero"):
        check_force_sensor(NetFT(address="127.0.0.1", counts_per_force=0.0))
    # The sensor's TPDO is one more 8-byte frame per cycle on the bus.
    config = CanopenReels(force_sensor=CanopenForceSensor())
    assert (check_canopen_reels(config, 7, 0.002)["bits"]
            - bus_load(7, 1_000_000, 0.002, 0.1)["bits"]) == 34 + 64 + 13


def test_force_sensor_from_yaml():
    scenario = load_scenario("exp2_interaction", overlay_text=(
        "{plant: !CanopenReels {interface: virtual, channel: c, force_sensor: "
        "!CanopenForceSensor {node_id: 21, counts_per_newton: -50.0, axes: [-y, +z, +x]}}}"))
    assert scenario.plant.force_sensor == CanopenForceSensor(
        node_id=21, counts_per_newton=-50.0, axes=AXES)
    scenario = load_scenario("exp2_interaction", overlay_text=(
        "{plant: !CanopenReels {force_sensor: !NetFT {address: 10.0.0.5}}}"))
    assert scenario.plant.force_sensor == NetFT(address="10.0.0.5")


def test_a_canopen_plant_without_a_force_sensor_refuses_before_opening_the_bus(robot):
    channel = fresh_channel()
    listener = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    try:
        with pytest.raises(ValueError, match=r"the admittance has no force source: "
                           r"plant.force_sensor is not set"):
            CanopenReelsSystem(robot, CanopenReels(interface="virtual", channel=channel),
                               time_step=T)
        assert listener.recv(0.05) is None  # not a frame: no NMT, no SYNC, nothing enabled
    finally:
        listener.shutdown()


def test_cdpm_run_without_a_force_sensor_refuses_to_enable(tmp_path, capsys):
    from cdpm_drake.cli.cdpm import main

    channel = fresh_channel()
    listener = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    try:
        code = main(["run", "exp1_no_interaction", "--duration", "0.1", "--out",
                     str(tmp_path / "run"), "--scenario-text",
                     f"plant: !CanopenReels {{interface: virtual, channel: {channel}}}"])
        assert listener.recv(0.05) is None
    finally:
        listener.shutdown()
    err = capsys.readouterr().err
    assert code == 1
    assert "cdpm run: error: refusing to enable the drives: the admittance has no force " \
           "source: plant.force_sensor is not set" in err, err


def test_canopen_force_node_scaled_axis_mapped_and_tared(robot):
    sensor = bus_sensor(counts_per_newton=50.0, axes=AXES)
    config = CanopenReels(interface="virtual", channel=fresh_channel(), ramp_time=0.0,
                          force_sensor=sensor, missed_tpdo_ticks=25)
    sim, reels, drives, bridge, _ = rig(robot, config, np.zeros(7), bridge=_bridge(robot),
                                        force_bias=BIAS)
    try:
        start_realtime(sim)
        np.testing.assert_array_equal(reels._force_scale.bias, BIAS_BASE)
        np.testing.assert_array_equal(_measured(sim, reels), np.zeros(3))  # tared
        lockstep(sim, reels, drives, 0.3)
        measured = _measured(sim, reels)
        # What the node sent last: the hand in the sensor's axes plus its bias, in counts.
        sent = drives.force_counts()
    finally:
        close(reels, drives)
    np.testing.assert_array_equal(measured, HAND)
    # Independent of the controller's decoding: sensor x = -F_y, y = F_z, z = F_x (+ bias).
    assert sent == [int((4.0 + 2.0) * 50), int((10.0 - 1.5) * 50), int((3.0 + 0.8) * 50)]


def test_a_silent_force_node_stops_the_drives(robot):
    config = CanopenReels(interface="virtual", channel=fresh_channel(), ramp_time=0.0,
                          force_sensor=bus_sensor(missed_ticks=2), missed_tpdo_ticks=25)
    sim, reels, drives, bridge, _ = rig(robot, config, np.zeros(7),
                                        faults=[("force_silent", 0, 0.1)])
    try:
        start_realtime(sim)
        with pytest.raises(ReelFault, match=r"no sample from the handle's force sensor "
                           r"\(node 20\) for 2 ticks"):
            lockstep(sim, reels, drives, 1.0)
    finally:
        close(reels, drives)
    # Counted from the node's first unanswered SYNC (1): two ticks without a sample, then
    # quick stop and disable voltage on the next two SYNCs (measured 4 and 5 here; 3 when
    # the silence falls just before a tick's update).
    zero, off, disabled = drives.fault_counts("force_silent")
    assert zero is not None and off is not None and disabled is not None
    assert 3 <= disabled <= 5, (zero, off, disabled)
    assert all(d.state == "switch on disabled" for d in drives.drives)


def test_netft_over_loopback_scaled_axis_mapped_and_tared(robot):
    bridge = _bridge(robot)
    server = NetFTServer(bridge, address=("127.0.0.1", 0), counts_per_force=1000.0,
                         axes=AXES, bias=BIAS).start()
    sensor = NetFT(address="127.0.0.1", port=server.address[1], local_address="127.0.0.1",
                   counts_per_force=1000.0, axes=AXES, tare_samples=5, missed_ticks=25)
    config = CanopenReels(interface="virtual", channel=fresh_channel(), ramp_time=0.0,
                          force_sensor=sensor, missed_tpdo_ticks=25)
    sim, reels, drives, bridge, _ = rig(robot, config, np.zeros(7), bridge=bridge)
    try:
        start_realtime(sim)
        np.testing.assert_allclose(reels._force_scale.bias, BIAS_BASE, atol=1e-12)
        lockstep(sim, reels, drives, 0.3)
        measured = _measured(sim, reels)
        records = reels.force_source.records
    finally:
        close(reels, drives)
        server.stop()
    np.testing.assert_allclose(measured, HAND, atol=1e-12)
    # One record per SYNC's plant step, all read: the tare's 5 and the run's ~150 ticks.
    assert records >= 150 and reels.force_source.lost == 0


def test_netft_on_the_udp_bridge_replaces_the_status_force_and_its_silence_stops(robot):
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from cdpm_drake.emulator import ReelBridgeServer
    from cdpm_drake.hardware.config import HardwareReels
    from cdpm_drake.hardware.reels import HardwareReelsSystem

    bridge = _bridge(robot)
    netft = NetFTServer(bridge, address=("127.0.0.1", 0), counts_per_force=1000.0, axes=AXES,
                        bias=BIAS).start()
    server = ReelBridgeServer(bridge, address=("127.0.0.1", 0)).start()
    config = HardwareReels(port=server.address[1], watchdog_ticks=25, force_sensor=NetFT(
        address="127.0.0.1", port=netft.address[1], local_address="127.0.0.1",
        counts_per_force=1000.0, axes=AXES, tare_samples=5, missed_ticks=25))
    b = DiagramBuilder()
    reels = b.AddNamedSystem("reels", HardwareReelsSystem(robot, config, time_step=T))
    source = b.AddSystem(ConstantVectorSource(np.zeros(7)))
    b.Connect(source.get_output_port(), reels.get_input_port())
    sim = Simulator(b.Build())
    try:
        start_realtime(sim)
        # The tare removed the box's bias (the bridge's status force has none to remove).
        np.testing.assert_allclose(reels.force_source.scale.bias, BIAS_BASE, atol=1e-12)
        sim.AdvanceTo(0.4)
        measured = _measured(sim, reels)
        records = reels.force_source.records
        netft.silent = True  # the box stops streaming: 25 ticks later the reels stop
        with pytest.raises(ReelFault, match=r"no record from the handle's force sensor \(Net "
                           r"F/T at 127.0.0.1:\d+\) for \d+ ticks") as fault:
            sim.AdvanceTo(1.5)
    finally:
        reels.close()
        server.stop()
        netft.stop()
    np.testing.assert_allclose(measured, HAND, atol=1e-12)
    assert records >= 100  # one per bridge period (2 ms) over 0.4 s, less a busy host's
    # 25 ticks and 48 ms of wall clock (a burst of catch-up ticks after a host stall may
    # count a few more before the wall clock agrees).
    silent = int(re.search(r"for (\d+) ticks", str(fault.value)).group(1))
    assert 25 <= silent <= 35, fault.value


def test_both_hardware_plants_implement_the_one_interface(robot):
    """hardware/INTERFACE.md: the ports and the resources cdpm run drives, on both buses."""
    from cdpm_drake.hardware.config import HardwareReels
    from cdpm_drake.hardware.interface import INPUT_PORTS, OUTPUT_PORTS, HardwarePlant
    from cdpm_drake.hardware.reels import HardwareReelsSystem

    for plant in (HardwareReelsSystem(robot, HardwareReels(), time_step=T),
                  CanopenReelsSystem(robot, CanopenReels(force_sensor=bus_sensor()),
                                     time_step=T)):
        assert isinstance(plant, HardwarePlant)
        assert [plant.get_input_port(i).get_name()
                for i in range(plant.num_input_ports())] == list(INPUT_PORTS)
        assert [plant.get_output_port(i).get_name()
                for i in range(plant.num_output_ports())] == list(OUTPUT_PORTS)
        assert plant.link is None  # nothing opened before the initialisation


def test_the_emulators_play_the_scenarios_force_sensor():
    """`cdpm emulate` serves a scenario's !NetFT at its address; `cdpm emulate --canopen`
    plays its !CanopenForceSensor node with the drives."""
    import socket

    from cdpm_drake.emulator import build_parser, build_server, canopen_drives
    from cdpm_drake.emulator.main import start_netft

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    args = build_parser().parse_args([
        "--scenario", "exp2_interaction", "--port", "0", "--scenario-text",
        "plant: !HardwareReels {force_sensor: !NetFT {address: 127.0.0.1, port: %d, "
        "counts_per_force: 10.0}}" % port])
    server = build_server(args)
    netft = start_netft(args, server.bridge)
    try:
        assert isinstance(netft, NetFTServer)
        assert netft.address == ("127.0.0.1", port) and netft.counts_per_force == 10.0
    finally:
        netft.stop()
    args = canopen_drives.build_parser().parse_args([
        "--scenario", "exp2_interaction", "--channel", fresh_channel(), "--scenario-text",
        "plant: !CanopenReels {interface: virtual, force_sensor: !CanopenForceSensor "
        "{node_id: 42, counts_per_newton: 20.0}}"])
    drives = canopen_drives.build_drives(args)
    try:
        assert canopen_drives.play_force_sensor(args, drives) is None  # no Net F/T
        assert drives.force_sensor == CanopenForceSensor(node_id=42, counts_per_newton=20.0)
    finally:
        drives.stop()
