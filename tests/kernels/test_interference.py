"""Cable-cable distance, its gradient, the logistic intensity and the interference force
(cdpm_drake.kernels.interference; paper sections 3.3 and 4, eqs. 8-30).

Independent references used here: hand-derived answers for the nine KKT cases; an exact
rational (fractions.Fraction) enumeration of the KKT candidates; central finite differences
and Drake's AutoDiffXd for the gradient; the paper's own eqs. 24-25 in case 1; Drake's
SceneGraph and python-fcl capsule distances (tests/kernels/test_interference_references.py).
"""

import dataclasses
import math
import warnings
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from helpers_robots import crossing_robot

from cdpm_drake.kernels.interference import (InterferenceParams, distance_gradient, initial_side,
                                     interference_force, logistic_intensity, pair_distances,
                                     segment_distance, update_side)
from cdpm_drake.robot import Robot, Workspace, load_robot

# --- references --------------------------------------------------------------------------------


def exact_min_sq(b_i, a_i, b_j, a_j):
    """Exact minimum of |C_i - C_j|^2 over [0, 1]^2 in rational arithmetic, and f(s, t).

    f is a convex quadratic, so its minimum over the box is the interior stationary point (if
    inside) or the minimum over the four edges, where it is the clamped 1-D optimum; the
    candidates are those and the four corners. Floats convert to Fractions exactly.
    """
    Bi, Ai, Bj, Aj = ([Fraction(float(x)) for x in pt] for pt in (b_i, a_i, b_j, a_j))
    u = [Ai[k] - Bi[k] for k in range(3)]
    v = [Aj[k] - Bj[k] for k in range(3)]
    w = [Bi[k] - Bj[k] for k in range(3)]

    def dot(x, y):
        return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]

    a, b, c, d, e, ww = dot(u, u), dot(u, v), dot(v, v), dot(u, w), dot(v, w), dot(w, w)

    def f(s, t):
        s, t = Fraction(s), Fraction(t)
        return a * s * s + c * t * t - 2 * b * s * t + 2 * d * s - 2 * e * t + ww

    def clamp(x):
        return min(max(x, Fraction(0)), Fraction(1))

    cands = [(s, t) for s in (0, 1) for t in (0, 1)]
    for t in (0, 1):
        if a:
            cands.append((clamp((b * t - d) / a), t))
    for s in (0, 1):
        if c:
            cands.append((s, clamp((b * s + e) / c)))
    det = a * c - b * b
    if det:
        s, t = (b * e - c * d) / det, (a * e - b * d) / det
        if 0 <= s <= 1 and 0 <= t <= 1:
            cands.append((s, t))
    return min(f(s, t) for s, t in cands), f


def paper_fig4_distance(b_i, a_i, b_j, a_j):
    """A direct transcription of the paper's Fig. 4: the nine cases of eqs. 13-21 with
    rho = B - A (eq. 1, reel to platform), keep those satisfying eq. 9, take the smallest
    |d_ij| of eq. 8. Case 1 needs the 2x2 solve of eq. 13, singular for parallel cables."""
    Bi, Ai, Bj, Aj = (np.asarray(x, dtype=float) for x in (b_i, a_i, b_j, a_j))
    ri, rj = Bi - Ai, Bj - Aj
    bij = Bi - Bj  # b_i - b_j: p cancels (B = p + b)
    cands = []
    try:
        M = np.array([[ri @ ri, -ri @ rj], [-rj @ ri, rj @ rj]])
        cands.append(tuple(np.linalg.solve(M, [ri @ bij, -rj @ bij])))
    except np.linalg.LinAlgError:
        pass
    cands += [((ri @ rj + ri @ bij) / (ri @ ri), 1.0), ((ri @ bij) / (ri @ ri), 0.0),
              (1.0, (rj @ ri - rj @ bij) / (rj @ rj)), (0.0, (-rj @ bij) / (rj @ rj)),
              (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.0, 0.0)]
    best = None
    for di, dj in cands:
        if 0.0 <= di <= 1.0 and 0.0 <= dj <= 1.0:
            dist = np.linalg.norm(di * ri - dj * rj - bij)
            if best is None or dist < best[0]:
                best = (dist, di, dj)
    return best


def paper_case1_gradient(b_i, a_i, b_j, a_j):
    """The paper's eqs. 24-25 (case 1 only), written as printed: rho_i = p + b_i - a_i."""
    Bi, Ai, Bj, Aj = (np.asarray(x, dtype=float) for x in (b_i, a_i, b_j, a_j))
    ri, rj = Bi - Ai, Bj - Aj
    bij = Bi - Bj
    M = np.array([[ri @ ri, -ri @ rj], [-rj @ ri, rj @ rj]])
    di, dj = np.linalg.solve(M, [ri @ bij, -rj @ bij])  # eq. 13
    dvec = di * ri - dj * rj - bij  # eq. 8
    dij = np.linalg.norm(dvec)
    I3 = np.eye(3)
    M6 = np.block([[ri @ ri * I3, -(ri @ rj) * I3], [-(rj @ ri) * I3, rj @ rj * I3]])
    gamma = np.concatenate([dj * (ri + rj) - 2 * di * ri + bij,
                            di * (ri + rj) - 2 * dj * rj - bij])
    dd = np.linalg.solve(M6, gamma)  # eq. 25: [d d_i / dp; d d_j / dp]
    bvec = (di**2 / dij) * ri + (dj**2 / dij) * rj - (di * dj / dij) * (ri + rj) \
        + ((dj - di) / dij) * bij
    return ((di * (ri @ ri) - dj * (ri @ rj) - bij @ ri) / dij) * dd[:3] \
        + ((dj * (rj @ rj) - di * (ri @ rj) + bij @ rj) / dij) * dd[3:] + bvec


def fd_gradient(fun, p, h=1e-6):
    """Central differences of a scalar function of p (3,)."""
    p = np.asarray(p, dtype=float)
    g = np.zeros(3)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        g[k] = (fun(p + e) - fun(p - e)) / (2 * h)
    return g


def cable_pair(p, b_i, a_i, b_j, a_j):
    """World points of two cables whose platform points move with p."""
    p = np.asarray(p, dtype=float)
    return p + b_i, np.asarray(a_i, float), p + b_j, np.asarray(a_j, float)


# --- the nine KKT cases, by hand ------------------------------------------------------------------
#
# Cable i runs along x: B_i = (0,0,0), A_i = (1,0,0), so C_i = (s, 0, 0). Cable j runs along y
# one metre above it: B_j = (x0, y0, 1), A_j = (x0, y0 + 1, 1), so C_j = (x0, y0 + t, 1) and
#   |C_i - C_j|^2 = (s - x0)^2 + (y0 + t)^2 + 1,
# separable: s* = clamp(x0, 0, 1), t* = clamp(-y0, 0, 1). x0 in {0.3 (free), 1.4 (s = 1),
# -0.4 (s = 0)} and y0 in {-0.6 (free), -1.5 (t = 1), 0.5 (t = 0)} give the nine cases.
S_FREE, T_FREE = 0.3, 0.6
KKT_CASES = {
    # case: (x0, y0, s*, t*, d*^2)
    1: (0.3, -0.6, 0.3, 0.6, 1.0),                    # eq. 13, both free
    2: (0.3, -1.5, 0.3, 1.0, 0.25 + 1.0),             # eq. 14, t = 1
    3: (0.3, 0.5, 0.3, 0.0, 0.25 + 1.0),              # eq. 15, t = 0
    4: (1.4, -0.6, 1.0, 0.6, 0.16 + 1.0),             # eq. 16, s = 1
    5: (-0.4, -0.6, 0.0, 0.6, 0.16 + 1.0),            # eq. 17, s = 0
    6: (1.4, 0.5, 1.0, 0.0, 0.16 + 0.25 + 1.0),       # eq. 18
    7: (-0.4, -1.5, 0.0, 1.0, 0.16 + 0.25 + 1.0),     # eq. 19
    8: (1.4, -1.5, 1.0, 1.0, 0.16 + 0.25 + 1.0),      # eq. 20, the two reels
    9: (-0.4, 0.5, 0.0, 0.0, 0.16 + 0.25 + 1.0),      # eq. 21, the two platform points
}


def rotation(seed):
    """A random proper rotation (QR of a Gaussian matrix, sign-fixed)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize("case", sorted(KKT_CASES))
@pytest.mark.parametrize("frame", [0, 1, 2])
def test_nine_kkt_cases_by_hand(case, frame):
    x0, y0, s_exp, t_exp, d2 = KKT_CASES[case]
    pts = np.array([[0, 0, 0], [1, 0, 0], [x0, y0, 1], [x0, y0 + 1, 1]], dtype=float)
    # Distances and parameters are invariant under rigid motions: frame 0 is the drawing,
    # frames 1, 2 a random rotation and translation of it.
    if frame:
        pts = pts @ rotation(frame).T + np.array([0.7, -2.0, 3.1]) * frame
    res = segment_distance(*pts)
    assert res.distance == pytest.approx(math.sqrt(d2), abs=1e-14)
    assert res.s == pytest.approx(s_exp, abs=1e-14)
    assert res.t == pytest.approx(t_exp, abs=1e-14)
    # Gradient: (t - s) (C_i - C_j) / d (module docstring). Here, before the rigid motion,
    # C_i - C_j = (s - x0, -(y0 + t), -1).
    diff = np.array([s_exp - x0, -(y0 + t_exp), -1.0]) / math.sqrt(d2)
    if frame:
        diff = rotation(frame) @ diff
    np.testing.assert_allclose(distance_gradient(*pts), (t_exp - s_exp) * diff, atol=1e-14)
    # Cases 8 and 9 (s == t): a translation moves both closest points alike.
    if case in (8, 9):
        assert np.all(distance_gradient(*pts) == 0.0)


@pytest.mark.parametrize("case", sorted(KKT_CASES))
def test_nine_kkt_cases_gradient_matches_central_differences(case):
    x0, y0, *_ = KKT_CASES[case]
    b_i, a_i = np.zeros(3), np.array([1.0, 0, 0])
    b_j, a_j = np.array([x0, y0, 1.0]), np.array([x0, y0 + 1, 1.0])
    g = distance_gradient(*cable_pair(np.zeros(3), b_i, a_i, b_j, a_j))
    fd = fd_gradient(lambda p: segment_distance(*cable_pair(p, b_i, a_i, b_j, a_j)).distance,
                     np.zeros(3))
    np.testing.assert_allclose(g, fd, atol=1e-8)


def test_paper_transcription_agrees_on_the_nine_cases():
    # The reference used by the benchmark is itself right where eq. 13 is regular.
    for x0, y0, s_exp, t_exp, d2 in KKT_CASES.values():
        d, di, dj = paper_fig4_distance([0, 0, 0], [1, 0, 0], [x0, y0, 1], [x0, y0 + 1, 1])
        assert d == pytest.approx(math.sqrt(d2), abs=1e-14)
        assert (di, dj) == pytest.approx((s_exp, t_exp), abs=1e-14)


# --- degenerate geometry --------------------------------------------------------------------------


DEGENERATE = {
    # name: (B_i, A_i, B_j, A_j, exact distance, why)
    "parallel, overlapping": ([0, 0, 0], [2, 0, 0], [1, 1, 0], [3, 1, 0], 1.0),
    "parallel, opposite directions": ([0, 0, 0], [2, 0, 0], [3, 1, 0], [1, 1, 0], 1.0),
    "parallel, disjoint": ([0, 0, 0], [1, 0, 0], [3, 1, 0], [4, 1, 0], math.sqrt(5.0)),
    "collinear, overlapping": ([0, 0, 0], [2, 0, 0], [1, 0, 0], [3, 0, 0], 0.0),
    "collinear, disjoint": ([0, 0, 0], [1, 0, 0], [3, 0, 0], [5, 0, 0], 2.0),
    "intersecting at interior points": ([0, 0, 0], [2, 0, 0], [1, -1, 0], [1, 1, 0], 0.0),
    "T: end on interior": ([0, 0, 0], [2, 0, 0], [1, 0, 0], [1, 3, 0], 0.0),
    "shared platform point": ([0, 0, 0], [2, 0, 0], [0, 0, 0], [0, 2, 1], 0.0),
    "reel of one on the other's platform point": ([0, 0, 0], [1, 1, 1], [1, 1, 1], [2, 0, 5],
                                                  0.0),
    "zero-length i": ([0, 0, 0], [0, 0, 0], [1, -1, 2], [1, 1, 2], math.sqrt(5.0)),
    "zero-length j, beyond the end": ([0, 0, 0], [1, 0, 0], [3, 0, 4], [3, 0, 4],
                                      math.sqrt(4 + 16.0)),
    "zero-length j, beside the middle": ([0, 0, 0], [2, 0, 0], [0.5, 3, 4], [0.5, 3, 4], 5.0),
    "both zero-length": ([1, 2, 3], [1, 2, 3], [4, 6, 3], [4, 6, 3], 5.0),
    "both zero-length, same point": ([1, 2, 3], [1, 2, 3], [1, 2, 3], [1, 2, 3], 0.0),
    "identical cables": ([0, 0, 0], [1, 2, 3], [0, 0, 0], [1, 2, 3], 0.0),
}


@pytest.mark.parametrize("name", sorted(DEGENERATE))
def test_degenerate_cases_exact_and_finite(name):
    Bi, Ai, Bj, Aj, d_exp = DEGENERATE[name]
    res = segment_distance(Bi, Ai, Bj, Aj)
    assert res.distance == pytest.approx(d_exp, abs=1e-15)
    assert 0.0 <= res.s <= 1.0 and 0.0 <= res.t <= 1.0
    # The returned (s, t) is a minimiser: its points are d apart (exact check in rationals).
    fmin, f = exact_min_sq(Bi, Ai, Bj, Aj)
    assert math.sqrt(float(f(res.s, res.t))) == pytest.approx(d_exp, abs=1e-15)
    assert math.sqrt(float(fmin)) == pytest.approx(d_exp, abs=1e-15)
    g = distance_gradient(Bi, Ai, Bj, Aj)
    assert np.all(np.isfinite(g))
    if d_exp == 0.0:  # undefined at contact: the documented zero
        assert np.all(g == 0.0)


def test_parallel_gradient_is_that_of_the_returned_minimiser():
    # Parallel overlapping cables: every s in [1, 2]/2 of cable i has a partner; the returned
    # (s, t) is one minimiser and the gradient is (t - s) n_hat there (module docstring).
    Bi, Ai, Bj, Aj = [0, 0, 0], [2, 0, 0], [1, 1, 0], [3, 1, 0]
    res = segment_distance(Bi, Ai, Bj, Aj)
    n_hat = np.array([0.0, -1.0, 0.0])
    np.testing.assert_allclose(distance_gradient(Bi, Ai, Bj, Aj), (res.t - res.s) * n_hat,
                               atol=1e-15)


@pytest.mark.parametrize("angle", [1e-3, 1e-6, 1e-9, 1e-12, 1e-15])
def test_nearly_parallel_matches_exact_rationals(angle):
    # Two 3 m cables, 2 cm apart, one tilted by `angle` rad about the normal of their plane:
    # where the Gram-matrix formula (b e - c d) / (a c - b^2) loses about half the digits,
    # the cross-product form keeps the distance exact to round-off.
    Bi, Ai = np.array([0.1, 0.2, 0.3]), np.array([3.1, 0.2, 0.3])
    Bj = np.array([0.6, 0.22, 0.3])
    Aj = Bj + 3.0 * np.array([math.cos(angle), math.sin(angle), 0.0])
    res = segment_distance(Bi, Ai, Bj, Aj)
    fmin, f = exact_min_sq(Bi, Ai, Bj, Aj)
    d_ref = math.sqrt(float(fmin))
    assert res.distance == pytest.approx(d_ref, abs=4e-16 * 4)
    assert math.sqrt(float(f(res.s, res.t))) == pytest.approx(d_ref, abs=4e-16 * 4)


def test_scalar_api_rejects_bad_points():
    with pytest.raises(ValueError, match=r"a_i must be a point \[x, y, z\] in m \(shape \(3,\)\)"):
        segment_distance([0, 0, 0], [1, 0], [0, 1, 0], [1, 1, 0])
    with pytest.raises(ValueError, match=r"b_j must have finite coordinates, got \[0, nan, 0\]"):
        distance_gradient([0, 0, 0], [1, 0, 0], [0, float("nan"), 0], [1, 1, 0])


# --- property tests against the exact rational reference -------------------------------------

SCALES = [1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3]
coords = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


def check_against_exact(pts, scale):
    res = segment_distance(*pts)
    assert np.isfinite(res.distance) and 0.0 <= res.s <= 1.0 and 0.0 <= res.t <= 1.0
    fmin, f = exact_min_sq(*pts)
    d_ref = math.sqrt(float(fmin))
    # Round-off of a difference of points of size `scale`: a few ulps of the coordinates.
    tol = 1e-14 * scale
    assert abs(res.distance - d_ref) <= tol, (res, d_ref)
    # ... and the returned parameters really achieve it.
    assert abs(math.sqrt(float(f(res.s, res.t))) - d_ref) <= tol


@settings(max_examples=150, deadline=None)
@given(st.lists(coords, min_size=12, max_size=12), st.sampled_from(SCALES))
def test_random_segments_match_exact_rationals(xs, scale):
    pts = np.array(xs).reshape(4, 3) * scale
    check_against_exact(pts, scale)


@settings(max_examples=100, deadline=None)
@given(st.lists(coords, min_size=9, max_size=9), st.sampled_from(SCALES),
       st.integers(3, 16), st.sampled_from([1.0, -1.0, 0.5]))
def test_nearly_parallel_segments_match_exact_rationals(xs, scale, digits, along):
    # Cable j is cable i's direction, scaled by `along`, tilted by 10^-digits (relative).
    Bi, u, Bj = (np.array(xs[3 * k:3 * k + 3]) * scale for k in range(3))
    if np.linalg.norm(u) < 1e-3 * scale:
        u = np.array([scale, 0.0, 0.0])
    tilt = np.cross(u, [0.3, -0.5, 0.7]) * 10.0**-digits
    pts = np.array([Bi, Bi + u, Bj, Bj + along * u + tilt])
    check_against_exact(pts, scale)


@settings(max_examples=60, deadline=None)
@given(st.lists(coords, min_size=12, max_size=12), st.sampled_from(SCALES),
       st.integers(4, 300), st.booleans())
def test_very_short_cable_matches_exact_rationals(xs, scale, digits, which):
    # One cable 10^-digits times shorter than the scene (down to below the smallest normal
    # length squared): the point-segment limit must come out, not round-off.
    pts = np.array(xs).reshape(4, 3) * scale
    k = 1 if which else 3
    pts[k] = pts[k - 1] + (pts[k] - pts[k - 1]) * 10.0**-digits
    check_against_exact(pts, scale)


@settings(max_examples=60, deadline=None)
@given(st.lists(coords, min_size=9, max_size=9), st.sampled_from(SCALES),
       st.one_of(st.sampled_from([0.0, 1.0]), st.floats(0.0, 1.0)),
       st.one_of(st.sampled_from([0.0, 1.0]), st.floats(0.0, 1.0)),
       st.sampled_from([0.0, 1.0, -1.0]))
def test_touching_and_shared_point_segments_match_exact_rationals(xs, scale, s0, t0, gap):
    # Both cables pass through (or end at) a common point X (s0, t0 = 0 or 1: a shared end
    # point), then cable j is moved by gap * 1e-12 of the scale: distance 0 or tiny.
    X, u, v = (np.array(xs[3 * k:3 * k + 3]) * scale for k in range(3))
    Bi, Bj = X - s0 * u, X - t0 * v + gap * 1e-12 * scale * np.array([0.36, -0.48, 0.8])
    pts = np.array([Bi, Bi + u, Bj, Bj + v])
    check_against_exact(pts, scale)


# --- gradient -------------------------------------------------------------------------------------


def random_cables(seed):
    """Two random cables with attachment offsets b and fixed reels a, m."""
    rng = np.random.default_rng(seed)
    return rng.normal(scale=0.2, size=3), rng.normal(size=3) * 2, \
        rng.normal(scale=0.2, size=3), rng.normal(size=3) * 2


@pytest.mark.parametrize("seed", range(12))
def test_gradient_matches_central_differences(seed):
    b_i, a_i, b_j, a_j = random_cables(seed)
    p = np.zeros(3)
    res = segment_distance(*cable_pair(p, b_i, a_i, b_j, a_j))
    fd = fd_gradient(lambda q: segment_distance(*cable_pair(q, b_i, a_i, b_j, a_j)).distance,
                     p)
    np.testing.assert_allclose(distance_gradient(*cable_pair(p, b_i, a_i, b_j, a_j)), fd,
                               atol=1e-7)
    assert res.distance > 0


def ad_distance(Bi, Ai, Bj, Aj):
    """The same minimisation written generically for Drake's AutoDiffXd (branches taken on the
    values); its derivative includes d s/dp and d t/dp, which the envelope formula drops."""
    def val(x):
        return x.value() if hasattr(x, "value") else x

    u = [Ai[k] - Bi[k] for k in range(3)]
    v = [Aj[k] - Bj[k] for k in range(3)]
    w = [Bi[k] - Bj[k] for k in range(3)]

    def dot(x, y):
        return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]

    a, b, c, d, e = dot(u, u), dot(u, v), dot(v, v), dot(u, w), dot(v, w)

    def clamp(x):
        return 0.0 if val(x) < 0 else (1.0 if val(x) > 1 else x)

    s = clamp((b * e - c * d) / (a * c - b * b))
    t = (b * s + e) / c
    if val(t) < 0:
        t, s = 0.0, clamp(-d / a)
    elif val(t) > 1:
        t, s = 1.0, clamp((b - d) / a)
    diff = [w[k] + s * u[k] - t * v[k] for k in range(3)]
    return np.sqrt(dot(diff, diff)), val(s), val(t)


@pytest.mark.parametrize("seed", range(12))
def test_gradient_matches_autodiff(seed):
    from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

    b_i, a_i, b_j, a_j = random_cables(seed)
    p_ad = InitializeAutoDiff(np.zeros(3)).ravel()
    d_ad, s, t = ad_distance(p_ad + b_i, a_i, p_ad + b_j, a_j)
    res = segment_distance(b_i, a_i, b_j, a_j)
    assert (s, t) == pytest.approx((res.s, res.t), abs=1e-12)
    g_ad = ExtractGradient(np.array([d_ad])).ravel()
    np.testing.assert_allclose(distance_gradient(b_i, a_i, b_j, a_j), g_ad, atol=1e-12)


def test_gradient_matches_paper_eqs_24_25_in_case_1():
    # Interior minimisers: the paper's formula (with d s/dp, d t/dp from eq. 25) and the
    # envelope formula (t - s) n_hat agree; the paper's is only defined in case 1.
    checked = 0
    for seed in range(60):
        b_i, a_i, b_j, a_j = random_cables(seed)
        res = segment_distance(b_i, a_i, b_j, a_j)
        if not (0.01 < res.s < 0.99 and 0.01 < res.t < 0.99):
            continue
        np.testing.assert_allclose(distance_gradient(b_i, a_i, b_j, a_j),
                                   paper_case1_gradient(b_i, a_i, b_j, a_j), atol=1e-10)
        checked += 1
    assert checked >= 5


# --- robots: pair distances ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def paper():
    return load_robot("paper_7cable")


def test_pair_distances_follow_pair_order_and_batch(paper):
    rng = np.random.default_rng(3)
    P = rng.uniform(paper.workspace.lower, paper.workspace.upper, size=(50, 3))
    D = pair_distances(paper, P)
    assert D.shape == (50, 21)
    assert paper.pairs[:3] == [(1, 2), (1, 3), (1, 4)] and paper.pairs[-1] == (6, 7)
    for n in (0, 17, 49):
        np.testing.assert_array_equal(pair_distances(paper, P[n]), D[n])
        for k, (i, j) in enumerate(paper.pairs):
            B = P[n] + paper.attachments
            ref = segment_distance(B[i - 1], paper.reels[i - 1], B[j - 1], paper.reels[j - 1])
            assert D[n, k] == pytest.approx(ref.distance, abs=1e-15)


@pytest.mark.parametrize("cable", range(1, 8))
def test_platform_at_a_reel_gives_finite_exact_values(paper, cable):
    # p + b_k = a_k: cable k has zero length (the robot path expands its products in p, so
    # its length comes out as round-off, not 0). Outputs stay finite and match the scalar API.
    p = paper.reels[cable - 1] - paper.attachments[cable - 1]
    params = InterferenceParams.uniform(paper, 0.05, 0.061, 2.0)
    res = interference_force(paper, p, params)
    for field in ("force", "distance", "s", "t", "gradient", "intensity", "direction"):
        assert np.all(np.isfinite(getattr(res, field))), field
    B = p + paper.attachments
    for k, (i, j) in enumerate(paper.pairs):
        ref = segment_distance(B[i - 1], paper.reels[i - 1], B[j - 1], paper.reels[j - 1])
        assert res.distance[k] == pytest.approx(ref.distance, abs=1e-12)


def test_pair_distances_rejects_bad_positions(paper):
    with pytest.raises(ValueError, match=r"shape \(3,\) or \(N, 3\).*\(2,\)"):
        pair_distances(paper, [1.0, 2.0])
    with pytest.raises(ValueError, match=r"must be finite, got \[1.0, inf, 1.0\]"):
        pair_distances(paper, [1.0, math.inf, 1.0])


def small_robot(attachments, reels=None, ignore_pairs=()):
    reels = reels if reels is not None else [[0, 0, 3], [4, 0, 3], [4, 3, 3], [0, 3, 3]]
    return Robot(name="shared", reels=np.array(reels, dtype=float),
                 attachments=np.array(attachments, dtype=float),
                 workspace=Workspace(np.array([1.0, 1.0, 0.5]), np.array([3.0, 2.0, 2.5])),
                 ignore_pairs=tuple(ignore_pairs))


def test_pairs_sharing_an_attachment_point_are_skipped():
    # Cables 1 and 2 end at one platform point: their distance is 0 at every pose, so the
    # interference block must not watch them. The other five pairs keep their order.
    r = small_robot([[0, 0, 0.1], [0, 0, 0.1], [0.1, 0.1, 0.1], [-0.1, 0.1, 0.1]])
    assert r.pairs == [(1, 3), (1, 4), (2, 3), (2, 4), (3, 4)]
    p = np.array([2.0, 1.5, 1.0])
    d = pair_distances(r, p)
    assert d.shape == (5,) and np.all(d > 0)
    B = p + r.attachments
    for k, (i, j) in enumerate(r.pairs):
        ref = segment_distance(B[i - 1], r.reels[i - 1], B[j - 1], r.reels[j - 1]).distance
        assert d[k] == pytest.approx(ref, abs=1e-15)
    params = InterferenceParams.uniform(r, 0.05, 0.1, 2.0)
    res = interference_force(r, p, params)
    assert res.distance.shape == (5,) and np.all(np.isfinite(res.force))


def test_ignored_pairs_are_skipped():
    r = small_robot([[-0.1, -0.1, 0.1], [0.1, -0.1, 0.1], [0.1, 0.1, 0.1], [-0.1, 0.1, 0.1]],
                    ignore_pairs=[(2, 4)])
    assert (2, 4) not in r.pairs and len(pair_distances(r, [2.0, 1.5, 1.0])) == 5


# --- logistic intensity --------------------------------------------------------------------------


def test_logistic_end_points_and_midpoint():
    # Eqs. 26-28 with the paper's example: d_l = 5 cm, d_u = 6.1 cm, F_u = 2 N, eps = 0.1 N:
    # F_u - eps at d_l, eps at d_u, F_u/2 at the band centre (the exponent is 0 there).
    d_l, d_u, F_u, eps = 0.05, 0.061, 2.0, 0.1
    a = logistic_intensity([d_l, d_u, 0.5 * (d_l + d_u)], d_l, d_u, F_u, eps)
    np.testing.assert_allclose(a, [F_u - eps, eps, F_u / 2], rtol=1e-14)
    d = np.linspace(-1.0, 1.0, 2001)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow far from the band
        a = logistic_intensity(d, d_l, d_u, F_u, eps)
    assert np.all(np.diff(a) <= 0) and a[0] == pytest.approx(F_u) and 0.0 <= a[-1] < 1e-200


@pytest.mark.parametrize("args, message", [
    ((0.06, 0.05, 2.0, 0.1), "d_u must be above d_l: got d_l = 0.06 m, d_u = 0.05 m"),
    ((-0.01, 0.05, 2.0, 0.1), "d_l must be >= 0 m, got -0.01"),
    ((0.05, 0.06, 2.0, 1.0), r"eps must lie in \(0, F_u/2\) = \(0, 1.0\) N, got 1.0"),
    ((0.05, 0.06, 0.0, 0.1), "F_u must be > 0 N, got 0.0"),
    ((0.05, math.nan, 2.0, 0.1), "d_u must be finite, got nan"),
])
def test_logistic_rejects_bad_parameters(args, message):
    with pytest.raises(ValueError, match=message):
        logistic_intensity(0.055, *args)


def test_params_errors_name_the_pair(paper):
    params = InterferenceParams.uniform(paper, 0.05, 0.061, 2.0)
    d_u = params.d_u.copy()
    d_u[paper.pair_position(3, 5)] = 0.04
    with pytest.raises(ValueError, match=r"d_u of pair \(3,5\) must be above d_l: got "
                                         r"d_l = 0.05 m, d_u = 0.04 m"):
        dataclasses.replace(params, d_u=d_u)
    with pytest.raises(ValueError, match=r"eps of pair \(1,2\) must lie in \(0, F_u/2\)"):
        InterferenceParams.uniform(paper, 0.05, 0.061, 2.0, eps=1.5)
    with pytest.raises(ValueError, match="F_max must be a finite value > 0 N, got -1"):
        InterferenceParams.uniform(paper, 0.05, 0.061, 2.0, F_max=-1)
    with pytest.raises(ValueError, match="one value per cable pair"):
        InterferenceParams(d_l=[0.05] * 21, d_u=[0.06] * 20, F_u=[2.0] * 21, eps=[0.1] * 21,
                           F_max=2.0)
    assert InterferenceParams.uniform(paper, 0.05, 0.061, [2.0] * 20 + [3.0]).F_max == 3.0


def test_params_of_another_robot_are_rejected(paper):
    cube = load_robot("cube_8cable")
    with pytest.raises(ValueError, match="interference parameters are for pairs"):
        interference_force(paper, paper.workspace.center,
                           InterferenceParams.uniform(cube, 0.05, 0.06, 2.0))


# --- the force ---------------------------------------------------------------------------------


def test_force_is_zero_when_every_pair_is_beyond_d_u(paper):
    c = paper.workspace.center
    params = InterferenceParams.uniform(paper, 0.05, 0.061, 2.0)
    res = interference_force(paper, c, params)
    assert np.all(res.distance > 0.061)  # the smallest, (2,7), is 95 mm (cdpm info)
    assert np.all(res.force == 0.0) and not res.active.any() and np.all(res.intensity == 0.0)


def test_swapped_pair_in_the_band_pushes_apart_with_the_logistic_intensity(paper):
    # Experiment 5.1: cables 1-3 swapped, p = [1.77, 3.65, 1.22], d13 = 57 mm (calibrated),
    # d_l = 5 cm, d_u = 6.1 cm, F_u = 2 N, eps = 0.1: only (1,3) is active.
    r = paper.with_swapped_attachments(1, 3)
    p = np.array([1.77, 3.65, 1.22])
    params = InterferenceParams.uniform(r, 0.05, 0.061, 2.0, 0.1)
    res = interference_force(r, p, params)
    k = r.pair_position(1, 3)
    assert res.active.tolist() == [n == k for n in range(21)]
    alpha = logistic_intensity(res.distance[k], 0.05, 0.061, 2.0, 0.1)
    assert res.intensity[k] == alpha and 0.1 < alpha < 1.9
    np.testing.assert_allclose(res.force, alpha * res.gradient[k]
                               / np.linalg.norm(res.gradient[k]), rtol=1e-14)
    # A small step along the force increases d13 (first order: |grad| * h).
    h = 1e-5
    d_after = pair_distances(r, p + h * res.force / np.linalg.norm(res.force))[k]
    assert d_after - res.distance[k] == pytest.approx(np.linalg.norm(res.gradient[k]) * h,
                                                      rel=1e-3)


@pytest.mark.parametrize("seed", range(6))
def test_every_pair_direction_increases_its_distance(seed):
    # Random platform positions of the swapped robot where pairs are close: each active,
    # uncrossed pair's direction is its ascent direction.
    paper = load_robot("paper_7cable")
    r = paper.with_swapped_attachments(1, 3).with_swapped_attachments(5, 7)
    rng = np.random.default_rng(seed)
    params = InterferenceParams.uniform(r, 0.1, 0.3, 2.0, 0.1, F_max=100.0)
    p = rng.uniform(r.workspace.lower, r.workspace.upper)
    res = interference_force(r, p, params)
    h = 1e-6
    for k in np.flatnonzero(res.active & ~res.crossed):
        dirn = res.direction[k]
        if not dirn.any():
            continue
        d_step = pair_distances(r, p + h * dirn)[k]
        assert d_step > res.distance[k], (r.pairs[k], res.distance[k], d_step)


def test_force_is_clipped_to_F_max():
    # Two pairs close to the platform, their unit pushes summing to more than F_max.
    paper = load_robot("paper_7cable")
    r = paper.with_swapped_attachments(1, 3).with_swapped_attachments(5, 7)
    p = np.array([2.22, 3.22, 1.03])
    # Experiment 5.3 (d13 = 59 mm, d57 = 61 mm, d_l = 57 mm, d_u = 62 mm, F_u = 2 N), with
    # F_max lowered to 1 N so that the sum of the two pair forces exceeds it.
    params = InterferenceParams.uniform(r, 0.057, 0.062, 2.0, 0.1, F_max=1.0)
    res = interference_force(r, p, params)
    unclipped = res.direction.T @ res.intensity
    assert res.active.sum() == 2 and np.linalg.norm(unclipped) > 1.0
    assert np.linalg.norm(res.force) == pytest.approx(1.0, rel=1e-14)
    np.testing.assert_allclose(res.force, unclipped / np.linalg.norm(unclipped), rtol=1e-14)
    assert np.linalg.norm(interference_force(r, p, dataclasses.replace(params, F_max=5.0))
                          .force) == pytest.approx(np.linalg.norm(unclipped), rel=1e-14)


def test_pair_with_zero_gradient_contributes_no_force():
    # Cables 1 and 2 start 2 cm apart and diverge: the closest points are the two platform
    # points (case 9, s = t = 0), no translation changes the distance, so there is no
    # direction: an active pair with zero force and no NaN.
    r = small_robot([[0, 0, 0.1], [0.02, 0, 0.1], [0.1, 0.1, 0.1], [-0.1, 0.1, -0.1]])
    p = np.array([2.0, 1.5, 1.0])
    params = InterferenceParams.uniform(r, 0.03, 0.05, 2.0)
    res = interference_force(r, p, params)
    k = r.pair_position(1, 2)
    assert res.s[k] == 0.0 and res.t[k] == 0.0 and res.distance[k] == pytest.approx(0.02)
    assert res.active[k] and res.intensity[k] > 1.9
    assert np.all(res.gradient[k] == 0.0) and np.all(res.direction[k] == 0.0)
    assert np.all(np.isfinite(res.force))


# --- crossing side -----------------------------------------------------------------------------


def test_side_rule_transitions():
    # (previous memory, line side, straddle, near) -> memory, per the module docstring.
    cases = [
        ((0, 1, True, True), 1),      # unknown adopts
        ((0, 0, True, True), 0),      # ... unless undefined
        ((1, 1, True, True), 1),      # same side: nothing happens
        ((1, -1, True, True), 2),     # flipped while straddling within d_u: crossed
        ((-1, 1, True, True), -2),
        ((1, -1, False, True), -1),   # flipped beyond a cable end: refreshed
        ((1, -1, True, False), -1),   # flipped farther than d_u: refreshed
        ((1, 0, True, True), 1),      # undefined (parallel, touching): kept
        ((2, -1, True, False), 2),    # crossed and far on the wrong side: held
        ((2, -1, False, False), 2),
        ((2, 0, False, False), 2),
        ((2, 1, True, True), 1),      # back on the remembered side: released
        ((-2, -1, False, False), -1),
    ]
    for (q, g, straddle, near), expected in cases:
        new, crossed = update_side(np.array([q], np.int8), np.array([g]), np.array([straddle]),
                                   np.array([near]))
        assert new.tolist() == [expected], (q, g, straddle, near)
        assert crossed.tolist() == [abs(expected) == 2]
    with pytest.raises(ValueError, match="side memory entries must be integers in -2..2"):
        update_side(np.array([3]), np.array([1]), np.array([True]), np.array([True]))
    with pytest.raises(ValueError, match="side memory entries must be integers in -2..2"):
        update_side(np.array([-3], np.int8), np.array([1]), np.array([True]), np.array([True]))
    with pytest.raises(ValueError, match=r"side memory must have shape \(21,\)"):
        paper = load_robot("paper_7cable")
        interference_force(paper, paper.workspace.center,
                            InterferenceParams.uniform(paper, 0.05, 0.06, 2.0), np.zeros(7))


def test_scripted_crossing_flags_and_pushes_back():
    r = crossing_robot()
    k = r.pair_position(1, 2)
    params = InterferenceParams.uniform(r, 0.01, 0.03, 2.0, 0.1)
    xs = np.round(np.arange(-0.2, 0.2001, 0.004), 6)
    side = initial_side(r, [xs[0], 0, 0])
    log = []
    for x in xs:
        res = interference_force(r, [x, 0.0, 0.0], params, side)
        side = res.side
        log.append((x, res.distance[k], res.crossed[k], res.force[0], res.s[k], res.t[k],
                    np.linalg.norm(res.force)))
    before = [e for e in log if e[0] < 0]
    after = [e for e in log if e[0] > 0]
    # The geometry is what the docstring says: contact at x = 0 with s = 1/2, t = 1/4.
    at0 = [e for e in log if e[0] == 0][0]
    assert at0[1] == pytest.approx(0.0, abs=1e-15) and at0[4:6] == pytest.approx((0.5, 0.25))
    assert not any(e[2] for e in before) and all(e[2] for e in after)
    # Before the crossing the active force pushes back towards -x (increasing d); after it,
    # it still pushes towards -x (back to the remembered side) at full intensity F_u, even
    # where d > d_u on the wrong side.
    assert all(e[3] < 0 for e in before if e[1] <= 0.03)
    assert all(e[3] == 0.0 for e in before if e[1] > 0.03)
    for x, d, crossed, fx, s, t, norm in after:
        # Only pair (1,2) acts: |F| = F_u = 2 N (the default F_max), pointing to -x.
        assert fx < 0 and norm == pytest.approx(2.0, rel=1e-12)
    assert any(e[1] > 0.03 for e in after)
    # Without the memory (the paper), right after the crossing the gradient pushes on, +x.
    res = interference_force(r, [0.004, 0.0, 0.0], params, side=None)
    assert res.force[0] > 0 and not res.crossed.any()
    # At the contact itself the distance gradient is undefined (zero), but a known side gives
    # the push direction: -x, finite.
    side0 = initial_side(r, [-0.01, 0, 0])
    res = interference_force(r, [0.0, 0.0, 0.0], params, side0)
    assert res.distance[k] == 0.0 and np.all(res.gradient[k] == 0.0)
    assert res.force[0] < 0 and np.all(np.isfinite(res.force))
    # Walking back releases the flag once the cables are on their side again (at the contact
    # itself, x = 0, the side is undefined and the flag is held).
    for x in xs[::-1]:
        res = interference_force(r, [x, 0.0, 0.0], params, side)
        side = res.side
        assert res.crossed[k] == (x >= 0)


def test_far_sign_change_is_not_a_crossing():
    # Same robot, but the memory says "the other side" while the cables are 10 cm apart and
    # straddling: that cannot come from a crossing this tick (d > d_u), so it is refreshed.
    r = crossing_robot()
    k = r.pair_position(1, 2)
    params = InterferenceParams.uniform(r, 0.01, 0.03, 2.0, 0.1)
    p = [-0.4, 0.0, 0.0]
    side = initial_side(r, p)
    res = interference_force(r, p, params, -side)
    assert not res.crossed[k] and res.side[k] == side[k]
