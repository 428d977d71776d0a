"""The plant configs of a scenario (its `plant:` field, a tagged union): the simulated
reels, the dynamic plant, and the real reels where the hardware package is installed (over
the UDP reel bridge, or CiA 402 drives over CANopen).

YAML tags are the class names (`plant: !DynamicReels {...}`); an untagged mapping is the
first member, SimulatedReels.
"""

import dataclasses
import typing


@dataclasses.dataclass
class SimulatedReels:
    """Simulated reels: integrate the reel velocity commands to cable lengths at 500 Hz."""

    # First-order lag of the reel drives, s (0: ideal).
    time_constant: float = 0.0
    # Reel speed limit, m/s of cable; None takes the robot file's max_reel_speed.
    max_reel_speed: typing.Optional[float] = None


@dataclasses.dataclass
class DynamicReels:
    """A dynamic plant (systems/dynamic_plant.py): the platform as a rigid body on elastic,
    tension-only cables paid out by reel drives with friction. Mass, inertia, cable and drive
    parameters come from the robot file (platform:, cables:, reel_drives:)."""

    # Time step of the discrete MultibodyPlant and the reel drives, s; must divide the
    # control period (1 ms: two steps per 2 ms tick; the default cables allow up to ~4 ms).
    time_step: float = 0.001
    # Floor of the start tension distribution, N: every cable at least this taut at t = 0.
    min_tension: float = 5.0
    # The platform's start orientation [roll, pitch, yaw], rad; the start position is the
    # scenario's initial_position. A robot whose cables cannot hold the platform level at the
    # start pose needs a tilt (the refusal says which one would do).
    initial_rpy: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 0.0])
    # True holds the platform at its start orientation (three prismatic joints take the
    # cables' moments): the translation-only model of the paper and of !SimulatedReels, for
    # comparing with it. False: the platform rotates freely, as the real one does.
    lock_rotation: bool = False
    # Reel speed limit, m/s of cable; None takes the robot file's max_reel_speed.
    max_reel_speed: typing.Optional[float] = None
    # Largest residual of the controller's forward kinematics on the encoder lengths, m: the
    # cables stretch and the platform rotates, so the lengths never fit a translating rigid
    # platform exactly. Above it the controller stops the run, as on the robot.
    max_length_residual: float = 0.02


def _plant_types():
    try:
        from cdpm_drake.hardware.config import HardwareReels
    except ImportError:  # the hardware package is optional for pure simulation
        return (SimulatedReels, DynamicReels)
    try:
        from cdpm_drake.hardware.canopen_config import CanopenReels
    except ImportError:  # pragma: no cover - shipped with the hardware package
        return (SimulatedReels, HardwareReels, DynamicReels)
    return (SimulatedReels, HardwareReels, DynamicReels, CanopenReels)


PLANT_TYPES = _plant_types()
PlantConfig = typing.Union[PLANT_TYPES] if len(PLANT_TYPES) > 1 else SimulatedReels
