"""Full-pose kinematics and the full-pose controller's kernels (pose.py, pose_control.py).

References: finite differences of the rigid lengths; the translating functions (kinematics,
interference) on a robot whose attachment points are rotated by hand; scipy's linprog
(HiGHS) for the largest achievable minimum tension t*; closed forms derived in comments.
"""

import dataclasses
import math

import numpy as np
import pytest
from conftest import highs_t_star

from cdpm_drake.kernels import full_pose as pc
from cdpm_drake.kernels.interference import InterferenceParams, interference_tick, pair_geometry
from cdpm_drake.kernels.pose import (PoseError, forward_pose, pose_jacobian, pose_lengths,
                             rotation_exp, rotation_log)
from cdpm_drake.robot import load_robot
from cdpm_drake.kernels.rotation import rotation_from_rpy
from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix

ROBOT = load_robot("paper_7cable")
M = ROBOT.num_cables
REELS = np.ascontiguousarray(ROBOT.reels)
ATTACH = np.ascontiguousarray(ROBOT.attachments)
EA = 70000.0
S = pc.sizes(M)


def exp(phi):
    out = np.empty((3, 3))
    rotation_exp(*phi, out)
    return out


def random_poses(seed, n, tilt=0.2):
    rng = np.random.default_rng(seed)
    lo, hi = ROBOT.workspace.lower + 0.3, ROBOT.workspace.upper - 0.3
    return [(lo + (hi - lo) * rng.uniform(size=3), rotation_from_rpy(rng.uniform(-tilt, tilt, 3)))
            for _ in range(n)]


# --- rotations ---------------------------------------------------------------------------------


@pytest.mark.parametrize("phi", [[0.1, 0.2, -0.3], [1e-9, 0.0, 0.0], [0.0, 3.1, 0.02],
                                 [0.0, 0.0, 0.0], [-2.0, 1.0, 0.5]])
def test_rotation_exp_and_log_are_inverse_and_exp_is_a_rotation(phi):
    R = exp(phi)
    np.testing.assert_allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(rotation_log(R), phi, rtol=0, atol=1e-12)
    # Rodrigues against the closed form of a rotation about z.
    np.testing.assert_allclose(exp([0.0, 0.0, 0.4]), rotation_from_rpy([0, 0, 0.4]), atol=1e-15)


# --- forward kinematics of a pose ------------------------------------------------------------


def test_forward_pose_recovers_random_poses_from_a_level_guess():
    for p, R in random_poses(1, 20):
        pe, Re, r = forward_pose(ROBOT, pose_lengths(ROBOT, p, R), p + 0.01, np.eye(3))
        np.testing.assert_allclose(pe, p, rtol=0, atol=1e-10)
        np.testing.assert_allclose(Re, R, rtol=0, atol=1e-10)
        assert np.abs(r).max() < 1e-10


def test_one_cholesky_factor_solves_every_right_hand_side_as_solve_spd_does():
    # The ringing kernel factors its stiffness once a tick and solves m + 1 right-hand sides
    # with it (cholesky, cholesky_solve): the same operations as solve_spd per side, so the
    # same bits; the reference for the values is numpy's solve. A matrix that is not
    # positive definite is refused by both, the solution left untouched.
    from cdpm_drake.kernels.pose import cholesky, cholesky_solve, solve_spd

    rng = np.random.default_rng(5)
    B = rng.normal(size=(6, 6))
    A = B @ B.T + 0.1 * np.eye(6)
    F = A.copy()
    assert cholesky(F)
    np.testing.assert_allclose(np.tril(F) @ np.tril(F).T, A, rtol=0, atol=1e-12)
    for g in rng.normal(size=(8, 6)):
        x, y = np.empty(6), np.empty(6)
        cholesky_solve(F, g, x)
        assert solve_spd(A.copy(), g, y)
        assert np.array_equal(x, y)
        np.testing.assert_allclose(x, np.linalg.solve(A, g), rtol=1e-10)
    indefinite = A - 2.0 * np.linalg.eigvalsh(A)[0] * np.eye(6)
    x = np.full(6, 7.0)
    assert not cholesky(indefinite.copy()) and not solve_spd(indefinite.copy(), g, x)
    assert np.all(x == 7.0)


def test_forward_pose_needs_six_cables():
    four = dataclasses.replace(ROBOT, reels=ROBOT.reels[:4], attachments=ROBOT.attachments[:4])
    with pytest.raises(PoseError, match="at least 6 cables"):
        forward_pose(four, np.ones(4))


def test_pose_jacobian_matches_finite_differences():
    h = 1e-6
    for p, R in random_poses(2, 5):
        J = pose_jacobian(ROBOT, p, R)
        fd = np.empty((M, 6))
        for k in range(3):
            d = np.eye(3)[k] * h
            fd[:, k] = (pose_lengths(ROBOT, p + d, R) - pose_lengths(ROBOT, p - d, R)) / (2 * h)
            fd[:, 3 + k] = (pose_lengths(ROBOT, p, exp(d) @ R)
                            - pose_lengths(ROBOT, p, exp(-d) @ R)) / (2 * h)
        np.testing.assert_allclose(J, fd, rtol=0, atol=1e-8)
        # J = -W^T: the wrench matrix of the same pose (tension.py's, an independent form).
        np.testing.assert_allclose(J, -wrench_matrix(ROBOT, p, R).T, rtol=0, atol=1e-14)


def _fk(L0, T_assumed, p_guess, R_guess, max_residual=0.02, EA_=EA, started=1.0,
        mass=2.5, handle=(0.0, 0.0, -0.15)):
    params = np.array([EA_, max_residual, mass, *handle, 40.0])
    x = np.concatenate([L0, T_assumed, p_guess, np.asarray(R_guess).ravel(), [started]])
    out = np.empty(S["fk_out"])
    status = pc.pose_fk_tick(REELS, ATTACH, params, x, out)
    return status, out[:3], out[3:12].reshape(3, 3), out[13:16], out[16:16 + M]


def test_pose_fk_tick_corrects_the_lengths_for_the_stretch():
    """Encoders read the unstretched lengths L0 = L EA / (EA + T); given the true tensions the
    fit is exact, without the correction it is off by about the stretch (T L / EA ~ 1 mm)."""
    p, R = random_poses(3, 1)[0]
    T = np.array([20.0, 35.0, 15.0, 40.0, 25.0, 30.0, 18.0])
    L0 = pose_lengths(ROBOT, p, R) * EA / (EA + T)
    status, pe, Re, rpy, r = _fk(L0, T, p + 0.002, np.eye(3))
    assert status == pc.FK_OK
    np.testing.assert_allclose(pe, p, rtol=0, atol=1e-10)
    np.testing.assert_allclose(Re, R, rtol=0, atol=1e-10)
    np.testing.assert_allclose(rotation_from_rpy(rpy), R, rtol=0, atol=1e-12)
    assert np.abs(r).max() < 1e-10
    status, pe, _, _, _ = _fk(L0, T, p, R, EA_=0.0)  # no correction
    assert np.linalg.norm(pe - p) > 2e-4


def test_pose_fk_tick_reports_lengths_no_pose_fits():
    p, R = random_poses(4, 1)[0]
    # 10 mm along the wrench matrix's nullspace: no pose change removes any of it, so some
    # cable keeps at least 10 / sqrt(7) = 3.8 mm.
    n = np.linalg.svd(wrench_matrix(ROBOT, p, R))[2][-1]
    L = pose_lengths(ROBOT, p, R) + 0.01 * n
    status, pe, _, _, r = _fk(L, np.zeros(M), p, R, max_residual=0.003)
    assert status == pc.FK_INCONSISTENT
    np.testing.assert_allclose(pe, p, atol=1e-9)  # the pose itself is still found
    np.testing.assert_allclose(np.abs(r), 0.01 * np.abs(n), atol=1e-9)
    assert _fk(L, np.zeros(M), p, R, max_residual=0.0101)[0] == pc.FK_OK


# --- tensions ------------------------------------------------------------------------------------


def _tension(p, R, F, r, L0, T_assumed, v=np.zeros(3), v_prev=np.zeros(3), ticks=0.0,
             floor=10.0, mass=2.5, handle=(0.0, 0.0, -0.15), slew=1e9, T_before=None,
             ceiling=1e9, warmup=1.0, hard_floor=3.0, fall=None, ringing=None, factor=0.0,
             lead=0.0, rate_time=0.0, speed=0.0, F_before=np.zeros(3), F_rate=np.zeros(3)):
    # The fall rate (N/s) is params[11]; it defaults to the slew rate as the block's does.
    # params[12] the ringing factor (0: no tension sensor), ringing the variance input (N^2).
    params = np.array([mass, *handle, EA, floor, ceiling, 0.002, slew, warmup, hard_floor,
                       slew if fall is None else fall, factor, lead, rate_time, speed])
    x = np.concatenate([p, np.asarray(R).ravel(), F, v, r, L0, T_assumed,
                        np.zeros(M) if ringing is None else ringing, np.zeros(M), v_prev,
                        [ticks], T_before if T_before is not None else np.zeros(M),
                        F_before, F_rate, np.zeros(3)])  # F_settled: no settle time here
    out = np.empty(S["tension_out"])
    status = pc.tension_tick(REELS, ATTACH, params, x, out)
    return status, out[:M], out[M:2 * M], out[3 * M], out[3 * M + 3:]


def test_the_target_balances_weight_hand_and_inertia_with_the_largest_floor_allowed():
    p = np.array([1.6, 2.2, 1.1])
    R = rotation_from_rpy([0.02, -0.01, 0.03])
    F = np.array([3.0, -1.5, 2.0])
    # The commanded acceleration the target takes in: the command against its low-passed
    # value (the memory's v_prev slot), over pose_control.ACCELERATION_TIME.
    v_prev, v = np.array([0.1, 0.0, 0.0]), np.array([0.1, 0.002, -0.001])
    a = (v - v_prev) / pc.ACCELERATION_TIME
    L0 = pose_lengths(ROBOT, p, R)
    status, T_cmd, _, t_star, _ = _tension(p, R, F, np.zeros(M), L0, np.full(M, 20.0), v=v,
                                           v_prev=v_prev, ticks=1.0)
    # The wrench, built independently: weight and hand at the rotated handle, minus m a.
    w = gravity_wrench(2.5, F, R @ np.array([0.0, 0.0, -0.15]))
    w[:3] -= 2.5 * a
    W = wrench_matrix(ROBOT, p, R)
    np.testing.assert_allclose(W @ T_cmd + w, 0.0, atol=1e-9)
    reference = highs_t_star(W, w)
    if math.isfinite(reference):
        assert t_star == pytest.approx(reference, abs=1e-6)
    else:
        assert t_star == reference
    assert T_cmd.min() >= min(10.0, t_star) - pc.FLOOR_MARGIN - 1e-9


def test_the_estimate_reads_the_internal_tension_from_the_redundant_length():
    """True tensions T = T_p + 60 n; the forward kinematics assumed T + 7 n (internal only).
    The fit's residual along n gives back the true internal level: within 2 % of the 7 N in
    one tick (the assumed error's stretch, weighted by each cable's length, also moves the
    fitted pose a little), and within 1 mN after five ticks of feeding the estimate back, as
    the controller does."""
    p, R = random_poses(5, 1)[0]
    F = np.array([1.0, -2.0, 0.5])
    W = wrench_matrix(ROBOT, p, R)
    w = gravity_wrench(2.5, F, R @ np.array([0.0, 0.0, -0.15]))
    n = np.linalg.svd(W)[2][-1]
    T_true = -np.linalg.pinv(W) @ w + 60.0 * n
    L0 = pose_lengths(ROBOT, p, R) * EA / (EA + T_true)
    T_assumed = T_true + 7.0 * n
    _, pe, Re, _, r = _fk(L0, T_assumed, p, R)
    _, _, T_est, _, _ = _tension(pe, Re, F, r, L0, T_assumed)
    assert np.abs(T_est - T_true).max() < 0.14
    for _ in range(5):
        _, pe, Re, _, r = _fk(L0, T_est, pe, Re)
        _, _, T_est, _, _ = _tension(pe, Re, F, r, L0, T_est)
    assert np.abs(T_est - T_true).max() < 1e-3
    # Without the residual, the estimate would keep the assumed 7 N of internal error.
    _, _, T_blind, _, _ = _tension(pe, Re, F, np.zeros(M), L0, T_assumed)
    assert np.linalg.norm(T_blind - T_true) > 5.0  # |7 n| = 7 N


# --- orientation hold ----------------------------------------------------------------------------


def test_the_orientation_hold_latches_and_turns_back_at_its_gain():
    R0 = rotation_from_rpy([0.01, 0.02, -0.03])
    x = np.concatenate([R0.ravel(), np.zeros(10)])
    out = np.empty(S["orientation_out"])
    pc.orientation_tick(7.0, 1.0, x, out)
    np.testing.assert_allclose(out[:3], 0.0, atol=1e-15)
    np.testing.assert_array_equal(out[3:12], R0.ravel())
    # Then yawed by 0.05 rad about z (base frame): w = 7 (-0.05) z.
    R = exp([0.0, 0.0, 0.05]) @ R0
    out2 = np.empty(S["orientation_out"])
    pc.orientation_tick(7.0, 1.0, np.concatenate([R.ravel(), out[12:]]), out2)
    np.testing.assert_allclose(out2[:3], [0.0, 0.0, -0.35], atol=1e-12)


# --- the Jacobian mapping of a pose --------------------------------------------------------------


def _rates(p, R, v, w, R_ref, L0, T, memory, gain=20.0, tension=False, integral=0.0,
           dead_band=0.0):
    x = np.concatenate([p, np.asarray(R).ravel(), v, w, np.asarray(R_ref).ravel(), L0, T,
                        memory])
    out = np.empty(S["rates_out"])
    params = np.array([gain, integral, 0.002, EA if tension else 0.0, float(tension),
                       dead_band, 1.0])
    pc.pose_rates_tick(REELS, ATTACH, params, x, out)
    return out[:M], out[M:2 * M], out[2 * M:]


def test_the_first_tick_sends_the_twist_through_the_pose_jacobian():
    p, R = random_poses(7, 1)[0]
    v, w = np.array([0.1, -0.05, 0.02]), np.array([0.01, 0.0, -0.02])
    L0 = pose_lengths(ROBOT, p, R) + 0.003  # offsets latched: no loop error
    cmd, l_d, memory = _rates(p, R, v, w, R, L0, np.zeros(M), np.zeros(3 * M + 4))
    np.testing.assert_allclose(cmd, pose_jacobian(ROBOT, p, R) @ np.r_[v, w], atol=1e-14)
    np.testing.assert_allclose(l_d, L0, atol=1e-14)
    np.testing.assert_allclose(memory[:3], p + 0.002 * v, atol=1e-15)


def test_tension_control_commands_the_unstretched_lengths_of_the_commanded_pose():
    p, R = random_poses(8, 1)[0]
    T = np.linspace(8.0, 30.0, M)
    L0 = pose_lengths(ROBOT, p, R) * EA / (EA + T) + 1e-4  # encoders 0.1 mm long
    memory = np.r_[p, np.zeros(2 * M), 1.0, T]  # the last command's tensions: the same
    cmd, l_d, _ = _rates(p, R, np.zeros(3), np.zeros(3), R, L0, T, memory, tension=True)
    np.testing.assert_allclose(l_d, pose_lengths(ROBOT, p, R) * EA / (EA + T), atol=1e-14)
    np.testing.assert_allclose(cmd, 20.0 * (l_d - L0), atol=1e-14)  # at rest: the loop alone


def test_a_ramping_tension_command_feeds_its_lengths_rate_forward():
    """The commanded tensions changed since the last tick (T_previous -> T): beside the loop,
    the reels get the rate of the unstretched lengths, (l_d(T) - l_d(T_previous)) / step,
    the finite difference of the kernel's own l_d (computed here from the lengths), and the
    loop's correction stays what it was: a ramp moves its lengths as it ramps."""
    p, R = random_poses(8, 1)[0]
    T = np.linspace(8.0, 30.0, M)
    T_previous = T - np.linspace(4.0, -2.0, M)  # 2000 to -1000 N/s
    L = pose_lengths(ROBOT, p, R)
    L0 = L * EA / (EA + T) + 1e-4
    memory = np.r_[p, np.zeros(2 * M), 1.0, T_previous]
    cmd, l_d, nxt = _rates(p, R, np.zeros(3), np.zeros(3), R, L0, T, memory, tension=True)
    feed = (L * EA / (EA + T) - L * EA / (EA + T_previous)) / 0.002
    np.testing.assert_allclose(cmd, feed + 20.0 * (l_d - L0), rtol=0, atol=1e-12)
    assert np.abs(feed).max() > 0.05  # more than the loop's corrections may add
    np.testing.assert_array_equal(nxt[-M:], T)  # the next tick's T_previous


# --- interference on the cables of a pose --------------------------------------------------------


def test_posed_interference_is_the_translating_tick_on_rotated_attachments():
    robot = ROBOT.with_swapped_attachments(1, 3)
    P = robot.num_pairs
    params = InterferenceParams(d_l=np.full(P, 0.05), d_u=np.full(P, 0.061),
                                F_u=np.full(P, 2.0), eps=np.full(P, 0.1), F_max=2.0,
                                pairs=tuple(robot.pairs))
    i, j = robot.pair_index
    p = np.array([1.77, 3.65, 1.22])
    for R in (np.eye(3), rotation_from_rpy([0.01, -0.02, 0.015])):
        out = np.empty(3 + 13 * P)
        pc.interference_posed_tick(np.ascontiguousarray(robot.reels),
                                   np.ascontiguousarray(robot.attachments),
                                   i.astype(np.int64), j.astype(np.int64), params.packed,
                                   params.gradient_floor, params.F_max,
                                   np.r_[p, R.ravel(), np.zeros(P)], np.zeros((P, 12)), out)
        rotated = dataclasses.replace(robot, attachments=robot.attachments @ R.T)
        ref = np.empty(3 + 13 * P)
        interference_tick(pair_geometry(rotated), params.packed, params.gradient_floor,
                          params.F_max, p, np.zeros(P), True, ref)
        np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)


def test_the_length_loop_is_pi_with_the_drives_dead_band_made_up():
    """At rest with a 1 mm error on one cable: l_dot = K_l e + K_i (I + T e) + 0.9 u_c
    tanh(e / 20 um), with u_c the drives' dead band (m/s); the integral is clipped so its
    term stays within MAX_INTEGRAL_SPEED."""
    p, R = random_poses(9, 1)[0]
    L = pose_lengths(ROBOT, p, R)
    e = np.zeros(M)
    e[3] = 0.001
    integral = np.full(M, 2e-5)
    memory = np.r_[p, np.zeros(M), integral, 1.0, np.zeros(M)]
    cmd, _, nxt = _rates(p, R, np.zeros(3), np.zeros(3), R, L - e, np.zeros(M), memory,
                         gain=20.0, integral=100.0, dead_band=0.005)
    new_integral = integral + 0.002 * e
    expected = 20.0 * e + 100.0 * new_integral + 0.9 * 0.005 * np.tanh(e / 2e-5)
    np.testing.assert_allclose(cmd, expected, rtol=0, atol=1e-12)  # lengths ~3 m: 1e-16 rel
    np.testing.assert_allclose(nxt[3 + M:3 + 2 * M], new_integral, rtol=0, atol=1e-18)
    # A long stall: the integral stops at MAX_INTEGRAL_SPEED / K_i.
    memory = np.r_[p, np.zeros(M), np.full(M, 1.0), 1.0, np.zeros(M)]
    _, _, nxt = _rates(p, R, np.zeros(3), np.zeros(3), R, L - e, np.zeros(M), memory,
                       integral=100.0)
    assert nxt[3 + M + 3] == pytest.approx(pc.MAX_INTEGRAL_SPEED / 100.0)


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["reeled_out", "reeled_in"])
@pytest.mark.parametrize("tension", [False, True], ids=["offsets", "tension_control"])
def test_the_pose_loop_s_corrections_keep_the_bound_for_cables_reeled_in_and_out(sign,
                                                                                 tension):
    """Issue 27: the full-pose length loop scales its corrections as the translating one
    (kinematics.add_scaled_corrections): at rest, 15 mm of error on cable 2 and 0.5 mm the
    other way on cable 5 give K_l e = 0.3 and 0.01 m/s in size at K_l = 20 1/s; both are
    scaled by MAX_CORRECTION / 0.3 m/s, whichever way the largest reels its cable, so cable
    2 gets MAX_CORRECTION in size and cable 5 keeps its 1/30 of it, its own sign."""
    from cdpm_drake.kernels.kinematics import MAX_CORRECTION

    p, R = random_poses(11, 1)[0]
    Tn = np.full(M, 20.0) if tension else np.zeros(M)
    target = pose_lengths(ROBOT, p, R) * (EA / (EA + Tn) if tension else 1.0)
    e = np.zeros(M)
    e[1], e[4] = sign * 0.015, -sign * 0.0005
    memory = np.r_[p, np.zeros(2 * M), 1.0, Tn]  # started, no offsets, no integral
    cmd, l_d, _ = _rates(p, R, np.zeros(3), np.zeros(3), R, target - e, Tn, memory,
                         gain=20.0, tension=tension)
    np.testing.assert_allclose(l_d, target, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cmd, 20.0 * e * MAX_CORRECTION / 0.3, rtol=1e-9, atol=1e-12)
    assert cmd[1] == pytest.approx(sign * MAX_CORRECTION, rel=1e-9)
    # Below the bound (1 mm: 0.02 m/s) nothing is scaled, either way.
    e[1] = sign * 0.001
    cmd, _, _ = _rates(p, R, np.zeros(3), np.zeros(3), R, target - e, Tn, memory, gain=20.0,
                       tension=tension)
    np.testing.assert_allclose(cmd, 20.0 * e, rtol=1e-9, atol=1e-12)


def test_the_tension_command_slews_from_the_estimate():
    p, R = random_poses(14, 1)[0]
    L0 = pose_lengths(ROBOT, p, R)
    # An estimate of every cable above 40 N: the lengths' assumed tensions are the target of
    # a 60 N floor less 20 N of internal force.
    _, T60, _, _, _ = _tension(p, R, np.zeros(3), np.zeros(M), L0, np.full(M, 20.0),
                               ticks=1.0, slew=1e9, fall=1e9, T_before=np.zeros(M), floor=60.0)
    n = np.linalg.svd(wrench_matrix(ROBOT, p, R))[2][-1]
    assumed = T60 - 20.0 * n * np.sign(n.sum())
    # First tick: from the estimate; the target is far (floor 60 N) but the command moves at
    # most 50 N/s x 2 ms = 0.1 N.
    _, T_cmd, T_est, _, memory = _tension(p, R, np.zeros(3), np.zeros(M), L0, assumed,
                                          floor=60.0, slew=50.0)
    assert T_est.min() > 30.0
    assert np.abs(T_cmd - T_est).max() <= 0.1 + 1e-12
    assert np.abs(T_cmd - T_est).max() == pytest.approx(0.1)
    # Next tick: from the last command, its statics at once (the first tick's clamp left it
    # unbalanced) and its internal force at most 0.1 N a tick on the cable with the largest
    # share of the nullspace.
    _, T_next, _, _, _ = _tension(p, R, np.zeros(3), np.zeros(M), L0, memory[:M],
                                  ticks=1.0, floor=60.0, slew=50.0,
                                  T_before=memory[M + 4:2 * M + 4])
    assert np.abs(n * (n @ (T_next - T_cmd))).max() == pytest.approx(0.1)


def test_the_tension_command_moves_its_internal_force_within_each_cable_s_limits():
    """docs/dynamic_plant.md: the command keeps the target's statics and moves its internal
    force (along the nullspace n) towards the target's, each cable's share n_i dlam at most
    500 N/s up and 50 N/s down (1 N and 0.1 N a 2 ms tick), the whole change scaled
    together: the command stays balanced (W T + w = 0), unlike a clamp per cable."""
    p, R = random_poses(14, 1)[0]  # t* = inf: the floor of 60 N holds
    L0 = pose_lengths(ROBOT, p, R)
    args = (p, R, np.zeros(3), np.zeros(M), L0, np.full(M, 20.0))
    # Unlimited rates: the command is the target.
    # A floor of 60 N keeps every cable of these commands above the hard floor (3 N).
    _, target, _, _, _ = _tension(*args, ticks=1.0, slew=1e9, fall=1e9, T_before=np.zeros(M),
                                  floor=60.0)
    assert target.min() >= 59.9
    W = wrench_matrix(ROBOT, p, R)
    n = np.linalg.svd(W)[2][-1]
    for offset in (20.0, -20.0, 0.05, -0.5):
        before = target + offset * n
        _, T_cmd, _, _, _ = _tension(*args, ticks=1.0, slew=500.0, fall=50.0, T_before=before,
                                     floor=60.0)
        change = -offset * n  # each cable's share of the internal force's change
        limit = np.where(change > 0, 1.0, 0.1)
        scale = min(1.0, float(np.min(limit / np.abs(change))))
        np.testing.assert_allclose(T_cmd, before + scale * change, rtol=0, atol=1e-9)
        np.testing.assert_allclose(W @ T_cmd, W @ target, rtol=0, atol=1e-9)


def test_the_target_leads_the_hand_along_its_rate():
    """The target is the distribution of the hand led by its low-passed rate: with lead
    0.014 s and a rate (memory) of [300, -100, 400] N/s, a hand F whose last sample was F -
    0.002 rate (so the low-pass keeps the rate) has the target of F + 0.014 rate without a
    lead (the same kernel, lead 0), to round-off; the estimate takes F as measured."""
    p, R = random_poses(14, 1)[0]
    L0 = pose_lengths(ROBOT, p, R)
    F, rate = np.array([3.0, -2.0, 5.0]), np.array([300.0, -100.0, 400.0])
    args = (p, R)
    rest = (np.zeros(M), L0, np.full(M, 20.0))
    kw = dict(ticks=1.0, slew=1e9, fall=1e9, T_before=np.zeros(M))
    led = _tension(*args, F, *rest, lead=0.014, rate_time=0.01, F_before=F - 0.002 * rate,
                   F_rate=rate, **kw)
    ref = _tension(*args, F + 0.014 * rate, *rest, **kw)
    plain = _tension(*args, F, *rest, **kw)
    np.testing.assert_allclose(led[1], ref[1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(led[2], plain[2], rtol=0, atol=1e-12)  # the estimate
    np.testing.assert_allclose(led[4][2 * M + 7:2 * M + 10], rate, rtol=0,
                               atol=1e-9)  # the rate kept


def test_the_target_takes_in_a_ramp_s_acceleration_through_the_low_pass():
    """The command ramps at a0 for 600 ticks (1.2 s), the low-passed command carried from
    tick to tick: v_slow follows v_k = a0 T k with v - v_slow -> a0 tau (the discrete
    first-order filter's steady lag, e = (1 - T / tau) e + a0 T), so the acceleration the
    target takes in, (v - v_slow) / tau, is a0 within (1 - T / tau)^600 = 6e-6 of it: the
    target balances the weight minus mass a0 (the wrench built independently, as above)."""
    p = np.array([1.6, 2.2, 1.1])
    R = rotation_from_rpy([0.02, -0.01, 0.03])
    L0 = pose_lengths(ROBOT, p, R)
    a0, T = np.array([0.5, -0.3, 0.2]), 0.002
    memory = np.zeros(S["tension_out"] - 3 * M - 3)
    for k in range(600):
        v = a0 * T * k
        _, T_cmd, _, _, memory = _tension(p, R, np.zeros(3), np.zeros(M), L0, np.full(M, 20.0),
                                          v=v, v_prev=memory[M:M + 3], ticks=float(min(k, 1)))
    w = gravity_wrench(2.5, np.zeros(3), R @ np.array([0.0, 0.0, -0.15]))
    w[:3] -= 2.5 * a0
    np.testing.assert_allclose(wrench_matrix(ROBOT, p, R) @ T_cmd + w, 0.0, atol=1e-4)

def test_the_first_tick_fits_pose_and_pretension_together():
    """A platform at rest, level at p, pretensioned by an internal force of unknown size
    (T = T_p + 40 n, weight only): from a guess 200 N off, the first tick's iterated fit finds
    the pose within 1e-9 m and the tensions within 1e-6 N; a later tick (started) does one
    fit with the guess and is off by ~0.1 mm and tenths of a degree or more, which is what
    the first tick avoids."""
    p, R = np.array([1.8, 2.3, 1.2]), np.eye(3)
    W = wrench_matrix(ROBOT, p, R)
    w = gravity_wrench(2.5)
    n = np.linalg.svd(W)[2][-1]
    n = n * np.sign(n.sum())
    T_true = -np.linalg.pinv(W) @ w + 40.0 * n
    L0 = pose_lengths(ROBOT, p, R) * EA / (EA + T_true)
    guess = T_true + 200.0 * n
    params = np.array([EA, 0.02, 2.5, 0.0, 0.0, -0.15, 40.0])
    out = np.empty(S["fk_out"])
    x = np.concatenate([L0, guess, p + 0.005, np.eye(3).ravel(), [0.0]])
    assert pc.pose_fk_tick(REELS, ATTACH, params, x, out) == pc.FK_OK
    np.testing.assert_allclose(out[:3], p, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out[3:12].reshape(3, 3), R, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out[16 + M:], T_true, rtol=0, atol=1e-6)
    assert out[12] == 1.0  # started
    x[-1] = 1.0
    pc.pose_fk_tick(REELS, ATTACH, params, x, out)
    # One fit with the guess is off by the 200 N error's stretch (200 N x 3 m / 70 kN ~ 8 mm
    # of length along n): a tenth of a millimetre and a tenth of a degree or more.
    assert np.linalg.norm(out[:3] - p) > 1e-4
    assert np.degrees(np.arccos(min(1.0, (np.trace(out[3:12].reshape(3, 3)) - 1) / 2))) > 0.1


def _bounded_reference(W, w, floor, ceiling):
    """max t s.t. W T = -w, t <= T_i <= ceiling (HiGHS), and the tensions."""
    from scipy.optimize import linprog

    m = W.shape[1]
    res = linprog(np.r_[np.zeros(m), -1.0], A_ub=np.c_[-np.eye(m), np.ones(m)],
                  b_ub=np.zeros(m), A_eq=np.c_[W, np.zeros(6)], b_eq=-w,
                  bounds=[(None, ceiling)] * m + [(None, None)], method="highs")
    return -res.fun


def test_the_bounded_distribution_keeps_the_ceiling_and_the_largest_floor_under_it():
    """For random poses and hand forces: every target tension within [floor used, ceiling];
    the floor used is min(floor, the largest minimum tension under the ceiling - FLOOR_MARGIN)
    (HiGHS reference); without a binding ceiling, where the floor holds with the margin to
    spare, the target is tension.py's least-norm one."""
    from cdpm_drake.kernels.tension import FEASIBLE, distribution_1d

    rng = np.random.default_rng(11)
    checked_binding = checked_free = 0
    for p, R in random_poses(12, 60, tilt=0.1):
        F = rng.normal(scale=5.0, size=3)
        W = wrench_matrix(ROBOT, p, R)
        w = gravity_wrench(2.5, F, R @ np.array([0.0, 0.0, -0.15]))
        U, s_, Vt = np.linalg.svd(W)
        n = Vt[-1]
        T_p = -np.linalg.pinv(W) @ w
        for floor, ceiling in ((10.0, 60.0), (5.0, 1e6)):
            T = np.empty(M)
            status, t_star, used, _ = pc.distribution_1d_bounded(T_p, n, floor, -math.inf,
                                                                 ceiling, T)
            np.testing.assert_allclose(W @ T + w, 0.0, atol=1e-9)
            best = _bounded_reference(W, w, floor, ceiling)
            if not np.isfinite(best) or best < floor - 1e-6 and T.max() > ceiling + 1e-9:
                continue  # no distribution under this ceiling at all: dropped, see docstring
            assert used == pytest.approx(min(floor, best - pc.FLOOR_MARGIN), abs=1e-6)
            assert T.min() >= used - 1e-9 and T.max() <= ceiling + 1e-9
            if ceiling == 1e6 and best >= floor + pc.FLOOR_MARGIN:
                ref = np.empty(M)
                ref_status, _ = distribution_1d(T_p, n, floor, ref)
                np.testing.assert_allclose(T, ref, atol=1e-9)
                checked_free += 1
            elif ceiling == 1e6:
                # The least-norm lam with every T_i >= used, in closed form: |T|^2 =
                # |T_p|^2 + lam^2 (n is a unit vector orthogonal to T_p, the pseudo-inverse's).
                with np.errstate(divide="ignore"):
                    bound = (used - T_p) / n
                lo, hi = bound[n > 0].max(initial=-np.inf), bound[n < 0].min(initial=np.inf)
                np.testing.assert_allclose(T, T_p + n * min(max(0.0, lo), hi), atol=1e-9)
                checked_free += 1
            if best < floor and ceiling != 1e6:
                checked_binding += 1
    assert checked_binding >= 5 and checked_free >= 50  # both cases were exercised


def test_the_target_does_not_jump_where_the_weakest_cable_cannot_be_changed():
    """Cable 7's nullspace component is +-1e-6: its tension (3 N, the pose's t*) is the same
    for every internal force, so the largest minimum is reached on a whole interval of lam
    ([-2, 2] here: cables 1 and 2 reach 3 N at its ends). The exact max-min distribution
    would be one end or the other as the component's sign flips (4 N apart on cables 1 and
    2); the target keeps every cable within FLOOR_MARGIN of t* and takes the least-norm
    distribution among those: lam = 0 for either sign."""
    T_p = np.array([5.0, 5.0, 6.0, 6.0, 7.0, 7.0, 3.0])
    targets = []
    for eps in (1e-6, -1e-6):
        n = np.array([1.0, -1.0, 0.5, -0.5, 0.8, -0.3, eps])
        n /= np.linalg.norm(n)
        T = np.empty(7)
        status, t_star, used, _ = pc.distribution_1d_bounded(T_p, n, 10.0, -math.inf, 1e6, T)
        assert t_star == pytest.approx(3.0, abs=1e-4)
        assert used == pytest.approx(t_star - pc.FLOOR_MARGIN)
        assert T.min() >= t_star - pc.FLOOR_MARGIN - 1e-9
        targets.append(T.copy())
    np.testing.assert_allclose(targets[0], T_p, atol=1e-4)  # lam = 0: least norm
    np.testing.assert_allclose(targets[0], targets[1], atol=1e-4)

