"""The robot file's YAML schema: mutable dataclasses, as yaml_load_typed requires. Each
field's comment gives its unit and frame; the defaults of the dynamic-plant sections say
where each estimate comes from. Loading and checking a file: file.py."""

import dataclasses


@dataclasses.dataclass
class WorkspaceSchema:
    # Lower corner of the axis-aligned virtual-wall box, base frame, m.
    lower: list[float] = dataclasses.field(default_factory=list)
    # Upper corner of the box, base frame, m.
    upper: list[float] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class LimitsSchema:
    # Largest platform speed the controller commands, m/s.
    max_velocity: float = 0.5
    # Largest platform acceleration the controller commands, m/s^2.
    max_acceleration: float = 2.0
    # Largest reel (cable) speed the drives accept, m/s of cable.
    max_reel_speed: float = 1.0


# Dynamic-plant sections (optional; only `plant: !DynamicReels` reads them). The defaults are
# for the paper's robot, whose paper gives none of these numbers: each is an estimate for a
# robot of its class, with where it comes from.
_CUBE = 0.30  # m: the attachment points span a 0.3 m cube (hardware/robots/paper_7cable.yaml)


@dataclasses.dataclass
class PlatformSchema:
    # Platform mass, kg. Estimate: a 0.3 m cube frame of 20 mm aluminium profile (12 edges x
    # 0.3 m x ~0.4 kg/m = 1.5 kg) plus the FSE103 sensor, handle and seven tension limiters
    # (~1 kg) near the centre.
    mass: float = 2.5
    # Rotational inertia about the platform centre, platform frame, kg m^2 (3 x 3, symmetric).
    # Estimate: the 1.5 kg frame as 12 thin edges of a 0.3 m cube, 7/18 m_f s^2 per axis
    # (0.0525); the 1 kg at the centre adds nothing.
    inertia: list[list[float]] = dataclasses.field(default_factory=lambda: [
        [0.0525, 0.0, 0.0], [0.0, 0.0525, 0.0], [0.0, 0.0, 0.0525]])
    # The handle point, where the operator's force acts, platform frame, m. Assumed: under
    # the sensor, at the centre of the cube's bottom face.
    handle: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, -0.15])


@dataclasses.dataclass
class CablesSchema:
    # Axial stiffness E A of every cable, N (k_i = EA / L0_i). The robot file's 1.5 mm
    # polyethylene (UHMWPE) braid: area 1.77e-6 m^2 times an effective braid modulus of
    # ~40 GPa (fibre 100 GPa; a braid's is 30-50 GPa) = 70 kN.
    EA: float = 70000.0
    # Viscous damping of each cable's stretch rate, N s/m. Chosen for ~5% of critical damping
    # of the platform's translation on 7 cables of k ~ 28 kN/m (2.5 m long) with 2.5 kg:
    # 0.05 * 2 sqrt(7/3 * 28e3 * 2.5) / (7/3) = 17 N s/m, rounded to 20.
    damping: float = 20.0


@dataclasses.dataclass
class ReelDrivesSchema:
    # Closed-loop bandwidth of each reel's velocity loop, rad/s (first order: time constant
    # 1/bandwidth). 100 rad/s (10 ms) is a typical servo drive's velocity loop (500 Hz command
    # rate); the emulator's default lag is of the same order.
    bandwidth: float = 100.0
    # Reel, gearbox and motor inertia seen at the cable, kg (J / r^2: ~1e-4 kg m^2 reflected
    # through the drum of r = 0.02 m); it turns the loop's bandwidth into a gain K = bandwidth
    # * inertia (N per m/s) that friction acts against.
    inertia: float = 0.25
    # Viscous friction at the cable, N s/m: 1% of the loop gain.
    viscous_friction: float = 0.25
    # Coulomb friction at the cable, N (drum bearings, cable guide). The paper calls the reels'
    # friction considerable; 0.125 N against K = 25 N s/m is a dead band of 5 mm/s.
    coulomb_friction: float = 0.125


@dataclasses.dataclass
class CalibrationSchema:
    """What `cdpm calibrate` wrote: where the geometry came from and how well the data knew
    it. The uncertainties widen the controller's margins (docs/calibration.md)."""

    # The logs the fit read, and when it ran (UTC, ISO 8601).
    calibrated_from: list[str] = dataclasses.field(default_factory=list)
    created: str = ""
    # The file the fit started from.
    original: str = ""
    # Poses fitted, and one encoder reading's noise the fit assumed, m.
    poses: int = 0
    encoder_std: float = 0.0
    # One standard deviation of each reel exit and attachment point, per axis, m (row i:
    # cable i+1); empty: not stated.
    reels_std: list[list[float]] = dataclasses.field(default_factory=list)
    attachments_std: list[list[float]] = dataclasses.field(default_factory=list)
    # The same relative to the frame the homing pose and the file's orientation define (a
    # translating platform's lengths cannot see a turn of that whole frame): how well the
    # cables are known relative to each other, which is what their distances depend on and
    # what the margins use. Empty: as above.
    reels_std_in_frame: list[list[float]] = dataclasses.field(default_factory=list)
    attachments_std_in_frame: list[list[float]] = dataclasses.field(default_factory=list)
    # Each encoder's offset found (reading minus the unstretched length at the homing), m,
    # and its standard deviation, m (the first run's).
    encoder_offsets: list[float] = dataclasses.field(default_factory=list)
    encoder_offsets_std: list[float] = dataclasses.field(default_factory=list)
    # RMS of each cable's misfit before and after the fit, m.
    residual_before: list[float] = dataclasses.field(default_factory=list)
    residual_after: list[float] = dataclasses.field(default_factory=list)
    # The parameters the data did not identify (their standard deviation above the bound).
    not_identified: list[str] = dataclasses.field(default_factory=list)
    # The externally measured poses that fixed the base frame ("": none; the homing pose and,
    # for a translating platform, the file's turn fixed it).
    measured_poses: str = ""


@dataclasses.dataclass
class RobotSchema:
    # A short identifier, e.g. paper_7cable.
    name: str = ""
    # a_i: cable exit points at the reels, base frame, m; row i is cable i+1.
    reels: list[list[float]] = dataclasses.field(default_factory=list)
    # b_i: attachment points on the platform, platform frame (origin at its centre), m.
    attachments: list[list[float]] = dataclasses.field(default_factory=list)
    # The virtual wall: an axis-aligned box for the platform centre p, base frame, m.
    workspace: WorkspaceSchema = dataclasses.field(default_factory=WorkspaceSchema)
    # Cable diameter, m (informative: documents the margin that d_l must cover).
    cable_diameter: float = 0.0
    # Controller limits; defaults documented in LimitsSchema.
    limits: LimitsSchema = dataclasses.field(default_factory=LimitsSchema)
    # Cable pairs [i, j] (1-based) that the interference block must skip, e.g. cables that
    # leave one reel exit point and so can never separate.
    ignore_pairs: list[list[int]] = dataclasses.field(default_factory=list)
    # Dynamic-plant sections (plant: !DynamicReels); defaults documented in each schema.
    platform: PlatformSchema = dataclasses.field(default_factory=PlatformSchema)
    cables: CablesSchema = dataclasses.field(default_factory=CablesSchema)
    reel_drives: ReelDrivesSchema = dataclasses.field(default_factory=ReelDrivesSchema)
    # Written by `cdpm calibrate`; absent in a file measured by hand.
    calibration: CalibrationSchema = dataclasses.field(default_factory=CalibrationSchema)


REQUIRED_FIELDS = ("name", "reels", "attachments", "workspace")
