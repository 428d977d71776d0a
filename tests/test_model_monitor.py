"""The model monitor (cdpm_drake.model_monitor): each condition named after exactly its number
of ticks, on lengths made from the geometry (pose.pose_lengths) with a known change."""

import numpy as np
import pytest

from cdpm_drake.model_monitor import (MISFIT, OK, SLACK, UNHOLDABLE, fault_message,
                                      monitor_params, monitor_sizes, monitor_tick)
from cdpm_drake.pose import pose_lengths

TICKS = 5


def _robot():
    from cdpm_drake.robot import load_robot, resolve_robot_path

    return load_robot(resolve_robot_path("paper_7cable"))


def _run(robot, frames, *, estimate=False, full=False, EA=70000.0):
    """Feed frames [(lengths, p, t*, T_est)] through the monitor tick by tick (its memory
    carried as the block's delay does); returns the (status, cable, value) of each tick."""
    m = robot.num_cables
    s = monitor_sizes(m, full, estimate)
    params = monitor_params(EA=EA, slack_tension=2.0, slack_length=0.003, fit_tolerance=0.01,
                            unholdable=1.0, ticks=TICKS, estimate=estimate, full_pose=full)
    memory = np.zeros(3)
    out = np.empty(s["out"])
    seen = []
    for lengths, p, t_star, T_est in frames:
        x = np.concatenate([lengths, p, [t_star], np.zeros(3)]
                           + ([np.eye(3).ravel()] if full else [])
                           + ([T_est] if estimate else []) + [memory])
        status = monitor_tick(robot.reels, robot.attachments, params, x, out)
        memory = out[s["memory_at"]:s["memory_at"] + 3].copy()
        seen.append((int(status), int(out[1]), float(out[2])))
        np.testing.assert_allclose(out[3:3 + m], pose_lengths(robot, p, np.eye(3)) - (
            lengths * (1 + T_est / EA) if estimate else lengths), atol=1e-12)
    return seen


def test_a_cable_longer_than_the_pose_explains_is_slack_after_exactly_its_ticks():
    robot = _robot()
    p = robot.workspace.center
    L = pose_lengths(robot, p, np.eye(3))
    slack = L.copy()
    slack[3] += 0.004  # cable 4 paid out 4 mm more than the pose needs: it sags
    frames = [(L, p, 10.0, None)] * 3 + [(slack, p, 10.0, None)] * TICKS
    seen = _run(robot, frames)
    assert [s for s, _, _ in seen[:3 + TICKS - 1]] == [OK] * (3 + TICKS - 1)
    assert seen[-1] == (SLACK, 4, pytest.approx(-0.004, abs=1e-12))
    # A stretched cable (shorter on the reel than the geometry) is no slack, and 2 mm is
    # within slack_length.
    taut = L.copy()
    taut[3] -= 0.004
    half = L.copy()
    half[3] += 0.002
    assert all(s == OK for s, _, _ in _run(robot, [(taut, p, 10.0, None)] * 8
                                           + [(half, p, 10.0, None)] * 8))


def test_an_interruption_restarts_the_count():
    robot = _robot()
    p = robot.workspace.center
    L = pose_lengths(robot, p, np.eye(3))
    slack = L.copy()
    slack[0] += 0.005
    frames = [(slack, p, 10.0, None)] * (TICKS - 1) + [(L, p, 10.0, None)] + [
        (slack, p, 10.0, None)] * (TICKS - 1)
    assert all(s == OK for s, _, _ in _run(robot, frames))


def test_the_tension_estimate_names_the_slack_cable():
    robot = _robot()
    p = robot.workspace.center
    EA = 70000.0
    T = np.full(7, 20.0)
    L0 = pose_lengths(robot, p, np.eye(3)) / (1 + T / EA)  # unstretched: residual 0
    T_bad = T.copy()
    T_bad[6] = -2.5  # below -slack_tension
    seen = _run(robot, [(L0, p, 10.0, T)] * 2 + [(L0 * (1 + T / EA) / (1 + T_bad / EA), p,
                                                 10.0, T_bad)] * TICKS, estimate=True)
    assert seen[-1][:2] == (SLACK, 7) and seen[-1][2] == pytest.approx(-2.5)
    assert all(s == OK for s, _, _ in seen[:-1])


def test_lengths_far_from_the_pose_are_a_misfit_and_an_unholdable_hand_is_named():
    robot = _robot()
    p = robot.workspace.center
    L = pose_lengths(robot, p, np.eye(3))
    off = L.copy()
    off[2] -= 0.012  # 12 mm shorter: beyond fit_tolerance, and not slack
    seen = _run(robot, [(off, p, 10.0, None)] * TICKS)
    assert seen[-1] == (MISFIT, 3, pytest.approx(0.012, abs=1e-12))
    seen = _run(robot, [(L, p, -1.5, None)] * TICKS)
    assert seen[-1][0] == UNHOLDABLE and seen[-1][2] == -1.5
    assert _run(robot, [(L, p, -0.5, None)] * (2 * TICKS))[-1][0] == OK  # within 1 N


def test_fault_messages_name_the_cable_the_reason_and_the_duration():
    text = fault_message(SLACK, 4, -0.004, ticks=5, time_step=0.002, estimate=False,
                         p=[1.0, 2.0, 3.0])
    assert text.startswith("cable 4 is slack") and "4.00 mm longer" in text and "10 ms" in text
    text = fault_message(UNHOLDABLE, 0, -3.2, ticks=5, time_step=0.002, estimate=True,
                         p=[1.0, 2.0, 3.0], F_H=[0.0, 0.0, 40.0])
    assert "cannot be held" in text and "[0.0, 0.0, 40.0] N" in text and "-3.20 N" in text
