"""Without a tension sensor the controller warns of the ringing the encoders cannot see,
asserted against the dynamic plant's ground truth (its `tensions` and `slack`, which the
controller never reads): every cable that goes truly slack where the statics at the true pose
could hold the measured hand is warned of (`ringing_warned`) at or before its first slack
tick; a hand under which every true tension stays above the floor is warned of nowhere; and
the run summary names the cables and the times. And the stretch estimate at high tensions
against the plant's truth. Deterministic simulations (no sensor noise without a sensor)."""

from pathlib import Path

import numpy as np

from cdpm_drake.cli.summaries import unseen_ringing_warning
from cdpm_drake.config import load_resolved_scenario
from cdpm_drake.robot.statics import posed_holding_tension
from cdpm_drake.runs.simulate import simulate

from helpers_robots import across_pair

NONE = ("controller: {pose: full, tension_control: true}, "
        "plant: !DynamicReels {tension_sensor: none}, ")


def _run(scenario, text, controller="", fault=False):
    text = "{%s%s}" % (NONE.replace("true}", "true%s}" % controller), text)
    resolved = load_resolved_scenario(scenario, text)
    result = simulate(scenario=resolved)
    assert (result.error is not None) == fault, result.error
    return resolved, result.log


def test_a_hand_faster_than_the_robot_is_warned_of_before_each_holdable_slack_cable():
    # exp3's 40 N push across 1-3 ramped at 400 N/s, faster than the tension path follows
    # (`cdpm info`): measured, cable 2 warned of at 0.026 s, truly slack from 0.044 s where
    # the statics at the true pose hold the hand in [2, 100] N. (exp2's 40 N lift at
    # 100 N/s, which slackened cable 2 unseen before the filter gave way, no longer does.)
    f = [round(float(x), 6) for x in 40.0 * across_pair("exp3_two_pairs", (1, 3))]
    resolved, log = _run("exp3_two_pairs", "duration: 0.3, operator: !ScriptedOperator "
                         "{times: [0, 0.1, 1.3], forces: [[0, 0, 0], %s, %s]}" % (f, f),
                         fault=True)  # the model monitor stops it, the log kept up to there
    slack = np.asarray(log["slack"], dtype=bool)
    ticks = np.flatnonzero(slack.any(axis=1))
    holdable = np.zeros(slack.shape[0], dtype=bool)
    holdable[ticks] = posed_holding_tension(
        resolved.robot, log["p_true"][ticks], log["rpy_true"][ticks], log["F_H"][ticks],
        floor=2.0, ceiling=resolved.scenario.controller.max_tension) >= 0.0
    warned = np.asarray(log["ringing_warned"]) > 0.5
    cables = np.flatnonzero((slack & holdable[:, None]).any(axis=0))
    assert cables.size, "the case no longer slackens a cable: pick a harder one"
    time = np.asarray(log["time"]).reshape(-1)
    for i in cables:
        first_slack = int(np.argmax(slack[:, i] & holdable))
        assert warned[:first_slack + 1, i].any(), (
            f"cable {i + 1} slack at {time[first_slack]:.3f} s, not warned before")
    # The summary names the cable the truth says slackened first, with the time it was
    # warned (at most the first slack's).
    first = int(cables[np.argmin([np.argmax(slack[:, i]) for i in cables])])
    text = unseen_ringing_warning(log)
    when = time[int(np.argmax(warned[:, first]))]
    assert f"cable {first + 1} from {when:.3f} s" in text
    assert when <= time[int(np.argmax(slack[:, first]))]


def test_a_hand_that_keeps_every_cable_above_the_floor_is_not_warned_of():
    # exp3's own operator, its first 3 s: the truth stays at 5 N or more (the floor is 4 N).
    resolved, log = _run("exp3_two_pairs", "duration: 3")
    assert log["tensions"].min() >= resolved.scenario.controller.tension_floor
    assert not np.asarray(log["ringing_warned"]).any()
    assert unseen_ringing_warning(log) == ""
    # The block is there and predicts a swing (it is not silent by being absent).
    assert np.asarray(log["ringing_swing"]).max() > 0.0


def test_the_stretch_estimate_holds_at_high_tensions():
    # cube_8cable held with every cable at 250 N or more (up to the 500 N ceiling): each
    # cable stretches by T L0 / EA (the plant's own law, kernels/plant/cable_net.py: 7 mm at
    # 500 N on a 1 m, 70 kN cable), and the estimate from the lengths corrected by that law
    # must find the true tensions and pose.
    cube = str(Path(__file__).resolve().parents[2] / "scripts" / "bench" / "adversarial"
               / "cube_5_7.yaml")
    resolved, log = _run(cube, "duration: 1.0",
                         controller=", min_tension: 250, max_tension: 500")
    time = np.asarray(log["time"]).reshape(-1)
    # Once the command has ramped up (at 2000 N/s, the estimate a tick behind the truth:
    # 4-5 N) and held: measured, within 0.075 N of 500 N from 0.6 s, where an EA 1 % off
    # would put the internal force (the lengths' residual over L0 / EA) ~1 % off.
    settled = time >= 0.6
    true = np.asarray(log["tensions"])[settled]
    assert true.max() > 450.0  # high tensions indeed
    np.testing.assert_allclose(np.asarray(log["tension_estimate"])[settled], true, atol=0.1)
    np.testing.assert_allclose(log["p"][settled], log["p_true"][settled], atol=1e-5)
    # The plant's stretch at the true pose, from its unstretched lengths (the encoders read
    # them less their start stretch, encoder_zero): the estimate's law is the plant's.
    EA = resolved.robot.dynamics.EA
    estimate = np.asarray(log["tension_estimate"])[settled]
    rigid = np.linalg.norm(resolved.robot.reels[None] - log["p_true"][settled][:, None]
                           - resolved.robot.attachments[None], axis=2)
    np.testing.assert_allclose(rigid / (1.0 + estimate / EA), rigid / (1.0 + true / EA),
                               atol=1e-5)


def test_with_a_tension_sensor_the_block_is_left_out():
    # The sensor measures the ringing (the tension damping block); the model is for its
    # absence only.
    resolved = load_resolved_scenario("exp2_interaction", "{duration: 0.02, %s}" % NONE.replace(
        "tension_sensor: none", "tension_sensor: drive_torque").rstrip(", "))
    log = simulate(scenario=resolved).log
    assert "ringing_warned" not in log and "ringing_swing" not in log
    assert "tension_estimate" in log
