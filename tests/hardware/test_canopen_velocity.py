"""The reel speed over CANopen: velocity actual 0x606C in TPDO2 (`reel_speed`), against the
emulated drives on python-can's `virtual` bus, tick by tick (helpers_canopen.lockstep).

The ground truth is the emulator's plant: a ReelBridge whose reels follow their command with a
20 ms lag (so that speed and acceleration change every tick) and whose drives report the force
that holds known cable tensions, computed as the emulator's dynamic plant does (the reel speed
after the step, its difference over the step: kernels/drive_torque.drive_force_for_tension).
At 7 drives TPDO2 fits a 1 Mbit/s bus at a 4 ms period (54 %), not at 2 ms (108 %)."""

import logging
import re
import time

import numpy as np
import pytest

can = pytest.importorskip("can", reason="the canopen extra (python-can) is not installed")
pytest.importorskip("canopen", reason="the canopen extra is not installed")

from cdpm_drake.emulator.bridges import ReelBridge
from cdpm_drake.hardware.canopen_config import (CanopenReels, bus_load, check_canopen_reels,
                                                frame_bits)
from cdpm_drake.hardware.reels import ReelFault, start_realtime
from cdpm_drake.kernels.drive_torque import drive_force_for_tension, drive_model
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.robot import load_robot
from cdpm_drake.hardware.canopen_reels import D_COUNT2
from helpers_canopen import bus_sensor, close, fresh_channel, lockstep, rig

PERIOD = 0.004  # s: TPDO2 of 7 drives fits the bus (54 %)
U = np.array([0.02, -0.02, 0.015, -0.015, 0.01, -0.01, 0.012])
TENSIONS = np.array([20.0, 15.0, 30.0, 12.0, 25.0, 18.0, 22.0])  # N, held by the drives


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


class _TorqueBridge(ReelBridge):
    """Reels with a 20 ms lag whose drives report the force that holds TENSIONS, as the
    dynamic emulator's sensor (the speed after the step and its difference over the step);
    `speeds`: each step's reel speeds after it."""

    def __init__(self, robot):
        super().__init__(robot, cable_lengths(robot, robot.workspace.center),
                         time_constant=0.02)
        self._model = drive_model(robot.dynamics, robot.num_cables)
        self._accel = np.zeros(robot.num_cables)
        self.speeds = []

    def step(self, dt):
        before = self.speed.copy()
        super().step(dt)
        self._accel = (self.speed - before) / dt
        self.speeds.append(self.speed.copy())

    def drive_force(self):
        return drive_force_for_tension(TENSIONS, self.speed, self._accel, *self._model)


def _rig(robot, bridge=None, time_step=PERIOD, **overrides):
    """helpers_canopen.rig at `time_step` in lockstep, `tpdo2` and `faults` to the drives."""
    drive_args = {k: overrides.pop(k) for k in ("tpdo2", "faults") if k in overrides}
    config = CanopenReels(**dict(dict(interface="virtual", channel=fresh_channel(),
                                      ramp_time=0.0, force_sensor=bus_sensor(),
                                      lockstep=True), **overrides))
    return rig(robot, config, U, bridge=bridge or _TorqueBridge(robot), time_step=time_step,
               lockstep=config.lockstep, **drive_args)


def _run(sim, reels, drives, until):
    """Tick by tick to `until` s: per tick the reel speeds and tensions the controller used
    and the TPDO2s it had counted per drive."""
    speeds, tensions, counts = [], [], []
    start_realtime(sim, 0.0)
    for n in range(1, int(round(until / PERIOD)) + 1):
        # Tick n at n x PERIOD exactly, as Drake times its events (helpers_canopen.lockstep
        # sums the period: an ulp short now and then, and a tick's events run with the
        # next, which reads two TPDOs at once).
        sim.AdvanceTo(n * PERIOD)
        deadline = time.monotonic() + 2.0  # lockstep: the answers are waited for anyway
        while drives.syncs != reels.master.syncs and time.monotonic() < deadline:
            time.sleep(0.0002)
        context = reels.GetMyContextFromRoot(sim.get_context())
        speeds.append(reels.reel_speeds(context))
        counts.append(context.get_discrete_state(reels._drives).get_value()[D_COUNT2 * 7:(D_COUNT2 + 1) * 7].copy())
        tensions.append(reels.get_output_port(2).Eval(context).copy())
    return np.array(speeds), np.array(tensions), np.array(counts, dtype=int)


@pytest.mark.parametrize("faults", [(), (("late_tpdo", 1, 0.1),)], ids=["on time", "late"])
def test_velocity_actual_is_mapped_into_tpdo2_and_is_the_reels_true_speed(robot, caplog,
                                                                          faults):
    """reel_speed auto on a bus with room: every drive takes TPDO2 (0x1A01 = 0x606C, 32 bits,
    COB-ID 0x280 + node, synchronous); each tick's reel speed is the emulator's true speed
    after the SYNC its TPDO answers, within half the velocity quantum (1 unit = 1 um/s), and
    the tensions from the drive torque are TENSIONS within what the torque's 0.1 N units and
    the speed's quantum leave (J x quantum / T = 0.25 x 1e-6 / 0.004: negligible). A TPDO
    (and its TPDO2) a SYNC late is read with the next: no fault, none lost, the speed the
    newest, the acceleration over the two periods."""
    bridge = _TorqueBridge(robot)
    sim, reels, drives, _, _ = _rig(robot, bridge, faults=list(faults))
    try:
        with caplog.at_level(logging.INFO, logger="cdpm_drake.hardware.canopen_bus"):
            speeds, tensions, counts = _run(sim, reels, drives, 0.4)
        for d in drives.drives:
            assert d.tpdo2 == [((0x606C, 0), "<i")]
            assert d.od[(0x1801, 1)] & 0x7FF == 0x280 + d.node_id
            assert d.od[(0x1801, 1)] & 0x80000000 == 0 and d.od[(0x1801, 2)] == 1
        assert reels.master.velocity_mapped.all()
        assert "reel speed from velocity actual 0x606C in TPDO2" in caplog.text
        assert drives.tpdo2_sent >= 7 * 100 and reels.lost_tpdos == 0
        assert reels.book(reels.GetMyContextFromRoot(sim.get_context()))["fault"] == 0
        if faults:
            assert drives.fault_syncs["late_tpdo"] > 0 and drives.drives[1].held == []
    finally:
        close(reels, drives)
    if not faults:
        # In lockstep the update of tick k reads the answers to its own SYNC: after
        # AdvanceTo(n T) (publish n sent SYNC n, the update of n - 1 ran) the run's SYNCs
        # 0..n - 1 are answered, n per drive.
        run = counts - reels._count_start2
        assert (run == np.arange(1, len(run) + 1)[:, None]).all(), run[:3]
    truth = np.array(bridge.speeds)  # one step per SYNC, from the first after NMT start
    # The n-th TPDO2 of a drive answers the n-th SYNC: its velocity actual is the plant's
    # speed after that SYNC's step, truth[n - 1].
    assert counts.min() >= 1
    true = np.take_along_axis(truth, counts - 1, axis=0)
    quantum = 1.0 / 1e6  # m/s: velocity_units default = counts_per_metre
    assert np.abs(speeds - true).max() <= quantum / 2 + 1e-12
    # The reels accelerate over the run (a 20 ms lag to U): a speed a SYNC off would be off
    # by up to U x T / 20 ms (4 mm/s), which the line above would not pass.
    assert np.abs(speeds - np.take_along_axis(truth, counts, axis=0)).max() > 1000 * quantum
    # The torque's 0.1 N units (0.05 N), but where a late TPDO2 is read with the next: the
    # speed is the newest, the acceleration the mean over both periods, where the drive's
    # torque went with the last one's: off by J x the two accelerations' half difference.
    J = drive_model(robot.dynamics, 7)[0]
    accel = np.diff(truth, axis=0) / PERIOD  # accel[n - 1]: over the step of SYNC n
    late = np.diff(counts, axis=0) == 2  # ticks 1.. that read two TPDO2s
    assert late.sum() == len(faults)
    bound = np.full(tensions.shape, 0.05 + 1e-3)
    for j, k in zip(*np.nonzero(late)):
        n = counts[j + 1, k]
        bound[j + 1, k] += J * abs(accel[n - 2, k] - accel[n - 3, k]) / 2
    assert (np.abs(tensions[1:] - TENSIONS) <= bound[1:]).all()
    # From the first tick: the drives at rest when read at start-up, a measured speed.
    assert np.isfinite(tensions[0]).all()


def test_a_drive_that_refuses_tpdo2_runs_on_position_differences_and_says_so(robot, caplog):
    """Drives without 0x1801/0x1A01 (they abort the SDO transfers: object does not exist):
    reel_speed auto logs, per drive, the refusal and that its speed comes from position
    differences, sends no TPDO2, and each tick's speed is the difference of the two last
    position actuals over the period (the emulator's encoders, rounded to counts: the ground
    truth here), not the true speed (which leads it by about half a period's change)."""
    bridge = _TorqueBridge(robot)
    lengths = []
    step = bridge.step

    def recorded(dt):
        step(dt)
        lengths.append(bridge.encoder_lengths())

    bridge.step = recorded
    sim, reels, drives, _, _ = _rig(robot, bridge, tpdo2=False)
    try:
        with caplog.at_level(logging.INFO, logger="cdpm_drake.hardware.canopen_bus"):
            speeds, _, _ = _run(sim, reels, drives, 0.04)
        count = reels.GetMyContextFromRoot(sim.get_context()).get_discrete_state(
            reels._drives).get_value()[:7].astype(int)
        assert not reels.master.velocity_mapped.any() and drives.tpdo2_sent == 0
        assert reels.book(reels.GetMyContextFromRoot(sim.get_context()))["fault"] == 0
    finally:
        close(reels, drives)
    for k in range(7):
        assert re.search(rf"drive of cable {k + 1} \(node {k + 1}\) refused the SDO read of "
                         rf"TPDO2 COB-ID \(0x1801:1\).*; the reel speed of cable {k + 1} "
                         rf"comes from position differences", caplog.text)
    # The last tick's speed: positions of TPDOs n and n - 1 (n = its count), answering SYNCs
    # n and n - 1, lengths[n - 1] and lengths[n - 2].
    counts = np.round(np.array(lengths) * 1e6)
    expected = (counts[count - 1, range(7)] - counts[count - 2, range(7)]) / 1e6 / PERIOD
    np.testing.assert_allclose(speeds[-1], expected, rtol=0, atol=1e-9)
    truth = np.array(bridge.speeds)[count - 1, range(7)]
    assert np.abs(speeds[-1] - truth).max() > 1e-4  # the reels still accelerate


def test_velocity_actual_required_refuses_a_drive_without_tpdo2(robot):
    """reel_speed: velocity_actual on drives that abort the mapping: the start is refused,
    naming the drive and the object."""
    sim, reels, drives, _, _ = _rig(robot, tpdo2=False, reel_speed="velocity_actual")
    try:
        with pytest.raises(ReelFault, match=r"refusing to enable the drives: drive of cable 1 "
                           r"\(node 1\) refused the SDO write of TPDO2 COB-ID \(disable\) "
                           r"\(0x1801:1\)"):
            start_realtime(sim, 0.0)
    finally:
        close(reels, drives)


def test_a_lost_tpdo2_is_a_fault_and_stops_the_drives_within_3_ticks(robot):
    """The drive of cable 2 stops sending TPDO2 (its TPDO1 goes on): after missed_tpdo_ticks
    = 2 ticks without one the run stops, naming it; target velocity 0 on every drive with
    the SYNC of the tick that sees it, disabled with the next (the drives' record), as for a
    lost TPDO (test_canopen.py: 3 and 4 SYNCs after the last one before the fault). On the
    wall clock, paced by helpers_canopen.lockstep (in lockstep each missing answer is waited
    for, startup_timeout s)."""
    sim, reels, drives, _, _ = _rig(robot, faults=[("lost_tpdo2", 1, 0.1)], lockstep=False)
    try:
        start_realtime(sim, 0.0)
        with pytest.raises(ReelFault, match=r"no TPDO2 \(velocity actual\) from the drive of "
                           r"cable 2 \(node 2\) for 2 ticks \(missed_tpdo_ticks = 2\)"):
            lockstep(sim, reels, drives, 0.4, T=PERIOD)
        # The two SYNCs the update saw unanswered by cable 2's TPDO2.
        assert reels.lost_tpdos == 2
    finally:
        close(reels, drives)
    zero, off, disabled = drives.fault_counts("lost_tpdo2")
    assert (zero, off, disabled) == (3, 3, 4)


def test_reel_speed_auto_takes_positions_where_the_bus_has_no_room_and_the_refusals(robot,
                                                                                   caplog):
    """TPDO2 is 4 bytes, 79 bits a frame; 7 of them on top of 1607.7 bits per 2 ms
    (test_wiring_canopen's count) make 2160.7 of the 2000 a 1 Mbit/s bus carries in 2 ms:
    reel_speed: velocity_actual is refused naming it, auto runs on positions without asking
    the drives (no TPDO2 sent) and says why; a reel_speed not in the list is refused."""
    assert frame_bits(4) == (79, 95)
    base = CanopenReels(force_sensor=bus_sensor())
    assert bus_load(7, 1_000_000, 0.002, 0.1, 1, True)["bits"] == pytest.approx(
        bus_load(7, 1_000_000, 0.002, 0.1, 1)["bits"] + 7 * 79)
    with pytest.raises(ValueError, match=r"7 TPDO2s \(reel_speed: velocity_actual\) of 79 "
                       r"bits.* 108.0 % .*reel_speed: position or auto"):
        check_canopen_reels(CanopenReels(force_sensor=bus_sensor(),
                                         reel_speed="velocity_actual"), 7, 0.002)
    assert check_canopen_reels(base, 7, 0.002)["load"] == pytest.approx(0.80385)
    with pytest.raises(ValueError, match=r"plant.reel_speed must be one of auto, "
                       r"velocity_actual, position, got 'velocity'"):
        check_canopen_reels(CanopenReels(reel_speed="velocity"), 7, 0.002)
    sim, reels, drives, _, _ = _rig(robot, time_step=0.002)
    try:
        with caplog.at_level(logging.INFO, logger="cdpm_drake.hardware.canopen_reels"):
            start_realtime(sim, 0.0)
            lockstep(sim, reels, drives, 0.05)
        assert not reels.master.velocity_mapped.any() and drives.tpdo2_sent == 0
        assert all(d.od[(0x1801, 1)] & 0x80000000 for d in drives.drives)  # never written
    finally:
        close(reels, drives)
    assert ("reel speed from position differences: TPDO2 (velocity actual) of 7 drives "
            "would load the bus to 108 % (more than 90 %)") in caplog.text


def test_the_emulated_drive_reads_velocity_0_on_a_frozen_encoder(robot):
    """velocity actual comes from the encoder: frozen_position stops it at 0 (SDO and
    TPDO2 alike), where the reel still turns."""
    import can as _can

    from cdpm_drake.emulator.canopen_drives import EmulatedDrives

    bridge = _TorqueBridge(robot)
    bridge.set_command(U, enable=True)
    bridge.step(PERIOD)
    bus = _can.Bus(interface="virtual", channel=fresh_channel(), receive_own_messages=False)
    drives = EmulatedDrives(bridge, bus, list(range(1, 8)), period=PERIOD)
    try:
        d = drives.drives[1]
        assert drives._value(d, (0x606C, 0)) == round(bridge.speed[1] * 1e6) != 0
        drives.inject("frozen_position", 1)
        assert drives._value(d, (0x606C, 0)) == 0
    finally:
        drives.stop()
