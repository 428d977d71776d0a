"""A scripted reel link: HardwareReelsSystem's watchdog without sockets or real time.

`ScriptedLink` plays `ReelLink` (the same methods and counters) for one HardwareReelsSystem.
Each `receive()` after start-up is one control tick: the clock, patched into
`cdpm_drake.hardware.reels.time` by `install`, advances one period, and `script(tick, link)`
says which statuses the bridge delivered since the previous tick, as a list of
`(skipped, echo, faults)`: `skipped` sequence numbers lost before this status, `echo` the
command sequence it echoes (`link.sequence` is the newest command sent), `faults` its fault
bits. The simulator then runs as fast as it can, and what the watchdog sees is exactly the
script: no timing, no host load.
"""

import numpy as np

from cdpm_drake.hardware import reels as reels_module
from cdpm_drake.hardware.link import LinkCounters
from cdpm_drake.hardware.protocol import Status, check_sequence


class ScriptedLink:
    def __init__(self, lengths, script, period: float = 0.002):
        self.lengths = np.array(lengths, dtype=float)
        self.script = script
        self.period = period
        self.counters = LinkCounters()
        self.last_error = ""
        self.closed = False
        self.sequence = 0          # the newest command's sequence
        self.tick = 0              # receive() calls since start-up: the update's tick
        self.now = 1000.0          # the patched time.monotonic(), s
        self.sent = []             # (tick, sequence, enable, velocity) of every command
        self._status_sequence = 0

    @property
    def last_sent_sequence(self) -> int:
        return self.sequence

    def monotonic(self) -> float:
        return self.now

    def send_command(self, velocity, enable, echo_sequence, echo_time=0.0, time=0.0,
                     version=1) -> int:
        self.sequence += 1
        self.counters.sent += 1
        self.sent.append((self.tick, self.sequence, bool(enable),
                          np.array(velocity, dtype=float)))
        return self.sequence

    def wait(self, timeout) -> bool:
        return True

    def receive(self, last, versions=(1, 2)):
        if last is None:  # start-up: the bridge answers the greeting at once
            return self._status(0, self.sequence, 0, None)
        self.tick += 1
        self.now += self.period
        newest = None
        for skipped, echo, faults in self.script(self.tick, self):
            newest = self._status(skipped, echo, faults, last if newest is None
                                  else newest.sequence)
        return newest

    def _status(self, skipped, echo, faults, last):
        self._status_sequence += 1 + skipped
        status = Status(sequence=self._status_sequence, time=self.now, lengths=self.lengths,
                        force=np.zeros(3), faults=faults, enabled=True, echo_sequence=echo)
        self.counters.received += 1
        self.counters.lost += check_sequence(status.sequence, last)
        self.counters.accepted += 1
        return status

    def close(self) -> None:
        self.closed = True

    # --- what the bridge read ---------------------------------------------------------------

    def commands_at(self, tick) -> list:
        return [c for c in self.sent if c[0] == tick]


def install(monkeypatch, reels, link) -> None:
    """Give `reels` (a HardwareReelsSystem) the scripted link and its clock."""
    monkeypatch.setattr(reels_module, "time", link)
    reels._link = link


def answering(tick, link):
    """The healthy bridge: one status per tick, echoing the newest command."""
    return [(0, link.sequence, 0)]
