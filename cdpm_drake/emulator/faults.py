"""The emulator's fault plan: how it impairs the link (drop, delay, duplicate, reorder,
corrupt) or breaks the bridge (freeze, NaN, stop, fault bits), from `after` seconds after the
controller first enables the reels."""

import dataclasses
import math


@dataclasses.dataclass(frozen=True)
class FaultPlan:
    """What the emulator breaks, from `after` seconds after the first enabling command."""

    # Share of datagrams dropped, in each direction, 0..1.
    drop: float = 0.0
    # Extra latency of every status, s.
    delay: float = 0.0
    # Share of statuses sent twice, 0..1.
    duplicate: float = 0.0
    # Share of statuses held back and sent after the next one, 0..1.
    reorder: float = 0.0
    # Share of statuses with one byte flipped after the CRC was computed, 0..1.
    corrupt: float = 0.0
    # Resend the last status unchanged, forever (a hung bridge task).
    freeze: bool = False
    # Report cable 1's length as NaN, in otherwise valid datagrams.
    nan: bool = False
    # Send nothing more (a crashed bridge); commands are still read and recorded.
    stop: bool = False
    # Fault bits to raise (protocol.FAULT_*); the reels stop.
    fault_bits: int = 0
    # Delay from the first command with enable set to the start of the faults above, s.
    after: float = 0.0

    def __post_init__(self):
        for name in ("drop", "duplicate", "reorder", "corrupt"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value <= 1.0):
                raise ValueError(f"{name} must be a share in [0, 1], got {value!r}")
        for name in ("delay", "after"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0 s, got {value!r}")
        if not (isinstance(self.fault_bits, int) and 0 <= self.fault_bits < 1 << 32):
            raise ValueError(f"fault_bits must be a 32-bit unsigned integer, got "
                             f"{self.fault_bits!r}")

    @property
    def any(self) -> bool:
        return self != FaultPlan(after=self.after)


    def describe(self) -> str:
        """The plan's active settings, e.g. 'stop, drop 0.01'."""
        parts = []
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "after" or value == f.default:
                continue
            parts.append(f.name if value is True else
                         f"{f.name} {value:#06x}" if f.name == "fault_bits" else
                         f"{f.name} {value:g}")
        return ", ".join(parts) or "none"
