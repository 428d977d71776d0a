"""Safety limits after the admittance (limits.limit_velocity) and the workspace-wall force
(limits.wall_force): closed-form values, and invariants over random inputs."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdpm_drake.kernels.safety_limits import limit_velocity, wall_force

LOWER = np.array([0.5, 0.8, 0.3])
UPPER = np.array([3.0, 4.0, 2.4])
CENTER = 0.5 * (LOWER + UPPER)
T = 0.002
A_MAX = 2.0
V_MAX = 0.5


def limit(v_desired, v_previous, p, *, max_velocity=V_MAX, max_acceleration=A_MAX,
          virtual_wall=True):
    return limit_velocity(v_desired, v_previous, p, LOWER, UPPER, max_velocity=max_velocity,
                          max_acceleration=max_acceleration, time_step=T,
                          virtual_wall=virtual_wall)


# --- limit_velocity: each cap alone ------------------------------------------------------------


def test_velocity_inside_every_limit_passes_unchanged():
    v = np.array([0.1, -0.2, 0.05])
    np.testing.assert_array_equal(limit(v, v - 0.001, CENTER), v)


def test_speed_is_capped_along_the_desired_direction():
    # |(3, 4, 0)| = 5 m/s; capped to 0.5 m/s along the same direction: (0.3, 0.4, 0). The
    # previous command is already there, so the acceleration cap does not act.
    v = limit([3.0, 4.0, 0.0], [0.3, 0.4, 0.0], CENTER)
    np.testing.assert_allclose(v, [0.3, 0.4, 0.0], rtol=0, atol=1e-15)


def test_acceleration_is_capped_along_the_change():
    # From rest towards (0, 0.3, 0.4) (0.5 m/s): one tick may change the velocity by
    # a T = 2 * 0.002 = 0.004 m/s, along the change: (0, 0.0024, 0.0032).
    v = limit([0.0, 0.3, 0.4], [0.0, 0.0, 0.0], CENTER)
    np.testing.assert_allclose(v, [0.0, 0.0024, 0.0032], rtol=0, atol=1e-15)


def test_braking_curve_near_a_face():
    # 10 mm from the upper x face, moving towards it at 0.5 m/s with a speed limit of 1 m/s:
    # the discrete braking curve allows sqrt(2 a' gap) - a' T / 2 with a' = a / sqrt(3) per
    # axis (derivation in limits._wall_cap): with a = 2, sqrt(0.04 / sqrt(3)) - 0.002 / sqrt(3)
    # = 0.150812 m/s. The wall wins over the acceleration limit.
    p = CENTER.copy()
    p[0] = UPPER[0] - 0.01
    v = limit([0.5, 0.0, 0.0], [0.5, 0.0, 0.0], p, max_velocity=1.0)
    cap = np.sqrt(0.04 / np.sqrt(3.0)) - 0.002 / np.sqrt(3.0)
    np.testing.assert_allclose(v, [cap, 0.0, 0.0], rtol=0, atol=1e-12)
    assert abs(cap - 0.150812) < 1e-6
    # The same speed away from the face is not touched; nor are the other axes.
    v = limit([-0.5, 0.3, -0.2], [-0.5, 0.3, -0.2], p, max_velocity=1.0)
    np.testing.assert_array_equal(v, [-0.5, 0.3, -0.2])


def test_at_a_face_no_velocity_points_out_and_leaving_is_free():
    p = CENTER.copy()
    p[2] = LOWER[2]  # on the floor of the box
    v = limit([0.0, 0.001, -0.3], [0.0, 0.0, 0.0], p)
    assert v[2] == 0.0
    assert v[1] == pytest.approx(0.001, abs=1e-15)
    v = limit([0.0, 0.0, 0.003], [0.0, 0.0, 0.0], p)  # upwards, within a T
    np.testing.assert_allclose(v, [0.0, 0.0, 0.003], rtol=0, atol=1e-15)


def test_without_the_virtual_wall_the_face_does_not_brake():
    p = CENTER.copy()
    p[0] = UPPER[0] - 0.001
    v = limit([0.5, 0.0, 0.0], [0.5, 0.0, 0.0], p, virtual_wall=False)
    np.testing.assert_array_equal(v, [0.5, 0.0, 0.0])


def test_outside_the_box_only_motion_back_inside_is_allowed():
    p = UPPER + 0.01
    v = limit([0.2, 0.2, 0.2], [0.0, 0.0, 0.0], p)
    np.testing.assert_array_equal(v, [0.0, 0.0, 0.0])
    v = limit([-0.003, -0.002, 0.0], [0.0, 0.0, 0.0], p)
    np.testing.assert_allclose(v, [-0.003, -0.002, 0.0], rtol=0, atol=1e-15)


# --- limit_velocity: a run of ticks against a face ----------------------------------------------


@pytest.mark.parametrize("axis,sign", [(0, 1), (1, -1), (2, 1), (2, -1)])
def test_ticks_towards_a_face_stop_at_it_within_every_limit(axis, sign):
    """A desired velocity of 10 m/s into a face, integrated p += T v as the reels do: the
    platform reaches the face, never crosses it, and no tick exceeds the speed or the
    acceleration limit (the wall is approached on the braking curve)."""
    v_desired = np.zeros(3)
    v_desired[axis] = 10.0 * sign
    face = UPPER[axis] if sign > 0 else LOWER[axis]
    p, v = CENTER.copy(), np.zeros(3)
    for _ in range(4000):  # 8 s: ample for ~1.6 m at 0.5 m/s
        v_new = limit(v_desired, v, p)
        assert np.linalg.norm(v_new) <= V_MAX * (1 + 1e-12)
        assert np.linalg.norm(v_new - v) <= A_MAX * T * (1 + 1e-9)
        v = v_new
        p = p + T * v
        assert np.all(p >= LOWER - 1e-12) and np.all(p <= UPPER + 1e-12)
    # Stopped on the face: the last admissible step is below a T^2 / 8 = 1e-6 m from it.
    assert v[axis] == 0.0
    assert abs(p[axis] - face) <= A_MAX * T**2 / 8 + 1e-12
    np.testing.assert_array_equal(np.delete(p, axis), np.delete(CENTER, axis))


# --- limit_velocity: invariants over random inputs ----------------------------------------------

finite = st.floats(-5.0, 5.0, allow_nan=False)
vec = st.tuples(finite, finite, finite).map(np.array)
# Positions inside the box, often right at a face or a few ticks from it.
coordinate = st.one_of(st.floats(0.0, 1.0), st.sampled_from([0.0, 1.0]),
                       st.floats(0.0, 1e-3), st.floats(1 - 1e-3, 1.0))
inside = st.tuples(coordinate, coordinate, coordinate).map(
    lambda u: LOWER + np.array(u) * (UPPER - LOWER))


@settings(max_examples=300, deadline=None)
@given(v_desired=vec, v_previous=vec, p=inside)
def test_one_tick_never_leaves_the_box(v_desired, v_previous, p):
    v = limit(v_desired, v_previous, p)
    p_next = p + T * v
    assert np.all(p_next >= LOWER - 1e-12) and np.all(p_next <= UPPER + 1e-12)


@settings(max_examples=300, deadline=None)
@given(v_desired=vec, v_previous=vec, p=inside)
def test_without_the_wall_speed_and_acceleration_caps_hold(v_desired, v_previous, p):
    # The previous command obeyed the speed limit (it came out of this function).
    n = np.linalg.norm(v_previous)
    if n > V_MAX:
        v_previous = v_previous * (V_MAX / n)
    v = limit(v_desired, v_previous, p, virtual_wall=False)
    assert np.linalg.norm(v) <= V_MAX * (1 + 1e-12)
    assert np.linalg.norm(v - v_previous) <= A_MAX * T * (1 + 1e-12)


@settings(max_examples=200, deadline=None)
@given(v_desired=vec, v_previous=vec, u=st.tuples(*[st.floats(0.0, 1.0)] * 3))
def test_far_from_the_faces_the_wall_changes_nothing(v_desired, v_previous, u):
    n = np.linalg.norm(v_previous)
    if n > V_MAX:
        v_previous = v_previous * (V_MAX / n)
    # Farther than the braking distance of the top speed at the per-axis deceleration
    # a' = a / sqrt(3) (v^2 / 2a' + v T = 0.1093 m) plus a step, the wall cap is inactive.
    margin = 0.15
    p = LOWER + margin + np.array(u) * (UPPER - LOWER - 2 * margin)
    np.testing.assert_array_equal(limit(v_desired, v_previous, p),
                                  limit(v_desired, v_previous, p, virtual_wall=False))


# --- wall_force --------------------------------------------------------------------------------

MARGIN = 0.10
F_WALL = 4.0


def wall(p):
    return wall_force(p, LOWER, UPPER, margin=MARGIN, max_force=F_WALL)


def test_wall_force_is_zero_beyond_the_margin():
    np.testing.assert_array_equal(wall(CENTER), np.zeros(3))
    p = LOWER + MARGIN + 1e-9  # just beyond the margin of three faces at once
    np.testing.assert_array_equal(wall(p), np.zeros(3))


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_wall_force_is_max_force_at_a_face_pointing_inside(axis):
    p = CENTER.copy()
    p[axis] = LOWER[axis]
    expected = np.zeros(3)
    expected[axis] = F_WALL  # pushes towards +axis, into the box
    np.testing.assert_array_equal(wall(p), expected)
    p[axis] = UPPER[axis]
    np.testing.assert_array_equal(wall(p), -expected)
    p[axis] = UPPER[axis] + 0.5  # outside: still max_force, not more
    np.testing.assert_array_equal(wall(p), -expected)


def test_wall_force_between_margin_and_face_is_the_quadratic():
    # gap = margin / 2: max_force * (1/2)^2 = 1 N; gap = margin / 4: 4 * (3/4)^2 = 2.25 N.
    p = CENTER.copy()
    p[1] = UPPER[1] - MARGIN / 2
    p[2] = LOWER[2] + MARGIN / 4
    np.testing.assert_allclose(wall(p), [0.0, -1.0, 2.25], rtol=0, atol=1e-12)


def test_wall_force_is_c1_at_the_margin():
    """Value and slope vanish at gap = margin: the one-sided finite-difference slope from
    inside the margin, F(margin - h) / h = max_force h / margin^2, goes to zero with h, unlike
    a step (F / h ~ 1/h) or a kink (constant)."""
    def force_at_gap(gap):
        p = CENTER.copy()
        p[0] = LOWER[0] + gap
        return wall(p)[0]

    assert force_at_gap(MARGIN) == pytest.approx(0.0, abs=1e-15)  # p - lower rounds
    for h in (1e-2, 1e-3, 1e-4):
        slope = force_at_gap(MARGIN - h) / h
        assert slope == pytest.approx(F_WALL * h / MARGIN**2, rel=1e-6)
        assert force_at_gap(MARGIN + h) == 0.0
    # Central difference at the margin: ~0 (O(h)), against 2 F / margin = 80 N/m at the face.
    h = 1e-6
    central = (force_at_gap(MARGIN + h) - force_at_gap(MARGIN - h)) / (2 * h)
    assert abs(central) < 1e-3
    face_slope = (force_at_gap(h) - force_at_gap(0.0)) / h
    assert face_slope == pytest.approx(-2 * F_WALL / MARGIN, rel=1e-4)
