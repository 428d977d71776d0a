"""Robot descriptions: loading, validation messages, construction in code, attachment swaps."""

import dataclasses
import math

import numpy as np
import pytest

from cdpm_drake.kernels.kinematics import cable_lengths, cable_vectors
from cdpm_drake.robot import Robot, RobotError, RobotLimits, Workspace, load_robot, robot_names

from conftest import HAND_ROBOT, SHIPPED_ROBOTS, to_yaml


def load_error(path) -> str:
    """The message of the RobotError that loading `path` raises."""
    with pytest.raises(RobotError) as info:
        load_robot(path)
    return str(info.value)


def assert_names(msg: str, *parts: str) -> None:
    for part in parts:
        assert part in msg, f"{part!r} missing from error message: {msg}"
    # Values are echoed as the file spells them, not as numpy reprs.
    assert "np.float64" not in msg and "array(" not in msg, msg


# --- a robot written by someone else ---------------------------------------------------------


def test_hand_written_robot_lengths_match_hand_calculation():
    robot = load_robot(HAND_ROBOT)
    assert robot.name == "garage_4cable"
    assert robot.num_cables == 4
    c = robot.workspace.center
    # centre = (lower + upper) / 2 = ((2.5+6.5)/2, (2.5+4.5)/2, (0.5+2.5)/2) = (4.5, 3.5, 1.5)
    np.testing.assert_array_equal(c, [4.5, 3.5, 1.5])
    # B_i = p + b_i: B1 = (4, 3, 2), B2 = (5, 3, 2), B3 = (5, 4, 2), B4 = (4, 4, 2).
    # rho_i = B_i - a_i (eq. 1):
    #   rho1 = (4-1, 3-1, 2-8) = ( 3,  2, -6): 9 + 4 + 36 = 49 -> 7
    #   rho2 = (5-7, 3-2, 2-4) = (-2,  1, -2): 4 + 1 +  4 =  9 -> 3
    #   rho3 = (5-8, 4-6, 2-8) = (-3, -2, -6): 9 + 4 + 36 = 49 -> 7
    #   rho4 = (4-0, 4-8, 2-0) = ( 4, -4,  2): 16 + 16 + 4 = 36 -> 6
    # Every number is a small dyadic rational, so the floating-point result is exact.
    np.testing.assert_array_equal(
        cable_vectors(robot, c), [[3, 2, -6], [-2, 1, -2], [-3, -2, -6], [4, -4, 2]])
    np.testing.assert_array_equal(cable_lengths(robot, c), [7.0, 3.0, 7.0, 6.0])


def test_hand_written_robot_gets_documented_defaults():
    robot = load_robot(str(HAND_ROBOT))  # str and Path both work
    # Defaults of LimitsSchema / RobotSchema: the file sets neither limits nor diameter.
    assert robot.limits == RobotLimits(max_velocity=0.5, max_acceleration=2.0, max_reel_speed=1.0)
    assert robot.cable_diameter == 0.0
    assert robot.source == str(HAND_ROBOT)
    # No shared reels or attachment points: all C(4, 2) = 6 pairs watched, in 1-based order.
    assert robot.pairs == [(1, 2), (1, 3), (1, 4), (2, 3), (2, 4), (3, 4)]


# --- shipped robots --------------------------------------------------------------------------


def test_shipped_robot_names():
    assert set(SHIPPED_ROBOTS) <= set(robot_names())


@pytest.mark.parametrize("name, m", [("paper_7cable", 7), ("cube_8cable", 8)])
def test_shipped_robots_load_by_name(name, m):
    robot = load_robot(name)
    assert robot.name == name
    assert robot.num_cables == m
    assert robot.reels.shape == robot.attachments.shape == (m, 3)
    assert robot.num_pairs == len(robot.pairs) == m * (m - 1) // 2
    i, j = robot.pair_index
    assert [(a + 1, b + 1) for a, b in zip(i, j)] == robot.pairs
    assert robot.workspace.contains(robot.workspace.center)


def test_paper_robot_reels_are_table_1():
    robot = load_robot("paper_7cable")
    # Table 1 of the paper, A1..A7 in metres.
    table_1 = [[-0.149, 3.894, 2.904], [3.562, 3.87, 2.904], [0.064, 4.587, 0.84],
               [3.439, 4.587, 0.84], [0.01, 0.12, 0.782], [3.385, 0.12, 0.782],
               [1.67, -0.08, 2.9]]
    np.testing.assert_array_equal(robot.reels, table_1)
    # Platform positions the paper reports (section 5) lie inside the virtual wall.
    assert robot.workspace.contains([1.77, 3.65, 1.22])
    assert robot.workspace.contains([[1.30, 3.22, 0.53], [2.22, 3.68, 1.22]]).all()


def test_unknown_robot_name_lists_builtins():
    msg = str(pytest.raises(RobotError, load_robot, "no_such_robot").value)
    assert_names(msg, "'no_such_robot'", "paper_7cable", "cube_8cable")


def test_missing_robot_file(tmp_path):
    path = tmp_path / "absent.yaml"
    assert_names(load_error(path), str(path), "does not exist")


# --- validation: each error names the file, the field, the cable and the value -----------------


@pytest.mark.parametrize("field", ["name", "reels", "attachments", "workspace"])
def test_missing_field(write_robot, valid_spec, field):
    del valid_spec[field]
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "missing", f"'{field}'")


@pytest.mark.parametrize("corner", ["lower", "upper"])
def test_missing_workspace_corner(write_robot, valid_spec, corner):
    del valid_spec["workspace"][corner]
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "missing", f"workspace.{corner}")


def test_unknown_field_lists_valid_fields(write_robot, valid_spec):
    valid_spec["colour"] = "red"
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "unknown", "'colour'", "'reels'", "'attachments'")


def test_unknown_workspace_field(write_robot, valid_spec):
    valid_spec["workspace"]["middle"] = [2.0, 1.5, 1.5]
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "'workspace.middle'", "'workspace.lower'")


def test_unknown_limits_field(write_robot, valid_spec):
    valid_spec["limits"] = {"max_speed": 1.0}
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "'limits.max_speed'", "'limits.max_velocity'")


def test_an_unknown_field_gives_its_line_and_the_closest_valid_name(write_robot, valid_spec):
    # Issue 22, point 15. The spec writes name, reels, attachments, workspace (lines 1-4, the
    # workspace's lower and upper on 5-6), then limits: line 7, its max_velocty on line 8.
    valid_spec["limits"] = {"max_velocty": 1.0}
    path = write_robot(valid_spec)
    assert path.read_text().splitlines()[7].strip() == "max_velocty: 1.0"
    msg = load_error(path)
    assert f"{path}: line 8: unknown field(s) ['limits.max_velocty']; did you mean " \
           "'limits.max_velocity'?" in msg, msg
    # A misspelt required field: both said, with the name meant.
    valid_spec["workspce"] = valid_spec.pop("workspace")
    msg = load_error(write_robot(valid_spec))
    assert "missing required field(s) ['workspace']" in msg
    assert "unknown field(s) ['workspce'] given; did you mean 'workspace'?" in msg, msg


@pytest.mark.parametrize("field, cable, row", [
    ("reels", 2, [4.0, 0.0]),
    ("attachments", 4, [0.0, 0.0, -0.1, 0.0]),
])
def test_wrong_row_length(write_robot, valid_spec, field, cable, row):
    valid_spec[field][cable - 1] = row
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), field, f"cable {cable}", f"got {len(row)}",
                 repr(row))


def test_wrong_workspace_corner_length(write_robot, valid_spec):
    valid_spec["workspace"]["upper"] = [3.0, 2.5]
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "workspace.upper", "[3.0, 2.5]")


def test_row_that_is_a_number(write_robot, valid_spec):
    valid_spec["reels"][2] = 4.0
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "reels of cable 3", "4.0")


def test_field_that_is_not_a_list(write_robot, valid_spec):
    valid_spec["attachments"] = 5
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "attachments", "got 5")


def test_workspace_that_is_not_a_mapping(write_robot, valid_spec):
    valid_spec["workspace"] = [1.0, 2.0]
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "workspace", "[1.0, 2.0]")


def test_reel_and_attachment_counts_differ(write_robot, valid_spec):
    del valid_spec["attachments"][-1]
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "reels has 4", "attachments has 3")


def test_fewer_than_three_cables(write_robot, valid_spec):
    valid_spec["reels"] = valid_spec["reels"][:2]
    valid_spec["attachments"] = valid_spec["attachments"][:2]
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "reels", "2 cables", "at least 3")


@pytest.mark.parametrize("field, cable, value, shown", [
    ("reels", 3, math.nan, "nan"),
    ("reels", 1, math.inf, "inf"),
    ("attachments", 2, -math.inf, "-inf"),
    ("attachments", 4, math.nan, "nan"),
])
def test_non_finite_cable_coordinate(write_robot, valid_spec, field, cable, value, shown):
    valid_spec[field][cable - 1][1] = value
    path = write_robot(valid_spec)
    text = path.read_text()
    assert (".nan" if math.isnan(value) else ".inf") in text  # YAML spelling, as users write it
    assert_names(load_error(path), str(path), f"{field} of cable {cable}", shown)


@pytest.mark.parametrize("corner", ["lower", "upper"])
def test_non_finite_workspace(write_robot, valid_spec, corner):
    valid_spec["workspace"][corner][2] = math.inf
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), f"workspace.{corner}", "inf")


@pytest.mark.parametrize("field, cable, value", [
    ("reels", 1, "abc"),
    ("attachments", 3, True),  # YAML `true`: float() would take it as 1.0
])
def test_non_number_coordinate(write_robot, valid_spec, field, cable, value):
    valid_spec[field][cable - 1][0] = value
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), f"{field} of cable {cable}", repr(value))


def test_non_number_workspace(write_robot, valid_spec):
    valid_spec["workspace"]["lower"][0] = "one"
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "workspace.lower", "'one'")


def test_exponent_without_dot_is_a_number(write_robot, valid_spec):
    # YAML 1.1 reads `3e0` (no dot) as a string; a user means the number 3.
    text = to_yaml(valid_spec).replace("[0.0, 0.0, 3.0]", "[0.0, 0.0, 3e0]", 1)
    assert "3e0" in text
    robot = load_robot(write_robot(text))
    np.testing.assert_array_equal(robot.reels[0], [0.0, 0.0, 3.0])


def test_two_reels_at_the_same_point(write_robot, valid_spec):
    valid_spec["reels"][3] = list(valid_spec["reels"][1])
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "reels", "cables 2 and 4", "same point",
                 "[4.0, 0.0, 3.0]", "ignore_pairs")


def test_shared_reel_allowed_when_pair_ignored(write_robot, valid_spec):
    valid_spec["reels"][3] = list(valid_spec["reels"][1])
    valid_spec["ignore_pairs"] = [[4, 2]]
    robot = load_robot(write_robot(valid_spec))
    assert (2, 4) in robot.excluded_pairs
    # C(4, 2) = 6 pairs minus the ignored one, order otherwise unchanged.
    assert robot.pairs == [(1, 2), (1, 3), (1, 4), (2, 3), (3, 4)]
    assert robot.pair_position(3, 4) == 4
    with pytest.raises(RobotError, match=r"\(2, 4\)"):
        robot.pair_position(2, 4)


@pytest.mark.parametrize("lower, upper, axis, lo, hi", [
    ([1.0, 0.5, 2.5], [3.0, 2.5, 2.5], "z", "2.5", "2.5"),  # empty: zero height
    ([3.0, 0.5, 0.5], [1.0, 2.5, 2.5], "x", "3.0", "1.0"),  # inverted
])
def test_empty_or_inverted_workspace(write_robot, valid_spec, lower, upper, axis, lo, hi):
    valid_spec["workspace"] = {"lower": lower, "upper": upper}
    path = write_robot(valid_spec)
    k = "xyz".index(axis)
    assert_names(load_error(path), str(path), f"along {axis}", f"lower[{k}] = {lo} m",
                 f"upper[{k}] = {hi} m")


def test_name_must_be_a_string(write_robot, valid_spec):
    valid_spec["name"] = 5
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "name must be a non-empty string, got 5")


def test_empty_name(write_robot, valid_spec):
    valid_spec["name"] = ""
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "name", "''")


@pytest.mark.parametrize("field, value", [("cable_diameter", -0.001),
                                          ("cable_diameter", math.nan)])
def test_bad_cable_diameter(write_robot, valid_spec, field, value):
    valid_spec[field] = value
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), field, repr(value))


@pytest.mark.parametrize("field, value, message", [
    # Issue 27: Drake's loader said only "could not convert string to float: 'thin'".
    ("cable_diameter", "thin", "cable_diameter must be a finite value >= 0 m, got 'thin'"),
    ("limits", {"max_velocity": "fast"},
     "limits.max_velocity must be a finite value > 0 m/s, got 'fast'"),
    ("ignore_pairs", [[1, "x"]], "ignore_pairs[0] must be two cable numbers [i, j], got "
                                 "[1, 'x']"),
    ("ignore_pairs", 5, "ignore_pairs must be a list of cable pairs [i, j], got 5"),
    ("name", [1], "name must be a non-empty string, got [1]")])
def test_a_wrong_kind_of_value_names_the_field(write_robot, valid_spec, field, value, message):
    valid_spec[field] = value
    path = write_robot(valid_spec)
    assert_names(load_error(path), f"{path}: {message}")


def test_a_box_beyond_the_reels_frame_is_warned_naming_the_face(write_robot, valid_spec,
                                                                 caplog):
    # Issue 27: accepted silently. The reels span x 0..4, y 0..3, z 0..3 (conftest's robot).
    import logging

    valid_spec["workspace"] = {"lower": [-0.5, 0.5, -0.5], "upper": [3.0, 3.2, 2.5]}
    path = write_robot(valid_spec)
    with caplog.at_level(logging.WARNING, logger="cdpm_drake.robot"):
        load_robot(path)
    frame = [r.getMessage() for r in caplog.records if "reels' frame" in r.getMessage()]
    assert frame == [
        "tetra_4cable: the workspace box's lower x face, workspace.lower[0] = -0.5 m, lies "
        "beyond the reels' frame: no reel exit is at x <= -0.5 m (the lowest at 0.0 m), so "
        "there every cable pulls the platform back along +x and nothing holds it",
        "tetra_4cable: the workspace box's upper y face, workspace.upper[1] = 3.2 m, lies "
        "beyond the reels' frame: no reel exit is at y >= 3.2 m (the highest at 3.0 m), so "
        "there every cable pulls the platform back along -y and nothing holds it"]
    # Below the lowest exit (z -0.5 < 0) is where a suspended platform hangs: no warning.
    valid_spec["workspace"] = {"lower": [1.0, 0.5, -0.5], "upper": [3.0, 2.5, 3.5]}
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="cdpm_drake.robot"):
        load_robot(write_robot(valid_spec, "high.yaml"))
    frame = [r.getMessage() for r in caplog.records if "reels' frame" in r.getMessage()]
    assert frame == [
        "tetra_4cable: the workspace box's upper z face, workspace.upper[2] = 3.5 m, lies "
        "beyond the reels' frame: no reel exit is at z >= 3.5 m (the highest at 3.0 m), so "
        "there every cable pulls the platform down (with its weight) and nothing holds it"]


def test_the_shipped_robots_boxes_lie_within_their_reels_frames():
    from cdpm_drake.robot import frame_warnings

    for name in SHIPPED_ROBOTS:
        assert frame_warnings(load_robot(name)) == []


def test_bad_limit(write_robot, valid_spec):
    valid_spec["limits"] = {"max_reel_speed": 0.0}
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "limits.max_reel_speed", "0.0")


@pytest.mark.parametrize("pair", [[1, 5], [2, 2], [0, 1]])
def test_bad_ignore_pair(write_robot, valid_spec, pair):
    valid_spec["ignore_pairs"] = [pair]
    path = write_robot(valid_spec)
    assert_names(load_error(path), str(path), "ignore_pairs", repr(pair), "1..4")


@pytest.mark.parametrize("text, expected", [("", "NoneType"), ("- 1\n- 2\n", "list"),
                                            ("name: [\n", "not valid YAML")])
def test_not_a_robot_mapping(write_robot, text, expected):
    path = write_robot(text)
    assert_names(load_error(path), str(path), expected)


# --- Robot built in code ---------------------------------------------------------------------


def _code_robot(**overrides):
    kw = dict(name="tri", reels=[[0.0, 0.0, 2.0], [2.0, 0.0, 2.0], [1.0, 2.0, 2.0]],
              attachments=np.zeros((3, 3)),
              workspace=Workspace(lower=[0.5, 0.5, 0.5], upper=[1.5, 1.5, 1.5]))
    kw.update(overrides)
    return Robot(**kw)


def test_robot_constructible_in_code():
    reels = np.array([[0.0, 0.0, 2.0], [2.0, 0.0, 2.0], [1.0, 2.0, 2.0]])
    robot = _code_robot(reels=reels)
    assert robot.num_cables == 3
    assert robot.source == "<code>"
    assert robot.limits == RobotLimits()
    np.testing.assert_array_equal(robot.workspace.center, [1.0, 1.0, 1.0])
    # The robot keeps its own copy: changing the caller's array does not move a reel.
    reels[0, 0] = 99.0
    assert robot.reels[0, 0] == 0.0
    # Frozen: neither the fields nor the arrays can be changed.
    with pytest.raises(dataclasses.FrozenInstanceError):
        robot.name = "other"
    with pytest.raises(ValueError):
        robot.reels[0, 0] = 1.0
    with pytest.raises(ValueError):
        robot.workspace.lower[0] = 0.0


def test_robot_in_code_is_validated_like_a_file():
    reels = np.array([[0.0, 0.0, 2.0], [2.0, 0.0, 2.0], [1.0, np.nan, 2.0]])
    with pytest.raises(RobotError) as info:
        _code_robot(reels=reels)
    assert_names(str(info.value), "<code>", "reels of cable 3", "nan")
    with pytest.raises(RobotError) as info:
        _code_robot(attachments=np.zeros((3, 2)))
    assert_names(str(info.value), "attachments of cable 1", "got 2", "[0.0, 0.0]")
    with pytest.raises(RobotError) as info:
        _code_robot(workspace=Workspace(lower=[1.5, 0.5, 0.5], upper=[0.5, 1.5, 1.5]))
    assert_names(str(info.value), "along x", "lower[0] = 1.5 m")


def test_workspace_contains():
    ws = Workspace(lower=np.array([0.0, 0.0, 0.0]), upper=np.array([1.0, 2.0, 3.0]))
    assert ws.contains([1.0, 2.0, 3.0]) is True  # the faces belong to the box
    assert ws.contains([1.0 + 1e-9, 1.0, 1.0]) is False
    assert ws.contains([1.0 + 1e-9, 1.0, 1.0], tol=1e-6) is True
    inside = ws.contains([[0.5, 0.5, 0.5], [0.5, -0.1, 0.5], [0.5, 0.5, 3.5]])
    np.testing.assert_array_equal(inside, [True, False, False])


# --- swapped attachments ---------------------------------------------------------------------


def test_swap_attachments_1_3():
    robot = load_robot("paper_7cable")
    before = robot.attachments.copy()
    swapped = robot.with_swapped_attachments(1, 3)
    # Cables are 1-based: swapping cables 1 and 3 exchanges rows 0 and 2, nothing else.
    expected = before.copy()
    expected[[0, 2]] = before[[2, 0]]
    np.testing.assert_array_equal(swapped.attachments, expected)
    assert not np.array_equal(before[0], before[2])  # so the swap is visible
    np.testing.assert_array_equal(swapped.reels, robot.reels)
    np.testing.assert_array_equal(swapped.workspace.lower, robot.workspace.lower)
    np.testing.assert_array_equal(robot.attachments, before)  # original unchanged
    # Swapping twice restores the robot; swaps commute with each other when disjoint.
    np.testing.assert_array_equal(swapped.with_swapped_attachments(3, 1).attachments, before)
    both = robot.with_swapped_attachments(1, 3).with_swapped_attachments(5, 7)
    other = robot.with_swapped_attachments(5, 7).with_swapped_attachments(1, 3)
    np.testing.assert_array_equal(both.attachments, other.attachments)
    # Lengths change only for the swapped cables (kinematics sees the new b_i).
    c = robot.workspace.center
    changed = cable_lengths(swapped, c) != cable_lengths(robot, c)
    np.testing.assert_array_equal(changed, [True, False, True, False, False, False, False])


@pytest.mark.parametrize("i, j, bad", [(0, 3, "0"), (1, 8, "8"), (-1, 2, "-1"),
                                       (1.0, 3, "1.0"), ("1", 3, "'1'")])
def test_swap_rejects_bad_cable_numbers(i, j, bad):
    robot = load_robot("paper_7cable")
    with pytest.raises(RobotError) as info:
        robot.with_swapped_attachments(i, j)
    assert_names(str(info.value), f"cable {bad}", "1..7")


def test_a_robot_built_in_code_takes_the_workspace_in_any_plain_form():
    import numpy as np

    from cdpm_drake.robot import Robot, RobotError, Workspace

    reels = [[0, 0, 3], [4, 0, 3], [2, 4, 3]]
    attachments = [[0, 0, 0.1], [0.1, 0, 0], [0, 0.1, 0]]
    for workspace in (Workspace([1, 1, 0.5], [3, 3, 2]), {"lower": [1, 1, 0.5],
                                                          "upper": [3, 3, 2]},
                      ([1, 1, 0.5], [3, 3, 2])):
        robot = Robot("tri", reels, attachments, workspace)
        np.testing.assert_array_equal(robot.workspace.center, [2.0, 2.0, 1.25])
    with pytest.raises(RobotError, match="workspace must be a Workspace"):
        Robot("tri", reels, attachments, 3.0)
