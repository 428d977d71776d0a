"""The run summary's word on a hand faster than the tension path (tension_status 5,
full_pose.HAND_TOO_FAST), and the tension path's numbers derived from the robot."""

import numpy as np

from cdpm_drake.cli.summaries import tension_control_summary
from cdpm_drake.kernels import tension_path
from cdpm_drake.kernels.full_pose import HAND_TOO_FAST


def test_the_summary_names_the_cable_and_the_first_time_the_hand_was_too_fast():
    status = np.array([0, 0, 1, HAND_TOO_FAST, HAND_TOO_FAST, 1, HAND_TOO_FAST])
    cable = np.array([0, 0, 2, 2, 2, 2, 3])
    log = {"tension_status": status[:, None], "tension_cable": cable[:, None],
           "t_star": np.full((7, 1), np.inf), "tension_estimate": np.full((7, 7), 10.0),
           "time": 0.002 * np.arange(7)}
    text = tension_control_summary(log)
    assert "hand faster than the tension path can follow on 3 ticks" in text
    assert "2 (2 ticks), 3 (1 tick)" in text
    assert "first at 0.006 s, cable 2" in text
    log["tension_status"] = np.zeros((7, 1))
    assert "hand faster" not in tension_control_summary(log)


def test_the_tension_path_s_numbers_follow_from_the_robot():
    # 2 ticks of 2 ms and the drives' 10 ms; the reel speed the motion leaves.
    assert tension_path.lead_time(0.002, 100.0) == 0.014
    assert tension_path.rate_time(80.0) == 1.0 / 80.0
    assert tension_path.stretch_speed(1.0, 0.5) == 0.5
    assert tension_path.stretch_speed(0.5, 0.5) == 0.05  # a tenth kept


def _printed_rates(robot, p):
    import io
    import re

    from cdpm_drake.cli.info import print_fastest_hand

    out = io.StringIO()
    print_fastest_hand(robot, p, out)
    return {k: float(v) for k, v in re.findall(r"([+-][xyz]) (\d+)", out.getvalue())}


def test_cdpm_info_s_fastest_hand_is_the_robot_s_own():
    """`cdpm info`'s fastest hand at exp2's start: each cable's rise S_i = EA / L_i x speed
    (kernels/tension_path.py) with L_i the closed form of eq. 2, ||B_i - (p + A_i)||; so a
    robot of twice the cables' EA follows every hand twice as fast."""
    import dataclasses

    from cdpm_drake.config import load_resolved_scenario
    from cdpm_drake.config.scenario import Controller
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix

    resolved = load_resolved_scenario("exp2_interaction")
    r, p = resolved.robot, np.asarray(resolved.scenario.initial_position, dtype=float)
    printed = _printed_rates(r, p)
    assert sorted(printed) == ["+x", "+y", "+z", "-x", "-y", "-z"]
    d, c = r.dynamics, Controller()  # `cdpm info` takes the controller's defaults
    lengths = np.linalg.norm(r.reels - (p + r.attachments), axis=1)
    speed = tension_path.stretch_speed(r.limits.max_reel_speed, r.limits.max_velocity)
    expected = tension_path.fastest_hand(
        wrench_matrix(r, p), lengths, d.EA, lambda F: gravity_wrench(d.mass, F, d.handle),
        np.array([0.0, 0.0, 1.0]), floor=c.min_tension, hard_floor=c.tension_floor,
        ceiling=c.max_tension, speed=speed)
    assert abs(printed["+z"] - expected) <= 0.5  # printed to the newton per second
    stiffer = dataclasses.replace(r, dynamics=dataclasses.replace(d, EA=2.0 * d.EA))
    for key, rate in _printed_rates(stiffer, p).items():
        assert abs(rate - 2.0 * printed[key]) <= 1.0, key
