"""The controller's end of the reel link: one non-blocking UDP socket (no Drake here).

It sends commands to the configured bridge address and drains the statuses waiting in the
socket without ever blocking the control loop. Datagrams from any other sender are ignored
and counted. The receive-side sequence state (the last accepted status) is passed in and
returned, so the Drake system can keep it in its context; the link only keeps counters and
its own transmit sequence number (see `send_command`).
"""

import dataclasses
import ipaddress
import select
import socket

import numpy as np

from cdpm_drake.hardware.protocol import (REASONS, VERSIONS, Command, ProtocolError, Status,
                                          check_sequence, decode_status, encode_command,
                                          next_sequence)

# A status burst larger than this in one tick means the loop stalled for a long time; the
# rest stays queued for the next call, so one call stays bounded in time.
MAX_DATAGRAMS_PER_POLL = 256


class LinkError(OSError):
    """The link could not be set up (bad address, port in use)."""


@dataclasses.dataclass
class LinkCounters:
    """What the link saw since it opened. Datagram counts, not bytes."""

    sent: int = 0            # commands handed to the socket
    send_errors: int = 0     # sends the socket refused (buffer full, bridge port closed)
    received: int = 0        # datagrams from the bridge's address, valid or not
    accepted: int = 0        # statuses that passed every check
    foreign: int = 0         # datagrams from any other sender, ignored
    lost: int = 0            # status sequence numbers skipped by accepted statuses
    rejected: dict = dataclasses.field(default_factory=lambda: {r: 0 for r in REASONS})

    def as_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["rejected"] = dict(self.rejected)
        return d


def resolve_ipv4(host: str, field: str) -> str:
    """An IPv4 address in dotted form for `host` ('localhost' resolves); ValueError naming the
    field otherwise."""
    if host == "localhost":
        return "127.0.0.1"
    try:
        return str(ipaddress.IPv4Address(host))
    except (ipaddress.AddressValueError, ValueError):
        raise ValueError(f"{field} must be an IPv4 address such as '127.0.0.1', got "
                         f"{host!r}") from None


class ReelLink:
    """UDP endpoint of the controller.

    num_cables: cables in every datagram. bridge: (address, port) of the reel bridge.
    local: (address, port) to bind; port 0 picks a free one (the bridge answers the sender
    of the latest valid command, so the controller's port need not be fixed).
    """

    def __init__(self, num_cables: int, bridge: tuple[str, int],
                 local: tuple[str, int] = ("127.0.0.1", 0)):
        self.num_cables = int(num_cables)
        self.bridge = (resolve_ipv4(bridge[0], "address"), int(bridge[1]))
        local = (resolve_ipv4(local[0], "local_address"), int(local[1]))
        self.counters = LinkCounters()
        self.last_error = ""        # text of the latest rejection, for fault messages
        # Transmit sequence numbers belong to the socket, like a TCP sequence: every datagram
        # leaving it, whether sent by an event, by shutdown() or after a re-initialisation,
        # must carry a newer number than the one before.
        self._sequence = 0
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.setblocking(False)
            self._sock.bind(local)
        except OSError as e:
            self._sock.close()
            raise LinkError(f"cannot bind the reel link to {local[0]}:{local[1]} "
                            f"(local_address, local_port): {e}") from None

    @property
    def local_address(self) -> tuple[str, int]:
        """(address, port) the socket is bound to."""
        return self._sock.getsockname()

    @property
    def last_sent_sequence(self) -> int:
        return self._sequence

    @property
    def closed(self) -> bool:
        return self._sock.fileno() < 0

    def send_command(self, velocity, enable: bool, echo_sequence: int | None,
                     echo_time: float = 0.0, time: float = 0.0, version: int = 1) -> int:
        """Send one command of protocol `version`; returns its sequence number. Velocities in
        m/s of cable. Never blocks: a full socket buffer counts as a send error."""
        self._sequence = next_sequence(self._sequence)
        data = encode_command(Command(sequence=self._sequence, time=float(time),
                                      velocity=np.asarray(velocity, dtype=float),
                                      enable=bool(enable), echo_sequence=echo_sequence,
                                      echo_time=float(echo_time), version=int(version)))
        try:
            self._sock.sendto(data, self.bridge)
            self.counters.sent += 1
        except OSError:
            # On loopback a closed bridge port comes back as ECONNREFUSED on a later call;
            # the watchdog, not the sender, decides what a silent bridge means.
            self.counters.send_errors += 1
        return self._sequence

    def receive(self, last_sequence: int | None, versions=VERSIONS) -> Status | None:
        """Drain waiting datagrams; the newest valid status of one of `versions` that is newer
        than `last_sequence` (None: accept any), or None if there is none."""
        newest = None
        last = last_sequence
        sock = self._sock
        for _ in range(MAX_DATAGRAMS_PER_POLL):
            try:
                data, sender = sock.recvfrom(4096)
            except BlockingIOError:
                break
            except ConnectionRefusedError:
                # Some systems report an earlier send's ICMP port-unreachable here; Linux does
                # not for unconnected sockets. Either way the watchdog judges the silence.
                continue
            if sender[0] != self.bridge[0] or sender[1] != self.bridge[1]:
                self.counters.foreign += 1
                continue
            self.counters.received += 1
            try:
                status = decode_status(data, self.num_cables, versions)
                gap = check_sequence(status.sequence, last)
            except ProtocolError as e:
                self.counters.rejected[e.reason] += 1
                self.last_error = str(e)
                continue
            self.counters.lost += gap
            self.counters.accepted += 1
            last = status.sequence
            newest = status
        return newest

    def wait(self, timeout: float) -> bool:
        """Block up to `timeout` s until a datagram is waiting (startup only, never in the
        control loop); True if one is."""
        readable, _, _ = select.select([self._sock], [], [], max(0.0, timeout))
        return bool(readable)

    def close(self) -> None:
        self._sock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
