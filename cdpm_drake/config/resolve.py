"""A scenario checked and resolved once (ResolvedScenario): its robot loaded with the cable
swaps, the logistic parameters per pair, the operator, the limits with the robot file's
defaults. What the builder, the runners and the views take."""

import dataclasses
import math
import typing
from pathlib import Path

import numpy as np

from cdpm_drake.config.checks import (check_controller, check_duration, check_dynamic_reels,
                                      check_finite, check_logistic_set, check_positive,
                                      check_safety, check_ticks, default_said,
                                      default_start)
from cdpm_drake.config.plants import DynamicReels, SimulatedReels, check_tension_sensor
from cdpm_drake.config.scenario import PairLogistic, Scenario, ScenarioError
from cdpm_drake.config.yaml_io import is_number
from cdpm_drake.kernels.plant.operators import CsvOperator, OperatorError, make_operator
from cdpm_drake.robot import Robot, RobotError, load_robot


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
    # The robot the simulated plant plays (plant.robot, plant.model_error; the scenario's
    # swaps applied); None: `robot` itself, the controller's.
    true_robot: typing.Any = None
    # Each encoder's zero error after the homing, m (m,); None: none.
    encoder_zero_error: typing.Any = None
    # What the robot file's stated geometry uncertainty adds (a calibrated file's): to each
    # pair's d_min, m (P,), and to the model monitor's length bounds, m; zeros without one.
    d_min_margin: typing.Any = None
    length_margin: float = 0.0
    # ... and to the safety filter's kinetostatic floor, N (the tensions computed on a
    # geometry known to sigma are off by as much).
    kinetostatic_margin: float = 0.0

    @property
    def time_step(self) -> float:
        return self.scenario.time_step

    @property
    def homing_offset(self):
        """What a homing at the start pose adds to the plant's encoder readings when the
        plant plays another robot than the controller's (plant.robot, plant.model_error):
        the homing writes the controller's rigid lengths of the start pose where the plant's
        are, plus each encoder's zero error, m (m,). None without model error."""
        if self.true_robot is None:
            return None
        from cdpm_drake.kernels.pose import pose_lengths
        from cdpm_drake.kernels.rotation import rotation_from_rpy

        p0 = np.asarray(self.scenario.initial_position, dtype=float)
        R0 = rotation_from_rpy(getattr(self.scenario.plant, "initial_rpy", [0.0, 0.0, 0.0]))
        return (pose_lengths(self.robot, p0, R0) - pose_lengths(self.true_robot, p0, R0)
                + self.encoder_zero_error)

    @property
    def plant_robot(self) -> Robot:
        """The robot the plant plays: `true_robot` where the plant has model error, else the
        controller's."""
        return self.robot if self.true_robot is None else self.true_robot


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


# Scenario.method's values: the hard promise (the default), the paper's method.
METHODS = ("promise", "paper")


def _resolve(scenario: Scenario, source: str) -> ResolvedScenario:
    if scenario.method not in METHODS:
        raise ScenarioError(f"method must be one of {list(METHODS)} (promise: the paper's "
                            f"Fig. 5 with the safety filter; paper: without it), got "
                            f"{scenario.method!r}")
    if scenario.method == "paper":
        scenario = dataclasses.replace(scenario, safety_filter=dataclasses.replace(
            scenario.safety_filter, enabled=False))
    check_name(scenario.name)
    robot = scenario_robot(scenario)
    check_positive(scenario.duration, "duration")
    check_positive(scenario.time_step, "time_step")
    check_duration(scenario.duration, scenario.time_step, "duration")
    check_positive(scenario.admittance.mass, "admittance.mass")
    check_positive(scenario.admittance.damping, "admittance.damping")
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
            check_positive(v, f"limits.{name}")
    seed = scenario.random_seed
    if isinstance(seed, bool) or not (isinstance(seed, int) and 0 <= seed < 2**32):
        # 32 bits: what every generator it seeds takes (numba's and numpy's legacy ones).
        raise ScenarioError(f"random_seed must be an integer in 0..{2**32 - 1}, got {seed!r}")
    s = scenario.sensor
    check_positive(s.axial_range, "sensor.axial_range")
    check_positive(s.transverse_range, "sensor.transverse_range")
    check_ticks(s.filter_window, "sensor.filter_window", scenario.time_step,
                "samples of the sliding average")
    if len(s.axial_axis) != 3 or not np.linalg.norm(s.axial_axis) > 0:
        raise ScenarioError(f"sensor.axial_axis must be a non-zero [x, y, z], got "
                            f"{s.axial_axis!r}")
    if not (math.isfinite(s.noise_std) and s.noise_std >= 0):
        raise ScenarioError(f"sensor.noise_std must be >= 0 N, got {s.noise_std!r}")
    gain = scenario.controller.length_gain
    if not (is_number(gain) and math.isfinite(float(gain)) and 0 <= float(gain)
            and float(gain) * scenario.time_step < 1.0):
        raise ScenarioError(
            f"controller.length_gain must be a number >= 0 1/s and below 1 / time_step = "
            f"{1.0 / scenario.time_step:g} 1/s (0: the paper's open loop), got {gain!r}"
            f"{default_said(scenario.controller, 'length_gain')}")
    check_controller(scenario.controller, robot, scenario.plant)
    scale = scenario.controller.tension_damping.gain_scale
    if not (is_number(scale) and math.isfinite(float(scale)) and float(scale) >= 0):
        raise ScenarioError(f"controller.tension_damping.gain_scale must be a number >= 0 "
                            f"(1: the derived gain), got {scale!r}")
    if scenario.wall_force.enabled:
        check_positive(scenario.wall_force.margin, "wall_force.margin")
        check_positive(scenario.wall_force.max_force, "wall_force.max_force")
    if isinstance(scenario.plant, DynamicReels):
        try:
            check_tension_sensor(scenario.plant)
        except ValueError as e:
            raise ScenarioError(str(e)) from None
        check_dynamic_reels(scenario, robot, defaulted=defaulted)
    elif not isinstance(scenario.plant, SimulatedReels):
        from cdpm_drake.hardware.canopen_config import CanopenReels, check_canopen_reels
        from cdpm_drake.hardware.config import check_hardware_reels
        if scenario.plant.max_length_residual is None:  # derived from the robot's cables
            from cdpm_drake.robot.stretch import derived_length_residual
            bound = derived_length_residual(robot, scenario.controller.max_tension)
            scenario = dataclasses.replace(scenario, plant=dataclasses.replace(
                scenario.plant, max_length_residual=bound))
        try:
            if isinstance(scenario.plant, CanopenReels):
                check_canopen_reels(scenario.plant, robot.num_cables, scenario.time_step)
            else:
                check_hardware_reels(scenario.plant)
        except ValueError as e:
            raise ScenarioError(str(e)) from None
    else:
        if not (math.isfinite(scenario.plant.time_constant) and scenario.plant.time_constant >= 0):
            raise ScenarioError(f"plant.time_constant must be >= 0 s, got "
                                f"{scenario.plant.time_constant!r}")
        if scenario.plant.max_reel_speed is not None:
            check_positive(scenario.plant.max_reel_speed, "plant.max_reel_speed")
    operator = scenario_operator(scenario)
    params = None
    if scenario.interference.enabled and robot.num_pairs:
        params = interference_params(scenario, robot)
    check_safety(scenario)
    d_min = pair_d_min(scenario, robot)
    check_pairs_separable(scenario, robot)
    d_min_margin, length_margin = uncertainty_margins(robot)
    d_min = d_min + d_min_margin
    kinetostatic_margin = kinetostatic_uncertainty(robot, scenario)
    limits = scenario.limits
    plant = scenario.plant
    simulated = isinstance(plant, SimulatedReels)
    true_robot, zero_error = plant_robot(scenario, robot)
    model_error = true_robot is not robot or bool(np.any(zero_error))
    fk_residual = 1e-6 if simulated else float(getattr(plant, "max_length_residual", 0.005))
    if simulated and plant.max_length_residual is not None:
        check_positive(plant.max_length_residual, "plant.max_length_residual")
        fk_residual = float(plant.max_length_residual)
    elif simulated and model_error:
        # The encoders no longer fit the file's geometry exactly: the robot's bound, as on
        # the real reels (5 mm plus the stretch of the longest cable at the ceiling).
        from cdpm_drake.robot.stretch import derived_length_residual
        fk_residual = derived_length_residual(robot, scenario.controller.max_tension)
    return ResolvedScenario(
        scenario=scenario, robot=robot, interference=params, operator=operator,
        max_velocity=float(_or(limits.max_velocity, robot.limits.max_velocity)),
        max_acceleration=float(_or(limits.max_acceleration, robot.limits.max_acceleration)),
        max_reel_speed=float(_or(getattr(plant, "max_reel_speed", None),
                                 robot.limits.max_reel_speed)),
        fk_max_residual=fk_residual,
        # The kinematic plant's reels have no friction: nothing to make up there.
        dead_band=(robot.dynamics.dead_band if scenario.controller.friction_compensation
                   and float(scenario.controller.length_gain) > 0 and not simulated
                   else 0.0),
        d_min=d_min,
        defaulted=defaulted,
        # Read right after the robot and the operator were loaded from them.
        files={field: path.read_bytes() for field, path in scenario_files(scenario).items()},
        true_robot=true_robot if model_error else None,
        encoder_zero_error=zero_error if model_error else None,
        d_min_margin=d_min_margin, length_margin=length_margin,
        kinetostatic_margin=kinetostatic_margin)


def check_name(name, folder: str = "runs/<name>/") -> None:
    """ScenarioError unless `name` is one folder name: a run's folder is runs/<name>/ (a
    sweep's `folder`), and a name with a path separator or `..` would put it elsewhere
    (`../../etc/x`)."""
    import re

    if not (isinstance(name, str) and re.fullmatch(r"[A-Za-z0-9_.+-]+", name)
            and name.strip(".")):
        raise ScenarioError(
            f"name must be one folder name of letters, digits, '_', '-', '.' and '+' (it is "
            f"written to {folder}; no '/', '\\', spaces or '..'), got {name!r}")


def _or(value, default):
    return default if value is None else value


def plant_robot(scenario: Scenario, robot: Robot) -> tuple[Robot, np.ndarray]:
    """(the robot the simulated plant plays, each encoder's zero error (m,) m): the
    controller's `robot` unless the plant names another (`plant.robot`) or perturbs it
    (`plant.model_error`). ScenarioError naming the field."""
    from cdpm_drake.robot.perturb import check_model_error, has_model_error, perturbed_robot

    plant = scenario.plant
    zero = np.zeros(robot.num_cables)
    if not isinstance(plant, (SimulatedReels, DynamicReels)):
        return robot, zero
    try:
        check_model_error(plant.model_error)
    except ValueError as e:
        raise ScenarioError(str(e)) from None
    true = robot
    if plant.robot:
        true = scenario_robot(scenario, plant.robot, field="plant.robot")
        if true.num_cables != robot.num_cables:
            raise ScenarioError(f"plant.robot {plant.robot!r} has {true.num_cables} cables; "
                                f"the controller's robot {robot.name!r} has "
                                f"{robot.num_cables}: the plant must play the same robot, "
                                "as built")
    if not has_model_error(plant.model_error):
        return true, zero
    seed = plant.model_error.seed
    try:
        return perturbed_robot(true, plant.model_error,
                               scenario.random_seed if seed is None else seed)
    except RobotError as e:
        raise ScenarioError(str(e)) from None


def scenario_robot(scenario: Scenario, ref=None, field: str = "robot") -> Robot:
    """The scenario's robot (or the robot `ref` names, as the scenario's field `field`) with
    the scenario's cable swaps applied."""
    from cdpm_drake.robot import ROBOTS_DIR, is_path_like

    ref = scenario.robot if ref is None else ref
    if is_path_like(ref):
        # Loaded scenarios hold absolute paths; one built in code resolves against base_dir.
        if scenario.base_dir and not Path(ref).is_absolute():
            ref = str(Path(scenario.base_dir) / ref)
    elif (ROBOTS_DIR / f"{ref}.yaml").is_file():
        ref = str(ROBOTS_DIR / f"{ref}.yaml")  # a name is a built-in robot, wherever we are
    try:
        robot = load_robot(ref)
    except RobotError as e:
        raise ScenarioError(f"{field}: {e}") from None
    check_swaps(scenario.swaps)
    for k, swap in enumerate(scenario.swaps):
        try:
            robot = robot.with_swapped_attachments(int(swap[0]), int(swap[1]))
        except RobotError as e:
            raise ScenarioError(f"swaps[{k}] = {swap!r}: {e}") from None
    return robot


def check_swaps(swaps) -> None:
    """ScenarioError for swaps that do not swap: a cable with itself ([1, 1]), or a list whose
    swaps undo each other for some cable ([[1, 3], [3, 1]]: the run would be unswapped while
    the file says 1-3 is). Cable numbers 1-based; their range is the robot's to check."""
    where = list(range(1 + max((int(c) for s in swaps if len(s) == 2 for c in s), default=0)))
    named = {}
    for k, swap in enumerate(swaps):
        if len(swap) != 2:
            raise ScenarioError(f"swaps[{k}] must be two cable numbers [i, j], got {swap!r}")
        i, j = (int(c) for c in swap)
        low = [c for c in (i, j) if c < 1]
        if low:
            raise ScenarioError(f"swaps[{k}] = {list(swap)!r}: {low[0]} is not a cable; "
                                "cables are numbered from 1 (cable 1 is the robot file's "
                                "first row)")
        if i == j:
            raise ScenarioError(f"swaps[{k}] = {list(swap)!r} swaps cable {i} with itself; "
                                "give two different cables")
        for c in (i, j):
            named.setdefault(c, []).append(k)
        if min(i, j) >= 1:
            where[i], where[j] = where[j], where[i]
    back = sorted(c for c in named if c >= 1 and where[c] == c)
    if back:
        ks = sorted({k for c in back for k in named[c]})
        listed = ", ".join(f"swaps[{k}] = {list(swaps[k])!r}" for k in ks)
        raise ScenarioError(f"{listed} undo each other: cable(s) {back} end where they "
                            "started, so the run would not swap them; list each swap once")


def check_pairs_separable(scenario: Scenario, robot: Robot) -> None:
    """ScenarioError for a watched pair that no platform translation separates: its cables
    cross (or touch: closer than the robot's cable_diameter, at least 1 um) at every pose,
    e.g. a swap that puts both attachment points on the line through the reels, so nothing
    the controller does keeps them apart (it was only the d_u warning). The message names
    the pair, the distance and the swaps that moved its cables."""
    from cdpm_drake.kernels.interference import translation_distance_bound

    if not robot.num_pairs:
        return
    touching = max(float(robot.cable_diameter), 1e-6)
    for (i, j), g in zip(robot.pairs, translation_distance_bound(robot)):
        if g < touching:
            swaps = [list(s) for s in scenario.swaps if {i, j} & {int(c) for c in s}]
            by = f" with swaps {swaps!r}" if swaps else ""
            raise ScenarioError(
                f"cables {i} and {j} of robot {robot.name!r}{by} cross at every pose: no "
                f"platform translation takes them more than {1000 * g:.2f} mm apart (their "
                f"diameter: {1000 * float(robot.cable_diameter):g} mm), so nothing keeps them "
                "apart (swap other cables, or list them in the robot file's ignore_pairs if "
                "they share a reel exit)")


def scenario_operator(scenario: Scenario):
    try:
        return make_operator(scenario.operator,
                             Path(scenario.base_dir) if scenario.base_dir else None)
    except OperatorError as e:
        raise ScenarioError(str(e)) from None


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
    check_logistic_set({k: getattr(cfg.default, k) for k in arrays}, default, "")
    for n, override in enumerate(cfg.pairs):
        k = robot.pair_position(int(override.pair[0]), int(override.pair[1]))
        names = {key: (f"interference.pairs[{n}].{key}" if getattr(override, key) is not None
                       else default[key]) for key in arrays}
        check_logistic_set({key: arrays[key][k] for key in arrays}, names,
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


# A robot file that states its geometry's uncertainty (calibration: reels_std,
# attachments_std) widens the margins by this many standard deviations (2: 97.7 % one-sided
# for a Gaussian error).
UNCERTAINTY_SIGMAS = 2.0


def uncertainty_margins(robot: Robot) -> tuple[np.ndarray, float]:
    """(what each watched pair's d_min gains, m (P,); what the model monitor's length bounds
    gain, m) from the robot's stated geometry uncertainty: UNCERTAINTY_SIGMAS times a pair's
    distance's standard deviation (the two cables' lines move independently, each by at most
    the larger of its end points' standard deviations: the closest points are convex
    combinations of the end points) and times the largest cable's. Zeros without one."""
    P = robot.num_pairs
    if robot.uncertainty is None:
        return np.zeros(P), 0.0
    sigma = robot.uncertainty.cable_std()
    i, j = robot.pair_index
    pair = UNCERTAINTY_SIGMAS * np.hypot(sigma[i], sigma[j])
    return pair, float(UNCERTAINTY_SIGMAS * np.max(sigma))


def kinetostatic_uncertainty(robot: Robot, scenario: Scenario) -> float:
    """What the robot's stated geometry uncertainty adds to the kinetostatic floor, N:
    UNCERTAINTY_SIGMAS times the tensions' first-order error at the start pose with every
    tension at the controller's ceiling (kinetostatics.geometry_tension_error); 0 without
    one."""
    if robot.uncertainty is None:
        return 0.0
    from cdpm_drake.kernels.kinetostatics import geometry_tension_error, wrench_rows

    p0 = np.asarray(scenario.initial_position, dtype=float)
    return UNCERTAINTY_SIGMAS * geometry_tension_error(
        robot, p0, wrench_rows(robot), robot.uncertainty.cable_std(),
        float(scenario.controller.max_tension))


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
    first = {}
    for n, override in enumerate(cfg.pairs):
        k = _override_position(n, override, robot)
        if k in first:  # the second would silently win over the first, field by field
            i, j = robot.pairs[k]
            raise ScenarioError(
                f"interference.pairs[{n}].pair = {list(override.pair)!r} overrides pair "
                f"({i},{j}) again (interference.pairs[{first[k]}].pair = "
                f"{list(cfg.pairs[first[k]].pair)!r}): give each pair one entry")
        first[k] = n
    if cfg.default.d_min is not None:
        check_finite(cfg.default.d_min, "interference.default.d_min")
        d_min[:] = float(cfg.default.d_min)
    for n, override in enumerate(cfg.pairs):
        k = _override_position(n, override, robot)
        if override.d_l is not None:
            d_l[k] = float(override.d_l)
        if override.d_min is not None:
            check_finite(override.d_min, f"interference.pairs[{n}].d_min")
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
    plant_ref = getattr(scenario.plant, "robot", "")
    if isinstance(plant_ref, str) and plant_ref and is_path_like(plant_ref):
        files["plant.robot"] = _under(plant_ref, base)
    return files


def _under(ref: str, base) -> Path:
    path = Path(ref)
    return path if path.is_absolute() or base is None else base / path
