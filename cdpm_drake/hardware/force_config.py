"""The handle's force sensor on the robot: the plant configs' `force_sensor` field (a tagged
union), one block of its own as in the paper's Fig. 5. Three kinds (hardware/INTERFACE.md):

* `!BridgeForce {}`: the force in the reel bridge's status (hardware/PROTOCOL.md), the
  `!HardwareReels` default;
* `!CanopenForceSensor {node_id, ...}`: a force-torque node on the drives' CAN bus, sending
  its forces in a TPDO on every SYNC (hardware/CANOPEN.md, "The handle's force sensor");
* `!NetFT {address, ...}`: an ATI Net F/T (or any box speaking its RDT protocol) streaming
  over UDP.

The sensor's readings are in its own axes and counts; `axes` says which base-frame axis each
sensor axis measures (`["-y", "+x", "+z"]`: the sensor's x along the base frame's -y, ...).
At start-up, with the handle left alone, the mean of `tare_samples` samples is taken as the
sensor's bias and subtracted from every later one (the tare).

No `from __future__ import annotations` here: pydrake's yaml_load_typed reads these
annotations as types, not strings.
"""

import dataclasses
import math
import typing

import numpy as np

from cdpm_drake.hardware.link import resolve_ipv4

AXIS_NAMES = ("+x", "+y", "+z", "-x", "-y", "-z")
# ATI's default RDT port on a Net F/T.
NETFT_PORT = 49152


@dataclasses.dataclass
class BridgeForce:
    """The force in the reel bridge's status, base frame, N (hardware/PROTOCOL.md): the
    bridge reads and scales its own sensor."""


@dataclasses.dataclass
class CanopenForceSensor:
    """A force-torque sensor node on the CAN bus of `!CanopenReels`: its TPDO (COB-ID 0x180 +
    node_id, synchronous: one per SYNC) carries Fx, Fy, Fz as signed 16-bit counts and,
    in 8-byte frames, a 16-bit status word (non-zero: the sensor reports an error)."""

    # CANopen node id (1..127), distinct from the drives'.
    node_id: int = 20
    # Counts per newton of the TPDO's forces (negative: the sensor counts the other way).
    counts_per_newton: float = 100.0
    # The base-frame axis each sensor axis (x, y, z) measures, with its sign.
    axes: list[str] = dataclasses.field(default_factory=lambda: ["+x", "+y", "+z"])
    # Samples averaged at start-up (the handle left alone) as the sensor's bias, subtracted
    # from every later sample; 0: no tare.
    tare_samples: int = 50
    # Control ticks without a new sample after which the run stops (and as many control
    # periods less one of wall time); None: the drives' missed_tpdo_ticks.
    missed_ticks: typing.Optional[int] = None


@dataclasses.dataclass
class NetFT:
    """An ATI Net F/T streaming its samples over UDP (RDT: a request of 8 bytes, header
    0x1234, command 2 starts high-speed real-time streaming; each record 36 bytes
    big-endian: RDT sequence, F/T sequence, status, Fx, Fy, Fz, Tx, Ty, Tz as int32)."""

    # IPv4 address of the sensor box.
    address: str = "192.168.1.1"
    # Its RDT UDP port.
    port: int = NETFT_PORT
    # Address the controller's socket binds to (0.0.0.0: any).
    local_address: str = "0.0.0.0"
    # Counts per newton of the records' forces: the box's "counts per force" (its
    # configuration page; 1000000 on many calibrations).
    counts_per_force: float = 1_000_000.0
    # The base-frame axis each sensor axis (x, y, z) measures, with its sign.
    axes: list[str] = dataclasses.field(default_factory=lambda: ["+x", "+y", "+z"])
    # Samples averaged at start-up (the handle left alone) as the sensor's bias; 0: no tare.
    tare_samples: int = 50
    # Longest wait for the first records at start-up (and the tare's), s.
    startup_timeout: float = 2.0
    # Control ticks without a new record after which the run stops.
    missed_ticks: int = 3


def force_source_problem(plant_config) -> str:
    """Why a hardware plant config gives the admittance no force source ('' if it does): a
    `force_sensor` that is None (the CiA 402 drives carry no handle sensor of their own)."""
    if getattr(plant_config, "force_sensor", "absent") is not None:
        return ""
    return ("refusing to enable the drives: the admittance has no force source: "
            "plant.force_sensor is not set and CiA 402 drives carry no handle force sensor. "
            "Configure the handle's sensor: plant.force_sensor: !CanopenForceSensor {node_id: "
            "..., counts_per_newton: ..., axes: [...]} (a node on this bus) or !NetFT "
            "{address: ..., counts_per_force: ...}")


def axes_matrix(axes, field: str = "force_sensor.axes") -> np.ndarray:
    """R with F_base = R @ F_sensor for `axes` (each sensor axis's base axis and sign);
    ValueError naming the field unless it is a permutation of x, y, z with signs."""
    if not isinstance(axes, (list, tuple)) or len(axes) != 3:
        raise ValueError(f"{field} must list 3 axes (the base axis of the sensor's x, y, z), "
                         f"got {axes!r}")
    R = np.zeros((3, 3))
    for i, name in enumerate(axes):
        if name not in AXIS_NAMES:
            raise ValueError(f"{field}[{i}] must be one of {list(AXIS_NAMES)}, got {name!r}")
        R["xyz".index(name[1]), i] = 1.0 if name[0] == "+" else -1.0
    if sorted(a[1] for a in axes) != ["x", "y", "z"]:
        raise ValueError(f"{field} must name each of x, y, z once, got {list(axes)!r}")
    return R


def check_force_sensor(sensor, field: str = "plant.force_sensor", drive_ids=()) -> None:
    """ValueError naming the field and value of an unusable sensor setting."""
    if isinstance(sensor, BridgeForce):
        return
    if isinstance(sensor, CanopenForceSensor):
        _int_in(sensor.node_id, 1, 127, f"{field}.node_id", "a CANopen node id")
        if sensor.node_id in drive_ids:
            raise ValueError(f"{field}.node_id {sensor.node_id} is also a drive's node id "
                             f"({list(drive_ids)}); give the sensor a node id of its own")
        _factor(sensor.counts_per_newton, f"{field}.counts_per_newton", "counts/N")
    elif isinstance(sensor, NetFT):
        resolve_ipv4(sensor.address, f"{field}.address")
        if sensor.local_address != "0.0.0.0":
            resolve_ipv4(sensor.local_address, f"{field}.local_address")
        _int_in(sensor.port, 1, 65535, f"{field}.port", "a UDP port")
        _factor(sensor.counts_per_force, f"{field}.counts_per_force", "counts/N")
        t = sensor.startup_timeout
        if not (_finite(t) and t > 0):
            raise ValueError(f"{field}.startup_timeout must be a finite number > 0 s, got "
                             f"{t!r}")
    else:
        raise ValueError(f"{field} must be !BridgeForce, !CanopenForceSensor or !NetFT, got "
                         f"{type(sensor).__name__}")
    axes_matrix(sensor.axes, f"{field}.axes")
    _int_in(sensor.tare_samples, 0, 10_000, f"{field}.tare_samples", "samples")
    if sensor.missed_ticks is not None:  # None: the drives' missed_tpdo_ticks
        _int_in(sensor.missed_ticks, 1, 1000, f"{field}.missed_ticks", "control ticks")


def _factor(value, field, unit):
    if not _finite(value) or value == 0:
        raise ValueError(f"{field} must be a finite non-zero number ({unit}; negative: the "
                         f"sensor counts the other way), got {value!r}")


def _finite(value) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def _int_in(value, lo, hi, field, what):
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{field} must be an integer in {lo}..{hi} ({what}), got {value!r}")
