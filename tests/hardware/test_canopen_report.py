"""What a `plant: !CanopenReels` run tells its user: the TPDOs lost on a clean bus (none), the
bus's interface and channel and the drives' rated torque in the end report, a dead node's
SDO timeout said as such (not "refused", and no stray log line of the canopen library), and
negative velocity and torque factors (a drive that counts or turns the other way) working as
documented. Against the emulated drives on python-can's virtual bus, tick by tick."""

import numpy as np
import pytest

can = pytest.importorskip("can", reason="the canopen extra (python-can) is not installed")
pytest.importorskip("canopen", reason="the canopen extra is not installed")

from cdpm_drake.emulator.bridges import ReelBridge
from cdpm_drake.hardware.canopen_config import CanopenReels
from cdpm_drake.hardware.reels import ReelFault, start_realtime
from cdpm_drake.kernels.drive_torque import tension_from_drive
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.robot import load_robot
from cdpm_drake.runs.realtime import RunResult, report_lines
from cdpm_drake.text import prefixed_log_records
from helpers_canopen import T, bus_sensor, close, fresh_channel, lockstep, rig

U = np.array([0.02, 0.0, -0.015, 0.0, 0.01, 0.0, -0.012])


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


def _config(**fields):
    return CanopenReels(**dict(dict(interface="virtual", channel=fresh_channel(),
                                    ramp_time=0.0, force_sensor=bus_sensor(),
                                    missed_tpdo_ticks=25), **fields))


def test_a_clean_bus_loses_no_tpdo_and_the_report_names_the_bus(robot):
    config = _config()
    sim, reels, drives, _, _ = rig(robot, config, U)
    try:
        start_realtime(sim, 0.0)
        lockstep(sim, reels, drives, 0.3)
        counters = reels.link.counters.as_dict()
    finally:
        close(reels, drives)
    # Every SYNC answered by every drive (the lockstep waits for it): nothing lost. The count
    # was 7 before, one per drive for tick 0, whose update follows no SYNC of the run.
    assert counters["lost"] == 0
    assert reels.master.syncs >= 150 and drives.tpdo_sent >= 7 * 150
    result = RunResult(log={}, timing={}, link=counters, error=None, ending="completed",
                       log_path=None, tick_log_path=None, signal=None)
    text = "\n".join(report_lines(result))
    assert "statuses received" in text and ", lost 0," in text, text
    # These drives have no 0x6076: said so, not left out.
    assert (f"CAN bus virtual '{config.channel}': rated torque 0x6076 not given by the "
            f"drives (force_per_torque_unit 0.1 N per per mille)") in text, text


def test_a_dead_node_did_not_answer_within_the_sdo_timeout(robot, capsys):
    sim, reels, drives, _, _ = rig(robot, _config(), U)
    drives.drives[1].dead = True  # node 2 sends nothing and ignores the bus
    try:
        with prefixed_log_records(), pytest.raises(ReelFault) as fault:
            start_realtime(sim, 0.0)
    finally:
        close(reels, drives)
    message = str(fault.value)
    assert ("refusing to enable the drives: drive of cable 2 (node 2) did not answer the SDO "
            "write of modes of operation (0x6060:0) within the SDO timeout (2 x 0.3 s)") \
        in message, message
    assert "refused" not in message
    # canopen's own "Transfer aborted by client with code 0x05040000" is not printed beside.
    err = capsys.readouterr().err
    assert "Transfer aborted" not in err and "error:" not in err, err


class _LoadedBridge(ReelBridge):
    """Ideal reels whose drives report FORCE (N at the cable)."""

    def drive_force(self):
        return FORCE.copy()


FORCE = -np.array([20.0, 21.5, 23.0, 24.5, 26.0, 27.5, 29.0])


def test_negative_velocity_and_torque_factors(robot):
    """A drive whose positive target velocity winds the cable in (velocity_units_per_mps <
    0) and whose positive torque pulls it in (force_per_torque_unit < 0), configured alike in
    the controller and the drives: the cables still move as commanded and the tensions come
    out as with positive factors."""
    config = _config(velocity_units_per_mps=-40_000.0, force_per_torque_unit=-0.05)
    L0 = cable_lengths(robot, robot.workspace.center)
    bridge = _LoadedBridge(robot, L0, time_constant=0.0)
    sim, reels, drives, bridge, _ = rig(robot, config, U, bridge=bridge,
                                        velocity_units=-40_000.0,
                                        force_per_torque_unit=-0.05)
    try:
        start_realtime(sim, 0.0)
        lockstep(sim, reels, drives, 0.3)
        context = reels.GetMyContextFromRoot(sim.get_context())
        tension = reels.GetOutputPort("tension_measured").Eval(context).copy()
    finally:
        close(reels, drives)
    # What reached the drives: -40 000 units per m/s of U.
    enabled = np.array([r[3] for r in drives.record if r[1][0] == "operation enabled"])
    moving = enabled[np.any(enabled != 0, axis=1)]
    assert np.abs(moving - U).max() <= 0.5 / 40_000 + 1e-12
    # The cables paid out as commanded (not the other way): the bridge integrated U.
    moved = bridge.lengths - L0
    assert np.all(np.sign(moved[U != 0]) == np.sign(U[U != 0]))
    # Torque actual = FORCE / -0.05 per mille, read back x -0.05: FORCE on the still cables.
    d = robot.dynamics
    expected = np.empty(7)
    tension_from_drive(FORCE, np.zeros(7), np.zeros(7), float(d.reel_inertia),
                       float(d.viscous_friction), float(d.coulomb_friction),
                       float(d.dead_band), expected)
    still = U == 0
    np.testing.assert_allclose(tension[still], expected[still], atol=0.05)


def test_negative_factors_are_documented_and_zero_refused():
    from pathlib import Path

    from cdpm_drake.hardware.canopen_config import check_canopen_reels

    reference = (Path(__file__).resolve().parents[2] / "docs" / "scenario_reference.md")
    rows = {line.split("|")[1].strip(" `"): line for line in reference.read_text().splitlines()
            if line.startswith("| `")}
    for name in ("counts_per_metre", "velocity_units_per_mps", "force_per_torque_unit"):
        assert "negative" in rows[name].lower(), rows[name]
        check_canopen_reels(CanopenReels(**{name: -3.0}), 7, 0.002)  # accepted
        with pytest.raises(ValueError, match=rf"plant.{name} must be a finite non-zero number"):
            check_canopen_reels(CanopenReels(**{name: 0.0}), 7, 0.002)
