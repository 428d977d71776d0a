"""A hand faster than the platform settles: the tension path names it from the first tick the
force sensor shows it. The kernel's swing against numpy's pseudo-inverse, the settle time
against the platform's modes, and a 40 N step at t = 0 on the dynamic plant (full pose,
tension control, the drives' torque as tension sensor) asserted on the plant's ground truth:
"hand faster than the tension path can follow" (tension_status 5) before the first tick a
cable is truly slack. Deterministic simulations (the sensor's noise is seeded)."""

import numpy as np
import pytest

from cdpm_drake.config import load_resolved_scenario
from cdpm_drake.kernels.full_pose import HAND_TOO_FAST
from cdpm_drake.kernels.tension import wrench_matrix
from cdpm_drake.kernels.tension_damping import platform_modes
from cdpm_drake.kernels.tension_path import hand_lag, ringing_cable, settle_time
from cdpm_drake.runs.simulate import simulate

from helpers_robots import across_pair

FULL = ("controller: {pose: full, tension_control: true}, "
        "plant: !DynamicReels {tension_sensor: drive_torque}, ")


def test_the_swing_is_the_statics_of_the_unsettled_hand_and_names_the_cable_it_rings_slack():
    resolved = load_resolved_scenario("exp3_two_pairs")
    robot = resolved.robot
    W = wrench_matrix(robot, np.asarray(resolved.scenario.initial_position, dtype=float))
    w_slow = np.array([0.0, 0.0, -20.0, 0.0, 0.0, 0.0])
    w = w_slow + np.array([23.0, -31.0, -11.0, 1.2, -0.4, 0.3])
    # The minimum-norm change of the tensions that balance w instead of w_slow (W T + w = 0).
    expected = np.abs(np.linalg.pinv(W) @ (w - w_slow))
    command = expected + 1.0
    k = int(np.argmax(expected))
    command[k] = expected[k] - 2.0  # the one cable the swing takes below zero
    swing = np.empty(W.shape[1])
    assert ringing_cable(W, w, w_slow, command, swing) == k + 1
    np.testing.assert_allclose(swing, expected, rtol=1e-9, atol=1e-9)
    # Every command above its swing: nothing named.
    assert ringing_cable(W, w, w_slow, expected + 0.5, swing) == 0


def test_the_settle_time_is_the_slowest_mode_and_the_lag_the_sliding_average():
    resolved = load_resolved_scenario("exp2_interaction")
    robot, p0 = resolved.robot, np.asarray(resolved.scenario.initial_position, dtype=float)
    d = robot.dynamics
    modes = platform_modes(robot.reels, robot.attachments, p0, d.EA, d.mass, d.inertia)
    assert settle_time(robot, p0) == 1.0 / modes[0]
    assert 0.03 < settle_time(robot, p0) < 0.045  # paper_7cable's lowest mode: 4.2 Hz
    assert hand_lag(10, 0.002) == pytest.approx(0.009)  # a ramp through a 10-sample average: 4.5 ticks late
    assert hand_lag(1, 0.002) == 0.0


def test_a_40_n_step_across_exp3s_pair_5_7_is_named_before_the_first_slack_tick():
    # Measured before the status took in the hand's unsettled part: status 5 first at 0.010 s,
    # the tick cable 6 went slack (the warm-up's last tick, where it was not checked); now
    # at 0.002 s, the first tick the force sensor shows the hand.
    scenario = "exp3_two_pairs"
    f = [round(float(x), 6) for x in 40.0 * across_pair(scenario, (5, 7))]
    text = ("{duration: 0.05, %soperator: !ScriptedOperator {times: [0, 0.05], forces: "
            "[%s, %s]}}" % (FULL, f, f))
    log = simulate(scenario=load_resolved_scenario(scenario, text)).log
    fast = np.flatnonzero(np.asarray(log["tension_status"]).reshape(-1) == HAND_TOO_FAST)
    slack = np.flatnonzero(log["slack"].any(axis=1))  # the plant's truth
    assert fast.size, "the controller never said the hand was too fast"
    assert slack.size, "the step no longer slackens a cable: the test needs a faster hand"
    assert fast[0] < slack[0]
    # The cable named is one the step takes slack.
    named = int(np.asarray(log["tension_cable"]).reshape(-1)[fast[0]])
    assert log["slack"][:, named - 1].any()
