"""CanopenReelsSystem: CiA 402 servo drives on a CANopen bus as a Drake plant, with the ports
of the other plants (the diagram does not change). hardware/CANOPEN.md describes the bus.

Events at the control rate (period `time_step`), as HardwareReelsSystem's:

* initialisation (inside Simulator.Initialize): SDO configuration of each drive (mode 9,
  cyclic synchronous velocity; RPDO1 = controlword 0x6040 + target velocity 0x60FF; TPDO1 =
  statusword 0x6041 + position actual 0x6064 + torque actual 0x6077; TPDO2 = velocity actual
  0x606C where `reel_speed` asks for it and the bus has room; heartbeat 0x1017), NMT
  start, the first TPDO of every drive within `startup_timeout`, the measured lengths checked
  against the robot file, then the enable sequence (shutdown, switch on, enable operation)
  with a deadline of `enable_timeout` per drive; a drive that misses it is named with its
  statusword. A drive in Fault is refused unless `fault_reset: true`.
* discrete update at t_k: reads the drives' TPDOs, EMCY and heartbeats as they were when
  the tick's publish sent its SYNC (CanopenMaster.sync_snapshot: what came in over the
  period just ended, not what this tick's own SYNC brought back meanwhile; in lockstep, the
  answers to the tick's own SYNC, CanopenMaster.answered_snapshot) into the lengths and
  tensions (the reel speed from velocity actual where TPDO2 is mapped, else from positions),
  and judges them: a drive's fault bit or any state but operation
  enabled, an EMCY with an error code, no TPDO (or no TPDO2 from a drive that maps it) for
  `missed_tpdo_ticks` ticks (and as many
  periods less one of wall time, as HardwareReels's watchdog: a catch-up burst after a stall
  of this process must not trip it), a heartbeat older than `heartbeat_timeout` or not
  operational, a frozen position (`frozen_ticks` TPDOs in a row with the position of the one
  before, counted per frame by the bus, or as many as 3 counts take at `frozen_speed`, while
  commanded at least `frozen_speed` the same way for 10 ticks more), a CAN send error
  (bus-off). Any of them latches the fault.
* publish at t_k: on the wall clock, judges the TPDOs received since the last update the
  same way (Drake runs the update at t_k right after this publish: without it a fault would
  stop the drives a tick later; in lockstep no SYNC went out since the update). Running: one RPDO per drive (enable operation, ramp x reel_velocity_command
  in drive units) and a SYNC. After a fault (or a non-finite command), the stop, one SYNC a
  tick as ever (a CSV drive watches the SYNC period): this tick's RPDOs carry target
  velocity 0 with quick stop, the next tick's target velocity 0 with disable voltage (to
  switch on disabled), and that publish raises ReelFault, ending the run with its log. So a
  fault whose first sign is the TPDO of SYNC s (the drive's onset) has every drive quick
  stopped at SYNC s + 1 + d and disabled at s + 2 + d, d the ticks its detection waits
  (0 for a fault bit or frozen position, 1 for a silent drive or a late TPDO).

The bus (CanopenMaster) is a resource held as an attribute; after the SDO configuration it
is read in the events themselves, without blocking, as HardwareReelsSystem reads its socket; what the
system outputs and judges lives in the Context, except facts about the commands sent that a
publish keeps (it cannot write the Context), like HardwareReelsSystem's `_stopped_at`: the
count of consecutive commands above `frozen_speed`, the stop's stage, and the fault a
publish found (the update latches it).
"""

import dataclasses
import logging
import time

import numpy as np
from pydrake.systems.framework import LeafSystem

from cdpm_drake.hardware.canopen_bus import (CW_DISABLE_VOLTAGE, CW_ENABLE_OPERATION,
                                             CW_FAULT_RESET, CW_QUICK_STOP, CW_SHUTDOWN,
                                             CW_SWITCH_ON, HEARTBEAT_OPERATIONAL, NMT_START,
                                             SW_FAULT_BIT, CanopenError, CanopenMaster,
                                             state_name)
from cdpm_drake.hardware.canopen_config import (MAX_BUS_LOAD, CanopenReels, bus_load,
                                                check_canopen_reels, resolved_node_ids,
                                                resolved_offsets, velocity_fits,
                                                velocity_units)
from cdpm_drake.hardware.force_config import CanopenForceSensor, force_source_problem
from cdpm_drake.hardware.force_sources import (RDT_STATUS_ERROR, ForceScale, ForceSensorError,
                                               NetFTSource)
from cdpm_drake.hardware.reels import ReelFault, start_pose_problem
from cdpm_drake.kernels.drive_torque import drive_model, tension_from_drive
from cdpm_drake.kernels.kinematics import KinematicsError, cable_lengths, forward_kinematics
from cdpm_drake.robot.stretch import derived_length_residual

_log = logging.getLogger(__name__)

# A frozen encoder: its position unchanged while the commands would have moved it at least
# this many counts, after FROZEN_LAG_TICKS ticks of commands of the same sign (20 ms at 2 ms:
# a drive with a 20 ms velocity lag that reverses has caught up by then).
FROZEN_COUNTS = 3
FROZEN_LAG_TICKS = 10
# Book-keeping state vector.
ENABLED, RAMP, FAULT, FAULT_CABLE, FAULT_DETAIL, FAULT_TIME, TICKS, LOST = range(8)
BOOK_SIZE = 8
# Why the run stops.
(FAULT_NONE, FAULT_STATUS, FAULT_EMCY, FAULT_SILENT, FAULT_HEARTBEAT, FAULT_FROZEN,
 FAULT_SEND, FAULT_COMMAND, FAULT_FORCE_SILENT, FAULT_FORCE_STATUS,
 FAULT_VELOCITY_SILENT) = range(11)
FAULT_NAMES = {FAULT_STATUS: "drive fault or state", FAULT_EMCY: "EMCY",
               FAULT_SILENT: "missing TPDOs", FAULT_HEARTBEAT: "heartbeat lost",
               FAULT_FROZEN: "frozen position", FAULT_SEND: "CAN send error",
               FAULT_COMMAND: "non-finite command",
               FAULT_FORCE_SILENT: "force sensor silent",
               FAULT_FORCE_STATUS: "force sensor error",
               FAULT_VELOCITY_SILENT: "missing TPDO2s (velocity actual)"}
# The per-drive state vector: blocks of m values each.
(D_COUNT, D_MISSED, D_POSITION, D_STILL, D_SPEED, D_HEARD, D_COUNT2, D_MISSED2,
 D_HEARD2) = range(9)
DRIVE_BLOCKS = 9


class _Counters:
    """The bus's counters in the shape realtime.py reports for the UDP link, and what the
    report says of the bus: its interface and channel, the drives' rated torque 0x6076 (N m,
    NaN: not read), the force sensor's tare (N, base frame)."""

    def __init__(self, system):
        master = system.master
        self.sent = master.sent
        self.received = int(master.tpdo_count.sum() + master.tpdo2_count.sum())
        self.accepted, self.lost = self.received, system.lost_tpdos
        self.rejected, self.foreign = {}, 0
        self.send_errors = master.send_errors
        self.bus = f"{master.interface} {master.channel!r}"
        self.rated_torque = [float(x) for x in master.rated_torque]
        self.force_per_torque_unit = float(system._config.force_per_torque_unit)
        self.force_bias = [float(x) for x in system._force_scale.bias]

    def as_dict(self) -> dict:
        return dict(sent=self.sent, received=self.received, accepted=self.accepted,
                    lost=self.lost, rejected={}, foreign=0, send_errors=self.send_errors,
                    bus=self.bus, rated_torque=self.rated_torque,
                    force_per_torque_unit=self.force_per_torque_unit,
                    force_bias=self.force_bias)


class _LinkView:
    def __init__(self, system):
        self._system = system

    @property
    def counters(self) -> _Counters:
        return _Counters(self._system)


class CanopenReelsSystem(LeafSystem):
    """The reels' CiA 402 drives over CANopen.

    .. pydrake_system::

        name: reels
        input_ports:
        - reel_velocity_command (m/s of cable, one per cable, + pays out)
        output_ports:
        - cable_lengths (m, one per cable, from position actual)
        - measured_force (N, base frame, from the handle's force sensor, tared at start-up)
        - tension_measured (N, one per cable, from torque actual; NaN where unknown)
    """

    def __init__(self, robot, config: CanopenReels, time_step: float = 0.002):
        super().__init__()
        if not (isinstance(time_step, (int, float)) and np.isfinite(time_step)
                and time_step > 0):
            raise ValueError(f"time_step must be a finite number > 0 s, got {time_step!r}")
        self._m = m = robot.num_cables
        self.bus_load = check_canopen_reels(config, m, float(time_step))
        if force_source_problem(config):
            # Refused here, before the bus is opened: the admittance would never move.
            raise ValueError(force_source_problem(config))
        if config.max_length_residual is None:  # derived from the robot's cables
            config = dataclasses.replace(
                config, max_length_residual=derived_length_residual(robot))
        self._robot, self._config, self._T = robot, config, float(time_step)
        self._vmax = float(robot.limits.max_reel_speed)
        self._ids = resolved_node_ids(config, m)
        self._offset = np.array(resolved_offsets(config, m))
        self._counts = float(config.counts_per_metre)
        self._vel_units = velocity_units(config)
        # Compiled now: a first call on the real-time path would take seconds.
        self._drive_model = drive_model(robot.dynamics, m)
        self._ramp_step = 1.0 if config.ramp_time == 0 else self._T / config.ramp_time
        self._silence = (config.missed_tpdo_ticks - 1) * self._T
        if config.lockstep:  # ticks are the clock: no catch-up burst to allow for
            self._silence = 0.0
        self.master = CanopenMaster(config.interface, config.channel, config.bitrate,
                                    self._ids, lockstep_period=self._T if config.lockstep
                                    else 0.0, lockstep_wait=config.startup_timeout)
        self._moving = np.zeros(m)  # consecutive commands >= frozen_speed, same sign
        # The handle's force sensor: the master reads a node on the bus, a NetFTSource a Net
        # F/T; either way `_force_scale` turns its counts into N in the base frame.
        sensor = config.force_sensor
        on_bus = isinstance(sensor, CanopenForceSensor)
        if on_bus:
            self.master.watch_force_node(sensor.node_id)
        self.force_source = None if on_bus else NetFTSource(sensor)
        self._force_scale = (ForceScale(sensor.counts_per_newton, sensor.axes) if on_bus
                             else self.force_source.scale)
        self._force_missed = (config.missed_tpdo_ticks if sensor.missed_ticks is None
                              else sensor.missed_ticks)
        self._force_silence = (self._force_missed - 1) * self._T
        if getattr(config, "lockstep", False):  # ticks are the clock: count them alone
            self._force_silence = 0.0
        # TPDOs of an unchanged position that make a frozen encoder: frozen_ticks, or more
        # where frozen_speed moves less than FROZEN_COUNTS counts in frozen_ticks (coarse
        # counts leave a slow drive's position unchanged for several ticks).
        per_tick = config.frozen_speed * self._T * abs(self._counts)
        self._frozen_ticks = max(config.frozen_ticks, int(np.ceil(FROZEN_COUNTS / per_tick)))
        self._last_sign = np.zeros(m)
        self._stopped = self._quick_stopped = False
        self._fault = None  # (reason, cable, detail, t) a publish found
        # (samples, force, status, time.monotonic()) when the publish ran.
        self._force_at_sync = None
        self.lost_tpdos = 0
        self._count_start = np.zeros(m)

        self._command = self.DeclareVectorInputPort("reel_velocity_command", m)
        self._lengths = self.DeclareDiscreteState(cable_lengths(robot, robot.workspace.center))
        self._force = self.DeclareDiscreteState(3)
        self._tension = self.DeclareDiscreteState(np.full(m, np.nan))
        self._book = self.DeclareDiscreteState(np.zeros(BOOK_SIZE))
        # Per drive (D_* blocks): TPDOs counted, ticks without one, position (counts), TPDOs
        # in a row unchanged, reel speed (m/s: velocity actual, or from the last two
        # positions read), clock() of the last new TPDO; the same three of TPDO2.
        self._drives = self.DeclareDiscreteState(np.zeros(DRIVE_BLOCKS * m))
        self._count_start2 = np.zeros(m)
        self._enable_positions = []
        # The force sensor: samples counted, ticks without a new one, time.monotonic() of
        # the last new one.
        self._sensor = self.DeclareDiscreteState(np.zeros(3))
        self.DeclareStateOutputPort("cable_lengths", self._lengths)
        self.DeclareStateOutputPort("measured_force", self._force)
        self.DeclareStateOutputPort("tension_measured", self._tension)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._initialize)
        self.DeclarePeriodicDiscreteUpdateEvent(self._T, 0.0, self._update)
        self.DeclarePeriodicPublishEvent(self._T, 0.0, self._publish)

    # --- resources ---------------------------------------------------------------------------

    @property
    def link(self):
        """The bus's counters (`link.counters`), as realtime.py reads the UDP link's."""
        return _LinkView(self) if self.master.network is not None else None

    def quick_stop(self) -> None:
        """Every drive: target velocity 0 with quick stop, and a SYNC to act on it."""
        self.master.send_cycle([CW_QUICK_STOP] * self._m, np.zeros(self._m))
        self._quick_stopped = True

    def shutdown(self) -> None:
        """Every drive: target velocity 0 with disable voltage (to switch on disabled), and a
        SYNC; first, if not sent yet, target velocity 0 with quick stop and a SYNC one period
        before (a CSV drive watches the SYNC period). Safe at any time and more than once
        (the CLI's Ctrl-C and SIGTERM): sent once."""
        if self.master.network is None or self._stopped:
            return
        if not self._quick_stopped:
            self.quick_stop()
            time.sleep(self._T)
        self.master.send_cycle([CW_DISABLE_VOLTAGE] * self._m, np.zeros(self._m))
        self._stopped = True

    def close(self) -> None:
        """shutdown(), then release the bus and the force sensor."""
        self.shutdown()
        self.master.close()
        if self.force_source is not None:
            self.force_source.close()

    def book(self, context) -> dict:
        """The book-keeping state as a dict, with the keys realtime.py reports."""
        b = context.get_discrete_state(self._book).get_value()
        return dict(enabled=float(b[ENABLED]), ramp=float(b[RAMP]), fault=float(b[FAULT]),
                    fault_cable=float(b[FAULT_CABLE]), fault_detail=float(b[FAULT_DETAIL]),
                    fault_time=float(b[FAULT_TIME]), ticks=float(b[TICKS]),
                    commands_lost=0.0, holds=0.0, longest_hold=0.0)

    def reel_speeds(self, context) -> np.ndarray:
        """The reel speeds the last tick's tension used, m/s of cable (NaN: none yet)."""
        m = self._m
        return context.get_discrete_state(self._drives).get_value()[
            D_SPEED * m:(D_SPEED + 1) * m].copy()

    def _speed_source(self) -> str:
        """reel_speed as configure() takes it: auto becomes position on a bus without room
        for TPDO2 (said in the log)."""
        c = self._config
        if c.reel_speed == "auto" and not velocity_fits(c, self._m, self._T):
            sensors = int(isinstance(c.force_sensor, CanopenForceSensor))
            load = bus_load(self._m, c.bitrate, self._T, c.heartbeat_period, sensors, True)
            _log.info("reel speed from position differences: TPDO2 (velocity actual) of %d "
                      "drives would load the bus to %.0f %% (more than %.0f %%)", self._m,
                      100 * load["load"], 100 * MAX_BUS_LOAD)
            return "position"
        return c.reel_speed

    # --- start-up ----------------------------------------------------------------------------

    def _fail(self, message, t):
        self.shutdown()
        return ReelFault(message, t)

    def _initialize(self, context, state):
        c, m, t = self._config, self._m, context.get_time()
        try:
            self.master.open()
            self.master.configure(c.heartbeat_period, self._T, self._speed_source())
            self.master.stop_notifier()
        except CanopenError as e:
            raise self._fail(f"refusing to enable the drives: {e}", t) from None
        rated = self.master.rated_torque
        if np.isfinite(rated).any():
            # torque actual is per mille of it: force_per_torque_unit should be ~ rated / 1000
            # x gear ratio / drum radius, which this cannot know; the log says what was read.
            _log.info("rated torque 0x6076 per cable: %s N m; force_per_torque_unit %g N",
                      np.round(rated, 4).tolist(), c.force_per_torque_unit)
        if self.force_source is not None:
            try:
                self.force_source.open()
            except OSError as e:
                raise self._fail(f"refusing to enable the drives: cannot open the socket of "
                                 f"the handle's force sensor: {e}", t) from None
        else:
            self.master.force_tare = []  # every sample after NMT start, for the tare
        self.master.nmt(NMT_START, 0)
        zero = np.zeros(m)
        deadline = time.monotonic() + c.startup_timeout
        all_tpdos = None  # time.monotonic() when every drive had sent a TPDO
        while True:
            self.master.send_cycle([CW_DISABLE_VOLTAGE] * m, zero)
            self._settle()
            sw, pos, torque, count, _, _, hb_state, *_ = self.master.snapshot()
            now = time.monotonic()
            silent = [k for k in range(m) if count[k] == 0]
            # A heartbeat that says operational: the one before NMT start says otherwise.
            hb_waiting = [k for k in range(m) if self.master.heartbeat_watched[k]
                          and hb_state[k] != HEARTBEAT_OPERATIONAL]
            if not silent and all_tpdos is None:
                all_tpdos = now
            if not silent and (not hb_waiting or now - all_tpdos > c.heartbeat_timeout):
                break
            if now > deadline:
                raise self._fail(
                    f"no TPDO within startup_timeout = {c.startup_timeout:g} s from the "
                    f"drive(s) of " + ", ".join(f"cable {k + 1} (node {self._ids[k]})"
                                                for k in silent)
                    + f" on {c.interface} {c.channel!r}; are they powered, on this bus, with "
                    f"these node ids?", t)
        for k in hb_waiting:
            if hb_state[k] >= 0:  # it speaks, but not as operational
                raise self._fail(
                    f"refusing to enable the drives: the drive of cable {k + 1} (node "
                    f"{self._ids[k]}) sends TPDOs but its heartbeat reports NMT state "
                    f"{int(hb_state[k])}, not operational (5)", t)
            # A drive that took 0x1017 but sends no heartbeat: watched by its TPDOs alone.
            self.master.heartbeat_watched[k] = False
            self.master.notes.append(f"no heartbeat from the drive of cable {k + 1} (node "
                                     f"{self._ids[k]}) within heartbeat_timeout")
            _log.warning("%s; its heartbeat is not watched", self.master.notes[-1])
        faulted = [k for k in range(m) if sw[k] & SW_FAULT_BIT]
        if faulted and not c.fault_reset:
            raise self._fail(
                "refusing to enable the drives: " + ", ".join(
                    f"cable {k + 1} (node {self._ids[k]}) is in fault, statusword "
                    f"{int(sw[k]):#06x}" for k in faulted)
                + "; clear the cause and set fault_reset: true to reset it", t)
        self._tare_force(t)
        lengths = self._offset + pos / self._counts
        try:
            p = forward_kinematics(self._robot, lengths, max_residual=c.max_length_residual)
        except KinematicsError as e:
            raise self._fail(
                f"refusing to enable the drives: the measured cable lengths "
                f"{np.round(lengths, 4).tolist()} m do not fit robot {self._robot.name!r} "
                f"within max_length_residual = {c.max_length_residual:g} m: {e}. Check "
                f"position_offset, counts_per_metre and the node ids' order.", t) from None
        problem = start_pose_problem(self._robot, p)
        if problem:
            raise self._fail(f"refusing to enable the drives: {problem}", t)
        self._enable(t)
        # Drops the start-up EMCY.
        sw, pos, torque, count, still, _, _, _, vel, count2 = self.master.snapshot()
        lengths = self._offset + pos / self._counts
        state.get_mutable_discrete_state(self._lengths).SetFromVector(lengths)
        samples, force, _ = self._force_sample()
        state.get_mutable_discrete_state(self._force).SetFromVector(force)
        state.get_mutable_discrete_state(self._sensor).SetFromVector(
            # Tick 0 follows no SYNC of the run (in lockstep it reads its own SYNC's).
            [samples, 0.0 if self.master.lockstep else -1.0, time.monotonic()])
        drives = np.zeros(DRIVE_BLOCKS * m).reshape(DRIVE_BLOCKS, m)
        drives[D_COUNT], drives[D_POSITION], drives[D_STILL] = count, pos, still
        drives[D_COUNT2] = count2
        self._count_start = count.astype(float)  # the TPDOs before the run's first SYNC
        self._count_start2 = count2.astype(float)
        self.lost_tpdos = 0
        # Tick 0 follows no SYNC of the run (the enable sequence's were answered above): its
        # lack of a new TPDO is not a miss; in lockstep it reads the answers to its own.
        drives[D_MISSED] = drives[D_MISSED2] = 0.0 if self.master.lockstep else -1.0
        drives[D_SPEED] = self._start_speed(vel, pos, count)
        drives[D_HEARD] = drives[D_HEARD2] = self.master.clock()
        # The tensions before the first tick, as the simulated sensor's first sample: the
        # reels at rest (within the drives' dead band) are not accelerating; a moving one
        # waits for a second speed.
        if c.tension_sensor == "drive_torque":
            w = drives[D_SPEED]
            accel = np.where(np.abs(w) <= self._drive_model[3], 0.0, np.nan)
            tension_from_drive(torque * c.force_per_torque_unit, w, accel, *self._drive_model,
                               state.get_mutable_discrete_state(self._tension)
                               .get_mutable_value())
        drives = drives.ravel()
        state.get_mutable_discrete_state(self._drives).SetFromVector(drives)
        book = np.zeros(BOOK_SIZE)
        book[ENABLED] = 1.0
        state.get_mutable_discrete_state(self._book).SetFromVector(book)
        self._stopped = self._quick_stopped = False
        self._fault = None

    def _start_speed(self, vel, pos, count) -> np.ndarray:
        """The reels' speeds at the end of the start-up, m/s: velocity actual where mapped,
        else the difference of the last two positions the enable sequence read (NaN if no
        TPDO came between them)."""
        speed = np.full(self._m, np.nan)
        if len(self._enable_positions) == 2:
            pos0, count0 = self._enable_positions[0]
            span = self._T * np.maximum(count - count0, 1)
            speed = np.where(count > count0, (pos - pos0) / self._counts / span, np.nan)
        return np.where(self.master.velocity_mapped, vel / self._vel_units, speed)

    def _tare_force(self, t) -> None:
        """The handle's sensor's first samples, `tare_samples` of them averaged as its bias
        (the handle left alone); the drives disabled meanwhile, the SYNCs going on."""
        sensor = self._config.force_sensor
        try:
            if self.force_source is not None:
                self.force_source.tare()
                return
            want = max(1, sensor.tare_samples)
            deadline = time.monotonic() + self._config.startup_timeout
            while True:
                with self.master.lock:
                    got = list(self.master.force_tare)
                if len(got) >= want:
                    break
                if time.monotonic() > deadline:
                    raise ForceSensorError(
                        f"the handle's force sensor (node {sensor.node_id}) sent {len(got)} "
                        f"of the {want} TPDOs the start needs within startup_timeout = "
                        f"{self._config.startup_timeout:g} s on {self._config.interface} "
                        f"{self._config.channel!r}; is it powered, on this bus, with this "
                        f"node id?")
                self.master.send_cycle([CW_DISABLE_VOLTAGE] * self._m, np.zeros(self._m))
                time.sleep(self._T)
            self.master.force_tare = None
            status = self.master.force_snapshot()[1]
            if status:
                raise ForceSensorError(f"the handle's force sensor (node {sensor.node_id}) "
                                       f"reports status word {status:#06x}")
            self._force_scale.tare(got[-sensor.tare_samples:] if sensor.tare_samples else [])
        except ForceSensorError as e:
            raise self._fail(f"refusing to enable the drives: {e}", t) from None
        _log.info("force sensor tared: bias %s N", np.round(self._force_scale.bias, 3).tolist())

    def _force_sample(self):
        """(samples counted, force N base frame, status word) of the handle's sensor now."""
        if self.force_source is not None:
            self.force_source.poll()
            src = self.force_source
            return src.records, src.force(), src.status
        counts, status, n = self.master.force_snapshot()
        return n, self._force_scale.force(counts), status

    def _judge_force(self, context, state) -> tuple:
        """The force sample into the state; (reason, detail) of a silent or failing sensor.
        As the drives' TPDOs: the sample as it was when the tick's publish sent its SYNC (the
        bus node: the master's last snapshot, `force_at_snapshot`; a Net F/T: what the
        publish read, `_force_at_sync`), not what this tick's own SYNC brought back
        meanwhile, so the sample answering SYNC k is read (and expected) on tick k + 1,
        whatever the host's timing."""
        if self.force_source is None:  # the bus node: as the SYNC's snapshot left it
            counts, status, samples, now = self.master.force_at_snapshot
            force = self._force_scale.force(counts)
        else:  # the Net F/T: as the tick's publish read it
            at = self._force_at_sync or (*self._force_sample(), time.monotonic())
            samples, force, status, now = at
        self._force_at_sync = None
        count0, missed, heard = context.get_discrete_state(self._sensor).get_value()
        new = samples != count0
        missed, heard = (0.0, now) if new else (missed + 1.0, heard)
        state.get_mutable_vector(self._sensor).SetFromVector([samples, missed, heard])
        state.get_mutable_vector(self._force).SetFromVector(force)
        error = (status & RDT_STATUS_ERROR) if self.force_source is not None else status
        if error:
            return FAULT_FORCE_STATUS, float(status)
        if missed >= self._force_missed and now - heard >= self._force_silence:
            return FAULT_FORCE_SILENT, missed
        return FAULT_NONE, 0.0

    def _enable(self, t) -> None:
        """Shutdown, switch on, enable operation, each drive from the state its statusword
        shows, until all are in operation enabled or one's enable_timeout runs out."""
        c, m = self._config, self._m
        start = time.monotonic()
        reset_edge = np.zeros(m, dtype=bool)
        self._enable_positions = []  # (position, TPDOs counted) of each snapshot
        while True:
            # In lockstep the enable sequence's SYNCs must not race the drives' answers: the
            # hand's force on the bus would differ at tick 0 between runs otherwise.
            self.master.await_answers()
            snap = self.master.snapshot()
            sw = snap[0]
            self._enable_positions = [*self._enable_positions[-1:], (snap[1], snap[3])]
            states = [state_name(int(s)) for s in sw]
            if all(s == "operation enabled" for s in states):
                return
            if time.monotonic() - start > c.enable_timeout:
                late = [k for k in range(m) if states[k] != "operation enabled"]
                raise self._fail(
                    "enable sequence timed out: " + "; ".join(
                        f"cable {k + 1} (node {self._ids[k]}) not in operation enabled within "
                        f"enable_timeout = {c.enable_timeout:g} s, statusword "
                        f"{int(sw[k]):#06x} ({states[k]})" for k in late), t)
            words = []
            for k, s in enumerate(states):
                if s in ("fault", "fault reaction active"):
                    # A reset takes a rising edge of bit 7: 0 then 0x80.
                    words.append(CW_FAULT_RESET if reset_edge[k] else CW_DISABLE_VOLTAGE)
                    reset_edge[k] = not reset_edge[k]
                    continue
                words.append({"switch on disabled": CW_SHUTDOWN,
                              "ready to switch on": CW_SWITCH_ON,
                              "switched on": CW_ENABLE_OPERATION,
                              "operation enabled": CW_ENABLE_OPERATION,
                              "quick stop active": CW_DISABLE_VOLTAGE}.get(s, CW_DISABLE_VOLTAGE))
            self.master.send_cycle(words, np.zeros(m))
            self._settle()

    def _settle(self) -> None:
        """After a start-up SYNC: a period for the drives to answer, or in lockstep their
        answers themselves (so the enable sequence takes the same SYNCs on any host)."""
        if self.master.lockstep:
            self.master.await_answers()
        else:
            time.sleep(self._T)

    # --- the tick ----------------------------------------------------------------------------

    def _advance(self, context, snap, now):
        """The per-drive state after the bus snapshot `snap` (CanopenMaster.snapshot) read at
        `now` (the master's clock()), the reels' accelerations (m/s^2, NaN: unknown), which
        drives sent a new TPDO, and the verdict (reason, cable, detail) on them."""
        m, T = self._m, self._T
        drives = context.get_discrete_state(self._drives).get_value().copy()
        d = drives.reshape(DRIVE_BLOCKS, m)  # a view: written through
        count0, pos0, speed0 = d[D_COUNT].copy(), d[D_POSITION].copy(), d[D_SPEED].copy()
        count20 = d[D_COUNT2].copy()
        sw, pos, torque, count, still, hb_wall, hb_state, emcy, vel, count2 = snap
        new = count != count0
        d[D_MISSED] = np.where(new, 0.0, d[D_MISSED] + 1.0)
        d[D_HEARD] = np.where(new, now, d[D_HEARD])
        mapped = self.master.velocity_mapped
        new2 = (count2 != count20) & mapped
        d[D_MISSED2] = np.where(new2 | ~mapped, 0.0, d[D_MISSED2] + 1.0)
        d[D_HEARD2] = np.where(new2, now, d[D_HEARD2])
        # Over as many periods as TPDOs came: a late one is read with the next.
        span = T * np.maximum(np.where(mapped, count2 - count20, count - count0), 1)
        speed = np.where(new, (pos - pos0) / self._counts / span, speed0)
        # Velocity actual where mapped: the drive's own measure at its SYNC, as the simulated
        # sensor's reel speed; its acceleration the difference over the periods between.
        speed = np.where(mapped, np.where(new2, vel / self._vel_units, speed0), speed)
        accel = (speed - speed0) / np.where(mapped, span, T)  # NaN while a speed is unknown
        d[D_COUNT], d[D_POSITION], d[D_STILL] = count, pos, still
        d[D_COUNT2], d[D_SPEED] = count2, speed
        # Silent for missed_tpdo_ticks ticks and (missed_tpdo_ticks - 1) periods of wall time:
        # the catch-up ticks after a stall of this process come faster than drives answer.
        silent = np.where(now - d[D_HEARD] >= self._silence, d[D_MISSED], 0.0)
        silent2 = np.where(now - d[D_HEARD2] >= self._silence, d[D_MISSED2], 0.0)
        verdict = self._judge(sw, silent, still, hb_wall, hb_state, emcy, now, silent2)
        return drives, accel, new, verdict

    def _update(self, context, state):
        book = context.get_discrete_state(self._book).get_value().copy()
        if book[FAULT] != FAULT_NONE:
            return  # latched; the next publish ends the run
        c, m = self._config, self._m
        if self.master.lockstep:
            # The answers to the SYNC this tick's publish just sent, as HardwareReels' lockstep
            # update reads the status answering its own command: the rehearsal's loop has the
            # simulation's one-tick latency (tick k's command from the plant at t_k).
            at = self.master.answered_snapshot()
        else:
            # The frames as the tick's publish saw them, before its SYNC: a silence counted
            # in SYNC periods, whatever this tick's compute time lets arrive meanwhile.
            at = self.master.sync_snapshot() or (self.master.snapshot(), self.master.clock())
        snap = at[0]
        drives, accel, new, (reason, cable, detail) = self._advance(context, *at)
        # TPDOs lost: the SYNCs of the run this update has seen answered (tick k's snapshot,
        # taken before its own SYNC, answers SYNCs 1..k: none on tick 0; in lockstep 0..k)
        # less the TPDOs that came for them, per drive. A TPDO a tick late is read with the
        # next: not lost.
        expected = book[TICKS] + float(self.master.lockstep)
        answered = drives[0:m] - self._count_start
        answered2 = drives[D_COUNT2 * m:(D_COUNT2 + 1) * m] - self._count_start2
        self.lost_tpdos = int(np.maximum(0.0, expected - answered).sum()
                              + np.maximum(0.0, expected - answered2)[
                                  self.master.velocity_mapped].sum())
        pos, torque = snap[1], snap[2]
        speed = drives[D_SPEED * m:(D_SPEED + 1) * m]
        lengths = self._offset + pos / self._counts
        tension = state.get_mutable_vector(self._tension).get_mutable_value()
        if c.tension_sensor == "drive_torque":
            tension_from_drive(torque * c.force_per_torque_unit, speed, accel,
                               *self._drive_model, tension)
        else:
            tension[:] = np.nan
        book[TICKS] += 1.0
        book[LOST] = self.lost_tpdos
        t = context.get_time()
        force_reason, force_detail = self._judge_force(context, state)
        if reason == FAULT_NONE and force_reason != FAULT_NONE:
            reason, cable, detail = force_reason, -1, force_detail
        if self._fault is not None:
            # The publish's, found first: the quick stop it sent may already show here.
            reason, cable, detail, t = self._fault
        if reason != FAULT_NONE:
            # The next publish sends the stop's first SYNC (if this tick's publish has not).
            book[FAULT], book[FAULT_CABLE], book[FAULT_DETAIL] = reason, cable, detail
            book[FAULT_TIME] = t
            book[ENABLED] = book[RAMP] = 0.0
        else:
            book[RAMP] = min(1.0, book[RAMP] + self._ramp_step)
        state.get_mutable_vector(self._lengths).SetFromVector(lengths)
        state.get_mutable_vector(self._drives).SetFromVector(drives)
        state.get_mutable_vector(self._book).SetFromVector(book)

    def _judge(self, sw, missed, still, hb_wall, hb_state, emcy, now, missed2):
        """(reason, cable (0-based), detail) of the first fault found, or FAULT_NONE.
        `missed`, `missed2`: ticks each drive's TPDO, TPDO2 has been silent."""
        c = self._config
        if emcy:
            k, code, _ = emcy[0]
            return FAULT_EMCY, k, code
        for k, s in enumerate(sw):
            if s & SW_FAULT_BIT or state_name(int(s)) != "operation enabled":
                return FAULT_STATUS, k, int(s)
        k = int(np.argmax(missed))
        if missed[k] >= c.missed_tpdo_ticks:
            return FAULT_SILENT, k, missed[k]
        k = int(np.argmax(missed2))
        if missed2[k] >= c.missed_tpdo_ticks:
            return FAULT_VELOCITY_SILENT, k, missed2[k]
        if c.heartbeat_period > 0:
            age = now - hb_wall
            for k in np.flatnonzero(self.master.heartbeat_watched):
                if not age[k] <= c.heartbeat_timeout:
                    return FAULT_HEARTBEAT, k, age[k]
                if hb_state[k] != HEARTBEAT_OPERATIONAL:
                    return FAULT_HEARTBEAT, k, -float(hb_state[k])
        # Commanded the same way long enough that a lagging drive (tens of ms) moves too.
        frozen = ((still >= self._frozen_ticks)
                  & (self._moving >= self._frozen_ticks + FROZEN_LAG_TICKS))
        if frozen.any():
            return FAULT_FROZEN, int(np.argmax(frozen)), still[int(np.argmax(frozen))]
        if self.master.send_errors:
            return FAULT_SEND, -1, self.master.send_errors
        return FAULT_NONE, -1, 0.0

    def _publish(self, context):
        if self.force_source is not None:  # the Net F/T's records as of now, for the update
            self._force_at_sync = (*self._force_sample(), time.monotonic())
        book = context.get_discrete_state(self._book).get_value()
        if book[FAULT] == FAULT_NONE and self._fault is None:
            # Drake runs this tick's update right after this publish, so the update has not
            # seen the TPDOs that came in during the period just ended: judge them here too,
            # so that a fault stops the drives in place of this tick's command, not the next.
            # In lockstep the update before has judged every answer to the last SYNC: no
            # SYNC since, nothing new to judge (a silence would count twice).
            t = context.get_time()
            reason, cable, detail = FAULT_NONE, -1, 0.0
            if not self.master.lockstep:
                _, _, _, (reason, cable, detail) = self._advance(
                    context, self.master.snapshot(drain_emcy=False), self.master.clock())
            u = self._command.Eval(context)
            bad = ~np.isfinite(u)
            if reason == FAULT_NONE and bad.any():
                reason, cable = FAULT_COMMAND, int(np.argmax(bad))
                detail = float(u[cable])
            if reason == FAULT_NONE:
                self._send_command(book, u)
                return
            self._fault = (reason, cable, detail, t)
        if not self._quick_stopped:
            self.quick_stop()  # this tick's SYNC; disable voltage on the next tick's
            return
        self.shutdown()
        if book[FAULT] == FAULT_NONE:  # a fault the update has not latched (yet)
            book = book.copy()
            book[FAULT], book[FAULT_CABLE], book[FAULT_DETAIL], book[FAULT_TIME] = self._fault
        raise ReelFault(self._fault_message(book), float(book[FAULT_TIME]))

    def _send_command(self, book, u) -> None:
        """One RPDO per drive (enable operation, the ramped command in drive units), a SYNC."""
        v = book[RAMP] * u if book[ENABLED] else np.zeros(self._m)
        peak = float(np.max(np.abs(v)))
        if peak > self._vmax:
            v = v * (self._vmax / peak)
        sign = np.sign(v) * (np.abs(v) >= self._config.frozen_speed)
        self._moving = np.where((sign != 0) & (sign == self._last_sign), self._moving + 1,
                                (sign != 0).astype(float))
        self._last_sign = sign
        self.master.send_cycle([CW_ENABLE_OPERATION] * self._m, v * self._vel_units)

    def _fault_message(self, book) -> str:
        reason, k = int(book[FAULT]), int(book[FAULT_CABLE])
        detail = float(book[FAULT_DETAIL])
        who = f"the drive of cable {k + 1} (node {self._ids[k]})" if k >= 0 else "the bus"
        sensor = self._config.force_sensor
        sensor_name = (f"the handle's force sensor ({self.force_source.describe()})"
                       if self.force_source is not None else
                       f"the handle's force sensor (node {sensor.node_id})")
        if reason == FAULT_FORCE_SILENT:
            why = (f"no sample from {sensor_name} for {int(detail)} ticks "
                   f"(missed ticks allowed: {self._force_missed})")
        elif reason == FAULT_FORCE_STATUS:
            why = f"{sensor_name} reports status {int(detail):#x}"
        elif reason == FAULT_STATUS:
            why = (f"{who} reports statusword {int(detail):#06x} "
                   f"({state_name(int(detail))})")
        elif reason == FAULT_EMCY:
            why = f"{who} sent EMCY error code {int(detail):#06x}"
        elif reason == FAULT_SILENT:
            why = (f"no TPDO from {who} for {int(detail)} ticks (missed_tpdo_ticks = "
                   f"{self._config.missed_tpdo_ticks})")
        elif reason == FAULT_VELOCITY_SILENT:
            why = (f"no TPDO2 (velocity actual) from {who} for {int(detail)} ticks "
                   f"(missed_tpdo_ticks = {self._config.missed_tpdo_ticks})")
        elif reason == FAULT_HEARTBEAT:
            why = (f"{who}'s heartbeat reports NMT state {int(-detail)}, not operational"
                   if detail < 0 else
                   f"{who}'s heartbeat is {detail * 1e3:.0f} ms old (heartbeat_timeout = "
                   f"{self._config.heartbeat_timeout * 1e3:g} ms)")
        elif reason == FAULT_COMMAND:
            why = f"reel_velocity_command of cable {k + 1} is {detail!r} m/s"
        elif reason == FAULT_FROZEN:
            why = (f"{who}'s position actual has not changed for {int(detail)} TPDOs while "
                   f"commanded at least frozen_speed = {self._config.frozen_speed:g} m/s "
                   f"(a frozen encoder)")
        else:
            why = (f"{int(detail)} CAN frame(s) could not be sent (bus-off?): "
                   f"{self.master.last_send_error}")
        return (f"reel fault at t = {float(book[FAULT_TIME]):.3f} s: {why}; every drive sent "
                f"target velocity 0 with quick stop, then (a tick later) disable voltage")
