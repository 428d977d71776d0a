"""`cdpm emulate --canopen`: m CiA 402 servo drives on a python-can bus, to rehearse a
`plant: !CanopenReels` run without the robot (hardware/CANOPEN.md).

Each drive is a CANopen node: NMT (start, stop, pre-operational, reset), an SDO server
(expedited transfers) over an object dictionary with the communication and mapping objects
(0x1400/0x1600, 0x1800/0x1A00, 0x1801/0x1A01, 0x1017) and the drive objects (0x6040, 0x6041, 0x6060/0x6061,
0x6064, 0x6077, 0x606C, 0x60FF), the CiA 402 state machine, mode 9 (cyclic synchronous
velocity) only, synchronous RPDOs and TPDOs as mapped by the controller (read from 0x1600 /
0x1A00 when the node is started), a heartbeat producer and EMCY. Until the controller maps
them, TPDO1 carries statusword and position only: a controller that skips the mapping does
not get the torque it expects; TPDO2 (COB-ID 0x280 + node id) is disabled (bit 31 of
0x1801:1) and empty until the controller maps it (`tpdo2=False`: a drive without 0x1801 /
0x1A01, which aborts their SDO transfers).

On each SYNC the drives act on the RPDOs received since the last one (controlword: the state
machine; target velocity: followed in operation enabled, 0 otherwise), the plant behind them
(emulator/bridges.py: ReelBridge kinematic or DynamicBridge dynamic, as `cdpm emulate`) steps
one control period, and each started drive sends its TPDO: statusword, position actual =
(cable length - position_offset) x counts_per_metre, torque actual = drive force at the cable /
force_per_torque_unit (0 when the plant has none); then TPDO2 if mapped and valid: velocity
actual = the reel's speed sampled with the torque (the plant's bridge.reel_speed()) x
velocity_units. A plant step per SYNC, not per wall-clock
interval: the lengths are the sum of the commanded velocities times the period, whatever the
host's timing.

Fault injection (`--fault KIND`, on `--fault-cable`, from `--fault-after` s after the first
drive reached operation enabled): drive_fault (the drive goes to Fault and sends EMCY 0x2310),
fault_bit (the drive goes to Fault without an EMCY: only its statusword tells), late_tpdo
(the drive's next TPDO is held back and sent a SYNC late, just before the following one; with
another kind on the same cable: the first TPDO that shows the fault comes late), lost_tpdo (the drive stops sending TPDOs; heartbeats go on), frozen_position (position actual
stops changing and velocity actual, from the same encoder, reads 0), dead_node (the node sends nothing and ignores the bus; its reel stops),
bus_off (every node leaves the bus: nothing sent or received; the reels stop),
force_silent (the handle's force sensor node stops sending its TPDO). TPDO2 goes with
TPDO1: held back, lost or silent with it; lost_tpdo2 (the drive stops sending TPDO2 alone).

The handle's force sensor, when the scenario's plant has `force_sensor: !CanopenForceSensor
{...}`: a node that NMT starts like the drives and that sends, after each SYNC's plant step,
its TPDO (COB-ID 0x180 + node_id): the plant's hand force (the force the UDP bridge's status
carries) in the sensor's axes (`axes`) and counts (`counts_per_newton`) plus the sensor's own
bias (`force_bias`, N in its axes: what the controller's tare must remove), as 3 int16, and a
status word 0.
"""

import argparse
import collections
import gc
import math
import struct
import sys
import threading
import time

import numpy as np

from cdpm_drake.hardware.canopen_bus import (COB_EMCY, COB_HEARTBEAT, COB_NMT, COB_SDO_RX,
                                             COB_SDO_TX, COB_SYNC, MODE_CSV, NMT_PRE_OPERATIONAL,
                                             NMT_START, NMT_STOP)

FAULT_KINDS = ("drive_fault", "fault_bit", "late_tpdo", "lost_tpdo", "frozen_position",
               "dead_node", "bus_off", "force_silent", "lost_tpdo2")
COB_TPDO2, COB_INVALID = 0x280, 0x80000000
# Statuswords of the states (bit 9 remote, bit 4 voltage enabled where it is).
SW = {"switch on disabled": 0x0250, "ready to switch on": 0x0231, "switched on": 0x0233,
      "operation enabled": 0x0237, "quick stop active": 0x0217, "fault": 0x0218}
# (index, sub) -> (struct format, writable)
OBJECTS = {(0x1000, 0): ("<I", False), (0x1017, 0): ("<H", True),
           (0x1400, 1): ("<I", True), (0x1400, 2): ("<B", True),
           (0x1800, 1): ("<I", True), (0x1800, 2): ("<B", True),
           (0x1801, 1): ("<I", True), (0x1801, 2): ("<B", True),
           (0x6040, 0): ("<H", True), (0x6041, 0): ("<H", False), (0x6060, 0): ("<b", True),
           (0x6061, 0): ("<b", False), (0x6064, 0): ("<i", False), (0x606C, 0): ("<i", False),
           (0x6077, 0): ("<h", False), (0x60FF, 0): ("<i", True),
           (0x60C2, 1): ("<B", True), (0x60C2, 2): ("<b", True)}  # stored, not used: one
# plant step of --period per SYNC
for _map in (0x1600, 0x1A00, 0x1A01):
    OBJECTS[(_map, 0)] = ("<B", True)
    for _sub in range(1, 9):
        OBJECTS[(_map, _sub)] = ("<I", True)
SDO_NO_OBJECT, SDO_READ_ONLY, SDO_VALUE_RANGE, SDO_BAD_COMMAND = (
    0x06020000, 0x06010002, 0x06090030, 0x05040001)
NMT_STATE = {"pre-operational": 0x7F, "operational": 0x05, "stopped": 0x04}


class Drive:
    """One emulated CiA 402 drive (node `node_id`, cable `cable`, 0-based); `tpdo2`: whether
    it has a second TPDO (0x1801/0x1A01)."""

    def __init__(self, node_id: int, cable: int, tpdo2: bool = True):
        self.node_id, self.cable, self.has_tpdo2 = node_id, cable, bool(tpdo2)
        self.od = {(0x1000, 0): 0x00020192, (0x1017, 0): 0,
                   (0x1400, 1): 0x200 + node_id, (0x1400, 2): 255,
                   (0x1800, 1): 0x180 + node_id, (0x1800, 2): 255,
                   (0x1600, 0): 2, (0x1600, 1): 0x60400010, (0x1600, 2): 0x60FF0020,
                   (0x1A00, 0): 2, (0x1A00, 1): 0x60410010, (0x1A00, 2): 0x60640020,
                   (0x1801, 1): COB_INVALID | (COB_TPDO2 + node_id), (0x1801, 2): 255,
                   (0x1A01, 0): 0,
                   (0x6040, 0): 0, (0x6060, 0): 0, (0x60FF, 0): 0,
                   (0x60C2, 1): 1, (0x60C2, 2): -3}
        self.nmt = "pre-operational"
        self.state = "switch on disabled"
        self.previous_cw = 0
        self.rpdo, self.tpdo = [], []   # mapped (index, format) lists, fixed at NMT start
        self.tpdo2 = []                 # TPDO2's, if valid
        self.lost_tpdo2 = False
        self.frozen = None              # the position reported while frozen, counts
        self.lost_tpdo = self.dead = False
        self.late = 0           # TPDOs still to hold back a SYNC
        self.held = []          # (COB-ID, payload) of the TPDOs held back
        self.next_heartbeat = 0.0

    def start(self) -> None:
        """NMT start: the mapping in the dictionary becomes the PDOs'."""
        self.rpdo = self._mapping(0x1600)
        self.tpdo = self._mapping(0x1A00)
        valid = self.has_tpdo2 and not self.od[(0x1801, 1)] & COB_INVALID
        self.tpdo2 = self._mapping(0x1A01) if valid else []
        self.nmt = "operational"

    def _mapping(self, index):
        out = []
        for sub in range(1, self.od.get((index, 0), 0) + 1):
            entry = self.od.get((index, sub), 0)
            key = (entry >> 16, (entry >> 8) & 0xFF)
            if key in OBJECTS:
                out.append((key, OBJECTS[key][0]))
        return out

    def statusword(self) -> int:
        return SW[self.state]

    def apply_controlword(self, cw: int) -> None:
        """The CiA 402 state machine on a controlword (device control commands)."""
        previous, self.previous_cw = self.previous_cw, cw
        s = self.state
        if s == "fault":
            if cw & 0x80 and not previous & 0x80:
                self.state = "switch on disabled"
            return
        if not cw & 0x02:                               # disable voltage
            self.state = "switch on disabled"
        elif s == "quick stop active":
            return                                      # until disable voltage
        elif cw & 0x06 == 0x02:                         # quick stop
            self.state = "quick stop active" if s == "operation enabled" else (
                "switch on disabled")
        elif cw & 0x87 == 0x06:                         # shutdown
            if s in ("switch on disabled", "switched on", "operation enabled"):
                self.state = "ready to switch on"
        elif cw & 0x8F == 0x07:                         # switch on / disable operation
            if s in ("ready to switch on", "operation enabled"):
                self.state = "switched on"
        elif cw & 0x8F == 0x0F:                         # enable operation
            if s in ("ready to switch on", "switched on"):
                self.state = "operation enabled"


class EmulatedDrives:
    """m CiA 402 drives on one python-can bus in front of a bridge plant (ReelBridge or
    DynamicBridge). `bus`: a python-can Bus (owned: shut down by stop()). Units as
    CanopenReels: counts_per_metre, position_offset (m per cable), velocity_units (target
    velocity units per m/s), force_per_torque_unit (N per unit of torque actual); `period`:
    the plant's step per SYNC, s. `faults`: [(kind, cable 0-based, after s)]. `lockstep`:
    the SYNCs are the only clock (SYNCs x period): heartbeats and the faults' `after` count
    SYNCs, not wall-clock time, so a run against `cdpm run --lockstep` is deterministic.
    `tpdo2` False: drives without a second TPDO (they abort its mapping)."""

    def __init__(self, bridge, bus, node_ids, *, counts_per_metre=1_000_000.0,
                 position_offset=None, velocity_units=None, force_per_torque_unit=0.1,
                 period=0.002, faults=(), record=100_000, log=None, lockstep=False,
                 tpdo2=True):
        m = bridge.robot.num_cables
        if len(node_ids) != m:
            raise ValueError(f"node ids must be one per cable ({m}), got {list(node_ids)!r}")
        self.bridge, self.bus, self.period = bridge, bus, float(period)
        self.drives = [Drive(int(i), k, tpdo2) for k, i in enumerate(node_ids)]
        self._by_id = {d.node_id: d for d in self.drives}
        self.counts = float(counts_per_metre)
        self.offset = np.zeros(m) if position_offset is None else np.asarray(
            position_offset, dtype=float)
        self.velocity_units = float(counts_per_metre if velocity_units is None
                                    else velocity_units)
        self.force_unit = float(force_per_torque_unit)
        self.faults = [(k, int(c), float(a)) for k, c, a in faults]
        for kind, cable, _ in self.faults:
            if kind not in FAULT_KINDS:
                raise ValueError(f"fault kind must be one of {', '.join(FAULT_KINDS)}, got "
                                 f"{kind!r}")
            if not 0 <= cable < m:
                raise ValueError(f"fault cable must be in 1..{m}, got {cable + 1}")
        self.lockstep = bool(lockstep)
        self.bus_off = False
        self.syncs = 0
        self.tpdo_sent = 0
        self.tpdo2_sent = 0
        self.first_enable_time = None
        self.fault_syncs = {}  # kind -> the SYNC count when it was injected
        # Per SYNC: (sync count, states, controlwords, target velocities m/s) of each drive.
        self.record = collections.deque(maxlen=record)
        self._log = log
        self._stop = threading.Event()
        self._thread = None
        self.play_force_sensor(None)

    def play_force_sensor(self, sensor, bias=(0.0, 0.0, 0.0)) -> "EmulatedDrives":
        """Play the handle's force sensor node `sensor` (a CanopenForceSensor, or None: none)
        with the drives, with a zero offset of its own, `bias` (N, in its axes)."""
        self.force_sensor = sensor
        self.force_nmt = "pre-operational"
        self.force_bias = np.asarray(bias, dtype=float)
        self.force_silent = False
        self.force_sent = 0
        return self

    # --- running -----------------------------------------------------------------------------

    def start(self) -> "EmulatedDrives":
        for d in self.drives:
            self._send(COB_HEARTBEAT + d.node_id, b"\x00", d)  # boot-up
        self._thread = threading.Thread(target=self.run, name="canopen-drives", daemon=True)
        self._thread.start()
        return self

    def run(self, duration: float | None = None) -> None:
        end = None if duration is None else time.monotonic() + duration
        while not self._stop.is_set() and (end is None or time.monotonic() < end):
            msg = self.bus.recv(timeout=0.001)
            now = time.monotonic()
            if msg is not None and not self.bus_off and not msg.is_error_frame:
                self._handle(msg.arbitration_id, bytes(msg.data))
            if self.lockstep:
                continue  # heartbeats and faults go with the SYNCs (_sync)
            self._inject(now)
            if not self.bus_off:
                self._heartbeats(now)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        try:
            self.bus.shutdown()
        except Exception:  # noqa: S110 - already shut
            pass

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    # --- frames ------------------------------------------------------------------------------

    def _send(self, cob_id: int, data: bytes, drive=None) -> bool:
        import can

        if self.bus_off or (drive is not None and drive.dead):
            return False
        try:
            self.bus.send(can.Message(arbitration_id=cob_id, data=data, is_extended_id=False))
            return True
        except Exception as e:  # a full queue: a frame lost, as on a real bus
            self._say(f"send failed: {e}")
            return False

    def _handle(self, cob_id: int, data: bytes) -> None:
        if cob_id == COB_NMT and len(data) >= 2:
            for d in self.drives:
                if data[1] in (0, d.node_id) and not d.dead:
                    self._nmt(d, data[0])
            if self.force_sensor is not None and data[1] in (0, self.force_sensor.node_id):
                self.force_nmt = "operational" if data[0] == NMT_START else "pre-operational"
        elif cob_id == COB_SYNC:
            self._sync()
        elif COB_SDO_RX < cob_id <= COB_SDO_RX + 127:
            d = self._by_id.get(cob_id - COB_SDO_RX)
            if d is not None and not d.dead and len(data) == 8:
                self._sdo(d, data)
        else:
            for d in self.drives:
                if d.nmt == "operational" and not d.dead and cob_id == d.od[(0x1400, 1)]:
                    at = 0
                    for key, fmt in d.rpdo:
                        size = struct.calcsize(fmt)
                        if at + size <= len(data):
                            d.od[key] = struct.unpack_from(fmt, data, at)[0]
                        at += size

    def _nmt(self, d: Drive, command: int) -> None:
        if command == NMT_START:
            d.start()
        elif command == NMT_STOP:
            d.nmt = "stopped"
        elif command == NMT_PRE_OPERATIONAL:
            d.nmt = "pre-operational"
        elif command in (0x81, 0x82):  # reset node / communication
            d.nmt = "pre-operational"
            self._send(COB_HEARTBEAT + d.node_id, b"\x00", d)

    def _sdo(self, d: Drive, data: bytes) -> None:
        ccs = data[0] >> 5
        index, sub = struct.unpack_from("<HB", data, 1)
        key = (index, sub)

        def reply(payload: bytes):
            self._send(COB_SDO_TX + d.node_id, payload, d)

        def abort(code):
            reply(struct.pack("<BHBI", 0x80, index, sub, code))

        if key not in OBJECTS or (index in (0x1801, 0x1A01) and not d.has_tpdo2):
            return abort(SDO_NO_OBJECT)
        fmt, writable = OBJECTS[key]
        size = struct.calcsize(fmt)
        if ccs == 1:  # initiate download, expedited only
            if not data[0] & 0x02:
                return abort(SDO_BAD_COMMAND)
            n = 4 - ((data[0] >> 2) & 3) if data[0] & 0x01 else 4
            if not writable:
                return abort(SDO_READ_ONLY)
            value = struct.unpack_from(fmt, bytes(data[4:4 + n]).ljust(size, b"\x00"))[0]
            if key == (0x6060, 0) and value != MODE_CSV:
                return abort(SDO_VALUE_RANGE)
            d.od[key] = value
            if key == (0x6040, 0):
                d.apply_controlword(value)
            reply(struct.pack("<BHB4x", 0x60, index, sub))
        elif ccs == 2:  # initiate upload
            value = self._value(d, key)
            reply(struct.pack("<BHB", 0x43 | ((4 - size) << 2), index, sub)
                  + struct.pack(fmt, value).ljust(4, b"\x00"))
        else:
            abort(SDO_BAD_COMMAND)

    def _value(self, d: Drive, key):
        if key == (0x6041, 0):
            return d.statusword()
        if key == (0x6061, 0):
            return d.od[(0x6060, 0)]
        if key == (0x6064, 0):
            return self._position(d)
        if key == (0x6077, 0):
            return self._torque(d)
        if key == (0x606C, 0):
            if d.frozen is not None:  # the encoder it is measured on is stuck
                return 0
            # The speed sampled with the torque (the dynamic plant's sensor's).
            v = self.bridge.reel_speed()[d.cable] * self.velocity_units
            return int(max(-2**31, min(2**31 - 1, round(float(v)))))
        return d.od.get(key, 0)

    def _position(self, d: Drive) -> int:
        if d.frozen is not None:
            return d.frozen
        x = (self.bridge.encoder_lengths()[d.cable] - self.offset[d.cable]) * self.counts
        return int(max(-2**31, min(2**31 - 1, round(float(x)))))

    def _torque(self, d: Drive) -> int:
        f = float(self.bridge.drive_force()[d.cable]) / self.force_unit
        return 0 if not math.isfinite(f) else int(max(-32768, min(32767, round(f))))

    # --- the cycle ---------------------------------------------------------------------------

    def _now(self) -> float:
        """The drives' clock, s: wall clock, or in lockstep SYNCs x period."""
        return self.syncs * self.period if self.lockstep else time.monotonic()

    def _sync(self) -> None:
        m = len(self.drives)
        if self.lockstep:
            self._inject(self._now())
        velocity = np.zeros(m)
        cws, targets = [], []
        for d in self.drives:
            cw, target = d.od[(0x6040, 0)], d.od[(0x60FF, 0)] / self.velocity_units
            if d.nmt == "operational" and not d.dead:
                d.apply_controlword(cw)
            if d.state == "operation enabled" and d.od[(0x6060, 0)] == MODE_CSV:
                velocity[d.cable] = target
            cws.append(cw)
            targets.append(target)
        enabled = bool(np.any([d.state == "operation enabled" for d in self.drives]))
        hold = False
        if enabled and self.first_enable_time is None:
            self.first_enable_time = self._now()
            # The SYNC that first enables a drive ends the enable sequence, not the run's
            # first: the reels are held over it (target velocity 0 there) and the plant's clock
            # (and the hand's) starts with the next SYNC, as the UDP bridge's with the first
            # enabling command, so the controller's first tick reads the plant at time 0.
            hold = True
        before = self.bridge.faults
        self.bridge.set_command(velocity, enable=enabled and not hold)
        if self.bridge.faults and not before:  # the plant's own fault (overspeed)
            for d in self.drives:
                self._drive_fault(d, 0x8400)
        self.bridge.step(self.period)
        # The force node first: a controller that waits for the drives' TPDOs has it then.
        self._send_force()
        self.record.append((self.syncs + 1, [d.state for d in self.drives], cws, targets))
        if self.lockstep and not self.bus_off:
            self._heartbeats(self._now())  # before the TPDOs: read with them
        for d in self.drives:
            for frame in d.held:  # last SYNC's TPDOs, a SYNC late
                self._send(*frame, d)
            d.held = []
            if d.nmt == "operational" and not d.lost_tpdo:
                late = d.late > 0
                d.late -= late
                for comm, mapped in ((0x1800, d.tpdo), (0x1801, d.tpdo2)):
                    if not mapped or (comm == 0x1801 and d.lost_tpdo2):
                        continue
                    frame = (d.od[(comm, 1)] & 0x7FF,
                             b"".join(struct.pack(fmt, self._value(d, key))
                                      for key, fmt in mapped))
                    if late:
                        d.held.append(frame)
                    elif self._send(*frame, d):
                        self.tpdo_sent += comm == 0x1800
                        self.tpdo2_sent += comm == 0x1801
        self.syncs += 1  # last: a SYNC counted is one fully answered

    def force_counts(self) -> list[int]:
        """The force sensor's Fx, Fy, Fz counts now: the plant's hand force (base frame) in the
        sensor's axes, plus its bias, times counts_per_newton, rounded, saturated at int16."""
        s = self.force_sensor
        f = np.asarray(self.bridge.force(), dtype=float)
        out = []
        for i, name in enumerate(s.axes):  # sensor axis i measures base axis `name`
            value = (1.0 if name[0] == "+" else -1.0) * f["xyz".index(name[1])]
            counts = (value + self.force_bias[i]) * s.counts_per_newton
            out.append(int(max(-32768, min(32767, round(counts)))))
        return out

    def _send_force(self) -> None:
        if (self.force_sensor is None or self.force_nmt != "operational"
                or self.force_silent):
            return
        payload = struct.pack("<3hH", *self.force_counts(), 0)
        if self._send(0x180 + self.force_sensor.node_id, payload):
            self.force_sent += 1

    def _drive_fault(self, d: Drive, code: int) -> None:
        d.state = "fault"
        self._send(COB_EMCY + d.node_id, struct.pack("<HB5x", code, 0x03), d)

    def _heartbeats(self, now: float) -> None:
        for d in self.drives:
            ms = d.od[(0x1017, 0)]
            if ms and now >= d.next_heartbeat:
                d.next_heartbeat = now + ms / 1000.0
                self._send(COB_HEARTBEAT + d.node_id, bytes([NMT_STATE[d.nmt]]), d)

    def inject(self, kind: str, cable: int) -> None:
        """Break drive `cable` (0-based) or the bus now (see the module docstring)."""
        d = self.drives[cable]
        self.fault_syncs[kind] = self.syncs
        if kind == "drive_fault":
            self._drive_fault(d, 0x2310)
        elif kind == "fault_bit":
            d.state = "fault"
        elif kind == "late_tpdo":
            d.late = 1
        elif kind == "lost_tpdo":
            d.lost_tpdo = True
        elif kind == "lost_tpdo2":
            d.lost_tpdo2 = True
        elif kind == "frozen_position":
            d.frozen = self._position(d)
        elif kind == "dead_node":
            d.dead = True
            d.state = "switch on disabled"  # a dead drive's power stage is off
        elif kind == "force_silent":
            self.force_silent = True
        elif kind == "bus_off":
            self.bus_off = True
            for d in self.drives:  # CiA 301 error behaviour: every drive stops
                d.state = "switch on disabled" if d.state != "fault" else d.state
        if kind in ("dead_node", "bus_off"):
            velocity = np.zeros(len(self.drives))
            for other in self.drives:
                if other.state == "operation enabled" and not other.dead:
                    velocity[other.cable] = self.bridge.command[other.cable]
            self.bridge.set_command(velocity, enable=bool(np.any(velocity)))
        where = (f"the force sensor (node {self.force_sensor.node_id})"
                 if kind == "force_silent" and self.force_sensor is not None else
                 f"cable {cable + 1} (node {d.node_id})")
        self._say(f"injected {kind} on {where} at SYNC {self.syncs}")

    def _inject(self, now: float) -> None:
        if self.first_enable_time is None or not self.faults:
            return
        due = [f for f in self.faults if now - self.first_enable_time >= f[2]]
        for f in due:
            self.faults.remove(f)
            self.inject(f[0], f[1])

    def fault_counts(self, kind: str) -> tuple:
        """(zero, off, disabled) for an injected fault: the SYNCs after the last one before
        it (the first SYNC after the fault is 1) until every live drive had target velocity
        0, was out of operation enabled, and was disabled (switch on disabled, or fault);
        None: never."""
        at = self.fault_syncs[kind]
        dead = {d.cable for d in self.drives if d.dead}
        live = [k for k in range(len(self.drives)) if k not in dead]
        after = [r for r in self.record if r[0] > at]

        def first(ok):
            return next((r[0] - at for r in after if all(ok(r, k) for k in live)), None)

        return (first(lambda r, k: r[3][k] == 0),
                first(lambda r, k: r[1][k] != "operation enabled"),
                first(lambda r, k: r[1][k] in ("switch on disabled", "fault")))

    def fault_report(self) -> list[str]:
        """For each injected fault, fault_counts() in words."""
        lines = []
        for kind, at in self.fault_syncs.items():
            zero, off, disabled = self.fault_counts(kind)
            lines.append(f"{kind} after SYNC {at}: target velocity 0 on every live drive "
                         f"{zero} SYNC(s) later, none in operation enabled {off} SYNC(s) later, "
                         f"all disabled {disabled} SYNC(s) later (None: never)")
        return lines

    def _say(self, text: str) -> None:
        if self._log is not None:
            self._log(text)


# --- command line ----------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cdpm emulate --canopen", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", help="robot, start, operator and the bus settings of its "
                   "plant: !CanopenReels from this scenario (name or path)")
    p.add_argument("--scenario-text", help="YAML overlay applied to --scenario")
    p.add_argument("--robot", help="built-in robot name or robot YAML path; with --scenario: "
                   "the robot as built, played under the scenario's file (encoders homed on "
                   "the file at the start)")
    p.add_argument("--start", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="platform start, base frame, m (default: the scenario's or the centre)")
    p.add_argument("--plant", choices=("kinematic", "dynamic"), default="kinematic")
    p.add_argument("--time-constant", type=float, default=0.02,
                   help="reel velocity lag of the kinematic plant, s (default 0.02)")
    p.add_argument("--interface", help="python-can interface (default: the scenario's, or "
                   "virtual)")
    p.add_argument("--channel", help="python-can channel (default: the scenario's)")
    p.add_argument("--period", type=float, default=None,
                   help="plant step per SYNC, s (default: the scenario's time_step, 0.002)")
    p.add_argument("--duration", type=float, default=None, help="stop after this long, s")
    p.add_argument("--lockstep", action="store_true",
                   help="the SYNCs are the drives' only clock: heartbeats and --fault-after "
                   "count SYNCs x period, so a rehearsal with `cdpm run --lockstep` is "
                   "deterministic on any host")
    p.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="run under SCHED_FIFO at priority N (1..99; needs root or "
                   "CAP_SYS_NICE), as a drive's firmware would; default 0: normal")
    p.add_argument("--fault", choices=FAULT_KINDS, action="append", default=[],
                   help="inject this fault (repeatable)")
    p.add_argument("--fault-cable", type=int, default=1, help="cable of the fault (1-based)")
    p.add_argument("--fault-after", type=float, default=0.0,
                   help="seconds after the first drive was enabled")
    return p


def build_drives(args, log=None) -> EmulatedDrives:
    """The drives described by parsed arguments, on a bus opened here."""
    try:
        import can
    except ImportError:
        raise RuntimeError("the emulated CiA 402 drives need the python-can package: pip "
                           "install 'cdpm_drake[canopen]' (pip install -e '.[canopen]' in a "
                           "clone)") from None

    from cdpm_drake.emulator.bridges import DynamicBridge, ReelBridge
    from cdpm_drake.emulator.plant_setup import (dynamic_scenario, homing_offset,
                                                 robot_as_built)
    from cdpm_drake.hardware.canopen_config import (CanopenReels, resolved_node_ids,
                                                    resolved_offsets, velocity_units)
    from cdpm_drake.kernels.kinematics import cable_lengths, jacobian
    from cdpm_drake.robot import load_robot

    config, force, period = CanopenReels(interface="virtual"), None, 0.002
    if args.scenario:
        from cdpm_drake.config import load_scenario, scenario_operator, scenario_robot

        scenario = load_scenario(args.scenario, args.scenario_text)
        robot, start = scenario_robot(scenario), scenario.initial_position
        force, period = scenario_operator(scenario).force, scenario.time_step
        if isinstance(scenario.plant, CanopenReels):
            config = scenario.plant
    else:
        robot = load_robot(args.robot or "paper_7cable")
        start = robot.workspace.center
    if args.start is not None:
        start = args.start
    start = np.asarray(start, dtype=float)
    m = robot.num_cables
    file_robot = robot
    if args.scenario and args.robot:  # the robot as built, under the scenario's file
        robot = robot_as_built(args, scenario, file_robot)
    if args.plant == "dynamic":
        args.force = None
        bridge = DynamicBridge(dynamic_scenario(args, file_robot, start))
    else:
        bridge = ReelBridge(robot, cable_lengths(robot, start), force=force,
                            time_constant=args.time_constant,
                            encoder_offset=homing_offset(file_robot, robot, start))
    # Compile (or load) the kinematics a SYNC uses now, not on the first SYNC enabled: a
    # first call takes tens of ms, which the controller would see as silent drives.
    jacobian(robot, bridge.platform())
    interface = args.interface or config.interface
    channel = args.channel or config.channel
    kwargs = dict(interface=interface, channel=channel)
    if interface == "virtual":
        kwargs["receive_own_messages"] = False
    bus = can.Bus(**kwargs)
    cable = args.fault_cable - 1
    return EmulatedDrives(bridge, bus, resolved_node_ids(config, m),
                          counts_per_metre=config.counts_per_metre,
                          position_offset=resolved_offsets(config, m),
                          velocity_units=velocity_units(config),
                          force_per_torque_unit=config.force_per_torque_unit,
                          period=args.period or period,
                          faults=[(k, cable, args.fault_after) for k in args.fault], log=log,
                          lockstep=args.lockstep)


def play_force_sensor(args, drives, log=None):
    """The handle's force sensor of the scenario's `!CanopenReels` (args.scenario): a node on
    the bus, played by `drives`, or a Net F/T served at its address (the NetFTServer, to
    stop, is returned; None otherwise)."""
    from cdpm_drake.emulator.plant_setup import netft_server
    from cdpm_drake.hardware.force_config import CanopenForceSensor

    if not args.scenario:
        return None
    from cdpm_drake.config import load_scenario

    plant = load_scenario(args.scenario, args.scenario_text).plant
    sensor = getattr(plant, "force_sensor", None)
    if isinstance(sensor, CanopenForceSensor):
        drives.play_force_sensor(sensor)
    return netft_server(plant, drives.bridge, log)


def main(argv=None) -> int:
    """Exit codes: 0 done (--duration), 1 error, 2 bad usage, 130 / 143 after Ctrl-C /
    SIGTERM."""
    from cdpm_drake.runs.interrupt import exit_code, terminate_raises

    args = build_parser().parse_args(argv)

    def say(text):
        print(f"cdpm emulate --canopen: {text}", flush=True)

    try:
        from cdpm_drake.hardware.priority import set_realtime_priority

        set_realtime_priority(args.rt_priority)
        drives = build_drives(args, log=say)
        netft = play_force_sensor(args, drives, log=say)
    except Exception as e:  # a robot, a scenario, a bus that will not open: say which
        print(f"cdpm emulate --canopen: error: {e}", file=sys.stderr)
        return 1
    # What exists now lives for the whole run: out of the collector's sight, as in the UDP
    # emulator (a full collection with pydrake loaded takes ~20 ms, ten SYNCs unanswered).
    gc.collect()
    gc.freeze()
    robot = drives.bridge.robot
    say(f"robot {robot.name!r}: {len(drives.drives)} CiA 402 drives, nodes "
        f"{[d.node_id for d in drives.drives]}, on {args.interface or 'the scenario bus'}, "
        f"{drives.bridge.describe()}" + (f", faults {args.fault} on cable {args.fault_cable} "
                                         f"after {args.fault_after:g} s" if args.fault else ""))
    for d in drives.drives:
        drives._send(COB_HEARTBEAT + d.node_id, b"\x00", d)  # boot-up
    code = 0
    with terminate_raises():
        try:
            drives.run(duration=args.duration)
        except KeyboardInterrupt as e:
            code = exit_code(e)
        finally:
            drives.stop()
            if netft is not None:
                netft.stop()
            states = ", ".join(f"{d.node_id}: {d.state}" for d in drives.drives)
            say(f"{drives.syncs} SYNCs; drive states {states}; lengths "
                f"{np.round(drives.bridge.lengths, 4).tolist()} m")
            for line in drives.fault_report():
                say(line)
    return code
