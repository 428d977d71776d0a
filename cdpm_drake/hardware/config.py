"""`!HardwareReels`: the scenario's plant entry for the real reels (or the emulator).

No `from __future__ import annotations` here: pydrake's yaml_load_typed reads these
annotations as types, not strings.
"""

import dataclasses
import math
import typing

from cdpm_drake.hardware.link import resolve_ipv4

# The bridge's UDP port when nothing else is configured (unassigned by IANA).
DEFAULT_BRIDGE_PORT = 47100
# Longest wait for a stopped bridge to answer before the fault latches, s.
MAX_RESUME_WITHIN = 1.0
# What `tension_measured` is made from (hardware/PROTOCOL.md, "Controller behaviour").
TENSION_SENSORS = ("drive_torque", "load_cell", "none")


@dataclasses.dataclass
class HardwareReels:
    """The reel bridge on the network, and the controller's safety settings for it."""

    # IPv4 address of the reel bridge (or cdpm-reel-emulator).
    address: str = "127.0.0.1"
    # UDP port of the reel bridge.
    port: int = DEFAULT_BRIDGE_PORT
    # IPv4 address the controller's socket binds to; loopback unless the bridge is remote.
    local_address: str = "127.0.0.1"
    # UDP port the controller binds to; 0 picks a free one (the bridge answers the sender
    # of the latest valid command).
    local_port: int = 0
    # Control ticks without a valid status after which the watchdog stops the reels (zero
    # velocity, enable off, at once).
    watchdog_ticks: int = 3
    # After the watchdog stopped the reels, how long the bridge has to answer, s (wall
    # clock): a valid status that echoes the stop, with no status lost since the silence
    # began, re-enables the reels (ramping from rest, as at start-up) and the run goes on;
    # otherwise the fault latches and the run ends. It rides out a bridge that was paused
    # rather than broken, e.g. a host that holds a virtual CPU for ~10 ms (see
    # scripts/bench/soak_realtime.py). 0: latch at once.
    resume_within: float = 0.015
    # Longest wait for the bridge's first status at startup, s (wall clock).
    startup_timeout: float = 2.0
    # Time for the commanded reel velocity to ramp from 0 to full after enabling, s.
    ramp_time: float = 0.5
    # Largest forward-kinematics residual accepted for the measured lengths, m: above it at
    # the start the lengths do not fit the robot file and the reels are not enabled, and in
    # the run the controller stops. None (the default): derived from the robot's cables, 5 mm
    # (the encoders' zero, the geometry's errors) plus the stretch controller.max_tension gives
    # the longest cable in the workspace box, which the translating, inextensible model sees
    # as misfit (robot.stretch.derived_length_residual; docs/on_the_robot.md gives exp2's).
    max_length_residual: typing.Optional[float] = None
    # Copies of the final zero-velocity, enable-off command sent by shutdown() (UDP may
    # drop one; the bridge ignores the repeats' identical content).
    shutdown_repeats: int = 3
    # Where the `tension_measured` output (N per cable) comes from, with a version-2 bridge:
    # drive_torque, each reel drive's force at the cable through the reel's equation of motion
    # with the robot file's reel_drives (inertia, friction); load_cell, the bridge's load
    # cells; none, no tension sensor (NaN, as with a version-1 bridge).
    tension_sensor: str = "drive_torque"


def check_hardware_reels(config: HardwareReels, field: str = "plant") -> None:
    """Raise ValueError naming the field and the value for any unusable setting."""
    if not isinstance(config, HardwareReels):
        raise ValueError(f"{field} must be a HardwareReels, got {type(config).__name__}")
    resolve_ipv4(config.address, f"{field}.address")
    resolve_ipv4(config.local_address, f"{field}.local_address")
    _int_in(config.port, 1, 65535, f"{field}.port", "a UDP port")
    _int_in(config.local_port, 0, 65535, f"{field}.local_port", "a UDP port (0: any free one)")
    _int_in(config.watchdog_ticks, 1, 1000, f"{field}.watchdog_ticks", "control ticks")
    _int_in(config.shutdown_repeats, 1, 100, f"{field}.shutdown_repeats", "datagrams")
    _number(config.startup_timeout, f"{field}.startup_timeout", "s", positive=True)
    _number(config.resume_within, f"{field}.resume_within", "s", positive=False)
    if config.resume_within > MAX_RESUME_WITHIN:
        raise ValueError(f"{field}.resume_within must be at most {MAX_RESUME_WITHIN:g} s (a "
                         f"bridge silent longer is broken, not paused), got "
                         f"{config.resume_within!r}")
    _number(config.ramp_time, f"{field}.ramp_time", "s", positive=False)
    if config.max_length_residual is not None:  # None: derived from the robot
        _number(config.max_length_residual, f"{field}.max_length_residual", "m", positive=True)
    if config.tension_sensor not in TENSION_SENSORS:
        raise ValueError(f"{field}.tension_sensor must be one of "
                         f"{', '.join(TENSION_SENSORS)}, got {config.tension_sensor!r}")


def _int_in(value, lo, hi, field, what):
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{field} must be an integer in {lo}..{hi} ({what}), got {value!r}")


def _number(value, field, unit, positive):
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or (value <= 0 if positive else value < 0):
        bound = "> 0" if positive else ">= 0"
        raise ValueError(f"{field} must be a finite number {bound} {unit}, got {value!r}")
