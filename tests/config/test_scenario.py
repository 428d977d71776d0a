"""Typed scenarios: the shipped ones load and build; overlays change one field; every bad
field fails with a ScenarioError naming the field, the value and the valid choices."""

import re

import numpy as np
import pytest

from cdpm_drake.diagram import build_diagram
from cdpm_drake.kernels.plant.operators import ScriptedOperator, SpringHandOperator
from cdpm_drake.robot import ROBOTS_DIR
from cdpm_drake.config import (Scenario, ScenarioError, SimulatedReels, load_scenario,
                                 scenario_operator,
                                 scenario_names, scenario_robot, scenario_to_yaml)

SHIPPED = ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs")


def test_the_three_experiments_ship():
    assert set(SHIPPED) <= set(scenario_names())


@pytest.mark.parametrize("name", scenario_names())
def test_every_shipped_scenario_loads_and_builds(name):
    scenario = load_scenario(name)
    assert scenario.name == name
    assert isinstance(scenario.plant, SimulatedReels)
    robot = scenario_robot(scenario)
    assert robot.workspace.contains(scenario.initial_position)
    diagram = build_diagram(scenario)
    # (Blocks whose systems are fused into the safety blocks' callback are flat blocks.)
    names = {s.get_name() for s in diagram.GetSystems()} | set(diagram.flat_blocks)
    assert {"reels", "force_sensor", "admittance", "safety_limits"} <= names


def test_paper_numbers_of_the_experiments():
    # Section 5 of the paper: M = C = 6.25, 500 Hz; per experiment d_l, d_u, F_u and swaps.
    expected = {"exp1_no_interaction": (0.050, 0.061, 2.0, [[1, 3]]),
                "exp2_interaction": (0.060, 0.062, 3.0, [[1, 3]]),
                "exp3_two_pairs": (0.057, 0.062, 2.0, [[1, 3], [5, 7]])}
    for name, (d_l, d_u, F_u, swaps) in expected.items():
        s = load_scenario(name)
        assert (s.admittance.mass, s.admittance.damping, s.time_step) == (6.25, 6.25, 0.002)
        d = s.interference.default
        assert (d.d_l, d.d_u, d.F_u) == (d_l, d_u, F_u), name
        assert s.swaps == swaps, name


def test_scenarios_resolve_by_name_from_any_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert load_scenario("exp1_no_interaction").name == "exp1_no_interaction"


def test_overlay_changes_only_the_fields_it_names():
    base = load_scenario("exp2_interaction")
    s = load_scenario("exp2_interaction", overlay_text=(
        "{duration: 0.5, admittance: {mass: 2.0}, interference: {default: {F_u: 4.0}}}"))
    assert (s.duration, s.admittance.mass, s.interference.default.F_u) == (0.5, 2.0, 4.0)
    # Siblings of the overlaid fields keep the file's values.
    assert s.admittance.damping == base.admittance.damping == 6.25
    assert s.interference.default.d_l == base.interference.default.d_l == 0.060
    assert s.swaps == base.swaps and s.initial_position == base.initial_position
    assert isinstance(s.operator, SpringHandOperator)


def test_overlay_can_switch_the_operator_type():
    s = load_scenario("exp2_interaction", overlay_text=(
        "operator: !ScriptedOperator {times: [0, 1], forces: [[0, 0, 0], [1, 2, 3]]}"))
    assert isinstance(s.operator, ScriptedOperator)
    assert s.operator.forces == [[0, 0, 0], [1, 2, 3]]


def test_resolved_scenario_yaml_loads_back_equal(tmp_path):
    s = load_scenario("exp3_two_pairs", overlay_text="{duration: 1.5, random_seed: 3}")
    path = tmp_path / "scenario.yaml"
    path.write_text(scenario_to_yaml(s))
    back = load_scenario(path)
    assert back == s  # base_dir included: the dump records where relative paths resolve


def test_resolved_scenario_with_relative_files_loads_back_from_elsewhere(tmp_path,
                                                                         write_robot,
                                                                         valid_spec):
    """The scenario.yaml written beside a log keeps working when the robot file and the
    force CSV were given relative to the original scenario file."""
    write_robot(valid_spec, "my_robot.yaml")
    (tmp_path / "push.csv").write_text("t,fx,fy,fz\n0,1,2,3\n")
    (tmp_path / "run.yaml").write_text(
        "robot: my_robot.yaml\ninitial_position: [2.0, 1.5, 1.5]\n"
        "operator: !CsvOperator {path: push.csv}\n")
    s = load_scenario(tmp_path / "run.yaml")
    out = tmp_path / "runs" / "a"
    out.mkdir(parents=True)
    (out / "scenario.yaml").write_text(scenario_to_yaml(s))
    back = load_scenario(out / "scenario.yaml")
    assert back == s
    assert scenario_robot(back).name == "tetra_4cable"


def test_robot_path_in_a_scenario_file_is_relative_to_that_file(tmp_path, monkeypatch,
                                                                write_robot, valid_spec):
    write_robot(valid_spec, "my_robot.yaml")
    (tmp_path / "run.yaml").write_text(
        "robot: my_robot.yaml\ninitial_position: [2.0, 1.5, 1.5]\n"
        "interference: {enabled: false}\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    s = load_scenario("../run.yaml")
    assert scenario_robot(s).name == "tetra_4cable"


def _push_in_a(tmp_path):
    (tmp_path / "a").mkdir()
    path = tmp_path / "a" / "my_push.yaml"
    path.write_text("name: my_push\nrobot: my_robot.yaml\ninitial_position: [2.0, 1.5, 1.5]\n"
                    "interference: {enabled: false}\n")
    return path


@pytest.mark.parametrize("cwd", [".", "elsewhere"])
def test_a_scenario_means_the_same_from_every_directory(tmp_path, monkeypatch, write_robot,
                                                        valid_spec, cwd):
    # Issue 10, point 6: the robot file sits in the current directory, not beside the
    # scenario. From every directory the scenario fails the same way, naming the scenario and
    # the full path tried: no fallback to the current directory.
    write_robot(valid_spec, "my_robot.yaml")  # tmp_path/my_robot.yaml
    scenario = _push_in_a(tmp_path)
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / cwd)
    with pytest.raises(ScenarioError) as info:
        load_scenario(scenario)
    msg = str(info.value)
    assert str(scenario) in msg
    assert f"tried {str(tmp_path / 'a' / 'my_robot.yaml')!r}" in msg
    assert "relative to the scenario file's folder" in msg


def test_a_robot_path_in_an_overlay_is_relative_to_the_current_directory(
        tmp_path, monkeypatch, write_robot, valid_spec):
    write_robot(valid_spec, "my_robot.yaml")
    scenario = _push_in_a(tmp_path)
    monkeypatch.chdir(tmp_path)
    s = load_scenario(scenario, overlay_text="{robot: my_robot.yaml}")
    assert s.robot == str(tmp_path / "my_robot.yaml")
    assert scenario_robot(s).name == "tetra_4cable"
    (tmp_path / "b").mkdir()
    monkeypatch.chdir(tmp_path / "b")
    with pytest.raises(ScenarioError, match=r"--scenario-text .* robot file 'my_robot.yaml' "
                                            r"does not exist: tried '.*/b/my_robot.yaml' "
                                            r"\(relative paths are relative to the current"):
        load_scenario(scenario, overlay_text="{robot: my_robot.yaml}")


def test_a_csv_operator_path_is_relative_to_the_scenario_file(tmp_path, monkeypatch):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "push.csv").write_text("t,fx,fy,fz\n0,1,2,3\n")
    (tmp_path / "a" / "csv.yaml").write_text("operator: !CsvOperator {path: push.csv}\n")
    monkeypatch.chdir(tmp_path)
    s = load_scenario("a/csv.yaml")
    assert s.operator.path == str(tmp_path / "a" / "push.csv")
    np.testing.assert_allclose(scenario_operator(s).force(0.0, None, None), [1, 2, 3])


def test_a_folder_named_like_a_shipped_scenario_does_not_shadow_it(tmp_path, monkeypatch):
    # The natural --out of a run: a folder exp2_interaction/ in the current directory.
    (tmp_path / "exp2_interaction").mkdir()
    (tmp_path / "paper_7cable").mkdir()
    monkeypatch.chdir(tmp_path)
    s = load_scenario("exp2_interaction")
    assert s.name == "exp2_interaction"
    assert scenario_robot(s).source == str(ROBOTS_DIR / "paper_7cable.yaml")
    with pytest.raises(ScenarioError, match=r"scenario file 'exp2_interaction' is a folder"):
        load_scenario("exp2_interaction/")


# --- errors -----------------------------------------------------------------------------------


def error_of(overlay, name="exp1_no_interaction") -> str:
    with pytest.raises(ScenarioError) as info:
        load_scenario(name, overlay_text=overlay)
    return str(info.value)


def test_unknown_scenario_lists_the_built_in_ones():
    with pytest.raises(ScenarioError) as info:
        load_scenario("exp9")
    msg = str(info.value)
    assert "unknown scenario 'exp9'" in msg
    for name in SHIPPED:
        assert name in msg


def test_missing_scenario_file_names_the_path(tmp_path):
    with pytest.raises(ScenarioError, match=r"scenario file '.*nothere\.yaml' does not exist"):
        load_scenario(tmp_path / "nothere.yaml")


def test_unknown_robot_lists_the_built_in_robots():
    msg = error_of("robot: paper_9cable")
    assert "unknown robot 'paper_9cable'" in msg
    assert "'cube_8cable'" in msg and "'paper_7cable'" in msg


def test_unknown_pair_lists_the_valid_pairs():
    msg = error_of("interference: {pairs: [{pair: [1, 9], F_u: 3.0}]}")
    assert "interference.pairs[0].pair = [1, 9]" in msg
    assert "valid pairs: [(1, 2), (1, 3)," in msg and "(6, 7)]" in msg


def test_pair_override_must_be_two_cables():
    msg = error_of("interference: {pairs: [{pair: [1, 3]}, {pair: [2]}]}")
    assert "interference.pairs[1].pair must be two cable numbers [i, j], got [2]" in msg


def test_unknown_operator_tag_lists_the_valid_operators():
    msg = error_of("operator: !Teleport {}")
    assert "'!Teleport'" in msg
    assert ("['!NoOperator', '!ScriptedOperator', '!CsvOperator', '!SpringHandOperator']"
            in msg)


def test_unknown_plant_tag_lists_the_valid_plants():
    msg = error_of("plant: !MagicReels {}")
    assert "'!MagicReels'" in msg and "'!SimulatedReels'" in msg


def test_untagged_operator_fields_hint_at_the_tags():
    # An untagged map is the first member of the union (!NoOperator), which has no fields.
    msg = error_of("operator: {times: [0.0], forces: [[1, 0, 0]]}")
    assert "unknown field 'operator.times'" in msg and "'!ScriptedOperator'" in msg


@pytest.mark.parametrize("overlay,field,valid", [
    ("{dt: 0.01}", "dt", "'time_step'"),
    ("{admittance: {mas: 1.0}}", "admittance.mas", "['mass', 'damping']"),
    ("{sensor: {window: 3}}", "sensor.window", "'filter_window'"),
    ("operator: !SpringHandOperator {stiffnes: 3}", "operator.stiffnes", "'stiffness'"),
    ("{interference: {pairs: [{pair: [1, 3], du: 0.1}]}}", "interference.pairs[0].du",
     "'d_u'"),
])
def test_unknown_fields_are_named_with_the_valid_ones(overlay, field, valid):
    msg = error_of(overlay)
    assert f"unknown field {field!r}" in msg
    assert valid in msg
    assert "--scenario-text" in msg  # says where the bad text came from


def test_unknown_field_in_a_scenario_file_names_the_file(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("name: bad\nlimits: {max_speed: 1.0}\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert str(path) in str(info.value)
    assert "unknown field 'limits.max_speed'" in str(info.value)


def test_an_unknown_field_in_a_file_gives_its_line_and_the_closest_name(tmp_path):
    # Issue 22, point 15: the line of the field (from 1), "did you mean", and the loader's
    # internal base_dir is no field to offer.
    path = tmp_path / "bad.yaml"
    path.write_text("name: bad\nduration: 1.0\ninterference:\n  default:\n    d_l: 0.05\n"
                    "    du: 0.07\n")
    msg = str(pytest.raises(ScenarioError, load_scenario, path).value)
    assert f"{path}: line 6: unknown field 'interference.default.du'; did you mean 'd_u'? " \
           "(valid fields of interference.default: ['d_l', 'd_u', 'F_u', 'eps', 'd_min'])" in msg, msg
    path.write_text("name: bad\nbasedir: x\n")
    msg = str(pytest.raises(ScenarioError, load_scenario, path).value)
    assert "line 2: unknown field 'basedir' (valid fields: ['name'," in msg, msg
    assert "base_dir" not in msg
    # A value error in a list, in a tagged operator: the line of the entry.
    path.write_text("name: bad\noperator: !SpringHandOperator\n  waypoints:\n"
                    "    - [1.0, 2.0, 1.0]\n    - [1.0, x, 1.0]\n  times: [0, 1]\n")
    msg = str(pytest.raises(ScenarioError, load_scenario, path).value)
    assert "line 5: operator.waypoints[1][1] must be a number, got 'x'" in msg, msg


@pytest.mark.parametrize("overlay,message", [
    # Types, checked on the raw YAML.
    ("{duration: abc}", "duration must be a number, got 'abc'"),
    ("{initial_position: abc}", "initial_position must be a list, got 'abc'"),
    ("{initial_position: [1.0, x, 1.0]}", "initial_position[1] must be a number, got 'x'"),
    ("{sensor: {filter_window: 2.5}}", "sensor.filter_window must be an integer, got 2.5"),
    ("{interference: {enabled: maybe}}", "interference.enabled must be true or false, "
                                         "got 'maybe'"),
    ("{admittance: 5}", "admittance must be a mapping, got 5"),
    ("{swaps: 3}", "swaps must be a list, got 3"),
    # Values, checked on the typed scenario.
    ("{duration: -1.0}", "duration must be a finite number > 0, got -1.0"),
    ("{time_step: 0.0}", "time_step must be a finite number > 0, got 0.0"),
    ("{admittance: {mass: -6.25}}", "admittance.mass must be a finite number > 0, got -6.25"),
    ("{admittance: {damping: .nan}}", "admittance.damping must be a finite number > 0, "
                                      "got nan"),
    ("{limits: {max_velocity: 0.0}}", "limits.max_velocity must be a finite number > 0, "
                                      "got 0.0"),
    ("{sensor: {filter_window: 0}}", "sensor.filter_window must be an integer in 1..500 "
                                     "(samples of the sliding average, ticks of time_step "
                                     "0.002 s: at most 1 s), got 0"),
    ("{sensor: {noise_std: -1.0}}", "sensor.noise_std must be >= 0 N, got -1.0"),
    ("{sensor: {axial_axis: [0, 0, 0]}}", "sensor.axial_axis must be a non-zero [x, y, z], "
                                          "got [0.0, 0.0, 0.0]"),
    ("{initial_position: [1.0, 2.0]}", "initial_position must be [x, y, z] in m, "
                                       "got [1.0, 2.0]"),
    ("{initial_position: [0.0, 0.0, 0.0]}", "initial_position [0.0, 0.0, 0.0] m is outside "
                                            "the workspace box"),
    ("{swaps: [[1, 9]]}", "swaps[0] = [1, 9]"),
    ("{swaps: [[1, 2, 3]]}", "swaps[0] must be two cable numbers [i, j], got [1, 2, 3]"),
    ("{wall_force: {enabled: true, margin: 0.0}}", "wall_force.margin must be a finite "
                                                   "number > 0, got 0.0"),
    ("plant: !SimulatedReels {time_constant: -0.1}", "plant.time_constant must be >= 0 s, "
                                                     "got -0.1"),
    ("plant: !SimulatedReels {max_reel_speed: 0.0}", "plant.max_reel_speed must be a finite "
                                                     "number > 0, got 0.0"),
    ("{interference: {default: {d_l: 0.07}}}", "d_u"),  # d_l above d_u = 0.061
    # Issue 22, point 6: an error in the default set names the default's fields, not the
    # first pair it reaches; a pair's override names the override and the pair.
    ("{interference: {default: {d_l: 0.07, d_u: 0.06}}}",
     "interference.default.d_u = 0.06 m must be above interference.default.d_l = 0.07 m"),
    ("{interference: {default: {F_u: -1.0}}}", "interference.default.F_u must be > 0 N, "
                                               "got -1.0"),
    ("{interference: {default: {eps: 2.0}}}", "interference.default.eps = 2.0 N must lie in "
                                              "(0, F_u/2) = (0, 1.0) N"),
    ("{interference: {pairs: [{pair: [1, 3], d_u: 0.04}]}}",
     "interference.pairs[0].d_u = 0.04 m (pair (1,3)) must be above "
     "interference.default.d_l = 0.05 m"),
    ("{interference: {pairs: [{pair: [1, 2]}, {pair: [3, 1], d_l: -0.01}]}}",
     "interference.pairs[1].d_l (pair (3,1)) must be >= 0 m, got -0.01"),
    # Issue 22, point 7: less than one tick of time_step (0.002 s) is refused, naming the tick.
    ("{duration: 0.001}", "duration 0.001 s is shorter than one tick (time_step 0.002 s)"),
    ("{duration: 0.01, time_step: 0.02}", "duration 0.01 s is shorter than one tick "
                                          "(time_step 0.02 s)"),
    ("operator: !ScriptedOperator {times: [0, 0], forces: [[0, 0, 0], [1, 1, 1]]}",
     "operator.times must increase strictly"),
    ("operator: !CsvOperator {path: no_such.csv}", "no_such.csv' does not exist"),
])
def test_bad_values_are_rejected_naming_field_and_value(overlay, message):
    assert message in error_of(overlay)


def test_a_duration_of_one_tick_is_enough():
    # Exactly one tick (and one tick less a round-off hair, 0.1 / 0.002 * 0.002) is a run.
    from cdpm_drake.config import check_duration
    load_scenario("exp1_no_interaction", overlay_text="{duration: 0.002}")
    check_duration(0.002 * (1 - 1e-12), 0.002, "duration")


def test_initial_position_outside_names_the_box():
    msg = error_of("{initial_position: [0.0, 0.0, 0.0]}")
    assert re.search(r"lower \[0\.5, 0\.8, 0\.3\], upper \[3\.0, 4\.0, 2\.4\]", msg), msg


def test_invalid_yaml_is_a_scenario_error():
    assert "not valid YAML" in error_of("{duration: [}")


def test_default_scenario_is_valid():
    # The dataclass defaults alone describe a runnable scenario (STYLE: defaults that work).
    from cdpm_drake.config import resolve_scenario
    resolved = resolve_scenario(Scenario())
    assert resolved.robot.num_cables == 7
    assert np.all(resolved.robot.workspace.contains(resolved.scenario.initial_position))


def test_a_left_out_start_is_the_workspace_centre_of_the_scenario_s_robot(tmp_path):
    # Issue 22, point 10: not the paper robot's start, whichever robot the scenario names.
    # cube_8cable's box is [0.5, 0.5, 0.5] to [3.5, 2.5, 2.5] m (its robot file): centre
    from cdpm_drake.config import load_resolved_scenario
    path = tmp_path / "cube.yaml"
    path.write_text("name: cube\nrobot: cube_8cable\nduration: 0.1\n")
    resolved = load_resolved_scenario(path)
    # [2.0, 1.5, 1.5] m.
    assert resolved.scenario.initial_position == [2.0, 1.5, 1.5]
    assert resolved.defaulted == ("initial_position",)
    assert Scenario().initial_position is None  # the schema's default is "left out"
    # The paper robot's box is [0.5, 0.8, 0.3] to [3.0, 4.0, 2.4] m: centre [1.75, 2.4, 1.35].
    resolved = load_resolved_scenario(path, "{robot: paper_7cable}")
    # Written to 12 significant digits: 1.35, not (0.3 + 2.4) / 2 = 1.3499999999999999.
    assert resolved.scenario.initial_position == [1.75, 2.4, 1.35]
    # Written explicitly, it is what was written, and nothing is said to be defaulted.
    resolved = load_resolved_scenario(path, "{initial_position: [1.9, 1.0, 1.1]}")
    assert resolved.scenario.initial_position == [1.9, 1.0, 1.1] and not resolved.defaulted


@pytest.mark.parametrize("name", scenario_names())
def test_every_shipped_scenario_writes_its_start(name):
    # A shipped scenario never relies on the default, so its paper reproduction (and the
    # reference logs, tests/runs/test_reference_logs.py) cannot move with it.
    from cdpm_drake.data import SCENARIOS_DIR
    from pydrake.common.yaml import yaml_load
    assert len(yaml_load(filename=str(SCENARIOS_DIR / f"{name}.yaml"))["initial_position"]) == 3


def test_a_message_about_a_defaulted_start_says_default(tmp_path):
    # No tension distribution holds the paper robot's platform with every cable above 1 kN
    # (its weight is 25 N); the start, at the workspace centre, is the default and the
    # message says so, as for the start tilt; the floor was written, and is not a default.
    path = tmp_path / "dyn.yaml"
    path.write_text("name: dyn\nduration: 0.1\nplant: !DynamicReels {min_tension: 1000}\n")
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    assert ("initial_position [1.75, 2.4, 1.35] m (the default: the centre of the workspace "
            "box of robot 'paper_7cable') with plant.initial_rpy [0.0, 0.0, 0.0] rad "
            "(default)") in str(e.value), str(e.value)
    assert "plant.min_tension = 1000 N;" in str(e.value)


def test_a_negative_random_seed_is_refused_at_load():
    with pytest.raises(ScenarioError,
                       match=r"random_seed must be an integer in 0\.\.4294967295, got -1"):
        load_scenario("exp1_no_interaction", overlay_text="random_seed: -1")


def test_an_untagged_operator_overlay_says_the_operator_needs_its_tag():
    # Issue 10, point 10: exp1 has no operator; an untagged mapping is the union's first
    # member (!NoOperator), which has no max_force: say which tag is meant.
    msg = error_of("{operator: {max_force: 3}}")
    assert "an operator needs its tag, e.g. `operator: !SpringHandOperator {max_force: 3}`" \
        in msg, msg
    # The same on a scenario whose operator already is a !SpringHandOperator.
    msg = error_of("{operator: {max_force: 3}}", name="exp2_interaction")
    assert "`operator: !SpringHandOperator {max_force: 3}`" in msg
    # A field no operator has: the plain unknown-field message with the valid types.
    msg = error_of("{operator: {bogus: 3}}")
    assert "unknown field 'operator.bogus'" in msg and "'!SpringHandOperator'" in msg


# --- the tension target's hard floor ---------------------------------------------------------

_TENSION = "plant: !DynamicReels {{}}\ncontroller: {{pose: full, tension_control: true, {}}}"


@pytest.mark.parametrize("setting, message", [
    ("tension_floor: 0", "controller.tension_floor must be a finite number > 0 N (the tension "
                         "no cable is commanded below), got 0.0"),
    ("tension_floor: -1.5", "controller.tension_floor must be a finite number > 0 N (the "
                            "tension no cable is commanded below), got -1.5"),
    ("tension_floor: .inf", "controller.tension_floor must be a finite number > 0 N (the "
                            "tension no cable is commanded below), got inf"),
    # A field the scenario leaves at its default is said to be (issue 42).
    ("min_tension: 2.5", "controller.min_tension must be a finite number >= "
                         "controller.tension_floor = 4.0 N (default value; the scenario does "
                         "not change it), got 2.5"),
    ("tension_floor: 12.0", "controller.min_tension must be a finite number >= "
                            "controller.tension_floor = 12.0 N, got 10.0 (default value; the "
                            "scenario does not change it)"),
    ("max_tension: 10.0", "controller.max_tension must be a finite number above "
                          "controller.min_tension = 10.0 N (default value; the scenario does "
                          "not change it), got 10.0"),
])
def test_the_tension_floors_and_ceiling_are_checked_at_load(setting, message):
    """0 < tension_floor <= min_tension < max_tension, each message naming the field and the
    value (defaults: 4, 10 and 100 N)."""
    with pytest.raises(ScenarioError) as e:
        load_scenario("exp1_no_interaction", _TENSION.format(setting))
    # Prefixed with where the overlay writes the field it names (issue 32: as a typo's
    # message is); a field the overlay leaves to its default is written nowhere.
    overlay = _TENSION.format(setting)
    named = message.split(" must")[0].split(".")[-1]
    where = f"--scenario-text {overlay!r}: line 2: " if setting.startswith(named) else ""
    assert str(e.value) == where + message


def test_tension_control_needs_a_wrench_matrix_of_rank_six(tmp_path):
    """cube_8cable with every cable at its own corner of the platform (the design before
    issue 18): the cables cannot hold a moment about x (rank 5), so no internal force can be
    set; tension control is refused naming the robot and the rank. The shipped cube is
    accepted: more than seven cables are no reason to refuse."""
    text = (ROBOTS_DIR / "cube_8cable.yaml").read_text()
    start = text.index("attachments:")
    end = text.index("# Half a metre")
    corners = "".join(f"  - [{x}, {y}, {z}]\n" for z in (-0.15, 0.15)
                      for x, y in ((-0.15, -0.15), (0.15, -0.15), (0.15, 0.15), (-0.15, 0.15)))
    path = tmp_path / "corner_cube.yaml"
    path.write_text(text[:start].replace("name: cube_8cable", "name: corner_cube")
                    + "attachments:\n" + corners + text[end:])
    overlay = f"robot: {path}\nswaps: []\ninitial_position: [2.0, 1.5, 1.5]\n"
    with pytest.raises(ScenarioError) as e:
        load_scenario("exp1_no_interaction", overlay + _TENSION.format("min_tension: 10.0"))
    assert str(e.value) == (
        "controller.tension_control needs a wrench matrix of rank 6 (cables that hold every "
        "force and moment: the internal force it sets lives in the rest); robot "
        "'corner_cube' has rank 5 at its workspace centre")
    cube = overlay.replace(str(path), "cube_8cable")
    assert load_scenario("exp1_no_interaction",
                         cube + _TENSION.format("min_tension: 10.0")).controller.tension_control
