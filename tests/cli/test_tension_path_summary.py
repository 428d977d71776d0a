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
