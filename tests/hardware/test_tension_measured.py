"""HardwareReelsSystem's `tension_measured` (issue 31): the protocol version agreed at start-up,
the tensions by `tension_sensor` from version-2 statuses, NaN from a version-1 bridge, and no
exception on the real-time path whatever the fields hold.

Scripted links (no sockets, no real time) check the numbers against the reel's equation of
motion written out here; real-time runs against the emulator thread check what goes over the
wire.
"""

import dataclasses
import time

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from cdpm_drake.emulator import ReelBridge, ReelBridgeServer
from cdpm_drake.hardware.config import HardwareReels
from cdpm_drake.hardware.reels import HardwareReelsSystem, ReelFault, start_realtime
from cdpm_drake.kernels import drive_torque
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.robot import load_robot
from helpers_scripted_link import ScriptedLink, install

T = 0.002
M = 7


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


@pytest.fixture(scope="module")
def p0(robot):
    return robot.workspace.center + np.array([0.2, -0.3, 0.1])


def _speed(tick):
    """Reel speeds of the scripted bridge at a status of tick `tick`, m/s: a different sine
    per cable, some through zero (the friction's band), some far from it."""
    k = np.arange(M)
    return 0.05 * np.sin(0.07 * tick + k) + 0.004 * (k - 3)


def _force(tick):
    """Drive forces at the cable, N (+ pays out: holding taut cables they pull in)."""
    return -(10.0 + np.arange(M) + 2.0 * np.cos(0.05 * tick))


def _cell(tick):
    return 5.0 + 0.1 * tick + np.arange(M)


class DriveLink(ScriptedLink):
    """A scripted version-2 bridge: each status carries _force, _speed and _cell of the
    bridge's own tick (which counts the statuses it lost too: `skipped`), stamped with that
    tick's time on the bridge's clock (T per tick); `spoil(tick, fields)` may change them (NaN,
    missing readings)."""

    def __init__(self, lengths, script, spoil=None):
        super().__init__(lengths, script)
        self.spoil = spoil
        self.bridge_tick = -1
        self.statuses = []   # every status handed to the controller

    def _status(self, skipped, echo, faults, last):
        status = super()._status(skipped, echo, faults, last)
        self.bridge_tick += 1 + skipped
        k = self.bridge_tick
        fields = dict(drive_force=_force(k), reel_speed=_speed(k), load_cell=_cell(k))
        if self.spoil is not None:
            self.spoil(k, fields)
        status = dataclasses.replace(status, version=2, time=k * T, **fields)
        self.statuses.append(status)
        return status


def _every_tick(tick, link):
    return [(0, link.sequence, 0)]


def _scripted(monkeypatch, robot, p0, link_class=DriveLink, spoil=None, **config):
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(np.zeros(M)))
    reels = builder.AddNamedSystem("reels", HardwareReelsSystem(
        robot, HardwareReels(**config), time_step=T))
    builder.Connect(source.get_output_port(), reels.GetInputPort("reel_velocity_command"))
    kwargs = {} if link_class is ScriptedLink else dict(spoil=spoil)
    link = link_class(cable_lengths(robot, p0), _every_tick, **kwargs)
    install(monkeypatch, reels, link)
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    return simulator, reels, link


def _tension(simulator, reels):
    ctx = reels.GetMyContextFromRoot(simulator.get_context())
    return reels.GetOutputPort("tension_measured").Eval(ctx).copy()


def _expected(robot, force, speed, previous_speed, dt):
    """The reel's equation of motion solved for the tension, written out (not the kernel):
    T = J a + b w + F_c sat(w / band) - F, with J, b, F_c from the robot file's reel_drives,
    band its dead band F_c / (bandwidth J), a the speed's difference over dt."""
    d = robot.dynamics
    band = d.coulomb_friction / (d.bandwidth * d.reel_inertia)
    a = (speed - previous_speed) / dt
    return (d.reel_inertia * a + d.viscous_friction * speed
            + d.coulomb_friction * np.clip(speed / band, -1.0, 1.0) - force)


# --- configuration ---------------------------------------------------------------------------


def test_the_default_sensor_is_the_drives_torque():
    assert HardwareReels().tension_sensor == "drive_torque"


def test_a_bad_tension_sensor_is_named(robot):
    with pytest.raises(ValueError, match=r"plant.tension_sensor must be one of drive_torque, "
                                         r"load_cell, none, got 'strain_gauge'"):
        HardwareReelsSystem(robot, HardwareReels(tension_sensor="strain_gauge"))


# --- the numbers, on a scripted link ---------------------------------------------------------


def test_drive_torque_is_the_reels_equation_of_motion(monkeypatch, robot, p0):
    simulator, reels, link = _scripted(monkeypatch, robot, p0)
    assert reels.book(reels.GetMyContextFromRoot(simulator.get_context()))[
        "protocol_version"] == 2
    # The first status has no earlier speed: a reel within the drives' dead band (at rest,
    # as before enabling) is taken as not accelerating; a moving one has no tension yet.
    first, w0 = _tension(simulator, reels), _speed(0)
    still = np.abs(w0) <= robot.dynamics.dead_band
    assert still.any() and not still.all()  # the scripted speeds have both
    assert np.isnan(first[~still]).all()
    np.testing.assert_allclose(first[still], _expected(robot, _force(0), w0, w0, T)[still],
                               rtol=1e-9, atol=1e-9)
    signatures = len(drive_torque.tension_from_drive.signatures)
    for k in range(1, 40):
        simulator.AdvanceTo(k * T)
        # Tick k's update read the status of tick k (the scripted clock steps T per tick).
        expected = _expected(robot, _force(k), _speed(k), _speed(k - 1), T)
        np.testing.assert_allclose(_tension(simulator, reels), expected, rtol=1e-9, atol=1e-9)
    # The sines make the cables' tensions differ from the drive forces by up to a newton:
    # the comparison would see a missing term.
    assert np.max(np.abs(expected + _force(39))) > 0.1
    # Nothing was compiled on the real-time path (the constructor compiled the kernel).
    assert len(drive_torque.tension_from_drive.signatures) == signatures


def test_the_acceleration_spans_a_lost_status_by_the_bridges_clock(monkeypatch, robot, p0):
    """A status lost between two accepted ones: the speed's difference is taken over the two
    statuses' time fields (2 periods of the bridge's clock), not over one control tick."""
    simulator, reels, link = _scripted(monkeypatch, robot, p0)
    simulator.AdvanceTo(6 * T)
    link.script = lambda tick, link: [(1 if tick == 7 else 0, link.sequence, 0)]
    simulator.AdvanceTo(7 * T)
    got = _tension(simulator, reels)
    # Control tick 7 read the bridge's status 8 (its 7 was lost); the one before was 6.
    assert link.bridge_tick == 8
    np.testing.assert_allclose(got, _expected(robot, _force(8), _speed(8), _speed(6), 2 * T),
                               rtol=1e-9, atol=1e-9)
    one_tick = _expected(robot, _force(8), _speed(8), _speed(6), T)
    assert np.max(np.abs(one_tick - got)) > 0.01  # over one tick it would be this far off


def test_load_cell_passes_the_bridges_load_cells(monkeypatch, robot, p0):
    simulator, reels, link = _scripted(monkeypatch, robot, p0, tension_sensor="load_cell")
    simulator.AdvanceTo(10 * T)
    np.testing.assert_array_equal(_tension(simulator, reels), _cell(10))


def test_none_is_nan_with_every_field_present(monkeypatch, robot, p0):
    simulator, reels, link = _scripted(monkeypatch, robot, p0, tension_sensor="none")
    simulator.AdvanceTo(10 * T)
    assert np.isnan(_tension(simulator, reels)).all()


def test_a_version_1_bridge_runs_and_yields_nan(monkeypatch, robot, p0):
    """ScriptedLink answers in version 1 (no drive fields): two greetings settle version 1,
    the commands go out as version 1 and the tensions are NaN, whatever the sensor."""
    simulator, reels, link = _scripted(monkeypatch, robot, p0, link_class=ScriptedLink)
    simulator.AdvanceTo(20 * T)
    book = reels.book(reels.GetMyContextFromRoot(simulator.get_context()))
    assert book["protocol_version"] == 1 and book["fault"] == 0 and book["enabled"] == 1
    assert np.isnan(_tension(simulator, reels)).all()


@pytest.mark.parametrize("sensor", ["drive_torque", "load_cell"])
def test_missing_readings_degrade_to_nan_per_cable_and_never_raise(monkeypatch, robot, p0,
                                                                   sensor):
    """NaN fields (a drive that stopped reporting, a cable without a load cell) make NaN in
    those cables only, for as long as they last; the run goes on."""
    def spoil(tick, fields):
        if 10 <= tick < 20:
            fields["drive_force"][2] = np.nan
            fields["reel_speed"][4] = np.nan
            fields["load_cell"][2] = np.nan
        if tick >= 30:
            for key in fields:
                fields[key] = np.full(M, np.nan)

    simulator, reels, link = _scripted(monkeypatch, robot, p0, tension_sensor=sensor,
                                       spoil=spoil)
    simulator.AdvanceTo(15 * T)
    got = _tension(simulator, reels)
    nan = {"drive_torque": [2, 4], "load_cell": [2]}[sensor]
    assert np.isnan(got[nan]).all() and np.isfinite(np.delete(got, nan)).all()
    simulator.AdvanceTo(22 * T)  # a reel speed is needed twice for an acceleration: tick 21
    assert np.isfinite(_tension(simulator, reels)).all()
    simulator.AdvanceTo(40 * T)
    assert np.isnan(_tension(simulator, reels)).all()
    book = reels.book(reels.GetMyContextFromRoot(simulator.get_context()))
    assert book["fault"] == 0 and book["enabled"] == 1


def test_a_fault_still_ends_in_zero_velocity_with_tensions_flowing(monkeypatch, robot, p0):
    """A bridge fault bit in a version-2 status: the same stop as in version 1 (zero velocity,
    enable off, then ReelFault), with the tension fields present."""
    simulator, reels, link = _scripted(monkeypatch, robot, p0)
    simulator.AdvanceTo(10 * T)
    link.script = lambda tick, link: [(0, link.sequence, 2)]  # FAULT_DRIVE
    with pytest.raises(ReelFault, match=r"fault bits 0x0002 \(DRIVE\)"):
        simulator.AdvanceTo(20 * T)
    stop = link.sent[-3:]
    assert all(not on and np.all(v == 0) for _, _, on, v in stop)


# --- over the wire, in real time, against the emulator thread --------------------------------


class _KnownDrives(ReelBridge):
    """Ideal reels whose drives report a fixed force per cable (N) and load cells."""

    FORCE = -np.linspace(8.0, 20.0, M)

    def drive_force(self):
        return self.FORCE.copy()

    def load_cell(self):
        return np.where(np.arange(M) % 2 == 0, 3.0 + np.arange(M), np.nan)


def _realtime(robot, p0, server, u, seconds, **config):
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(u))
    reels = builder.AddNamedSystem("reels", HardwareReelsSystem(
        robot, HardwareReels(port=server.address[1], watchdog_ticks=25, ramp_time=0.0,
                             **config), time_step=T))
    builder.Connect(source.get_output_port(), reels.GetInputPort("reel_velocity_command"))
    simulator = Simulator(builder.Build())
    try:
        start_realtime(simulator)
        simulator.AdvanceTo(seconds)
        ctx = reels.GetMyContextFromRoot(simulator.get_context())
        return reels.book(ctx), reels.GetOutputPort("tension_measured").Eval(ctx).copy()
    finally:
        reels.close()
        time.sleep(0.01)
        server.stop()


def test_tensions_cross_the_wire_from_a_version_2_bridge(robot, p0):
    """Ideal reels (no lag) at a constant command: constant speeds, zero acceleration once
    two statuses have come, so T = b u + F_c sat(u / band) - F exactly, F the drives' fixed
    forces."""
    u = np.array([0.02, -0.01, 0.0, 0.003, -0.04, 0.01, 0.0])
    server = ReelBridgeServer(_KnownDrives(robot, cable_lengths(robot, p0), time_constant=0.0),
                              record=0).start()
    book, got = _realtime(robot, p0, server, u, 0.2)
    assert book["protocol_version"] == 2 and book["fault"] == 0
    np.testing.assert_allclose(got, _expected(robot, _KnownDrives.FORCE, u, u, 1.0),
                               rtol=1e-9, atol=1e-9)


def test_load_cells_cross_the_wire_nan_where_there_is_none(robot, p0):
    server = ReelBridgeServer(_KnownDrives(robot, cable_lengths(robot, p0), time_constant=0.0),
                              record=0).start()
    book, got = _realtime(robot, p0, server, np.zeros(M), 0.1, tension_sensor="load_cell")
    np.testing.assert_array_equal(got, _KnownDrives(robot, cable_lengths(robot, p0)).load_cell())


def test_a_version_1_emulator_runs_and_yields_nan(robot, p0):
    """`cdpm emulate --protocol-version 1`: it refuses the version-2 greetings, answers the
    version-1 ones; the run agrees on version 1, moves the reels, and its tensions are NaN
    although this plant would report drive forces."""
    u = np.array([0.02, -0.01, 0.0, 0.003, -0.04, 0.01, 0.0])
    bridge = _KnownDrives(robot, cable_lengths(robot, p0), time_constant=0.0)
    server = ReelBridgeServer(bridge, record=0, protocol_version=1).start()
    l0 = bridge.lengths.copy()
    book, got = _realtime(robot, p0, server, u, 0.2)
    assert book["protocol_version"] == 1 and book["fault"] == 0
    assert np.isnan(got).all()
    assert server.counters["rejected"]["version"] >= 1  # a version-2 greeting
    moved = bridge.lengths - l0
    assert np.all(np.sign(moved) == np.sign(u)) and np.abs(moved).max() > 0.003
