"""The typed scenario: everything one run needs, loaded from YAML with yaml_load_typed.

A scenario names a robot, the cable swaps, the start, the admittance, the logistic parameters
per cable pair, the limits, the operator, the force sensor and the plant (simulated reels or the
real ones). Shipped scenarios live in `cdpm_drake/data/scenarios/` and resolve by name from any
directory; `--scenario-text` overlays a YAML snippet for one-off changes.
"""

import dataclasses
import logging
import math
import typing
from pathlib import Path

import numpy as np

from cdpm_drake.kernels.plant.operators import (CsvOperator, NoOperator, OperatorError, ScriptedOperator,
                        SpringHandOperator, OPERATOR_TYPES, make_operator)
from cdpm_drake.robot import Robot, RobotError, load_robot, resolve_named_yaml, robot_statics

from cdpm_drake.data import SCENARIOS_DIR  # noqa: E402

_log = logging.getLogger(__name__)


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


# --- Plants ----------------------------------------------------------------------------------


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
    return (SimulatedReels, HardwareReels, DynamicReels)


_PLANTS = _plant_types()
PlantConfig = typing.Union[_PLANTS] if len(_PLANTS) > 1 else SimulatedReels
OperatorConfig = typing.Union[NoOperator, ScriptedOperator, CsvOperator, SpringHandOperator]


# --- The scenario ----------------------------------------------------------------------------


@dataclasses.dataclass
class Scenario:
    # A short identifier, used in logs and file names.
    name: str = "unnamed"
    # What the run shows.
    description: str = ""
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
    # The reel plant: `!SimulatedReels {...}`, `!DynamicReels {...}` or `!HardwareReels {...}`.
    plant: PlantConfig = dataclasses.field(default_factory=SimulatedReels)
    # Seed of every random number generator (sensor noise), for repeatable runs.
    random_seed: int = 0
    # The directory relative paths resolve against; the loader sets it to the scenario
    # file's directory. Internal: not written by scenario_to_yaml, not compared (a loaded
    # scenario's paths are absolute already).
    base_dir: str = dataclasses.field(default="", compare=False)


def scenario_names() -> list[str]:
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.yaml"))


def resolve_scenario_path(name_or_path) -> Path:
    return resolve_named_yaml(name_or_path, SCENARIOS_DIR, "scenario", ScenarioError)


def load_scenario(name_or_path="exp2_interaction", overlay_text: str | None = None) -> Scenario:
    """Load a scenario by name or path, apply a YAML overlay, and check it."""
    return load_resolved_scenario(name_or_path, overlay_text).scenario


def load_resolved_scenario(name_or_path="exp2_interaction",
                           overlay_text: str | None = None) -> "ResolvedScenario":
    """`load_scenario`, returning the check's `resolve_scenario` result, so that a caller that
    goes on to build and run it resolves it only once."""
    from pydrake.common.yaml import yaml_load, yaml_load_typed

    path = resolve_scenario_path(name_or_path)
    _check_yaml_text(f"{path}", filename=str(path))
    try:
        scenario = yaml_load_typed(schema=Scenario, filename=str(path))
    except Exception as e:
        raise ScenarioError(f"{path}: {explain_load_error(e)}") from None
    # Every path resolves against the file it appears in, so a scenario means the same from
    # every directory; an overlay's, typed on the command line, against the current one.
    source = f"--scenario-text {overlay_text!r}"
    raw = {}
    if overlay_text:
        _check_yaml_text(source, data=overlay_text)
        raw = yaml_load(data=overlay_text) or {}
    _resolve_paths(scenario, path.parent.resolve(), f"scenario {str(path)!r}",
                   "the scenario file's folder", robot="robot" not in raw,
                   operator="operator" not in raw)
    if overlay_text:
        try:
            scenario = yaml_load_typed(schema=Scenario, data=overlay_text, defaults=scenario)
        except Exception as e:
            raise ScenarioError(f"{source}: {explain_load_error(e)}") from None
        _resolve_paths(scenario, Path.cwd(), source, "the current directory for an overlay",
                       robot="robot" in raw, operator="operator" in raw)
    # Absolute, so the resolved scenario written beside a log (which records base_dir) finds
    # the same robot and CSV files when loaded back from elsewhere.
    scenario.base_dir = str((path.parent / scenario.base_dir).resolve())
    resolved = resolve_scenario(scenario, source=str(path))
    if resolved.interference is not None:
        warn_unreachable_d_u(resolved.robot, resolved.interference)
    warn_reel_saturation(scenario, resolved.robot)
    _warn_sensor_range(resolved)
    return resolved


def sensor_range_text(sensor: Sensor) -> str:
    """"axial 100 N, transverse 80 N": the sensor's range, for messages."""
    return f"axial {sensor.axial_range:g} N, transverse {sensor.transverse_range:g} N"


def _warn_sensor_range(resolved) -> None:
    """Once, before a run: a hand force the operator will apply beyond the sensor's range is
    clipped by the sensor model (as the real FSE103 saturates), so the controller never sees
    it. A force table says where; a spring hand, its max_force."""
    from cdpm_drake.kernels.plant.operators import ForceProfile, SpringHand
    from cdpm_drake.kernels.force_sensor import beyond_range

    s = resolved.scenario.sensor
    op = resolved.operator
    if isinstance(op, ForceProfile):
        beyond = beyond_range(op.forces, s.axial_axis, s.axial_range, s.transverse_range)
        if beyond.any():
            k = int(np.argmax(beyond))
            _log.warning("%s: the hand force %s N is beyond the sensor's range (%s): the "
                         "controller sees it clipped (%d of the %d rows are beyond it; the "
                         "summary counts the clipped ticks)", op.rows[k], op.forces[k].tolist(),
                         sensor_range_text(s), int(beyond.sum()), len(beyond))
    elif isinstance(op, SpringHand) and op.F_max > min(s.axial_range, s.transverse_range):
        _log.warning("operator.max_force %g N is above the sensor's range (%s): a larger hand "
                     "force is clipped (the summary counts the clipped ticks)", op.F_max,
                     sensor_range_text(s))


def _resolve_paths(scenario: Scenario, base: Path, source: str, base_what: str, *,
                   robot: bool, operator: bool) -> None:
    """Make the scenario's robot file and CSV operator path absolute, relative to `base`
    (the folder of the file they appear in), with no fallback; a robot name must be a
    built-in one. ScenarioError names the `source` and the full path tried."""
    from cdpm_drake.robot import ROBOTS_DIR, is_path_like, robot_names

    if robot:
        ref = scenario.robot
        if is_path_like(ref):
            full = Path(ref) if Path(ref).is_absolute() else base / ref
            if not full.is_file():
                raise ScenarioError(
                    f"{source}: robot file {ref!r} does not exist: tried {str(full)!r}"
                    + ("" if Path(ref).is_absolute() else
                       f" (relative paths are relative to {base_what})"))
            scenario.robot = str(full)
        elif not (ROBOTS_DIR / f"{ref}.yaml").is_file():
            raise ScenarioError(f"{source}: unknown robot {ref!r}; built-in robots: "
                                f"{robot_names()} (or give a path to a .yaml file)")
    if operator and isinstance(scenario.operator, CsvOperator) and scenario.operator.path:
        ref = scenario.operator.path
        full = Path(ref) if Path(ref).is_absolute() else base / ref
        if not full.is_file():
            raise ScenarioError(
                f"{source}: operator.path {ref!r} does not exist: tried {str(full)!r}"
                + ("" if Path(ref).is_absolute() else
                   f" (relative paths are relative to {base_what})"))
        scenario.operator.path = str(full)


def warn_reel_saturation(scenario, robot):
    """Each reel's speed is |u_i . v| <= |v| (J's rows are unit vectors): a platform speed limit
    above the reel speed limit lets the reels saturate, which slows the motion."""
    v_max = scenario.limits.max_velocity or robot.limits.max_velocity
    reel = getattr(scenario.plant, "max_reel_speed", None) or robot.limits.max_reel_speed
    if v_max > reel:
        # Each value says where it comes from: a left-out field takes the robot file's.
        v_from = ("limits.max_velocity" if scenario.limits.max_velocity else
                  "default: the robot file's limits.max_velocity")
        reel_from = ("plant.max_reel_speed" if getattr(scenario.plant, "max_reel_speed", None)
                     else "default: the robot file's limits.max_reel_speed")
        _log.warning("the platform speed limit %g m/s (%s) is above the reel speed limit %g "
                     "m/s (%s): fast motions will be slowed by the reels", v_max, v_from, reel,
                     reel_from)


def _check_yaml_text(source: str, **where) -> None:
    """Check raw YAML against the Scenario schema before yaml_load_typed, whose messages do not
    say which nested field is wrong (`The fields ['mas'] were unknown to the schema`,
    `could not convert string to float: 'a'`) nor list the valid fields. A file's message
    gives the line of the field."""
    from pydrake.common.yaml import yaml_load

    try:
        raw = yaml_load(**where)
    except Exception as e:
        raise ScenarioError(f"{source}: not valid YAML: {e}") from None
    if raw is None:
        return
    try:
        check_yaml(raw, Scenario, "")
    except ScenarioError as e:
        raise ScenarioError(f"{source}: {with_line(e, where.get('filename'))}") from None


# Fields the loader fills in, not for users to write: accepted, never listed as choices.
INTERNAL_FIELDS = ("base_dir",)


def _field_error(field: str, message: str) -> ScenarioError:
    """A ScenarioError about the YAML field at `field` (e.g. interference.pairs[0].du)."""
    error = ScenarioError(message)
    error.field = field
    return error


def field_keys(field: str) -> list:
    """`interference.pairs[0].du` -> ["interference", "pairs", 0, "du"] (text.yaml_line's
    key path)."""
    import re

    return [int(index) if index else name
            for name, index in re.findall(r"([^.\[\]]+)|\[(\d+)\]", field)]


def with_line(error: Exception, filename=None) -> str:
    """The message of a check_yaml error, prefixed with `line N: ` where the file `filename`
    writes the field it names."""
    from cdpm_drake.text import yaml_line

    field = getattr(error, "field", None)
    line = (yaml_line(field_keys(field), filename=filename)
            if filename is not None and field else None)
    return f"line {line}: {error}" if line is not None else str(error)


def _is_number(v) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, (int, float)):
        return True
    try:  # YAML 1.1 reads `1e3` as a string; Drake's loader takes it as a number
        float(v)
        return isinstance(v, str)
    except (TypeError, ValueError):
        return False


def check_yaml(value, schema, field: str) -> None:
    """Raise ScenarioError naming the field, the value and the valid choices where raw YAML
    data `value` does not fit the type `schema`."""
    from cdpm_drake.text import did_you_mean

    name = field or "the scenario"
    if dataclasses.is_dataclass(schema):
        if not isinstance(value, dict):
            raise _field_error(field, f"{name} must be a mapping, got {value!r}")
        fields = [f.name for f in dataclasses.fields(schema)]
        valid = [f for f in fields if f not in INTERNAL_FIELDS]
        for key, item in value.items():
            if key == "_tag":
                continue
            if key not in fields:
                where = f"{field}.{key}" if field else str(key)
                raise _field_error(where, f"unknown field {where!r}{did_you_mean(key, valid)} "
                                          f"(valid fields{' of ' + field if field else ''}: "
                                          f"{valid})")
        types = typing.get_type_hints(schema)
        for key, item in value.items():
            if key != "_tag":
                check_yaml(item, types[key], f"{field}.{key}" if field else key)
        return
    origin, args = typing.get_origin(schema), typing.get_args(schema)
    if origin is typing.Union:
        if type(None) in args:
            if value is None:
                return
            rest = [a for a in args if a is not type(None)]
            return check_yaml(value, rest[0] if len(rest) == 1 else typing.Union[tuple(rest)],
                               field)
        tags = ["!" + a.__name__ for a in args]
        tag = value.get("_tag") if isinstance(value, dict) else None
        if tag is None:
            try:  # an untagged entry is the first member, as yaml_load_typed reads it
                return check_yaml(value, args[0], field)
            except ScenarioError as e:
                raise _field_error(getattr(e, "field", field),
                                   _untagged_hint(e, value, args, tags, field)) from None
        if tag not in tags:
            raise _field_error(field, f"{field}: unknown type {tag!r}{did_you_mean(tag, tags)} "
                                      f"(valid {field} types: {tags})")
        return check_yaml(value, args[tags.index(tag)], field)
    if origin is list:
        if not isinstance(value, list):
            raise _field_error(field, f"{name} must be a list, got {value!r}")
        for k, item in enumerate(value):
            check_yaml(item, args[0], f"{field}[{k}]")
        return
    if schema is float and not _is_number(value):
        raise _field_error(field, f"{name} must be a number, got {value!r}")
    if schema is int and not (isinstance(value, int) and not isinstance(value, bool)):
        raise _field_error(field, f"{name} must be an integer, got {value!r}")
    if schema is bool and not isinstance(value, bool):
        raise _field_error(field, f"{name} must be true or false, got {value!r}")
    if schema is str and not isinstance(value, str):
        raise _field_error(field, f"{name} must be a string, got {value!r}")


def _untagged_hint(e: ScenarioError, value, args, tags, field: str) -> str:
    """The message for an untagged mapping that does not fit the union's first member: name
    the tag it needs, with the members that have its fields (a scenario whose operator is a
    !SpringHandOperator still needs the tag in an overlay: untagged means the first member)."""
    text = f"{e} (an untagged {field} is {tags[0]}; valid {field} types: {tags})"
    if not isinstance(value, dict) or not value:
        return text
    keys = [k for k in value if k != "_tag"]
    fits = [tag for tag, member in zip(tags, args) if dataclasses.is_dataclass(member)
            and set(keys) <= {f.name for f in dataclasses.fields(member)}]
    if not fits:
        return text
    flow = ", ".join(f"{k}: {_flow_yaml(value[k])}" for k in keys)
    article = "an" if field[:1] in "aeiou" else "a"
    return (f"{e}; a mapping without a tag is read as {tags[0]}, so {article} {field} needs "
            f"its tag, e.g. `{field}: {fits[0]} {{{flow}}}` (types with these fields: "
            f"{fits}; valid {field} types: {tags})")


def _flow_yaml(v) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(_flow_yaml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k}: {_flow_yaml(x)}" for k, x in v.items()) + "}"
    return str(v)


def explain_load_error(e: Exception) -> str:
    msg = str(e)
    if "did not match any of the allowed type options" in msg:
        if "'operator'" in msg:
            msg += f"; valid operators: {['!' + t.__name__ for t in OPERATOR_TYPES]}"
        if "'plant'" in msg:
            msg += f"; valid plants: {['!' + t.__name__ for t in _PLANTS]}"
    return msg


def scenario_robot(scenario: Scenario) -> Robot:
    """The scenario's robot with its cable swaps applied."""
    from cdpm_drake.robot import ROBOTS_DIR, is_path_like

    ref = scenario.robot
    if is_path_like(ref):
        # Loaded scenarios hold absolute paths; one built in code resolves against base_dir.
        if scenario.base_dir and not Path(ref).is_absolute():
            ref = str(Path(scenario.base_dir) / ref)
    elif (ROBOTS_DIR / f"{ref}.yaml").is_file():
        ref = str(ROBOTS_DIR / f"{ref}.yaml")  # a name is a built-in robot, wherever we are
    try:
        robot = load_robot(ref)
    except RobotError as e:
        raise ScenarioError(f"robot: {e}") from None
    for k, swap in enumerate(scenario.swaps):
        if len(swap) != 2:
            raise ScenarioError(f"swaps[{k}] must be two cable numbers [i, j], got {swap!r}")
        try:
            robot = robot.with_swapped_attachments(int(swap[0]), int(swap[1]))
        except RobotError as e:
            raise ScenarioError(f"swaps[{k}] = {swap!r}: {e}") from None
    return robot


def scenario_operator(scenario: Scenario):
    try:
        return make_operator(scenario.operator,
                             Path(scenario.base_dir) if scenario.base_dir else None)
    except OperatorError as e:
        raise ScenarioError(str(e)) from None


def _positive(value, field):
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ScenarioError(f"{field} must be a finite number > 0, got {value!r}")


def interference_params(scenario: Scenario, robot: Robot):
    """Per-pair logistic parameters in the robot's pair order (InterferenceParams)."""
    from cdpm_drake.kernels.interference import InterferenceParams

    P = robot.num_pairs
    cfg = scenario.interference
    arrays = {k: np.full(P, float(getattr(cfg.default, k))) for k in ("d_l", "d_u", "F_u", "eps")}
    for n, override in enumerate(cfg.pairs):
        k = _override_position(n, override, robot)
        for key in arrays:
            value = getattr(override, key)
            if value is not None:
                arrays[key][k] = float(value)
    F_max = float(cfg.F_max) if cfg.F_max is not None else (float(arrays["F_u"].max()) if P else 0.0)
    # Checked here, field by field, so a message names what the user wrote (the default set,
    # or a pair's override) rather than the first pair the default reaches.
    default = {k: f"interference.default.{k}" for k in arrays}
    _check_logistic_set({k: getattr(cfg.default, k) for k in arrays}, default, "")
    for n, override in enumerate(cfg.pairs):
        k = robot.pair_position(int(override.pair[0]), int(override.pair[1]))
        names = {key: (f"interference.pairs[{n}].{key}" if getattr(override, key) is not None
                       else default[key]) for key in arrays}
        _check_logistic_set({key: arrays[key][k] for key in arrays}, names,
                            f" (pair ({override.pair[0]},{override.pair[1]}))")
    try:
        extra = {} if cfg.gradient_floor is None else {"gradient_floor": cfg.gradient_floor}
        return InterferenceParams(F_max=F_max, pairs=tuple(robot.pairs), **arrays, **extra)
    except ValueError as e:
        raise ScenarioError(f"interference: {e}") from None


def _override_position(n: int, override: PairLogistic, robot: Robot) -> int:
    """The position in robot.pairs of interference.pairs[n]'s pair; ScenarioError naming the
    entry where it is not a watched pair of the robot."""
    if len(override.pair) != 2:
        raise ScenarioError(f"interference.pairs[{n}].pair must be two cable numbers "
                            f"[i, j], got {override.pair!r}")
    i, j = override.pair
    try:
        return robot.pair_position(int(i), int(j))
    except (RobotError, TypeError, ValueError):
        raise ScenarioError(
            f"interference.pairs[{n}].pair = {override.pair!r} is not a cable pair of "
            f"robot {robot.name!r}; valid pairs: {robot.pairs}") from None


# d_min where the scenario leaves it out: this far under d_l, m (Logistic.d_min).
D_MIN_BELOW_D_L = 0.0


def pair_d_min(scenario: Scenario, robot: Robot) -> np.ndarray:
    """Each watched pair's hard floor d_min (m, robot.pairs order): the pair's override, else
    the default's, else its d_l - D_MIN_BELOW_D_L (at least 0). Whether or not the
    interference force is on: the safety filter keeps the pairs apart either way.
    ScenarioError naming the field unless 0 <= d_min <= d_l."""
    P = robot.num_pairs
    cfg = scenario.interference
    d_l = np.full(P, float(cfg.default.d_l))
    d_min = np.full(P, math.nan)
    field = ["interference.default.d_min"] * P
    if cfg.default.d_min is not None:
        _finite_number(cfg.default.d_min, "interference.default.d_min")
        d_min[:] = float(cfg.default.d_min)
    for n, override in enumerate(cfg.pairs):
        k = _override_position(n, override, robot)
        if override.d_l is not None:
            d_l[k] = float(override.d_l)
        if override.d_min is not None:
            _finite_number(override.d_min, f"interference.pairs[{n}].d_min")
            d_min[k] = float(override.d_min)
            field[k] = f"interference.pairs[{n}].d_min"
    given = ~np.isnan(d_min)
    for k in np.flatnonzero(given):
        i, j = robot.pairs[k]
        if not 0.0 <= d_min[k] <= d_l[k]:
            raise ScenarioError(
                f"{field[k]} = {d_min[k]!r} m (pair ({i},{j})) must lie in [0, d_l] = "
                f"[0, {d_l[k]!r}] m: the hard floor the safety filter keeps, under the "
                "interference force's d_l")
    d_min[~given] = np.maximum(d_l[~given] - D_MIN_BELOW_D_L, 0.0)
    return d_min


def _finite_number(value, field: str) -> None:
    if not (_is_number(value) and math.isfinite(float(value))):
        raise ScenarioError(f"{field} must be a finite number, got {value!r}")


def _check_safety(scenario: Scenario) -> None:
    """The safety filter's, the kinetostatic cue's, the model monitor's and the tension
    floor's fields; ScenarioError naming the field and the value."""
    c = scenario.controller
    for name in ("tension_floor", "max_tension"):
        _finite_number(getattr(c, name), f"controller.{name}")
    if not 0 < float(c.tension_floor) < float(c.max_tension):
        raise ScenarioError(f"controller.tension_floor must be > 0 N and below "
                            f"controller.max_tension = {c.max_tension!r} N, got "
                            f"{c.tension_floor!r}")
    f = scenario.safety_filter
    _finite_number(f.kinetostatic_floor, "safety_filter.kinetostatic_floor")
    if not 0 < float(f.kinetostatic_floor) < float(c.max_tension):
        raise ScenarioError(f"safety_filter.kinetostatic_floor must be > 0 N and below "
                            f"controller.max_tension = {c.max_tension!r} N, got "
                            f"{f.kinetostatic_floor!r}")
    _finite_number(f.gamma, "safety_filter.gamma")
    if not 0 < float(f.gamma) <= 1:
        raise ScenarioError(f"safety_filter.gamma must lie in (0, 1] (the share of a "
                            f"barrier's margin one tick may use), got {f.gamma!r}")
    _finite_number(f.position_smoothing, "safety_filter.position_smoothing")
    if float(f.position_smoothing) < 0:
        raise ScenarioError(f"safety_filter.position_smoothing must be >= 0 s (0: the "
                            f"estimated position itself), got {f.position_smoothing!r}")
    _finite_number(f.return_speed, "safety_filter.return_speed")
    if float(f.return_speed) < 0:
        raise ScenarioError(f"safety_filter.return_speed must be >= 0 m/s, got "
                            f"{f.return_speed!r}")
    cue = f.kinetostatic_force
    if cue.enabled:
        for name in ("t_l", "t_u", "F_u", "eps"):
            _finite_number(getattr(cue, name), f"safety_filter.kinetostatic_force.{name}")
        if not cue.t_u > cue.t_l:
            raise ScenarioError(f"safety_filter.kinetostatic_force.t_u = {cue.t_u!r} N must "
                                f"be above t_l = {cue.t_l!r} N")
        _positive(cue.F_u, "safety_filter.kinetostatic_force.F_u")
        if not 0 < cue.eps < cue.F_u / 2:
            raise ScenarioError(f"safety_filter.kinetostatic_force.eps = {cue.eps!r} N must "
                                f"lie in (0, F_u/2) = (0, {cue.F_u / 2!r}) N")
    mon = scenario.model_monitor
    _finite_number(mon.holdable, "model_monitor.holdable")
    for name in ("slack_tension", "unholdable"):
        _finite_number(getattr(mon, name), f"model_monitor.{name}")
        if float(getattr(mon, name)) < 0:
            raise ScenarioError(f"model_monitor.{name} must be >= 0 N, got "
                                f"{getattr(mon, name)!r}")
    for name in ("slack_length", "fit_tolerance"):
        _positive(getattr(mon, name), f"model_monitor.{name}")
    for name in ("ticks", "slack_ticks"):
        value = getattr(mon, name)
        if not (isinstance(value, int) and value >= 1):
            raise ScenarioError(f"model_monitor.{name} must be an integer >= 1 tick, got "
                                f"{value!r}")


def _check_logistic_set(values: dict, names: dict, pair: str) -> None:
    """ScenarioError unless d_l, d_u (m), F_u, eps (N) of `values` form a logistic (eqs.
    26-28: 0 <= d_l < d_u, 0 < eps < F_u / 2); the message names each value by `names` (its
    field path), with `pair` after the first."""
    d_l, d_u, F_u, eps = (values[k] for k in ("d_l", "d_u", "F_u", "eps"))
    for key, value in values.items():
        if not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise ScenarioError(f"{names[key]}{pair} must be a finite number, got {value!r}")
    if d_l < 0:
        raise ScenarioError(f"{names['d_l']}{pair} must be >= 0 m, got {float(d_l)!r}")
    if d_u <= d_l:
        raise ScenarioError(f"{names['d_u']} = {float(d_u)!r} m{pair} must be above "
                            f"{names['d_l']} = {float(d_l)!r} m")
    if F_u <= 0:
        raise ScenarioError(f"{names['F_u']}{pair} must be > 0 N, got {float(F_u)!r}")
    if not 0 < eps < F_u / 2:
        raise ScenarioError(f"{names['eps']} = {float(eps)!r} N{pair} must lie in (0, F_u/2) "
                            f"= (0, {float(F_u) / 2!r}) N, F_u being {names['F_u']} = "
                            f"{float(F_u)!r} N")


@dataclasses.dataclass(frozen=True, eq=False)
class ResolvedScenario:
    """A scenario checked and resolved once (`resolve_scenario`): what the builder, the runners
    and the views take, so that none of them goes back to the scenario's fields to derive
    these again. The scenario is kept as given but for the robot's defaults (initial_position)
    filled in."""

    # The scenario with what depends on its robot filled in: a left-out initial_position is
    # the robot's workspace centre.
    scenario: Scenario
    # The robot with the scenario's cable swaps applied.
    robot: Robot
    # Per-pair logistic parameters (interference.InterferenceParams); None when the block is
    # off (interference.enabled false, or a robot without watched pairs).
    interference: typing.Any
    # The person at the handle (an operators model: force(t, p, v) in N).
    operator: typing.Any
    # Safety limits with the robot file's defaults applied: m/s, m/s^2.
    max_velocity: float
    max_acceleration: float
    # Simulated reels' speed limit, m/s of cable (the plant's or the robot file's).
    max_reel_speed: float
    # How far measured lengths may disagree with the geometry, m: the simulated plant keeps
    # them consistent to round-off; real encoders and cable stretch do not.
    fk_max_residual: float
    # The reel drives' dead band the length loop makes up, m/s of cable (robot file
    # reel_drives; 0 without controller.friction_compensation, without the loop, or on the
    # kinematic plant).
    dead_band: float = 0.0
    # Each watched pair's hard floor d_min, m (pair_d_min), robot.pairs order.
    d_min: typing.Any = None
    # The fields the scenario left out whose value came from the robot (for messages).
    defaulted: tuple = ()
    # The contents of the files the scenario reads, as loaded ({"robot": bytes,
    # "operator.path": bytes}, scenario_files): what a run folder keeps a copy of.
    files: dict = dataclasses.field(default_factory=dict)

    @property
    def time_step(self) -> float:
        return self.scenario.time_step


def resolve_scenario(scenario, source: str = "<scenario>") -> ResolvedScenario:
    """Check the scenario (as `check_scenario`) and resolve it: robot loaded and swapped,
    parameters per pair, operator, limits with the robot's defaults. A ResolvedScenario is
    returned as it is."""
    if isinstance(scenario, ResolvedScenario):
        return scenario
    return _resolve(scenario, source)


def check_scenario(scenario: Scenario, source: str = "<scenario>") -> Robot:
    """Check every field a run depends on; returns the robot (swaps applied)."""
    return resolve_scenario(scenario, source).robot


def _resolve(scenario: Scenario, source: str) -> ResolvedScenario:
    robot = scenario_robot(scenario)
    _positive(scenario.duration, "duration")
    _positive(scenario.time_step, "time_step")
    check_duration(scenario.duration, scenario.time_step, "duration")
    _positive(scenario.admittance.mass, "admittance.mass")
    _positive(scenario.admittance.damping, "admittance.damping")
    p0 = scenario.initial_position
    defaulted = ()
    if p0 is None:  # the robot's workspace centre, whichever robot the scenario names
        scenario = dataclasses.replace(scenario, initial_position=default_start(robot))
        p0, defaulted = scenario.initial_position, ("initial_position",)
    if len(p0) != 3 or not all(math.isfinite(x) for x in p0):
        raise ScenarioError(f"initial_position must be [x, y, z] in m, got {p0!r}")
    if not robot.workspace.contains(p0):
        raise ScenarioError(
            f"initial_position {p0!r} m is outside the workspace box of robot {robot.name!r} "
            f"(lower {robot.workspace.lower.tolist()}, upper {robot.workspace.upper.tolist()})")
    for name in ("max_velocity", "max_acceleration"):
        v = getattr(scenario.limits, name)
        if v is not None:
            _positive(v, f"limits.{name}")
    if not (isinstance(scenario.random_seed, int) and scenario.random_seed >= 0):
        raise ScenarioError(f"random_seed must be an integer >= 0, got "
                            f"{scenario.random_seed!r}")
    s = scenario.sensor
    _positive(s.axial_range, "sensor.axial_range")
    _positive(s.transverse_range, "sensor.transverse_range")
    if not (isinstance(s.filter_window, int) and s.filter_window >= 1):
        raise ScenarioError(f"sensor.filter_window must be an integer >= 1 sample, got "
                            f"{s.filter_window!r}")
    if len(s.axial_axis) != 3 or not np.linalg.norm(s.axial_axis) > 0:
        raise ScenarioError(f"sensor.axial_axis must be a non-zero [x, y, z], got "
                            f"{s.axial_axis!r}")
    if not (math.isfinite(s.noise_std) and s.noise_std >= 0):
        raise ScenarioError(f"sensor.noise_std must be >= 0 N, got {s.noise_std!r}")
    gain = scenario.controller.length_gain
    if not (_is_number(gain) and math.isfinite(float(gain)) and 0 <= float(gain)
            and float(gain) * scenario.time_step < 1.0):
        raise ScenarioError(
            f"controller.length_gain must be a number >= 0 1/s and below 1 / time_step = "
            f"{1.0 / scenario.time_step:g} 1/s (0: the paper's open loop), got {gain!r}")
    _check_controller(scenario.controller, robot, scenario.plant)
    if scenario.wall_force.enabled:
        _positive(scenario.wall_force.margin, "wall_force.margin")
        _positive(scenario.wall_force.max_force, "wall_force.max_force")
    if isinstance(scenario.plant, DynamicReels):
        check_dynamic_reels(scenario, robot, defaulted=defaulted)
    elif not isinstance(scenario.plant, SimulatedReels):
        from cdpm_drake.hardware.config import check_hardware_reels
        try:
            check_hardware_reels(scenario.plant)
        except ValueError as e:
            raise ScenarioError(str(e)) from None
    else:
        if not (math.isfinite(scenario.plant.time_constant) and scenario.plant.time_constant >= 0):
            raise ScenarioError(f"plant.time_constant must be >= 0 s, got "
                                f"{scenario.plant.time_constant!r}")
        if scenario.plant.max_reel_speed is not None:
            _positive(scenario.plant.max_reel_speed, "plant.max_reel_speed")
    operator = scenario_operator(scenario)
    params = None
    if scenario.interference.enabled and robot.num_pairs:
        params = interference_params(scenario, robot)
    _check_safety(scenario)
    d_min = pair_d_min(scenario, robot)
    limits = scenario.limits
    plant = scenario.plant
    simulated = isinstance(plant, SimulatedReels)
    return ResolvedScenario(
        scenario=scenario, robot=robot, interference=params, operator=operator,
        max_velocity=float(_or(limits.max_velocity, robot.limits.max_velocity)),
        max_acceleration=float(_or(limits.max_acceleration, robot.limits.max_acceleration)),
        max_reel_speed=float(_or(getattr(plant, "max_reel_speed", None),
                                 robot.limits.max_reel_speed)),
        fk_max_residual=1e-6 if simulated else float(getattr(plant, "max_length_residual",
                                                             0.005)),
        # The kinematic plant's reels have no friction: nothing to make up there.
        dead_band=(robot.dynamics.dead_band if scenario.controller.friction_compensation
                   and float(scenario.controller.length_gain) > 0 and not simulated
                   else 0.0),
        d_min=d_min,
        defaulted=defaulted,
        # Read right after the robot and the operator were loaded from them.
        files={field: path.read_bytes() for field, path in scenario_files(scenario).items()})


def check_duration(duration: float, time_step: float, field: str) -> None:
    """ScenarioError when `duration` (s) is shorter than one tick of `time_step` (s): the run
    would be the start tick alone."""
    # A hair of round-off (0.1 / 0.002 = 49.99...) does not make a whole tick shorter.
    if duration < time_step * (1 - 1e-9):
        raise ScenarioError(f"{field} {duration!r} s is shorter than one tick (time_step "
                            f"{time_step!r} s): a run needs at least one tick, e.g. "
                            f"{field} {time_step!r}")


POSES = ("translation", "full")


def _check_controller(c: Controller, robot: Robot, plant) -> None:
    if c.pose not in POSES:
        raise ScenarioError(f"controller.pose must be one of {list(POSES)}, got {c.pose!r}")
    m = robot.num_cables
    if c.pose == "full" and m < 6:
        raise ScenarioError(
            f"controller.pose 'full' needs at least 6 cables to estimate position and "
            f"orientation; robot {robot.name!r} has {m} (use pose: translation)")
    if c.pose == "full":
        _positive(c.orientation_gain, "controller.orientation_gain")
    if not c.tension_control:
        return
    if c.pose != "full":
        raise ScenarioError(
            "controller.tension_control: true needs controller.pose: full (the stretch it "
            "commands fits only a fitted orientation, and the redundant cable's length "
            f"measures the internal tension only in a full pose); got pose {c.pose!r}")
    if isinstance(plant, SimulatedReels):
        raise ScenarioError(
            "controller.tension_control: true needs a plant whose cables stretch "
            "(plant: !DynamicReels {} or !HardwareReels {...}): the kinematic !SimulatedReels "
            "has inextensible cables, whose lengths no stretch can be commanded on")
    rank = robot_statics(robot).rank
    if rank < 6:
        raise ScenarioError(
            f"controller.tension_control needs a wrench matrix of rank 6 (cables that hold "
            f"every force and moment: the internal force it sets lives in the rest); robot "
            f"{robot.name!r} has rank {rank} at its workspace centre")
    if not (_is_number(c.tension_floor) and math.isfinite(float(c.tension_floor))
            and float(c.tension_floor) > 0):
        raise ScenarioError(f"controller.tension_floor must be a finite number > 0 N (the "
                            f"tension no cable is commanded below), got {c.tension_floor!r}")
    if not (_is_number(c.min_tension) and math.isfinite(float(c.min_tension))
            and float(c.min_tension) >= float(c.tension_floor)):
        raise ScenarioError(f"controller.min_tension must be a finite number >= "
                            f"controller.tension_floor = {c.tension_floor!r} N, got "
                            f"{c.min_tension!r}")
    if not (_is_number(c.max_tension) and math.isfinite(float(c.max_tension))
            and float(c.max_tension) > float(c.min_tension)):
        raise ScenarioError(f"controller.max_tension must be a finite number above "
                            f"controller.min_tension = {c.min_tension!r} N, got "
                            f"{c.max_tension!r}")


def _or(value, default):
    return default if value is None else value


def default_start(robot: Robot) -> list[float]:
    """The start of a scenario that leaves initial_position out: the centre of the robot's
    workspace box, m, to 12 significant digits (1.35, not the 1.3499999999999999 of
    (0.3 + 2.4) / 2, in messages and in the scenario.yaml a run writes)."""
    return [float(f"{x:.12g}") for x in robot.workspace.center]


def start_text(scenario: Scenario, robot: Robot, defaulted=()) -> str:
    """"initial_position [x, y, z] m" for messages, saying "default" when the scenario left
    it out (`defaulted` names it, or it is None: the robot's workspace centre)."""
    p0 = scenario.initial_position
    if p0 is None or "initial_position" in defaulted:
        centre = default_start(robot) if p0 is None else p0
        return (f"initial_position {centre!r} m (the default: the centre of the workspace box "
                f"of robot {robot.name!r})")
    return f"initial_position {p0!r} m"


def _default_note(config, field: str) -> str:
    """" (default)" when `config`'s field has its dataclass default value."""
    default = next(f for f in dataclasses.fields(config) if f.name == field)
    value = (default.default_factory() if default.default_factory is not dataclasses.MISSING
             else default.default)
    return " (default)" if getattr(config, field) == value else ""


def check_dynamic_reels(scenario: Scenario, robot: Robot, defaulted=()):
    """Check a !DynamicReels plant and its start; returns the start tension distribution
    (tension_program.Distribution). A start pose no positive tension distribution holds is refused,
    naming the pose (and whether it is the default) and the cables that would go slack."""
    from cdpm_drake.kernels.rotation import rotation_from_rpy
    from cdpm_drake.kernels.tension import gravity_wrench, stable_time_step, wrench_matrix
    from cdpm_drake.robot.statics import balancing_rotation
    from cdpm_drake.robot.tension_program import tension_distribution

    cfg = scenario.plant
    _positive(cfg.time_step, "plant.time_step")
    ticks = scenario.time_step / cfg.time_step
    if abs(ticks - round(ticks)) > 1e-9 * ticks:
        raise ScenarioError(f"plant.time_step {cfg.time_step!r} s must divide the control "
                            f"period time_step {scenario.time_step!r} s (e.g. "
                            f"{scenario.time_step / max(1, math.ceil(ticks)):g} s)")
    if not (isinstance(cfg.min_tension, (int, float)) and math.isfinite(cfg.min_tension)
            and cfg.min_tension >= 0):
        raise ScenarioError(f"plant.min_tension must be a finite number >= 0 N, got "
                            f"{cfg.min_tension!r}")
    rpy = cfg.initial_rpy
    if len(rpy) != 3 or not all(math.isfinite(a) for a in rpy):
        raise ScenarioError(f"plant.initial_rpy must be [roll, pitch, yaw] in rad, got {rpy!r}")
    if cfg.max_reel_speed is not None:
        _positive(cfg.max_reel_speed, "plant.max_reel_speed")
    _positive(cfg.max_length_residual, "plant.max_length_residual")
    start = start_text(scenario, robot, defaulted)
    p0 = np.asarray(scenario.initial_position if scenario.initial_position is not None
                    else default_start(robot), dtype=float)
    dyn = robot.dynamics
    W, wrench = wrench_matrix(robot, p0, rotation_from_rpy(rpy)), gravity_wrench(dyn.mass)
    if cfg.lock_rotation:  # the lock takes the moments; the cables balance the force
        W, wrench = W[:3], wrench[:3]
    dist = tension_distribution(W, wrench, cfg.min_tension)
    if not dist.feasible:
        cables = [k + 1 for k in dist.slack]
        rpy_text = f"plant.initial_rpy {list(rpy)!r} rad{_default_note(cfg, 'initial_rpy')}"
        msg = (f"{start} with {rpy_text}: no tension distribution of robot {robot.name!r} holds "
               f"the platform's {dyn.mass:g} kg with every cable >= plant.min_tension = "
               f"{cfg.min_tension:g} N{_default_note(cfg, 'min_tension')}; cable(s) {cables} "
               f"would go slack (the best distribution leaves them at {dist.best_min:.2f} N)")
        if dist.residual > 1e-6:
            msg = (f"{start} with {rpy_text}: the cables of robot {robot.name!r} cannot balance the "
                   f"platform's weight at all (force/moment residual {dist.residual:.3g}): "
                   f"their {robot.num_cables} lines of action leave a moment unbalanced; "
                   "plant.lock_rotation: true models the platform as only translating")
        elif not any(rpy) and not cfg.lock_rotation:
            tilt = balancing_rotation(robot, p0, mass=dyn.mass, min_tension=cfg.min_tension)
            if tilt is not None:
                msg += (f"; the cables hold it tilted by plant.initial_rpy "
                        f"{np.round(tilt, 3).tolist()!r} rad")
        raise ScenarioError(msg)
    h_max = stable_time_step(robot, p0, rotation_from_rpy(rpy), dist.tensions,
                             locked=cfg.lock_rotation)
    if cfg.time_step > 0.5 * h_max:
        raise ScenarioError(
            f"plant.time_step {cfg.time_step!r} s is too long for the cables of robot "
            f"{robot.name!r} (cables.EA {dyn.EA:g} N, platform.mass {dyn.mass:g} kg): their "
            f"stiffest mode is stable up to {h_max:.3g} s and accurate to half of that; use "
            f"plant.time_step <= {0.5 * h_max:.2g} s (dividing time_step "
            f"{scenario.time_step:g} s)"
            + (f"; {cfg.time_step!r} s is plant.time_step's default"
               if _default_note(cfg, "time_step") else ""))
    return dist


def warn_unreachable_d_u(robot, params):
    """A pair whose d_u is above the largest distance translation can give it keeps its force
    on everywhere: worth saying before a run, not an error (the paper's own numbers come close)."""
    from cdpm_drake.kernels.interference import translation_distance_bound

    bound = translation_distance_bound(robot)
    for (i, j), d_u, g in zip(robot.pairs, params.d_u, bound):
        if d_u >= g:
            _log.warning(
                "pair (%d,%d): d_u = %.1f mm is not below %.1f mm, the largest distance any "
                "platform translation gives these cables; its interference force never "
                "switches off", i, j, 1000 * d_u, 1000 * g)


def scenario_to_yaml(scenario: Scenario) -> str:
    """The resolved scenario as YAML (written beside every log), without the loader's
    internal base_dir (a loaded file's paths are resolved already)."""
    from pydrake.common.yaml import yaml_dump_typed

    text = yaml_dump_typed(dataclasses.replace(scenario, base_dir=""))
    return text.replace("\nbase_dir: ''\n", "\n")


# The copies of a scenario's own files in the run folders (write_run_scenario).
RUN_ROBOT_FILE = "robot.yaml"
RUN_FORCE_FILE = "force.csv"


def scenario_files(scenario: Scenario) -> dict:
    """{field: Path} of the files the scenario reads, "robot" (a robot file, not a built-in
    robot's name) and "operator.path" (a CSV operator's), as it resolves them."""
    from cdpm_drake.robot import is_path_like

    base = Path(scenario.base_dir) if scenario.base_dir else None
    files = {}
    if is_path_like(scenario.robot):
        files["robot"] = _under(scenario.robot, base)
    if isinstance(scenario.operator, CsvOperator) and scenario.operator.path:
        files["operator.path"] = _under(scenario.operator.path, base)
    return files


def _under(ref: str, base) -> Path:
    path = Path(ref)
    return path if path.is_absolute() or base is None else base / path


def write_run_scenario(out_dir, scenario, **changes) -> Path:
    """Write DIR/scenario.yaml, the resolved scenario (with `changes`, e.g. the duration that
    ran), and copies of the robot file and force CSV it reads, DIR/robot.yaml and
    DIR/force.csv, which it refers to instead of the originals: the folder can be moved,
    shared and rerun alone. The copies are of the files as the run loaded them (a
    ResolvedScenario's `files`), so a rerun into its own folder with --force (which empties
    it first) still has them. Returns the scenario.yaml path."""
    resolved = resolve_scenario(scenario)
    out = Path(out_dir)
    recorded = dataclasses.replace(resolved.scenario, **changes)
    names = {"robot": RUN_ROBOT_FILE, "operator.path": RUN_FORCE_FILE}
    for field, data in resolved.files.items():
        (out / names[field]).write_bytes(data)
    if "robot" in resolved.files:
        recorded = dataclasses.replace(recorded, robot=RUN_ROBOT_FILE)
    if "operator.path" in resolved.files:
        recorded = dataclasses.replace(recorded, operator=dataclasses.replace(
            recorded.operator, path=RUN_FORCE_FILE))
    path = out / "scenario.yaml"
    path.write_text(scenario_to_yaml(recorded))
    return path
