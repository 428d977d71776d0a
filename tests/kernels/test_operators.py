"""Operator models (the person at the handle): force tables, CSV replay, the spring-damper
hand, and the errors on bad descriptions."""

import numpy as np
import pytest

from cdpm_drake.kernels.plant.operators import (CsvOperator, ForceProfile, NoForce, NoOperator,
                                  OperatorError, ScriptedOperator, SpringHand,
                                  SpringHandOperator, load_force_csv, make_operator)

P = np.array([1.0, 2.0, 1.0])
V = np.zeros(3)

TIMES = [0.0, 1.0, 3.0]
FORCES = [[0.0, 0.0, 0.0], [2.0, -4.0, 1.0], [0.0, 4.0, 1.0]]


# --- ForceProfile ------------------------------------------------------------------------------


def test_profile_interpolates_linearly_between_breakpoints():
    profile = ForceProfile(TIMES, FORCES)
    np.testing.assert_allclose(profile.force(0.25, P, V), [0.5, -1.0, 0.25], atol=1e-15)
    np.testing.assert_allclose(profile.force(1.0, P, V), [2.0, -4.0, 1.0], atol=1e-15)
    # Halfway between t = 1 and t = 3: the mean of the two rows.
    np.testing.assert_allclose(profile.force(2.0, P, V), [1.0, 0.0, 1.0], atol=1e-15)


def test_profile_holds_its_end_values_outside_the_table():
    profile = ForceProfile(TIMES, FORCES)
    np.testing.assert_array_equal(profile.force(-5.0, P, V), FORCES[0])
    np.testing.assert_array_equal(profile.force(3.0, P, V), FORCES[-1])
    np.testing.assert_array_equal(profile.force(100.0, P, V), FORCES[-1])


def test_single_row_profile_is_constant_and_ignores_the_motion():
    profile = ForceProfile([0.5], [[1.0, 2.0, 3.0]])
    for t in (0.0, 0.5, 7.0):
        np.testing.assert_array_equal(profile.force(t, P + t, V + 1.0), [1.0, 2.0, 3.0])


def test_no_force_is_zero():
    np.testing.assert_array_equal(NoForce().force(1.0, P, V), np.zeros(3))


@pytest.mark.parametrize("times,forces,match", [
    ([], [], r"operator\.times must be a non-empty list"),
    ([0.0, 1.0], [[0.0, 0.0, 0.0]], r"operator\.forces must have one \[Fx, Fy, Fz\] row.*"
                                    r"shape \(1, 3\) for 2 times"),
    ([0.0], [[1.0, 2.0]], r"operator\.forces.*shape \(1, 2\)"),
    ([0.0, 1.0, 1.0], [[0, 0, 0]] * 3, r"operator\.times must increase strictly: "
                                       r"times\[2\] = .*1\.0.* s follows .*1\.0.* s"),
    ([0.0, 2.0, 1.0], [[0, 0, 0]] * 3, r"times\[2\] = .*1\.0"),
    ([0.0, float("nan")], [[0, 0, 0]] * 2, r"finite"),
    ([0.0, 1.0], [[0, 0, 0], [0, float("inf"), 0]], r"finite"),
])
def test_bad_profiles_are_rejected_naming_the_field(times, forces, match):
    with pytest.raises(OperatorError, match=match):
        ForceProfile(times, forces)


# --- CSV replay --------------------------------------------------------------------------------


def write_csv(tmp_path, text, name="force.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_csv_replay_matches_the_table(tmp_path):
    path = write_csv(tmp_path, "t,fx,fy,fz\n0,0,0,0\n1,2,-4,1\n3,0,4,1\n")
    replay = load_force_csv(path)
    reference = ForceProfile(TIMES, FORCES)
    for t in (-1.0, 0.0, 0.3, 1.0, 2.2, 3.0, 9.0):
        np.testing.assert_allclose(replay.force(t, P, V), reference.force(t, P, V), atol=1e-15)


def test_csv_header_is_case_and_space_tolerant(tmp_path):
    # (An extra column is refused: test_bad_csv_files_are_rejected_naming_the_file_and_line.)
    path = write_csv(tmp_path, " T , Fx,FY ,fz\n0,1,2,3\n2,3,2,1\n")
    np.testing.assert_allclose(load_force_csv(path).force(1.0, P, V), [2.0, 2.0, 2.0])


def test_csv_operator_resolves_relative_paths_against_the_scenario_dir(tmp_path):
    write_csv(tmp_path, "t,fx,fy,fz\n0,1,1,1\n")
    operator = make_operator(CsvOperator(path="force.csv"), base_dir=tmp_path)
    np.testing.assert_array_equal(operator.force(0.0, P, V), [1.0, 1.0, 1.0])


@pytest.mark.parametrize("text,match", [
    ("", r"is empty"),
    ("t,fx,fy,fz\n", r"has no data rows"),
    ("time,fx,fy,fz\n0,0,0,0\n", r"must have exactly the header t,fx,fy,fz \(four columns\), "
                                 r"got 'time,fx,fy,fz'"),
    ("t,fx,fy,fz\n0,0,0,0\n1,2,x,3\n", r"line 3: not four numbers \(t, fx, fy, fz\): "
                                      r"\['1', '2', 'x', '3'\]"),
    # Issue 42: an extra column, in the header or in a row, was dropped without a word.
    ("t,fx,fy,fz,tz\n0,0,0,0,1\n", r"exactly the header t,fx,fy,fz \(four columns\), got "
                                   r"'t,fx,fy,fz,tz'"),
    ("t,fx,fy,fz\n0,0,0,0\n1,2,3,4,5\n", r"line 3: not four numbers \(t, fx, fy, fz\): "
                                        r"\['1', '2', '3', '4', '5'\]"),
    ("t,fx,fy,fz\n0,0,0\n", r"line 2: not four numbers"),
    ("t,fx,fy,fz\n1,0,0,0\n0,0,0,0\n", r"times must increase strictly"),
    # Issue 22: NaN, inf and rows out of order name the file's line and the value. Lines count
    # from 1 with the header as line 1; the blank line 3 still counts.
    ("t,fx,fy,fz\n0,0,0,0\n\n1,nan,0,0\n", r"'.*force\.csv' line 4: t, fx, fy, fz must be "
                                        r"finite numbers, got \['1', 'nan', '0', '0'\]"),
    ("t,fx,fy,fz\n0,0,0,0\n1,0,-inf,0\n", r"line 3: .*finite.*'-inf'"),
    ("t,fx,fy,fz\n0,0,0,0\ninf,0,0,0\n", r"line 3: .*finite.*'inf'"),
    ("t,fx,fy,fz\n0,0,0,0\n2,0,0,0\n\n1.5,0,0,0\n", r"'.*force\.csv' line 5: times must "
                                                  r"increase strictly: t = 1\.5 s follows "
                                                  r"t = 2\.0 s on line 3"),
])
def test_bad_csv_files_are_rejected_naming_the_file_and_line(tmp_path, text, match):
    path = write_csv(tmp_path, text)
    with pytest.raises(OperatorError, match=match) as info:
        load_force_csv(path)
    assert "operator.path" in str(info.value)


def test_a_spreadsheets_trailing_commas_are_not_an_extra_column(tmp_path):
    path = write_csv(tmp_path, "t,fx,fy,fz,\n0,0,0,0,\n1,2,0,0,\n")
    np.testing.assert_array_equal(load_force_csv(path).forces, [[0, 0, 0], [2, 0, 0]])


def test_a_blank_line_in_a_csv_is_skipped(tmp_path):
    path = write_csv(tmp_path, "t,fx,fy,fz\n0,0,0,0\n\n2,2,0,0\n\n")
    np.testing.assert_array_equal(load_force_csv(path).force(1.0, P, V), [1.0, 0.0, 0.0])


def test_a_non_finite_scripted_row_is_named_by_its_index():
    with pytest.raises(OperatorError, match=r"operator\.times\[1\], operator\.forces\[1\]: .*"
                                            r"finite numbers, got t = 1\.0 s, \[0\.0, nan, 0\.0\]"):
        ForceProfile([0.0, 1.0], [[0, 0, 0], [0, float("nan"), 0]])


def test_missing_csv_file_names_the_path(tmp_path):
    with pytest.raises(OperatorError, match=r"operator\.path: force file '.*nope\.csv' does "
                                            r"not exist"):
        make_operator(CsvOperator(path="nope.csv"), base_dir=tmp_path)


# --- SpringHand --------------------------------------------------------------------------------


def hand(**kwargs):
    args = dict(waypoints=[[1.0, 2.0, 1.0], [2.0, 2.0, 1.0]], times=[0.0, 10.0],
                stiffness=60.0, damping=6.0, max_force=5.0)
    args.update(kwargs)
    return SpringHand(**args)


def test_spring_hand_target_moves_through_the_waypoints():
    h = hand()
    np.testing.assert_allclose(h.target(2.5), [1.25, 2.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(h.target(50.0), [2.0, 2.0, 1.0], atol=1e-15)


def test_spring_hand_below_the_cap_is_the_spring_damper():
    # At t = 1 s the target is [1.1, 2, 1]; p 2 cm short of it in x, moving at 0.05 m/s in y:
    # F = 60 (0.02, 0, 0) - 6 (0, 0.05, 0) = (1.2, -0.3, 0) N, |F| < 5 N.
    p = np.array([1.08, 2.0, 1.0])
    v = np.array([0.0, 0.05, 0.0])
    np.testing.assert_allclose(hand().force(1.0, p, v), [1.2, -0.3, 0.0], atol=1e-12)


def test_spring_hand_force_is_capped_at_max_force_along_the_spring():
    # 1 m from the target: the spring asks 60 N; the hand gives 5 N in the same direction.
    p = np.array([1.0, 2.0, 1.0])
    target = np.array([2.0, 2.6, 1.8])
    h = hand(waypoints=[target, target], times=[0.0, 1.0])
    f = h.force(0.5, p, np.zeros(3))
    assert np.linalg.norm(f) == pytest.approx(5.0, rel=1e-12)
    direction = (target - p) / np.linalg.norm(target - p)
    np.testing.assert_allclose(f / 5.0, direction, atol=1e-12)


def test_spring_hand_release_time_lets_go():
    h = hand(release_time=2.0)
    p = np.array([0.0, 0.0, 0.0])
    assert np.linalg.norm(h.force(1.999, p, V)) == pytest.approx(5.0)
    np.testing.assert_array_equal(h.force(2.0, p, V), np.zeros(3))


@pytest.mark.parametrize("field,value", [("stiffness", -1.0), ("damping", float("nan")),
                                         ("max_force", -0.5)])
def test_spring_hand_bad_gains_name_the_field_and_value(field, value):
    with pytest.raises(OperatorError, match=rf"operator\.{field} must be a finite value >= 0, "
                                            rf"got {value!r}"):
        hand(**{field: value})


def test_spring_hand_waypoints_must_match_the_times():
    # The message names the field the user wrote (waypoints), not the force table inside.
    with pytest.raises(OperatorError, match=r"waypoints must have one \[x, y, z\] row \(m\)"):
        hand(waypoints=[[1.0, 2.0, 1.0]], times=[0.0, 1.0])


# --- make_operator -----------------------------------------------------------------------------


def test_make_operator_builds_each_type():
    assert isinstance(make_operator(NoOperator()), NoForce)
    scripted = make_operator(ScriptedOperator(times=TIMES, forces=FORCES))
    np.testing.assert_allclose(scripted.force(2.0, P, V), [1.0, 0.0, 1.0])
    spring = make_operator(SpringHandOperator(waypoints=[[1.0, 2.0, 1.0]], times=[0.0]))
    np.testing.assert_array_equal(spring.force(0.0, [1.0, 2.0, 1.0], V), np.zeros(3))


def test_make_operator_rejects_an_unknown_type_listing_the_valid_ones():
    with pytest.raises(OperatorError, match=r"unknown operator 'dict'; valid operators: "
                                            r"\['NoOperator', 'ScriptedOperator', "
                                            r"'CsvOperator', 'SpringHandOperator'\]"):
        make_operator({"times": [0.0]})
