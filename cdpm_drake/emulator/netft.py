"""An ATI Net F/T played on a UDP socket (its RDT protocol, hardware/INTERFACE.md): the
handle's force sensor of `force_sensor: !NetFT {...}`, for either emulator.

A request (8 bytes, big-endian: header 0x1234, command, sample count) with command 2 starts
high-speed real-time streaming to its sender (sample count 0: until stopped, else that many
records), command 0 stops it. After each step of the plant behind the emulator (the bridge's
`step`, wrapped here: no change to the emulators' loops) one record goes to the streaming
client: RDT sequence, F/T sequence, status 0, and the plant's hand force in the sensor's axes
(`axes`) times `counts_per_force`, plus the sensor's own bias (`bias`, N in its axes: what
the controller's tare must remove); torques 0.
"""

import socket
import struct
import threading

import numpy as np

RDT_HEADER = 0x1234
RDT_REQUEST = struct.Struct(">HHI")
RDT_RECORD = struct.Struct(">III6i")


class NetFTServer:
    """The sensor box on `address` (host, port; port 0 picks a free one: see `.address`)
    in front of `bridge` (ReelBridge or DynamicBridge: its force() is the hand's)."""

    def __init__(self, bridge, address=("127.0.0.1", 49152), counts_per_force=1_000_000.0,
                 axes=("+x", "+y", "+z"), bias=(0.0, 0.0, 0.0), log=None, hand=None):
        self.bridge = bridge
        # The hand force it measures, N, base frame: the bridge's, unless `hand()` says.
        self.hand = bridge.force if hand is None else hand
        self.counts_per_force = float(counts_per_force)
        self.axes = list(axes)
        self.bias = np.asarray(bias, dtype=float)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(address)
        self.sock.settimeout(0.05)
        self.address = self.sock.getsockname()
        self.client = None     # where the records go, while streaming
        self.remaining = 0     # records still asked for (0: until stopped)
        self.rdt_sequence = 0
        self.records_sent = 0
        self.silent = False    # a fault to rehearse: the box stops sending
        self._log = log
        self._stop = threading.Event()
        self._thread = None
        self._lock = threading.Lock()
        step = bridge.step

        def stepped(dt):
            step(dt)
            self.publish()

        bridge.step = stepped  # one record per plant step, in the emulator's own loop

    def start(self) -> "NetFTServer":
        self._thread = threading.Thread(target=self._serve, name="netft", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)
        self.sock.close()

    def counts(self) -> list[int]:
        """Fx, Fy, Fz, Tx, Ty, Tz counts now: the hand force (base frame) in the sensor's
        axes, plus its bias, times counts_per_force."""
        f = np.asarray(self.hand(), dtype=float)
        out = []
        for i, name in enumerate(self.axes):  # sensor axis i measures base axis `name`
            value = (1.0 if name[0] == "+" else -1.0) * f["xyz".index(name[1])]
            out.append(int(round((value + self.bias[i]) * self.counts_per_force)))
        return out + [0, 0, 0]

    def publish(self) -> None:
        with self._lock:
            client = self.client
            if client is None or self.silent:
                return
            self.rdt_sequence += 1
            record = RDT_RECORD.pack(self.rdt_sequence & 0xFFFFFFFF,
                                     self.rdt_sequence & 0xFFFFFFFF, 0, *self.counts())
            if self.remaining:
                self.remaining -= 1
                if not self.remaining:
                    self.client = None
        try:
            self.sock.sendto(record, client)
            self.records_sent += 1
        except OSError:  # noqa: S110 - a client gone: UDP drops it, as the box would
            pass

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                data, sender = self.sock.recvfrom(64)
            except (socket.timeout, OSError):
                continue
            if len(data) != RDT_REQUEST.size:
                continue
            header, command, samples = RDT_REQUEST.unpack(data)
            if header != RDT_HEADER:
                continue
            with self._lock:
                if command == 2:
                    self.client, self.remaining = sender, samples
                elif command == 0:
                    self.client = None
            if self._log is not None and command == 2:
                self._log(f"Net F/T: streaming to {sender[0]}:{sender[1]}")
