"""An independent set of CiA 402 servo drives for tests, written from CiA 301 (the CANopen
application layer) and CiA 402 (the drive profile) directly on raw python-can frames. It
shares no code with cdpm_drake (not its emulator, not the master's constants) nor with the
canopen package (no LocalNode): what the controller gets right against it, it does not get
right by agreeing with itself.

Each node, as a real drive would (and in places stricter than cdpm's own emulator):

* NMT (CiA 301 7.2.8): boot-up message, pre-operational / operational / stopped, reset node
  and reset communication (the dictionary back to its defaults); SDO only outside stopped,
  PDOs only in operational.
* SDO server, expedited transfers only (CiA 301 7.2.4.3): download and upload of the objects
  below, with the abort codes of CiA 301 table 22 (no object, no sub-index, read only, length
  mismatch, value out of range, cannot be mapped, mapping too long, device state).
* PDOs per their communication and mapping parameters (0x1400/0x1600, 0x1800/0x1A00): the
  mapping changeable only in pre-operational with the PDO invalid (COB-ID bit 31) and its
  count 0 (CiA 301 7.5.2.36's procedure); a TPDO COB-ID with bit 30 clear refused (this drive
  answers no remote frames); synchronous RPDOs applied at the next SYNC, asynchronous ones
  (254/255) at once; TPDOs of type n sent on every n-th SYNC.
* The CiA 402 state machine on the controlword (table 'device control commands', transitions
  0-16: shutdown, switch on, switch on + enable operation, disable voltage, quick stop,
  disable operation, enable operation, fault reset on the rising edge of bit 7), the
  statusword of each state with bits 4 (voltage enabled), 9 (remote), 10 (target reached)
  and 12 (CSV: following the command) set where they apply; quick stop option code 0x605A =
  6 (stop, then stay in quick stop active until disable voltage).
* Modes 0x6060 (3 profile velocity, 8 CSP, 9 CSV accepted; motion in 9 only), the display
  0x6061 following 20 ms after the write (a drive switches modes in its own time).
* Units of its own: position actual 0x6064 in encoder counts (`counts_per_rev`), target and
  actual velocity 0x60FF/0x606C in milli-rpm, torque actual 0x6077 in per mille of the rated
  torque 0x6076 (mNm). An ideal motor: in operation enabled in CSV it turns at its target
  velocity for one interpolation period 0x60C2 per SYNC (default 1 ms: a master that does not
  write the SYNC period gets half the motion at 2 ms).
* Heartbeat producer 0x1017 (ms); EMCY (0x80 + node) on a fault.

Faults (`--fault KIND:NODE:N`, N counted in SYNCs from the first SYNC on which every drive
was in operation enabled, so that the onset is a SYNC, not a wall-clock instant): `fault`
(the drive enters fault reaction active on SYNC N, its statusword showing bit 3 in the TPDO
of that SYNC, and sends EMCY 0x2310), `fault_bit` (the same without EMCY), `silent` (from
SYNC N on the node sends nothing and hears nothing: no TPDO for SYNC N), `frozen` (from
SYNC N on position actual repeats the value of SYNC N - 1), `late` (the TPDO of SYNC N is
sent a SYNC late, just before that of SYNC N + 1).

Run as a program (`python independent_cia402.py --help`); on SIGTERM or at --duration it
writes --record, a JSON file: per SYNC each node's state, controlword and target velocity,
the SDO and NMT requests it served in order, the first all-enabled SYNC and the faults.
"""

import argparse
import gc
import json
import math
import os
import signal
import struct
import sys
import time

import can

# --- CiA 301 --------------------------------------------------------------------------------
NMT, SYNC, EMCY, TPDO1, RPDO1, SDO_TX, SDO_RX, HEARTBEAT = (
    0x000, 0x080, 0x080, 0x180, 0x200, 0x580, 0x600, 0x700)
PRE_OPERATIONAL, OPERATIONAL, STOPPED = 0x7F, 0x05, 0x04
ABORT = dict(command=0x05040001, write_only=0x06010001, read_only=0x06010002,
             no_object=0x06020000, cannot_map=0x06040041, too_long=0x06040042,
             incompatible=0x06040043, length=0x06070010, no_sub=0x06090011,
             value=0x06090030, state=0x08000022)
# --- CiA 402 --------------------------------------------------------------------------------
NOT_READY, DISABLED, READY, SWITCHED_ON, ENABLED, QUICK_STOP, REACTION, FAULT = (
    "not ready to switch on", "switch on disabled", "ready to switch on", "switched on",
    "operation enabled", "quick stop active", "fault reaction active", "fault")
# Statusword bits 0-3, 5, 6 of each state (CiA 402 table 'state coding'), bit 4 voltage
# enabled where the power stage is on.
STATUS = {NOT_READY: 0x0000, DISABLED: 0x0040, READY: 0x0031, SWITCHED_ON: 0x0033,
          ENABLED: 0x0037, QUICK_STOP: 0x0017, REACTION: 0x001F, FAULT: 0x0008}
CSV = 9
MODES = (3, 8, 9)

# (index, sub) -> (struct format, access "ro"/"rw", PDO direction "R"/"T"/"" mappable)
DICTIONARY = {
    (0x1000, 0): ("<I", "ro", ""), (0x1001, 0): ("<B", "ro", ""),
    (0x1017, 0): ("<H", "rw", ""),
    (0x1018, 0): ("<B", "ro", ""), (0x1018, 1): ("<I", "ro", ""),
    (0x1400, 0): ("<B", "ro", ""), (0x1400, 1): ("<I", "rw", ""),
    (0x1400, 2): ("<B", "rw", ""),
    (0x1800, 0): ("<B", "ro", ""), (0x1800, 1): ("<I", "rw", ""),
    (0x1800, 2): ("<B", "rw", ""), (0x1800, 3): ("<H", "rw", ""),
    (0x1800, 5): ("<H", "rw", ""),
    (0x6040, 0): ("<H", "rw", "R"), (0x6041, 0): ("<H", "ro", "T"),
    (0x605A, 0): ("<h", "rw", ""), (0x6060, 0): ("<b", "rw", "R"),
    (0x6061, 0): ("<b", "ro", "T"), (0x6064, 0): ("<i", "ro", "T"),
    (0x606C, 0): ("<i", "ro", "T"), (0x6076, 0): ("<I", "rw", ""),
    (0x6077, 0): ("<h", "ro", "T"), (0x60C2, 0): ("<B", "ro", ""),
    (0x60C2, 1): ("<B", "rw", ""), (0x60C2, 2): ("<b", "rw", ""),
    (0x60FF, 0): ("<i", "rw", "R"), (0x6502, 0): ("<I", "ro", ""),
}
for _index in (0x1600, 0x1A00):
    DICTIONARY[(_index, 0)] = ("<B", "rw", "")
    for _sub in range(1, 9):
        DICTIONARY[(_index, _sub)] = ("<I", "rw", "")


def defaults(node: int, period_ms: int = 1, rtr: bool = False) -> dict:
    """The dictionary at power-on: PDO1s as CiA 402's predefined mapping (controlword in,
    statusword out), event-driven, heartbeat off, SYNC period `period_ms`, TPDO1 with
    remote requests (`rtr`) or not (COB-ID bit 30)."""
    od = {key: 0 for key in DICTIONARY}
    od.update({(0x1000, 0): 0x00020192, (0x1018, 0): 1, (0x1018, 1): 0x00C1A402,
               (0x1400, 0): 2, (0x1400, 1): RPDO1 + node, (0x1400, 2): 255,
               (0x1800, 0): 5, (0x1800, 1): (0 if rtr else 0x40000000) | (TPDO1 + node),
               (0x1800, 2): 255,
               (0x1600, 0): 1, (0x1600, 1): 0x60400010,
               (0x1A00, 0): 1, (0x1A00, 1): 0x60410010,
               (0x605A, 0): 6, (0x6076, 0): 500, (0x60C2, 0): 2, (0x60C2, 1): period_ms,
               (0x60C2, 2): -3, (0x6502, 0): (1 << 2) | (1 << 7) | (1 << 8)})
    return od


class Node:
    """One drive: node id, dictionary, NMT and CiA 402 state, an ideal motor."""

    def __init__(self, node: int, start_counts: int, counts_per_rev: int, torque: int,
                 period_ms: int = 1, rtr: bool = False):
        self.node, self.counts_per_rev, self.torque = node, counts_per_rev, torque
        self.period_ms, self.rtr = period_ms, rtr
        self.start_counts = start_counts
        self.reset()
        self.position = float(start_counts)  # counts; the motor keeps turning across resets
        self.silent = False
        self.frozen = None      # position actual reported while frozen
        self.late = False       # hold the next TPDO back a SYNC
        self.reaction_at = 0    # the SYNC its fault reaction began
        self.held = []          # TPDO frames held back
        self.reported = start_counts

    def reset(self) -> None:
        self.od = defaults(self.node, self.period_ms, self.rtr)
        self.nmt = PRE_OPERATIONAL
        self.state = DISABLED   # transitions 0 and 1 are automatic
        self.rpdo_buffer = None
        self.previous_cw = 0
        self.mode_written = -math.inf
        self.next_heartbeat = 0.0
        self.velocity = 0.0     # milli-rpm

    # --- CiA 402 ---------------------------------------------------------------------------

    def statusword(self) -> int:
        word = STATUS[self.state] | 0x0200  # remote: the controlword is obeyed
        if self.state == ENABLED and self.od[(0x6060, 0)] == CSV:
            word |= 0x1000                  # following the command value
        if self.velocity == self.od[(0x60FF, 0)]:
            word |= 0x0400                  # target reached
        return word

    def controlword(self, cw: int) -> None:
        """Device control commands (CiA 402 table 'command coding'), on each SYNC."""
        rising_reset = bool(cw & 0x80) and not self.previous_cw & 0x80
        self.previous_cw = cw
        s = self.state
        if s in (FAULT, REACTION):
            if s == FAULT and rising_reset:
                self.state = DISABLED                                    # 15
            return
        if cw & 0x80:
            return  # fault reset outside fault: no command
        if not cw & 0x02:                                                # disable voltage
            if s in (READY, SWITCHED_ON, ENABLED, QUICK_STOP):
                self.state = DISABLED                                    # 7, 9, 10, 12
        elif not cw & 0x04:                                              # quick stop
            if s in (READY, SWITCHED_ON):
                self.state = DISABLED                                    # 7, 10
            elif s == ENABLED:
                self.state = QUICK_STOP                                  # 11
        elif cw & 0x07 == 0x06:                                          # shutdown
            if s in (DISABLED, SWITCHED_ON, ENABLED):
                self.state = READY                                       # 2, 6, 8
        elif cw & 0x0F == 0x07:                                          # switch on /
            if s == READY:                                               # disable operation
                self.state = SWITCHED_ON                                 # 3
            elif s == ENABLED:
                self.state = SWITCHED_ON                                 # 5
        elif cw & 0x0F == 0x0F:                                          # enable operation
            if s in (READY, SWITCHED_ON):
                self.state = ENABLED                                     # 3 + 4, 4
            elif s == QUICK_STOP and self.od[(0x605A, 0)] in (5, 6, 7, 8):
                self.state = ENABLED                                     # 16

    def period(self) -> float:
        return self.od[(0x60C2, 1)] * 10.0 ** self.od[(0x60C2, 2)]

    def step(self) -> None:
        """One interpolation period: an ideal motor at the target velocity in CSV, stopped
        at once on a quick stop, coasting to rest (here: stopped) otherwise."""
        moving = self.state == ENABLED and self.od[(0x6060, 0)] == CSV
        self.velocity = float(self.od[(0x60FF, 0)]) if moving else 0.0
        self.position += self.velocity / 60000.0 * self.counts_per_rev * self.period()

    def value(self, key):
        if key == (0x6041, 0):
            return self.statusword()
        if key == (0x6061, 0):
            # The mode switches 20 ms after the write.
            if time.monotonic() - self.mode_written >= 0.02:
                return self.od[(0x6060, 0)]
            return self.od[(0x6061, 0)]
        if key == (0x6064, 0):
            if self.frozen is not None:
                return self.frozen
            return int(max(-2**31, min(2**31 - 1, math.floor(self.position + 0.5))))
        if key == (0x606C, 0):
            return int(round(self.velocity))
        if key == (0x6077, 0):
            return self.torque if self.state in (ENABLED, QUICK_STOP) else 0
        return self.od[key]

    # --- PDO mapping -----------------------------------------------------------------------

    def mapped(self, mapping: int):
        out = []
        for sub in range(1, self.od[(mapping, 0)] + 1):
            entry = self.od[(mapping, sub)]
            out.append(((entry >> 16, (entry >> 8) & 0xFF), entry & 0xFF))
        return out

    def check_entry(self, mapping: int, entry: int):
        """An abort name if `entry` cannot be mapped in this PDO, else None."""
        key, bits = (entry >> 16, (entry >> 8) & 0xFF), entry & 0xFF
        if key not in DICTIONARY:
            return "no_object"
        fmt, _, direction = DICTIONARY[key]
        if direction != ("R" if mapping == 0x1600 else "T"):
            return "cannot_map"
        if bits != 8 * struct.calcsize(fmt):
            return "length"
        return None


class DriveSet:
    """The nodes on one bus, served from one loop (run())."""

    def __init__(self, bus, nodes, start_counts, counts_per_rev, torque, faults, *,
                 mute=(), period_ms=1, rtr=False, force_node=None, force_counts=(0, 0, 0)):
        """`mute`: ("read" | "write", index) SDO requests left unanswered (a simple drive
        that neither serves nor aborts them); `period_ms`: the default 0x60C2; `rtr`: the
        TPDOs take remote requests (COB-ID bit 30 clear accepted)."""
        self.bus = bus
        self.mute = set(mute)
        self.nodes = [Node(n, c, counts_per_rev, torque, period_ms, rtr)
                      for n, c in zip(nodes, start_counts)]
        self.by_id = {d.node: d for d in self.nodes}
        self.faults = list(faults)   # (kind, node, SYNCs after the first all-enabled one)
        self.syncs = 0
        self.enabled_at = None       # the SYNC on which every node was first enabled
        self.onsets = []             # (kind, node, SYNC)
        self.records = []            # per SYNC: [[state, controlword, target] per node]
        self.requests = []           # SDO and NMT requests served, in order
        self.stop = False
        # A handle force sensor node: after each SYNC, once NMT started, a TPDO (0x180 +
        # node) of Fx, Fy, Fz (int16 counts, constant) and a status word 0.
        self.force_node, self.force_counts = force_node, tuple(force_counts)
        self.force_started = False

    # --- frames ----------------------------------------------------------------------------

    def send(self, cob_id: int, data: bytes, node: Node) -> None:
        if node.silent:
            return
        try:
            self.bus.send(can.Message(arbitration_id=cob_id, data=data,
                                      is_extended_id=False))
        except can.CanError as e:
            print(f"independent drives: send failed: {e}", flush=True)

    def handle(self, msg) -> None:
        cob, data = msg.arbitration_id, bytes(msg.data)
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            return
        if cob == NMT and len(data) == 2:
            if self.force_node is not None and data[1] in (0, self.force_node):
                self.force_started = data[0] == 0x01
            for d in self.nodes:
                if data[1] in (0, d.node) and not d.silent:
                    self.nmt(d, data[0])
        elif cob == SYNC:
            self.sync()
        elif SDO_RX < cob <= SDO_RX + 127 and len(data) == 8:
            d = self.by_id.get(cob - SDO_RX)
            if d is not None and not d.silent and d.nmt != STOPPED:
                self.sdo(d, data)
        else:
            for d in self.nodes:
                cob_id = d.od[(0x1400, 1)]
                if (not d.silent and d.nmt == OPERATIONAL and not cob_id & 0x80000000
                        and cob == cob_id & 0x7FF):
                    if d.od[(0x1400, 2)] >= 254:
                        self.apply_rpdo(d, data)  # asynchronous: at once
                    else:
                        d.rpdo_buffer = data      # synchronous: at the next SYNC

    def nmt(self, d: Node, command: int) -> None:
        self.requests.append(["nmt", d.node, command, self.syncs])
        if command == 0x01:
            d.nmt = OPERATIONAL
        elif command == 0x02:
            d.nmt = STOPPED
        elif command == 0x80:
            d.nmt = PRE_OPERATIONAL
        elif command in (0x81, 0x82):
            if command == 0x81:
                d.reset()
            else:
                keep = {k: v for k, v in d.od.items() if k[0] >= 0x2000}
                d.reset()
                d.od.update(keep)
            self.send(HEARTBEAT + d.node, b"\x00", d)  # boot-up

    def apply_rpdo(self, d: Node, data: bytes) -> None:
        mapping = d.mapped(0x1600)
        if sum(bits for _, bits in mapping) > 8 * len(data):
            return  # too short: not processed (CiA 301: EMCY 0x8210; not needed here)
        at = 0
        for key, bits in mapping:
            fmt = DICTIONARY[key][0]
            d.od[key] = struct.unpack_from(fmt, data, at)[0]
            if key == (0x6060, 0):
                d.mode_written = time.monotonic()
            at += bits // 8

    # --- SDO server ------------------------------------------------------------------------

    def sdo(self, d: Node, data: bytes) -> None:
        command = data[0]
        ccs = command >> 5
        index, sub = struct.unpack_from("<HB", data, 1)
        key = (index, sub)

        def abort(name):
            self.requests.append(["abort", d.node, index, sub, name])
            self.send(SDO_TX + d.node, struct.pack("<BHBI", 0x80, index, sub, ABORT[name]), d)

        if ccs == 4:
            return  # the client aborted: nothing to answer
        if ccs not in (1, 2):
            return abort("command")  # segments, blocks: not served
        if (("read" if ccs == 2 else "write"), index) in self.mute:
            self.requests.append(["unanswered", d.node, index, sub])
            return
        if key not in DICTIONARY:
            return abort("no_object" if all(k[0] != index for k in DICTIONARY) else "no_sub")
        fmt, access, _ = DICTIONARY[key]
        size = struct.calcsize(fmt)
        if ccs == 2:
            value = d.value(key)
            self.requests.append(["read", d.node, index, sub, value])
            return self.send(SDO_TX + d.node, struct.pack("<BHB", 0x43 | ((4 - size) << 2),
                                                          index, sub)
                             + struct.pack(fmt, value).ljust(4, b"\x00"), d)
        if not command & 0x02:
            return abort("command")  # a segmented download
        if access == "ro":
            return abort("read_only")
        n = 4 - ((command >> 2) & 3) if command & 0x01 else size
        if n != size:
            return abort("length")
        value = struct.unpack_from(fmt, data, 4)[0]
        problem = self.check_write(d, key, value)
        if problem:
            return abort(problem)
        d.od[key] = value
        if key == (0x6060, 0):
            d.mode_written = time.monotonic()
        self.requests.append(["write", d.node, index, sub, value])
        self.send(SDO_TX + d.node, struct.pack("<BHB4x", 0x60, index, sub), d)

    @staticmethod
    def check_write(d: Node, key, value):
        """An abort name for a write the drive refuses, else None."""
        index, sub = key
        if index in (0x1400, 0x1800) and sub == 1:
            old = d.od[key]
            if value & 0x20000000:
                return "value"  # 29-bit ids: not on this drive
            if index == 0x1800 and not value & 0x40000000 and not d.rtr:
                return "value"  # remote frames: not on this drive
            if not old & 0x80000000 and not value & 0x80000000 and (
                    old & 0x7FF) != (value & 0x7FF):
                return "value"  # a valid PDO's CAN-ID changes only through invalid
            if not value & 0x80000000 and d.od[(0x1600 if index == 0x1400 else 0x1A00, 0)]:
                mapping = 0x1600 if index == 0x1400 else 0x1A00
                if sum(b for _, b in d.mapped(mapping)) > 64:
                    return "too_long"
        if index in (0x1400, 0x1800) and sub == 2:
            if not (value <= 240 or value >= 254):
                return "value"  # RTR-only types: not on this drive
        if index in (0x1600, 0x1A00):
            comm = 0x1400 if index == 0x1600 else 0x1800
            if d.nmt != PRE_OPERATIONAL or not d.od[(comm, 1)] & 0x80000000:
                return "state"  # mapping: in pre-operational with the PDO invalid
            if sub == 0:
                if value > 8:
                    return "value"
                if sum(d.od[(index, s)] & 0xFF for s in range(1, value + 1)) > 64:
                    return "too_long"
                for s in range(1, value + 1):
                    problem = d.check_entry(index, d.od[(index, s)])
                    if problem:
                        return problem
            else:
                if d.od[(index, 0)]:
                    return "state"  # entries change while the count is 0
                return d.check_entry(index, value)
        if key == (0x6060, 0) and value not in MODES:
            return "value"
        if key == (0x605A, 0) and not -32768 <= value <= 8:
            return "value"
        if key == (0x60C2, 1) and value == 0:
            return "value"
        if key == (0x60C2, 2) and not -128 <= value <= 63:
            return "value"
        return None

    # --- the cycle -------------------------------------------------------------------------

    def sync(self) -> None:
        n = self.syncs + 1  # counted when answered: `syncs` SYNCs have their TPDOs out
        for d in self.nodes:
            if not d.silent and d.nmt == OPERATIONAL and d.rpdo_buffer is not None:
                self.apply_rpdo(d, d.rpdo_buffer)
                d.rpdo_buffer = None
        if self.enabled_at is None and all(d.state == ENABLED for d in self.nodes):
            self.enabled_at = n  # counted before this SYNC's controlwords
        self.inject(n)
        for d in self.nodes:
            if d.silent:
                continue
            if d.state == REACTION and d.reaction_at < n:
                d.state = FAULT  # 14: the reaction (a stop) took the cycle before
            if d.nmt == OPERATIONAL:
                d.controlword(d.od[(0x6040, 0)])
            d.step()
        self.records.append([[d.state, d.od[(0x6040, 0)], d.od[(0x60FF, 0)]]
                             for d in self.nodes])
        for d in self.nodes:
            if d.silent or d.nmt != OPERATIONAL:
                continue
            for frame in d.held:
                self.send(*frame, d)
            d.held = []
            cob_id, kind = d.od[(0x1800, 1)], d.od[(0x1800, 2)]
            if cob_id & 0x80000000 or not 1 <= kind <= 240 or n % kind:
                continue
            payload = b"".join(struct.pack(DICTIONARY[key][0], d.value(key))
                               for key, _ in d.mapped(0x1A00))
            frame = (cob_id & 0x7FF, payload)
            if d.late:
                d.late = False
                d.held.append(frame)
            else:
                self.send(*frame, d)
            d.reported = d.value((0x6064, 0))
        if self.force_node is not None and self.force_started:
            self.bus.send(can.Message(arbitration_id=0x180 + self.force_node, data=struct.pack(
                "<3hH", *self.force_counts, 0), is_extended_id=False))
        self.syncs = n

    def inject(self, n: int) -> None:
        if self.enabled_at is None:
            return
        for fault in [f for f in self.faults if n == self.enabled_at + f[2]]:
            self.faults.remove(fault)
            kind, node, _ = fault
            d = self.by_id[node]
            self.onsets.append([kind, node, n])
            if kind in ("fault", "fault_bit"):
                d.state, d.reaction_at = REACTION, n  # 13
                if kind == "fault":
                    self.send(EMCY + d.node, struct.pack("<HB5x", 0x2310, 0x03), d)
            elif kind == "silent":
                d.silent = True
            elif kind == "frozen":
                d.frozen = d.reported
            elif kind == "late":
                d.late = True
            print(f"independent drives: {kind} on node {node} at SYNC {n}", flush=True)

    def heartbeats(self, now: float) -> None:
        for d in self.nodes:
            ms = d.od[(0x1017, 0)]
            if ms and now >= d.next_heartbeat and not d.silent:
                d.next_heartbeat = now + ms / 1000.0
                self.send(HEARTBEAT + d.node, bytes([d.nmt]), d)

    def run(self, duration: float) -> None:
        for d in self.nodes:
            self.send(HEARTBEAT + d.node, b"\x00", d)  # boot-up
        end = time.monotonic() + duration
        while not self.stop and time.monotonic() < end:
            msg = self.bus.recv(timeout=0.002)
            if msg is not None:
                self.handle(msg)
            self.heartbeats(time.monotonic())

    def summary(self) -> dict:
        return dict(nodes=[d.node for d in self.nodes], syncs=self.syncs,
                    enabled_at=self.enabled_at, onsets=self.onsets, records=self.records,
                    requests=self.requests,
                    positions=[d.value((0x6064, 0)) for d in self.nodes],
                    states=[d.state for d in self.nodes])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--interface", default="udp_multicast")
    p.add_argument("--channel", required=True)
    p.add_argument("--nodes", type=int, nargs="+", required=True)
    p.add_argument("--start-counts", type=int, nargs="+", required=True,
                   help="position actual of each node at power-on, counts")
    p.add_argument("--counts-per-rev", type=int, default=1 << 20)
    p.add_argument("--torque", type=int, default=100,
                   help="torque actual while powered, per mille of 0x6076")
    p.add_argument("--fault", action="append", default=[], metavar="KIND:NODE:N")
    p.add_argument("--duration", type=float, default=120.0)
    p.add_argument("--rt-priority", type=int, default=0)
    p.add_argument("--record", required=True, help="JSON file written at the end")
    p.add_argument("--force-node", type=int, default=None,
                   help="also play a handle force sensor node with this id (forces 0)")
    args = p.parse_args(argv)
    if len(args.start_counts) != len(args.nodes):
        p.error("--start-counts needs one value per node")
    faults = []
    for text in args.fault:
        kind, node, n = text.split(":")
        faults.append((kind, int(node), int(n)))
    if args.rt_priority:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.rt_priority))
    bus = can.Bus(interface=args.interface, channel=args.channel)
    drives = DriveSet(bus, args.nodes, args.start_counts, args.counts_per_rev, args.torque,
                      faults, force_node=args.force_node)

    def stop(signum, frame):
        drives.stop = True

    signal.signal(signal.SIGTERM, stop)
    gc.collect()
    gc.disable()  # a collection would hold every drive up for ms
    print(f"independent drives: nodes {args.nodes} ready on {args.interface} {args.channel}",
          flush=True)
    try:
        drives.run(args.duration)
    finally:
        bus.shutdown()
        with open(args.record, "w") as f:
            json.dump(drives.summary(), f)
        print(f"independent drives: {drives.syncs} SYNCs, states {drives.summary()['states']}",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
