"""ReelBridgeServer: the bridge on a UDP socket, serving a bridge plant (emulator/bridges.py)
to a controller under a fault plan (emulator/faults.py), and what it records: the commands
read (ReceivedCommand), the controller sessions, the counters and the compute per tick. The
protocol is hardware/PROTOCOL.md."""

import collections
import dataclasses
import errno
import math
import select
import socket
import threading
import time

import numpy as np

from cdpm_drake.emulator.bridges import ReelBridge
from cdpm_drake.emulator.faults import FaultPlan
from cdpm_drake.hardware.link import resolve_ipv4
from cdpm_drake.hardware.protocol import (FAULT_COMMAND_TIMEOUT, REASONS, VERSION, VERSIONS,
                                          ProtocolError, SequenceTracker, Status,
                                          decode_command, encode_status, next_sequence)

# Longest wait for a command in lockstep before looking at the session's silence, s.
LOCKSTEP_POLL = 0.05

# Ticks whose compute time the server keeps for its summary (8.7 min at 500 Hz).
COMPUTE_WINDOW = 1 << 18

@dataclasses.dataclass(frozen=True)
class ReceivedCommand:
    """A command as the emulator read it: `time` is the bridge clock when it was read, s;
    `command_time` the controller's `time` field, s."""

    time: float
    tick: int
    sequence: int
    command_time: float
    enable: bool
    velocity: np.ndarray
    fault_active: bool


class ReelBridgeServer:
    """The bridge on a UDP socket, run in this thread (`run`) or a background one (`start`).

    Every `period` s it reads the waiting commands (the newest valid one takes effect),
    advances the reels, and sends one status to the sender of the latest valid command (or to
    `controller` if given; then commands from anyone else are ignored). If the reels are
    enabled and no valid command came for `command_timeout` s, it raises FAULT_COMMAND_TIMEOUT.
    """

    def __init__(self, bridge: ReelBridge, address: tuple[str, int] = ("127.0.0.1", 0),
                 faults: FaultPlan = FaultPlan(), period: float = 0.002, seed: int = 0,
                 controller: tuple[str, int] | None = None, command_timeout: float = 0.05,
                 record: int = 100_000, log=None, session_timeout: float = 1.0,
                 protocol_version: int = VERSION, truth: int = 0, lockstep: bool = False):
        """`record`: how many received commands to keep in `commands` (tests read them; the
        command-line emulator keeps none). `log(text)` is told what the bridge sees: each
        controller session opened and closed, the first rejected datagram of each reason per
        session (None: silent). A session closes when a new one starts or after
        `session_timeout` s without a valid command. The fault plan applies to one session:
        the first in which it takes effect; later sessions run without faults.

        `protocol_version`: the newest version the bridge speaks (1 plays a version-1 bridge:
        it refuses version-2 commands). A version-2 bridge answers in version 1 until it
        accepts a version-2 command in a session (hardware/PROTOCOL.md "Versions"); its
        statuses carry the plant's drive forces, reel speeds and load cells (`drive_force()`,
        `speed`, `load_cell()` of the bridge plant). `truth`: how many statuses to keep in
        `truth` with the plant's ground truth beside what they carried (a plant with
        `true_tensions()` only; 0: none).

        `lockstep`: the bridge keeps no clock of its own: each valid command read is one
        tick (the plant stepped one `period` under the command before it, the new command
        taken, one status sent), so the bridge's time is ticks x period, whatever the wall
        clock does; the command timeout is off (no time passes without a command) and a
        session still closes after `session_timeout` s of wall clock without a command."""
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period must be a finite number > 0 s, got {period!r}")
        if not (math.isfinite(session_timeout) and session_timeout > 0):
            raise ValueError(f"session_timeout must be a finite number > 0 s, got "
                             f"{session_timeout!r}")
        if protocol_version not in VERSIONS:
            raise ValueError(f"protocol_version must be one of {VERSIONS}, got "
                             f"{protocol_version!r}")
        self.bridge = bridge
        self.protocol_version = int(protocol_version)
        self._versions = tuple(v for v in VERSIONS if v <= protocol_version)
        self._status_version = 1         # the session's, until a version-2 command
        self.period = float(period)
        self.lockstep = bool(lockstep)
        self.command_timeout = float(command_timeout)
        self._faults = faults
        self._rng = np.random.default_rng(seed)
        self._m = bridge.robot.num_cables
        self._fixed_controller = (None if controller is None
                                  else (resolve_ipv4(controller[0], "controller"),
                                        int(controller[1])))
        self._controller = self._fixed_controller
        self._log = log
        self.session_timeout = float(session_timeout)
        host, port = resolve_ipv4(address[0], "address"), int(address[1])
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.setblocking(False)
        try:
            self._sock.bind((host, port))
        except OSError as e:
            self._sock.close()
            hint = (" (another cdpm emulate or bridge is listening there? choose another "
                    "--port)" if e.errno == errno.EADDRINUSE else
                    " (not an address of this machine? see --address)"
                    if e.errno == errno.EADDRNOTAVAIL else "")
            raise OSError(e.errno, f"cannot listen on UDP {host}:{port}: "
                                   f"{e.strerror or e}{hint}") from None
        self._tracker = SequenceTracker()
        self._last_command = None
        self._last_command_wall = None
        self._last_command_wall_clock = None  # time.monotonic() of it (lockstep's sessions)
        self._sequence = 0
        self._frozen = None              # the datagram a frozen bridge repeats
        self._held = None                # a status held back for reordering
        self._delayed = collections.deque()  # (due time, datagram)
        self._stop = threading.Event()
        self._thread = None
        self._lock = threading.Lock()
        self.start_wall = None
        self.first_enable_time = None    # bridge time of the first enabling command, s
        self.fault_onset = None          # bridge time the FaultPlan took effect, s
        self.fault_onset_tick = None
        self.tick = 0
        self.commands = collections.deque(maxlen=record)
        # (bridge time s, plant time s, true tensions N, drive_force sent N, reel_speed sent
        # m/s, true platform centre m, true roll-pitch-yaw rad, load_cell sent N) per status
        # sent, if asked for and the plant has a ground truth.
        self.truth = collections.deque(maxlen=truth or None) if (
            truth and hasattr(bridge, "true_tensions")) else None
        # Controller sessions, numbered from 1 (0: none yet); `session_open` while one runs.
        self.session = 0
        self.session_open = False
        self._session_start = 0.0
        self._session_commands = 0
        self._session_rejected = {}
        self._fault_session = None   # the session in which the fault plan took effect
        # Compute time of each tick (reading commands, stepping the plant, sending the
        # status), s: the last COMPUTE_WINDOW ticks.
        self.compute = collections.deque(maxlen=COMPUTE_WINDOW)
        self.counters = {"statuses_sent": 0, "statuses_dropped": 0, "commands_received": 0,
                         "commands_dropped": 0, "commands_foreign": 0, "late_ticks": 0,
                         "sessions": 0,
                         "rejected": {r: 0 for r in REASONS}}

    @property
    def address(self) -> tuple[str, int]:
        """(address, port) the bridge listens on."""
        return self._sock.getsockname()

    def now(self) -> float:
        """The bridge's clock, s: wall time since run() began, or in lockstep ticks x
        period."""
        if self.lockstep:
            return self.tick * self.period
        return time.monotonic() - self.start_wall if self.start_wall is not None else 0.0

    @property
    def faults(self) -> FaultPlan:
        return self._faults

    def compute_summary(self) -> str:
        """Compute per tick over the last COMPUTE_WINDOW ticks: p50, p99 and max, ms."""
        if not self.compute:
            return "compute per tick: no ticks"
        c = 1e3 * np.asarray(self.compute)
        return (f"compute per tick p50 {np.percentile(c, 50):.3f} / p99 "
                f"{np.percentile(c, 99):.3f} / max {c.max():.3f} ms over {c.size} ticks "
                f"(period {self.period * 1e3:g} ms)")

    @property
    def commands_lost(self) -> int:
        """Command sequence numbers skipped by the commands read (the status's
        commands_lost)."""
        return self._tracker.lost

    def inject(self, faults: FaultPlan) -> None:
        """Replace the fault plan while running; its `after` counts from now."""
        with self._lock:
            self._faults = faults
            self._fault_session = None
            self.fault_onset = None
            self.fault_onset_tick = None
            if self.start_wall is not None:
                self.first_enable_time = self.now()

    # --- the loop ----------------------------------------------------------------------------

    def run(self, duration: float | None = None) -> None:
        """Serve until `duration` s have passed (of the bridge's clock in lockstep), stop()
        is called, or forever."""
        if self.lockstep:
            self._run_lockstep(duration)
            return
        self.start_wall = time.monotonic()
        last = 0.0
        deadline = self.start_wall
        while not self._stop.is_set():
            tick_start = time.monotonic()
            now = tick_start - self.start_wall
            if duration is not None and now >= duration:
                break
            with self._lock:
                command = self._drain(now)
                if (self.session_open and self._last_command_wall is not None
                        and now - self._last_command_wall > self.session_timeout):
                    self.close_session(now, f"no command for {self.session_timeout:g} s")
                self.bridge.step(now - last)
                last = now
                if command is not None:
                    self.bridge.set_command(command.velocity, command.enable)
                    if command.enable and self.first_enable_time is None:
                        self.first_enable_time = now
                if (self.bridge.enabled and self._last_command_wall is not None
                        and now - self._last_command_wall > self.command_timeout):
                    self.bridge.raise_fault(FAULT_COMMAND_TIMEOUT)
                active = self._fault_active(now)
                self._send_status(now, active)
            self.compute.append(time.monotonic() - tick_start)
            self.tick += 1
            deadline += self.period
            pause = deadline - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            elif pause < -10 * self.period:
                # Far behind (the host stalled): restart the schedule rather than burst.
                self.counters["late_ticks"] += 1
                deadline = time.monotonic()

    def _run_lockstep(self, duration: float | None) -> None:
        """One tick per valid command, in the order they came (module docstring: lockstep).
        A datagram that is not a valid command (rejected, foreign, dropped by the fault plan)
        steps nothing: only the controller's ticks move the plant."""
        self.start_wall = time.monotonic()
        last = 0.0
        while not self._stop.is_set():
            now = self.tick * self.period
            if duration is not None and now >= duration:
                break
            readable, _, _ = select.select([self._sock], [], [], LOCKSTEP_POLL)
            wall = time.monotonic()
            with self._lock:
                if not readable:
                    if (self.session_open and self._last_command_wall_clock is not None
                            and wall - self._last_command_wall_clock > self.session_timeout):
                        self.close_session(now, f"no command for {self.session_timeout:g} s")
                    continue
                command = self._drain(now, one=True)
                if command is None:
                    continue
                self._last_command_wall_clock = wall
                self.bridge.step(now - last)
                last = now
                self.bridge.set_command(command.velocity, command.enable)
                if command.enable and self.first_enable_time is None:
                    self.first_enable_time = now
                self._send_status(now, self._fault_active(now))
            self.compute.append(time.monotonic() - wall)
            self.tick += 1

    def _fault_active(self, now: float) -> bool:
        plan = self._faults
        if not plan.any or self.first_enable_time is None:
            return False
        if self.fault_onset is None:
            if now < self.first_enable_time + plan.after:
                return False
            self.fault_onset, self.fault_onset_tick = now, self.tick
            # Before any command (inject() at start-up), the faults belong to the first session.
            self._fault_session = max(self.session, 1)
            self._say(f"session {self.session}: injecting faults now ({now:.3f} s): "
                      f"{plan.describe()}")
            if plan.fault_bits:
                self.bridge.raise_fault(plan.fault_bits)
        return True

    def _drain(self, now: float, one: bool = False):
        """Read the waiting commands (at most 256 datagrams; with `one`, up to the first
        valid command); the newest valid one, or None."""
        newest = None
        active = self.fault_onset is not None
        for _ in range(256):
            if one and newest is not None:
                break
            try:
                data, sender = self._sock.recvfrom(4096)
            except (BlockingIOError, ConnectionRefusedError):
                break
            if self._fixed_controller is not None and sender != self._fixed_controller:
                self.counters["commands_foreign"] += 1
                continue
            if active and self._faults.drop and self._rng.random() < self._faults.drop:
                self.counters["commands_dropped"] += 1
                continue
            try:
                command = decode_command(data, self._m, self._versions)
                self._accept_sequence(command, now, sender)
            except ProtocolError as e:
                self.counters["rejected"][e.reason] += 1
                self._note_rejection(e, sender)
                continue
            if not self.session_open:
                self._open_session(now, sender)
            if command.version > self._status_version:
                # The controller reads this version: answer in it to the session's end.
                self._status_version = command.version
                self._say(f"session {self.session}: speaking protocol version "
                          f"{command.version}")
            self.counters["commands_received"] += 1
            self._session_commands += 1
            self._controller = sender
            self._last_command = command
            self._last_command_wall = now
            newest = command
            self.commands.append(ReceivedCommand(now, self.tick, command.sequence, command.time,
                                                 command.enable, command.velocity, active))
        return newest

    def _accept_sequence(self, command, now: float = 0.0, sender=None) -> None:
        """Order the command stream. A controller that starts again (a new `cdpm run`) greets
        with enable-clear commands from sequence 1; while the reels are at rest, such a
        command opens a new session instead of being dropped as old (hardware/PROTOCOL.md)."""
        try:
            self._tracker.accept(command.sequence)
        except ProtocolError as e:
            if e.reason != "sequence" or command.enable or self.bridge.enabled:
                raise
            self._tracker = SequenceTracker()
            self._tracker.accept(command.sequence)
            self.counters["sessions"] += 1
            if self.session_open:
                self.close_session(now, "a new controller session began")
            self._open_session(now, sender)

    # --- sessions ----------------------------------------------------------------------------

    def _say(self, text: str) -> None:
        if self._log is not None:
            self._log(text)

    def _open_session(self, now: float, sender) -> None:
        self.session += 1
        self.session_open = True
        self._status_version = 1
        self._session_start = now
        self._session_commands = 0
        self._session_rejected = {}
        where = f" by {sender[0]}:{sender[1]}" if sender else ""
        self._say(f"session {self.session} opened{where} at {now:.3f} s")
        if (self._fault_session is not None and self._fault_session < self.session
                and self._faults.any):
            # The plan was spent on an earlier session: this one runs clean. The bits the plan
            # raised are cleared (the operator reset the e-stop between runs); the bits the
            # bridge raised itself (COMMAND_TIMEOUT, OVERSPEED) stay, as on a real bridge.
            injected = self.bridge.faults & self._faults.fault_bits
            self._say(f"session {self.session}: no faults injected (the fault plan applied "
                      f"to session {self._fault_session})"
                      + (f"; injected fault bits {injected:#06x} cleared" if injected else ""))
            self.bridge.faults &= ~self._faults.fault_bits
            self._faults = FaultPlan()
        if self.session > 1:
            # The fault plan's clock restarts with each session (`after` counts from its first
            # enabling command); the first session keeps what inject() set.
            self.first_enable_time = None
            self.fault_onset = self.fault_onset_tick = None
            self._frozen, self._held = None, None
            self._delayed.clear()
            # Each rehearsal starts where the scenario does, as after a homing: the last run
            # left the platform wherever the hand took it.
            left = self.bridge.platform()
            self.bridge.reset()
            start = self.bridge.platform()
            self._say(f"session {self.session}: the platform is back at its start "
                      f"{vector_text(start)} m (reset, as a homing would; the last session left "
                      f"it at {vector_text(left)} m, {np.linalg.norm(left - start):.3f} m away), "
                      f"the operator's clock at 0")

    def close_session(self, now: float, why: str) -> None:
        """Close the session open at bridge time `now` (s), saying `why` and what it saw: the
        commands accepted and rejected, the reels' state and, with a plant that keeps one,
        what the cables went through."""
        self.session_open = False
        rejected = count_by_reason(self._session_rejected)
        self._say(f"session {self.session} closed at {now:.3f} s ({why}): "
                  f"{self._session_commands} commands accepted, rejected {rejected}, reels "
                  f"{'enabled' if self.bridge.enabled else 'at rest'}, faults "
                  f"{self.bridge.faults:#06x}")
        if hasattr(self.bridge, "summary"):  # what the plant went through in the session
            self._say(f"session {self.session}: {self.bridge.summary()}")

    def _note_rejection(self, e: ProtocolError, sender) -> None:
        n = self._session_rejected.get(e.reason, 0)
        self._session_rejected[e.reason] = n + 1
        if n == 0:  # the first of each reason per session; the rest are counted
            self._say(f"rejected a command from {sender[0]}:{sender[1]} ({e.reason}): {e}; "
                      f"further '{e.reason}' rejections are counted, not shown")

    def _send_status(self, now: float, active: bool) -> None:
        plan = self._faults if active else FaultPlan()
        if plan.stop:
            return
        if plan.freeze and self._frozen is not None:
            self._emit(self._frozen)
            return
        b = self.bridge
        self._sequence = next_sequence(self._sequence)
        c = self._last_command
        lengths = np.array(b.encoder_lengths(), dtype=float)
        if plan.nan:
            lengths[0] = np.nan
        drive = {}
        if self._status_version >= 2:
            drive = dict(drive_force=b.drive_force(), reel_speed=b.reel_speed(),
                         load_cell=b.load_cell())
            if self.truth is not None:
                self.truth.append((now, b.plant_time, b.true_tensions(), drive["drive_force"],
                                   drive["reel_speed"], *b.true_pose(), drive["load_cell"]))
        data = encode_status(Status(
            sequence=self._sequence, time=now, lengths=lengths, force=b.force(),
            faults=b.faults, enabled=b.enabled,
            echo_sequence=None if c is None else c.sequence,
            echo_time=0.0 if c is None else c.time,
            commands_lost=self._tracker.lost % (1 << 32), version=self._status_version,
            **drive), check=not plan.nan)
        self._frozen = data  # what a hung bridge task would keep resending
        rng = self._rng
        if plan.drop and rng.random() < plan.drop:
            self.counters["statuses_dropped"] += 1
            return
        if plan.corrupt and rng.random() < plan.corrupt:
            buf = bytearray(data)
            buf[int(rng.integers(len(buf)))] ^= int(rng.integers(1, 256))
            data = bytes(buf)
        copies = [data, data] if plan.duplicate and rng.random() < plan.duplicate else [data]
        if plan.reorder and self._held is None and rng.random() < plan.reorder:
            self._held = copies
            return
        if self._held is not None:
            copies, self._held = copies + self._held, None
        for d in copies:
            if plan.delay > 0:
                self._delayed.append((now + plan.delay, d))
            else:
                self._emit(d)
        while self._delayed and self._delayed[0][0] <= now:
            self._emit(self._delayed.popleft()[1])

    def _emit(self, data: bytes) -> None:
        if self._controller is None:
            return
        try:
            self._sock.sendto(data, self._controller)
            self.counters["statuses_sent"] += 1
        except OSError:
            pass  # the controller is gone; it is the one that must notice

    # --- in-process mode ---------------------------------------------------------------------

    def start(self) -> "ReelBridgeServer":
        """Serve from a daemon thread (tests, benchmarks)."""
        self._thread = threading.Thread(target=self.run, name="reel-bridge-emulator",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and release the socket. Commands that arrived since the last tick
        (a controller's shutdown burst, sent just before stop() is called) are read into
        `commands` and the counters first, not lost with the socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._sock.fileno() < 0:
            return  # stopped before
        if self._thread is None or not self._thread.is_alive():
            with self._lock:
                self._drain(self.now())
        self._sock.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


def vector_text(v) -> str:
    """A vector as the emulator prints it: [1.500, 3.000, 1.000] (3 decimals)."""
    return "[" + ", ".join(f"{x:.3f}" for x in np.asarray(v, dtype=float)) + "]"


def count_by_reason(counts: dict) -> str:
    """{'value': 3, 'crc': 1} -> '4 (value 3, crc 1)'; {} -> '0'."""
    total = sum(counts.values())
    if not total:
        return "0"
    return f"{total} (" + ", ".join(f"{r} {n}" for r, n in counts.items() if n) + ")"
