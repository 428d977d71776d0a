"""The shipped paper_7cable robot reproduces the cable-cable distances the paper reports
(section 5), its attachment points being calibrated by scripts/tools/calibrate_attachments.py; its
swapped pairs can separate beyond the experiments' d_u by translating; and (issue 18) its
cables hold the level platform at every reported pose and along every shipped experiment's
path, and over most of the workspace box, while the unswapped cables keep apart.

Statics references: scipy's linprog (HiGHS) for t*, the largest achievable minimum tension of
the level platform (2.5 kg at its centre, moments about the centre)."""

from pathlib import Path

import numpy as np
import pytest
from conftest import highs_t_star

from cdpm_drake.kernels.interference import pair_distances, translation_distance_bound
from cdpm_drake.robot import load_robot
from cdpm_drake.config import (interference_params, load_scenario, scenario_names,
                                 scenario_robot)
from cdpm_drake.kernels.tension import gravity_wrench, step_grid, wrench_matrix
from cdpm_drake.robot.statics import holding_tension

# Paper, section 5: swaps (1-based cable pairs), platform position p (m), reported distances
# (m). These numbers are typed from the paper, not from the calibration script.
REPORTED = [
    ([(1, 3)], [1.77, 3.65, 1.22], {(1, 3): 0.057}),            # 5.1
    ([(1, 3)], [1.56, 3.24, 1.22], {(1, 3): 0.061}),            # 5.2, start
    ([(1, 3)], [1.87, 3.68, 0.53], {(1, 3): 0.059}),            # 5.2, Fig. 12 (a)
    ([(1, 3)], [1.30, 3.68, 1.05], {(1, 3): 0.060}),            # 5.2, Fig. 12 (b)
    ([(1, 3), (5, 7)], [2.22, 3.22, 1.03], {(1, 3): 0.059, (5, 7): 0.061}),  # 5.3
]


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


@pytest.mark.parametrize("swaps, p, reported", REPORTED)
def test_reported_distances_within_1_mm(robot, swaps, p, reported):
    r = robot
    for i, j in swaps:
        r = r.with_swapped_attachments(i, j)
    d = pair_distances(r, np.array(p))
    for (i, j), expected in reported.items():
        assert abs(d[r.pair_position(i, j)] - expected) <= 1e-3, ((i, j), p, d)


def test_attachments_lie_on_a_0_3_m_platform(robot):
    assert np.all(np.abs(robot.attachments) <= 0.15)


def test_unswapped_cables_stay_apart_over_the_workspace(robot):
    # The paper's platform is designed so that the unswapped cables do not meet in
    # translation; issue 18 asks for >= 80 mm anywhere in the box. A 5 cm grid (the script
    # reports 94.0 mm there, refined by local minimisation).
    grid = step_grid(robot.workspace.lower, robot.workspace.upper, 0.05)
    assert pair_distances(robot, grid).min() >= 0.080


# Paper, sections 5.2 and 5.3: d_u = 62 mm for pair 1-3 (experiment 2) and pairs 1-3 and 5-7
# (experiment 3); typed from the paper. The calibration requires g >= 64 mm (2 mm margin).
PAPER_D_U = 0.062


@pytest.mark.parametrize("swaps, pairs", [
    ([(1, 3)], [(1, 3)]),                    # experiment 2
    ([(1, 3), (5, 7)], [(1, 3), (5, 7)]),    # experiment 3
])
def test_swapped_pairs_can_separate_beyond_the_paper_d_u(robot, swaps, pairs):
    # The largest distance translation can reach (translation_distance_bound) must exceed
    # d_u, or the force of the pair never switches off (gradient ascent stops at d = g).
    r = robot
    for i, j in swaps:
        r = r.with_swapped_attachments(i, j)
    g = translation_distance_bound(r)
    for i, j in pairs:
        assert g[r.pair_position(i, j)] >= 0.064 > PAPER_D_U, ((i, j), g[r.pair_position(i, j)])


@pytest.mark.parametrize("name", scenario_names())
def test_every_shipped_scenario_lets_its_swapped_pairs_separate(name):
    # Each shipped scenario's swapped pairs, with that scenario's own d_u per pair.
    scenario = load_scenario(name)
    r = scenario_robot(scenario)
    params = interference_params(scenario, r)
    g = translation_distance_bound(r)
    for i, j in scenario.swaps:
        k = r.pair_position(i, j)
        assert g[k] > params.d_u[k], (name, (i, j), g[k], params.d_u[k])


# --- statics (issue 18) ----------------------------------------------------------------------



WEIGHT = gravity_wrench(2.5)  # the robot file's platform mass


@pytest.mark.parametrize("swaps, p, reported", REPORTED)
def test_every_reported_pose_holds_the_level_platform_at_5_N(robot, swaps, p, reported):
    # The real robot held its platform in every experiment (issue 18: >= 5 N with the swaps).
    r = robot
    for i, j in swaps:
        r = r.with_swapped_attachments(i, j)
    assert robot.dynamics.mass == 2.5
    assert highs_t_star(wrench_matrix(r, p), WEIGHT) >= 5.0
    assert holding_tension(r, p) >= 5.0


def test_the_unswapped_platform_is_held_on_most_of_the_box(robot):
    # Issue 18: maximise the share of the box held at >= 5 N unswapped (it was 28 %; the
    # calibration reports 69.4 % on this 5 cm grid). The compiled t* on the whole grid, HiGHS
    # on 400 of its points.
    grid = step_grid(robot.workspace.lower, robot.workspace.upper, 0.05)
    t = holding_tension(robot, grid)
    assert np.mean(t >= 5.0) > 0.65
    sample = np.random.default_rng(0).choice(len(grid), 400, replace=False)
    for k in sample:
        assert (highs_t_star(wrench_matrix(robot, grid[k]), WEIGHT) >= 5.0) == (t[k] >= 5.0)


REFERENCE_LOGS = Path(__file__).resolve().parents[1] / "data" / "reference_logs"


@pytest.mark.parametrize("name", ["exp1_no_interaction", "exp2_interaction",
                                  "exp3_two_pairs"])
def test_every_tick_of_each_shipped_experiment_holds_the_platform(name):
    # The stored paths of the shipped experiments (kinematic plant, scripts/
    # make_reference_logs.py), every tick with the experiment's swaps: t* >= 5 N (issue 18;
    # the calibration reports 14.11, 5.93 and 17.16 N as the smallest). HiGHS every 250 ticks.
    with np.load(REFERENCE_LOGS / f"{name}.npz") as f:
        p = np.cumsum(f["p"], axis=0) * float(f["quantum"])
    r = scenario_robot(load_scenario(name))
    t = holding_tension(r, p)
    assert t.min() >= 5.0, (name, t.min(), p[np.argmin(t)])
    for k in range(0, len(p), 250):
        assert highs_t_star(wrench_matrix(r, p[k]), WEIGHT) >= 5.0
