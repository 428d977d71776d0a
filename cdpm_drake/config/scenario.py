"""The scenario schema: the dataclasses yaml_load_typed reads a scenario file into.

A scenario names a robot, the cable swaps, the start, the admittance, the logistic parameters
per cable pair, the limits, the operator, the force sensor and the plant (plants.py). Each
field's comment gives its unit; the defaults run. Loading and checking: load.py, resolve.py.
"""

import dataclasses
import typing

from cdpm_drake.config.plants import PlantConfig, SimulatedReels
from cdpm_drake.kernels.plant.operators import (CsvOperator, NoOperator, ScriptedOperator,
                                                SpringHandOperator)


class ScenarioError(ValueError):
    """A bad scenario; the message names the field and the value and lists valid choices."""


# --- Controller ------------------------------------------------------------------------------


@dataclasses.dataclass
class Admittance:
    """F_d = M x'' + C x' per axis (eq. 5), discretised by zero-order hold."""

    # Virtual mass M, kg.
    mass: float = 6.25
    # Virtual damping C, N s/m.
    damping: float = 6.25


@dataclasses.dataclass
class Logistic:
    """Logistic intensity of the interference force (eqs. 26-28)."""

    # Minimum eligible distance d_l, m: intensity F_u - eps there and below.
    d_l: float = 0.050
    # Maximum eligible distance d_u, m: intensity eps there; no force above.
    d_u: float = 0.061
    # Maximum intensity F_u, N.
    F_u: float = 2.0
    # Allowed variation eps, N.
    eps: float = 0.1
    # Beyond the paper: the hard floor of the distance that the safety filter keeps
    # (safety_filter), m; left out: d_l, the paper's "minimum permissible distance". The
    # paper's force is soft: a hand pushing harder than F_u still takes the pair below d_l;
    # the filter lets the estimated distance go no lower than d_min. At d_l the 2 mm the
    # promise allows (true distance >= d_l - 2 mm) are all left to what the controller cannot
    # see: the estimate's error and the platform's ringing (on the dynamic plant with the full
    # pose the true distance swings up to ~0.8 mm about the estimate under an 8 N push).
    d_min: typing.Optional[float] = None


@dataclasses.dataclass
class PairLogistic:
    """Logistic parameters for one cable pair, overriding the defaults."""

    # The cable pair, 1-based, e.g. [1, 3].
    pair: list[int] = dataclasses.field(default_factory=list)
    # Overrides, m, m, N, N (None keeps the default).
    d_l: typing.Optional[float] = None
    d_u: typing.Optional[float] = None
    F_u: typing.Optional[float] = None
    eps: typing.Optional[float] = None
    d_min: typing.Optional[float] = None


@dataclasses.dataclass
class Interference:
    """The interference-force block (section 4)."""

    # False removes F_int (the controller then is a plain admittance).
    enabled: bool = True
    # Parameters for every watched pair.
    default: Logistic = dataclasses.field(default_factory=Logistic)
    # Per-pair overrides.
    pairs: list[PairLogistic] = dataclasses.field(default_factory=list)
    # Clip of |F_int| (eq. 30), N; None: the largest F_u.
    F_max: typing.Optional[float] = None
    # Beyond the paper: each pair pushes along grad d / max(|grad d|, gradient_floor), so the
    # force fades where translation cannot separate the cables any further (|grad d| -> 0)
    # instead of flipping direction every tick; 0 is the paper's unit gradient. Dimensionless.
    gradient_floor: typing.Optional[float] = None


@dataclasses.dataclass
class Limits:
    """Safety limits after the admittance (Fig. 5); None takes the robot file's value."""

    # Platform speed limit, m/s.
    max_velocity: typing.Optional[float] = None
    # Platform acceleration limit, m/s^2.
    max_acceleration: typing.Optional[float] = None
    # Stop at the workspace box (virtual wall).
    virtual_wall: bool = True


@dataclasses.dataclass
class WallForce:
    """Beyond the paper: a smooth repulsion from the workspace box, added to F_d (section 6)."""

    # Off by default, as in the paper.
    enabled: bool = False
    # Distance from a face at which the force starts, m.
    margin: float = 0.10
    # Force at the face, N; it rises as ((margin - gap) / margin)^2.
    max_force: float = 4.0


@dataclasses.dataclass
class Sensor:
    """The handle's force sensor (Variense FSE103) and the sliding-average filter (section 5)."""

    # Sensing range along the handle axis, N.
    axial_range: float = 100.0
    # Sensing range across the handle axis, N.
    transverse_range: float = 80.0
    # Handle axis in the base frame (normalised on load).
    axial_axis: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 1.0])
    # Sliding-average window, samples of 2 ms (1: no filter).
    filter_window: int = 10
    # Simulated only: standard deviation of the sensor noise per axis, N.
    noise_std: float = 0.0


@dataclasses.dataclass
class TensionDamping:
    """The tension damping block between the Jacobian mapping and the reels: each
    reel pays out cable in proportion to its measured tension's high-passed part, a damper in
    series with its cable. Its gain and filter come from the robot's stiffness and mass and
    the loop's delays (kernels/tension_damping.damping_gains), not from this file."""

    # Off: the mapping's command goes to the reels unchanged.
    enabled: bool = True
    # The derived gain times this (1: the derivation's; a margin test raises it until the
    # tensions diverge).
    gain_scale: float = 1.0


@dataclasses.dataclass
class Controller:
    """Beyond the paper's Fig. 5: how the controller drives the reels."""

    # Gain K_l of the cable-length loop in the Jacobian velocity mapping, 1/s: the reels get
    # l_dot = J v + K_l (l_d - l), l_d the lengths of the commanded position, l the measured
    # ones, so the drives' velocity error and stiction do not integrate into length drift
    # (on a robot with 70 kN cables 1 mm of drift is ~26 N of tension). 0 is the paper's open
    # loop; on the kinematic plant's ideal reels l == l_d and the loop changes nothing. At
    # most 1 / time_step (the loop would overshoot within a tick). 40 1/s: on the dynamic
    # plant's exp2, the full pose's largest tilt 0.40 deg at 20, 0.31 at 30, 0.26 at 40; the
    # translating controller's 0.51, 0.50, 0.49 (a quarter of the drives' 100 rad/s loop:
    # well damped with their lag).
    length_gain: float = 40.0
    # Make up the reel drives' dead band in the length loop: a drive holds still under a
    # command slower than coulomb_friction / (bandwidth x inertia) (robot file reel_drives),
    # so the loop adds 90 % of that speed, smoothly, where its length error asks for motion.
    # Measured on exp2 with the dynamic plant: slack ticks 104 -> 0, largest tilt 0.95 ->
    # 0.51 deg. Not on the kinematic plant (its reels have no friction), nor with
    # length_gain 0.
    friction_compensation: bool = True
    # What the forward kinematics estimates: "translation" (the paper's Fig. 5: a level
    # platform, position only) or "full" (position and orientation from m >= 6 lengths; the
    # interference distances, the Jacobian and the commanded lengths then use the attachment
    # points p + R b_i, and an angular-velocity command holds the start's orientation).
    pose: str = "translation"
    # Gain of the orientation hold (pose: full), 1/s: w = K_R log(R_held R^T).
    orientation_gain: float = 10.0
    # Tension control (needs pose: full): every tick a target tension distribution at the
    # estimated pose for the platform's weight (robot file: platform.mass), the measured hand
    # force at the handle and the commanded acceleration, and commanded lengths = rigid lengths
    # - the target's stretch (robot file: cables.EA), tracked by the length loop.
    tension_control: bool = False
    # Floor of the target distribution, N: every cable at least this taut where the pose
    # and the ceiling allow; where they allow less, the floor is lowered to what they allow
    # (never below tension_floor).
    min_tension: float = 10.0
    # Ceiling of the target distribution, N: where raising the weakest cable to min_tension
    # would take an internal force that pulls another cable above this, the floor is lowered
    # instead (a cable whose share of the internal force is small can cost hundreds of N).
    max_tension: float = 100.0
    # The hard floor of every cable's tension, N: no cable is ever commanded below it. Where
    # the ceiling allows no more, the ceiling gives way (a cable above max_tension, logged as
    # tension_status 3); where the pose itself allows no more (t* < tension_floor), the weak
    # cables are raised to it (status 4); the safety filter keeps the platform where the
    # cables can hold it (safety_filter.kinetostatic_floor), so the second never lasts.
    # 4 N: on the dynamic plant the true tensions ring around their target at the platform's
    # lightly damped modes, which the encoders do not see: ~1 N at rest (README, "Full pose
    # and tension control"), more with a hand pushing against a barrier; 1 N above the
    # kinetostatic barrier's floor (3 N), since where the pose allows less than this floor
    # under the ceiling the ceiling gives way, steeply where the distributions form a thin
    # sliver (cube_8cable pushed at 10 N along its swapped pair: 5 N asked 368 N of cable 8
    # against a 100 N ceiling, the stretch slackened cable 6 and the run faulted; 49 slack
    # ticks at 5 N, 7 at 3-4 N; scripts/bench/adversarial_benchmark.py). 0 < tension_floor <=
    # min_tension.
    tension_floor: float = 4.0
    # Damp the cables' ringing through the reels with the plant's measured tensions
    # (systems/tension_damping.py; a plant without a tension sensor: nothing changes).
    tension_damping: TensionDamping = dataclasses.field(default_factory=TensionDamping)


# --- The promise made hard (beyond the paper) ---------------------------------------------


@dataclasses.dataclass
class KinetostaticForce:
    """The felt cue of the kinetostatic limit, beside F_int: a logistic force (the paper's
    eqs. 26-28 in tensions) along the gradient of the kinetostatic margin, added to F_d. Its
    argument t_c is the largest minimum cable tension the pose allows under
    controller.max_tension with the platform's weight and the measured hand force (t*
    where the ceiling does not bind); the safety filter stops the platform where t_c reaches
    safety_filter.kinetostatic_floor (plus its margin for the hand's force)."""

    # Off keeps the barrier (the safety filter) without the cue.
    enabled: bool = True
    # t_c at which the cue is F_u - eps, N (and stronger below): half a newton above the
    # default safety_filter.kinetostatic_floor, where the filter stops an unpushed platform.
    t_l: float = 3.5
    # t_c at which it is eps, N; none above (as the paper's force is none above d_u). 5 N:
    # paper_7cable's ceiling keeps t_c at 5.4 N at experiment 1's start and 3.2 N along
    # experiment 2's path (its hand included), so the cue is felt where the limit is near
    # (Fig. 12 (a)) and nowhere in experiment 1, which the paper ran without a hand.
    t_u: float = 5.0
    # Largest intensity, N; the allowed variation eps, N (eq. 28).
    F_u: float = 3.0
    eps: float = 0.1


@dataclasses.dataclass
class SafetyFilter:
    """Beyond the paper: a block between the limits and the Jacobian mapping that commands,
    every tick, the twist closest to the admittance's (weighted least squares) that keeps
    every watched cable pair at or above its d_min, the platform in its workspace box, and its
    weight and the measured hand force holdable with every cable between kinetostatic_floor
    and controller.max_tension; within the speed and acceleration limits (discrete-time
    control barrier functions, safety_filter.py). Off: the paper's Fig. 5 exactly."""

    enabled: bool = True
    # Per tick, a barrier may lose at most this fraction of its margin (h(x + T u) >=
    # (1 - gamma) h(x)); also capped by braking at the acceleration limit. In (0, 1].
    gamma: float = 0.2
    # Where a margin is already lost (a start inside d_min, a hand force that changed), the
    # platform is brought back at most this fast, m/s.
    return_speed: float = 0.02
    # The time constant, s, with which the position the barriers are evaluated at follows
    # the estimated one; in between it advances by the filter's own commands (where they put
    # the platform). The estimate rings with the platform (the dynamic plant: micrometres at
    # ~15 Hz), and a pair's distance changes ~0.05 m per m of platform travel near exp2's
    # boundary: barriers at the estimate turned that ringing into centimetres per second of
    # command and rang the cables (exp2, full pose: one cable down to 0.04 N against 2.3 N
    # without the filter). 0: the estimate itself.
    position_smoothing: float = 0.1
    # The kinetostatic barrier (and its block): off leaves the pairs and the box.
    kinetostatic: bool = True
    # The floor of the kinetostatic barrier, N: the platform stays where a distribution with
    # every cable between this (plus 0.1 N per newton of measured hand force: the tensions
    # ring more under a harder hand) and controller.max_tension holds its weight and the hand.
    # Below controller.tension_floor, which the tension target keeps anyway (letting the
    # ceiling give way near the barrier): at 5 N the barrier would sit at experiment 1's
    # start, where paper_7cable's cables can have at most 5.4 N under a 100 N ceiling.
    kinetostatic_floor: float = 3.0
    kinetostatic_force: KinetostaticForce = dataclasses.field(
        default_factory=KinetostaticForce)


@dataclasses.dataclass
class ModelMonitor:
    """Beyond the paper: from the measurements alone, a slack cable, lengths that no longer
    fit the estimated pose, or a hand force the cables cannot hold, lasting `ticks` ticks,
    stop the run with zero reel velocity and a fault naming the cable and the reason
    (model_monitor.py), in simulation and on the robot alike."""

    enabled: bool = True
    # A cable whose tension estimate (full pose with tension control) is below -this is
    # slack, N.
    slack_tension: float = 2.0
    # Without a tension estimate: a cable longer than the estimated pose explains by more
    # than this is slack, m.
    slack_length: float = 0.003
    # A cable length this far from the estimated pose (after the modelled stretch), m.
    fit_tolerance: float = 0.01
    # t* (the largest minimum tension the cables can have at the estimated pose with the
    # platform's weight and the measured hand force) below -this, N: no tension
    # distribution holds the platform against that hand.
    unholdable: float = 0.0
    # How long a condition must last to be a fault, ticks (5 x 2 ms: within 20 ms of its
    # start, with the tick the estimate needs).
    ticks: int = 5
    # Where t* is at least this, N, the cables can hold the hand: a slack cable there is a
    # knock the controller takes up again (a hand that hits the platform with 40 N at once
    # slackens a cable for ~10-40 ms whatever the controller does: the cables' stretch, not
    # their lengths, gives first), and must last slack_ticks to be a fault.
    holdable: float = 2.0
    # How long a slack cable must last to be a fault where t* >= holdable, ticks.
    slack_ticks: int = 25
    # With tension control, where the plant measures a cable's tension (plant
    # tension_sensor: drive_torque, load_cell; the real reels' drive torque), the cable is
    # slack when its measured tension is below this, N, whatever the estimate from the
    # lengths says (it cannot see a cable ringing slack); 0 reads no measured tensions. 1 N:
    # three times the drive-torque sensor's noise (0.3 N) above a slack cable's zero, and
    # below the target's hard floor (controller.tension_floor).
    measured_slack: float = 1.0


OperatorConfig = typing.Union[NoOperator, ScriptedOperator, CsvOperator, SpringHandOperator]


# --- The scenario ----------------------------------------------------------------------------


@dataclasses.dataclass
class Scenario:
    # A short identifier, used in logs and file names.
    name: str = "unnamed"
    # What the run shows.
    description: str = ""
    # Which controller runs: "promise" (the default), the paper's Fig. 5 with the safety filter
    # that keeps every cable pair at or above d_min whatever the hand does (safety_filter:,
    # with its kinetostatic force); "paper", the paper's method exactly: Fig. 5 without the
    # filter, the logistic interference force alone keeping the pairs apart (it overrides
    # safety_filter.enabled). The model monitor only watches and stays as configured.
    method: str = "promise"
    # A built-in robot's name or a path to a robot YAML (relative to the scenario file).
    robot: str = "paper_7cable"
    # Cable pairs whose platform attachment points are swapped, 1-based (the paper swaps
    # [1, 3] and [5, 7] to provoke interference).
    swaps: list[list[int]] = dataclasses.field(default_factory=list)
    # Platform start p, base frame, m; left out (null): the centre of the robot's workspace
    # box, whichever robot the scenario names (resolve_scenario fills it in).
    initial_position: typing.Optional[list[float]] = None
    # Simulated time, s.
    duration: float = 10.0
    # Control period, s (500 Hz in the paper).
    time_step: float = 0.002
    admittance: Admittance = dataclasses.field(default_factory=Admittance)
    interference: Interference = dataclasses.field(default_factory=Interference)
    limits: Limits = dataclasses.field(default_factory=Limits)
    wall_force: WallForce = dataclasses.field(default_factory=WallForce)
    controller: Controller = dataclasses.field(default_factory=Controller)
    safety_filter: SafetyFilter = dataclasses.field(default_factory=SafetyFilter)
    model_monitor: ModelMonitor = dataclasses.field(default_factory=ModelMonitor)
    # The person at the handle (simulation and the emulator; on the robot, a real person).
    operator: OperatorConfig = dataclasses.field(default_factory=NoOperator)
    sensor: Sensor = dataclasses.field(default_factory=Sensor)
    # The reel plant: `!SimulatedReels {...}`, `!DynamicReels {...}`, `!HardwareReels {...}`
    # (the UDP reel bridge) or `!CanopenReels {...}` (CiA 402 drives, hardware/CANOPEN.md).
    plant: PlantConfig = dataclasses.field(default_factory=SimulatedReels)
    # Seed of every random number generator (sensor noise), for repeatable runs.
    random_seed: int = 0
    # The directory relative paths resolve against; the loader sets it to the scenario
    # file's directory. Internal: not written by scenario_to_yaml, not compared (a loaded
    # scenario's paths are absolute already).
    base_dir: str = dataclasses.field(default="", compare=False)
