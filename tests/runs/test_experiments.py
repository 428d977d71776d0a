"""The paper's experiments (section 5) and the crossing behaviour, through the whole diagram.

These run the shipped scenarios (calibrated paper robot, cdpm_drake/data/robots/paper_7cable.yaml)
and a small robot built so that two cables can be pushed through each other
(tests/data/robots/crossing_4cable.yaml): the paper robot's swapped cables never come closer
than 41 mm anywhere in its workspace box (5 cm grid), so no hand can cross them there.
"""

from pathlib import Path

import numpy as np
import pytest

from cdpm_drake.kernels.interference import pair_distances
from cdpm_drake.config import load_scenario, scenario_robot
from cdpm_drake.runs.simulate import simulate

CROSSING_ROBOT = Path(__file__).resolve().parents[1] / "data" / "robots" / "crossing_4cable.yaml"


def _run(name, overlay=None, duration=None):
    scenario = load_scenario(name, overlay_text=overlay)
    result = simulate(scenario=scenario, duration=duration)
    assert result.error is None, result.error
    return scenario, scenario_robot(scenario), result.log


@pytest.fixture(scope="module")
def exp1():
    return _run("exp1_no_interaction", duration=20.0)


def test_exp1_distance_rises_monotonically_and_settles_just_above_d_u(exp1):
    scenario, robot, log = exp1
    k = robot.pair_position(1, 3)
    d = log["pair_distances"][:, k]
    d_u = scenario.interference.default.d_u  # 61 mm (section 5.1)
    assert d[0] < d_u  # starts inside the band: 56 mm (paper: 57 mm; calibration residual)
    assert np.all(np.diff(d) >= -1e-12)
    # The force is zero from d_u on; the admittance (time constant M/C = 1 s) coasts a little
    # further: settled "just above" d_u, within half a millimetre.
    assert d_u < d[-1] < d_u + 0.5e-3
    assert abs(d[-1] - d[-500]) < 1e-6  # settled: under a micrometre in the last second
    assert not log["active"][-1, k]


def test_exp1_first_motion_is_along_the_initial_distance_gradient(exp1):
    scenario, robot, log = exp1
    k = robot.pair_position(1, 3)
    p0 = np.array(scenario.initial_position)
    # Reference: central differences of the distance (not the force code's analytic gradient).
    h = 1e-6
    grad = np.array([(pair_distances(robot, p0 + h * e)[k] - pair_distances(robot, p0 - h * e)[k])
                     / (2 * h) for e in np.eye(3)])
    step = log["p"][25] - log["p"][0]  # the first 50 ms
    cosine = step @ grad / (np.linalg.norm(step) * np.linalg.norm(grad))
    assert cosine > 0.99, cosine


def test_exp1_nothing_but_the_interference_force_moves_the_platform(exp1):
    _, _, log = exp1
    assert np.all(log["F_H"] == 0.0)
    np.testing.assert_array_equal(log["F_d"], log["F_int"])
    assert not np.any(log["crossed"])
    # Only pair (1,3) ever acts.
    assert set(np.flatnonzero(log["active"].any(axis=0))) == {1}


def test_exp3_both_pairs_recover_above_their_d_u():
    scenario, robot, log = _run("exp3_two_pairs")
    d_u = scenario.interference.default.d_u  # 62 mm for both pairs (section 5.3)
    for pair in ((1, 3), (5, 7)):
        k = robot.pair_position(*pair)
        d = log["pair_distances"][:, k]
        assert d[0] < d_u, pair  # 59 and 61 mm at the start, as in the paper (within 1 mm)
        assert d[-1] > d_u, (pair, d[-1])
        assert not log["active"][-1, k]
    np.testing.assert_array_equal(log["F_int"][-1], 0.0)


def test_exp2_hand_keeps_cables_apart_without_crossing():
    scenario, robot, log = _run("exp2_interaction")
    k = robot.pair_position(1, 3)
    d = log["pair_distances"][:, k]
    assert log["active"][:, k].any()
    assert not np.any(log["crossed"])
    # The hand pulls with up to 5 N against F_u = 3 N: it may press into the band below d_l
    # (the paper's Fig. 12a shows 59 mm, d_l = 60 mm) but never makes the cables meet.
    assert d.min() > 0.05
    # The interference force is at most F_u and always opposes the approach.
    assert np.linalg.norm(log["F_int"], axis=1).max() <= 3.0 + 1e-9


# --- Crossing: a robot whose cables 1 and 2 can be pushed through each other -----------------


# The paper's Fig. 5 alone: without issue 26's safety filter, which stops the push at d_min.
FIG_5 = "safety_filter: {enabled: false}, model_monitor: {enabled: false}, "


def _push(force_y, release=4.0, duration=12.0, extra=FIG_5):
    """From y = 0.5 m (d12 = 33 mm) a constant hand force along -y, towards the plane y = 0
    where cables 1 and 2 meet, released at `release` s. d_l = 20 mm, d_u = 30 mm, F_u = 2 N."""
    overlay = (
        f"{{robot: {CROSSING_ROBOT}, swaps: [], initial_position: [0.0, 0.5, 0.5], "
        f"duration: {duration}, {extra}"
        "interference: {default: {d_l: 0.02, d_u: 0.03, F_u: 2.0, eps: 0.1}}, "
        f"operator: !ScriptedOperator {{times: [0, {release}, {release + 0.002}], "
        f"forces: [[0, {-force_y}, 0], [0, {-force_y}, 0], [0, 0, 0]]}}}}")
    return _run("exp1_no_interaction", overlay)


def test_a_gentle_push_below_F_u_never_gets_below_d_l():
    # 1 N along -y: its component along any unit gradient is at most 1 N < F_u - eps.
    _, robot, log = _push(1.0)
    d = log["pair_distances"][:, robot.pair_position(1, 2)]
    assert d.min() < 0.03  # it did push into the band
    assert d.min() > 0.02
    assert not np.any(log["crossed"])


def test_a_strong_push_crosses_the_cables_and_the_force_pushes_back():
    # 5 N > 2 F_u: the interference force cannot hold; the crossing is reported and from then
    # on the force points back to the original side (+y), at full intensity F_u - eps or more.
    _, robot, log = _push(5.0)
    k = robot.pair_position(1, 2)
    crossed = log["crossed"][:, k]
    assert crossed.any()
    first = int(np.argmax(crossed))
    assert log["p"][first, 1] < 0.0  # really on the other side of y = 0
    during = np.flatnonzero(crossed)
    assert np.all(log["F_int"][during, 1] > 1.9 - 1e-9)
    assert np.all(log["active"][during, k])
    # Released at 4 s, the force alone brings the platform back and the crossing clears.
    assert not crossed[-1]
    assert log["p"][-1, 1] > 0.0


def test_the_safety_filter_stops_a_strong_push_at_d_min_and_lets_it_back():
    # The same 5 N push with the safety filter (the default, issue 26): the pair's distance
    # never goes below its d_min (= d_l, 20 mm: the default) by more than the linearisation
    # of one tick, nothing crosses, and the filter is what held it (its status says so).
    _, robot, log = _push(5.0, extra="")
    k = robot.pair_position(1, 2)
    d = log["pair_distances"][:, k]
    assert d.min() > 0.02 - 1e-6, d.min()
    assert d.min() < 0.0201  # it was pushed right to the floor
    assert not np.any(log["crossed"])
    held = (log["filter_binding"][:, 0].astype(int) & 1) > 0  # a pair's barrier binds
    assert held.any() and np.all(d[held] < 0.03)  # only near the pair
    # Released at 4 s, the interference force moves it back out of the band.
    assert d[-1] > 0.03
