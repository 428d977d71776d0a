"""The safety filter brakes no harder than the cables can take (issue 31 item 5): without a
tension sensor, the shipped experiments keep every true tension >= 1 N on the dynamic plant.

The bound (kinetostatics.ringing_deceleration) against the wrench matrix built here from the
geometry; the experiments against the plant's ground truth (the log's `tensions`)."""

import numpy as np
import pytest

from cdpm_drake.config import load_scenario
from cdpm_drake.kernels.kinetostatics import ringing_deceleration
from cdpm_drake.robot import load_robot
from cdpm_drake.runs.simulate import simulate


def _largest_share(robot, p):
    """max_i |W^+_i| over the force columns, W built here from the geometry (the level
    platform at p): force and moment of each unit tension."""
    b = np.asarray(robot.attachments, dtype=float)
    d = np.asarray(robot.reels, dtype=float) - (p + b)
    u = d / np.linalg.norm(d, axis=1)[:, None]
    W = np.vstack([u.T, np.cross(b, u).T])
    return np.linalg.norm(np.linalg.pinv(W)[:, :3], axis=1).max()


@pytest.mark.parametrize("name", ["paper_7cable", "cube_8cable"])
def test_the_ringing_bound_is_the_swing_over_twice_the_mass_and_the_largest_share(name):
    robot = load_robot(name)
    p = robot.workspace.center
    share = _largest_share(robot, p)
    expected = 3.0 / (2.0 * robot.dynamics.mass * share)
    assert ringing_deceleration(robot, p, 6, 3.0) == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("name", ["exp1_no_interaction", "exp2_interaction", "exp3_two_pairs"])
def test_without_a_tension_sensor_the_shipped_experiments_keep_every_cable_above_1_n(name):
    # Measured: exp2 dipped to 0.53 N when the filter braked at a / sqrt(3) = 1.15 m/s^2 (the
    # onset of braking rang paper_7cable's 4.2 Hz mode); with the ringing bound 1.70 N.
    scenario = load_scenario(name, "{plant: !DynamicReels {tension_sensor: none}, "
                                   "controller: {pose: full, tension_control: true}}")
    result = simulate(scenario=scenario)
    assert result.error is None, result.error
    assert result.log["time"][-1] == pytest.approx(scenario.duration)
    assert np.min(result.log["tensions"]) >= 1.0


@pytest.mark.parametrize("name", ["paper_7cable", "cube_8cable"])
def test_the_braking_swing_is_twice_the_mass_the_deceleration_and_the_largest_share(name):
    # The soft margin's temperature (kinetostatics.braking_swing) against the same wrench
    # matrix built here; at the ringing bound's deceleration it is the swing that bound took.
    from cdpm_drake.kernels.kinetostatics import braking_swing

    robot = load_robot(name)
    p = robot.workspace.center
    share = _largest_share(robot, p)
    assert braking_swing(robot, p, 6, 0.7) == pytest.approx(
        2.0 * robot.dynamics.mass * 0.7 * share, rel=1e-9)
    assert braking_swing(robot, p, 6, ringing_deceleration(robot, p, 6, 3.0)) == \
        pytest.approx(3.0, rel=1e-9)


def test_a_robot_with_mass_gets_the_soft_margin_and_the_gentle_slowdown():
    # The full pose with tension control: the kinetostatic block's soft margin at the swing
    # of the filter's braking (3 N on paper_7cable, where a_brake is the ringing bound of the
    # 3 N kinetostatic floor) and the lost-margin slowdown at a_brake; the translating
    # controller keeps the hard margin and RAMP_SHARE a_max (the paper's experiments as
    # shipped, pinned by the reference logs).
    from cdpm_drake.config import load_resolved_scenario
    from cdpm_drake.diagram import filter_braking, safety_filter_params, kinetostatic_block_params
    from cdpm_drake.kernels.kinetostatics import P_SOFT
    from cdpm_drake.kernels.safety_filter import F_CABLE_BRAKE, RAMP_SHARE

    full = load_resolved_scenario("exp2_interaction", "{plant: !DynamicReels {}, controller: "
                                                      "{pose: full, tension_control: true}}")
    plain = load_resolved_scenario("exp2_interaction")
    assert kinetostatic_block_params(full)[P_SOFT] == pytest.approx(3.0, rel=1e-9)
    assert kinetostatic_block_params(plain)[P_SOFT] == 0.0
    a_brake = filter_braking(full)
    assert a_brake < RAMP_SHARE * full.max_acceleration
    assert safety_filter_params(full, full=True, kinetostatic=True)[F_CABLE_BRAKE] == a_brake
    assert safety_filter_params(plain, full=False, kinetostatic=True)[F_CABLE_BRAKE] == \
        RAMP_SHARE * plain.max_acceleration


# Hands that rang cables slack on the dynamic plant before the soft margin and the gentle
# slowdown (holdable slack ticks, drive torque sensor: 16 and 17; the adversarial benchmark's
# rows), run here to their end: the plant's true tensions, t* at the true pose.
RANG = [("exp2 (paper_7cable, 1-3 swapped)", "lift 20 N"),
        ("long_8cable (ours)", "corner 20 N")]


@pytest.mark.parametrize("robot, hand", RANG + [("exp2 (paper_7cable, 1-3 swapped)",
                                                 "corner 40 N")])
def test_hands_that_rang_cables_slack_keep_them_taut(robot, hand):
    # The 40 N corner pull is the benchmark's 20 N one doubled (not one of its hands): with
    # the soft margin alone it still rang cable 5 slack for 13 ticks, the kinetostatic rows
    # ramping at 0.9 a_max; none at the cable brake.
    import ast
    import dataclasses

    from helpers_scripts import load_script

    bench = load_script("bench/adversarial_benchmark.py")
    case = next(c for c in bench.cases(methods=("default",), plants=("dynamic",))
                if c.robot == robot and c.hand == hand.replace("40", "20"))
    if hand != case.hand:
        head, forces = case.overlay.split("forces: ")
        rows = ast.literal_eval(forces.split("]]")[0] + "]]")  # the benchmark's numbers
        doubled = [[round(2 * x, 6) for x in row] for row in rows]
        case = dataclasses.replace(case, hand=hand, overlay=head + "forces: " + str(doubled)
                                   + forces.split("]]", 1)[1])
    row = bench.measure(case)
    assert row["fault"] == ""
    assert row["slack_holdable"] == 0
    assert not row["crossed"] and row["closest_vs_d_l_mm"] >= -2.0
