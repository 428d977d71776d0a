"""The reel speed over CANopen: velocity actual 0x606C in TPDO2 (`reel_speed`), against the
emulated drives on python-can's `virtual` bus, tick by tick (helpers_canopen.lockstep).

The ground truth is the emulator's plant: a ReelBridge whose reels follow their command with a
20 ms lag (so that speed and acceleration change every tick) and whose drives report the force
that holds known cable tensions, computed as the emulator's dynamic plant does (the reel speed
after the step, its difference over the step: kernels/drive_torque.drive_force_for_tension).
At 7 drives TPDO2 fits a 1 Mbit/s bus at a 4 ms period (54 %), not at 2 ms (108 %)."""

import logging

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


def _rig(robot, bridge=None, **overrides):
    drive_args = {k: overrides.pop(k) for k in ("tpdo2", "faults") if k in overrides}
    config = CanopenReels(**dict(dict(interface="virtual", channel=fresh_channel(),
                                      ramp_time=0.0, force_sensor=bus_sensor(),
                                      lockstep=True), **overrides))
    return rig(robot, config, U, bridge=bridge or _TorqueBridge(robot), time_step=PERIOD,
               **drive_args)


def _run(sim, reels, drives, until):
    """Tick by tick to `until` s: per tick the reel speeds and tensions the controller used
    and the TPDO2s it had counted per drive."""
    speeds, tensions, counts = [], [], []
    t = 0.0
    start_realtime(sim, 0.0)
    while t < until - 1e-9:
        t += PERIOD
        lockstep(sim, reels, drives, t, T=PERIOD)
        context = reels.GetMyContextFromRoot(sim.get_context())
        speeds.append(reels.reel_speeds(context))
        counts.append(context.get_discrete_state(reels._drives).get_value()[D_COUNT2 * 7:(D_COUNT2 + 1) * 7].copy())
        tensions.append(reels.get_output_port(2).Eval(context).copy())
    return np.array(speeds), np.array(tensions), np.array(counts, dtype=int)


def test_velocity_actual_is_mapped_into_tpdo2_and_is_the_reels_true_speed(robot, caplog):
    """reel_speed auto on a bus with room: every drive takes TPDO2 (0x1A01 = 0x606C, 32 bits,
    COB-ID 0x280 + node, synchronous); each tick's reel speed is the emulator's true speed
    after the SYNC its TPDO answers, within half the velocity quantum (1 unit = 1 um/s), and
    the tensions from the drive torque are TENSIONS within what the torque's 0.1 N units and
    the speed's quantum leave (J x quantum / T = 0.25 x 1e-6 / 0.004: negligible)."""
    bridge = _TorqueBridge(robot)
    sim, reels, drives, _, _ = _rig(robot, bridge)
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
    finally:
        close(reels, drives)
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
    np.testing.assert_allclose(tensions[1:], np.broadcast_to(TENSIONS, tensions[1:].shape),
                               atol=0.05 + 1e-3)
    # From the first tick: the drives at rest when read at start-up, a measured speed.
    assert np.isfinite(tensions[0]).all()
