"""The safety blocks' logged outputs against independent references, on a real run (the shipped
experiment 2, 12 s: through the kinetostatic limit it meets at 10.3 s). A block that sent another
slot of its kernel's output to a logged port, or a cue that pointed the wrong way, would pass
every test that reads only the summary.

- the model monitor's `t_star_hand`: t* by a linear program (scipy's HiGHS) at the logged pose
  and hand force: max t with W T = -w, T_i >= t (+inf where unbounded);
- the kinetostatic block's `kappa` by the same LP with the floor and the ceiling, and its cue
  `F_kin` along the LP margin's gradient (central differences);
- the safety filter's `pair_margin` against the interference block's logged pair distances
  minus each pair's d_min.
The statics are built here from the robot's geometry, not from the package's kernels."""

import numpy as np
import pytest
from scipy.optimize import linprog

from cdpm_drake.config import load_resolved_scenario
from cdpm_drake.diagram import RIPPLE
from cdpm_drake.runs.simulate import simulate

GRAVITY = 9.81


@pytest.fixture(scope="module")
def run():
    resolved = load_resolved_scenario("exp2_interaction", "{duration: 12.0}")
    result = simulate(scenario=resolved)
    assert result.error is None, result.error
    return resolved, result.log


def _statics(robot, p, F):
    """W (6, m) and the external wrench w (6,) at the level platform at p with the hand force F
    at the handle: cable i pulls the platform towards its reel, moments about the centre."""
    b = np.asarray(robot.attachments, dtype=float)
    d = np.asarray(robot.reels, dtype=float) - (p + b)
    u = d / np.linalg.norm(d, axis=1)[:, None]
    W = np.vstack([u.T, np.cross(b, u).T])
    weight = np.array([0.0, 0.0, -robot.dynamics.mass * GRAVITY])
    w = np.concatenate([F + weight, np.cross(np.asarray(robot.dynamics.handle), F)])
    return W, w


def _lp(W, w, floor=None, ceiling=None):
    """max s over (T, s): W T = -w, T_i - s >= floor-side, ceiling - T_i >= s (when given)."""
    m = W.shape[1]
    c = np.zeros(m + 1)
    c[-1] = -1.0
    rows = [np.hstack([-np.eye(m), np.ones((m, 1))])]
    rhs = [np.zeros(m) if floor is None else -floor * np.ones(m)]
    if ceiling is not None:
        rows.append(np.hstack([np.eye(m), np.ones((m, 1))]))
        rhs.append(ceiling * np.ones(m))
    r = linprog(c, A_ub=np.vstack(rows), b_ub=np.concatenate(rhs),
                A_eq=np.hstack([W, np.zeros((6, 1))]), b_eq=-w,
                bounds=[(None, None)] * (m + 1), method="highs")
    if r.status == 3:
        return np.inf
    return r.x[-1] if r.status == 0 else -np.inf


def test_the_monitors_t_star_is_the_lps_at_the_logged_pose_and_hand(run):
    resolved, log = run
    t_star = np.asarray(log["t_star_hand"], dtype=float).reshape(-1)
    ticks = np.linspace(0, t_star.size - 1, 60).astype(int)
    finite = 0
    for k in ticks:
        ref = _lp(*_statics(resolved.robot, log["p"][k], log["F_H"][k]))
        if np.isinf(ref):
            assert t_star[k] == ref, k
        else:
            finite += 1
            assert t_star[k] == pytest.approx(ref, abs=1e-6), k
    assert finite > 40  # the comparison is not all +inf


def test_the_kinetostatic_margin_and_its_cue_follow_the_lps_margin(run):
    resolved, log = run
    scenario = resolved.scenario
    ceiling = float(scenario.controller.max_tension)
    floor0 = float(scenario.safety_filter.kinetostatic_floor)
    kappa = np.asarray(log["kappa"], dtype=float).reshape(-1)
    F_kin = np.asarray(log["F_kin"], dtype=float)

    def margin(p, F):
        floor = floor0 + RIPPLE * np.linalg.norm(F)  # the floor rises with the hand's ripple
        return _lp(*_statics(resolved.robot, p, F), floor=floor, ceiling=ceiling)

    # kappa: the block evaluates it where the filter's barriers are (the estimate smoothed
    # over a tick), not at the logged estimate itself: a few mN apart on this run.
    for k in np.linspace(0, kappa.size - 1, 40).astype(int):
        assert kappa[k] == pytest.approx(margin(log["p"][k], log["F_H"][k]), abs=0.05), k
    assert kappa.min() < 0.0  # the run meets the limit: the cue acts
    cue = np.flatnonzero(np.linalg.norm(F_kin, axis=1) > 0.1)
    assert cue.size > 100
    for k in cue[::40]:
        p, F = log["p"][k], log["F_H"][k]
        grad = np.array([(margin(p + 1e-4 * e, F) - margin(p - 1e-4 * e, F)) / 2e-4
                         for e in np.eye(3)])
        cos = grad @ F_kin[k] / (np.linalg.norm(grad) * np.linalg.norm(F_kin[k]))
        assert cos > 0.99, (k, cos)  # towards more margin


def test_the_filters_pair_margin_is_the_closest_pair_above_its_d_min(run):
    _, log = run
    margin = np.asarray(log["pair_margin"], dtype=float).reshape(-1)
    expected = (np.asarray(log["pair_distances"]) - np.asarray(log["d_min"])[None, :]).min(axis=1)
    np.testing.assert_allclose(margin, expected, atol=1e-6)
