"""The translation bound g_ij of a cable pair and the gradient floor of the interference force
(cdpm_drake.kernels.interference; beyond the paper, follow-up of issue 4).

References: g by exact rational arithmetic (the 1-D quadratic min over s of
|(1 - s)(b_i - b_j) + s (a_i - a_j)|^2, clamped, in fractions.Fraction); the distance itself by
brute force over random platform positions; closed forms worked out in the comments.
"""

import dataclasses
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from cdpm_drake.kernels import interference as itf
from cdpm_drake.kernels.interference import (InterferenceParams, initial_side, interference_force,
                                     pair_distances, translation_distance_bound)
from cdpm_drake.robot import Robot, Workspace, load_robot


def exact_bound(b_i, a_i, b_j, a_j) -> float:
    """min over s in [0, 1] of |W + s D|, W = b_i - b_j, D = (a_i - a_j) - W, in exact
    rationals (a convex quadratic in s: the clamped stationary point)."""
    W = [Fraction(float(x)) - Fraction(float(y)) for x, y in zip(b_i, b_j)]
    A = [Fraction(float(x)) - Fraction(float(y)) for x, y in zip(a_i, a_j)]
    D = [a - w for a, w in zip(A, W)]
    DD = sum(d * d for d in D)
    s = Fraction(0) if DD == 0 else min(max(-sum(w * d for w, d in zip(W, D)) / DD, 0), 1)
    return math.sqrt(float(sum((w + s * d) ** 2 for w, d in zip(W, D))))


def ridge_points(robot, k, rng, n, spread=5.0):
    """n random platform positions on the plane e . p = e . (a_i - b_i) of pair k, where e is
    the vector achieving g (derivation in translation_distance_bound's docstring: there
    (s*, s*) satisfies the KKT conditions, so d = g)."""
    i, j = (x[k] for x in robot.pair_index)
    W = robot.attachments[i] - robot.attachments[j]
    D = robot.reels[i] - robot.reels[j] - W
    s = min(max(-(W @ D) / (D @ D), 0.0), 1.0)
    e = W + s * D
    c = e @ (robot.reels[i] - robot.attachments[i])
    P = robot.workspace.center + rng.uniform(-spread, spread, (n, 3))
    return P - ((P @ e - c) / (e @ e))[:, None] * e


def three_cable_robot(b1, a1, b2, a2, name="pair"):
    """Cables 1 and 2 as given (platform frame b, base frame a, m); cable 3 far from both."""
    return Robot(name=name, reels=np.array([a1, a2, [50.0, 50.0, 50.0]], dtype=float),
                 attachments=np.array([b1, b2, [0.0, 0.0, -7.0]], dtype=float),
                 workspace=Workspace(np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])))


# --- translation_distance_bound ---------------------------------------------------------------


@pytest.mark.parametrize("b1, a1, b2, a2, expected", [
    # W = b1 - b2 = (0, 0.1, 0), A = a1 - a2 = (0, -0.1, 2): the segment [W, A] passes the
    # origin at distance |W x A| / |A - W| = |(0.2, 0, 0)| / sqrt(0.2^2 + 2^2) (interior
    # s* = 0.02 / 4.04).
    ([0, 0.05, 0], [0, 0, 2], [0, -0.05, 0], [0, 0.1, 0], 0.2 / math.sqrt(4.04)),
    # W = (0, 0, 0.1), A = (0, 0, 2): the segment points away from the origin, s* = 0,
    # g = |W| = 0.1 (the platform points are the closest pair at best).
    ([0, 0, 0.05], [1, 0, 3], [0, 0, -0.05], [1, 0, 1], 0.1),
    # W = (0, 0, -0.1), A = (0, 0, 2): the segment passes through the origin (s* = 1/21),
    # the points at the same fraction of both cables coincide at every p: g = 0.
    ([0, 0, -0.05], [1, 0, 3], [0, 0, 0.05], [1, 0, 1], 0.0),
    # W = (0.3, 0, 0), A = (0.2, 0, 0): s* = 1, g = |a_1 - a_2| = 0.2 (parallel cables
    # converging towards the reels).
    ([0.15, 0, 0], [0.1, 0, 3], [-0.15, 0, 0], [-0.1, 0, 3], 0.2),
])
def test_translation_bound_closed_forms(b1, a1, b2, a2, expected):
    r = three_cable_robot(b1, a1, b2, a2)
    g = translation_distance_bound(r)
    assert g.shape == (3,) and r.pairs[0] == (1, 2)
    assert g[0] == pytest.approx(expected, abs=1e-15)
    assert g[0] == pytest.approx(exact_bound(b1, a1, b2, a2), abs=1e-16)
    # Reached: on the ridge plane (interior s* and s* at either end alike); for g = 0 the
    # plane is everything (e = 0): the cables meet at every platform position.
    rng = np.random.default_rng(0)
    P = (ridge_points(r, 0, rng, 50, spread=1.0) if expected > 0
         else rng.uniform(-1.0, 1.0, (50, 3)))
    np.testing.assert_allclose(pair_distances(r, P)[:, 0], expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize("swaps", [(), ((1, 3),), ((1, 3), (5, 7))])
def test_translation_bound_is_the_sup_of_the_distance(swaps):
    # Brute force: no platform position, in the workspace or metres outside it, beats g; and
    # g is attained (so it is the sup, not only a bound) on the ridge plane of every pair.
    r = load_robot("paper_7cable")
    for i, j in swaps:
        r = r.with_swapped_attachments(i, j)
    g = translation_distance_bound(r)
    assert g.shape == (r.num_pairs,)
    rng = np.random.default_rng(len(swaps))
    for spread in (1.0, 10.0, 1e3):
        P = r.workspace.center + rng.uniform(-spread, spread, (4000, 3))
        assert np.all(pair_distances(r, P) <= g + 1e-12)
    for k in range(r.num_pairs):
        d = pair_distances(r, ridge_points(r, k, rng, 200))[:, k]
        np.testing.assert_allclose(d, g[k], rtol=0, atol=1e-12)
    # Each g equals the exact rational minimum.
    i, j = r.pair_index
    for k in range(r.num_pairs):
        ref = exact_bound(r.attachments[i[k]], r.reels[i[k]], r.attachments[j[k]],
                          r.reels[j[k]])
        assert g[k] == pytest.approx(ref, rel=1e-15, abs=1e-17)


coords = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(st.lists(coords, min_size=15, max_size=15),
       st.sampled_from([1e-3, 1e-1, 1.0, 1e1, 1e3]))
def test_translation_bound_random_pairs(xs, scale):
    # Random cable pairs at scales 1e-3..1e3 m: g matches exact rationals, no random p
    # beats it, and it is reached on the ridge plane (to round-off of coordinates ~ scale).
    pts = np.array(xs).reshape(5, 3) * scale
    b1, a1, b2, a2, p0 = pts
    assume(np.linalg.norm(b1 - b2) > 1e-6 * scale and np.linalg.norm(a1 - a2) > 1e-6 * scale)
    r = three_cable_robot(b1, 10 * a1, b2, 10 * a2)
    g = translation_distance_bound(r)[0]
    ref = exact_bound(b1, 10 * a1, b2, 10 * a2)
    assert g == pytest.approx(ref, rel=1e-14, abs=1e-15 * scale)
    rng = np.random.default_rng(0)
    P = p0 + rng.uniform(-20 * scale, 20 * scale, (300, 3))
    tol = 1e-13 * scale
    assert np.all(pair_distances(r, P)[:, 0] <= g + tol)
    # On the ridge points of size ~ spread, products lose ~ eps * spread^2 / d: keep it near.
    d = pair_distances(r, ridge_points(r, 0, rng, 20, spread=2 * scale))[:, 0]
    np.testing.assert_allclose(d, g, rtol=1e-9, atol=1e-9 * scale)


# --- the gradient floor -------------------------------------------------------------------------

H = 0.05  # m, offset of the ridge robot's cables


def ridge_robot():
    """Cables 1 and 2 form a symmetric X offset by H in y; at p = 0 they are on their ridge.

    Cable 1 runs from B1 = p + (-1, 0, 0) to A1 = (1, 0, 2), cable 2 from B2 = p + (1, H, 0) to
    A2 = (-1, H, 2): at p = 0 both pass x = 0, z = 1 at their midpoints, so s = t = 1/2 exactly
    (all products are small integers), d = H and grad d = (t - s) n_hat = 0. The bound is
    g = H as well (W = (-2, -H, 0), A = (2, -H, 0), s* = 1/2, e = (0, -H, 0)), reached on the
    ridge plane e . p = e . (a_1 - b_1), i.e. p_y = 0. Cable 3 stays far away.
    """
    return three_cable_robot([-1, 0, 0], [1, 0, 2], [1, H, 0], [-1, H, 2], name="ridge")


def ridge_params(robot, floor):
    # d = 50 mm is the centre of the band (d_l 40 mm, d_u 60 mm): intensity F_u / 2 = 1 N
    # (eq. 26, the exponent is zero there).
    return InterferenceParams.uniform(robot, 0.04, 0.06, 2.0, 0.1, gradient_floor=floor)


def test_force_is_zero_on_the_ridge_without_nan():
    r = ridge_robot()
    k = r.pair_position(1, 2)
    assert translation_distance_bound(r)[k] == pytest.approx(H, abs=1e-16)
    for floor in (itf.DEFAULT_GRADIENT_FLOOR, 0.05, 0.0):
        res = interference_force(r, np.zeros(3), ridge_params(r, floor))
        assert res.s[k] == 0.5 and res.t[k] == 0.5 and res.distance[k] == pytest.approx(H)
        assert res.active[k] and res.intensity[k] == pytest.approx(1.0, rel=1e-12)
        # No direction: zero force, whether the floor is on or not (paper: t == s exactly).
        assert np.all(res.direction[k] == 0.0) and np.all(res.force == 0.0)
        assert all(np.all(np.isfinite(getattr(res, f))) for f in ("force", "direction",
                                                                  "gradient"))


def test_floored_force_is_continuous_across_the_ridge_and_the_paper_chatters():
    # Crossing the ridge plane p_y = 0 along y: t - s changes sign. The paper's unit direction
    # jumps from +n to -n (full intensity on both sides: the chatter); the floored one
    # shrinks linearly: |F| <= intensity * |t - s| / floor.
    r = ridge_robot()
    k = r.pair_position(1, 2)
    floor = 0.05
    ys = np.array([-1e-2, -1e-3, -1e-5, 1e-5, 1e-3, 1e-2])
    paper, floored = [], []
    for y in ys:
        p = np.array([0.0, y, 0.0])
        rp = interference_force(r, p, ridge_params(r, 0.0))
        rf = interference_force(r, p, ridge_params(r, floor))
        ts = rf.t[k] - rf.s[k]
        assert 0 < abs(ts) < floor
        np.testing.assert_allclose(rf.direction[k], rf.gradient[k] / floor, rtol=1e-14)
        assert np.linalg.norm(rf.force) == pytest.approx(rf.intensity[k] * abs(ts) / floor,
                                                         rel=1e-12)
        assert np.linalg.norm(rp.force) == pytest.approx(rp.intensity[k], rel=1e-12)
        paper.append(rp.force)
        floored.append(rf.force)
    paper, floored = np.array(paper), np.array(floored)
    # Paper: the two sides closest to the ridge (y = -+1e-5) push in opposite directions at
    # full intensity, a jump of about 2 alpha for a 20 um step.
    assert paper[2] @ paper[3] < -0.99 * np.linalg.norm(paper[2]) * np.linalg.norm(paper[3])
    # Floored: |F| proportional to |y| near the ridge (t - s is smooth in p, linear at
    # first order), i.e. Lipschitz with L = |F(1 cm)| / 1 cm: the 20 um step across the ridge
    # changes F by 20 um * L, where the paper's jumps by 2 alpha.
    norms = np.linalg.norm(floored, axis=1)
    assert norms[2] / norms[0] == pytest.approx(1e-3, rel=1e-2)
    assert norms[1] / norms[0] == pytest.approx(1e-1, rel=1e-2)
    lipschitz = norms[0] / 1e-2
    assert np.linalg.norm(floored[3] - floored[2]) <= 1.01 * 2e-5 * lipschitz
    assert np.linalg.norm(paper[3] - paper[2]) == pytest.approx(2.0, rel=1e-6)  # 2 alpha


def test_floor_zero_is_the_paper_and_the_default_keeps_the_paper_in_the_band():
    # Random positions of the swapped paper robot: with gradient_floor = 0 every uncrossed
    # pair's direction is the unit gradient, eq. after 25 (and zero where the gradient is
    # zero); with any floor, pairs whose |grad| >= floor get bit-for-bit the same direction.
    paper = load_robot("paper_7cable")
    r = paper.with_swapped_attachments(1, 3).with_swapped_attachments(5, 7)
    rng = np.random.default_rng(3)
    P = rng.uniform(r.workspace.lower, r.workspace.upper, (40, 3))
    for p in P:
        p0 = interference_force(r, p, InterferenceParams.uniform(r, 0.1, 0.4, 2.0, 0.1,
                                                                   gradient_floor=0.0))
        norm = np.linalg.norm(p0.gradient, axis=1)
        uncrossed = ~p0.crossed
        unit = np.where(norm[:, None] > 0, p0.gradient / np.where(norm > 0, norm, 1)[:, None],
                        0.0)
        np.testing.assert_allclose(p0.direction[uncrossed], unit[uncrossed], rtol=0,
                                   atol=1e-15)
        for floor in (0.002, 0.02):
            pf = interference_force(r, p, InterferenceParams.uniform(
                r, 0.1, 0.4, 2.0, 0.1, gradient_floor=floor))
            above = norm >= floor
            np.testing.assert_array_equal(pf.direction[above], p0.direction[above])
            below = ~above & uncrossed
            np.testing.assert_allclose(pf.direction[below], p0.gradient[below] / floor,
                                       rtol=1e-14, atol=1e-18)
    # The paper's experiments: at every reported position |grad| of the interfering pairs is
    # above the default floor, so the default force is exactly the paper's.
    for swaps, p in (([(1, 3)], [1.77, 3.65, 1.22]), ([(1, 3)], [1.56, 3.24, 1.22]),
                     ([(1, 3)], [1.87, 3.68, 0.53]), ([(1, 3)], [1.30, 3.68, 1.05]),
                     ([(1, 3), (5, 7)], [2.22, 3.22, 1.03])):
        rs = paper
        for i, j in swaps:
            rs = rs.with_swapped_attachments(i, j)
        default = interference_force(rs, p, InterferenceParams.uniform(rs, 0.057, 0.062, 2.0))
        exact = interference_force(rs, p, InterferenceParams.uniform(rs, 0.057, 0.062, 2.0,
                                                                     gradient_floor=0.0))
        assert default.active.any()
        np.testing.assert_array_equal(default.force, exact.force)


def test_floor_never_weakens_a_crossed_pair():
    # The scripted crossing of test_interference.py (cables cross at x = 0, s = 1/2,
    # t = 1/4), with the largest floor allowed: before the crossing the pair's push is
    # scaled by |t - s| / 1 < 1, after it the pair pushes back at full F_u = 2 N.
    from helpers_robots import crossing_robot

    r = crossing_robot()
    k = r.pair_position(1, 2)
    params = InterferenceParams.uniform(r, 0.01, 0.03, 2.0, 0.1, gradient_floor=1.0)
    side = initial_side(r, [-0.2, 0.0, 0.0])
    for x in np.round(np.arange(-0.02, 0.0201, 0.004), 6):
        res = interference_force(r, [x, 0.0, 0.0], params, side)
        side = res.side
        norm = np.linalg.norm(res.force)
        if x < 0 and res.active[k]:
            assert norm == pytest.approx(res.intensity[k] * abs(res.t[k] - res.s[k]),
                                         rel=1e-12)
            assert norm < 0.5 * res.intensity[k]
        if x > 0:
            assert res.crossed[k] and res.force[0] < 0
            assert norm == pytest.approx(2.0, rel=1e-12)
    # Touching (d == 0) with a known side: the side-aware unit direction, not floored.
    res = interference_force(r, [0.0, 0.0, 0.0], params, initial_side(r, [-0.01, 0, 0]))
    assert res.distance[k] == 0.0 and np.linalg.norm(res.direction[k]) == pytest.approx(1.0)


@pytest.mark.parametrize("value", [-0.01, 1.5, math.nan, "big"])
def test_gradient_floor_is_checked(value):
    r = ridge_robot()
    with pytest.raises(ValueError, match=rf"gradient_floor must be a number in \[0, 1\].*"
                                         rf"got {value!r}"):
        InterferenceParams.uniform(r, 0.04, 0.06, 2.0, gradient_floor=value)
    params = InterferenceParams.uniform(r, 0.04, 0.06, 2.0)
    assert params.gradient_floor == itf.DEFAULT_GRADIENT_FLOOR
    assert dataclasses.replace(params, gradient_floor=0).gradient_floor == 0.0
