"""Loop-closure kinematics (paper eqs. 1-3): Jacobian against Drake AutoDiffXd, inverse/forward
round trips, error messages, single vs batch shapes."""

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdpm_drake.kernels.kinematics import (KinematicsError, cable_lengths, cable_vectors,
                                   forward_kinematics, jacobian)
from cdpm_drake.robot import load_robot

from conftest import HAND_ROBOT, SHIPPED_ROBOTS

ALL_ROBOTS = SHIPPED_ROBOTS + (str(HAND_ROBOT),)


@pytest.fixture(scope="module", params=ALL_ROBOTS, ids=lambda r: r.rsplit("/", 1)[-1])
def robot(request):
    return load_robot(request.param)


@pytest.fixture(scope="module", params=SHIPPED_ROBOTS)
def shipped(request):
    return load_robot(request.param)


def workspace_points(robot, n, seed, margin=0.0):
    """n uniform random platform positions in the workspace box grown by `margin` m."""
    rng = np.random.default_rng(seed)
    ws = robot.workspace
    return rng.uniform(ws.lower - margin, ws.upper + margin, size=(n, 3))


def autodiff_lengths_gradient(robot, P):
    """d l_i / d p at each row of P (N, 3) by forward-mode AutoDiffXd, from eq. 2 written out
    independently of cdpm_drake.kernels.kinematics: l_i = sqrt(sum_k (p_k + b_ik - a_ik)^2)."""
    from pydrake.autodiffutils import AutoDiffXd

    eye = np.eye(3)
    P_ad = np.array([[AutoDiffXd(P[n, k], eye[k]) for k in range(3)] for n in range(len(P))],
                    dtype=object)
    rho = P_ad[:, None, :] + (robot.attachments - robot.reels)  # (N, m, 3) of AutoDiffXd
    lengths = np.sqrt((rho * rho).sum(axis=-1))  # object ufunc: AutoDiffXd.sqrt
    return np.array([[l.derivatives() for l in row] for row in lengths])  # (N, m, 3)


# --- eq. 1 and 2 on numbers worked by hand ----------------------------------------------------


def test_lengths_of_hand_robot_off_centre():
    robot = load_robot(HAND_ROBOT)
    # p = (4.5, 3.5, 1.5) + (1, 0, 0) = (5.5, 3.5, 1.5): B1 = p + b1 = (5, 3, 2),
    # rho1 = B1 - a1 = (5-1, 3-1, 2-8) = (4, 2, -6): |rho1|^2 = 16 + 4 + 36 = 56.
    # B2 = (6, 3, 2), rho2 = (6-7, 3-2, 2-4) = (-1, 1, -2): 1 + 1 + 4 = 6.
    # B3 = (6, 4, 2), rho3 = (-2, -2, -6): 4 + 4 + 36 = 44.
    # B4 = (5, 4, 2), rho4 = (5, -4, 2): 25 + 16 + 4 = 45.
    p = np.array([5.5, 3.5, 1.5])
    np.testing.assert_array_equal(cable_vectors(robot, p),
                                  [[4, 2, -6], [-1, 1, -2], [-2, -2, -6], [5, -4, 2]])
    np.testing.assert_allclose(cable_lengths(robot, p), np.sqrt([56, 6, 44, 45]), rtol=1e-15)
    # Eq. 3 by hand: row i of J is rho_i / |rho_i|.
    np.testing.assert_allclose(jacobian(robot, p)[1], np.array([-1, 1, -2]) / np.sqrt(6),
                               rtol=1e-15)


# --- Jacobian (eq. 3) -------------------------------------------------------------------------


def test_jacobian_matches_autodiff_at_1000_points(robot):
    # Random positions in the workspace grown by 0.3 m, so the check is not limited to the
    # box; away from the reels (lengths > 0.1 m), where eq. 3 is smooth.
    P = workspace_points(robot, 1000, seed=1, margin=0.3)
    assert cable_lengths(robot, P).min() > 0.1
    J_ad = autodiff_lengths_gradient(robot, P)
    J = jacobian(robot, P)
    assert J.shape == J_ad.shape == (1000, robot.num_cables, 3)
    # Relative error per row (each row of J is a unit vector, so this is also absolute).
    err = np.linalg.norm(J - J_ad, axis=-1) / np.linalg.norm(J_ad, axis=-1)
    assert err.max() < 1e-9, err.max()


def test_jacobian_maps_platform_velocity_to_cable_speed(shipped):
    # l_dot = J p_dot (eq. 3), checked with central differences along a straight path,
    # independent of AutoDiff: (l(p + h v) - l(p - h v)) / (2h) = J(p) v + O(h^2).
    P = workspace_points(shipped, 50, seed=2)
    V = np.random.default_rng(3).normal(size=P.shape)
    h = 1e-5
    fd = (cable_lengths(shipped, P + h * V) - cable_lengths(shipped, P - h * V)) / (2 * h)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", jacobian(shipped, P), V), fd,
                               rtol=0, atol=1e-8)


# --- forward kinematics -----------------------------------------------------------------------


def test_round_trip_1000_workspace_positions(shipped):
    P = workspace_points(shipped, 1000, seed=4)
    L = cable_lengths(shipped, P)
    # Default start: the workspace centre.
    P_fk = forward_kinematics(shipped, L)
    assert P_fk.shape == (1000, 3)
    assert np.linalg.norm(P_fk - P, axis=-1).max() < 1e-9
    np.testing.assert_allclose(cable_lengths(shipped, P_fk), L, rtol=0, atol=1e-9)


def test_converges_from_a_guess_half_a_metre_away(robot):
    P = workspace_points(robot, 300, seed=5)
    d = np.random.default_rng(6).normal(size=P.shape)
    guess = P + 0.5 * d / np.linalg.norm(d, axis=-1, keepdims=True)
    np.testing.assert_allclose(np.linalg.norm(guess - P, axis=-1), 0.5)
    P_fk = forward_kinematics(robot, cable_lengths(robot, P), p_guess=guess)
    assert np.linalg.norm(P_fk - P, axis=-1).max() < 1e-9
    # One position with one guess: same answer, single shape.
    p = forward_kinematics(robot, cable_lengths(robot, P[0]), p_guess=guess[0])
    assert p.shape == (3,)
    np.testing.assert_allclose(p, P[0], rtol=0, atol=1e-9)


def test_noise_below_the_allowed_residual_is_accepted(shipped):
    # Lengths measured to 0.1 um still give a position: max_residual defaults to 1e-6 m.
    P = workspace_points(shipped, 20, seed=7)
    L = cable_lengths(shipped, P) + 1e-7 * np.random.default_rng(8).uniform(-1, 1, (20, 1))
    P_fk = forward_kinematics(shipped, L)
    assert np.abs(cable_lengths(shipped, P_fk) - L).max() < 1e-6


@pytest.mark.parametrize("delta", [0.1, 1e-4])
def test_inconsistent_lengths_raise_naming_the_residual(shipped, delta):
    c = shipped.workspace.center
    L = cable_lengths(shipped, c)
    L[0] += delta  # cable 1 too long by delta: no position fits all cables
    with pytest.raises(KinematicsError) as info:
        forward_kinematics(shipped, L)
    msg = str(info.value)
    assert "inconsistent" in msg and repr(shipped.name) in msg
    found = re.search(r"position \[(.*?)\] m leaves a residual of (\S+) mm on cable (\d+) "
                      r"\(allowed (\S+) mm\)", msg)
    assert found, msg
    p_fit = np.array([float(x) for x in found.group(1).split(",")])
    residual, cable = float(found.group(2)) / 1000, int(found.group(3))
    assert float(found.group(4)) / 1000 == pytest.approx(1e-6)
    # The true position leaves a residual of delta on cable 1, so the best fit does no worse;
    # and it must exceed the allowed 1e-6 m, or it should not have raised.
    assert 1e-6 < residual <= delta
    # The message is consistent with itself: at the reported position (rounded to 1 um) the
    # worst cable and its residual are the ones named.
    r = cable_lengths(shipped, p_fit) - L
    assert cable == int(np.argmax(np.abs(r))) + 1
    assert residual == pytest.approx(np.abs(r).max(), rel=1e-2, abs=3e-6)


def test_inconsistent_row_in_a_batch_raises(shipped):
    P = workspace_points(shipped, 10, seed=9)
    L = cable_lengths(shipped, P)
    L[7, 2] -= 0.05
    with pytest.raises(KinematicsError, match="residual"):
        forward_kinematics(shipped, L)


def test_cut_short_is_reported_as_not_converging(shipped):
    # Consistent lengths, but one iteration from 0.5 m away cannot reach them: the error must
    # say so rather than blame the lengths.
    p = shipped.workspace.center
    with pytest.raises(KinematicsError, match=r"did not converge in 1 iterations \(residual"):
        forward_kinematics(shipped, cable_lengths(shipped, p),
                           p_guess=p + [0.5, 0.0, 0.0], max_iterations=1)


@pytest.mark.parametrize("count", [0, 6, 9])
def test_wrong_number_of_lengths(count):
    robot = load_robot("cube_8cable")
    with pytest.raises(KinematicsError) as info:
        forward_kinematics(robot, np.ones(count))
    msg = str(info.value)
    assert "expected 8 cable lengths" in msg and f"got {count}" in msg and "'cube_8cable'" in msg


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_lengths(bad):
    robot = load_robot("paper_7cable")
    L = cable_lengths(robot, np.tile(robot.workspace.center, (3, 1)))
    L[1, 3] = bad  # batch row 1, cable 4 (1-based)
    with pytest.raises(KinematicsError) as info:
        forward_kinematics(robot, L)
    assert "cable 4" in str(info.value) and repr(float(bad)) in str(info.value)


# --- single vs batch -------------------------------------------------------------------------


def test_single_and_batch_shapes(robot):
    m = robot.num_cables
    P = workspace_points(robot, 5, seed=10)
    p = P[2]
    assert cable_vectors(robot, p).shape == (m, 3)
    assert cable_lengths(robot, p).shape == (m,)
    assert jacobian(robot, p).shape == (m, 3)
    assert forward_kinematics(robot, cable_lengths(robot, p)).shape == (3,)
    assert cable_vectors(robot, P).shape == (5, m, 3)
    assert cable_lengths(robot, P).shape == (5, m)
    assert jacobian(robot, P).shape == (5, m, 3)
    assert forward_kinematics(robot, cable_lengths(robot, P)).shape == (5, 3)
    # A batch of one stays a batch.
    assert forward_kinematics(robot, cable_lengths(robot, P[:1])).shape == (1, 3)
    # Row n of a batch equals the single-position result (no mixing across the batch).
    np.testing.assert_array_equal(cable_vectors(robot, P)[2], cable_vectors(robot, p))
    np.testing.assert_array_equal(cable_lengths(robot, P)[2], cable_lengths(robot, p))
    np.testing.assert_array_equal(jacobian(robot, P)[2], jacobian(robot, p))
    # Lists work as well as arrays.
    np.testing.assert_array_equal(cable_lengths(robot, p.tolist()), cable_lengths(robot, p))


@settings(max_examples=50, deadline=None)
@given(p=st.tuples(*[st.floats(-5.0, 5.0) for _ in range(3)]))
def test_jacobian_rows_are_unit_vectors_along_the_cables(p):
    # Eq. 3: J_i = rho_i^T / |rho_i|, so |J_i| = 1 and J_i . rho_i = |rho_i| = l_i.
    robot = load_robot("cube_8cable")
    rho = cable_vectors(robot, p)
    lengths = cable_lengths(robot, p)
    if lengths.min() < 1e-6:
        return  # at a reel the direction is undefined
    J = jacobian(robot, p)
    np.testing.assert_allclose(np.linalg.norm(J, axis=-1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", J, rho), lengths, rtol=1e-12)
    # rho_i = p + b_i - a_i: every cable vector moves with p one-for-one (eq. 1).
    np.testing.assert_allclose(cable_vectors(robot, np.add(p, [1.0, 0, 0])) - rho,
                               np.tile([1.0, 0, 0], (8, 1)), atol=1e-12)
