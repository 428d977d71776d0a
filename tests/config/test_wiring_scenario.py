"""Every scenario and robot-file field reaches what it configures.

Each test sets one or a few fields to values distinct from every other value in play (no
M = C), runs a short simulation (or a short real-time run against an in-process emulated
bridge for `!HardwareReels`) and checks the number where it lands: the log, a behaviour that
depends on it, or a public object built from it. Expected numbers come from closed forms
derived in the comments, or from the public math functions fed the expected parameters
(independent of the builder under test).

`test_every_schema_field_has_a_case` walks the dataclass schemas (Scenario and its nested
configs, every member of the operator and plant unions, RobotSchema and nested) and fails
when a field has no case here: a new field must come with a test that it reaches its block.

Log timing (tests/systems/test_diagram.py derives it): row k is at t_k = k T; with filter_window 1
F_H_k is the operator's force at tick k; velocity_admittance_k follows the ZOH recursion
v_{k+1} = a v_k + b F_d_k; p_{k+1} integrates the command of tick k.
"""

import dataclasses
import socket
import time
import typing

import numpy as np
import pytest

from cdpm_drake import config as scenario_module
from cdpm_drake.hardware.config import HardwareReels
from cdpm_drake.emulator import FaultPlan, ReelBridge, ReelBridgeServer
from cdpm_drake.kernels.interference import InterferenceParams, interference_force
from cdpm_drake.kernels.kinematics import KinematicsError, cable_lengths, forward_kinematics, jacobian
from cdpm_drake.kernels.plant.operators import CsvOperator, NoOperator, ScriptedOperator, SpringHandOperator
from cdpm_drake.runs.realtime import run as realtime_run
from cdpm_drake.robot import RobotSchema, load_robot
from cdpm_drake.config import (Admittance, DynamicReels, Interference, Limits, Logistic,
                                 ModelMonitor, PairLogistic, SafetyFilter, Scenario, ScenarioError, Sensor,
                                 SimulatedReels, WallForce, load_scenario, scenario_robot)
from cdpm_drake.runs.log import save_log
from cdpm_drake.runs.simulate import simulate
from cdpm_drake.systems.plants.dynamic_plant import ground_truth_now, plant_state_now, reel_step

from conftest import case_registry, to_yaml

T = 0.002
# Inside paper_7cable's box [0.5, 0.8, 0.3]..[3.0, 4.0, 2.4] m, away from every face and with
# no cable pair within 0.2 m (so interference never acts unless a test asks for it).
P0 = [1.77, 2.4, 1.3]
# exp1's start: with cables 1 and 3 swapped, pair (1,3) is 56.08 mm apart (inside the default
# band 50..61 mm), s = 0.111, t = 0.128, every other pair > 0.2 m away.
P_EXP1 = [1.77, 3.65, 1.22]

CASES: dict[str, str] = {}
# Fields with no wiring case here yet (none now). NOT a case: a field listed here lets the
# suite run while its owner adds the case; the walk fails if one of them gets a case (then
# remove it here) or is gone.
NO_CASE_YET: set[str] = set()

# Registers the schema fields a test checks (see test_every_schema_field_has_a_case).
covers = case_registry(CASES)
# `!CanopenReels`'s cases live in test_wiring_canopen.py (a real-time bus in this process).
try:
    from test_wiring_canopen import CANOPEN_CASES
except pytest.skip.Exception:  # no canopen extra: its fields have no case to run
    CANOPEN_CASES = {}


def base(**changes) -> Scenario:
    """paper_7cable at P0, no interference, no sensor filter, a scripted zero force; the
    fields given replace these."""
    s = Scenario(name="wiring", duration=0.2, initial_position=list(P0),
                 interference=Interference(enabled=False), sensor=Sensor(filter_window=1),
                 operator=ScriptedOperator(times=[0.0], forces=[[0.0, 0.0, 0.0]]))
    return dataclasses.replace(s, **changes)


def push(force, **changes) -> Scenario:
    """`base` with a constant operator force (N)."""
    return base(operator=ScriptedOperator(times=[0.0], forces=[list(map(float, force))]),
                **changes)


def sim(scenario, duration=None):
    result = simulate(scenario=scenario, duration=duration)
    assert result.error is None, result.error
    return result.log


# --- the schema walk -----------------------------------------------------------------------


def _unwrap_optional(tp):
    if typing.get_origin(tp) is typing.Union:
        rest = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(rest) == 1:
            return rest[0]
    return tp


def schema_fields(schema, prefix=""):
    """Leaf field paths of a dataclass schema: `a.b` for nested dataclasses, `a[].b` for lists
    of dataclasses, `a=!Member` for each member of a tagged union and `a!Member.b` for its
    fields."""
    out = []
    hints = typing.get_type_hints(schema)
    for f in dataclasses.fields(schema):
        path = f"{prefix}{f.name}"
        tp = _unwrap_optional(hints[f.name])
        if dataclasses.is_dataclass(tp):
            out += schema_fields(tp, path + ".")
        elif typing.get_origin(tp) is typing.Union:
            for member in typing.get_args(tp):
                if member is type(None):  # an optional union: None is no member to wire
                    continue
                out.append(f"{path}=!{member.__name__}")
                out += schema_fields(member, f"{path}!{member.__name__}.")
        elif (typing.get_origin(tp) is list and typing.get_args(tp)
              and dataclasses.is_dataclass(typing.get_args(tp)[0])):
            out += schema_fields(typing.get_args(tp)[0], path + "[].")
        else:
            out.append(path)
    return out


def all_schema_fields():
    return ([f"Scenario.{p}" for p in schema_fields(Scenario)]
            + [f"RobotSchema.{p}" for p in schema_fields(RobotSchema)])


def test_every_schema_field_has_a_case():
    """Fails when a scenario or robot field (or a union member) is added without a test here
    that it reaches what it configures, and when a case names a field that is gone."""
    fields = all_schema_fields()
    # The walk itself sees the unions and the nested lists (else it would pass vacuously).
    assert "Scenario.operator!SpringHandOperator.stiffness" in fields
    assert "Scenario.plant!HardwareReels.watchdog_ticks" in fields
    assert "Scenario.interference.pairs[].d_u" in fields
    assert "RobotSchema.limits.max_reel_speed" in fields
    missing = sorted(set(fields) - set(CASES) - set(CANOPEN_CASES) - NO_CASE_YET)
    stale = sorted(set(CASES) - set(fields))
    assert not missing, f"schema fields with no wiring case in {__file__}: {missing}"
    assert not stale, f"wiring cases for fields that no longer exist: {stale}"
    assert not NO_CASE_YET & set(CASES), "fields with a case now: drop them from NO_CASE_YET"
    assert NO_CASE_YET <= set(fields), f"gone: {sorted(NO_CASE_YET - set(fields))}"


# --- identity, robot, start, duration --------------------------------------------------------


@covers("Scenario.name", "Scenario.description")
def test_name_and_description_reach_the_log_and_the_resolved_scenario(tmp_path):
    s = base(name="wire_name_7", description="a description only this test uses")
    log = sim(s, 0.01)
    assert str(log["scenario_name"]) == "wire_name_7"
    save_log(log, tmp_path, s)
    back = load_scenario(tmp_path / "scenario.yaml")
    assert (back.name, back.description) == ("wire_name_7", "a description only this test uses")


@covers("Scenario.robot", "Scenario.base_dir", "RobotSchema.name", "RobotSchema.reels",
        "RobotSchema.attachments")
def test_a_robot_file_relative_to_base_dir_reaches_the_geometry(tmp_path, valid_spec):
    """A 4-cable robot written here, named by a path relative to base_dir: the log carries its
    name, reels and attachments, and the first logged lengths are |p0 + b_i - a_i| (eq. 2)."""
    valid_spec["name"] = "wired_tetra"
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "tetra.yaml").write_text(to_yaml(valid_spec) + "\n")
    p0 = [2.1, 1.4, 1.6]
    log = sim(base(robot="robots/tetra.yaml", base_dir=str(tmp_path), initial_position=p0),
              0.01)
    a, b = np.array(valid_spec["reels"]), np.array(valid_spec["attachments"])
    assert str(log["robot_name"]) == "wired_tetra"
    np.testing.assert_array_equal(log["reels"], a)
    np.testing.assert_array_equal(log["attachments"], b)
    np.testing.assert_allclose(log["lengths"][0], np.linalg.norm(np.add(p0, b) - a, axis=1),
                               atol=1e-9)


@covers("Scenario.method")
def test_method_paper_removes_the_safety_filter_and_promise_keeps_it():
    # The default is the promise: the filter's columns are logged; the paper's method has none.
    assert "filter_status" in sim(base(), 0.01)
    assert "filter_status" not in sim(base(method="paper"), 0.01)


@covers("Scenario.swaps")
def test_swaps_trade_the_two_cables_attachment_points():
    robot = load_robot("paper_7cable")
    log = sim(base(swaps=[[2, 6]]), 0.01)
    expected = robot.attachments.copy()
    expected[[1, 5]] = robot.attachments[[5, 1]]  # cables 2 and 6 are rows 1 and 5
    np.testing.assert_array_equal(log["attachments"], expected)
    np.testing.assert_allclose(log["lengths"][0], cable_lengths(
        dataclasses.replace(robot, attachments=expected), P0), atol=1e-9)


@covers("Scenario.initial_position")
def test_initial_position_is_the_first_logged_position():
    p0 = [1.31, 2.07, 0.93]
    log = sim(base(initial_position=p0), 0.01)
    np.testing.assert_allclose(log["p"][0], p0, atol=1e-9)


@covers("Scenario.duration", "Scenario.time_step")
def test_duration_and_time_step_set_the_log_rows():
    # duration 0.12 s at T = 0.004 s: rows at 0, 0.004, ..., 0.12 s, i.e. 0.12 / 0.004 + 1 = 31.
    log = sim(base(duration=0.12, time_step=0.004))
    assert len(log["time"]) == 31
    np.testing.assert_allclose(np.diff(log["time"]), 0.004, atol=1e-12)
    # The argument overrides the field: 0.05 s -> 13 rows.
    assert len(sim(base(duration=0.12, time_step=0.004), duration=0.05)["time"]) == 13


# --- admittance ---------------------------------------------------------------------------


def _admittance_velocity(M, C, F, k):
    """ZOH of 1/(M s + C) under a constant force F from rest: v_k = F/C (1 - exp(-k T C/M))."""
    return F / C * (1.0 - np.exp(-k * T * C / M))


@covers("Scenario.admittance.mass")
@pytest.mark.parametrize("M, C", [(2.0, 5.0), (2.0, 6.25)])
def test_admittance_mass_and_damping_reach_the_block(M, C):
    """A 1 N push along x: v_k = 1/C (1 - exp(-k T C/M)). With M = 2, C = 5 it is 0.0787 m/s
    at k = 100 (0.2 s); swapped (M = 5, C = 2) it would be 0.0384 m/s; final value 0.2 vs
    0.5 m/s."""
    log = sim(push([1.0, 0, 0], admittance=Admittance(mass=M, damping=C)), 0.3)
    k = np.arange(len(log["time"]))
    np.testing.assert_allclose(log["velocity_admittance"][:, 0],
                               _admittance_velocity(M, C, 1.0, k), atol=1e-12)


@covers("Scenario.admittance.damping")
def test_admittance_damping_alone_reaches_the_block():
    # M at its default 6.25 kg, C = 3.5 N s/m: v_150 = 1/3.5 (1 - exp(-0.3 * 3.5 / 6.25)).
    log = sim(push([1.0, 0, 0], admittance=Admittance(damping=3.5)), 0.3)
    assert log["velocity_admittance"][150, 0] == pytest.approx(
        _admittance_velocity(6.25, 3.5, 1.0, 150), abs=1e-12)


# --- interference ----------------------------------------------------------------------------


def exp1(**interference) -> Scenario:
    """exp1's geometry (cables 1 and 3 swapped, pair (1,3) inside the band at t = 0)."""
    return base(swaps=[[1, 3]], initial_position=list(P_EXP1),
                interference=Interference(**interference))


def _first_F_int(scenario):
    return sim(scenario, 0.004)["F_int"][0]


def _expected_F_int(params_changes=None, **uniform):
    """F_int at exp1's start from the public math, fed the parameters the test expects."""
    robot = scenario_robot(exp1())
    values = dict(d_l=0.050, d_u=0.061, F_u=2.0, eps=0.1)
    values.update(uniform)
    params = InterferenceParams.uniform(robot, **values)
    if params_changes:
        arrays = {k: np.array(getattr(params, k)) for k in ("d_l", "d_u", "F_u", "eps")}
        for (i, j), changes in params_changes.items():
            for key, value in changes.items():
                arrays[key][robot.pair_position(i, j)] = value
        F_max = uniform.get("F_max", float(arrays["F_u"].max()))
        kw = {"gradient_floor": uniform["gradient_floor"]} if "gradient_floor" in uniform else {}
        params = InterferenceParams(**arrays, F_max=F_max, pairs=tuple(robot.pairs), **kw)
    return interference_force(robot, np.array(P_EXP1), params).force


def test_the_default_interference_parameters_reach_the_block():
    # The reference every other interference case differs from: |F_int| = 0.8224 N.
    F = _first_F_int(exp1())
    np.testing.assert_allclose(F, _expected_F_int(), atol=1e-12)
    assert np.linalg.norm(F) == pytest.approx(0.8224, abs=1e-4)


@covers("Scenario.interference.enabled")
def test_interference_enabled_false_removes_the_force():
    on, off = sim(exp1(), 0.02), sim(exp1(enabled=False), 0.02)
    assert np.linalg.norm(on["F_int"], axis=1).min() > 0.5
    np.testing.assert_array_equal(off["F_int"], 0.0)
    assert np.isnan(off["d_u"]).all() and not np.isnan(on["d_u"]).any()


@covers("Scenario.interference.default.d_l", "Scenario.interference.default.d_u",
        "Scenario.interference.default.F_u", "Scenario.interference.default.eps")
@pytest.mark.parametrize("field, value", [("d_l", 0.043), ("d_u", 0.067), ("F_u", 3.3),
                                          ("eps", 0.37)])
def test_default_logistic_parameters_reach_the_block(field, value):
    """Each parameter changes F_int at d = 56.08 mm to what eqs. 26-30 give for it."""
    F = _first_F_int(exp1(default=Logistic(**{field: value})))
    expected = _expected_F_int(**{field: value})
    np.testing.assert_allclose(F, expected, atol=1e-12)
    assert np.linalg.norm(expected - _expected_F_int()) > 0.05  # the value matters here
    log = sim(exp1(default=Logistic(**{field: value})), 0.004)
    np.testing.assert_array_equal(log[field], value)


@covers("Scenario.interference.pairs[].pair", "Scenario.interference.pairs[].d_l",
        "Scenario.interference.pairs[].d_u", "Scenario.interference.pairs[].F_u",
        "Scenario.interference.pairs[].eps")
@pytest.mark.parametrize("field, value", [("d_l", 0.046), ("d_u", 0.071), ("F_u", 2.9),
                                          ("eps", 0.23)])
def test_a_per_pair_override_reaches_that_pair_and_only_it(field, value):
    """An override for pair [3, 1] (written backwards) lands on pair (1,3) only: F_int is the
    math's for that one change, and the logged parameter arrays differ from the default at
    the position of (1,3) alone. A second override for the far pair (5,6) moves nothing."""
    robot = scenario_robot(exp1())
    far = {"d_l": 0.011, "d_u": 0.058, "F_u": 0.9, "eps": 0.02}
    s = exp1(pairs=[PairLogistic(pair=[3, 1], **{field: value}),
                    PairLogistic(pair=[5, 6], **{field: far[field]})])
    log = sim(s, 0.004)
    expected = _expected_F_int({(1, 3): {field: value}, (5, 6): {field: far[field]}})
    np.testing.assert_allclose(log["F_int"][0], expected, atol=1e-12)
    assert np.linalg.norm(expected - _expected_F_int()) > 0.02
    default = getattr(Logistic(), field)
    k13, k56 = robot.pair_position(1, 3), robot.pair_position(5, 6)
    want = np.full(robot.num_pairs, default)
    want[k13], want[k56] = value, far[field]
    np.testing.assert_array_equal(log[field], want)


@covers("Scenario.interference.F_max")
def test_F_max_clips_the_force():
    # Unclipped |F_int| = 0.8224 N at the start; F_max = 0.31 N clips it to 0.31 N, same
    # direction (eq. 30).
    F = _first_F_int(exp1(F_max=0.31))
    unclipped = _expected_F_int()
    assert np.linalg.norm(F) == pytest.approx(0.31, abs=1e-12)
    np.testing.assert_allclose(F, unclipped * 0.31 / np.linalg.norm(unclipped), atol=1e-12)


@covers("Scenario.interference.gradient_floor")
def test_gradient_floor_scales_the_force_where_the_gradient_is_below_it():
    """At the start |grad d| = |t - s| = 0.0164 for pair (1,3). A floor of 0.05 scales the push
    by 0.0164 / 0.05 = 0.327 (grad d / max(|grad d|, floor)); the default 0.002 leaves it at
    the unit gradient."""
    F = _first_F_int(exp1(gradient_floor=0.05))
    np.testing.assert_allclose(F, _expected_F_int(gradient_floor=0.05), atol=1e-12)
    robot = scenario_robot(exp1())
    r = interference_force(robot, np.array(P_EXP1), InterferenceParams.uniform(
        robot, 0.050, 0.061, 2.0, 0.1, gradient_floor=0.0))
    k = robot.pair_position(1, 3)
    ratio = abs(r.t[k] - r.s[k]) / 0.05
    assert ratio == pytest.approx(0.327, abs=0.002)
    np.testing.assert_allclose(F, r.force * ratio, atol=1e-12)


# --- limits and the wall force ------------------------------------------------------------------


@covers("Scenario.limits.max_velocity")
def test_scenario_speed_limit_caps_the_command():
    # 6 N along x with C = 6.25 would reach 0.96 m/s; the cap 0.137 m/s (robot file: 0.5) holds.
    log = sim(push([6.0, 0, 0], limits=Limits(max_velocity=0.137)), 0.6)
    speed = np.linalg.norm(log["velocity"], axis=1)
    assert speed.max() == pytest.approx(0.137, abs=1e-9)


@covers("Scenario.limits.max_acceleration")
def test_scenario_acceleration_limit_caps_the_change_per_tick():
    # 20 N / 6.25 kg asks 3.2 m/s^2 at the start; the cap 0.7 m/s^2 allows 0.0014 m/s per tick.
    log = sim(push([20.0, 0, 0], limits=Limits(max_acceleration=0.7)), 0.1)
    step = np.linalg.norm(np.diff(log["velocity"], axis=0), axis=1)
    assert step.max() == pytest.approx(0.7 * T, rel=1e-9)


@covers("Scenario.limits.virtual_wall")
def test_virtual_wall_false_lets_the_platform_leave_the_box():
    # Start 5 mm inside the upper x face (3.0 m), push +x at 5 N for 0.3 s.
    # Without the safety filter (issue 26), whose kinetostatic barrier would hold it: the
    # cables cannot hold the platform out there.
    start = [2.995, 2.4, 1.3]
    off = {"safety_filter": SafetyFilter(enabled=False)}
    walled = sim(push([5.0, 0, 0], initial_position=start, **off), 0.3)
    free = sim(push([5.0, 0, 0], initial_position=start, limits=Limits(virtual_wall=False),
                    **off), 0.3)
    assert walled["p"][:, 0].max() <= 3.0 + 1e-9
    assert free["p"][-1, 0] > 3.01


@covers("Scenario.wall_force.enabled", "Scenario.wall_force.margin",
        "Scenario.wall_force.max_force")
def test_wall_force_follows_its_margin_and_force():
    """30 mm from the lower x face (0.5 m), margin 80 mm, force 3 N at the face: F_wall,x =
    3 ((0.08 - 0.03) / 0.08)^2 = 1.171875 N inwards (+x); no other face within its margin."""
    start = [0.53, 2.4, 1.3]
    log = sim(base(initial_position=start,
                   wall_force=WallForce(enabled=True, margin=0.08, max_force=3.0)), 0.004)
    np.testing.assert_allclose(log["F_wall"][0], [1.171875, 0, 0], atol=1e-12)
    np.testing.assert_allclose(log["F_d"][0], log["F_wall"][0] + log["F_H"][0], atol=1e-12)
    off = sim(base(initial_position=start), 0.004)
    np.testing.assert_array_equal(off["F_wall"], 0.0)


# --- sensor -----------------------------------------------------------------------------------


@covers("Scenario.sensor.axial_range")
def test_axial_range_saturates_the_axial_component():
    # 30 N along the default axis z, range 12 N: F_H = [0, 0, 12].
    log = sim(push([0, 0, 30.0], sensor=Sensor(filter_window=1, axial_range=12.0)), 0.004)
    np.testing.assert_allclose(log["F_H"][0], [0, 0, 12.0], atol=1e-12)


@covers("Scenario.sensor.transverse_range")
def test_transverse_range_saturates_the_transverse_part():
    # 30 N along x (across the z handle), range 9 N: F_H = [9, 0, 0].
    log = sim(push([30.0, 0, 0], sensor=Sensor(filter_window=1, transverse_range=9.0)), 0.004)
    np.testing.assert_allclose(log["F_H"][0], [9.0, 0, 0], atol=1e-12)


@covers("Scenario.sensor.axial_axis")
def test_axial_axis_sets_which_range_applies():
    """Handle along [0, 2, 0] (normalised to y): 30 N along y is axial (range 12 N -> 12), 30 N
    along z transverse (range 80 N -> 30). With the default z axis it would be the reverse."""
    sensor = Sensor(filter_window=1, axial_axis=[0.0, 2.0, 0.0], axial_range=12.0)
    log = sim(push([0, 30.0, 30.0], sensor=sensor), 0.004)
    np.testing.assert_allclose(log["F_H"][0], [0, 12.0, 30.0], atol=1e-12)


@covers("Scenario.sensor.filter_window")
def test_filter_window_averages_that_many_samples():
    # A 1 N step at t = 0, window 4 (history starts at zero): F_H,x = 1/4, 2/4, 3/4, 1, 1.
    log = sim(push([1.0, 0, 0], sensor=Sensor(filter_window=4)), 0.008)
    np.testing.assert_allclose(log["F_H"][:5, 0], [0.25, 0.5, 0.75, 1.0, 1.0], atol=1e-12)


@covers("Scenario.sensor.noise_std")
def test_noise_std_sets_the_spread_of_the_measured_force():
    """No force, noise 0.37 N per axis, 501 ticks: each axis's sample std is within ~3 % of
    0.37 N (1 sigma), so 15 % is 5 sigma; a new sample every tick (white: the lag-1
    correlation of 500 pairs is within 0.045 of 0 at 1 sigma, 0.2 is > 4 sigma); the mean
    is within 0.37 / sqrt(501) = 0.017 N of 0 (1 sigma)."""
    log = sim(base(sensor=Sensor(filter_window=1, noise_std=0.37)), 1.0)
    F = log["F_H"]
    np.testing.assert_allclose(F.std(axis=0), 0.37, rtol=0.15)
    np.testing.assert_allclose(F.mean(axis=0), 0.0, atol=0.08)
    for axis in range(3):
        assert abs(np.corrcoef(F[:-1, axis], F[1:, axis])[0, 1]) < 0.2


@covers("Scenario.random_seed")
def test_random_seed_sets_the_noise():
    def noise(seed):
        s = base(sensor=Sensor(filter_window=1, noise_std=0.2), random_seed=seed)
        return sim(s, 0.02)["F_H"]

    np.testing.assert_array_equal(noise(3), noise(3))
    assert not np.allclose(noise(3), noise(4))
    assert not np.allclose(noise(4), noise(0))


# --- operators ----------------------------------------------------------------------------


@covers("Scenario.operator=!NoOperator")
def test_no_operator_gives_no_force():
    log = sim(base(operator=NoOperator()), 0.02)
    np.testing.assert_array_equal(log["F_H"], 0.0)


@covers("Scenario.operator=!ScriptedOperator", "Scenario.operator!ScriptedOperator.times",
        "Scenario.operator!ScriptedOperator.forces")
def test_scripted_forces_are_interpolated_at_their_times():
    # 0 N at 0.02 s rising to [1.6, -0.8, 0.4] N at 0.06 s: half-way at t = 0.04 s (row 20).
    op = ScriptedOperator(times=[0.02, 0.06], forces=[[0, 0, 0], [1.6, -0.8, 0.4]])
    log = sim(base(operator=op), 0.08)
    np.testing.assert_allclose(log["F_H"][20], [0.8, -0.4, 0.2], atol=1e-12)
    np.testing.assert_allclose(log["F_H"][5], 0.0, atol=1e-12)
    np.testing.assert_allclose(log["F_H"][35], [1.6, -0.8, 0.4], atol=1e-12)


@covers("Scenario.operator=!CsvOperator", "Scenario.operator!CsvOperator.path")
def test_csv_operator_replays_the_file_relative_to_base_dir(tmp_path):
    (tmp_path / "push.csv").write_text("t,fx,fy,fz\n0.0,0,0,0\n0.04,0.6,0,-1.2\n")
    log = sim(base(operator=CsvOperator(path="push.csv"), base_dir=str(tmp_path)), 0.06)
    np.testing.assert_allclose(log["F_H"][10], [0.3, 0, -0.6], atol=1e-12)  # t = 0.02 s
    np.testing.assert_allclose(log["F_H"][25], [0.6, 0, -1.2], atol=1e-12)


@covers("Scenario.operator=!SpringHandOperator",
        "Scenario.operator!SpringHandOperator.waypoints",
        "Scenario.operator!SpringHandOperator.times",
        "Scenario.operator!SpringHandOperator.stiffness",
        "Scenario.operator!SpringHandOperator.damping",
        "Scenario.operator!SpringHandOperator.max_force",
        "Scenario.operator!SpringHandOperator.release_time")
def test_spring_hand_force_follows_every_field():
    """F_H_k = K (target(t_k) - p_k) - D v_k, capped at max_force, zero from release_time on,
    recomputed here from the log (v_k = (p_k - p_{k-1}) / T: the true velocity the simulated
    reels give the operator). K = 23 N/m and D = 3.5 N s/m differ enough that swapping them
    changes the force by far more than the tolerance."""
    w0 = np.add(P0, [0.08, 0, 0])
    w1 = w0 + [0, 0.1, 0]
    op = SpringHandOperator(waypoints=[w0.tolist(), w1.tolist()], times=[0.0, 0.3],
                            stiffness=23.0, damping=3.5, max_force=1.7, release_time=0.35)
    log = sim(base(operator=op, admittance=Admittance(mass=1.5, damping=2.5)), 0.4)
    t, p = log["time"], log["p"]
    v = np.vstack([np.zeros(3), np.diff(p, axis=0) / T])
    target = np.stack([np.interp(t, [0.0, 0.3], [w0[k], w1[k]]) for k in range(3)], axis=1)
    F = 23.0 * (target - p) - 3.5 * v
    n = np.linalg.norm(F, axis=1)
    capped = n > 1.7
    F[capped] *= (1.7 / n[capped])[:, None]
    F[t >= 0.35 - 1e-12] = 0.0
    np.testing.assert_allclose(log["F_H"], F, atol=1e-6)
    # Each branch is reached: capped at the start (23 x 0.08 = 1.84 N > 1.7 N), below the cap
    # later, released at the end; and the damping term is not negligible.
    before = t < 0.35
    assert capped[before].any() and (~capped[before]).any()
    assert np.abs(3.5 * v).max() > 0.1


# --- plants -------------------------------------------------------------------------------------


@covers("Scenario.plant=!SimulatedReels", "Scenario.plant!SimulatedReels.time_constant")
def test_reel_time_constant_lags_the_motion():
    """With tau = 0.05 s each tick's actual reel speed moves 1 - exp(-T/tau) = 3.9 % of the way
    to the command; the platform velocity (the cables are consistent and J barely changes over
    millimetres) follows the commanded velocity through that same first-order filter."""
    # The paper's open loop: the cable-length loop would make up the lag it measures.
    log = sim(push([1.0, 0, 0], plant=SimulatedReels(time_constant=0.05),
                   controller=scenario_module.Controller(length_gain=0.0)), 0.3)
    lag = 1.0 - np.exp(-T / 0.05)
    command = log["velocity"][:, 0]
    actual = np.diff(log["p"][:, 0]) / T
    y, predicted = 0.0, []
    for c in command[:-1]:
        y += lag * (c - y)
        predicted.append(y)
    np.testing.assert_allclose(actual, predicted, atol=2e-5)
    assert np.abs(actual - command[:-1]).max() > 0.004  # the lag is visible (100 x the tolerance)


@covers("Scenario.controller.length_gain")
def test_length_gain_sets_the_cable_length_loop():
    """Every tick's reel command is J(p) v + K_l (l_d - l) with the scenario's K_l = 13.7 1/s
    (distinct from the default 40): recomputed from the logged p, velocity, commanded and
    measured lengths with kinematics.jacobian. Lagging drives (tau = 0.05 s) make l_d - l
    non-zero, so the gain shows."""
    s = push([1.0, 0, 0], plant=SimulatedReels(time_constant=0.05),
             controller=scenario_module.Controller(length_gain=13.7))
    log = sim(s, 0.3)
    robot = scenario_robot(s)
    error = log["lengths_commanded"] - log["lengths"]
    expected = (np.einsum("kij,kj->ki", jacobian(robot, log["p"]), log["velocity"])
                + 13.7 * error)
    np.testing.assert_allclose(log["reel_velocity"], expected, rtol=0, atol=1e-12)
    assert np.abs(error).max() > 1e-4  # 1e8 x the tolerance: the loop acts


@covers("Scenario.controller.pose")
def test_pose_full_estimates_the_orientation_and_holds_it():
    """pose: full adds the orientation to the estimate (logged rpy) and the orientation hold;
    on the kinematic plant (a level platform) the estimate is level and the position the
    translating estimate's."""
    log = sim(push([1.0, 0, 0], controller=scenario_module.Controller(pose="full")), 0.1)
    reference = sim(push([1.0, 0, 0]), 0.1)
    assert np.abs(log["rpy"]).max() < 1e-9 and np.abs(log["omega"]).max() < 1e-8
    # The full pose's PI loop and dead-band compensation act on round-off-level length errors
    # (1e-12 m), which moves the platform by nanometres, no more.
    np.testing.assert_allclose(log["p"], reference["p"], rtol=0, atol=1e-7)
    assert "rpy" not in reference and "omega" not in reference


def _full_dynamic(**controller):
    c = scenario_module.Controller(pose="full", **controller)
    # P0, where the cables hold the platform with a few tens of newtons.
    return dataclasses.replace(_dynamic(), initial_position=list(P0), controller=c,
                               operator=ScriptedOperator(times=[0.0], forces=[[2.0, -1.0, 1.0]]))


@covers("Scenario.controller.orientation_gain")
def test_orientation_gain_scales_the_angular_velocity_command():
    """omega = K_R log(R_ref R^T) with R_ref the first tick's estimate: recomputed from the
    logged orientation estimate with K_R = 3.7 1/s."""
    from cdpm_drake.kernels.pose import rotation_log
    from cdpm_drake.kernels.rotation import rotation_from_rpy

    log = sim(_full_dynamic(orientation_gain=3.7), 0.2)
    # The orientation held: the estimate's at the first tick; zero command there.
    R_ref = rotation_from_rpy(log["rpy"][0])
    expected = np.array([3.7 * np.array(rotation_log(R_ref @ rotation_from_rpy(rpy).T))
                         for rpy in log["rpy"]])
    expected[0] = 0.0
    np.testing.assert_allclose(log["omega"], expected, rtol=0, atol=1e-12)
    assert np.abs(log["omega"]).max() > 1e-6  # the platform did turn a little


@covers("Scenario.controller.tension_control")
def test_tension_control_commands_the_unstretched_lengths():
    """At the first tick the commanded pose is the estimate (p, R of the log), so the
    commanded lengths are its rigid lengths unstretched by the commanded tensions,
    L EA / (EA + T) with the robot file's EA."""
    from cdpm_drake.kernels.pose import pose_lengths
    from cdpm_drake.kernels.rotation import rotation_from_rpy

    s = _full_dynamic(tension_control=True)
    log = sim(s, 0.02)
    robot = scenario_robot(s)
    EA = robot.dynamics.EA
    L = pose_lengths(robot, log["p"][0], rotation_from_rpy(log["rpy"][0]))
    np.testing.assert_allclose(log["lengths_commanded"][0],
                               L * EA / (EA + log["tension_command"][0]), rtol=0, atol=1e-9)
    plain = sim(_full_dynamic(), 0.02)
    assert "tension_command" not in plain


@covers("Scenario.controller.min_tension")
def test_min_tension_is_the_floor_of_the_target():
    """Where the pose allows (status 0) every target tension is at least 7.5 N and the
    least-norm distribution puts some cable on that floor."""
    log = sim(_full_dynamic(tension_control=True, min_tension=7.5), 0.1)
    held = log["tension_status"][:, 0] == 0
    assert held.any()
    target = log["tension_target"][held]
    assert target.min() >= 7.5 - 1e-9
    np.testing.assert_allclose(target.min(axis=1), 7.5, atol=1e-9)


@covers("Scenario.controller.max_tension")
def test_max_tension_is_the_ceiling_of_the_target():
    """At this start the least-norm target with the 10 N floor reaches ~23.37 N (default
    100 N ceiling), while no distribution of this weight has every cable below 22.98 N (the
    smallest largest tension over the nullspace line): a 23.1 N ceiling binds, is kept, and
    still lets the floor hold."""
    low = sim(_full_dynamic(tension_control=True, max_tension=23.1), 0.05)
    high = sim(_full_dynamic(tension_control=True), 0.05)
    assert low["tension_target"].max() <= 23.1 + 1e-9
    assert low["tension_target"].min() >= 10.0 - 1e-9
    assert high["tension_target"].max() > 23.3


@covers("Scenario.controller.tension_floor")
def test_tension_floor_is_the_target_s_hard_floor():
    """At P0 the pose holds every cable at no more than t* = 16.5-17.6 N (logged t_star).
    With min_tension 23.5 N and the default hard floor (4 N) the floor is lowered to t* -
    FLOOR_MARGIN (status 1); with tension_floor 20 or 23.5 N, above t*, it cannot be: the
    max-min target's weak cables are raised to exactly tension_floor (status 4), and the
    cable named is one of them, the one raised most (cable 3, the weakest there)."""
    from cdpm_drake.kernels.full_pose import FLOOR_MARGIN, FLOOR_UNREACHABLE
    from cdpm_drake.kernels.tension import BELOW_FLOOR

    lowered = sim(_full_dynamic(tension_control=True, min_tension=23.5), 0.05)
    assert (lowered["tension_status"] == BELOW_FLOOR).all()
    np.testing.assert_allclose(lowered["tension_target"].min(axis=1),
                               lowered["t_star"][:, 0] - FLOOR_MARGIN, atol=1e-9)
    for floor in (20.0, 23.5):
        log = sim(_full_dynamic(tension_control=True, min_tension=23.5, tension_floor=floor),
                  0.05)
        assert (log["t_star"] < floor).all()
        assert (log["tension_status"] == FLOOR_UNREACHABLE).all()
        target = log["tension_target"]
        np.testing.assert_allclose(target.min(axis=1), floor, rtol=0, atol=1e-12)
        assert (log["tension_cable"] == 3).all()
        assert (target[:, 2] == floor).all()  # cable 3 was raised to the floor


@covers("Scenario.controller.friction_compensation")
def test_friction_compensation_makes_up_the_drives_dead_band():
    """On the dynamic plant every reel command is J(p) v + K_l e + 0.9 u_c tanh(e / 20 um),
    u_c the robot file's drive dead band, e = l_d - l (recomputed from the log); off, the
    tanh term is gone."""
    from cdpm_drake.kernels.kinematics import FRICTION_ERROR, FRICTION_SHARE

    def reproduce(log, robot, band):
        e = log["lengths_commanded"] - log["lengths"]
        return (np.einsum("kij,kj->ki", jacobian(robot, log["p"]), log["velocity"])
                + 40.0 * e + FRICTION_SHARE * band * np.tanh(e / FRICTION_ERROR))

    s = dataclasses.replace(push([2.0, 0, 0]), plant=scenario_module.DynamicReels(),
                            initial_position=list(P_EXP2))
    robot = scenario_robot(s)
    on = sim(s, 0.2)
    # The mapping's command: the reels' less the tension damping's part (its own block).
    on["reel_velocity"] = on["reel_velocity"] - on["reel_velocity_damping"]
    np.testing.assert_allclose(on["reel_velocity"], reproduce(on, robot,
                                                             robot.dynamics.dead_band),
                               rtol=0, atol=1e-12)
    off = sim(dataclasses.replace(
        s, controller=scenario_module.Controller(friction_compensation=False)), 0.2)
    off["reel_velocity"] = off["reel_velocity"] - off["reel_velocity_damping"]
    np.testing.assert_allclose(off["reel_velocity"], reproduce(off, robot, 0.0), rtol=0,
                               atol=1e-12)
    assert np.abs(on["reel_velocity"] - off["reel_velocity"]).max() > 1e-3  # it acts


def _reel_speeds(log):
    return np.abs(np.diff(log["lengths"], axis=0)) / T


@covers("Scenario.plant!SimulatedReels.max_reel_speed")
def test_plant_reel_speed_limit_scales_the_reels():
    # 8 N along x commands up to ~0.4 m/s of cable after 0.4 s; the plant limit 0.043 m/s
    # (robot file: 1.0) scales every reel alike, so the fastest reel runs at exactly 0.043.
    log = sim(push([8.0, 0, 0], plant=SimulatedReels(max_reel_speed=0.043)), 0.4)
    assert np.abs(log["reel_velocity"]).max() > 0.1  # the command is above the limit
    assert _reel_speeds(log).max() == pytest.approx(0.043, rel=1e-3)


# --- the dynamic plant ---------------------------------------------------------------------------

# exp2's start, where the paper robot's cables hold the platform (tests/systems/test_dynamic_plant.py).
P_EXP2 = [1.56, 3.24, 1.22]


def _dynamic(robot="paper_7cable", **plant):
    from cdpm_drake.config import DynamicReels

    return base(robot=robot, initial_position=list(P_EXP2), plant=DynamicReels(**plant))


def _force_residual(scenario, log, k, mass):
    """The force rows of W(p, R) T + gravity at row k, N: zero when the cables carry `mass`."""
    from cdpm_drake.kernels.rotation import rotation_from_rpy
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix

    robot = scenario_robot(scenario)
    W = wrench_matrix(robot, log["p_true"][k], rotation_from_rpy(log["rpy_true"][k]))
    return (W @ log["tensions"][k] + gravity_wrench(mass))


@covers("Scenario.plant=!DynamicReels", "Scenario.plant!DynamicReels.initial_rpy",
        "Scenario.plant!DynamicReels.lock_rotation", "Scenario.plant!DynamicReels.min_tension")
def test_dynamic_plant_starts_at_its_pose_and_tension_floor_locked():
    """Yaw 0.03 rad at the start, rotation locked, tension floor 7.3 N (default 5): the true
    orientation stays [0, 0, 0.03] at every tick although the cables leave a moment of more
    than 0.1 N m (the lock's joints take it), the start distribution puts its smallest
    tension on the floor, and the tensions carry the platform's weight (2.5 kg, forces)."""
    s = _dynamic(initial_rpy=[0.0, 0.0, 0.03], lock_rotation=True, min_tension=7.3)
    log = sim(s, 0.02)
    np.testing.assert_allclose(log["rpy_true"], np.broadcast_to([0, 0, 0.03], (11, 3)),
                               atol=1e-12)
    assert log["tensions"][0].min() == pytest.approx(7.3, abs=1e-9)
    residual = _force_residual(s, log, 0, 2.5)
    assert np.abs(residual[:3]).max() < 1e-6 and np.abs(residual[3:]).max() > 0.1


@covers("RobotSchema.platform.mass")
def test_robot_file_platform_mass_is_what_the_cables_carry(tmp_path):
    # platform: {mass: 3.1} kg: at the start the tensions balance 3.1 g = 30.4 N, not the
    # default 2.5 kg (5.9 N less).
    from cdpm_drake.robot import resolve_robot_path

    path = tmp_path / "heavy.yaml"
    from helpers_robots import with_sections

    path.write_text(with_sections(resolve_robot_path("paper_7cable").read_text(),
                                  "platform: {mass: 3.1}"))
    s = _dynamic(robot=str(path), lock_rotation=True)
    log = sim(s, 0.004)
    assert np.abs(_force_residual(s, log, 0, 3.1)[:3]).max() < 1e-6
    assert np.abs(_force_residual(s, log, 0, 2.5)[:3]).max() > 5.0


def _paper_with(tmp_path, extra, name="robot.yaml"):
    """paper_7cable's file with `extra` (YAML sections) in place of its own sections of the
    same names (as YAML's last-of-two-keys would have read them)."""
    from cdpm_drake.robot import resolve_robot_path

    from helpers_robots import with_sections

    path = tmp_path / name
    path.write_text(with_sections(resolve_robot_path("paper_7cable").read_text(), extra))
    return str(path)


def _plant_alone(scenario, command=None):
    """The scenario's dynamic plant alone, its reel command held at `command` (zeros), and a
    Simulator on it (as tests/systems/test_dynamic_plant.py's _plant_only)."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from cdpm_drake.diagram import make_plant

    robot = scenario_robot(scenario)
    builder = DiagramBuilder()
    builder.AddNamedSystem("reels", make_plant(scenario, robot))
    source = builder.AddSystem(ConstantVectorSource(
        np.zeros(robot.num_cables) if command is None else np.asarray(command, float)))
    builder.Connect(source.get_output_port(),
                    builder.GetSubsystemByName("reels").GetInputPort("reel_velocity_command"))
    diagram = builder.Build()
    return diagram, Simulator(diagram), robot


def _sub(diagram, simulator, name):
    """Plant subsystem `name` and its context in the simulator."""
    system = diagram.GetSubsystemByName("reels").GetSubsystemByName(name)
    return system, system.GetMyMutableContextFromRoot(simulator.get_mutable_context())


def _start_geometry(scenario):
    """Rigid cable lengths L and unit vectors u (attachment -> reel) at the start pose (level),
    and the start tension distribution (tension.py, via check_dynamic_reels)."""
    robot = scenario_robot(scenario)
    rho = robot.reels - (np.asarray(scenario.initial_position) + robot.attachments)
    L = np.linalg.norm(rho, axis=1)
    dist = scenario_module.check_dynamic_reels(scenario, robot)
    return L, rho / L[:, None], dist.tensions


@covers("RobotSchema.cables.EA")
def test_cables_EA_sets_the_start_stretch(tmp_path):
    """EA 41 kN (default 70 kN): the plant pays out L0 with L - L0 = T L0 / EA at the start
    distribution T (tension.py's unstretched_lengths, solved here by hand: L0 = L EA/(EA + T)),
    the encoders log that L0 (encoder_zero: unstretched; homed ones read L), and the cables'
    elastic law gives back T from it."""
    s = _dynamic(robot=_paper_with(tmp_path, "cables: {EA: 41000.0}"), lock_rotation=True,
                 encoder_zero="unstretched")
    L, _, T0 = _start_geometry(s)
    log = sim(s, 0.004)
    L0 = L * 41000.0 / (41000.0 + T0)
    np.testing.assert_allclose(log["lengths"][0], L0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(log["tensions"][0], T0, rtol=1e-9)
    # With the default EA the stretch would differ by > 0.1 mm (100 000 x the tolerance).
    assert np.abs(L * 70000.0 / (70000.0 + T0) - L0).max() > 1e-4


@covers("RobotSchema.cables.damping")
def test_cables_damping_adds_its_force_to_a_knocked_platform_and_decays_it(tmp_path):
    """Damping 33 N s/m (default 20). Knocked at v = [0.03, -0.02, 0.04] m/s (rotation
    locked), each cable at once carries T_i + c dL_i, dL_i = -u_i . v (cable_tensions; the
    reels still). Over 0.1 s the knock decays faster than with damping 3 N s/m."""
    def knocked(c, duration):
        s = _dynamic(robot=_paper_with(tmp_path, f"cables: {{damping: {c}}}", f"c{c}.yaml"),
                     lock_rotation=True)
        diagram, simulator, _ = _plant_alone(s)
        mbp, mbp_context = _sub(diagram, simulator, "platform_plant")
        mbp.SetVelocities(mbp_context, v)
        T_knocked = ground_truth_now(diagram, simulator.get_context())["tensions"]
        simulator.AdvanceTo(duration)
        return s, T_knocked, mbp.GetVelocities(mbp_context)

    v = np.array([0.03, -0.02, 0.04])
    s, T_knocked, v_end = knocked(33.0, 0.1)
    _, u, T0 = _start_geometry(s)
    np.testing.assert_allclose(T_knocked, T0 + 33.0 * (-u @ v), rtol=0, atol=1e-9)
    assert np.abs(20.0 * (-u @ v) - 33.0 * (-u @ v)).max() > 0.1  # the default: 0.1 N off
    _, _, v_light = knocked(3.0, 0.1)
    assert np.linalg.norm(v_end) < 0.5 * np.linalg.norm(v_light)


# The reel drive's closed form (reel_step, cables.py): inertia dw/dt = K (u - w) - b w
# - F_c sgn w, K = bandwidth * inertia, stepped implicitly with h. From rest under a constant
# command u with |K u| > F_c the reel never reverses, so each step is
# w' = (J w + h K u - h F_c sgn u) / (J + h (K + b)): w_n = w_inf (1 - r^n), w_inf = (K u - F_c
# sgn u) / (K + b), r = J / (J + h (K + b)). With |K u| <= F_c it sticks: w_n = 0.
def _drive_closed_form(u, n, h, *, bandwidth, inertia, viscous, coulomb):
    u = np.asarray(u, dtype=float)
    K = bandwidth * inertia
    w_inf = (K * u - coulomb * np.sign(u)) / (K + viscous)
    r = inertia / (inertia + h * (K + viscous))
    return np.where(np.abs(K * u) <= coulomb, 0.0, w_inf * (1.0 - r ** n))


def _reel_speeds_after(scenario, command, duration):
    """The reel drives' speeds (m/s, their state) after `duration` s of a constant command."""
    diagram, simulator, _ = _plant_alone(scenario, command)
    simulator.AdvanceTo(duration)
    return plant_state_now(diagram, simulator.get_context())["reel_speeds"]


FRICTIONLESS = "reel_drives: {viscous_friction: 0.0, coulomb_friction: 0.0"
COMMAND = [0.012, -0.009, 0.006, -0.011, 0.004, 0.010, -0.007]  # m/s, within every limit


@covers("RobotSchema.reel_drives.bandwidth")
def test_reel_bandwidth_sets_the_velocity_step_response(tmp_path):
    """Bandwidth 37 rad/s (default 100), no friction: the implicit first-order loop gives
    w_n = u (1 - (1 + h bw)^-n), within 2 % of 1 - exp(-bw t): after 20 steps of 1 ms (the
    reels' updates up to t = 0.02 s), 51.6 % of the command (default: 85.1 %)."""
    s = _dynamic(robot=_paper_with(tmp_path, FRICTIONLESS + ", bandwidth: 37.0}"),
                 lock_rotation=True)
    w = _reel_speeds_after(s, COMMAND, 0.02)
    fraction = 1.0 - 1.037 ** -20
    assert fraction == pytest.approx(1.0 - np.exp(-37.0 * 0.02), rel=0.02)
    np.testing.assert_allclose(w, fraction * np.array(COMMAND), rtol=1e-12, atol=1e-15)
    assert 1.0 - 1.1 ** -20 - fraction > 0.3


@covers("RobotSchema.reel_drives.inertia", "RobotSchema.reel_drives.viscous_friction",
        "RobotSchema.reel_drives.coulomb_friction")
def test_reel_inertia_and_friction_set_the_drive_response(tmp_path):
    """Inertia 0.41 kg, viscous 1.7 N s/m, Coulomb 0.23 N (defaults 0.25, 0.25, 0.125),
    bandwidth 100: K = 41 N s/m, so cable 5's 4 mm/s (K u = 0.164 N < 0.23 N) sticks and the
    others follow `_drive_closed_form` (the expected numbers) after 30 steps. The step
    function itself matches the form, and each of the three at its default would move some
    reel's speed by > 100 x the tolerance."""
    params = dict(bandwidth=100.0, inertia=0.41, viscous=1.7, coulomb=0.23)
    expected = _drive_closed_form(COMMAND, 30, 0.001, **params)
    assert expected[4] == 0.0 and np.all(expected[[0, 1, 2, 3, 5, 6]] != 0.0)
    w = np.zeros(7)
    for _ in range(30):
        w = reel_step(w, np.array(COMMAND), 0.001, **params)
    np.testing.assert_allclose(w, expected, rtol=1e-12, atol=1e-15)
    s = _dynamic(robot=_paper_with(tmp_path, "reel_drives: {inertia: 0.41, "
                                   "viscous_friction: 1.7, coulomb_friction: 0.23}"),
                 lock_rotation=True)
    np.testing.assert_allclose(_reel_speeds_after(s, COMMAND, 0.03), expected,
                               rtol=1e-12, atol=1e-15)
    for key, default in (("inertia", 0.25), ("viscous", 0.25), ("coulomb", 0.125)):
        other = _drive_closed_form(COMMAND, 30, 0.001, **{**params, key: default})
        assert np.abs(other - expected).max() > 1e-5, key


@covers("Scenario.plant!DynamicReels.max_reel_speed")
def test_dynamic_plant_reel_speed_limit_scales_the_command(tmp_path):
    """Limit 0.0047 m/s (robot file 1.0): the command (peak 0.012) is scaled by 0.0047/0.012
    before the drives, which (no friction, bandwidth 100) then reach w_n = u' (1 - 1.1^-n):
    after 100 steps the fastest reel runs at 0.0047 m/s (to 7e-5 relative). In a closed-loop
    run the logged encoder lengths move at most that fast."""
    s = _dynamic(robot=_paper_with(tmp_path, FRICTIONLESS + "}"), lock_rotation=True,
                 max_reel_speed=0.0047)
    scaled = np.array(COMMAND) * (0.0047 / 0.012)
    w = _reel_speeds_after(s, COMMAND, 0.1)
    np.testing.assert_allclose(w, scaled * (1.0 - 1.1 ** -100), rtol=1e-12, atol=1e-15)
    assert np.abs(w).max() == pytest.approx(0.0047, rel=1e-4)
    # In the loop, an 8 N push asks for up to ~0.19 m/s of cable within 0.2 s; the encoder
    # lengths logged tick to tick never move faster than the limit, and reach it.
    log = sim(dataclasses.replace(s, operator=ScriptedOperator(times=[0.0],
                                                               forces=[[8.0, 0.0, 0.0]])), 0.2)
    assert np.abs(log["reel_velocity"]).max() > 0.1
    logged = np.abs(np.diff(log["lengths"], axis=0)).max(axis=1) / T
    assert logged.max() <= 0.0047 * (1 + 1e-9)
    assert logged[-1] == pytest.approx(0.0047, rel=1e-4)


@covers("Scenario.plant!DynamicReels.time_step")
def test_dynamic_plant_time_step_sets_the_steps_per_tick(tmp_path):
    """time_step 0.0005 s (default 0.001): the MultibodyPlant is discrete at 0.5 ms, and the
    reel drives take 4 steps per 2 ms tick: after 0.02 s (40 steps, no friction, bandwidth
    100) the reels are at 1 - 1.05^-40 = 85.80 % of the command (20 steps of 1 ms: 85.14 %).
    0.0015 s does not divide the 2 ms control period: refused."""
    s = _dynamic(robot=_paper_with(tmp_path, FRICTIONLESS + "}"), lock_rotation=True,
                 time_step=0.0005)
    diagram, _, _ = _plant_alone(s)
    mbp = diagram.GetSubsystemByName("reels").GetSubsystemByName("platform_plant")
    assert mbp.time_step() == 0.0005
    w = _reel_speeds_after(s, COMMAND, 0.02)
    np.testing.assert_allclose(w, (1.0 - 1.05 ** -40) * np.array(COMMAND), rtol=1e-12,
                               atol=1e-15)
    assert (1.0 - 1.05 ** -40) - (1.0 - 1.1 ** -20) > 6e-3
    with pytest.raises(ScenarioError, match=r"plant\.time_step 0\.0015 s must divide"):
        scenario_module.check_scenario(_dynamic(time_step=0.0015))


@covers("Scenario.plant!DynamicReels.max_length_residual")
def test_dynamic_plant_max_length_residual_bounds_the_forward_kinematics_misfit():
    """The start's encoder lengths L0 = L EA/(EA + T) (unstretched) do not fit a rigid
    translating platform: forward_kinematics' best fit leaves 0.70 mm on cable 4 (re-measured
    for issue 18's recalibrated robot). A limit of 0.65 mm refuses them; 0.75 mm accepts (the
    default 20 mm would accept both). The encoders read unstretched here (`encoder_zero:
    unstretched`); homed ones read the rigid lengths at the start, which fit exactly."""
    s = _dynamic(encoder_zero="unstretched")
    L, _, T0 = _start_geometry(s)
    L0 = L * 70000.0 / (70000.0 + T0)
    with pytest.raises(KinematicsError, match=r"residual of 0\.700\d mm on cable 4"):
        forward_kinematics(scenario_robot(s), L0, max_residual=0.00065)
    forward_kinematics(scenario_robot(s), L0, max_residual=0.00075)
    with pytest.raises(KinematicsError, match=r"allowed 0\.65 mm"):
        sim(_dynamic(max_length_residual=0.00065, encoder_zero="unstretched"), 0.004)
    sim(_dynamic(max_length_residual=0.00075, encoder_zero="unstretched"), 0.004)


def _first_step_angular_velocity(tmp_path, platform, force, name):
    """The free platform's angular velocity w_WB (rad/s, base frame) after its first 1 ms
    step under a constant hand force, with `platform` (a YAML mapping) in the robot file. At
    the start the cables and gravity balance exactly (tests/systems/test_dynamic_plant.py), and at
    v = 0 the discrete MultibodyPlant's step is v_1 = h M^-1 f: w_1 = h I^-1 (h_pt x F)."""
    s = dataclasses.replace(
        _dynamic(robot=_paper_with(tmp_path, f"platform: {platform}", name)),
        operator=ScriptedOperator(times=[0.0], forces=[list(force)]))
    diagram, simulator, _ = _plant_alone(s)
    simulator.AdvanceTo(0.001)
    mbp, context = _sub(diagram, simulator, "platform_plant")
    return mbp.GetVelocities(context)[:3]


@covers("RobotSchema.platform.handle")
def test_platform_handle_is_where_the_hand_force_acts(tmp_path):
    """Handle [0.11, 0.06, 0] m (default [0, 0, -0.15], on the line of an upward force: no
    moment): 4 N up gives the moment h x F = [0.24, -0.44, 0] N m, and after one 1 ms step
    w = h tau / 0.0525 kg m^2; the handle on the other side turns the platform the other way."""
    F = [0.0, 0.0, 4.0]
    tau = np.cross([0.11, 0.06, 0.0], F)
    np.testing.assert_allclose(tau, [0.24, -0.44, 0.0], atol=1e-15)
    w = _first_step_angular_velocity(tmp_path, "{handle: [0.11, 0.06, 0.0]}", F, "h1.yaml")
    np.testing.assert_allclose(w, 0.001 * tau / 0.0525, rtol=0, atol=1e-9)
    w_other = _first_step_angular_velocity(tmp_path, "{handle: [-0.11, -0.06, 0.0]}", F,
                                           "h2.yaml")
    np.testing.assert_allclose(w_other, -w, rtol=0, atol=1e-9)
    assert np.abs(w).max() > 5e-3  # 5000 x the tolerance


@covers("RobotSchema.platform.inertia")
def test_platform_inertia_sets_the_rotation_rate_under_a_moment(tmp_path):
    """Inertia with distinct diagonal and off-diagonal entries (default 0.0525 I): the hand's
    moment tau = h_pt x F (default handle [0, 0, -0.15], F = [2, -3, 1] N) turns the platform
    at w = h I^-1 tau after one 1 ms step (the full matrix: its diagonal alone, or the default,
    gives another w)."""
    I = np.array([[0.051, 0.004, -0.003], [0.004, 0.043, 0.002], [-0.003, 0.002, 0.058]])
    F = [2.0, -3.0, 1.0]
    tau = np.cross([0.0, 0.0, -0.15], F)
    w = _first_step_angular_velocity(tmp_path, f"{{inertia: {I.tolist()}}}", F, "I.yaml")
    expected = 0.001 * np.linalg.solve(I, tau)
    np.testing.assert_allclose(w, expected, rtol=0, atol=1e-9)
    for wrong in (np.diag(np.diag(I)), 0.0525 * np.eye(3)):
        assert np.abs(0.001 * np.linalg.solve(wrong, tau) - expected).max() > 1e-5


# --- the robot file's optional fields ---------------------------------------------------


def _robot_file(tmp_path, valid_spec, **extra):
    valid_spec.update(extra)
    path = tmp_path / "robot.yaml"
    path.write_text(to_yaml(valid_spec) + "\n")
    return path


# The tetra robot of conftest: box [1, 0.5, 0.5]..[3, 2.5, 2.5] m, centre [2, 1.5, 1.5].
TETRA_P0 = [2.0, 1.5, 1.5]
# Its centre lies over the line between the upper reels 1 and 3 (y = 0.75 x), so no tensions
# hold it with every cable above zero (kappa -3 N with the 3 N floor), and a push makes it
# worse: the kinetostatic barrier would rightly cap the speed at LOST_SPEED. The limit tests
# below test the robot file's limits, so they leave that barrier out.
NO_KINETOSTATIC = SafetyFilter(kinetostatic=False)


@covers("RobotSchema.limits.max_velocity", "RobotSchema.limits.max_acceleration")
def test_robot_file_speed_and_acceleration_limits_reach_the_limits(tmp_path, valid_spec):
    """Speed 0.11 m/s and acceleration 0.9 m/s^2 in the file (swapped, 0.9 m/s would never be
    reached and 0.11 m/s^2 would allow only 0.00022 m/s per tick)."""
    path = _robot_file(tmp_path, valid_spec,
                       limits={"max_velocity": 0.11, "max_acceleration": 0.9})
    log = sim(push([20.0, 0, 0], robot=str(path), initial_position=TETRA_P0,
                   safety_filter=NO_KINETOSTATIC), 0.4)
    speed = np.linalg.norm(log["velocity"], axis=1)
    assert speed.max() == pytest.approx(0.11, abs=1e-9)
    step = np.linalg.norm(np.diff(log["velocity"], axis=0), axis=1)
    assert step.max() == pytest.approx(0.9 * T, rel=1e-9)


@covers("RobotSchema.limits.max_reel_speed")
def test_robot_file_reel_speed_limit_reaches_the_reels(tmp_path, valid_spec):
    path = _robot_file(tmp_path, valid_spec, limits={"max_reel_speed": 0.037})
    log = sim(push([8.0, 0, 0], robot=str(path), initial_position=TETRA_P0,
                   safety_filter=NO_KINETOSTATIC), 0.4)
    assert np.abs(log["reel_velocity"]).max() > 0.1
    assert _reel_speeds(log).max() == pytest.approx(0.037, rel=1e-3)


def test_robot_file_reel_speed_limit_scales_what_the_real_reels_are_sent(tmp_path):
    """The same limit on the robot: paper_7cable with max_reel_speed 0.031 m/s and a 6 N push
    (which asks for ~0.3 m/s of cable). Every velocity sent is scaled to the limit (the
    emulated bridge, given the same robot, would latch OVERSPEED above it)."""
    spec = _paper_spec()
    spec["limits"] = {"max_reel_speed": 0.031}
    path = tmp_path / "slow_reels.yaml"
    path.write_text(to_yaml(spec) + "\n")
    robot = load_robot(path)
    bridge = ReelBridge(robot, cable_lengths(robot, np.array(P0)), time_constant=0.0,
                        force=lambda t, p, v: np.array([6.0, 0.0, 0.0]))
    server = ReelBridgeServer(bridge, address=("127.0.0.1", 0), command_timeout=5.0).start()
    try:
        scenario = dataclasses.replace(_hw(server.address[1]), robot=str(path))
        result = _run(tmp_path, scenario, duration=0.4)
        _settle(server)
    finally:
        server.stop()
    assert result.ending == "completed", result.error
    assert np.abs(result.log["reel_velocity"]).max() > 0.1  # the diagram asks for more
    sent = max(np.abs(c.velocity).max() for c in server.commands)
    assert sent == pytest.approx(0.031, rel=1e-9)


def _paper_spec():
    """paper_7cable's description as Python data (from the shipped file)."""
    from pydrake.common.yaml import yaml_load

    from cdpm_drake.robot import resolve_robot_path

    return yaml_load(filename=str(resolve_robot_path("paper_7cable")))


@covers("RobotSchema.workspace.lower", "RobotSchema.workspace.upper")
@pytest.mark.parametrize("direction", [+1, -1])
def test_robot_file_workspace_is_the_virtual_wall(tmp_path, valid_spec, direction):
    """A box of x in [1.93, 2.04] m: pushing +x stops at 2.04, pushing -x at 1.93."""
    valid_spec["workspace"] = {"lower": [1.93, 0.5, 0.5], "upper": [2.04, 2.5, 2.5]}
    path = _robot_file(tmp_path, valid_spec)
    # The virtual wall of the limits block alone (the safety filter's box, issue 26, brakes
    # on a gentler curve and would not reach the face in the time).
    log = sim(push([6.0 * direction, 0, 0], robot=str(path), initial_position=TETRA_P0,
                   safety_filter=SafetyFilter(enabled=False)), 0.6)
    np.testing.assert_array_equal(log["workspace_lower"], [1.93, 0.5, 0.5])
    x = log["p"][:, 0]
    face = 2.04 if direction > 0 else 1.93
    assert abs(x[-1] - face) < 1e-3  # it got there
    assert (x <= 2.04 + 1e-9).all() and (x >= 1.93 - 1e-9).all()  # and never through


@covers("RobotSchema.ignore_pairs")
def test_ignore_pairs_removes_the_pair_from_the_watched_ones(tmp_path, valid_spec):
    path = _robot_file(tmp_path, valid_spec, ignore_pairs=[[2, 4]])
    log = sim(base(robot=str(path), initial_position=TETRA_P0,
                   interference=Interference()), 0.004)
    pairs = [tuple(p) for p in log["pairs"]]
    assert pairs == [(1, 2), (1, 3), (1, 4), (2, 3), (3, 4)]
    assert log["pair_distances"].shape == (3, 5)


@covers("RobotSchema.cable_diameter")
def test_cable_diameter_reaches_the_robot(tmp_path, valid_spec):
    # Informative only (documents the margin d_l must cover): it lands on Robot.cable_diameter.
    robot = load_robot(_robot_file(tmp_path, valid_spec, cable_diameter=0.0023))
    assert robot.cable_diameter == 0.0023
    with pytest.raises(Exception, match="cable_diameter"):
        load_robot(_robot_file(tmp_path, valid_spec, cable_diameter=-0.001))


# --- !HardwareReels: short real-time runs against an in-process emulated bridge -----------------


def _free_port(host):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def _bridge(address="127.0.0.1", offset=None, force=None, **server):
    robot = load_robot("paper_7cable")
    lengths = cable_lengths(robot, np.array(P0))
    if offset is not None:
        lengths = lengths + offset
    bridge = ReelBridge(robot, lengths, force=force, time_constant=0.0)
    # The bridge's own command watchdog widened too: a stalled controller is not the point.
    server.setdefault("command_timeout", 5.0)
    return ReelBridgeServer(bridge, address=(address, 0), **server).start()


def _hw(port, **fields):
    """`base` with a !HardwareReels plant; the watchdog is widened to 1 s (this host is
    shared) unless the test sets it."""
    cfg = dict(port=port, watchdog_ticks=500, ramp_time=0.0)
    cfg.update(fields)
    return base(plant=HardwareReels(**cfg))


def _run(tmp_path, scenario, duration=0.1, name="run"):
    return realtime_run(scenario=scenario, out_dir=tmp_path / name, duration=duration)


@covers("Scenario.plant=!HardwareReels", "Scenario.plant!HardwareReels.address",
        "Scenario.plant!HardwareReels.port")
def test_hardware_address_and_port_reach_the_link(tmp_path):
    # The bridge on 127.0.0.2 (not the default 127.0.0.1) at an ephemeral port (not 47100).
    server = _bridge("127.0.0.2")
    try:
        host, port = server.address
        result = _run(tmp_path, _hw(port, address=host))
        _settle(server)
    finally:
        server.stop()
    assert result.ending == "completed", result.error
    assert server.counters["commands_received"] > 10


_HF = "Scenario.plant!HardwareReels.force_sensor"


@covers(_HF + "=!BridgeForce", _HF + "=!NetFT", _HF + "!NetFT.address", _HF + "!NetFT.port",
        _HF + "!NetFT.local_address", _HF + "!NetFT.counts_per_force", _HF + "!NetFT.axes",
        _HF + "!NetFT.tare_samples", _HF + "!NetFT.startup_timeout",
        _HF + "!NetFT.missed_ticks")
def test_hardware_force_sensor_reaches_the_diagrams_measured_force(tmp_path):
    """The bridge's status carries a hand of [2, 0, 0] N; a Net F/T on the same plant, in
    axes [+y, -z, -x] with 500 counts per N and a bias of [1, -1, 0.5] N of its own, a hand
    of [-3, 5, 1.5] N from its 51st record on. !BridgeForce logs the status's force; !NetFT
    the box's, tared (the bias gone) and mapped back to the base frame."""
    from cdpm_drake.emulator.netft import NetFTServer
    from cdpm_drake.hardware.force_config import BridgeForce, NetFT

    status_hand, box_hand = np.array([2.0, 0.0, 0.0]), np.array([-3.0, 5.0, 1.5])
    server = _bridge(force=lambda t, p, v: status_hand)
    # The box's hand: nothing for the tare (its first records), then box_hand.
    box = NetFTServer(server.bridge, address=("127.0.0.1", 0), counts_per_force=500.0,
                      axes=["+y", "-z", "-x"], bias=[1.0, -1.0, 0.5],
                      hand=lambda: box_hand if box.records_sent > 50 else np.zeros(3)).start()
    try:
        sensor = NetFT(address="127.0.0.1", port=box.address[1], local_address="127.0.0.1",
                       counts_per_force=500.0, axes=["+y", "-z", "-x"], tare_samples=7,
                       startup_timeout=1.0, missed_ticks=400)
        bridge_run = _run(tmp_path, _hw(server.address[1], force_sensor=BridgeForce()),
                          name="bridge")
        _settle(server)
        server.bridge.reset()
        box_run = _run(tmp_path, _hw(server.address[1], force_sensor=sensor), duration=0.6,
                       name="box")
    finally:
        server.stop()
        box.stop()
    assert bridge_run.ending == "completed" and box_run.ending == "completed", box_run.error
    np.testing.assert_array_equal(bridge_run.log["F_measured"][-1], status_hand)
    # The box's last samples: its hand, to the counts' 1/500 N (whole counts here: exact).
    np.testing.assert_allclose(box_run.log["F_measured"][-1], box_hand, atol=1e-12)
    assert not np.any(np.all(box_run.log["F_measured"] == status_hand, axis=1))


@covers("Scenario.plant!HardwareReels.local_address", "Scenario.plant!HardwareReels.local_port")
def test_hardware_local_address_and_port_bind_the_controller(tmp_path):
    # A bridge that answers only 127.0.0.3:<port> and ignores everyone else: the run works only
    # if the controller's socket is bound exactly there.
    local = ("127.0.0.3", _free_port("127.0.0.3"))
    server = _bridge(controller=local)
    try:
        result = _run(tmp_path, _hw(server.address[1], local_address=local[0],
                                    local_port=local[1]))
        _settle(server)
    finally:
        server.stop()
    assert result.ending == "completed", result.error
    assert server.counters["commands_foreign"] == 0
    assert server.counters["commands_received"] > 10


@covers("Scenario.plant!HardwareReels.startup_timeout")
def test_hardware_startup_timeout_bounds_the_wait_for_a_silent_bridge(tmp_path):
    port = _free_port("127.0.0.1")  # nobody listens there
    start = time.monotonic()
    result = _run(tmp_path, _hw(port, startup_timeout=0.35))
    waited = time.monotonic() - start
    assert result.ending == "fault"
    assert "startup_timeout = 0.35 s" in str(result.error)
    assert 0.35 <= waited < 2.0  # the default 2 s would wait longer


@covers("Scenario.plant!HardwareReels.watchdog_ticks")
def test_hardware_watchdog_ticks_sets_the_silence_that_faults():
    """The bridge stops sending 0.1 s after enabling: the run faults on exactly the 9th silent
    tick (watchdog_ticks = 9; the default is 3).

    The fault needs N silent ticks and (N - 1) T = 16 ms of wall time since the last status
    (the guard against catch-up bursts after a host stall). The diagram runs here at a
    quarter of real time (a tick every 8 ms of wall time), so the wall-time guard is met
    after 3 ticks and the count alone decides; only a stall of ~60 ms right at the fault
    could delay it, so a run that faults later than the 9th tick is repeated, twice."""
    from pydrake.systems.analysis import Simulator

    from cdpm_drake.diagram import build_diagram
    from cdpm_drake.hardware.reels import ReelFault, start_realtime

    counts = []
    for attempt in range(3):
        server = _bridge(faults=FaultPlan(stop=True, after=0.1))
        diagram = build_diagram(_hw(server.address[1], watchdog_ticks=9))
        reels = diagram.GetSubsystemByName("reels")
        simulator = Simulator(diagram)
        try:
            start_realtime(simulator, 0.25)
            with pytest.raises(ReelFault) as fault:
                simulator.AdvanceTo(1.0)
        finally:
            reels.close()
            server.stop()
        message = str(fault.value)
        assert "watchdog_ticks = 9" in message
        counts.append(int(message.split(" for ")[1].split(" ticks")[0]))
        # It stopped right after the bridge did (0.1 s + 9 ticks, in diagram time).
        assert simulator.get_context().get_time() < 0.3
        if counts[-1] == 9:
            break
    assert counts[-1] == 9, counts


def _settle(server, quiet=0.1, timeout=3.0):
    """Wait until the bridge has read every datagram sent to it (none new for `quiet` s): on a
    busy host its thread may still be behind when the run returns."""
    deadline = time.monotonic() + timeout
    count, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        n = server.counters["commands_received"] + server.counters["commands_dropped"]
        if n != count:
            count, since = n, time.monotonic()
        elif time.monotonic() - since >= quiet:
            return
        time.sleep(0.01)


def _enabled_commands(server):
    return [c for c in server.commands if c.enable]


@covers("Scenario.plant!HardwareReels.ramp_time")
def test_hardware_ramp_time_ramps_the_sent_velocity(tmp_path):
    """A 3 N push: the velocity sent is ramp * command, the ramp rising by T / ramp_time = 1/60
    per tick (ramp_time 0.12 s): about half-way at 0.06 s, full from 0.12 s on."""
    server = _bridge(force=lambda t, p, v: np.array([3.0, 0.0, 0.0]))
    try:
        result = _run(tmp_path, _hw(server.address[1], ramp_time=0.12), duration=0.3)
        _settle(server)
    finally:
        server.stop()
    assert result.ending == "completed", result.error
    log = result.log
    ratios = []
    for c in _enabled_commands(server):
        k = int(round(c.command_time / T))
        wanted = log["reel_velocity"][k]
        if np.abs(wanted).max() > 1e-4:
            ratios.append((c.command_time, np.abs(c.velocity).max() / np.abs(wanted).max()))
    ratios = np.array(ratios)
    mid = ratios[np.abs(ratios[:, 0] - 0.06) < 0.003, 1]
    late = ratios[ratios[:, 0] > 0.14, 1]
    assert mid.size and np.all(np.abs(mid - 0.5) < 0.05), mid
    assert late.size and np.allclose(late, 1.0, atol=1e-9)


@covers("Scenario.plant!HardwareReels.max_length_residual")
def test_hardware_max_length_residual_refuses_lengths_that_do_not_fit(tmp_path):
    """Cable 1 reported 6 mm long: the best fit's residual is within 5 mm (the former
    default; checked here with the same forward kinematics), but not within 2.1 mm: refused."""
    offset = np.zeros(7)
    offset[0] = 0.006
    robot = load_robot("paper_7cable")
    forward_kinematics(robot, cable_lengths(robot, np.array(P0)) + offset, max_residual=0.005)
    server = _bridge(offset=offset)
    try:
        result = _run(tmp_path, _hw(server.address[1], max_length_residual=0.0021))
        _settle(server)
    finally:
        server.stop()
    assert result.ending == "fault"
    assert "max_length_residual = 0.0021 m" in str(result.error)
    assert not _enabled_commands(server)  # never enabled


@covers("Scenario.plant!HardwareReels.shutdown_repeats")
def test_hardware_shutdown_repeats_sets_the_final_zero_commands(tmp_path):
    # Every shutdown sends shutdown_repeats disabling zero commands; the run ends with whole
    # groups of 5 (the default 3 gives groups of 3).
    server = _bridge()
    try:
        result = _run(tmp_path, _hw(server.address[1], shutdown_repeats=5))
        _settle(server)
    finally:
        server.stop()
    assert result.ending == "completed", result.error
    commands = list(server.commands)
    last_enabled = max(k for k, c in enumerate(commands) if c.enable)
    trailing = commands[last_enabled + 1:]
    assert all(not c.enable and not np.any(c.velocity) for c in trailing)
    assert len(trailing) >= 5 and len(trailing) % 5 == 0, len(trailing)


@covers("Scenario.plant!HardwareReels.tension_sensor")
def test_hardware_tension_sensor_reaches_the_reels(monkeypatch):
    """The scenario's sensor is the one the reels measure with: on a scripted version-2 link
    (tests/helpers_scripted_link.py) whose load cells read 10 + cable number N, `load_cell`
    logs exactly those, `none` NaN; a sensor that does not exist is refused by its field."""
    from pydrake.systems.analysis import Simulator

    from cdpm_drake.diagram import build_diagram
    from helpers_scripted_link import ScriptedLink, answering, install

    cells = 10.0 + np.arange(1, 8)

    class CellLink(ScriptedLink):  # a version-2 bridge with load cells, no drive readings
        def _status(self, *args):
            return dataclasses.replace(
                super()._status(*args), version=2, load_cell=cells,
                drive_force=np.full(7, np.nan), reel_speed=np.full(7, np.nan))

    lengths = cable_lengths(load_robot("paper_7cable"), np.array(P0))
    for sensor in ("load_cell", "none"):
        diagram = build_diagram(_hw(47100, tension_sensor=sensor))
        reels = diagram.GetSubsystemByName("reels")
        link = CellLink(lengths, answering)
        install(monkeypatch, reels, link)
        simulator = Simulator(diagram)
        simulator.Initialize()
        simulator.AdvanceTo(0.02)
        got = reels.GetOutputPort("tension_measured").Eval(
            reels.GetMyContextFromRoot(simulator.get_context()))
        if sensor == "none":
            assert np.isnan(got).all()
        else:
            np.testing.assert_array_equal(got, cells)
    with pytest.raises(ValueError, match="tension_sensor"):
        build_diagram(_hw(47100, tension_sensor="strain_gauge"))


@covers("Scenario.plant!HardwareReels.lockstep")
def test_hardware_lockstep_waits_for_each_answer(tmp_path):
    """`lockstep: true` in the scenario (no run option): against a lockstep bridge, which
    steps once per command and answers each, the run completes with one bridge tick per
    command (the greeting, ticks 0..50 of 0.1 s, the final stop's copies), its watchdog at
    the default 3 ticks; on wall clock the same watchdog and this shared host's stalls are
    what test_hardware_watchdog_ticks_is_the_trip_count is about."""
    server = _bridge(lockstep=True)
    try:
        result = _run(tmp_path, _hw(server.address[1], lockstep=True, watchdog_ticks=3))
        deadline = time.monotonic() + 3.0
        while server.tick < 1 + 51 + 3 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        server.stop()
    assert result.ending == "completed", result.error
    assert len(result.log["time"]) == 51
    assert server.tick == server.counters["commands_received"] == 1 + 51 + 3


@covers("Scenario.plant!HardwareReels.resume_within")
def test_hardware_resume_within_bounds_the_wait_for_the_bridge_after_a_stop(monkeypatch):
    """The scenario's diagram on a scripted link (tests/helpers_scripted_link.py: one period
    of clock per tick, no sockets): the bridge is silent from tick 50, the watchdog (3 ticks)
    stops the reels in tick 52's update, and the bridge answers the stop `gap` ticks later.
    resume_within = 6.5 ms (not the default 15 ms) takes an answer 3 ticks (6 ms) later and
    the run goes on; 4 ticks (8 ms) later the fault has latched."""
    from pydrake.systems.analysis import Simulator

    from cdpm_drake.diagram import build_diagram
    from cdpm_drake.hardware.reels import ReelFault
    from helpers_scripted_link import ScriptedLink, answering, install

    lengths = cable_lengths(load_robot("paper_7cable"), np.array(P0))
    for gap, resumes in ((3, True), (4, False)):
        diagram = build_diagram(_hw(47100, watchdog_ticks=3, resume_within=0.0065))
        reels = diagram.GetSubsystemByName("reels")
        link = ScriptedLink(lengths, lambda k, link, gap=gap: (
            [] if 50 <= k < 52 + gap else answering(k, link)))
        install(monkeypatch, reels, link)
        simulator = Simulator(diagram)
        simulator.Initialize()
        if resumes:
            simulator.AdvanceTo(0.2)
            book = reels.book(reels.GetMyContextFromRoot(simulator.get_context()))
            assert book["holds"] == 1 and book["fault"] == 0
        else:
            with pytest.raises(ReelFault, match=r"none answered the stop within "
                                                r"resume_within = 6.5 ms"):
                simulator.AdvanceTo(0.2)


@covers("Scenario.plant!HardwareReels.position_offset",
        "Scenario.plant!HardwareReels.homing_min_tension")
def test_hardware_homing_fields_reach_the_lengths_and_the_encoder_zero(monkeypatch):
    """A bridge whose encoders read 0.1-0.7 m short of the start pose's rigid lengths, on a
    scripted link (no sockets, no clock): position_offset brings its lengths to the rigid
    ones (without it the start check refuses them), and the encoder zero takes off each
    cable's stretch under the homing's tensions: the least-norm distribution holding the
    platform's weight at P0 with every cable >= homing_min_tension = 8 N (checked here by its
    balance and its floor), l T / (EA + T). The full pose's estimate starts on it."""
    from pydrake.systems.analysis import Simulator

    from cdpm_drake.config import homing_tensions
    from cdpm_drake.diagram import block_output_port, build_diagram
    from cdpm_drake.hardware.reels import ReelFault
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix
    from helpers_scripted_link import ScriptedLink, answering, install

    robot = load_robot("paper_7cable")
    rigid = cable_lengths(robot, np.array(P0))
    offset = np.linspace(0.1, 0.7, robot.num_cables)
    full = scenario_module.Controller(pose="full", tension_control=True)

    def run(**fields):
        scenario = dataclasses.replace(_hw(47100, tension_sensor="none", **fields),
                                       controller=full)
        diagram = build_diagram(scenario)
        install(monkeypatch, diagram.GetSubsystemByName("reels"),
                ScriptedLink(rigid - offset, answering))
        simulator = Simulator(diagram)
        simulator.Initialize()
        simulator.AdvanceTo(0.01)
        context = simulator.get_context()

        def value(block, name):
            port = block_output_port(diagram, block, name)
            return port.Eval(port.get_system().GetMyContextFromRoot(context)).copy()

        return scenario, {name: value(block, name) for block, name in (
            ("reels", "cable_lengths"), ("encoder_zero", "homing_stretch"),
            ("tension_distribution", "tension_estimate"))}

    with pytest.raises(ReelFault, match="position_offset"):
        run()
    scenario, out = run(position_offset=offset.tolist(), homing_min_tension=8.0)
    np.testing.assert_allclose(out["cable_lengths"], rigid, rtol=0, atol=1e-12)
    T = homing_tensions(scenario, robot)
    assert np.min(T) == pytest.approx(8.0, abs=1e-9)
    np.testing.assert_allclose(wrench_matrix(robot, np.array(P0)) @ T,
                               -gravity_wrench(robot.dynamics.mass), atol=1e-9)
    EA = robot.dynamics.EA
    np.testing.assert_allclose(out["homing_stretch"], rigid * T / (EA + T), rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["tension_estimate"], T, atol=1e-6)
    # The default floor (5 N) is another distribution.
    default = homing_tensions(dataclasses.replace(scenario, plant=HardwareReels()), robot)
    assert np.max(np.abs(default - T)) > 1.0


@covers("Scenario.plant!DynamicReels.encoder_zero",
        "Scenario.plant!CanopenReels.homing_min_tension")
def test_encoder_zero_and_canopen_homing_tension_reach_the_encoder_zero_block():
    """encoder_zero: homed (default) puts the encoder zero after the dynamic plant for the
    full pose with tension control, on the plant's start distribution (the controllers that
    take the cables as rigid read the homed lengths as they are); unstretched leaves it out
    (the plant then reads unstretched lengths: tests/systems/test_encoder_convention.py). A
    !CanopenReels plant's homing tensions take its homing_min_tension as their floor."""
    from cdpm_drake.config import DynamicReels, check_dynamic_reels, homing_tensions
    from cdpm_drake.diagram import build_diagram
    from cdpm_drake.hardware.canopen_config import CanopenReels

    full = scenario_module.Controller(pose="full", tension_control=True)
    homed = dataclasses.replace(_dynamic(), controller=full)
    robot = scenario_robot(homed)
    np.testing.assert_array_equal(homing_tensions(homed, robot),
                                  check_dynamic_reels(homed, robot).tensions)
    assert build_diagram(homed).HasSubsystemNamed("encoder_zero")
    assert not build_diagram(_dynamic()).HasSubsystemNamed("encoder_zero")
    unstretched = dataclasses.replace(_dynamic(encoder_zero="unstretched"), controller=full)
    assert homing_tensions(unstretched, robot) is None
    assert not build_diagram(unstretched).HasSubsystemNamed("encoder_zero")
    for floor in (5.0, 9.0):
        T = homing_tensions(base(plant=CanopenReels(homing_min_tension=floor)), robot)
        assert np.min(T) == pytest.approx(floor, abs=1e-9)
    with pytest.raises(ScenarioError, match="plant.encoder_zero"):
        check_dynamic_reels(dataclasses.replace(homed, plant=DynamicReels(
            encoder_zero="rigid")), robot)


# --- bad values are refused by field name, for every checked field -------------------------------


@pytest.mark.parametrize("changes, field", [
    (dict(admittance=Admittance(damping=0.0)), "admittance.damping"),
    (dict(admittance=Admittance(mass=-1.0)), "admittance.mass"),
    (dict(plant=SimulatedReels(max_reel_speed=0.0)), "plant.max_reel_speed"),
    (dict(plant=SimulatedReels(time_constant=-0.1)), "plant.time_constant"),
    (dict(wall_force=WallForce(enabled=True, margin=0.0)), "wall_force.margin"),
])
def test_a_bad_value_is_refused_naming_its_own_field(changes, field):
    with pytest.raises(ScenarioError, match=field.replace(".", r"\.")):
        scenario_module.check_scenario(base(**changes))


# --- the safety filter, the kinetostatic limit, the model monitor -----------------------------


def _across_1_3(scale=1.0):
    """A hand force of `scale` N at exp1's start along minus the gradient of pair (1,3)'s
    distance (central differences of the segment distance: across the pair's plane)."""
    from cdpm_drake.kernels.interference import pair_distances

    robot = scenario_robot(exp1())
    k, h, p = robot.pair_position(1, 3), 1e-6, np.array(P_EXP1)
    g = np.array([(pair_distances(robot, p + h * e)[k] - pair_distances(robot, p - h * e)[k])
                  / (2 * h) for e in np.eye(3)])
    return -scale * g / np.linalg.norm(g), g, robot, k


@covers("Scenario.interference.default.d_min", "Scenario.interference.pairs[].d_min",
        "Scenario.safety_filter.enabled")
def test_d_min_is_the_floor_the_filter_keeps_each_pair_at():
    """A 5 N push across pair (1,3) (kinematic plant: the distance is exact) stops where the
    pair's d_min says: the default's 53.5 mm, or pair (1,3)'s own 52.0 mm; every other pair
    logs the default. With the filter off the same push goes far below."""
    force, _, robot, k = _across_1_3(5.0)
    default = Logistic(d_l=0.055, d_u=0.061, d_min=0.0535)
    for pairs, floor in (([], 0.0535), ([PairLogistic(pair=[1, 3], d_min=0.052)], 0.052)):
        log = sim(push(force, swaps=[[1, 3]], initial_position=list(P_EXP1),
                       interference=Interference(default=default, pairs=pairs)), 3.0)
        expected = np.full(robot.num_pairs, 0.0535)
        expected[k] = floor
        np.testing.assert_array_equal(log["d_min"], expected)
        d = log["pair_distances"][:, k]
        assert floor - 1e-6 < d.min() < floor + 2e-5, (floor, d.min())
    off = sim(push(force, swaps=[[1, 3]], initial_position=list(P_EXP1),
                   interference=Interference(default=default),
                   safety_filter=SafetyFilter(enabled=False)), 1.5)
    assert off["pair_distances"][:, k].min() < 0.05 and "filter_status" not in off


@covers("Scenario.safety_filter.position_smoothing")
def test_pair_margin_is_the_closest_pair_above_d_min_at_the_smoothed_position():
    """docs/LOG_FORMAT.md: pair_margin is the smallest watched pair's distance above its d_min
    (none crossed here) at the filter's barrier position: the last one advanced by the last
    command and drawn towards the estimate by T / position_smoothing a tick
    (safety_filter.barrier_position; the estimate itself with 0 and on the first tick).
    Recomputed from the log (the estimate p, the command `velocity`) with the segment
    distances of interference.pair_distances, for the 5 N push of the test above, which takes
    pair 1-3 to its d_min."""
    from cdpm_drake.kernels.interference import pair_distances

    force, _, robot, k = _across_1_3(5.0)
    default = Logistic(d_l=0.055, d_u=0.061, d_min=0.0535)
    T = 0.002
    for tau in (0.0, 0.05):
        log = sim(push(force, swaps=[[1, 3]], initial_position=list(P_EXP1),
                       interference=Interference(default=default),
                       safety_filter=SafetyFilter(position_smoothing=tau)), 1.0)
        p, v = log["p"], log["velocity"]
        p_c = p.copy()
        for row in range(1, len(p)):
            ahead = p_c[row - 1] + T * v[row - 1]
            p_c[row] = ahead + (T / tau) * (p[row] - ahead) if tau else p[row]
        margin = np.array([(pair_distances(robot, q) - log["d_min"]).min() for q in p_c])
        np.testing.assert_allclose(log["pair_margin"][:, 0], margin, rtol=0, atol=1e-12)
        assert margin.min() < 0.001  # the push took a pair to its d_min
        if tau:  # the smoothed position is not the estimate
            assert np.abs(p_c - p).max() > 1e-8


@covers("Scenario.safety_filter.gamma")
def test_gamma_is_the_share_of_the_margin_a_tick_may_use():
    """Pushed down onto the lower z face (0.3 m; the cables hold 5 N there with margin): in
    the last tens of micrometres the filter's DCBF h_{k+1} >= (1 - gamma) h_k is what binds
    (the braking curves allow more there), so the gap shrinks by exactly 1 - gamma a tick
    (the kinematic plant moves p by T v to ~1e-4 relative). The barriers at the estimate
    itself (position_smoothing 0): the smoothed position lags the estimate by the FK's
    ~1e-4, which shows at 0.3 % in these ratios."""
    for gamma in (0.25, 0.37):
        log = sim(push([0, 0, -5.0], initial_position=[1.77, 2.4, 0.34],
                       safety_filter=SafetyFilter(gamma=gamma, position_smoothing=0.0)), 1.2)
        gap = log["p"][:, 2] - 0.3
        # (Below ~0.6 um the virtual wall's own curve, sqrt(2 a gap) - a T / 2, is zero.)
        # (Above ~1e-5 m the braking curve at the ringing bound's deceleration binds.)
        near = (gap[:-1] < 1e-5) & (gap[:-1] > 1e-6)
        assert near.sum() >= 3
        np.testing.assert_allclose(gap[1:][near] / gap[:-1][near], 1 - gamma, rtol=2e-3)


@covers("Scenario.safety_filter.return_speed")
def test_return_speed_brings_a_lost_margin_back_at_that_speed():
    """Pair (1,3) starts 56.08 mm apart with d_min 57.5 mm (a lost margin), no hand and no
    interference force: the filter alone moves the platform out along the pair's distance
    gradient, at return_speed once its ramp (0.9 a_max T a tick) is done."""
    _, g, _, k = _across_1_3()
    log = sim(base(swaps=[[1, 3]], initial_position=list(P_EXP1),
                   interference=Interference(enabled=False,
                                             default=Logistic(d_l=0.058, d_u=0.062,
                                                              d_min=0.0575)),
                   safety_filter=SafetyFilter(return_speed=0.013)), 0.2)
    v = log["velocity"][10:60]
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 0.013, rtol=1e-4)
    np.testing.assert_allclose(v / np.linalg.norm(v, axis=1)[:, None],
                               np.broadcast_to(g / np.linalg.norm(g), v.shape), atol=2e-3)


def _holdable_share(robot, p, force, floor):
    """kappa at p (level platform) with the hand force at the handle, by HiGHS (the margin
    of the floor and a 100 N ceiling, tests/kernels/test_kinetostatics.py)."""
    from conftest import highs_margin

    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix

    w = gravity_wrench(robot.dynamics.mass, force, robot.dynamics.handle)
    return highs_margin(wrench_matrix(robot, p), w, floor, 100.0)


@covers("Scenario.safety_filter.kinetostatic", "Scenario.safety_filter.kinetostatic_floor")
def test_the_kinetostatic_barrier_keeps_the_platform_where_its_cables_hold_it():
    """5 N along +x from P0 towards the x face, where the cables cannot hold the platform
    (HiGHS): with the barrier the platform stops where kappa (floor 2.7 N + 0.1 N per newton
    of hand: 3.2 N) is zero; the log's t_c - kappa is that floor. Without, it goes on."""
    robot = scenario_robot(base())
    on = sim(push([5.0, 0, 0], safety_filter=SafetyFilter(kinetostatic_floor=2.7)), 4.0)
    off = sim(push([5.0, 0, 0], safety_filter=SafetyFilter(kinetostatic=False)), 3.0)
    floor = 2.7 + 0.1 * 5.0
    # Where it comes closest to the limit (it then slides along it to the box's x face).
    closest = int(np.argmin(on["kappa"][:, 0]))
    end_on, end_off = on["p"][closest], off["p"][-1]
    assert abs(_holdable_share(robot, end_on, [5.0, 0, 0], floor)) < 0.1
    assert _holdable_share(robot, end_off, [5.0, 0, 0], floor) < -1.0
    assert "kappa" not in off and "F_kin" not in off
    # The hand force the block uses is the sensor's, a tick old.
    F_prev = np.vstack([np.zeros((1, 3)), on["F_H"][:-1]])
    np.testing.assert_allclose(on["t_c"] - on["kappa"],
                               2.7 + 0.1 * np.linalg.norm(F_prev, axis=1)[:, None], atol=1e-12)


@covers("Scenario.safety_filter.kinetostatic_force.enabled",
        "Scenario.safety_filter.kinetostatic_force.t_l",
        "Scenario.safety_filter.kinetostatic_force.t_u",
        "Scenario.safety_filter.kinetostatic_force.F_u",
        "Scenario.safety_filter.kinetostatic_force.eps")
def test_the_kinetostatic_cue_is_the_logistic_of_its_parameters():
    """The same push: |F_kin| is eq. 26 in tensions at t = kappa + kinetostatic_floor with
    eq. 28's steepness from t_l, t_u, F_u, eps (zero above t_u), and F_d = F_H + F_kin
    (interference off); off, F_d = F_H."""
    from cdpm_drake.config import KinetostaticForce

    cue = KinetostaticForce(t_l=3.3, t_u=6.1, F_u=2.2, eps=0.15)
    log = sim(push([5.0, 0, 0], safety_filter=SafetyFilter(kinetostatic_force=cue)), 6.0)
    t = log["kappa"][:, 0] + 3.0
    b = 2 * np.log((2.2 - 0.15) / 0.15) / (3.3 - 6.1)
    expected = np.where(t <= 6.1, 2.2 / (1 + np.exp(-b * (t - 0.5 * (3.3 + 6.1)))), 0.0)
    np.testing.assert_allclose(np.linalg.norm(log["F_kin"], axis=1), expected, atol=1e-9)
    assert (expected > 1.0).any() and (expected == 0.0).any()  # both sides of t_u
    np.testing.assert_allclose(log["F_d"], log["F_H"] + log["F_kin"], atol=1e-12)
    off = sim(push([5.0, 0, 0], safety_filter=SafetyFilter(
        kinetostatic_force=KinetostaticForce(enabled=False))), 0.2)
    np.testing.assert_array_equal(off["F_d"], off["F_H"])


def _monitor_fault(scenario, duration):
    result = simulate(scenario=scenario, duration=duration)
    return result.error, result.log


@covers("Scenario.model_monitor.enabled", "Scenario.model_monitor.unholdable",
        "Scenario.model_monitor.ticks")
def test_the_monitor_stops_a_hand_the_cables_cannot_hold_after_its_ticks():
    """At (0.55, 1.85, 2.2) m the cables cannot hold the platform's weight (HiGHS: t* =
    -13.9 N). With unholdable 5 N the run stops after exactly `ticks` ticks, naming the
    reason and t*; with 20 N, or the monitor off, it runs on."""
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix
    from conftest import highs_t_star

    from cdpm_drake.kernels.model_monitor import ModelFault

    p = [0.55, 1.85, 2.2]
    robot = scenario_robot(base())
    t_star = highs_t_star(wrench_matrix(robot, np.array(p)), gravity_wrench(robot.dynamics.mass))
    assert -15 < t_star < -5
    off = {"safety_filter": SafetyFilter(enabled=False)}
    for ticks in (3, 7):
        error, log = _monitor_fault(base(initial_position=p, model_monitor=ModelMonitor(
            unholdable=5.0, ticks=ticks), **off), 0.1)
        assert isinstance(error, ModelFault)
        # Counted from tick 0: the fault comes in tick ticks - 1, whose row is not logged.
        assert len(log["time"]) == ticks - 1
        assert f"leaves one at {t_star:.2f} N for {ticks} ticks" in str(error), str(error)
    for monitor in (ModelMonitor(unholdable=20.0), ModelMonitor(enabled=False)):
        error, log = _monitor_fault(base(initial_position=p, model_monitor=monitor, **off),
                                    0.1)
        assert error is None and len(log["time"]) == 51
    assert "model_status" not in log


@covers("Scenario.model_monitor.slack_length", "Scenario.model_monitor.holdable",
        "Scenario.model_monitor.slack_ticks", "Scenario.model_monitor.fit_tolerance",
        "Scenario.model_monitor.slack_tension")
def test_the_monitor_s_slack_and_fit_thresholds_reach_it():
    """Experiment 2 on the dynamic plant with the paper's open loop (its slack cables:
    tests/data/dynamic_reference/exp2_friction.yaml), the hand force judged holdable or not
    by `holdable`: the first slack fault comes slack_ticks - ticks ticks later where the
    statics are trusted; slack_length 30 mm hides the slack; fit_tolerance 0.2 mm is a misfit
    first. With tension control the estimate's slack_tension decides likewise."""
    from cdpm_drake.config import Controller, DynamicReels

    def run(monitor, **controller):
        scenario = load_scenario("exp2_interaction", None)
        scenario = dataclasses.replace(
            scenario, plant=DynamicReels(), safety_filter=SafetyFilter(enabled=False),
            controller=Controller(**({"length_gain": 0.0} | controller)),
            # The rules on the lengths and the estimate: the plant's measured tensions
            # (test_the_monitor_reads_measured_tensions_where_the_plant_has_them) left out.
            model_monitor=dataclasses.replace(monitor, measured_slack=0.0))
        return _monitor_fault(scenario, 12.0)

    fast, log_fast = run(ModelMonitor(holdable=1e9, slack_ticks=40, unholdable=1e9))
    slow, log_slow = run(ModelMonitor(holdable=-1e9, slack_ticks=40, unholdable=1e9))
    assert "is slack" in str(fast) and "is slack" in str(slow)
    assert "for 5 ticks" in str(fast) and "for 40 ticks" in str(slow)
    assert len(log_slow["time"]) - len(log_fast["time"]) == 40 - 5
    hidden, _ = run(ModelMonitor(holdable=1e9, slack_length=0.03, unholdable=1e9,
                                 fit_tolerance=1.0))
    assert hidden is None or "is slack" not in str(hidden)
    misfit, _ = run(ModelMonitor(fit_tolerance=0.0002, unholdable=1e9))
    assert "no longer fit" in str(misfit)
    # With tension control the slack is the estimate's: none below -1e6 N.
    est, _ = run(ModelMonitor(slack_tension=1e6, unholdable=1e9, fit_tolerance=1.0),
                 pose="full", tension_control=True, length_gain=40.0)
    assert est is None or "is slack" not in str(est)


@covers("Scenario.model_monitor.measured_slack")
def test_the_monitor_reads_measured_tensions_where_the_plant_has_them():
    """exp2's start on the dynamic plant, full pose and tension control, no hand: every cable
    is taut (5-25 N). A measured_slack above every tension (1000 N) calls the cable measured
    lowest slack after slack_ticks (t* holds the weight: the knock's allowance), naming its
    measured tension; 0 reads none, and without a sensor (NaN) the estimate decides: both
    run on."""
    from cdpm_drake.config import Controller, DynamicReels

    def run(plant, **monitor):
        scenario = dataclasses.replace(
            load_scenario("exp2_interaction", None), plant=plant,
            controller=Controller(pose="full", tension_control=True),
            operator=ScriptedOperator(times=[0.0, 1.0], forces=[[0.0] * 3, [0.0] * 3]),
            model_monitor=ModelMonitor(**monitor))
        return _monitor_fault(scenario, 0.2)

    fault, log = run(DynamicReels(), measured_slack=1000.0, slack_ticks=30)
    later, log_later = run(DynamicReels(), measured_slack=1000.0, slack_ticks=40)
    assert "is slack: its measured tension is" in str(fault) and "for 30 ticks" in str(fault)
    assert len(log_later["time"]) - len(log["time"]) == 40 - 30
    cable = int(str(fault).split("cable ")[1].split(" ")[0])
    assert cable - 1 == int(np.argmin(log["tension_measured"][-1]))
    assert run(DynamicReels(), measured_slack=0.0)[0] is None
    assert run(DynamicReels(tension_sensor="none"), measured_slack=1000.0)[0] is None


@covers("Scenario.model_monitor.overload")
def test_the_monitor_stops_a_cable_measured_above_its_overload():
    """exp2's start on the dynamic plant, the translating controller, no hand: its drive
    torques read 5-25 N. With the ceiling controller.max_tension at 10 N, overload 2 (20 N)
    stops the run after `ticks` ticks naming the cable read highest; 3 (30 N: above every
    reading) and 0 (off) run on, as does a plant without a tension sensor."""
    from cdpm_drake.config import Controller, DynamicReels

    def run(plant, overload):
        scenario = dataclasses.replace(
            load_scenario("exp2_interaction", None), plant=plant,
            controller=Controller(max_tension=10.0),
            safety_filter=SafetyFilter(kinetostatic_floor=3.0),
            operator=ScriptedOperator(times=[0.0, 1.0], forces=[[0.0] * 3, [0.0] * 3]),
            model_monitor=ModelMonitor(overload=overload))
        return _monitor_fault(scenario, 0.1)

    fault, log = run(DynamicReels(), 2.0)
    assert "is overloaded: its measured tension is" in str(fault), str(fault)
    assert "above 20 N" in str(fault) and "for 5 ticks" in str(fault)
    cable = int(str(fault).split("cable ")[1].split(" ")[0])
    assert cable - 1 == int(np.argmax(log["tension_measured"][-1]))
    assert (log["tension_measured"][:, cable - 1] > 20.0).all()
    _, quiet = run(DynamicReels(), 3.0)
    assert quiet["tension_measured"].max() < 30.0  # why 3 runs on
    assert run(DynamicReels(), 3.0)[0] is None and run(DynamicReels(), 0.0)[0] is None
    assert run(DynamicReels(tension_sensor="none"), 2.0)[0] is None


# --- the dynamic plant's tension sensor and the damping block ----------------------------------


def _sensed(duration=0.1, damping=False, **plant):
    """exp2's start on the dynamic plant under a hand, full pose and tension control, the
    damping off unless asked (then the sensor cannot change the motion: runs compare; the
    encoders unstretched, else the first measured tensions would set the encoders' zero)."""
    c = scenario_module.Controller(
        pose="full", tension_control=True,
        tension_damping=scenario_module.TensionDamping(enabled=damping))
    return sim(dataclasses.replace(
        _dynamic(**({"encoder_zero": "unstretched"} | plant)), controller=c,
        operator=ScriptedOperator(times=[0.0, 0.05], forces=[[0.0, 0.0, 0.0], [6.0, -4.0, 3.0]])),
        duration)


EXACT_DRIVE = dict(noise_std=0.0, quantum=0.0, filter_time_constant=0.0, inertia_error=0.0,
                   friction_error=0.0, friction_band=0.002)


@covers("Scenario.plant!DynamicReels.tension_sensor",
        "Scenario.plant!DynamicReels.drive_torque.noise_std",
        "Scenario.plant!DynamicReels.drive_torque.quantum",
        "Scenario.plant!DynamicReels.drive_torque.filter_time_constant",
        "Scenario.plant!DynamicReels.drive_torque.inertia_error",
        "Scenario.plant!DynamicReels.drive_torque.friction_error",
        "Scenario.plant!DynamicReels.drive_torque.friction_band")
def test_the_drive_torque_sensor_settings_reach_the_measured_tensions():
    """Each setting against the exact sensor (no noise, quantum, lag or model error) on the
    same motion: the noise's std, the quantum's bound, the filter's smoothing, the model
    errors and the friction band each change tension_measured, and only it."""
    from cdpm_drake.config import DriveTorqueSensor

    def run(**changes):
        return _sensed(tension_sensor="drive_torque",
                       drive_torque=DriveTorqueSensor(**(EXACT_DRIVE | changes)))

    exact = run()
    none = _sensed(tension_sensor="none")
    assert np.isnan(none["tension_measured"]).all()
    np.testing.assert_array_equal(none["tensions"], exact["tensions"])
    # The exact sensor is the true tension of the tick before within the drives' static
    # friction (0.125 N: a stuck reel's friction is anywhere in [-F_c, F_c]) and the reel's
    # inertia times its acceleration's change within the tick (two 1 ms plant steps; the
    # sensor takes the tick's mean): 0.2 N (tests/systems/test_tension_sensor.py has the
    # exact case to round-off).
    assert np.abs(exact["tension_measured"][1:] - exact["tensions"][:-1]).max() <= 0.2
    noisy = run(noise_std=0.8)["tension_measured"] - exact["tension_measured"]
    assert 0.6 < noisy[1:].std() < 1.0  # 49 x 7 samples of std 0.8 N
    coarse = run(quantum=0.5)["tension_measured"] - exact["tension_measured"]
    assert np.abs(coarse).max() <= 0.25 + 1e-9 and np.abs(coarse).max() > 0.1
    lagged = run(filter_time_constant=0.05)["tension_measured"]
    # A 50 ms lag is the first-order filter y_k = y_(k-1) + a (x_k - y_(k-1)), a = 1 -
    # exp(-T / 50 ms), of the drive force the exact sensor reads; recomputed here on the exact
    # reading. What the two leave between them is the reel model's inertia and friction terms,
    # which the sensor takes off after its filter (measured 0.54 N, against 10.9 N between
    # the lagged and the exact reading).
    a = 1.0 - np.exp(-0.002 / 0.05)
    expected = exact["tension_measured"].copy()
    for k in range(1, len(expected)):
        expected[k] = expected[k - 1] + a * (exact["tension_measured"][k] - expected[k - 1])
    apart = np.abs(lagged - exact["tension_measured"]).max()
    assert apart > 2.0, apart
    assert np.abs(lagged - expected).max() < 0.1 * apart
    for changes in ({"inertia_error": 1.0}, {"friction_error": 1.0}, {"friction_band": 0.2}):
        other = run(**changes)
        np.testing.assert_array_equal(other["tensions"], exact["tensions"])
        assert np.abs(other["tension_measured"] - exact["tension_measured"]).max() > 1e-3, changes


@covers("Scenario.plant!DynamicReels.load_cell.bandwidth",
        "Scenario.plant!DynamicReels.load_cell.bias_std",
        "Scenario.plant!DynamicReels.load_cell.noise_std")
def test_the_load_cell_settings_reach_the_measured_tensions():
    """A cell of bandwidth f is the first-order filter y_k = y_(k-1) + a (T_k - y_(k-1)),
    a = 1 - exp(-2 pi f T), on the true tensions, logged a tick later (recomputed here from
    the logged truth); its bias a constant offset per cable; its noise of the std asked."""
    from cdpm_drake.config import LoadCellSensor

    def run(**changes):
        cell = dict(noise_std=0.0, bias_std=0.0, bandwidth=3.0) | changes
        return _sensed(tension_sensor="load_cell", load_cell=LoadCellSensor(**cell))

    log = run()
    truth, measured = log["tensions"], log["tension_measured"]
    a = 1.0 - np.exp(-2.0 * np.pi * 3.0 * T)
    y = truth[0].copy()  # the cell starts at the start tensions
    expected = [y.copy()]
    for k in range(len(truth) - 1):
        y = y + a * (truth[k] - y)
        expected.append(y.copy())
    np.testing.assert_allclose(measured, np.array(expected), rtol=0, atol=1e-9)
    biased = run(bias_std=1.5)["tension_measured"] - measured
    np.testing.assert_allclose(biased, np.repeat(biased[:1], len(biased), axis=0), atol=1e-9)
    assert 0.3 < biased[0].std() and np.abs(biased[0]).max() < 6.0
    noisy = run(noise_std=0.4)["tension_measured"] - measured
    assert 0.3 < noisy[1:].std() < 0.5


@covers("Scenario.controller.tension_damping.enabled",
        "Scenario.controller.tension_damping.gain_scale")
def test_the_tension_damping_settings_reach_its_block():
    """Off: no block, no damping logged. The damping is linear in its gain until it changes
    the motion: its first two ticks (before the damped command reaches the sensor, a tick
    later and sampled a tick after that) at 2.5 x the gain are 2.5 x the damping at 1 x."""
    off = _sensed(duration=0.02)
    assert "reel_velocity_damping" not in off
    one = _sensed(duration=0.02, damping=True)
    c = scenario_module.Controller(
        pose="full", tension_control=True,
        tension_damping=scenario_module.TensionDamping(enabled=True, gain_scale=2.5))
    scaled = sim(dataclasses.replace(
        _dynamic(), controller=c, operator=ScriptedOperator(
            times=[0.0, 0.05], forces=[[0.0, 0.0, 0.0], [6.0, -4.0, 3.0]])), 0.02)
    first, second = one["reel_velocity_damping"][:2], scaled["reel_velocity_damping"][:2]
    assert np.abs(first).max() > 1e-6
    np.testing.assert_allclose(second, 2.5 * first, rtol=1e-9, atol=1e-15)


# --- the robot as built, a calibrated file ---------------------------------------------------


@covers("Scenario.plant!SimulatedReels.robot", "Scenario.plant!DynamicReels.robot")
def test_plant_robot_is_the_robot_the_plant_plays(tmp_path):
    """The plant plays plant.robot (exits moved 1 cm here) under the controller's file: the
    log's true geometry is that file's, the controller's the scenario's."""
    robot = load_robot("paper_7cable")
    spec = RobotSchema(name="as_built", reels=(robot.reels + 0.01).tolist(),
                       attachments=robot.attachments.tolist())
    spec.workspace.lower, spec.workspace.upper = (robot.workspace.lower.tolist(),
                                                  robot.workspace.upper.tolist())
    path = tmp_path / "as_built.yaml"
    path.write_text(to_yaml(dataclasses.asdict(spec)) + "\n")
    for plant in (SimulatedReels(robot=str(path)), DynamicReels(robot=str(path))):
        resolved = scenario_module.resolve_scenario(base(plant=plant))
        np.testing.assert_allclose(resolved.plant_robot.reels, robot.reels + 0.01)
        np.testing.assert_array_equal(resolved.robot.reels, robot.reels)
    log = sim(base(plant=SimulatedReels(robot=str(path))), 0.02)
    np.testing.assert_allclose(log["reels_true"], robot.reels + 0.01)


_ERROR_FIELDS = ("reels_std", "attachments_std", "encoder_offset_std", "EA_rel_std",
                 "mass_rel_std", "com_std", "seed")


@covers(*[f"Scenario.plant!{p}.model_error.{f}" for p in ("SimulatedReels", "DynamicReels")
          for f in _ERROR_FIELDS])
@pytest.mark.parametrize("plant", [SimulatedReels, DynamicReels])
def test_each_model_error_field_reaches_its_part_of_the_true_robot(plant):
    """Each standard deviation moves its own part only (the draw's order is fixed), the seed
    changes the draw and repeats it."""
    from cdpm_drake.config.plants import ModelError

    robot = load_robot("paper_7cable")

    def true(**error):
        resolved = scenario_module.resolve_scenario(base(plant=plant(
            model_error=ModelError(**error))))
        t = resolved.plant_robot
        return t, resolved.encoder_zero_error

    t, z = true(reels_std=0.01)
    assert np.abs(t.reels - robot.reels).max() > 1e-3 and np.all(t.attachments == robot.attachments)
    assert not np.any(z) and t.dynamics.EA == robot.dynamics.EA
    t, z = true(attachments_std=0.005)
    assert np.abs(t.attachments - robot.attachments).max() > 1e-4 and np.all(t.reels == robot.reels)
    t, z = true(encoder_offset_std=0.003)
    assert np.abs(z).max() > 1e-4 and np.all(t.reels == robot.reels)
    t, _ = true(EA_rel_std=0.2)
    assert t.dynamics.EA != robot.dynamics.EA and t.dynamics.mass == robot.dynamics.mass
    t, _ = true(mass_rel_std=0.1)
    assert t.dynamics.mass != robot.dynamics.mass and t.dynamics.EA == robot.dynamics.EA
    assert np.all(t.dynamics.com == 0.0)
    t, _ = true(com_std=0.01)
    assert np.abs(t.dynamics.com).max() > 1e-4 and t.dynamics.mass == robot.dynamics.mass
    assert np.all(t.reels == robot.reels)
    # Drawn last: the reels' draw is the one before the centre of mass existed.
    r, _ = true(reels_std=0.01, seed=4)
    rc, _ = true(reels_std=0.01, com_std=0.01, seed=4)
    assert np.all(r.reels == rc.reels) and np.any(rc.dynamics.com != 0)
    a, _ = true(reels_std=0.01, seed=1)
    b, _ = true(reels_std=0.01, seed=2)
    c, _ = true(reels_std=0.01, seed=1)
    assert np.any(a.reels != b.reels) and np.all(a.reels == c.reels)


@covers("Scenario.plant!SimulatedReels.max_length_residual")
def test_simulated_max_length_residual_is_the_forward_kinematics_bound():
    exact = scenario_module.resolve_scenario(base())
    assert exact.fk_max_residual == 1e-6
    given = scenario_module.resolve_scenario(base(plant=SimulatedReels(max_length_residual=0.03)))
    assert given.fk_max_residual == 0.03
    with pytest.raises(ScenarioError, match=r"plant\.max_length_residual"):
        scenario_module.resolve_scenario(base(plant=SimulatedReels(max_length_residual=-1.0)))


_CALIBRATION_FIELDS = ("calibrated_from", "created", "original", "poses", "encoder_std",
                       "reels_std", "attachments_std", "reels_std_in_frame",
                       "attachments_std_in_frame", "encoder_offsets", "encoder_offsets_std",
                       "residual_before", "residual_after", "not_identified",
                       "measured_poses")


@covers(*[f"RobotSchema.calibration.{f}" for f in _CALIBRATION_FIELDS])
def test_a_calibration_section_reaches_the_margins_and_cdpm_info(tmp_path, capsys):
    """The in-frame standard deviations are what the margins use (the absolute ones where a
    file states only those); every field shows in `cdpm info`."""
    from cdpm_drake.cli.cdpm import main as cdpm

    robot = load_robot("paper_7cable")
    spec = dataclasses.asdict(RobotSchema(name="calibrated", reels=robot.reels.tolist(),
                                          attachments=robot.attachments.tolist()))
    spec["workspace"] = {"lower": robot.workspace.lower.tolist(),
                         "upper": robot.workspace.upper.tolist()}
    spec["calibration"] = {
        "calibrated_from": ["runs/a", "runs/b"], "created": "2026-01-02T03:04:05+00:00",
        "original": "orig.yaml", "poses": 77, "encoder_std": 2e-4,
        "reels_std": [[0.02, 0.02, 0.02]] * 7, "attachments_std": [[0.0, 0.0, 0.0]] * 7,
        "reels_std_in_frame": [[0.0004, 0.0005, 0.0003]] * 7,
        "attachments_std_in_frame": [[0.0001, 0.0, 0.0]] * 7,
        "encoder_offsets": [0.001] * 7, "encoder_offsets_std": [0.0003] * 7,
        "residual_before": [0.004] * 7, "residual_after": [0.0001] * 7,
        "not_identified": ["reel 1 x", "reel 2 x"], "measured_poses": "tracker.yaml"}
    path = tmp_path / "calibrated.yaml"
    path.write_text(to_yaml(spec) + "\n")
    loaded = load_robot(path)
    np.testing.assert_allclose(loaded.uncertainty.cable_std(), np.hypot(0.0005, 0.0001))
    assert cdpm(["info", str(path), "--grid", "0.5"]) == 0
    out = capsys.readouterr().out
    for text in ("2026-01-02T03:04:05+00:00", "from 2 run(s), 77 poses", "orig.yaml",
                 "0.2 mm", "misfit 4.000 -> 0.100 mm", "reel exits up to 0.50 mm",
                 "attachment points up to 0.10 mm", "absolute: up to 20.0 mm",
                 "+1.00, +1.00", "(+-0.30 mm)", "2 parameter(s) (reel 1 x, reel 2 x)",
                 "measured poses: tracker.yaml"):
        assert text in out, (text, out[:2000])
