"""Every `plant: !CanopenReels` field reaches what it configures (the wiring cases of
test_wiring_scenario.py for this plant, which merges CANOPEN_CASES into its walk).

Each case runs the plant built from a scenario against EmulatedDrives on a `virtual` bus in
this process, tick by tick (helpers_canopen.lockstep), with values distinct from the
defaults, and checks where each lands: the drives' object dictionary and record (what reached
the bus), the plant's outputs against the emulator's ground truth and the public kernel, or
the message of the refusal or fault that names the field and its value."""

import re

import numpy as np
import pytest

pytest.importorskip("can", reason="the canopen extra (python-can) is not installed")
pytest.importorskip("canopen", reason="the canopen extra is not installed")

from conftest import case_registry  # noqa: E402
from helpers_canopen import T, close, fresh_channel, lockstep, rig  # noqa: E402

from cdpm_drake.config import ScenarioError, load_scenario  # noqa: E402
from cdpm_drake.emulator.bridges import ReelBridge  # noqa: E402
from cdpm_drake.emulator.canopen_drives import Drive  # noqa: E402
from cdpm_drake.hardware.reels import ReelFault, start_realtime  # noqa: E402
from cdpm_drake.kernels.drive_torque import tension_from_drive  # noqa: E402
from cdpm_drake.kernels.kinematics import cable_lengths  # noqa: E402
from cdpm_drake.config import scenario_robot  # noqa: E402

CANOPEN_CASES: dict[str, str] = {}
covers = case_registry(CANOPEN_CASES)
F = "Scenario.plant!CanopenReels."
# Half the cables move, half hold still (their tension has speed and acceleration 0).
U = np.array([0.02, 0.0, -0.015, 0.0, 0.01, 0.0, -0.012])
FORCE = -np.array([20.0, 21.5, 23.0, 24.5, 26.0, 27.5, 29.0])  # drive forces at the cable, N


class _LoadedBridge(ReelBridge):
    """Ideal reels whose drives report FORCE (N at the cable)."""

    def drive_force(self):
        return FORCE.copy()


def _scenario(fields: str, sensor="!CanopenForceSensor {node_id: 20, tare_samples: 5}"):
    return load_scenario("exp1_no_interaction", overlay_text=(
        f"{{plant: !CanopenReels {{interface: virtual, channel: {fresh_channel()}, "
        f"force_sensor: {sensor}, {fields}}}}}"))


def _rigged(scenario, u=U, **kwargs):
    robot = scenario_robot(scenario)
    c = scenario.plant
    bridge = _LoadedBridge(robot, cable_lengths(robot, robot.workspace.center),
                           time_constant=0.0)
    return rig(robot, c, u, bridge=bridge, counts_per_metre=c.counts_per_metre,
               position_offset=c.position_offset or None,
               velocity_units=c.velocity_units_per_mps,
               force_per_torque_unit=c.force_per_torque_unit, **kwargs)


@covers("Scenario.plant=!CanopenReels", F + "interface", F + "channel", F + "node_ids",
        F + "counts_per_metre", F + "position_offset", F + "velocity_units_per_mps",
        F + "force_per_torque_unit", F + "ramp_time", F + "heartbeat_period")
def test_units_ids_ramp_and_heartbeat_reach_the_bus():
    from cdpm_drake.diagram import make_plant
    from cdpm_drake.hardware.canopen_reels import CanopenReelsSystem

    offsets = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]
    scenario = _scenario(f"node_ids: [21, 22, 23, 24, 25, 26, 27], counts_per_metre: -250000.0, "
                         f"position_offset: {offsets}, velocity_units_per_mps: 40000.0, "
                         f"force_per_torque_unit: 0.05, ramp_time: 0.02, "
                         f"heartbeat_period: 0.05, heartbeat_timeout: 0.2")
    assert isinstance(make_plant(scenario), CanopenReelsSystem)
    robot = scenario_robot(scenario)
    sim, reels, drives, bridge, _ = _rigged(scenario)
    try:
        start_realtime(sim, 0.0)
        lockstep(sim, reels, drives, 0.3)
        context = reels.GetMyContextFromRoot(sim.get_context())
        lengths = reels.get_output_port(0).Eval(context).copy()
        tension = reels.get_output_port(2).Eval(context).copy()
        truth = bridge.lengths.copy()
    finally:
        close(reels, drives)
    assert [d.node_id for d in drives.drives] == list(range(21, 28))
    assert all(d.od[(0x1017, 0)] == 50 for d in drives.drives)  # ms
    # What the drives received, in their units (40 000 per m/s): the ramp over 0.02 s = 10
    # ticks (0.1 u, 0.2 u, ...), then u, to the units' 1 / 40 000 m/s.
    enabled = np.array([r[3] for r in drives.record if r[1][0] == "operation enabled"])
    moving = enabled[np.any(enabled != 0, axis=1)]
    ramp = np.minimum(1.0, np.arange(1, len(moving) + 1) / 10.0)[:, None] * U
    assert np.abs(moving - ramp).max() <= 0.5 / 40000 + 1e-12
    # Position actual in -250 000 counts/m from each offset, read back by the plant: the
    # lengths lag the truth by one SYNC's motion at most, to 4 um counts.
    assert np.abs(lengths - truth).max() <= np.abs(U).max() * T + 4e-6
    # Torque actual in 0.05 N units: on the still cables (speed and acceleration 0) the
    # tension is the kernel's for FORCE.
    d = robot.dynamics
    expected = np.empty(7)
    tension_from_drive(FORCE, np.zeros(7), np.zeros(7), float(d.reel_inertia),
                       float(d.viscous_friction), float(d.coulomb_friction),
                       float(d.dead_band), expected)
    still = U == 0
    np.testing.assert_allclose(tension[still], expected[still], atol=1e-9)


@covers(F + "lockstep")
def test_lockstep_answers_every_sync_before_the_next_and_counts_in_syncs():
    """`lockstep: true`: against drives in lockstep (heartbeats by SYNC count), the plant's
    own ticks wait for every drive's answer, so after each tick every drive has answered
    every SYNC but the last (no helper pacing the ticks here), and its clock and heartbeat
    stamps are SYNCs x period, not wall-clock seconds."""
    scenario = _scenario("lockstep: true, ramp_time: 0.0, heartbeat_period: 0.02")
    sim, reels, drives, _, _ = _rigged(scenario, lockstep=True)
    master = reels.master
    try:
        start_realtime(sim, 0.0)
        behind = []
        for k in range(1, 51):
            sim.AdvanceTo(k * T)
            behind.append(int(master.syncs - master.tpdo_count.min()))
        clock, syncs, stamps = master.clock(), master.syncs, master.heartbeat_wall.copy()
    finally:
        close(reels, drives)
    assert master.lockstep and set(behind) == {1}
    assert clock == syncs * T
    assert np.isfinite(stamps).all()
    np.testing.assert_allclose(stamps / T, np.round(stamps / T), atol=1e-6)


@covers(F + "reel_speed")
def test_reel_speed_maps_velocity_actual_where_asked_and_the_bus_has_room():
    """`reel_speed: velocity_actual` at a 4 ms period (7 TPDO2s fit: 54 % of the bus): every
    drive's TPDO2 carries 0x606C (32 bits) and is sent; `position` there: no TPDO2 mapped or
    sent; velocity_actual at the scenario's 2 ms: 108 % of the bus, refused naming it."""
    with pytest.raises(ScenarioError, match=r"7 TPDO2s \(reel_speed: velocity_actual\).* "
                       r"108.0 %"):
        _scenario("reel_speed: velocity_actual")
    for value, mapped in (("velocity_actual", True), ("position", False)):
        scenario = load_scenario("exp1_no_interaction", overlay_text=(
            f"{{time_step: 0.004, plant: !CanopenReels {{interface: virtual, channel: "
            f"{fresh_channel()}, force_sensor: !CanopenForceSensor {{node_id: 20, "
            f"tare_samples: 5}}, reel_speed: {value}}}}}"))
        sim, reels, drives, _, _ = _rigged(scenario, time_step=0.004)
        try:
            start_realtime(sim, 0.0)
            lockstep(sim, reels, drives, 0.1, T=0.004)
        finally:
            close(reels, drives)
        assert reels.master.velocity_mapped.tolist() == [mapped] * 7
        assert all(d.tpdo2 == ([((0x606C, 0), "<i")] if mapped else []) for d in drives.drives)
        assert (drives.tpdo2_sent >= 7 * 25) if mapped else drives.tpdo2_sent == 0


@covers(F + "tension_sensor")
def test_tension_sensor_none_gives_nan():
    sim, reels, drives, _, _ = _rigged(_scenario("tension_sensor: none, ramp_time: 0.0"))
    try:
        start_realtime(sim, 0.0)
        lockstep(sim, reels, drives, 0.05)
        tension = reels.get_output_port(2).Eval(reels.GetMyContextFromRoot(sim.get_context()))
    finally:
        close(reels, drives)
    assert np.isnan(tension).all()


@covers(F + "bitrate")
def test_bitrate_sets_the_bus_load_budget():
    # 7 x (95 + 111 + 0.02 x 55) + 47 + 111 (the force sensor node's TPDO) = 1607.7 bits per
    # 2 ms; 125 kbit/s carry 250: 643.1 %.
    with pytest.raises(ScenarioError, match=r"7 drives at 125000 bit/s with a 2 ms cycle need "
                       r"1608 bits per cycle .* force sensor's TPDO of 111 bits.* 643.1 % of "
                       r"the 250 bits"):
        _scenario("bitrate: 125000")


@covers(F + "max_length_residual")
def test_max_length_residual_refuses_lengths_that_do_not_fit():
    # 1 um counts put the lengths up to 0.5 um off the rigid geometry: more than 1e-9 m.
    sim, reels, drives, _, _ = _rigged(_scenario("max_length_residual: 1.0e-9"))
    try:
        with pytest.raises(ReelFault, match=r"within max_length_residual = 1e-09 m"):
            start_realtime(sim, 0.0)
    finally:
        close(reels, drives)


@covers(F + "startup_timeout")
def test_startup_timeout_names_the_silent_drives():
    sim, reels, drives, _, _ = _rigged(_scenario("startup_timeout: 0.3"))
    drives.drives[4].lost_tpdo = True
    try:
        with pytest.raises(ReelFault, match=r"within startup_timeout = 0.3 s from the drive\(s\) "
                           r"of cable 5 \(node 5\) on virtual"):
            start_realtime(sim, 0.0)
    finally:
        close(reels, drives)


@covers(F + "enable_timeout")
def test_enable_timeout_bounds_the_enable_sequence(monkeypatch):
    original = Drive.apply_controlword
    monkeypatch.setattr(Drive, "apply_controlword", lambda self, cw: (
        None if self.node_id == 6 else original(self, cw)))
    sim, reels, drives, _, _ = _rigged(_scenario("enable_timeout: 0.15"))
    try:
        with pytest.raises(ReelFault, match=r"cable 6 \(node 6\) not in operation enabled within "
                           r"enable_timeout = 0.15 s"):
            start_realtime(sim, 0.0)
    finally:
        close(reels, drives)


@covers(F + "fault_reset")
def test_fault_reset_clears_a_fault_at_start_only_when_set():
    for reset in ("false", "true"):
        sim, reels, drives, _, _ = _rigged(_scenario(f"fault_reset: {reset}"))
        drives.drives[3].state = "fault"
        try:
            if reset == "true":
                start_realtime(sim, 0.0)
                assert drives.drives[3].state == "operation enabled"
            else:
                with pytest.raises(ReelFault, match=r"cable 4 \(node 4\) is in fault"):
                    start_realtime(sim, 0.0)
        finally:
            close(reels, drives)


def _fault_run(fields, faults, match, before=None):
    sim, reels, drives, _, _ = _rigged(_scenario("ramp_time: 0.0, " + fields), faults=faults)
    try:
        start_realtime(sim, 0.0)
        if before is not None:
            before(drives)
        with pytest.raises(ReelFault, match=match):
            lockstep(sim, reels, drives, 2.0)
    finally:
        close(reels, drives)


@covers(F + "missed_tpdo_ticks")
def test_missed_tpdo_ticks_counts_the_silence():
    _fault_run("missed_tpdo_ticks: 4", [("lost_tpdo", 2, 0.1)],
               r"no TPDO from the drive of cable 3 \(node 3\) for 4 ticks "
               r"\(missed_tpdo_ticks = 4\)")


@covers(F + "frozen_speed", F + "frozen_ticks")
def test_frozen_speed_and_ticks_judge_a_frozen_encoder():
    # Cable 1 runs at 20 mm/s >= 12 mm/s: 40 um a tick, 3 unchanged TPDOs are frozen.
    _fault_run("frozen_speed: 0.012, frozen_ticks: 3", [("frozen_position", 0, 0.1)],
               r"cable 1 \(node 1\)'s position actual has not changed for 3 TPDOs while "
               r"commanded at least frozen_speed = 0.012 m/s")


@covers(F + "heartbeat_timeout")
def test_heartbeat_timeout_judges_a_lost_heartbeat():
    def silence(drives):  # drive 7 stops its heartbeat; its TPDOs go on
        drives.drives[6].od[(0x1017, 0)] = 0

    _fault_run("heartbeat_period: 0.05, heartbeat_timeout: 0.12", [],
               r"cable 7 \(node 7\)'s heartbeat is \d+ ms old \(heartbeat_timeout = 120 ms\)",
               before=silence)


# --- the handle's force sensor ----------------------------------------------------------------

S = F + "force_sensor"
HAND = np.array([6.0, -2.5, 4.0])  # N, base frame, from 0.05 s after the enable


def _hand(t, p, v):
    return HAND if t >= 0.05 else np.zeros(3)


def _sensed(scenario, until=0.2, faults=(), **drive_args):
    """(measured_force at the end or the ReelFault, drives, the plant) of a run with the
    hand above and ideal reels."""
    robot = scenario_robot(scenario)
    bridge = ReelBridge(robot, cable_lengths(robot, robot.workspace.center), force=_hand,
                        time_constant=0.0)
    sim, reels, drives, bridge, _ = rig(robot, scenario.plant, np.zeros(7), bridge=bridge,
                                        faults=faults, **drive_args)
    try:
        start_realtime(sim, 0.0)
        lockstep(sim, reels, drives, until)
        out = reels.GetOutputPort("measured_force").Eval(
            reels.GetMyContextFromRoot(sim.get_context())).copy()
    except ReelFault as e:
        out = e
    finally:
        close(reels, drives)
    return out, drives, reels


@covers(S + "=!CanopenForceSensor", S + "!CanopenForceSensor.node_id",
        S + "!CanopenForceSensor.counts_per_newton", S + "!CanopenForceSensor.axes",
        S + "!CanopenForceSensor.tare_samples", S + "!CanopenForceSensor.missed_ticks")
def test_the_force_sensor_node_reaches_measured_force_and_its_silence_stops_the_run():
    scenario = _scenario("missed_tpdo_ticks: 25", sensor=(
        "!CanopenForceSensor {node_id: 33, counts_per_newton: -40.0, axes: [+z, -x, +y], "
        "tare_samples: 4, missed_ticks: 3}"))
    bias = np.array([1.0, 0.5, -2.0])  # the node's own offset, N in its axes
    measured, drives, reels = _sensed(scenario, force_bias=bias)
    # The node's counts (-40 per N) in its axes: x = F_z, y = -F_x, z = F_y, plus its bias.
    assert drives.force_counts() == [int(-40 * (4.0 + 1.0)), int(-40 * (-6.0 + 0.5)),
                                     int(-40 * (-2.5 - 2.0))]
    np.testing.assert_array_equal(measured, HAND)
    # The tare took 4 samples and removed the bias, in the base frame: x = -b_y, y = b_z,
    # z = b_x.
    np.testing.assert_array_equal(reels._force_scale.bias, [-0.5, -2.0, 1.0])
    error, drives, _ = _sensed(scenario, until=1.0, faults=[("force_silent", 0, 0.05)])
    assert isinstance(error, ReelFault)
    assert "no sample from the handle's force sensor (node 33) for 3 ticks" in str(error)


@covers(S + "=!NetFT", S + "!NetFT.address", S + "!NetFT.port", S + "!NetFT.local_address",
        S + "!NetFT.counts_per_force", S + "!NetFT.axes", S + "!NetFT.tare_samples",
        S + "!NetFT.startup_timeout", S + "!NetFT.missed_ticks")
def test_the_net_ft_reaches_measured_force_and_a_silent_box_is_refused():
    import socket

    from cdpm_drake.emulator.netft import NetFTServer
    from cdpm_drake.emulator.plant_setup import netft_server

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    sensor = ("!NetFT {address: 127.0.0.1, port: %d, local_address: 127.0.0.1, "
              "counts_per_force: 250.0, axes: [-x, -y, +z], tare_samples: 3, "
              "startup_timeout: 0.3, missed_ticks: 30}" % port)
    scenario = _scenario("missed_tpdo_ticks: 25", sensor=sensor)
    robot = scenario_robot(scenario)
    bridge = ReelBridge(robot, cable_lengths(robot, robot.workspace.center), force=_hand,
                        time_constant=0.0)
    server = netft_server(scenario.plant, bridge)  # the emulator's, at the sensor's address
    assert isinstance(server, NetFTServer) and server.address == ("127.0.0.1", port)
    sim, reels, drives, bridge, _ = rig(robot, scenario.plant, np.zeros(7), bridge=bridge)
    try:
        start_realtime(sim, 0.0)
        lockstep(sim, reels, drives, 0.2)
        measured = reels.GetOutputPort("measured_force").Eval(
            reels.GetMyContextFromRoot(sim.get_context())).copy()
    finally:
        close(reels, drives)
        server.stop()
    np.testing.assert_array_equal(measured, HAND)  # 250 counts per N: whole counts
    assert server.counts()[:3] == [-6 * 250, 2.5 * 250, 4 * 250]
    assert reels.force_source.records >= 3 + 100  # the tare's and one per tick
    # No box at that port: refused after startup_timeout, naming it and the field.
    scenario = _scenario("missed_tpdo_ticks: 25", sensor=sensor)
    error, drives, _ = _sensed(scenario)
    assert isinstance(error, ReelFault)
    assert re.search(r"refusing to enable the drives: the handle's force sensor \(Net F/T at "
                     r"127.0.0.1:%d\) sent 0 of the 3 records .* "
                     r"plant.force_sensor.startup_timeout = 0.3 s" % port, str(error)), error
    assert not any(r[1][0] == "operation enabled" for r in drives.record)  # never enabled
