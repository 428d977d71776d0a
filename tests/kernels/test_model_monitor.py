"""The model monitor (cdpm_drake.kernels.model_monitor): each condition named after exactly its number
of ticks, on lengths made from the geometry (pose.pose_lengths) with a known change, and
hand forces whose t* comes from scipy's HiGHS (conftest.highs_t_star)."""

import numpy as np
import pytest

from cdpm_drake.kernels.kinetostatics import margin_scratch
from cdpm_drake.kernels.model_monitor import (MISFIT, OK, OVERLOAD, SLACK, UNHOLDABLE,
                                              fault_message, monitor_params, monitor_sizes,
                                              monitor_tick)
from cdpm_drake.kernels.pose import pose_lengths
from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix
from conftest import highs_t_star

TICKS, SLACK_TICKS, HOLDABLE = 5, 25, 2.0


def _robot():
    from cdpm_drake.robot import load_robot, resolve_robot_path

    return load_robot(resolve_robot_path("paper_7cable"))


def _run(robot, frames, *, estimate=False, EA=70000.0, F=(0.0, 0.0, 0.0), measured=None,
         overload=0.0, measured_slack=None, reconciled=None):
    """Feed frames [(lengths, p, T_est)] through the monitor tick by tick (its memory carried
    as the block's delay does), the hand force F (N) at every tick; measured: the measured
    tensions (N, NaN: no reading) of every tick, read below 1 N as slack; reconciled: the
    encoder zero's flag at each tick (None: the monitor reads none); returns (status,
    cable, value, t*) of each tick."""
    m = robot.num_cables
    s = monitor_sizes(m, False, estimate, measured is not None, reconciled is not None)
    params = monitor_params(robot, EA=EA, slack_tension=2.0, slack_length=0.003,
                            fit_tolerance=0.01, unholdable=1.0, ticks=TICKS,
                            estimate=estimate, full_pose=False, rows=6, holdable=HOLDABLE,
                            slack_ticks=SLACK_TICKS,
                            measured_slack=(0.0 if measured is None else 1.0)
                            if measured_slack is None else measured_slack,
                            overload=overload, reconciling=reconciled is not None)
    scratch = margin_scratch(m)
    memory = np.zeros(s["memory"])
    out = np.empty(s["out"])
    seen = []
    for k, (lengths, p, T_est) in enumerate(frames):
        x = np.concatenate([lengths, p, F] + ([T_est] if estimate else [])
                           + ([measured] if measured is not None else [])
                           + ([[reconciled[k]]] if reconciled is not None else []) + [memory])
        status = monitor_tick(robot.reels, robot.attachments, params, scratch, x, out)
        memory = out[s["memory_at"]:s["memory_at"] + s["memory"]].copy()
        seen.append((int(status), int(out[1]), float(out[2]), float(out[3])))
        expected = pose_lengths(robot, p, np.eye(3)) - (
            lengths * (1 + T_est / EA) if estimate else lengths)
        np.testing.assert_allclose(out[4:4 + m], expected, atol=1e-12)
    return seen


def _t_star(robot, p, F):
    """t* of the level platform at p with its weight and the hand force F at the handle,
    by HiGHS."""
    w = gravity_wrench(robot.dynamics.mass, F, robot.dynamics.handle)
    return highs_t_star(wrench_matrix(robot, p), w)


def _force_with_t_star(robot, p, low, high):
    """A lift (+z) whose t* (HiGHS) lies in (low, high), found by bisection on its size (at
    P the weight alone leaves t* = 16.5 N and 30 N of lift -5.1 N)."""
    a, b = 0.0, 200.0
    for _ in range(60):
        mid = 0.5 * (a + b)
        t = _t_star(robot, p, [0.0, 0.0, mid])
        if low < t < high:
            return np.array([0.0, 0.0, mid]), t
        a, b = (mid, b) if t > high else (a, mid)
    raise AssertionError("no such force")


P = np.array([1.77, 2.4, 1.3])  # inside paper_7cable's box, where the weight is held


def test_a_slack_cable_where_the_statics_hold_is_a_fault_after_slack_ticks():
    robot = _robot()
    assert _t_star(robot, P, [0, 0, 0]) > HOLDABLE  # the weight alone: held with margin
    L = pose_lengths(robot, P, np.eye(3))
    slack = L.copy()
    slack[3] += 0.004  # cable 4 paid out 4 mm more than the pose needs: it sags
    seen = _run(robot, [(L, P, None)] * 3 + [(slack, P, None)] * SLACK_TICKS)
    assert [s for s, *_ in seen[:-1]] == [OK] * (3 + SLACK_TICKS - 1)
    assert seen[-1][:3] == (SLACK, 4, pytest.approx(-0.004, abs=1e-12))
    # A stretched cable (shorter on the reel than the geometry) is no slack, and 2 mm is
    # within slack_length.
    taut, half = L.copy(), L.copy()
    taut[3] -= 0.004
    half[3] += 0.002
    assert all(s == OK for s, *_ in _run(robot, [(taut, P, None)] * 30 + [(half, P, None)] * 30))


def test_a_slack_cable_the_hand_keeps_slack_is_a_fault_after_ticks():
    # A hand force that leaves t* between 0 and `holdable`: the slack is the hand's doing.
    robot = _robot()
    F, t = _force_with_t_star(robot, P, 0.3, HOLDABLE - 0.3)
    L = pose_lengths(robot, P, np.eye(3))
    slack = L.copy()
    slack[0] += 0.005
    seen = _run(robot, [(slack, P, None)] * TICKS, F=F)
    assert seen[-1][:2] == (SLACK, 1) and all(s == OK for s, *_ in seen[:-1])
    assert seen[-1][3] == pytest.approx(t, abs=1e-6)  # the t* it judged by, HiGHS's


def test_an_interruption_restarts_the_count():
    robot = _robot()
    L = pose_lengths(robot, P, np.eye(3))
    slack = L.copy()
    slack[0] += 0.005
    frames = [(slack, P, None)] * (SLACK_TICKS - 1) + [(L, P, None)] + [
        (slack, P, None)] * (SLACK_TICKS - 1)
    assert all(s == OK for s, *_ in _run(robot, frames))


def test_the_tension_estimate_names_the_slack_cable():
    robot = _robot()
    EA = 70000.0
    T = np.full(7, 20.0)
    L0 = pose_lengths(robot, P, np.eye(3)) / (1 + T / EA)  # unstretched: residual 0
    T_bad = T.copy()
    T_bad[6] = -2.5  # below -slack_tension
    bad = (L0 * (1 + T / EA) / (1 + T_bad / EA), P, T_bad)
    seen = _run(robot, [(L0, P, T)] * 2 + [bad] * SLACK_TICKS, estimate=True)
    assert seen[-1][:2] == (SLACK, 7) and seen[-1][2] == pytest.approx(-2.5)
    assert all(s == OK for s, *_ in seen[:-1])


def test_lengths_far_from_the_pose_are_a_misfit_and_an_unholdable_hand_is_named():
    robot = _robot()
    L = pose_lengths(robot, P, np.eye(3))
    off = L.copy()
    off[2] -= 0.012  # 12 mm shorter: beyond fit_tolerance, and not slack
    seen = _run(robot, [(off, P, None)] * TICKS)
    assert seen[-1][:3] == (MISFIT, 3, pytest.approx(0.012, abs=1e-12))
    F, t = _force_with_t_star(robot, P, -3.0, -1.5)  # beyond unholdable = 1 N
    seen = _run(robot, [(L, P, None)] * TICKS, F=F)
    assert seen[-1][0] == UNHOLDABLE and seen[-1][2] == pytest.approx(t, abs=1e-6)
    assert all(s == OK for s, *_ in seen[:-1])
    F, t = _force_with_t_star(robot, P, -0.9, -0.1)  # within 1 N of holding it
    assert all(s == OK for s, *_ in _run(robot, [(L, P, None)] * (2 * TICKS), F=F))


def test_no_slack_is_judged_before_the_encoder_zero_is_reconciled():
    """Homed encoders read each cable's stretch at the homing more than the unstretched
    lengths the estimate takes until the encoder zero has reconciled them: an estimate of
    -5 N on cable 7 (below -slack_tension) counts from the first reconciled tick only. At P
    the weight alone leaves t* = 16.5 N: the slack must last SLACK_TICKS ticks; without the
    flag it faults SLACK_TICKS ticks from the start, with it 10 ticks later; the lengths'
    slack (no estimate: a cable 5 mm longer than the pose explains) waits alike."""
    robot = _robot()
    EA = 70000.0
    T_bad = np.full(7, 20.0)
    T_bad[6] = -5.0
    bad = (pose_lengths(robot, P, np.eye(3)) / (1 + T_bad / EA), P, T_bad)
    n = SLACK_TICKS + 12
    flags = [0.0] * 10 + [1.0] * (n - 10)
    for estimate, frame, cable in ((True, bad, 7), (False, None, 1)):
        if frame is None:
            L = pose_lengths(robot, P, np.eye(3))
            L[0] += 0.005
            frame = (L, P, None)
        plain = [s for s, *_ in _run(robot, [frame] * n, estimate=estimate)]
        waited = _run(robot, [frame] * n, estimate=estimate, reconciled=flags)
        assert plain.index(SLACK) == SLACK_TICKS - 1
        assert [s for s, *_ in waited].index(SLACK) == 10 + SLACK_TICKS - 1
        assert waited[-1][1] == cable


def test_fault_messages_name_the_cable_the_reason_and_the_duration():
    text = fault_message(SLACK, 4, -0.004, ticks=5, time_step=0.002, estimate=False,
                         p=[1.0, 2.0, 3.0])
    assert text.startswith("cable 4 is slack") and "4.00 mm longer" in text and "10 ms" in text
    text = fault_message(UNHOLDABLE, 0, -3.2, ticks=5, time_step=0.002, estimate=True,
                         p=[1.0, 2.0, 3.0], F_H=[0.0, 0.0, 40.0])
    assert "cannot be held" in text and "[0.0, 0.0, 40.0] N" in text and "-3.20 N" in text


def test_a_measured_tension_decides_where_the_estimate_cannot_see():
    """With measured tensions, a cable measured below 1 N is slack after its ticks (the
    estimate says 15 N: it cannot see the cable ring slack), and a cable measured taut is
    not, though its estimate says -5 N (below -slack_tension); a cable without a reading
    (NaN) is judged by its estimate. At P the weight alone leaves t* = 16.5 N: a slack cable
    must last SLACK_TICKS."""
    robot = _robot()
    m = robot.num_cables
    p = P
    L = pose_lengths(robot, p, np.eye(3)) / (1 + 15.0 / 70000.0)
    T_est = np.full(m, 15.0)
    T_meas = np.full(m, 15.0)
    T_meas[3] = 0.4
    seen = _run(robot, [(L, p, T_est)] * SLACK_TICKS, estimate=True, measured=T_meas)
    assert [s[0] for s in seen] == [OK] * (SLACK_TICKS - 1) + [SLACK]
    assert seen[-1][1] == 4 and seen[-1][2] == pytest.approx(0.4)
    # The same without measured tensions: the estimate (15 N) sees nothing.
    assert {s[0] for s in _run(robot, [(L, p, T_est)] * SLACK_TICKS, estimate=True)} == {OK}
    # A taut measured cable overrides a negative estimate; without its reading the
    # estimate decides.
    T_est[5] = -5.0
    T_meas = np.full(m, 15.0)
    assert {s[0] for s in _run(robot, [(L, p, T_est)] * SLACK_TICKS, estimate=True,
                               measured=T_meas)} == {OK}
    T_meas[5] = np.nan
    seen = _run(robot, [(L, p, T_est)] * SLACK_TICKS, estimate=True, measured=T_meas)
    assert seen[-1][0] == SLACK and seen[-1][1] == 6 and seen[-1][2] == pytest.approx(-5.0)
    message = fault_message(SLACK, 4, 0.4, ticks=25, time_step=0.002, estimate=True, p=p,
                            measured=True)
    assert "its measured tension is 0.40 N" in message


def test_a_cable_measured_above_the_overload_is_a_fault_after_ticks():
    """A cable measured above the overload tension (model_monitor.overload x
    controller.max_tension: 150 N here) for TICKS ticks is OVERLOAD, naming the cable and the
    largest reading; at the overload itself, or with no reading (NaN), nothing. It comes
    before a slack cable (an overloaded cable may snap): cable 2 slack and cable 5 overloaded
    on the same ticks is cable 5's overload. Without a tension estimate (the translating
    controller) too: the readings alone decide."""
    robot = _robot()
    m = robot.num_cables
    L = pose_lengths(robot, P, np.eye(3))
    T_meas = np.full(m, 20.0)
    T_meas[4], T_meas[6] = 203.0, 160.0
    seen = _run(robot, [(L, P, None)] * TICKS, measured=T_meas, overload=150.0,
                measured_slack=0.0)
    assert [s[0] for s in seen] == [OK] * (TICKS - 1) + [OVERLOAD]
    assert seen[-1][1] == 5 and seen[-1][2] == pytest.approx(203.0)
    at = np.full(m, 150.0)  # at the overload, not above it
    assert {s[0] for s in _run(robot, [(L, P, None)] * TICKS, measured=at, overload=150.0,
                               measured_slack=0.0)} == {OK}
    unread = np.full(m, np.nan)
    assert {s[0] for s in _run(robot, [(L, P, None)] * TICKS, measured=unread,
                               overload=150.0, measured_slack=0.0)} == {OK}
    # Off (0): a reading of 1000 N is nobody's business but the summary's.
    huge = np.full(m, 1000.0)
    assert {s[0] for s in _run(robot, [(L, P, None)] * TICKS, measured=huge,
                               measured_slack=0.0)} == {OK}
    # With a slack cable on the same ticks (its estimate 15 N; at P the weight alone leaves
    # t* = 16.5 N, so the slack alone would need SLACK_TICKS anyway).
    Lt = L / (1 + 15.0 / 70000.0)
    both = np.full(m, 15.0)
    both[1], both[4] = 0.2, 203.0
    seen = _run(robot, [(Lt, P, np.full(m, 15.0))] * TICKS, estimate=True, measured=both,
                overload=150.0)
    assert seen[-1][0] == OVERLOAD and seen[-1][1] == 5
    message = fault_message(OVERLOAD, 5, 203.0, ticks=TICKS, time_step=0.002,
                            estimate=False, p=P, overload=150.0)
    assert message.startswith("cable 5 is overloaded: its measured tension is 203.0 N, "
                              "above 150 N (model_monitor.overload x controller.max_tension) "
                              "for 5 ticks (10 ms)"), message


def _tetrahedral_robot():
    """A point platform (attachments at its centre) on four cables from the corners of a
    tetrahedron around a 1 m box: it can only translate (wrench rows 3) and has one internal
    force (m = rows + 1), like paper_7cable in six rows."""
    from cdpm_drake.robot import Robot, Workspace

    reels = np.array([[-2.0, -2.0, 3.0], [2.0, -2.0, 3.0], [0.0, 2.5, 3.0], [0.0, 0.0, -2.0]])
    return Robot(name="tetrahedron", reels=reels, attachments=np.zeros((4, 3)),
                 workspace=Workspace(np.array([-0.5, -0.5, 0.0]), np.array([0.5, 0.5, 1.0])))


def _pre_18_robot():
    """paper_7cable with its attachment points before they were calibrated for holding (a
    geometry of its own: the level platform held on 28 % of the box)."""
    import dataclasses

    from helpers_robots import PRE_18

    return dataclasses.replace(_robot(), attachments=np.array(PRE_18))


@pytest.mark.parametrize("name", ["paper_7cable", "cube_8cable", "tetrahedron", "pre_18"])
def test_the_monitor_s_t_star_is_the_pivoted_qr_s(name):
    # The monitor takes t* of a robot with one internal force (paper_7cable and the
    # pre-calibration one in six rows, the tetrahedron in three) by Gaussian elimination
    # (model_monitor.hand_t_star); the reference is kinetostatics.margin's pivoted QR on the
    # same pose and wrench (held_wrench, as the monitor forms it): the same max-min over the
    # same line of tensions, so equal to round-off, +inf (an internal force raises every
    # tension) and -inf (no tension holds) at the same poses. cube_8cable (two internal
    # forces) keeps the QR. Poses across and beyond the workspace box, tilted where the
    # statics have six rows, hands up to ~60 N.
    from cdpm_drake.kernels.full_pose import held_wrench
    from cdpm_drake.kernels.kinetostatics import (MARGIN_T_STAR, margin_in, scratch_views,
                                                  wrench_rows)
    from cdpm_drake.kernels.rotation import rotation_from_rpy
    from cdpm_drake.robot import load_robot, resolve_robot_path

    robot = {"tetrahedron": _tetrahedral_robot, "pre_18": _pre_18_robot}.get(
        name, lambda: load_robot(resolve_robot_path(name)))()
    m, rows = robot.num_cables, wrench_rows(robot)
    assert rows == (3 if name == "tetrahedron" else 6)
    s = monitor_sizes(m, True, False)
    params = monitor_params(robot, EA=0.0, slack_tension=2.0, slack_length=0.003,
                            fit_tolerance=0.01, unholdable=1.0, ticks=TICKS, estimate=False,
                            full_pose=True, rows=rows, holdable=HOLDABLE,
                            slack_ticks=SLACK_TICKS)
    scratch = margin_scratch(m)
    views = scratch_views(margin_scratch(m))
    rng = np.random.default_rng(61)
    lo, hi = robot.workspace.lower, robot.workspace.upper
    out = np.empty(s["out"])
    finite = infinite = lost = 0
    for trial in range(600):
        p = rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo))
        R = rotation_from_rpy(rng.normal(size=3) * (0.0 if trial % 3 == 0 or rows == 3
                                                    else 0.15))
        F = rng.normal(size=3) * 20.0
        x = np.zeros(s["x"])
        x[:m] = pose_lengths(robot, p, R)
        x[m:m + 3], x[m + 3:m + 6], x[m + 6:m + 15] = p, F, R.ravel()
        monitor_tick(robot.reels, robot.attachments, params, scratch, x, out)
        w = np.empty(6)
        held_wrench(R, params[8:12], F, np.zeros(3), w)
        qr = margin_in(robot.reels, robot.attachments, rows, p, R, w, 0.0, np.inf, views,
                       0.0, MARGIN_T_STAR)[1]
        if np.isfinite(qr):
            finite += 1
            lost += qr < 0.0
            assert out[3] == pytest.approx(qr, rel=1e-9, abs=1e-9), (p, qr, out[3])
        else:
            infinite += 1
            assert out[3] == qr, (p, qr, out[3])
        # The residual reads the lengths the statics posed: zero for the pose's own lengths.
        np.testing.assert_allclose(out[4:4 + m], 0.0, atol=1e-12)
    # Both kinds of pose, and hands held and not held among the finite ones (measured:
    # finite, infinite, lost of 600: paper_7cable 512, 88, 433; cube_8cable 152, 448, 120;
    # tetrahedron 111, 489, 51; pre_18 553, 47, 518).
    assert finite > 60 and infinite > 20 and 10 < lost < finite - 10, (finite, infinite, lost)
