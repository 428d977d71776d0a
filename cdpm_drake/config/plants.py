"""The plant configs of a scenario (its `plant:` field, a tagged union): the simulated
reels, the dynamic plant, and the real reels where the hardware package is installed (over
the UDP reel bridge, or CiA 402 drives over CANopen).

YAML tags are the class names (`plant: !DynamicReels {...}`); an untagged mapping is the
first member, SimulatedReels.
"""

import dataclasses
import typing


@dataclasses.dataclass
class ModelError:
    """How the simulated robot differs from the controller's robot file: seeded Gaussian
    perturbations, one standard deviation each (0: exact). A real robot matches its file to
    millimetres or centimetres (a tape or a laser tracker, swivel pulleys, a homing)."""

    # Each reel exit a_i moved by this, per axis, base frame, m.
    reels_std: float = 0.0
    # Each attachment point b_i moved by this, per axis, platform frame, m.
    attachments_std: float = 0.0
    # Each encoder's zero off by this after the homing, m of cable.
    encoder_offset_std: float = 0.0
    # The cables' stiffness EA and the platform's mass off by this fraction (dynamic plant).
    EA_rel_std: float = 0.0
    mass_rel_std: float = 0.0
    # The platform's centre of mass off its centre by this, per axis, platform frame, m
    # (dynamic plant: under gravity it tilts the platform and shifts the tensions).
    com_std: float = 0.0
    # The seed of the draw; None: the scenario's random_seed.
    seed: typing.Optional[int] = None


@dataclasses.dataclass
class SimulatedReels:
    """Simulated reels: integrate the reel velocity commands to cable lengths at 500 Hz."""

    # First-order lag of the reel drives, s (0: ideal).
    time_constant: float = 0.0
    # Reel speed limit, m/s of cable; None takes the robot file's max_reel_speed.
    max_reel_speed: typing.Optional[float] = None
    # The robot the plant plays, when it is not the controller's: a built-in name or a robot
    # YAML path (the scenario's swaps applied to it too); "" the scenario's robot.
    robot: str = ""
    # Seeded differences from that robot (on top of `robot`).
    model_error: ModelError = dataclasses.field(default_factory=ModelError)
    # Largest residual of the controller's forward kinematics on the encoder lengths, m,
    # above which the run stops (as max_length_residual of the real reels). None: 1 um on the
    # exact plant; with model error, the real reels' default (5 mm plus the stretch of the
    # longest cable at the tension ceiling).
    max_length_residual: typing.Optional[float] = None


@dataclasses.dataclass
class DriveTorqueSensor:
    """The reel drives' force as a tension sensor (DynamicReels.tension_sensor:
    drive_torque): each drive's current, filtered, noisy and quantised, turned into its
    cable's tension with the controller's model of the drive (kernels/drive_torque.py). The
    model is the robot file's reel_drives; the plant's true drives differ from it by the
    errors below."""

    # Current noise, N at the cable (standard deviation per tick).
    noise_std: float = 0.3
    # Current quantisation, N at the cable (0: none).
    quantum: float = 0.02
    # The drive's current filter, a first-order lag, s (0: none).
    filter_time_constant: float = 0.002
    # The true drives' reel inertia and friction (viscous and Coulomb) over the robot file's,
    # less one: 0.2 is 20 % more than the controller's model takes.
    inertia_error: float = 0.2
    friction_error: float = 0.3
    # The model's Coulomb friction is linear in the speed within this band, m/s (a reel at
    # rest sticks with any friction in [-F_c, F_c]: the model takes the middle).
    friction_band: float = 0.002


@dataclasses.dataclass
class LoadCellSensor:
    """A load cell on each cable (DynamicReels.tension_sensor: load_cell)."""

    # Noise, N (standard deviation per tick).
    noise_std: float = 0.2
    # Each cell's offset is drawn once per run (seeded by the scenario's random_seed) with
    # this standard deviation, N.
    bias_std: float = 0.5
    # The cell's bandwidth (first-order), Hz.
    bandwidth: float = 200.0


TENSION_SENSORS = ("drive_torque", "load_cell", "none")
ENCODER_ZEROS = ("homed", "unstretched")


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
    # What the plant tells the controller about the cables' tensions (its tension_measured
    # output, sampled at the control tick): drive_torque (the reel drives' force), load_cell
    # (a cell per cable), none (encoders and the handle's sensor only: NaN).
    tension_sensor: str = "drive_torque"
    # What the encoders read (the cable_lengths output): homed, as a robot's encoders after
    # its homing (the rigid length of each cable at the start pose, the unstretched length
    # plus the start stretch, and each reel's payout from there); unstretched, each reel's
    # payout of unstretched cable (no homing: for tests of the models that take it).
    encoder_zero: str = "homed"
    drive_torque: DriveTorqueSensor = dataclasses.field(default_factory=DriveTorqueSensor)
    load_cell: LoadCellSensor = dataclasses.field(default_factory=LoadCellSensor)
    # The robot the plant plays, when it is not the controller's (as SimulatedReels.robot).
    robot: str = ""
    # Seeded differences from that robot (as SimulatedReels.model_error).
    model_error: ModelError = dataclasses.field(default_factory=ModelError)


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


def check_tension_sensor(plant: DynamicReels) -> None:
    """ValueError naming the field and value of a bad tension sensor setting."""
    import math

    if plant.tension_sensor not in TENSION_SENSORS:
        raise ValueError(f"plant.tension_sensor must be one of {list(TENSION_SENSORS)}, got "
                         f"{plant.tension_sensor!r}")
    for group, fields in (("drive_torque", ("noise_std", "quantum", "filter_time_constant",
                                            "friction_band")),
                          ("load_cell", ("noise_std", "bias_std"))):
        for name in fields:
            value = getattr(getattr(plant, group), name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"plant.{group}.{name} must be a number >= 0, got {value!r}")
    for name in ("inertia_error", "friction_error"):
        value = getattr(plant.drive_torque, name)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > -1):
            raise ValueError(f"plant.drive_torque.{name} must be a number > -1 (the true "
                             f"drive over the model's, less one), got {value!r}")
    value = plant.load_cell.bandwidth
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"plant.load_cell.bandwidth must be a number > 0 Hz, got {value!r}")
