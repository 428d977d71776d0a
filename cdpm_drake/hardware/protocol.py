"""The reel link: UDP datagrams between the controller and the reel bridge (hardware/PROTOCOL.md).

Plain Python and numpy, no Drake: the same code runs in the controller, in the emulator and
in tests. Every datagram has a fixed little-endian layout: a 32-byte header, a body whose size
depends only on the cable count, and a CRC-32 trailer. Decoding checks, in this order: length,
magic, version, cable count, flags, CRC, value ranges; the first failure raises ProtocolError
naming the field and the value. Sequence numbers are 32-bit and wrap; `check_sequence` orders
them with serial-number arithmetic (RFC 1982).

Two versions: version 1, and version 2, whose status adds per drive its force at the cable,
the reel's speed and an optional load cell's tension (NaN: no reading). A version-2 command is
byte for byte a version-1 command with 2 in its version field: it tells the bridge that the
controller reads version-2 statuses. Decoders take the versions they accept.

Cables are numbered 1..m in messages; arrays are 0-based.
"""

import dataclasses
import math
import struct
import zlib

import numpy as np

MAGIC_COMMAND = b"CDPC"
MAGIC_STATUS = b"CDPS"
VERSION = 2           # the newest version this code speaks
VERSIONS = (1, 2)     # every version it reads
MAX_CABLES = 64

# Header shared by both directions: magic, version, cable count, flags, sequence,
# echo_sequence, time (s), echo_time (s).
HEADER = struct.Struct("<4sBBHIIdd")
# Status body before the arrays: fault bits, commands the bridge saw lost.
STATUS_WORDS = struct.Struct("<II")
CRC = struct.Struct("<I")

# Flag bits. ECHO_VALID is shared: the echo fields are meaningful only once the sender has
# accepted a datagram from the other side.
FLAG_ECHO_VALID = 0x0001
COMMAND_FLAG_ENABLE = 0x0002          # drive the reels at `velocity`; clear: hold them at rest
STATUS_FLAG_ENABLED = 0x0002          # the bridge is driving the reels (enabled, no fault)
COMMAND_FLAGS = FLAG_ECHO_VALID | COMMAND_FLAG_ENABLE
STATUS_FLAGS = FLAG_ECHO_VALID | STATUS_FLAG_ENABLED

# Bridge fault bits (status `faults`). Any non-zero value stops the reels on the bridge and
# latches a fault in the controller; bits stay set until the bridge is reset.
FAULT_ESTOP = 1 << 0             # emergency stop pressed
FAULT_DRIVE = 1 << 1             # a drive reports a fault (over-current, temperature, ...)
FAULT_ENCODER = 1 << 2           # an encoder reading is invalid
FAULT_FORCE_SENSOR = 1 << 3      # force sensor disconnected or saturated
FAULT_COMMAND_TIMEOUT = 1 << 4   # the bridge's watchdog: no valid command while enabled
FAULT_LENGTH_LIMIT = 1 << 5      # a cable reached its shortest or longest allowed length
FAULT_OVERSPEED = 1 << 6         # a command exceeded the drives' speed limit
FAULT_NAMES = {
    FAULT_ESTOP: "ESTOP",
    FAULT_DRIVE: "DRIVE",
    FAULT_ENCODER: "ENCODER",
    FAULT_FORCE_SENSOR: "FORCE_SENSOR",
    FAULT_COMMAND_TIMEOUT: "COMMAND_TIMEOUT",
    FAULT_LENGTH_LIMIT: "LENGTH_LIMIT",
    FAULT_OVERSPEED: "OVERSPEED",
}

# Accepted value ranges (sanity bounds of the link, not the robot's limits).
MAX_VELOCITY = 10.0      # |reel velocity|, m/s of cable
MAX_LENGTH = 100.0       # cable length in [0, MAX_LENGTH], m
MAX_FORCE = 2000.0       # |force component|, N (the FSE103 saturates at 100 N)
MAX_TIME = 1.0e9         # timestamps in [0, MAX_TIME], s
# Version 2's drive fields: NaN is "no reading"; anything else must be finite and within these.
MAX_CABLE_FORCE = 1.0e5  # |drive force| and |load-cell tension| at the cable, N
MAX_REEL_SPEED = 100.0   # |measured reel speed|, m/s of cable

# Version 2's per-cable status arrays, in wire order, and the largest |value| of each.
DRIVE_FIELDS = {"drive_force": MAX_CABLE_FORCE, "reel_speed": MAX_REEL_SPEED,
                "load_cell": MAX_CABLE_FORCE}

SEQUENCE_MODULUS = 1 << 32
_HALF = 1 << 31

# Why a datagram was refused; the link counts rejections per reason.
REASONS = ("length", "magic", "version", "cable_count", "flags", "crc", "value", "sequence")


class ProtocolError(ValueError):
    """A datagram was refused. `reason` is one of REASONS; the message names the field and
    the value."""

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason


@dataclasses.dataclass(frozen=True)
class Command:
    """Controller -> bridge. velocity: (m,) reel velocities, m/s of cable, + pays out."""

    sequence: int
    time: float                 # controller clock when sent, s
    velocity: np.ndarray
    enable: bool
    echo_sequence: int | None   # sequence of the last status accepted; None before the first
    echo_time: float = 0.0      # `time` of that status, s
    version: int = 1            # 2: the controller reads version-2 statuses


@dataclasses.dataclass(frozen=True)
class Status:
    """Bridge -> controller. lengths: (m,) measured cable lengths, m; force: (3,) raw force
    sample, base frame, N. Version 2 adds, per cable (NaN: no reading; None encodes as all
    NaN; a decoded version-1 status has them all NaN): drive_force, the drive's force at the
    cable (its torque over the drum radius), N, + pays cable out; reel_speed, the reel's
    measured speed, m/s of cable, + pays out; load_cell, a load cell's tension, N."""

    sequence: int
    time: float                 # bridge clock when sent, s
    lengths: np.ndarray
    force: np.ndarray
    faults: int = 0             # FAULT_* bits
    enabled: bool = False       # the bridge is driving the reels
    echo_sequence: int | None = None  # sequence of the last command accepted
    echo_time: float = 0.0      # `time` of that command, s
    commands_lost: int = 0      # command sequence numbers the bridge never received
    version: int = 1
    drive_force: np.ndarray | None = None
    reel_speed: np.ndarray | None = None
    load_cell: np.ndarray | None = None


def command_size(num_cables: int, version: int = 1) -> int:
    """Bytes in a command datagram for m cables (the same in both versions)."""
    return HEADER.size + 8 * num_cables + CRC.size


def status_size(num_cables: int, version: int = 1) -> int:
    """Bytes in a status datagram for m cables: version 2 adds 3 x 8 bytes per cable."""
    extra = 24 * num_cables if version >= 2 else 0
    return HEADER.size + STATUS_WORDS.size + 8 * num_cables + 24 + extra + CRC.size


def fault_names(faults: int) -> list[str]:
    """Names of the set fault bits, e.g. ['ESTOP', 'DRIVE']; unknown bits as 'BIT<k>'."""
    names = []
    for k in range(32):
        bit = 1 << k
        if faults & bit:
            names.append(FAULT_NAMES.get(bit, f"BIT{k}"))
    return names


# --- encoding --------------------------------------------------------------------------------


def encode_command(command: Command, check: bool = True) -> bytes:
    """The datagram for `command`. Raises ProtocolError on out-of-range values unless
    check=False (fault injection only)."""
    v = np.ascontiguousarray(command.velocity, dtype="<f8")
    m = v.shape[0]
    _check_count(m, "velocity")
    _check_version(command.version)
    if check:
        _check_sequence_field(command.sequence, "sequence")
        _check_time(command.time, "time")
        _check_time(command.echo_time, "echo_time")
        _check_array(v, MAX_VELOCITY, "velocity", "m/s", lo=-MAX_VELOCITY)
    flags = (COMMAND_FLAG_ENABLE if command.enable else 0)
    echo = 0
    if command.echo_sequence is not None:
        if check:
            _check_sequence_field(command.echo_sequence, "echo_sequence")
        flags |= FLAG_ECHO_VALID
        echo = command.echo_sequence
    body = HEADER.pack(MAGIC_COMMAND, command.version, m, flags, command.sequence, echo,
                       command.time, command.echo_time) + v.tobytes()
    return body + CRC.pack(zlib.crc32(body))


def encode_status(status: Status, check: bool = True) -> bytes:
    """The datagram for `status`. Raises ProtocolError on out-of-range values unless
    check=False (the emulator's NaN injection)."""
    lengths = np.ascontiguousarray(status.lengths, dtype="<f8")
    force = np.ascontiguousarray(status.force, dtype="<f8")
    m = lengths.shape[0]
    _check_count(m, "lengths")
    _check_version(status.version)
    drive = [_drive_array(getattr(status, name), m, name) for name in DRIVE_FIELDS] \
        if status.version >= 2 else []
    if check:
        for (name, hi), values in zip(DRIVE_FIELDS.items(), drive):
            _check_drive_array(values, hi, name)
        if force.shape != (3,):
            raise ProtocolError("value", f"force must have 3 components, got shape "
                                         f"{force.shape!r}")
        _check_sequence_field(status.sequence, "sequence")
        _check_time(status.time, "time")
        _check_time(status.echo_time, "echo_time")
        _check_array(lengths, MAX_LENGTH, "lengths", "m", lo=0.0)
        _check_array(force, MAX_FORCE, "force", "N", lo=-MAX_FORCE)
        for name in ("faults", "commands_lost"):
            value = getattr(status, name)
            if not (isinstance(value, (int, np.integer)) and 0 <= value < SEQUENCE_MODULUS):
                raise ProtocolError("value", f"{name} must be a 32-bit unsigned integer, got "
                                             f"{value!r}")
    flags = STATUS_FLAG_ENABLED if status.enabled else 0
    echo = 0
    if status.echo_sequence is not None:
        flags |= FLAG_ECHO_VALID
        echo = status.echo_sequence
    body = (HEADER.pack(MAGIC_STATUS, status.version, m, flags, status.sequence, echo,
                        status.time, status.echo_time)
            + STATUS_WORDS.pack(status.faults, status.commands_lost)
            + lengths.tobytes() + force.tobytes() + b"".join(a.tobytes() for a in drive))
    return body + CRC.pack(zlib.crc32(body))


# --- decoding --------------------------------------------------------------------------------


def decode_command(data: bytes, num_cables: int, versions=VERSIONS) -> Command:
    """Parse and check a command datagram for a robot with `num_cables` cables, of one of
    `versions`."""
    version, flags, seq, echo, t, echo_t = _decode_header(
        data, num_cables, MAGIC_COMMAND, "command", command_size, COMMAND_FLAGS, versions)
    v = np.frombuffer(data, dtype="<f8", count=num_cables, offset=HEADER.size).astype(float)
    _check_time(t, "time")
    _check_time(echo_t, "echo_time")
    _check_array(v, MAX_VELOCITY, "velocity", "m/s", lo=-MAX_VELOCITY)
    return Command(sequence=seq, time=t, velocity=v, enable=bool(flags & COMMAND_FLAG_ENABLE),
                   echo_sequence=echo if flags & FLAG_ECHO_VALID else None, echo_time=echo_t,
                   version=version)


def decode_status(data: bytes, num_cables: int, versions=VERSIONS) -> Status:
    """Parse and check a status datagram for a robot with `num_cables` cables, of one of
    `versions`. A version-1 status decodes with drive_force, reel_speed and load_cell all
    NaN."""
    version, flags, seq, echo, t, echo_t = _decode_header(
        data, num_cables, MAGIC_STATUS, "status", status_size, STATUS_FLAGS, versions)
    faults, lost = STATUS_WORDS.unpack_from(data, HEADER.size)
    arrays = np.frombuffer(data, dtype="<f8", count=num_cables + 3,
                           offset=HEADER.size + STATUS_WORDS.size).astype(float)
    lengths, force = arrays[:num_cables], arrays[num_cables:]
    _check_time(t, "time")
    _check_time(echo_t, "echo_time")
    _check_array(lengths, MAX_LENGTH, "lengths", "m", lo=0.0)
    _check_array(force, MAX_FORCE, "force", "N", lo=-MAX_FORCE)
    m = num_cables
    if version >= 2:
        drive = np.frombuffer(data, dtype="<f8", count=3 * m, offset=HEADER.size
                              + STATUS_WORDS.size + 8 * m + 24).astype(float)
        drive = [drive[k * m:(k + 1) * m] for k in range(3)]
        for (name, hi), values in zip(DRIVE_FIELDS.items(), drive):
            _check_drive_array(values, hi, name)
    else:
        drive = [np.full(m, np.nan) for _ in range(3)]
    return Status(sequence=seq, time=t, lengths=lengths, force=force, faults=faults,
                  enabled=bool(flags & STATUS_FLAG_ENABLED),
                  echo_sequence=echo if flags & FLAG_ECHO_VALID else None, echo_time=echo_t,
                  commands_lost=lost, version=version, drive_force=drive[0],
                  reel_speed=drive[1], load_cell=drive[2])


def _drive_array(values, m, field):
    if values is None:
        return np.full(m, np.nan, dtype="<f8")
    values = np.ascontiguousarray(values, dtype="<f8")
    if values.shape != (m,):
        raise ProtocolError("value", f"{field} must have {m} entries (one per cable), got "
                                     f"shape {values.shape!r}")
    return values


def _check_drive_array(values, hi, field):
    """NaN is "no reading"; any other value must be finite and within [-hi, hi]."""
    bad = ~np.isnan(values) & ~(np.abs(values) <= hi)
    if bad.any():
        k = int(np.argmax(bad))
        unit = "m/s" if field == "reel_speed" else "N"
        raise ProtocolError("value", f"{field} of cable {k + 1} is {float(values[k])!r} "
                                     f"{unit}, outside [{-hi:g}, {hi:g}] {unit} (NaN: no "
                                     f"reading)")


def _check_version(version):
    if version not in VERSIONS:
        raise ProtocolError("version", f"version is {version!r}, this link speaks versions "
                                       f"{', '.join(map(str, VERSIONS))}")


def _decode_header(data, num_cables, magic, kind, size_of, allowed_flags, versions):
    _check_count(num_cables, "num_cables")
    n = len(data)
    if n < HEADER.size:
        raise ProtocolError("length", f"{kind} datagram is {n} bytes, shorter than the "
                                      f"{HEADER.size}-byte header")
    got_magic, version, m, flags, seq, echo, t, echo_t = HEADER.unpack_from(data, 0)
    if got_magic != magic:
        other = {MAGIC_COMMAND: "a command", MAGIC_STATUS: "a status"}.get(got_magic)
        hint = f" (that is {other} datagram)" if other else ""
        raise ProtocolError("magic", f"magic is {got_magic!r}{hint}, expected {magic!r} "
                                     f"for a {kind}")
    if version not in versions:
        raise ProtocolError("version", f"version is {version!r}, this link speaks version"
                                       f"{'s' if len(versions) > 1 else ''} "
                                       f"{', '.join(map(str, versions))}")
    if m != num_cables:
        raise ProtocolError("cable_count", f"cable_count is {m!r}, expected {num_cables} "
                                           f"(the robot's cables)")
    expected = size_of(m, version)
    if n != expected:
        raise ProtocolError("length", f"{kind} datagram is {n} bytes, expected {expected} "
                                      f"for {m} cables")
    if flags & ~allowed_flags:
        raise ProtocolError("flags", f"flags is {flags:#06x}: bits {flags & ~allowed_flags:#06x} "
                                     f"are not defined for a {kind}")
    (crc,) = CRC.unpack_from(data, n - CRC.size)
    actual = zlib.crc32(memoryview(data)[:n - CRC.size])
    if crc != actual:
        raise ProtocolError("crc", f"crc is {crc:#010x}, the datagram's bytes give "
                                   f"{actual:#010x}")
    return version, flags, seq, echo, t, echo_t


def _check_count(m, field):
    if not (isinstance(m, (int, np.integer)) and 1 <= m <= MAX_CABLES):
        raise ProtocolError("cable_count", f"{field}: cable count must be 1..{MAX_CABLES}, "
                                           f"got {m!r}")


def _check_sequence_field(value, field):
    if not (isinstance(value, (int, np.integer)) and 0 <= value < SEQUENCE_MODULUS):
        raise ProtocolError("value", f"{field} must be an integer in 0..{SEQUENCE_MODULUS - 1},"
                                     f" got {value!r}")


def _check_time(value, field):
    if not (math.isfinite(value) and 0.0 <= value <= MAX_TIME):
        raise ProtocolError("value", f"{field} is {value!r} s, outside [0, {MAX_TIME:g}] s")


def _check_array(values, hi, field, unit, lo):
    ok = np.isfinite(values) & (values >= lo) & (values <= hi)
    if not ok.all():
        k = int(np.argmin(ok))
        # Force components are x, y, z; everything else is per cable (1-based).
        where = f"{field}[{'xyz'[k]}]" if field == "force" else f"{field} of cable {k + 1}"
        raise ProtocolError("value", f"{where} is {float(values[k])!r} {unit}, outside "
                                     f"[{lo:g}, {hi:g}] {unit}")


# --- sequence numbers ------------------------------------------------------------------------


def sequence_delta(new: int, last: int) -> int:
    """Signed distance from `last` to `new` modulo 2^32, in [-2^31, 2^31)."""
    d = (int(new) - int(last)) % SEQUENCE_MODULUS
    return d - SEQUENCE_MODULUS if d >= _HALF else d


def check_sequence(new: int, last: int | None) -> int:
    """How many sequence numbers were skipped between `last` and `new` (0 if consecutive).

    Raises ProtocolError('sequence') when `new` repeats `last` or is older (serial-number
    arithmetic: newer means 1..2^31-1 steps ahead, modulo 2^32). `last` None accepts anything.
    """
    if last is None:
        return 0
    d = sequence_delta(new, last)
    if d == 0:
        raise ProtocolError("sequence", f"sequence {new!r} repeats the last accepted one")
    if d < 0:
        raise ProtocolError("sequence", f"sequence {new!r} is {-d} older than the last "
                                        f"accepted {last!r}")
    return d - 1


class SequenceTracker:
    """Receiver-side ordering of one stream: accepts strictly newer sequence numbers and counts
    the skipped ones as lost. (The Drake system keeps `last` in its state and calls
    `check_sequence` directly; the emulator uses this class.)"""

    def __init__(self):
        self.last: int | None = None
        self.lost = 0

    def accept(self, sequence: int) -> int:
        """Record `sequence`; returns the gap; ProtocolError if repeated or old."""
        gap = check_sequence(sequence, self.last)
        self.last = int(sequence)
        self.lost += gap
        return gap


def next_sequence(sequence: int) -> int:
    return (int(sequence) + 1) % SEQUENCE_MODULUS
