"""The controller's side of a CANopen bus of CiA 402 drives (no Drake): SDO configuration of
the PDO mapping and the mode, NMT, the cyclic RPDOs and SYNC, and what the drives send back
(TPDOs, EMCY, heartbeats), read into arrays by python-can's notifier thread while the drives
are configured, then by the control loop itself, without blocking (poll).

The CiA 402 words (controlword commands, statusword states) are here too: the emulated
drives (emulator/canopen_drives.py) speak the same ones.
"""

import contextlib
import logging
import struct
import threading
import time

import numpy as np

from cdpm_drake.hardware.canopen_config import (NO_BITRATE_INTERFACES, RPDO_OBJECTS,
                                                TPDO2_OBJECTS, TPDO_OBJECTS)

# Controlword commands (CiA 402, 0x6040).
CW_DISABLE_VOLTAGE = 0x0000
CW_QUICK_STOP = 0x0002
CW_SHUTDOWN = 0x0006
CW_SWITCH_ON = 0x0007
CW_ENABLE_OPERATION = 0x000F
CW_FAULT_RESET = 0x0080

# Statusword states: (mask, value, name).
STATES = ((0x4F, 0x00, "not ready to switch on"), (0x4F, 0x40, "switch on disabled"),
          (0x6F, 0x21, "ready to switch on"), (0x6F, 0x23, "switched on"),
          (0x6F, 0x27, "operation enabled"), (0x6F, 0x07, "quick stop active"),
          (0x4F, 0x0F, "fault reaction active"), (0x4F, 0x08, "fault"))
SW_FAULT_BIT = 0x0008
MODE_CSV = 9

COB_NMT, COB_SYNC, COB_EMCY, COB_TPDO1, COB_RPDO1 = 0x000, 0x080, 0x080, 0x180, 0x200
COB_SDO_TX, COB_SDO_RX, COB_HEARTBEAT, COB_TPDO2 = 0x580, 0x600, 0x700, 0x280
COB_INVALID = 0x80000000  # bit 31 of a PDO's COB-ID entry: the PDO does not exist (disabled)
COB_NO_RTR = 0x40000000  # bit 30 of a PDO's COB-ID entry: no remote request
NMT_START, NMT_STOP, NMT_PRE_OPERATIONAL = 0x01, 0x02, 0x80
HEARTBEAT_OPERATIONAL = 0x05
OPTIONAL_SDO_TIMEOUT = 0.1  # s
_log = logging.getLogger(__name__)


def state_name(statusword: int) -> str:
    """The CiA 402 state a statusword shows."""
    for mask, value, name in STATES:
        if statusword & mask == value:
            return name
    return "unknown"


def is_state(statusword: int, name: str) -> bool:
    return state_name(statusword) == name


def interpolation_period(period: float):
    """0x60C2's (value, index) for a period of `period` s: value x 10^index s, value in
    1..255, the largest index 0..-9 that is exact to 1e-9 relative (2 ms: (2, -3)); None if
    there is none."""
    for exponent in range(0, -10, -1):
        value = period / 10.0 ** exponent
        if abs(value - round(value)) <= 1e-9 * value and 1 <= round(value) <= 255:
            return int(round(value)), exponent
    return None


class CanopenError(RuntimeError):
    """The bus or a drive refused what the controller needs; the message names the node."""


class CanopenMaster:
    """The controller's end of the bus: `node_ids` drives, one per cable (0-based inside).

    Arrays updated by the notifier thread until stop_notifier(), then by poll() (read them
    with snapshot()): statusword, position (counts), torque (per mille), tpdo_count (TPDOs
    received per drive), velocity (velocity actual 0x606C, drive units, from TPDO2 where
    `velocity_mapped`), tpdo2_count (TPDO2s received per drive), still (the drive's latest TPDOs in a row whose position equals the
    one before: counted per frame, so two TPDOs read on one tick, one of them late, count
    as two), heartbeat_wall (clock() of the last heartbeat, NaN: none),
    heartbeat_state, and `emcy`, a list of (cable, error code, error register) of the EMCY
    frames with a non-zero code.
    """

    def __init__(self, interface: str, channel: str, bitrate: int, node_ids, *,
                 lockstep_period: float = 0.0, lockstep_wait: float = 2.0):
        """`lockstep_period` > 0 (s, the SYNC period): lockstep (`clock`, `send_cycle`);
        `lockstep_wait`: how long a SYNC waits for the answers to the one before, s."""
        self.interface, self.channel, self.bitrate = interface, channel, int(bitrate)
        self.lockstep = lockstep_period > 0
        self._lockstep_period = float(lockstep_period)
        self._lockstep_wait = float(lockstep_wait)
        self.node_ids = [int(i) for i in node_ids]
        m = len(self.node_ids)
        self._cable = {i: k for k, i in enumerate(self.node_ids)}
        self.lock = threading.Lock()
        self.statusword = np.zeros(m, dtype=np.int64)
        self.position = np.zeros(m, dtype=np.int64)
        self.torque = np.zeros(m, dtype=np.int64)
        self.tpdo_count = np.zeros(m, dtype=np.int64)
        self.velocity = np.zeros(m, dtype=np.int64)
        self.tpdo2_count = np.zeros(m, dtype=np.int64)
        # Which drives took the mapping of TPDO2 (velocity actual) at configure().
        self.velocity_mapped = np.zeros(m, dtype=bool)
        self.still = np.zeros(m, dtype=np.int64)
        self.heartbeat_wall = np.full(m, np.nan)
        self.heartbeat_state = np.full(m, -1, dtype=np.int64)
        self.emcy: list[tuple[int, int, int]] = []
        self.sent = 0          # RPDO frames sent
        self.syncs = 0         # SYNC frames sent
        self.send_errors = 0
        self.last_send_error = ""
        self.network = None
        self.heartbeat_watched = np.zeros(m, dtype=bool)
        # Each drive's rated torque 0x6076, N m (NaN: not read): torque actual 0x6077 is in
        # per mille of it, what force_per_torque_unit must carry.
        self.rated_torque = np.full(m, np.nan)
        self.notes: list[str] = []  # what a drive refused that the run does without
        self.polling = False
        self._at_sync = None
        self._answered = None  # tpdo_count when the last SYNC was sent (lockstep)
        self._answered2 = None  # and tpdo2_count
        self._handlers = {}
        for node_id in self.node_ids:
            self._handlers[COB_TPDO1 + node_id] = self._on_tpdo
            self._handlers[COB_TPDO2 + node_id] = self._on_tpdo2
            self._handlers[COB_EMCY + node_id] = self._on_emcy
            self._handlers[COB_HEARTBEAT + node_id] = self._on_heartbeat
        # The handle's force sensor node, if on this bus (watch_force_node): its TPDO's Fx,
        # Fy, Fz (counts), status word, the TPDOs counted, and while `force_tare` is a list,
        # each sample.
        self.force_node_id = None
        self.force_counts = np.zeros(3)
        self.force_status = 0
        self.force_count = 0
        self.force_tare: list | None = None
        self.force_at_snapshot = (np.zeros(3), 0, 0, time.monotonic())

    # --- connection and configuration -----------------------------------------------------

    def open(self) -> None:
        try:
            import canopen
        except ImportError:
            raise CanopenError("plant: !CanopenReels needs the canopen and python-can "
                               "packages: pip install 'cdpm_drake[canopen]'") from None
        if self.network is not None:
            return
        kwargs = dict(interface=self.interface, channel=self.channel)
        if self.interface not in NO_BITRATE_INTERFACES:
            kwargs["bitrate"] = self.bitrate
        if self.interface == "virtual":
            kwargs["receive_own_messages"] = False
        network = canopen.Network()
        try:
            network.connect(**kwargs)
        except Exception as e:
            raise CanopenError(f"cannot open CAN interface {self.interface!r} channel "
                               f"{self.channel!r}: {type(e).__name__}: {e}") from None
        self.network = network
        for k, node_id in enumerate(self.node_ids):
            network.add_node(canopen.RemoteNode(node_id, canopen.ObjectDictionary()))
            network.subscribe(COB_TPDO1 + node_id, self._on_tpdo)
            network.subscribe(COB_TPDO2 + node_id, self._on_tpdo2)
            network.subscribe(COB_EMCY + node_id, self._on_emcy)
            network.subscribe(COB_HEARTBEAT + node_id, self._on_heartbeat)
        if self.force_node_id is not None:
            network.subscribe(COB_TPDO1 + self.force_node_id, self._on_force)

    def close(self) -> None:
        network, self.network = self.network, None
        if network is not None:
            try:
                network.disconnect()
            except Exception:  # noqa: S110 - a bus already gone has nothing to release
                pass

    def configure(self, heartbeat_period: float, period: float = 0.0,
                  velocity: str = "position") -> None:
        """Each drive to pre-operational, then over SDO: mode 9 (cyclic synchronous velocity),
        RPDO1 = controlword + target velocity and TPDO1 = statusword + position actual +
        torque actual, both synchronous (every SYNC), with `velocity` "velocity_actual" or
        "auto" TPDO2 = velocity actual (synchronous; `velocity_mapped` says which drives took
        it: with "auto" a drive that refuses it runs without, noted), the interpolation time period 0x60C2
        (the SYNC period `period` s, if > 0: a CSV drive integrates each target velocity
        over it) and the heartbeat producer time (`heartbeat_watched` says for which drives
        it was accepted; a refusal of 0x60C2 or 0x1017, like one of reading back 0x6061,
        goes to `notes`: the drive runs without).

        What a drive may do differently, and this does not assume: the objects written in
        the order CiA 301 asks of a mapping (the PDO invalid, its count 0, the entries, the
        count, the PDO valid again), the COB-IDs written with bit 30 (RTR) as the drive has it
        (read first: a drive without remote frames refuses it clear, a simple one may take
        the whole entry for its CAN-ID), the mode display 0x6061 read until it
        shows 9 (a drive may switch modes a few cycles after the write)."""
        for node_id in self.node_ids:
            self.nmt(NMT_PRE_OPERATIONAL, node_id)
        for k, node_id in enumerate(self.node_ids):
            write = self._writer(k, node_id)
            optional_write = self._writer(k, node_id, optional=True)
            write(0x6060, 0, struct.pack("<b", MODE_CSV), "modes of operation")
            for comm, mapping, cob_id, objects, name in (
                    (0x1400, 0x1600, COB_RPDO1 + node_id, RPDO_OBJECTS, "RPDO1"),
                    (0x1800, 0x1A00, COB_TPDO1 + node_id, TPDO_OBJECTS, "TPDO1")):
                try:
                    entry = self._read(k, node_id, comm, 1, f"{name} COB-ID", optional=True)
                    cob_id |= struct.unpack_from("<I", entry.ljust(4, b"\0"))[0] & COB_NO_RTR
                except CanopenError as e:
                    self.notes.append(str(e))  # written with bit 30 clear
                self._map(write, comm, mapping, cob_id, objects, name)
            if velocity != "position":
                self._map_velocity(k, node_id, required=velocity == "velocity_actual")
            optional = []
            if period > 0 and interpolation_period(period) is not None:
                value, exponent = interpolation_period(period)
                optional.append((0x60C2, 1, struct.pack("<B", value),
                                 "interpolation time period value", None))
                optional.append((0x60C2, 2, struct.pack("<b", exponent),
                                 "interpolation time index", None))
            if heartbeat_period > 0:
                optional.append((0x1017, 0, struct.pack("<H", int(round(heartbeat_period
                                                                        * 1000))),
                                 "producer heartbeat time", "heartbeat"))
            refused = set()
            for index, sub, data, what, watched in optional:
                if index in refused:
                    continue  # 0x60C2's index is pointless without its value
                try:
                    optional_write(index, sub, data, what)
                    if watched:
                        self.heartbeat_watched[k] = True
                except CanopenError as e:
                    # Without a heartbeat producer a drive is watched by its TPDOs alone;
                    # without 0x60C2 it takes the SYNC period from its own settings.
                    refused.add(index)
                    self.notes.append(str(e))
                    _log.warning("%s; the drive runs without it", e)
            self._confirm_mode(k, node_id)
            try:
                rated = self._read(k, node_id, 0x6076, 0, "rated torque", optional=True)
                if len(rated) >= 4:
                    self.rated_torque[k] = struct.unpack_from("<I", rated)[0] / 1000.0
            except CanopenError:  # not every drive has it; the run does not need it
                pass

    def _confirm_mode(self, k, node_id, timeout: float = 0.5) -> None:
        """Read 0x6061 until it shows mode 9, for `timeout` s at most; a drive without a
        0x6061 to read runs on the accepted write of 0x6060 (noted)."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                mode = self._read(k, node_id, 0x6061, 0, "modes of operation display")
            except CanopenError as e:  # no read-back: the write of 0x6060 was accepted
                self.notes.append(str(e))
                _log.warning("%s; mode 9 written to 0x6060 is not confirmed", e)
                return
            if len(mode) >= 1 and struct.unpack_from("<b", mode)[0] == MODE_CSV:
                return
            if time.monotonic() > deadline:
                raise CanopenError(f"drive of cable {k + 1} (node {node_id}) reports mode "
                                   f"{mode.hex()} in 0x6061 {timeout:g} s after mode "
                                   f"{MODE_CSV} (cyclic synchronous velocity) was written to "
                                   f"0x6060: it does not support CSV")
            time.sleep(0.01)

    def _map_velocity(self, k, node_id, required: bool) -> None:
        """TPDO2 = velocity actual 0x606C (0x1801/0x1A01, COB-ID 0x280 + node id), as TPDO1.
        Not `required` (reel_speed: auto): a refusal leaves the drive's TPDO2 disabled (if it
        takes that) and its reel speed from positions, said in the log."""
        write = self._writer(k, node_id, optional=not required)
        cob_id = COB_TPDO2 + node_id
        try:
            try:
                entry = self._read(k, node_id, 0x1801, 1, "TPDO2 COB-ID", optional=True)
                cob_id |= struct.unpack_from("<I", entry.ljust(4, b"\0"))[0] & COB_NO_RTR
            except CanopenError as e:
                if not required:
                    raise
                self.notes.append(str(e))  # written with bit 30 clear
            self._map(write, 0x1801, 0x1A01, cob_id, TPDO2_OBJECTS, "TPDO2")
        except CanopenError as e:
            if required:
                raise
            with contextlib.suppress(CanopenError):  # not sending a half-made TPDO2
                write(0x1801, 1, struct.pack("<I", COB_INVALID | cob_id), "TPDO2 COB-ID")
            self.notes.append(str(e))
            _log.info("%s; the reel speed of cable %d comes from position differences", e,
                      k + 1)
            return
        self.velocity_mapped[k] = True
        _log.info("drive of cable %d (node %d): reel speed from velocity actual 0x606C in "
                  "TPDO2", k + 1, node_id)

    @staticmethod
    def _map(write, comm, mapping, cob_id, objects, name) -> None:
        write(comm, 1, struct.pack("<I", COB_INVALID | cob_id), f"{name} COB-ID (disable)")
        write(comm, 2, bytes([1]), f"{name} transmission type (synchronous)")
        write(mapping, 0, bytes([0]), f"{name} mapping count (clear)")
        for n, (index, bits) in enumerate(objects, start=1):
            write(mapping, n, struct.pack("<I", (index << 16) | bits),
                  f"{name} mapping entry {n} ({index:#06x})")
        write(mapping, 0, bytes([len(objects)]), f"{name} mapping count")
        write(comm, 1, struct.pack("<I", cob_id), f"{name} COB-ID (enable)")

    def _writer(self, k, node_id, optional: bool = False):
        def write(index, sub, data, what):
            try:
                with self._patience(node_id, optional):
                    self.network[node_id].sdo.download(index, sub, data)
            except Exception as e:
                raise CanopenError(self._sdo_failure(k, node_id, "write", what, index, sub, e,
                                                     optional)) from None
        return write

    def _read(self, k, node_id, index, sub, what, optional: bool = False) -> bytes:
        try:
            with self._patience(node_id, optional):
                return bytes(self.network[node_id].sdo.upload(index, sub))
        except Exception as e:
            raise CanopenError(self._sdo_failure(k, node_id, "read", what, index, sub, e,
                                                 optional)) from None

    def _sdo_failure(self, k, node_id, kind, what, index, sub, e, optional) -> str:
        """What went wrong with an SDO request, in words: a drive that aborted it refused it
        (its abort code says why); one that sent nothing did not answer within the SDO
        timeout (canopen's, tried twice)."""
        who = f"drive of cable {k + 1} (node {node_id})"
        try:
            from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError
        except ImportError:  # pragma: no cover - open() needs canopen first
            SdoAbortedError = SdoCommunicationError = ()
        if isinstance(e, SdoCommunicationError) and not isinstance(e, SdoAbortedError):
            sdo = self.network[node_id].sdo
            timeout = OPTIONAL_SDO_TIMEOUT if optional else sdo.RESPONSE_TIMEOUT
            tries = 1 + int(getattr(sdo, "MAX_RETRIES", 0))
            return (f"{who} did not answer the SDO {kind} of {what} ({index:#06x}:{sub}) within "
                    f"the SDO timeout ({tries} x {timeout:g} s): is it powered, on "
                    f"{self.interface} {self.channel!r}, with this node id?")
        return (f"{who} refused the SDO {kind} of {what} ({index:#06x}:{sub}): "
                f"{type(e).__name__}: {e}")

    @contextlib.contextmanager
    def _patience(self, node_id, optional: bool):
        """For an object the run does without (`optional`): an SDO timeout of
        OPTIONAL_SDO_TIMEOUT s instead of canopen's 0.3 (twice, with its retry), so that a
        drive that leaves such requests unanswered instead of aborting them costs 0.2 s an
        object, not 0.6."""
        sdo = self.network[node_id].sdo
        # canopen logs its own abort of an unanswered request as an error ("Transfer aborted
        # by client with code 0x05040000"); the CanopenError raised instead says it in words.
        quiet = logging.getLogger("canopen.sdo.client")
        level = quiet.level
        quiet.setLevel(logging.CRITICAL)
        try:
            if not optional:
                yield
                return
            sdo.RESPONSE_TIMEOUT = OPTIONAL_SDO_TIMEOUT
            try:
                yield
            finally:
                del sdo.RESPONSE_TIMEOUT  # back to the class's
        finally:
            quiet.setLevel(level)

    # --- cyclic traffic ----------------------------------------------------------------------

    def nmt(self, command: int, node_id: int = 0) -> None:
        self._send(COB_NMT, bytes([command, node_id]))

    def clock(self) -> float:
        """The watchdogs' clock, s: time.monotonic(), or in lockstep the SYNCs sent x the
        period (heartbeats are stamped with it, the controller's silences judged on it)."""
        if self.lockstep:
            return self.syncs * self._lockstep_period
        return time.monotonic()

    def await_answers(self) -> None:
        """Lockstep: wait (lockstep_wait s of wall clock at most) until every drive sent a
        TPDO (and a TPDO2 where mapped) since the last SYNC; what came is read into the arrays. A drive that stays
        silent is left to the watchdog, which counts the SYNCs it missed."""
        if not self.lockstep or self._answered is None or self.network is None:
            return
        deadline = time.monotonic() + self._lockstep_wait
        while True:
            self.poll()
            with self.lock:
                if ((self.tpdo_count > self._answered).all()
                        and (self.tpdo2_count > self._answered2)[self.velocity_mapped].all()):
                    return
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return
            if self.polling:
                try:
                    msg = self.network.bus.recv(min(remaining, 0.05))
                except Exception:  # a bus gone bad: the silence it makes is judged
                    return
                handler = None if msg is None else self._handlers.get(msg.arbitration_id)
                if handler is not None and not msg.is_error_frame and not msg.is_remote_frame:
                    handler(msg.arbitration_id, msg.data, msg.timestamp)
            else:
                time.sleep(0.0002)

    def send_cycle(self, controlwords, velocities) -> None:
        """One RPDO per drive (controlword, target velocity in drive units), then the SYNC
        on which the drives act on them and answer with their TPDOs. In lockstep, first
        the answers to the SYNC before (await_answers)."""
        self.await_answers()
        # What came in before this SYNC, for the tick's update to judge (sync_snapshot): the
        # drives answer within a fraction of a period, often before the rest of the tick has
        # run, and a TPDO read on the tick of its own SYNC would make a silence count a tick
        # early (and a TPDO a tick late look like two missing).
        self._at_sync = (self.snapshot(drain_emcy=False), self.clock())
        with self.lock:
            self._answered = self.tpdo_count.copy()
            self._answered2 = self.tpdo2_count.copy()
        for node_id, cw, v in zip(self.node_ids, controlwords, velocities):
            v = int(max(-2**31, min(2**31 - 1, round(float(v)))))
            if self._send(COB_RPDO1 + node_id, struct.pack("<Hi", int(cw), v)):
                self.sent += 1
        if self._send(COB_SYNC, b""):
            self.syncs += 1

    def sync_snapshot(self):
        """(snapshot, clock()) as they were just before the last SYNC was sent, once
        (then None: take a snapshot() instead); the EMCY frames it lists are drained."""
        at, self._at_sync = self._at_sync, None
        if at is not None:
            with self.lock:
                del self.emcy[:len(at[0][7])]
        return at

    def answered_snapshot(self):
        """Lockstep: (snapshot, clock()) once every drive answered the last SYNC sent
        (await_answers), the EMCY frames drained; the one kept before that SYNC
        (sync_snapshot) is dropped."""
        self._at_sync = None
        self.await_answers()
        return self.snapshot(), self.clock()

    def _send(self, cob_id: int, data: bytes) -> bool:
        network = self.network
        if network is None:
            return False
        try:
            network.send_message(cob_id, data)
            return True
        except Exception as e:  # bus-off, a full transmit queue: counted, the watchdog judges
            self.send_errors += 1
            self.last_send_error = f"{type(e).__name__}: {e}"
            return False

    def stop_notifier(self) -> None:
        """From now on the frames are read by poll() in the caller's thread (snapshot() does):
        a notifier thread waits for the interpreter's lock while the control loop's Python
        runs (up to the 5 ms switch interval), longer than a tick. SDO needs the notifier:
        call this after configure()."""
        network = self.network
        if network is not None and network.notifier is not None:
            network.notifier.stop(1.5)
            network.notifier = None
            self.polling = True

    def poll(self) -> int:
        """Read every frame waiting on the bus (without blocking) into the arrays; returns
        how many were read. Nothing to do while the notifier thread reads them."""
        if not self.polling or self.network is None:
            return 0
        bus, handlers, n = self.network.bus, self._handlers, 0
        while True:
            try:
                msg = bus.recv(0.0)
            except Exception as e:  # a bus gone bad: the silence it makes is judged
                self.last_send_error = f"receive: {type(e).__name__}: {e}"
                return n
            if msg is None:
                return n
            n += 1
            handler = handlers.get(msg.arbitration_id)
            if handler is not None and not msg.is_error_frame and not msg.is_remote_frame:
                handler(msg.arbitration_id, msg.data, msg.timestamp)

    def snapshot(self, drain_emcy: bool = True):
        """(statusword, position, torque, tpdo_count, still, heartbeat_wall, heartbeat_state,
        new EMCY list, velocity, tpdo2_count) after poll(), copied under the lock; the EMCY list is emptied if
        `drain_emcy`. The force sensor node's state at the same moment goes to
        `force_at_snapshot` ((Fx, Fy, Fz counts, status word, TPDOs counted, time.monotonic())):
        as the drives', the last snapshot before a SYNC is what the tick judges."""
        self.poll()
        with self.lock:
            self.force_at_snapshot = (self.force_counts.copy(), self.force_status,
                                      self.force_count, time.monotonic())
            emcy = self.emcy
            self.emcy = [] if drain_emcy else list(emcy)
            return (self.statusword.copy(), self.position.copy(), self.torque.copy(),
                    self.tpdo_count.copy(), self.still.copy(), self.heartbeat_wall.copy(),
                    self.heartbeat_state.copy(), emcy, self.velocity.copy(),
                    self.tpdo2_count.copy())

    # --- notifier thread ---------------------------------------------------------------------

    def _on_tpdo(self, can_id, data, timestamp) -> None:
        k = self._cable.get(can_id - COB_TPDO1)
        if k is None or len(data) < 8:
            return
        sw, pos, torque = struct.unpack_from("<Hih", bytes(data))
        with self.lock:
            same = self.tpdo_count[k] > 0 and pos == self.position[k]
            self.still[k] = self.still[k] + 1 if same else 0
            self.statusword[k], self.position[k], self.torque[k] = sw, pos, torque
            self.tpdo_count[k] += 1

    def _on_tpdo2(self, can_id, data, timestamp) -> None:
        k = self._cable.get(can_id - COB_TPDO2)
        if k is None or len(data) < 4:
            return
        (velocity,) = struct.unpack_from("<i", bytes(data))
        with self.lock:
            self.velocity[k] = velocity
            self.tpdo2_count[k] += 1

    def watch_force_node(self, node_id: int) -> None:
        """Read the TPDO of the handle's force sensor node `node_id` too (before open())."""
        self.force_node_id = int(node_id)
        self._handlers[COB_TPDO1 + self.force_node_id] = self._on_force

    def _on_force(self, can_id, data, timestamp) -> None:
        if len(data) < 6:
            return
        counts = struct.unpack_from("<3h", bytes(data))
        status = struct.unpack_from("<H", bytes(data), 6)[0] if len(data) >= 8 else 0
        with self.lock:
            self.force_counts = np.array(counts, dtype=float)
            self.force_status = status
            self.force_count += 1
            if self.force_tare is not None:
                self.force_tare.append(self.force_counts)

    def force_snapshot(self):
        """(Fx, Fy, Fz counts, status word, TPDOs counted) of the force sensor node, after
        poll()."""
        self.poll()
        with self.lock:
            return self.force_counts.copy(), self.force_status, self.force_count

    def _on_emcy(self, can_id, data, timestamp) -> None:
        k = self._cable.get(can_id - COB_EMCY)
        if k is None or len(data) < 3:
            return
        code, register = struct.unpack_from("<HB", bytes(data))
        if code:  # 0x0000: error reset / no error
            with self.lock:
                self.emcy.append((k, code, register))

    def _on_heartbeat(self, can_id, data, timestamp) -> None:
        k = self._cable.get(can_id - COB_HEARTBEAT)
        if k is None or len(data) < 1:
            return
        with self.lock:
            self.heartbeat_wall[k] = self.clock()
            self.heartbeat_state[k] = data[0] & 0x7F
