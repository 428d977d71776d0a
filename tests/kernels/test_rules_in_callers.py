"""The crossing rule, the gradient floor and the force clip inside their callers.

`update_side` and the logistic are tested as pure functions in test_interference.py; here the
same rules are exercised through `interference.interference_force` (where the straddle and
near flags are computed from the geometry) and through the whole diagram (a short
simulation), on geometry built so that each branch is reached:

- two cable LINES that pass through each other beyond a cable's end while the pair is within
  d_u: not a crossing (the memory is refreshed, the force stays the logistic one);
- a real crossing (both closest points inside their cables): flagged, pushed back to the
  remembered side at F_u, clipped by F_max;
- the gradient floor above and below |t - s|, and the clip of the sum of two pairs.
"""

import dataclasses

import numpy as np
import pytest

from cdpm_drake.kernels.interference import (InterferenceParams, interference_force, logistic_intensity,
                                     segment_distance)
from cdpm_drake.kernels.plant.operators import ScriptedOperator
from cdpm_drake.robot import Robot, Workspace
from cdpm_drake.config import (Admittance, Interference, Logistic, ModelMonitor, SafetyFilter,
                                 Scenario, Sensor, scenario_robot)
from cdpm_drake.runs.simulate import simulate

from conftest import DATA_DIR, to_yaml

# --- geometry: lines that meet beyond a cable's end --------------------------------------------

# Cable 1 runs from B1 = p to A1 = (0, 2, 0) (along +y); cable 2 from B2 = p + (0.3, -0.01, 0)
# to A2 = (-3, -0.01, 0) (along -x, 1 cm behind B1 in y). With p = (0, 0, z) the line of
# cable 1 reaches y = -0.01 at s = -0.005 (beyond its platform end B1) and height 1.005 z; the
# line of cable 2 passes x = 0 at t = 0.3 / 3.3 = 0.0909 and height 0.909 z. The two LINES
# therefore meet only at z = 0, at a point outside cable 1, so the sign of their signed
# distance flips there while the SEGMENTS' closest points are B1 (s = 0) and a point of
# cable 2 (t = 0.0909), d = sqrt(0.01^2 + (0.0955 z)^2) ~ 10 mm: inside d_u = 30 mm the whole
# time, yet no cable passes through the other. Cable 3 (vertical, 0.3 m away) holds the
# platform in z.
BEYOND_END = dict(
    name="beyond_end_3cable",
    reels=[[0.0, 2.0, 0.0], [-3.0, -0.01, 0.0], [0.3, 0.3, 3.0]],
    attachments=[[0.0, 0.0, 0.0], [0.3, -0.01, 0.0], [0.3, 0.3, 0.3]],
    workspace={"lower": [-0.2, -0.2, -0.2], "upper": [0.2, 0.2, 0.2]},
)
BEYOND_PARAMS = dict(d_l=0.005, d_u=0.03, F_u=0.5, eps=0.05)


def beyond_end_robot():
    return Robot(name=BEYOND_END["name"], reels=np.array(BEYOND_END["reels"]),
                 attachments=np.array(BEYOND_END["attachments"]),
                 workspace=Workspace(np.array(BEYOND_END["workspace"]["lower"]),
                                     np.array(BEYOND_END["workspace"]["upper"])))


def _line_sigma(robot, p, i=0, j=1):
    """Signed distance of the two cable LINES, (B_i - B_j) . (u_i x u_j) / |u_i x u_j|, m."""
    B = np.asarray(p) + robot.attachments
    u = robot.reels - B
    n = np.cross(u[i], u[j])
    return float((B[i] - B[j]) @ n / np.linalg.norm(n))


def test_lines_meeting_beyond_a_cable_end_within_d_u_is_not_a_crossing():
    r = beyond_end_robot()
    k = r.pair_position(1, 2)
    params = InterferenceParams.uniform(r, **BEYOND_PARAMS)
    zs = np.round(np.arange(-0.05, 0.0501, 0.005), 6)
    side = None
    sides, sigmas = [], []
    for z in zs:
        res = interference_force(r, [0.0, 0.0, z], params, side)
        side = res.side
        # The geometry is as derived above: within d_u, closest point at cable 1's end.
        assert res.distance[k] < BEYOND_PARAMS["d_u"] and res.s[k] == 0.0
        assert res.t[k] == pytest.approx(0.0909, abs=1e-3)
        assert res.active[k] and not res.crossed[k], z
        # The force is the paper's: the logistic intensity along the (unit) gradient.
        alpha = logistic_intensity(res.distance[k], **BEYOND_PARAMS)
        assert res.intensity[k] == pytest.approx(alpha, rel=1e-12)
        assert np.linalg.norm(res.force) == pytest.approx(alpha, rel=1e-9)
        sides.append(int(res.side[k]))
        sigmas.append(_line_sigma(r, [0.0, 0.0, z]))
    # The line side really flips (so the rule had something to decide): the memory follows the
    # sign of sigma, -1 below z = 0 and +1 above, never the crossed values +-2.
    sigmas = np.array(sigmas)
    assert (sigmas[zs < 0] < 0).all() and (sigmas[zs > 0] > 0).all()
    assert set(sides) == {-1, 1}
    assert sides == [int(np.sign(s)) if s != 0 else sides[n - 1] for n, s in enumerate(sigmas)]


def _beyond_end_scenario(tmp_path, z0, force_z, duration):
    path = tmp_path / "beyond_end.yaml"
    path.write_text(to_yaml(BEYOND_END) + "\n")
    return Scenario(
        name="beyond_end", robot=str(path), initial_position=[0.0, 0.0, z0], duration=duration,
        admittance=Admittance(mass=1.0, damping=10.0), sensor=Sensor(filter_window=1),
        interference=Interference(default=Logistic(**BEYOND_PARAMS)),
        operator=ScriptedOperator(times=[0.0], forces=[[0.0, 0.0, force_z]]),
        # The crossing rule of the paper's diagram: the safety filter would hold the pair at
        # its d_min (d_l) before the platform got through.
        safety_filter=SafetyFilter(enabled=False), model_monitor=ModelMonitor(enabled=False))


def test_lines_meeting_beyond_a_cable_end_through_the_diagram_is_not_a_crossing(tmp_path):
    """The hand pushes the platform from z = -0.04 m through z = 0 (3 N, 0.3 m/s): the pair
    stays within d_u, its lines pass through each other beyond cable 1's end, and the
    diagram never reports a crossing; F_int keeps the logistic intensity of the distance."""
    scenario = _beyond_end_scenario(tmp_path, -0.04, 3.0, 0.4)
    result = simulate(scenario=scenario)
    assert result.error is None, result.error
    log = result.log
    robot = scenario_robot(scenario)
    k = robot.pair_position(1, 2)
    z = log["p"][:, 2]
    assert z[0] < -0.03 and z[-1] > 0.03  # it went through the plane where the lines meet
    d = log["pair_distances"][:, k]
    assert d.max() < BEYOND_PARAMS["d_u"] and log["active"][:, k].all()
    assert not log["crossed"].any()
    # F_int is exactly the logistic of the logged distance (a crossed pair would push at F_u).
    np.testing.assert_allclose(np.linalg.norm(log["F_int"], axis=1),
                               logistic_intensity(d, **BEYOND_PARAMS), rtol=1e-9)


# --- a real crossing through the diagram --------------------------------------------------------

CROSSING_ROBOT = DATA_DIR / "robots" / "crossing_4cable.yaml"


def test_a_real_crossing_is_flagged_pushed_back_at_F_u_and_clipped_by_F_max():
    """crossing_4cable (cables 1 and 2 meet at interior points when the platform crosses
    y = 0): a 4 N push along -y from y = 0.5 m. F_u = 0.6 N cannot hold it; once across,
    the pair is flagged crossed with both closest points inside their cables (a straddling
    crossing), and pushed back towards +y at F_u = 0.6 N, clipped to F_max = 0.45 N."""
    scenario = Scenario(
        name="crossing", robot=str(CROSSING_ROBOT), initial_position=[0.0, 0.5, 0.5],
        duration=1.6, admittance=Admittance(mass=1.0, damping=5.0),
        sensor=Sensor(filter_window=1),
        interference=Interference(default=Logistic(d_l=0.01, d_u=0.025, F_u=0.6, eps=0.1),
                                  F_max=0.45),
        operator=ScriptedOperator(times=[0.0], forces=[[0.0, -4.0, 0.0]]),
        # The paper's Fig. 5: the safety filter would stop the push before the crossing.
        safety_filter=SafetyFilter(enabled=False), model_monitor=ModelMonitor(enabled=False))
    result = simulate(scenario=scenario)
    assert result.error is None, result.error
    log = result.log
    robot = scenario_robot(scenario)
    k = robot.pair_position(1, 2)
    crossed = log["crossed"][:, k]
    assert crossed.any() and not crossed[0]
    first = int(np.argmax(crossed))
    p = log["p"][first]
    assert p[1] < 0.0 <= log["p"][first - 1, 1]  # flagged on the tick it went across
    B = p + robot.attachments
    sd = segment_distance(B[0], robot.reels[0], B[1], robot.reels[1])
    assert 0.0 < sd.s < 1.0 and 0.0 < sd.t < 1.0  # a straddling crossing
    during = np.flatnonzero(crossed)
    F = log["F_int"][during]
    np.testing.assert_allclose(np.linalg.norm(F, axis=1), 0.45, rtol=1e-12)
    assert (F[:, 1] > 0.4).all()  # back towards +y, the side it came from
    # Before the crossing, in the band, the force is the logistic one, below the clip.
    before = np.flatnonzero(log["active"][:first, k])
    d = log["pair_distances"][before, k]
    alpha = logistic_intensity(d, 0.01, 0.025, 0.6, 0.1)
    np.testing.assert_allclose(np.linalg.norm(log["F_int"][before], axis=1),
                               np.minimum(alpha, 0.45), rtol=1e-9)


# --- gradient floor: both sides of |t - s|, through the function and the diagram ----------------

# exp1's start (cables 1 and 3 swapped): pair (1,3) at d = 56.17 mm, |t - s| = 0.0164.
P_EXP1 = np.array([1.77, 3.65, 1.22])


def _exp1(**interference):
    return Scenario(name="floor", swaps=[[1, 3]], initial_position=P_EXP1.tolist(),
                    duration=0.004, sensor=Sensor(filter_window=1),
                    interference=Interference(**interference))


@pytest.mark.parametrize("floor, scale", [(0.0, 1.0), (0.01, 1.0), (0.05, 0.0164 / 0.05),
                                          (0.5, 0.0164 / 0.5)])
def test_gradient_floor_branches_in_the_function_and_the_diagram(floor, scale):
    """Below |t - s| (and at 0, the paper) the push is the unit gradient: |F_int| = alpha.
    Above it, grad d / floor: |F_int| = alpha |t - s| / floor (0.327 alpha at 0.05)."""
    robot = scenario_robot(_exp1())
    k = robot.pair_position(1, 3)
    params = InterferenceParams.uniform(robot, 0.050, 0.061, 2.0, 0.1, gradient_floor=floor)
    res = interference_force(robot, P_EXP1, params)
    ts = abs(res.t[k] - res.s[k])
    assert ts == pytest.approx(0.0164, abs=1e-4)
    alpha = logistic_intensity(res.distance[k], 0.050, 0.061, 2.0, 0.1)
    expected = alpha * (1.0 if floor <= ts else ts / floor)
    assert expected == pytest.approx(alpha * scale, rel=0.01)
    assert np.linalg.norm(res.force) == pytest.approx(expected, rel=1e-12)
    # The same through the diagram, with the floor set in the scenario.
    log = simulate(scenario=_exp1(gradient_floor=floor)).log
    np.testing.assert_allclose(log["F_int"][0], res.force, atol=1e-12)


# --- the clip acts on the sum of the pairs ----------------------------------------------------


def test_F_max_clips_the_sum_of_two_pairs_through_the_diagram():
    """Experiment 3's geometry (pairs (1,3) and (5,7) both in the band, 1.187 N and 0.118 N,
    summing to 1.166 N as they partly oppose): with F_max = 1.0 N the diagram's F_int is that
    sum scaled to 1.0 N (eq. 30), not the sum of per-pair clipped forces."""
    p = np.array([2.22, 3.22, 1.03])
    scenario = Scenario(
        name="clip", swaps=[[1, 3], [5, 7]], initial_position=p.tolist(), duration=0.004,
        sensor=Sensor(filter_window=1),
        interference=Interference(default=Logistic(d_l=0.057, d_u=0.062, F_u=2.0, eps=0.1),
                                  F_max=1.0))
    robot = scenario_robot(scenario)
    free = interference_force(robot, p, InterferenceParams.uniform(
        robot, 0.057, 0.062, 2.0, 0.1, F_max=100.0))
    per_pair = free.direction * free.intensity[:, None]
    active = np.flatnonzero(free.active)
    assert [robot.pairs[a] for a in active] == [(1, 3), (5, 7)]
    total = per_pair.sum(axis=0)
    assert np.linalg.norm(total) == pytest.approx(1.166, abs=1e-3)
    norms = np.linalg.norm(per_pair, axis=1, keepdims=True)
    clipped_each = (per_pair * np.minimum(1.0, 1.0 / np.maximum(norms, 1e-300))).sum(axis=0)
    expected = total / np.linalg.norm(total)
    assert np.linalg.norm(clipped_each - expected) > 0.01  # the two readings differ here
    log = simulate(scenario=scenario).log
    np.testing.assert_allclose(log["F_int"][0], expected, atol=1e-12)
    # And with the clip above the sum (F_max = 5 N), the sum itself.
    log = simulate(scenario=dataclasses.replace(scenario, interference=dataclasses.replace(
        scenario.interference, F_max=5.0))).log
    np.testing.assert_allclose(log["F_int"][0], total, atol=1e-12)
