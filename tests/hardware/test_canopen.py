"""`plant: !CanopenReels` against the emulated CiA 402 drives on python-can's `virtual` bus, in
one process: the configuration and its refusals, the bus-load budget, the life cycle (SDO
mapping, NMT, enable sequence), the lengths against the commanded velocities, and each fault
ending in zero target velocity and disabled drives within 3 ticks.

The drives' record (EmulatedDrives.record: per SYNC, each drive's state, controlword and
target velocity) is the ground truth of what reached the drives; the plant behind them
(ReelBridge, ideal drives) integrates the target velocities exactly."""

import numpy as np
import pytest

can = pytest.importorskip("can", reason="the canopen extra (python-can) is not installed")
pytest.importorskip("canopen", reason="the canopen extra is not installed")

from cdpm_drake.config import ScenarioError, load_scenario
from cdpm_drake.emulator.canopen_drives import Drive
from cdpm_drake.hardware.canopen_config import (CanopenReels, bus_load, check_canopen_reels,
                                                frame_bits, max_drives)
from cdpm_drake.hardware.reels import ReelFault, start_realtime
from cdpm_drake.robot import load_robot
from helpers_canopen import T, bus_sensor, close, fresh_channel, lockstep, rig

# Each cable's command, m/s: all of them at least the frozen-position speed (10 mm/s) and small
# enough to stay in the workspace for the runs' 1-2 s.
U = np.array([0.02, -0.02, 0.015, -0.015, 0.01, -0.01, 0.012])


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


def _rig(robot, *, faults=(), u=U, **overrides):
    """helpers_canopen.rig with a CanopenReels on a fresh virtual channel, ramp_time 0."""
    config = CanopenReels(**dict(dict(interface="virtual", channel=fresh_channel(),
                                      ramp_time=0.0, force_sensor=bus_sensor()), **overrides))
    return rig(robot, config, u, faults=faults)


_lockstep = lockstep


def _close(reels, drives):
    close(reels, drives)


def test_config_from_yaml_and_refusals_name_the_field(robot):
    scenario = load_scenario("exp1_no_interaction", overlay_text=(
        "{plant: !CanopenReels {interface: virtual, channel: c, node_ids: [7, 6, 5, 4, 3, 2, "
        "1], counts_per_metre: 4096.0}}"))
    # The residual bound unset is derived from the scenario's robot (robot.stretch).
    from cdpm_drake.config import scenario_robot
    from cdpm_drake.robot.stretch import derived_length_residual
    assert scenario.plant == CanopenReels(
        interface="virtual", channel="c", node_ids=[7, 6, 5, 4, 3, 2, 1],
        counts_per_metre=4096.0,
        max_length_residual=derived_length_residual(scenario_robot(scenario)))
    for text, match in (("node_ids: [1, 2, 3]", r"plant.node_ids must have one node id per "
                         r"cable \(7\), got \[1, 2, 3\]"),
                        ("node_ids: [1, 2, 3, 4, 5, 6, 6]", r"node_ids must be distinct"),
                        ("node_ids: [1, 2, 3, 4, 5, 6, 128]",
                         r"plant.node_ids\[6\] \(cable 7\) must be an integer in 1..127"),
                        ("counts_per_metre: 0.0", r"plant.counts_per_metre must be a finite "
                         r"non-zero number \(counts/m\), got 0.0"),
                        ("heartbeat_timeout: 0.05", r"heartbeat_timeout must exceed "
                         r"heartbeat_period \(0.1 s\), got 0.05"),
                        ("tension_sensor: load_cell", r"plant.tension_sensor must be one of "
                         r"drive_torque, none, got 'load_cell'")):
        with pytest.raises(ScenarioError, match=match):
            load_scenario("exp1_no_interaction", overlay_text=(
                f"{{plant: !CanopenReels {{interface: virtual, {text}}}}}"))


def test_bus_load_counts_the_frames_bits_and_refuses_an_overloaded_bus():
    # ISO 11898-1 classic base frame: 1 SOF + 11 id + RTR + IDE + r0 + 4 DLC + 8n data + 15 CRC
    # = 34 + 8n bits that are stuffed, + CRC delimiter, ACK slot and delimiter, 7 EOF, 3 IFS.
    assert frame_bits(8) == (34 + 64 + 13, 34 + 64 + 13 + (34 + 64 - 1) // 4) == (111, 135)
    assert frame_bits(0) == (47, 55)
    # 7 drives, 2 ms at 1 Mbit/s: 7 RPDOs (6 bytes: 95 bits) + 7 TPDOs (111) + SYNC (47)
    # + 7 heartbeats (1 byte: 55 bits) every 100 ms, i.e. 2 % of one per cycle.
    load = bus_load(7, 1_000_000, 0.002, 0.1)
    assert load["bits"] == pytest.approx(7 * (95 + 111 + 0.02 * 55) + 47)
    assert load["load"] == pytest.approx((7 * (95 + 111 + 1.1) + 47) / 2000)
    # 9 drives: (9 * 207.1 + 47) / 2000 = 95.5 % > 90 %; 8 drives (85.2 %) fit.
    assert max_drives(1_000_000, 0.002, 0.1) == 8
    assert max_drives(500_000, 0.002, 0.1) == 4
    with pytest.raises(ValueError, match=r"9 drives at 1000000 bit/s with a 2 ms cycle need "
                       r"1911 bits per cycle .* 95.5 % of the 2000 bits the cycle holds: more "
                       r"than 90 % .* at most 8 drives here: split the drives onto a second "
                       r"channel"):
        check_canopen_reels(CanopenReels(), 9, 0.002)
    assert check_canopen_reels(CanopenReels(), 8, 0.002)["load"] == pytest.approx(0.8519)


def test_life_cycle_mapping_and_lengths_follow_the_commands(robot):
    # 25 ticks, as the UDP run tests: this in-process bus shares the GIL with the drives.
    sim, reels, drives, bridge, L0 = _rig(robot, missed_tpdo_ticks=25)
    try:
        start_realtime(sim)
        sim.AdvanceTo(1.0)
        context = reels.GetMyContextFromRoot(sim.get_context())
        measured = reels.get_output_port(0).Eval(context).copy()
        _close(reels, drives)
    finally:
        drives.stop()
    for d in drives.drives:
        # The mapping the controller wrote over SDO, in force from NMT start on.
        assert [k for k, _ in d.rpdo] == [(0x6040, 0), (0x60FF, 0)]
        assert [k for k, _ in d.tpdo] == [(0x6041, 0), (0x6064, 0), (0x6077, 0)]
        assert d.od[(0x6060, 0)] == 9 and d.od[(0x1017, 0)] == 100
        # The SYNC period as 0x60C2: 2 x 10^-3 s.
        assert (d.od[(0x60C2, 1)], d.od[(0x60C2, 2)]) == (2, -3)
        assert d.state == "switch on disabled"  # close(): disable voltage
    states = [r[1][0] for r in drives.record]
    # The enable sequence, one transition per SYNC: shutdown, switch on, enable operation.
    seen = [s for i, s in enumerate(states) if i == 0 or s != states[i - 1]]
    assert seen[:4] == ["switch on disabled", "ready to switch on", "switched on",
                        "operation enabled"]
    enabled = [r for r in drives.record if r[1][0] == "operation enabled"]
    # The target velocities the drives received: U in counts/s (1e6 counts/m), rounded.
    targets = np.array([r[3] for r in enabled])
    moving = targets[np.any(targets != 0, axis=1)]
    assert np.abs(moving - U).max() <= 0.5e-6
    # Ideal drives: each SYNC in operation enabled moves a cable by its target x T.
    np.testing.assert_allclose(bridge.lengths - L0, targets.sum(axis=0) * T, atol=1e-12)
    # The controller's lengths: position actual (1 um counts) after one of the SYNCs (the
    # last it had read when the run stopped; this in-process bus shares the GIL with the
    # drives, so which one depends on the host's load: within missed_tpdo_ticks of the end).
    moved = np.cumsum([np.asarray(r[3]) * T * (np.array(r[1]) == "operation enabled")
                       for r in drives.record], axis=0)
    off = np.abs(measured - L0 - moved).max(axis=1)
    assert off.min() <= 1e-6 and np.argmin(off) >= len(moved) - 25 - 3, (off.min(),
                                                                         np.argmin(off))
    assert len(moving) >= 0.9 * 500  # at most a few ticks of 500 lost to the host


def test_enable_timeout_names_the_node_and_its_statusword(robot, monkeypatch):
    original = Drive.apply_controlword

    def stuck(self, cw):
        if self.node_id != 3:  # node 3 never leaves switch on disabled
            original(self, cw)

    monkeypatch.setattr(Drive, "apply_controlword", stuck)
    sim, reels, drives, _, _ = _rig(robot, enable_timeout=0.2)
    try:
        with pytest.raises(ReelFault, match=r"enable sequence timed out: cable 3 \(node 3\) not "
                           r"in operation enabled within enable_timeout = 0.2 s, statusword "
                           r"0x0250 \(switch on disabled\)$"):
            start_realtime(sim)
        _close(reels, drives)
    finally:
        drives.stop()
    assert [d.state for d in drives.drives if d.node_id != 3] == ["switch on disabled"] * 6


def test_a_drive_in_fault_at_start_is_refused_unless_fault_reset(robot):
    for reset in (False, True):
        sim, reels, drives, _, _ = _rig(robot, fault_reset=reset)
        drives.drives[1].state = "fault"
        try:
            if reset:
                start_realtime(sim)
                assert [d.state for d in drives.drives] == ["operation enabled"] * 7
            else:
                with pytest.raises(ReelFault, match=r"cable 2 \(node 2\) is in fault, "
                                   r"statusword 0x0218; .* fault_reset: true"):
                    start_realtime(sim)
            _close(reels, drives)
        finally:
            drives.stop()


# Each fault: (kinds injected on cable 2, settings, the message, zero, disabled). zero and
# disabled count SYNCs from the last one before the fault (the first after it is 1, the SYNC
# s whose TPDO is the first to show it, the drive's onset). In lockstep every TPDO is read
# on the tick after its SYNC, unless held back a SYNC (late_tpdo): the fault shows on tick
# s + 1 (s + 2 late), or after missed_tpdo_ticks = 2 ticks of silence (tick s + 2), the
# quick stop goes with that tick's SYNC, disable voltage with the next. The EMCY of a drive
# fault comes as it happens: read on tick s (quick stop 1) or, if it comes just after that
# tick's read, s + 1 (2). Without the per-TPDO count of unchanged positions, frozen_ticks 2
# with a late TPDO would take a tick more (the two TPDOs read on one tick counted once).
FAULTS = [
    (("drive_fault",), {}, r"the drive of cable 2 \(node 2\) sent EMCY error code 0x2310",
     (1, 2), 3),
    (("fault_bit",), {}, r"cable 2 \(node 2\) reports statusword 0x0218 \(fault\)", 2, 3),
    (("fault_bit", "late_tpdo"), {}, r"reports statusword 0x0218 \(fault\)", 3, 4),
    (("frozen_position",), {}, r"the drive of cable 2 \(node 2\)'s position actual has not "
                               r"changed for 1 TPDOs", 2, 3),
    (("frozen_position", "late_tpdo"), {}, r"has not changed for 2 TPDOs", 3, 4),
    # Two unchanged TPDOs read on one tick count as two: stopped as soon as on time.
    (("frozen_position", "late_tpdo"), {"frozen_ticks": 2}, r"has not changed for 2 TPDOs",
     3, 4),
    (("lost_tpdo",), {}, r"no TPDO from the drive of cable 2 \(node 2\) for 2 ticks", 3, 4),
    (("dead_node",), {}, r"no TPDO from the drive of cable 2 \(node 2\) for 2 ticks", 3, 4),
    (("bus_off",), {}, r"no TPDO from the drive of cable \d \(node \d\) for 2 ticks", None,
     None),
]


@pytest.mark.parametrize("kinds, settings, message, zero, disabled", FAULTS,
                         ids=["+".join(f[0]) + "".join(f"-{k}{v}" for k, v in f[1].items())
                              for f in FAULTS])
def test_each_fault_ends_in_zero_velocity_and_disabled_drives_within_3_ticks(
        robot, kinds, settings, message, zero, disabled):
    """Quick stop (target velocity 0) with the SYNC of the tick that sees the fault, disable
    voltage (switch on disabled) with the next: by the drive's record, both within 3 SYNCs of
    the drive's onset (SYNC 1 here), 4 after the last SYNC before the fault."""
    sim, reels, drives, bridge, _ = _rig(robot, faults=[(k, 1, 0.3) for k in kinds],
                                         **settings)
    try:
        start_realtime(sim, 0.0)
        with pytest.raises(ReelFault, match=message):
            _lockstep(sim, reels, drives, 2.0)
        _close(reels, drives)
    finally:
        drives.stop()
    kind = kinds[0]
    injected = drives.fault_syncs[kind]  # the last SYNC before the fault
    after = [r for r in drives.record if r[0] > injected]
    live = [k for k in range(7) if not (kind == "dead_node" and k == 1)]
    if kind == "bus_off":
        # Nothing reaches the drives any more: each stops itself (CiA 301 error behaviour).
        assert after == [] and all(d.state != "operation enabled" for d in drives.drives)
        assert not bridge.command.any()
        return
    counts = drives.fault_counts(kind)
    # At most as expected: a TPDO late before the fault (lockstep gives up waiting after
    # 0.1 s on a loaded host) starts a silence a tick sooner.
    zero = max(zero) if isinstance(zero, tuple) else zero
    assert 1 <= counts[0] <= zero and counts[1:] == (counts[0], counts[0] + 1), counts
    assert counts[2] <= disabled
    stopped, off = after[counts[0] - 1], after[counts[2] - 1]
    assert all(stopped[2][k] == 0x0002 for k in live)  # quick stop, target velocity 0
    assert {k: stopped[1][k] for k in live if k != 1} == {
        k: "quick stop active" for k in live if k != 1}
    assert all(off[3][k] == 0 and off[2][k] == 0 for k in live)  # disable voltage
    expected = {k: "switch on disabled" for k in live}
    if kind in ("drive_fault", "fault_bit"):
        expected[1] = "fault"
    assert {k: off[1][k] for k in live} == expected
    # Before the fault they were driven at U.
    before = [r for r in drives.record if r[0] <= injected][-1]
    assert np.allclose(before[3], U, atol=1e-6)


def test_a_late_tpdo_alone_is_no_fault_and_moves_the_speed_by_its_periods(robot):
    """A TPDO a SYNC late is read with the next one: neither silence (missed_tpdo_ticks 2)
    nor a frozen position (the two positions differ from the one before), and the reel speed
    behind the drive-torque tension is the position change over both periods: U on every
    tick (ideal drives, 1 um counts: to a count a period), not 2 U on the late one."""
    sim, reels, drives, _, _ = _rig(robot, faults=[("late_tpdo", 1, 0.3)])
    speeds = []
    try:
        start_realtime(sim, 0.0)
        t = 0.0
        while "late_tpdo" not in drives.fault_syncs or drives.syncs < (
                drives.fault_syncs["late_tpdo"] + 10):
            t += T
            _lockstep(sim, reels, drives, t)
            context = reels.GetMyContextFromRoot(sim.get_context())
            speeds.append(context.get_discrete_state(reels._drives).get_value()[4 * 7 + 1])
        assert reels.book(context)["fault"] == 0 and drives.drives[1].held == []
        # Late, not lost: it came, with the next SYNC's (lost counts TPDOs that never came).
        assert reels.lost_tpdos == 0
    finally:
        _close(reels, drives)
    assert np.abs(np.array(speeds[-20:]) - U[1]).max() <= 1e-6 / T


def test_coarse_counts_lengthen_the_frozen_window(robot):
    """A slow drive with coarse counts leaves its position unchanged for ticks on end: the
    window is as many TPDOs as 3 counts take at frozen_speed (closed form: 10 mm/s x 2 ms x
    10 000 counts/m = 0.2 count per tick -> 15 TPDOs), and frozen_ticks (1) where that is
    fewer."""
    from cdpm_drake.hardware.canopen_reels import CanopenReelsSystem

    coarse = CanopenReelsSystem(robot, CanopenReels(counts_per_metre=10_000.0,
                                                    force_sensor=bus_sensor()), time_step=T)
    fine = CanopenReelsSystem(robot, CanopenReels(counts_per_metre=-1_000_000.0,
                                                  force_sensor=bus_sensor()), time_step=T)
    assert coarse._frozen_ticks == 15 and fine._frozen_ticks == 1


def test_a_drive_without_heartbeat_or_mode_read_back_is_watched_by_its_tpdos(robot,
                                                                                monkeypatch):
    """Drives whose dictionaries have no 0x1017 and no 0x6061 (their SDO servers abort them:
    7 x 2 refusals noted) still run: their heartbeats are not watched, and a silent one still
    stops every drive."""
    from cdpm_drake.emulator import canopen_drives

    objects = {k: v for k, v in canopen_drives.OBJECTS.items()
               if k not in ((0x1017, 0), (0x6061, 0))}
    monkeypatch.setattr(canopen_drives, "OBJECTS", objects)
    sim, reels, drives, _, _ = _rig(robot, faults=[("lost_tpdo", 0, 0.1)])
    try:
        start_realtime(sim, 0.0)
        assert not reels.master.heartbeat_watched.any()
        assert len(reels.master.notes) == 14 and "0x1017:0" in reels.master.notes[0]
        with pytest.raises(ReelFault, match=r"no TPDO from the drive of cable 1 \(node 1\) "
                           r"for 2 ticks"):
            _lockstep(sim, reels, drives, 1.0)
    finally:
        _close(reels, drives)


def test_drives_without_heartbeats_run_and_a_wrong_nmt_state_is_refused(robot, monkeypatch):
    """Drives that take 0x1017 but never send a heartbeat run, watched by their TPDOs (a note
    each); a heartbeat that says pre-operational (0x7F) while TPDOs flow is refused."""
    from cdpm_drake.emulator import canopen_drives

    monkeypatch.setattr(canopen_drives.EmulatedDrives, "_heartbeats", lambda self, now: None)
    sim, reels, drives, _, _ = _rig(robot)
    try:
        start_realtime(sim, 0.0)
        assert not reels.master.heartbeat_watched.any()
        assert [n.split(" within")[0] for n in reels.master.notes] == [
            f"no heartbeat from the drive of cable {k} (node {k})" for k in range(1, 8)]
    finally:
        _close(reels, drives)
    monkeypatch.undo()
    monkeypatch.setattr(canopen_drives, "NMT_STATE", dict(canopen_drives.NMT_STATE,
                                                          operational=0x7F))
    sim, reels, drives, _, _ = _rig(robot)
    try:
        with pytest.raises(ReelFault, match=r"cable 1 \(node 1\) sends TPDOs but its heartbeat "
                           r"reports NMT state 127, not operational \(5\)"):
            start_realtime(sim, 0.0)
    finally:
        _close(reels, drives)
