"""The handle's force sensor at run time (no Drake): the scaling, axes and tare every kind
shares (ForceScale), ATI's RDT protocol (rdt_request, rdt_record, parse_rdt) and a Net F/T
read over UDP without blocking (NetFTSource). The CANopen node's frames are read by the
bus's master (hardware/canopen_bus.py) with the drives'.
"""

import socket
import struct
import time

import numpy as np

from cdpm_drake.hardware.force_config import NetFT, axes_matrix

RDT_HEADER = 0x1234
RDT_STOP, RDT_START_REALTIME = 0x0000, 0x0002
RDT_REQUEST = struct.Struct(">HHI")            # header, command, sample count (0: forever)
RDT_RECORD = struct.Struct(">III6i")           # rdt seq, ft seq, status, Fx..Tz counts
RDT_STATUS_ERROR = 0x80000000                  # status bit 31: the box reports an error


class ForceSensorError(RuntimeError):
    """The handle's force sensor did not answer or reported an error; the message says
    which."""


def rdt_request(command: int = RDT_START_REALTIME, samples: int = 0) -> bytes:
    return RDT_REQUEST.pack(RDT_HEADER, command, samples)


def rdt_record(rdt_sequence: int, ft_sequence: int, status: int, counts) -> bytes:
    return RDT_RECORD.pack(rdt_sequence & 0xFFFFFFFF, ft_sequence & 0xFFFFFFFF,
                           status & 0xFFFFFFFF, *[int(c) for c in counts])


def parse_rdt(data: bytes):
    """(rdt_sequence, ft_sequence, status, 6 counts) of a 36-byte record, or None."""
    if len(data) != RDT_RECORD.size:
        return None
    values = RDT_RECORD.unpack(data)
    return values[0], values[1], values[2], values[3:]


class ForceScale:
    """Counts in the sensor's axes to N in the base frame, less the bias the tare found:
    F = R @ (counts / counts_per_newton) - bias."""

    def __init__(self, counts_per_newton: float, axes, field: str = "plant.force_sensor"):
        self.per_newton = float(counts_per_newton)
        self.R = axes_matrix(axes, f"{field}.axes")
        self.bias = np.zeros(3)

    def raw(self, counts) -> np.ndarray:
        """The force of `counts` (Fx, Fy, Fz in the sensor's axes), base frame, N, untared."""
        return self.R @ (np.asarray(counts[:3], dtype=float) / self.per_newton)

    def force(self, counts) -> np.ndarray:
        return self.raw(counts) - self.bias

    def tare(self, samples) -> None:
        """The mean of `samples` (rows of counts) as the bias; none: no tare."""
        if len(samples):
            self.bias = np.mean([self.raw(c) for c in samples], axis=0)


class NetFTSource:
    """A Net F/T streaming high-speed real-time records to this host: open() binds a socket
    and asks for the stream, tare() waits for the tare's records, poll() reads what came
    without blocking. `records` counts the records read, `status` is the newest's."""

    def __init__(self, config: NetFT, field: str = "plant.force_sensor"):
        self.config, self.field = config, field
        self.scale = ForceScale(config.counts_per_force, config.axes, field)
        self.sock = None
        self.records = 0
        self.status = 0
        self.counts = np.zeros(6)
        self.rdt_sequence = None
        self.lost = 0  # records skipped, by their RDT sequence numbers

    def describe(self) -> str:
        return f"Net F/T at {self.config.address}:{self.config.port}"

    def open(self) -> None:
        c = self.config
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((c.local_address, 0))
        self.sock.setblocking(False)
        self.sock.sendto(rdt_request(), (c.address, c.port))

    def tare(self) -> None:
        """Wait (startup_timeout s at most) for the first record and `tare_samples` more, and
        take their mean as the bias."""
        c = self.config
        want = max(1, c.tare_samples)
        deadline = time.monotonic() + c.startup_timeout
        samples, asked = [], time.monotonic()
        while len(samples) < want:
            if self.poll(keep=samples) == 0:
                now = time.monotonic()
                if now > deadline:
                    raise ForceSensorError(
                        f"the handle's force sensor ({self.describe()}) sent "
                        f"{len(samples)} of the {want} records the start needs within "
                        f"{self.field}.startup_timeout = {c.startup_timeout:g} s; is it "
                        f"powered, at this address, with RDT on port {c.port}?")
                if now - asked > 0.25 and not samples:  # a request lost on the way: again
                    self.sock.sendto(rdt_request(), (c.address, c.port))
                    asked = now
                time.sleep(0.001)
            if self.status & RDT_STATUS_ERROR:
                raise ForceSensorError(self.status_problem())
        self.scale.tare(samples[:c.tare_samples] if c.tare_samples else [])

    def poll(self, keep=None) -> int:
        """Read every record waiting; the newest is the sample. Returns how many came."""
        n = 0
        while True:
            try:
                data = self.sock.recv(64)
            except (BlockingIOError, InterruptedError):
                return n
            except OSError:  # e.g. ICMP port unreachable on loopback: nothing read
                return n
            record = parse_rdt(data)
            if record is None:
                continue
            seq, _, status, counts = record
            if self.rdt_sequence is not None:
                self.lost += max(0, ((seq - self.rdt_sequence) & 0xFFFFFFFF) - 1)
            self.rdt_sequence, self.status = seq, status
            self.counts = np.asarray(counts, dtype=float)
            self.records += 1
            n += 1
            if keep is not None:
                keep.append(self.counts[:3].copy())

    def force(self) -> np.ndarray:
        return self.scale.force(self.counts)

    def status_problem(self) -> str:
        return (f"the handle's force sensor ({self.describe()}) reports status "
                f"{self.status:#010x} (bit 31: an error; see its web page)")

    def close(self) -> None:
        sock, self.sock = self.sock, None
        if sock is not None:
            try:
                sock.sendto(rdt_request(RDT_STOP), (self.config.address, self.config.port))
            except OSError:  # noqa: S110 - a box gone has nothing to stop
                pass
            sock.close()
