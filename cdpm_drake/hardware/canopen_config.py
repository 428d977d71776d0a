"""`!CanopenReels`: the scenario's plant entry for CiA 402 servo drives on a CANopen bus, and
the bus-load budget of its PDO mapping (hardware/CANOPEN.md).

No `from __future__ import annotations` here: pydrake's yaml_load_typed reads these
annotations as types, not strings.
"""

import dataclasses
import math
import typing

from cdpm_drake.hardware.force_config import CanopenForceSensor, NetFT, check_force_sensor

# python-can interfaces that take no bitrate argument (socketcan's is set with `ip link`; the
# software buses have none).
NO_BITRATE_INTERFACES = ("socketcan", "virtual", "udp_multicast")
# Largest share of the control period the cyclic frames may fill.
MAX_BUS_LOAD = 0.90
TENSION_SENSORS = ("drive_torque", "none")

# The PDO mapping written at start-up: (index, bits) of each mapped object.
RPDO_OBJECTS = ((0x6040, 16), (0x60FF, 32))                 # controlword, target velocity
TPDO_OBJECTS = ((0x6041, 16), (0x6064, 32), (0x6077, 16))   # statusword, position, torque
TPDO2_OBJECTS = ((0x606C, 32),)                               # velocity actual
# Where the controller takes each reel's speed from (CanopenReels.reel_speed).
REEL_SPEEDS = ("auto", "velocity_actual", "position")


@dataclasses.dataclass
class CanopenReels:
    """CiA 402 drives (one per cable) in cyclic synchronous velocity mode on one CAN bus."""

    # python-can interface: socketcan on a robot; virtual or udp_multicast to rehearse.
    interface: str = "socketcan"
    # python-can channel: can0; a virtual bus's name; udp_multicast's group address.
    channel: str = "can0"
    # Bit rate of the bus, bit/s (the bus-load check uses it; socketcan's is set by ip link).
    bitrate: int = 1_000_000
    # CANopen node id (1..127) of each cable's drive, cable 1 first; empty: 1..m.
    node_ids: list[int] = dataclasses.field(default_factory=list)
    # Position actual (0x6064) counts per metre of cable paid out (negative: the drive counts
    # the other way).
    counts_per_metre: float = 1_000_000.0
    # Cable length at position count 0, m, per cable (set by the homing); empty: all 0.
    position_offset: list[float] = dataclasses.field(default_factory=list)
    # Target velocity (0x60FF) units per m/s of cable paid out; None: counts_per_metre
    # (counts/s). Negative: the drive turns the other way for a positive target.
    velocity_units_per_mps: typing.Optional[float] = None
    # Drive force at the cable (N, + pays out) per unit of torque actual (0x6077, per mille
    # of rated torque): rated motor torque / 1000 x gear ratio / drum radius. Negative: the
    # drive's positive torque winds the cable in.
    force_per_torque_unit: float = 0.1
    # tension_measured from the drives' torque (kernels/drive_torque) or none (NaN).
    tension_sensor: str = "drive_torque"
    # Each reel's speed (for the drive-torque tension's friction and inertia): velocity_actual
    # (0x606C, in the units of velocity_units_per_mps, mapped into TPDO2 at start-up: a
    # drive that refuses the mapping stops the start, a bus without room for it is refused),
    # position (differences of position actual over the SYNC period), or auto: velocity
    # actual where the bus has room for TPDO2 and the drive accepts its mapping, position
    # differences elsewhere (the log says which).
    reel_speed: str = "auto"
    # The handle's force sensor, the admittance's input: a node on this bus
    # (!CanopenForceSensor {node_id: ...}) or a Net F/T on the network (!NetFT {address:
    # ...}). None: the drives carry no force sensor, and the run refuses to enable.
    force_sensor: typing.Optional[typing.Union[CanopenForceSensor, NetFT]] = None
    # Control ticks without a TPDO from a drive after which every drive is stopped (and as
    # many control periods less one of wall time). 2: a TPDO a tick late is waited for, a
    # drive silent for two SYNCs is stopped (quick stop with the third SYNC of its silence,
    # disabled with the fourth); 1 would stop the run on every late TPDO.
    missed_tpdo_ticks: int = 2
    # Rehearsal only, against `cdpm emulate --canopen --lockstep` (`cdpm run --lockstep` sets
    # it): each tick waits for every drive's TPDO answering its SYNC (up to startup_timeout s
    # of wall clock) instead of keeping time, and the watchdogs (missed TPDOs, heartbeat)
    # count ticks, not seconds; the run is then deterministic on any host.
    lockstep: bool = False
    # Heartbeat producer time written to each drive (0x1017), s; 0: no heartbeat watch.
    heartbeat_period: float = 0.1
    # A drive whose heartbeat is older than this is lost, s (wall clock).
    heartbeat_timeout: float = 0.35
    # Longest wait for all drives' configuration and first TPDO, s.
    startup_timeout: float = 2.0
    # Longest wait for each drive to reach Operation enabled, s.
    enable_timeout: float = 1.0
    # True: a drive found in Fault at start-up is sent a fault reset (controlword bit 7);
    # False (default): the run refuses to start. A fault during the run always ends it.
    fault_reset: bool = False
    # A drive commanded at least this fast, m/s of cable (the same sign for frozen_ticks + 10
    # ticks), whose position actual in `frozen_ticks` TPDOs in a row equals that of the one
    # before (or in as many as 3 counts take at this speed, if more) has a frozen encoder.
    # Above the drives' dead band (the robot file's reel_drives: 5 mm/s), where a reel may
    # stick without a fault.
    frozen_speed: float = 0.01
    # TPDOs in a row with the position of the one before that make a frozen encoder (with
    # frozen_speed). 1: at 10 mm/s and 1 um counts a TPDO should have moved 20 counts; each
    # one more waits a tick longer.
    frozen_ticks: int = 1
    # Time for the commanded reel velocity to ramp from 0 to full after enabling, s.
    ramp_time: float = 0.5
    # Largest forward-kinematics residual accepted for the measured lengths, m; None (the
    # default): derived from the robot's cables, as HardwareReels.max_length_residual.
    max_length_residual: typing.Optional[float] = None
    # The tensions the homing leaves the cables at, as the controller takes them where the
    # drives measure none at start-up (as HardwareReels.homing_min_tension), N.
    homing_min_tension: float = 5.0


def resolved_node_ids(config: CanopenReels, m: int) -> list[int]:
    return list(config.node_ids) if config.node_ids else list(range(1, m + 1))


def resolved_offsets(config: CanopenReels, m: int) -> list[float]:
    return [float(x) for x in config.position_offset] if config.position_offset else [0.0] * m


def velocity_units(config: CanopenReels) -> float:
    v = config.velocity_units_per_mps
    return float(config.counts_per_metre if v is None else v)


def check_canopen_reels(config: CanopenReels, m: int, period: float,
                        field: str = "plant") -> dict:
    """Raise ValueError naming the field and value for an unusable setting, or for a bus
    the cyclic frames would overload; returns the bus load (bus_load) of `m` drives at the
    control `period` (s)."""
    if not isinstance(config, CanopenReels):
        raise ValueError(f"{field} must be a CanopenReels, got {type(config).__name__}")
    for name in ("interface", "channel"):
        value = getattr(config, name)
        if not isinstance(value, str) or not value:
            raise ValueError(f"{field}.{name} must be a non-empty string, got {value!r}")
    _int_in(config.bitrate, 10_000, 1_000_000, f"{field}.bitrate", "bit/s of classic CAN")
    ids = resolved_node_ids(config, m)
    if len(ids) != m:
        raise ValueError(f"{field}.node_ids must have one node id per cable ({m}), got "
                         f"{list(config.node_ids)!r}")
    for k, i in enumerate(ids):
        _int_in(i, 1, 127, f"{field}.node_ids[{k}] (cable {k + 1})", "a CANopen node id")
    if len(set(ids)) != m:
        raise ValueError(f"{field}.node_ids must be distinct, got {ids!r}")
    offsets = resolved_offsets(config, m)
    if len(offsets) != m or not all(math.isfinite(x) for x in offsets):
        raise ValueError(f"{field}.position_offset must have {m} finite lengths in m (one "
                         f"per cable), got {list(config.position_offset)!r}")
    value = config.homing_min_tension
    if not _finite(value) or value < 0:
        raise ValueError(f"{field}.homing_min_tension must be a finite number >= 0 N, got "
                         f"{value!r}")
    for name, unit in (("counts_per_metre", "counts/m"), ("force_per_torque_unit", "N"),
                       ("velocity_units_per_mps", "units per m/s")):
        value = getattr(config, name)
        if value is None and name == "velocity_units_per_mps":
            continue
        if not _finite(value) or value == 0:
            raise ValueError(f"{field}.{name} must be a finite non-zero number ({unit}), "
                             f"got {value!r}")
    if not isinstance(config.lockstep, bool):
        raise ValueError(f"{field}.lockstep must be true or false, got {config.lockstep!r}")
    if config.reel_speed not in REEL_SPEEDS:
        raise ValueError(f"{field}.reel_speed must be one of {', '.join(REEL_SPEEDS)}, got "
                         f"{config.reel_speed!r}")
    if config.tension_sensor not in TENSION_SENSORS:
        raise ValueError(f"{field}.tension_sensor must be one of {', '.join(TENSION_SENSORS)}"
                         f", got {config.tension_sensor!r}")
    _int_in(config.missed_tpdo_ticks, 1, 1000, f"{field}.missed_tpdo_ticks", "control ticks")
    _int_in(config.frozen_ticks, 1, 1000, f"{field}.frozen_ticks", "control ticks")
    if not isinstance(config.fault_reset, bool):
        raise ValueError(f"{field}.fault_reset must be true or false, got "
                         f"{config.fault_reset!r}")
    for name, positive in (("heartbeat_period", False), ("heartbeat_timeout", True),
                           ("startup_timeout", True), ("enable_timeout", True),
                           ("frozen_speed", True), ("ramp_time", False),
                           ("max_length_residual", True)):
        value = getattr(config, name)
        if name == "max_length_residual" and value is None:  # derived from the robot
            continue
        if not _finite(value) or (value <= 0 if positive else value < 0):
            raise ValueError(f"{field}.{name} must be a finite number "
                             f"{'> 0' if positive else '>= 0'} s, got {value!r}")
    if config.heartbeat_period > 65.535:
        raise ValueError(f"{field}.heartbeat_period must be at most 65.535 s (0x1017 holds "
                         f"ms in 16 bits), got {config.heartbeat_period!r}")
    if config.heartbeat_period and config.heartbeat_timeout <= config.heartbeat_period:
        raise ValueError(f"{field}.heartbeat_timeout must exceed heartbeat_period "
                         f"({config.heartbeat_period:g} s), got {config.heartbeat_timeout!r}")
    if config.force_sensor is not None:
        check_force_sensor(config.force_sensor, f"{field}.force_sensor", ids)
    sensors = int(isinstance(config.force_sensor, CanopenForceSensor))
    velocity = config.reel_speed == "velocity_actual"
    load = bus_load(m, config.bitrate, period, config.heartbeat_period, sensors, velocity)
    if load["load"] > MAX_BUS_LOAD:
        per_bus = max_drives(config.bitrate, period, config.heartbeat_period, sensors,
                             velocity)
        raise ValueError(
            f"{field}: {m} drives at {config.bitrate} bit/s with a {period * 1e3:g} ms cycle "
            f"need {load['bits']:.0f} bits per cycle ({m} RPDOs of {load['rpdo_bits']} bits, "
            f"{m} TPDOs of {load['tpdo_bits']} bits, "
            + (f"{m} TPDO2s (reel_speed: velocity_actual) of {load['tpdo2_bits']} bits, "
               if velocity else "")
            + (f"the force sensor's TPDO of {load['tpdo_bits']} bits, " if sensors else "")
            + f"a SYNC of {load['sync_bits']} bits, "
            f"heartbeats {load['heartbeat_bits']:.1f} bits), {100 * load['load']:.1f} % of "
            f"the {load['capacity']:.0f} bits the cycle holds: more than "
            f"{100 * MAX_BUS_LOAD:.0f} % (worst case with bit stuffing "
            f"{100 * load['worst_load']:.1f} %). One bus carries at most {per_bus} drives "
            f"here: split the drives onto a second channel (a second CAN interface, e.g. can1, "
            f"with its own `cdpm run`-side bus), raise the bit rate, or lengthen time_step"
            + (", or take the reel speed from positions (reel_speed: position or auto)"
               if velocity else ""))
    return load


def velocity_fits(config: CanopenReels, m: int, period: float) -> bool:
    """Whether TPDO2 (velocity actual) of every drive fits the bus with the rest within
    MAX_BUS_LOAD (reel_speed: auto maps it only then)."""
    sensors = int(isinstance(config.force_sensor, CanopenForceSensor))
    return bus_load(m, config.bitrate, period, config.heartbeat_period, sensors,
                    True)["load"] <= MAX_BUS_LOAD


def frame_bits(data_bytes: int) -> tuple[int, int]:
    """(nominal, worst-case) bits on the wire of a classic CAN frame with an 11-bit id and
    `data_bytes` of data, with the 3-bit interframe space: SOF, id, RTR, IDE, r0, DLC, data
    and CRC (34 + 8 n bits, the stuffed part), CRC and ACK delimiters, ACK, EOF, IFS (13);
    bit stuffing adds at most one bit per 4 after the first of the stuffed part."""
    stuffed = 34 + 8 * data_bytes
    return stuffed + 13, stuffed + 13 + (stuffed - 1) // 4


def bus_load(m: int, bitrate: int, period: float, heartbeat_period: float,
             sensors: int = 0, velocity: bool = False) -> dict:
    """Bits per control cycle of m drives (each an RPDO of 6 bytes and a TPDO of 8 bytes per
    cycle, with `velocity` a TPDO2 of 4 bytes too, a heartbeat of 1 byte per
    heartbeat_period), `sensors` force sensor nodes (a TPDO of 8 bytes each) and one SYNC,
    as a share `load` of
    what the bus carries in `period` s at `bitrate` bit/s, without bit stuffing (what
    bus-load tools report); `worst_load` with the most stuffing a frame can have."""
    rpdo, rpdo_worst = frame_bits(sum(b for _, b in RPDO_OBJECTS) // 8)
    tpdo, tpdo_worst = frame_bits(sum(b for _, b in TPDO_OBJECTS) // 8)
    tpdo2, tpdo2_worst = frame_bits(sum(b for _, b in TPDO2_OBJECTS) // 8)
    if not velocity:
        tpdo2 = tpdo2_worst = 0
    sync, sync_worst = frame_bits(0)
    hb, hb_worst = frame_bits(1)
    share = period / heartbeat_period if heartbeat_period > 0 else 0.0
    bits = m * (rpdo + tpdo + tpdo2 + share * hb) + sync + sensors * tpdo
    worst = (m * (rpdo_worst + tpdo_worst + tpdo2_worst + share * hb_worst) + sync_worst
             + sensors * tpdo_worst)
    capacity = bitrate * period
    return dict(bits=bits, worst_bits=worst, capacity=capacity, load=bits / capacity,
                worst_load=worst / capacity, rpdo_bits=rpdo, tpdo_bits=tpdo, tpdo2_bits=tpdo2,
                sync_bits=sync,
                heartbeat_bits=m * share * hb)


def max_drives(bitrate: int, period: float, heartbeat_period: float, sensors: int = 0,
               velocity: bool = False) -> int:
    """The most drives one bus carries within MAX_BUS_LOAD."""
    n = 0
    while bus_load(n + 1, bitrate, period, heartbeat_period, sensors,
                   velocity)["load"] <= MAX_BUS_LOAD:
        n += 1
    return n


def _finite(value) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def _int_in(value, lo, hi, field, what):
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{field} must be an integer in {lo}..{hi} ({what}), got {value!r}")
