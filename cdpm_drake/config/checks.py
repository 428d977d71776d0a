"""The checks of a scenario's fields that need more than their type: ranges, the
controller's and the safety filter's settings, the dynamic plant's start. Each raises
ScenarioError naming the field and the value. The start position a scenario may leave out
(default_start) is here too: the dynamic plant's check needs it."""

import dataclasses
import math

import numpy as np

from cdpm_drake.config.plants import ENCODER_ZEROS, DynamicReels, SimulatedReels
from cdpm_drake.config.scenario import Controller, Scenario, ScenarioError
from cdpm_drake.config.yaml_io import is_number
from cdpm_drake.robot import Robot, robot_statics


def check_positive(value, field):
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ScenarioError(f"{field} must be a finite number > 0, got {value!r}")


def check_finite(value, field: str) -> None:
    if not (is_number(value) and math.isfinite(float(value))):
        raise ScenarioError(f"{field} must be a finite number, got {value!r}")


# The longest a count of ticks a scenario sets may span, s: a sliding average or a
# monitor's wait longer than this is no filter or watch (and a window of a million samples
# would take terabytes of memory).
MAX_TICKS_SPAN = 1.0


def check_ticks(value, field: str, time_step: float, what: str) -> None:
    """ScenarioError unless `value` is an integer count of ticks of `time_step` s from 1 to
    MAX_TICKS_SPAN s's worth, naming the field, the value and the range."""
    most = max(1, int(round(MAX_TICKS_SPAN / time_step)))
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= most:
        raise ScenarioError(f"{field} must be an integer in 1..{most} ({what}, ticks of "
                            f"time_step {time_step:g} s: at most {MAX_TICKS_SPAN:g} s), got "
                            f"{value!r}")


def check_duration(duration: float, time_step: float, field: str) -> None:
    """ScenarioError when `duration` (s) is shorter than one tick of `time_step` (s): the run
    would be the start tick alone."""
    # A hair of round-off (0.1 / 0.002 = 49.99...) does not make a whole tick shorter.
    if duration < time_step * (1 - 1e-9):
        raise ScenarioError(f"{field} {duration!r} s is shorter than one tick (time_step "
                            f"{time_step!r} s): a run needs at least one tick, e.g. "
                            f"{field} {time_step!r}")


def check_safety(scenario: Scenario) -> None:
    """The safety filter's, the kinetostatic cue's, the model monitor's and the tension
    floor's fields; ScenarioError naming the field and the value."""
    c = scenario.controller
    for name in ("tension_floor", "max_tension"):
        check_finite(getattr(c, name), f"controller.{name}")
    if not 0 < float(c.tension_floor) < float(c.max_tension):
        raise ScenarioError(f"controller.tension_floor must be > 0 N and below "
                            f"controller.max_tension = {c.max_tension!r} N"
                            f"{default_said(c, 'max_tension')}, got {c.tension_floor!r}"
                            f"{default_said(c, 'tension_floor')}")
    f = scenario.safety_filter
    check_finite(f.kinetostatic_floor, "safety_filter.kinetostatic_floor")
    if not 0 < float(f.kinetostatic_floor) < float(c.max_tension):
        raise ScenarioError(f"safety_filter.kinetostatic_floor must be > 0 N and below "
                            f"controller.max_tension = {c.max_tension!r} N"
                            f"{default_said(c, 'max_tension')}, got "
                            f"{f.kinetostatic_floor!r}{default_said(f, 'kinetostatic_floor')}")
    check_finite(f.gamma, "safety_filter.gamma")
    if not 0 < float(f.gamma) <= 1:
        raise ScenarioError(f"safety_filter.gamma must lie in (0, 1] (the share of a "
                            f"barrier's margin one tick may use), got {f.gamma!r}")
    check_finite(f.position_smoothing, "safety_filter.position_smoothing")
    if float(f.position_smoothing) < 0:
        raise ScenarioError(f"safety_filter.position_smoothing must be >= 0 s (0: the "
                            f"estimated position itself), got {f.position_smoothing!r}")
    check_finite(f.return_speed, "safety_filter.return_speed")
    if float(f.return_speed) < 0:
        raise ScenarioError(f"safety_filter.return_speed must be >= 0 m/s, got "
                            f"{f.return_speed!r}")
    cue = f.kinetostatic_force
    if cue.enabled:
        for name in ("t_l", "t_u", "F_u", "eps"):
            check_finite(getattr(cue, name), f"safety_filter.kinetostatic_force.{name}")
        if not cue.t_u > cue.t_l:
            raise ScenarioError(f"safety_filter.kinetostatic_force.t_u = {cue.t_u!r} N must "
                                f"be above t_l = {cue.t_l!r} N")
        check_positive(cue.F_u, "safety_filter.kinetostatic_force.F_u")
        if not 0 < cue.eps < cue.F_u / 2:
            raise ScenarioError(f"safety_filter.kinetostatic_force.eps = {cue.eps!r} N must "
                                f"lie in (0, F_u/2) = (0, {cue.F_u / 2!r}) N")
    mon = scenario.model_monitor
    check_finite(mon.holdable, "model_monitor.holdable")
    for name in ("slack_tension", "unholdable", "measured_slack"):
        check_finite(getattr(mon, name), f"model_monitor.{name}")
        if float(getattr(mon, name)) < 0:
            raise ScenarioError(f"model_monitor.{name} must be >= 0 N, got "
                                f"{getattr(mon, name)!r}")
    for name in ("slack_length", "fit_tolerance"):
        check_positive(getattr(mon, name), f"model_monitor.{name}")
    check_finite(mon.overload, "model_monitor.overload")
    if not (float(mon.overload) == 0 or float(mon.overload) > 1):
        raise ScenarioError(f"model_monitor.overload must be 0 (off) or above 1 (times "
                            f"controller.max_tension: a cable measured above it is "
                            f"overloaded), got {mon.overload!r}")
    for name in ("ticks", "slack_ticks"):
        check_ticks(getattr(mon, name), f"model_monitor.{name}", scenario.time_step,
                    "ticks a condition must last to be a fault")


def check_logistic_set(values: dict, names: dict, pair: str) -> None:
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


POSES = ("translation", "full")


def check_controller(c: Controller, robot: Robot, plant) -> None:
    if c.pose not in POSES:
        raise ScenarioError(f"controller.pose must be one of {list(POSES)}, got {c.pose!r}")
    m = robot.num_cables
    if c.pose == "full" and m < 6:
        raise ScenarioError(
            f"controller.pose 'full' needs at least 6 cables to estimate position and "
            f"orientation; robot {robot.name!r} has {m} (use pose: translation)")
    if c.pose == "full":
        check_positive(c.orientation_gain, "controller.orientation_gain")
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
    if not (is_number(c.tension_floor) and math.isfinite(float(c.tension_floor))
            and float(c.tension_floor) > 0):
        raise ScenarioError(f"controller.tension_floor must be a finite number > 0 N (the "
                            f"tension no cable is commanded below), got {c.tension_floor!r}")
    if not (is_number(c.min_tension) and math.isfinite(float(c.min_tension))
            and float(c.min_tension) >= float(c.tension_floor)):
        raise ScenarioError(f"controller.min_tension must be a finite number >= "
                            f"controller.tension_floor = {c.tension_floor!r} N"
                            f"{default_said(c, 'tension_floor')}, got {c.min_tension!r}"
                            f"{default_said(c, 'min_tension')}")
    if not (is_number(c.max_tension) and math.isfinite(float(c.max_tension))
            and float(c.max_tension) > float(c.min_tension)):
        raise ScenarioError(f"controller.max_tension must be a finite number above "
                            f"controller.min_tension = {c.min_tension!r} N"
                            f"{default_said(c, 'min_tension')}, got {c.max_tension!r}"
                            f"{default_said(c, 'max_tension')}")


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


def default_said(config, field: str) -> str:
    """" (default value; the scenario does not change it)" when `config`'s field has its
    dataclass default, for a message that blames it while another field is the one changed
    (a tension_floor raised above the default min_tension)."""
    return (" (default value; the scenario does not change it)"
            if _default_note(config, field) else "")


def _default_note(config, field: str) -> str:
    """" (default)" when `config`'s field has its dataclass default value."""
    default = next(f for f in dataclasses.fields(config) if f.name == field)
    value = (default.default_factory() if default.default_factory is not dataclasses.MISSING
             else default.default)
    return " (default)" if getattr(config, field) == value else ""


class UnholdableRobot(ScenarioError):
    """A run on the free-rotating dynamic plant of a robot whose cables cannot resist every
    wrench of the rigid platform (wrench matrix rank < 6 at the start): refused, the message
    says why and the ways out. `cdpm info` reports it without stopping: `scenario` is the
    scenario refused (its start filled in)."""

    def __init__(self, message: str, scenario: Scenario):
        super().__init__(message)
        self.scenario = scenario


def check_holds_a_rigid_body(scenario: Scenario, robot: Robot, W, defaulted=()) -> None:
    """UnholdableRobot when W (6, m; the start pose's wrench matrix, moments about the
    platform centre) has rank < 6 and the plant lets the platform turn (lock_rotation false):
    the platform turns under the wrenches the rank lacks and a cable goes slack, while the
    controller's translating statics (t* = +inf where the cables' lines meet) see nothing.
    The message names the robot, its cables, the rank, every direction it cannot resist
    (robot.unresisted) and the ways out."""
    from cdpm_drake.robot.unresisted import unresisted_directions, unresisted_text

    rank, directions = unresisted_directions(W)
    if rank >= 6 or scenario.plant.lock_rotation:
        return
    m = robot.num_cables
    rpy = (f"plant.initial_rpy {list(scenario.plant.initial_rpy)!r} rad"
           f"{_default_note(scenario.plant, 'initial_rpy')}")
    where = ((f" ({m} cables: below 6 at every pose)" if m < 6 else "")
             + f" at the start, {start_text(scenario, robot, defaulted)} with {rpy}")
    raise UnholdableRobot(
        f"robot {robot.name!r} ({m} cables) cannot hold a platform that turns freely: its "
        f"wrench matrix has rank {rank} < 6{where}, so no cable tensions resist "
        f"{unresisted_text(W)} ({len(directions)} direction{'s' if len(directions) > 1 else ''}"
        f"; moments about the platform centre, base frame). On plant: !DynamicReels with "
        f"lock_rotation: false{_default_note(scenario.plant, 'lock_rotation')} the platform "
        "would turn and a cable go slack while the controller's translating model sees "
        "nothing, so the run is refused. Ways out: plant.lock_rotation: true (plant: "
        "!DynamicReels {lock_rotation: true}: the platform held at its start orientation, the "
        "paper's translation-only model), "
        "the kinematic plant (plant: !SimulatedReels {}), or a robot whose cables resist "
        "every force and moment (rank 6: at least 7 cables for a positive internal force, "
        "attachment points spread so their moments span all three axes)", scenario)


def check_dynamic_reels(scenario: Scenario, robot: Robot, defaulted=()):
    """Check a !DynamicReels plant and its start; returns the start tension distribution
    (tension_program.Distribution). A start pose no positive tension distribution holds is refused,
    naming the pose (and whether it is the default) and the cables that would go slack."""
    from cdpm_drake.kernels.rotation import rotation_from_rpy
    from cdpm_drake.kernels.tension import gravity_wrench, stable_time_step, wrench_matrix
    from cdpm_drake.robot.statics import balancing_rotation
    from cdpm_drake.robot.tension_program import tension_distribution

    cfg = scenario.plant
    check_positive(cfg.time_step, "plant.time_step")
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
        check_positive(cfg.max_reel_speed, "plant.max_reel_speed")
    check_positive(cfg.max_length_residual, "plant.max_length_residual")
    if cfg.encoder_zero not in ENCODER_ZEROS:
        raise ScenarioError(f"plant.encoder_zero must be one of {list(ENCODER_ZEROS)}, got "
                            f"{cfg.encoder_zero!r}")
    start = start_text(scenario, robot, defaulted)
    p0 = np.asarray(scenario.initial_position if scenario.initial_position is not None
                    else default_start(robot), dtype=float)
    dyn = robot.dynamics
    W, wrench = wrench_matrix(robot, p0, rotation_from_rpy(rpy)), gravity_wrench(dyn.mass)
    check_holds_a_rigid_body(scenario, robot, W, defaulted)
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
    check_start_fits_translation(scenario, robot, p0, dist.tensions, f"{start} with "
                                 f"plant.initial_rpy {list(rpy)!r} rad")
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


def check_start_fits_translation(scenario: Scenario, robot: Robot, p0, tensions,
                                 start: str) -> None:
    """ScenarioError when the translating controller (controller.pose: translation) cannot
    read the dynamic plant's start: the encoder lengths of the platform turned by
    plant.initial_rpy (stretched by the start `tensions`, N) fit no level platform within
    plant.max_length_residual, so its first tick would stop on "cable lengths are
    inconsistent with the robot" while the cause is the orientation. `start` names the pose
    for the message."""
    from cdpm_drake.kernels.kinematics import KinematicsError, forward_kinematics
    from cdpm_drake.kernels.rotation import rotation_from_rpy

    cfg = scenario.plant
    if scenario.controller.pose != "translation" or not any(cfg.initial_rpy):
        return  # the full pose estimates the orientation too; a level start has none

    def misfit(rpy):
        """Each cable's residual of the level fit to the start lengths turned by rpy, m."""
        R0 = rotation_from_rpy(rpy)
        rigid = np.linalg.norm(robot.reels - (p0 + robot.attachments @ R0.T), axis=1)
        # Homed encoders read the rigid lengths at the start; unstretched ones less the
        # start stretch.
        lengths = (rigid if getattr(cfg, "encoder_zero", "homed") == "homed" else
                   rigid / (1.0 + np.asarray(tensions, dtype=float) / robot.dynamics.EA))
        p = forward_kinematics(robot, lengths, p_guess=p0, max_residual=math.inf)
        return np.abs(np.linalg.norm(robot.reels - (p + robot.attachments), axis=1) - lengths)

    bound = float(cfg.max_length_residual)
    try:
        # The orientation is the trouble only where the level start fits (the stretch alone
        # can exceed a tight bound: the run's own check says so then).
        residual = misfit(cfg.initial_rpy)
        if residual.max() <= bound or misfit([0.0, 0.0, 0.0]).max() > bound:
            return
    except KinematicsError:
        return  # no fit at all: the run's own check says so
    cable = int(np.argmax(residual))
    raise ScenarioError(
        f"{start}: the platform's orientation is the trouble: controller.pose "
        f"{scenario.controller.pose!r}{_default_note(scenario.controller, 'pose')} estimates "
        f"a level platform, and the cable lengths of one turned by plant.initial_rpy fit no "
        f"level one (the best fit leaves {1000 * residual[cable]:.1f} mm on cable "
        f"{cable + 1}; plant.max_length_residual {1000 * float(cfg.max_length_residual):g} "
        f"mm): give a smaller plant.initial_rpy, or controller.pose: full to estimate the "
        "orientation too")


def homing_tensions(scenario: Scenario, robot: Robot):
    """The tensions (m,) N the plant's homing leaves the cables at, by the statics of the
    start pose, where the controller reconciles the encoders' zero with the cables' stretch
    (kernels/encoder_zero.py); None where the plant's lengths need no reconciling (the
    kinematic plant's rigid cables, a dynamic plant whose encoders read unstretched
    lengths). The dynamic plant: its start distribution (check_dynamic_reels); the real
    reels: the least-norm distribution that holds the level platform's weight at the start
    with every cable at least the plant's homing_min_tension."""
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix
    from cdpm_drake.robot.tension_program import tension_distribution

    cfg = scenario.plant
    if isinstance(cfg, SimulatedReels):
        return None
    if isinstance(cfg, DynamicReels):
        if cfg.encoder_zero != "homed":
            return None
        return np.asarray(check_dynamic_reels(scenario, robot).tensions, dtype=float)
    floor = float(cfg.homing_min_tension)
    p0 = np.asarray(scenario.initial_position if scenario.initial_position is not None
                    else default_start(robot), dtype=float)
    return np.asarray(tension_distribution(wrench_matrix(robot, p0),
                                           gravity_wrench(robot.dynamics.mass),
                                           floor).tensions, dtype=float)
