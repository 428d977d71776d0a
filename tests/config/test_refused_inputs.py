"""Bad inputs a new user gave that were silently accepted or answered with a misleading
message: each is now refused at load with a message naming the field, the value and what is
wrong (or, for a field left at its default, saying so). Every case here loaded before (or
blamed the wrong thing); the expected texts are the messages' own words."""

import re

import numpy as np
import pytest

from cdpm_drake.config import ScenarioError, load_scenario
from cdpm_drake.robot import RobotError, load_robot


def _scenario(tmp_path, text, name="s.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _robot_text(**replace):
    """paper_7cable's file with `old: new` line replacements, its comments dropped."""
    from cdpm_drake.data import ROBOTS_DIR

    text = "\n".join(line for line in (ROBOTS_DIR / "paper_7cable.yaml").read_text()
                     .splitlines() if not line.lstrip().startswith("#"))
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new, 1)
    return text


# --- robot files -----------------------------------------------------------------------------


def test_a_duplicate_key_in_a_robot_file_is_refused_with_both_lines(tmp_path):
    # YAML keeps the last of two equal keys: the 0.0015 m the user wrote first was dropped.
    path = tmp_path / "r.yaml"
    path.write_text(_robot_text(**{"cable_diameter: 0.0015":
                                   "cable_diameter: 0.0015\ncable_diameter: 0.003"}))
    with pytest.raises(RobotError, match=r"the key 'cable_diameter' \(cable_diameter\) on "
                                         r"lines (\d+) and (\d+): write each key once"):
        load_robot(path)


def test_a_duplicate_nested_key_in_a_robot_file_is_refused(tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text(_robot_text(**{"  mass: 2.5": "  mass: 2.5\n  mass: 3.5"}))
    with pytest.raises(RobotError, match=r"'mass' \(platform\.mass\) on lines"):
        load_robot(path)


def test_a_quoted_number_in_a_robot_file_is_refused_naming_field_and_line(tmp_path):
    # Drake's loader turned the string "3.0" into 3.0 m of cable diameter without a word.
    text = _robot_text(**{"cable_diameter: 0.0015": 'cable_diameter: "3.0"'})
    path = tmp_path / "r.yaml"
    path.write_text(text)
    line = 1 + text.splitlines().index('cable_diameter: "3.0"')
    with pytest.raises(RobotError, match=rf"line {line}: cable_diameter must be a number, got "
                                         r"the string '3\.0' \(quoted\)"):
        load_robot(path)


def test_a_quoted_name_is_still_a_name(tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text(_robot_text(**{"name: paper_7cable": 'name: "42"'}))
    assert load_robot(path).name == "42"


@pytest.mark.parametrize("mass", ["1e-12", "0.001", "2e4"])
def test_a_platform_mass_no_platform_has_is_refused(tmp_path, mass):
    path = tmp_path / "r.yaml"
    path.write_text(_robot_text(**{"  mass: 2.5": f"  mass: {mass}"}))
    with pytest.raises(RobotError, match=r"platform\.mass must lie in \[0\.01, 10000\] kg .*"
                                         rf"got {re.escape(f'{float(mass):g}')}"):
        load_robot(path)


# --- scenario files --------------------------------------------------------------------------


def test_a_quoted_number_in_a_scenario_is_refused_naming_field_and_line(tmp_path):
    path = _scenario(tmp_path, 'name: t\nduration: "3.0"\n')
    with pytest.raises(ScenarioError, match=r"line 2: duration must be a number, got the "
                                            r"string '3\.0' \(quoted\); write it without "
                                            r"quotes: 3\.0"):
        load_scenario(path)
    # An unquoted 1e3 (a string to YAML 1.1, a number to Drake) stays a number.
    assert load_scenario(_scenario(tmp_path, "name: t\nduration: 1e-1\n", "b.yaml")) \
        .duration == pytest.approx(0.1)


def test_a_quoted_number_in_an_overlay_is_refused():
    with pytest.raises(ScenarioError, match=r"admittance\.mass must be a number, got the "
                                            r"string '3\.0' \(quoted\)"):
        load_scenario("exp1_no_interaction", "admittance: {mass: '3.0'}")


@pytest.mark.parametrize("name", ["../../etc/x", "a/b", "..", "a\\b", "", "with space"])
def test_a_scenario_name_that_is_not_one_folder_is_refused(tmp_path, name):
    # The run folder is runs/<name>/: `../../etc/x` wrote it two levels above runs/.
    import yaml

    path = _scenario(tmp_path, yaml.safe_dump({"name": name, "duration": 0.1}))
    with pytest.raises(ScenarioError, match=r"name must be one folder name .*got "
                                            + re.escape(repr(name))):
        load_scenario(path)


def test_an_ordinary_scenario_name_is_kept(tmp_path):
    assert load_scenario(_scenario(tmp_path, "name: exp2.v3-b_1\n")).name == "exp2.v3-b_1"


@pytest.mark.parametrize("field,value,most", [
    # 500 = 1 s of 2 ms ticks (checks.MAX_TICKS_SPAN): a million samples asked for 65.5 TiB.
    ("sensor.filter_window", 1000000, 500),
    ("sensor.filter_window", 3000, 500),
    ("model_monitor.ticks", 100000, 500),
    ("model_monitor.slack_ticks", 501, 500),
])
def test_a_count_of_ticks_beyond_a_second_is_refused_naming_field_and_range(field, value,
                                                                           most):
    section, key = field.split(".")
    with pytest.raises(ScenarioError, match=rf"{re.escape(field)} must be an integer in "
                                            rf"1\.\.{most} .* got {value}"):
        load_scenario("exp1_no_interaction", f"{section}: {{{key}: {value}}}")


def test_the_tick_bound_follows_the_time_step():
    # 1 s of 10 ms ticks is 100 samples: 100 passes, 101 does not.
    load_scenario("exp1_no_interaction", "time_step: 0.01\ncontroller: {length_gain: 40}\n"
                  "sensor: {filter_window: 100}")
    with pytest.raises(ScenarioError, match=r"filter_window must be an integer in 1\.\.100"):
        load_scenario("exp1_no_interaction", "time_step: 0.01\nsensor: {filter_window: 101}")


def test_a_random_seed_beyond_32_bits_is_refused():
    with pytest.raises(ScenarioError, match=r"random_seed must be an integer in "
                                            r"0\.\.4294967295, got 4294967296"):
        load_scenario("exp1_no_interaction", "random_seed: 4294967296")


def test_swap_with_cable_0_says_0_is_not_a_cable():
    # It said the swaps "undo each other" (cable 3 ended where it started).
    with pytest.raises(ScenarioError, match=r"swaps\[0\] = \[0, 3\]: 0 is not a cable; "
                                            r"cables are numbered from 1"):
        load_scenario("exp1_no_interaction", "swaps: [[0, 3]]")


def test_swaps_that_make_two_cables_cross_at_every_pose_are_refused():
    # cube_8cable's cables 1 and 2 swapped: no translation takes them apart (largest
    # distance 0, kernels.interference.translation_distance_bound); it was a d_u warning.
    from cdpm_drake.config import Scenario, scenario_robot
    from cdpm_drake.kernels.interference import translation_distance_bound

    robot = scenario_robot(Scenario(robot="cube_8cable", swaps=[[1, 2]]))
    assert translation_distance_bound(robot)[robot.pairs.index((1, 2))] < 1e-6
    with pytest.raises(ScenarioError, match=r"cables 1 and 2 of robot 'cube_8cable_swap12' "
                                            r"with swaps \[\[1, 2\]\] cross at every pose"):
        load_scenario("exp1_no_interaction", "robot: cube_8cable\nswaps: [[1, 2]]\n"
                      "initial_position: null")


def test_swaps_whose_cables_come_close_but_separate_are_not_refused():
    # paper_7cable with 2-7 swapped: at most 11.1 mm apart, but apart (the d_u warning says
    # the force never switches off; the run is the user's choice).
    load_scenario("exp1_no_interaction", "swaps: [[2, 7]]")


def test_a_pair_overridden_twice_is_refused_naming_both_entries():
    overlay = ("interference: {pairs: [{pair: [1, 3], d_l: 0.04}, "
               "{pair: [3, 1], d_u: 0.07}]}")
    with pytest.raises(ScenarioError, match=r"interference\.pairs\[1\]\.pair = \[3, 1\] "
                                            r"overrides pair \(1,3\) again "
                                            r"\(interference\.pairs\[0\]\.pair = \[1, 3\]\)"):
        load_scenario("exp1_no_interaction", overlay)


def test_an_empty_overlay_says_so():
    # It said "YAML root was a <class 'NoneType'> but should have been a dict".
    for text in ("null", "~", "# nothing"):
        with pytest.raises(ScenarioError, match=r"the overlay is empty .*an overlay is a "
                                                r"mapping of fields") as info:
            load_scenario("exp1_no_interaction", text)
        assert "NoneType" not in str(info.value)


def test_a_field_left_at_its_default_is_said_to_be_the_default():
    # time_step raised to 50 ms: the length loop's gain (default 40 1/s) is now too high;
    # the message blames length_gain, which the user never wrote.
    with pytest.raises(ScenarioError, match=r"controller\.length_gain must be .* got 40\.0 "
                                            r"\(default value; the scenario does not change "
                                            r"it\)"):
        load_scenario("exp1_no_interaction", "time_step: 0.05")
    with pytest.raises(ScenarioError, match=r"controller\.max_tension = 100\.0 N \(default "
                                            r"value; the scenario does not change it\), got "
                                            r"150\.0$"):
        load_scenario("exp1_no_interaction", "controller: {tension_floor: 150}")
    with pytest.raises(ScenarioError, match=r"controller\.min_tension must be .* got 10\.0 "
                                            r"\(default value; the scenario does not change "
                                            r"it\)"):
        load_scenario("exp1_no_interaction", "controller: {pose: full, tension_control: "
                      "true, tension_floor: 20}\nplant: !DynamicReels {}")
    # A value the scenario sets is not called a default.
    with pytest.raises(ScenarioError) as info:
        load_scenario("exp1_no_interaction", "controller: {pose: full, tension_control: "
                      "true, tension_floor: 20, min_tension: 15}\nplant: !DynamicReels {}")
    assert "default value" not in str(info.value)


def test_a_start_orientation_the_translating_controller_cannot_read_blames_the_orientation():
    # initial_rpy [3, 0, 0] on cube_8cable: the run stopped at its first tick with "cable
    # lengths are inconsistent with robot 'cube_8cable' ... 62.879 mm on cable 8" when the
    # dynamic plant's encoders read unstretched lengths; homed, they read the turned
    # platform's rigid lengths, whose level fit leaves 62.6 mm on cable 7: the fit's
    # residual is the run's number, now at load and naming the orientation.
    with pytest.raises(ScenarioError, match=r"plant\.initial_rpy \[3\.0, 0\.0, 0\.0\] rad: "
                                            r"the platform's orientation is the trouble: "
                                            r"controller\.pose 'translation' \(default\) .*"
                                            r"the best fit leaves 62\.6 mm on cable 7") as info:
        load_scenario("exp1_no_interaction", "robot: cube_8cable\nswaps: []\n"
                      "initial_position: null\nplant: !DynamicReels {initial_rpy: [3, 0, 0]}")
    assert "inconsistent" not in str(info.value)
    # The full pose estimates the orientation: it loads.
    load_scenario("exp1_no_interaction", "robot: cube_8cable\nswaps: []\n"
                  "initial_position: null\ncontroller: {pose: full}\n"
                  "plant: !DynamicReels {initial_rpy: [3, 0, 0]}")


def test_a_small_tilt_still_loads():
    resolved = load_scenario("exp1_no_interaction",
                             "plant: !DynamicReels {initial_rpy: [0.01, 0, 0]}")
    assert np.allclose(resolved.plant.initial_rpy, [0.01, 0, 0])
