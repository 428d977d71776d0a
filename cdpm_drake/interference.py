"""Cable-cable interference: exact segment distance, its gradient, the repulsive force.

Plain numpy, no Drake import (the Drake `InterferenceForce` system is a thin wrapper). Paper
sections 3.3 and 4, eqs. 8-30. All positions are in the base frame A, in m; forces in N.

Cable i is the segment from its platform point B_i = p + b_i (parameter 0) to its reel exit
A_i = a_i (parameter 1); the paper's d_i* is `s` here and d_j* is `t`. The closest points are
C_i = B_i + s (A_i - B_i) and C_j = B_j + t (A_j - B_j).

Gradient (all nine KKT cases). Only the B points move with the platform: dC_i/dp = (1 - s) I.
The constraint box [0, 1]^2 does not depend on p, so by the envelope (Danskin) theorem, wherever
the minimiser is unique and the distance d > 0,

    grad_p d = ((1 - s) - (1 - t)) (C_i - C_j) / d = (t - s) n_hat,   n_hat = (C_i - C_j) / d.

In case 1 this equals the paper's eqs. 24-25 (tested). It is zero when s == t (cases 8, 9 and
any s = t): a translation moves both closest points alike. Where it is undefined we return:
d == 0 (cables touch; d is a cone there): the zero vector; non-unique minimiser (parallel
overlapping cables): (t - s) n_hat at the returned minimiser, one element of the generalised
gradient (the one-sided derivative along directions that keep that minimiser).

Crossing side (beyond the paper). The unsigned distance cannot tell which side of each other
two cables are on, so once they pass through each other its gradient holds them crossed. Let
m_hat = (u_i x u_j) / |u_i x u_j| (u = A - B, the cable directions) and sigma =
(B_i - B_j) . m_hat, the signed distance between the two cable LINES. Its sign `line_side` in
{-1, 0, +1} changes only when the lines meet or pass through parallel, and is 0 where undefined
(parallel cables, sin angle <= 1e-6, or lines that touch). A real crossing is a sign change of
sigma while the segments straddle each other (both closest points strictly inside their
cables, 0 < s < 1 and 0 < t < 1, so d == |sigma|); a sign change anywhere else (the lines meet
beyond a cable's end, or far away) is geometry, not a crossing. The memory is one int8 per
pair, a pure function of the previous memory and the current geometry (`update_side`), so it
fits a Drake discrete state:

    0        unknown: adopt line_side (the start assumes the cables are not crossed).
    +1 / -1  on the remembered side o.  line_side == -o: if the segments straddle and
             d <= d_u, the cables have crossed (memory becomes 2 o); otherwise (beyond an end,
             or farther than d_u) the memory is refreshed to line_side.
    +2 / -2  crossed, remembered side o = sign.  Released (back to o) only when line_side == o
             again. We prefer a spurious push back to forgetting a real tangle.
    line_side == 0 never changes the memory.

`InterferenceResult.side` is that memory (values -2..2, not only -1..1): store it and pass it
back as `side` on the next tick. A crossed pair is active at full intensity F_u, pushed along
o (t_L - s_L) m_hat, the gradient of o sigma, which points back to the remembered side (t_L,
s_L: the closest-point parameters of the two lines, equal to t, s while the segments
straddle). A pair that is not crossed follows the paper (direction grad d / |grad d|, but see
the gradient floor below); at d == 0 with a known side it uses the same side-aware direction
o (t - s) m_hat, the limit of grad d from the remembered side.

Translation bound. With t = s, C_i(s) - C_j(s) = (1 - s)(b_i - b_j) + s (a_i - a_j) does not
depend on p, so d <= g_ij, the distance from the origin to the segment [b_i - b_j, a_i - a_j]
(`translation_distance_bound`); d = g_ij on a whole plane of positions, where s = t and the
gradient vanishes. Gradient ascent of d ends on that ridge: a pair with g_ij < d_u can never
switch its force off by translating.

Gradient floor (beyond the paper). The paper pushes along the unit gradient (the equation
after eq. 25). Near the ridge s = t, |grad d| = |t - s| goes to 0, the unit direction is
ill-defined and flips sign from one tick to the next as the platform crosses the ridge: the
force chatters at full intensity instead of fading. We push along
grad d / max(|grad d|, gradient_floor) instead: the unit gradient wherever |t - s| >=
gradient_floor (the paper exactly), shrinking linearly to zero at the ridge, so the force is
continuous in p and zero where the gradient is. gradient_floor = 0 is the paper. The default
(DEFAULT_GRADIENT_FLOOR) is below |t - s| everywhere the shipped experiments are active. The
floor applies only to pairs that follow the paper's gradient: a crossed pair, and a touching
pair (d == 0) with a known side, keep their unit side-aware direction at full intensity,
because fading there would let a tangle stay in place (where that direction itself is
ill-defined, t_L = s_L, it may still flip; we accept that over losing the push-back).
"""

import dataclasses
import math
import weakref

import numpy as np

# A cable direction is "parallel" to another when sin(angle) <= this: the side is undefined.
PARALLEL_SIN = 1e-6
# |t - s| (the gradient norm, m/m) below which a pair has no direction to push along.
MIN_GRADIENT = 1e-12
# Default gradient floor (m/m, see the module docstring). The paper's robot has |t - s| =
# 0.005..0.017 where its swapped pairs are active (d <= 62 mm): 0.002 leaves the paper's force
# unchanged there (0.05 would scale it down to 10-35 %) and still spreads the fade over tens of
# centimetres of platform motion around a ridge, far more than one tick's step.
DEFAULT_GRADIENT_FLOOR = 0.002
# Smallest normal float: squared lengths at or below it are treated as zero.
_TINY = np.finfo(float).tiny


@dataclasses.dataclass(frozen=True)
class SegmentDistance:
    """Minimum distance (m) between two cables and its parameters s = d_i*, t = d_j*
    (0 at the platform point B, 1 at the reel A)."""

    distance: float
    s: float
    t: float


# --- the vectorised kernel ------------------------------------------------------------------

# Index rows for cross products of stacked (k, 3, ...) arrays: (x cross y)_r uses rows r+1, r+2.
_R1 = np.array([1, 2, 0])
_R2 = np.array([2, 0, 1])


def _kernel(u, v, w):
    """Closest points of cable i, B_i + s u, and cable j, B_j + t v (s, t in [0, 1]), with
    u = A_i - B_i, v = A_j - B_j, w = B_i - B_j; arrays of shape (3, ...), m.

    Ericson's clamped solution (Real-Time Collision Detection, 5.1.9): s0 = clamp of the line
    optimum, t = the optimum for s0, clamped, then s = the optimum for that t, clamped. It
    returns a global minimiser of the convex problem (10): (s0, t*(s0)) minimises f over the
    strip [0, 1] x R; if t*(s0) < 0, the chord from it to any box minimiser crosses t = 0 at a
    point no worse (convexity), so some minimiser has t = 0 (likewise t = 1). The nine KKT
    cases of eqs. 13-21 are the nine outcomes (interior, four edges, four corners). The line
    optimum uses cross products, s_L = ((v x w) . n) / |n|^2 with n = u x v, equal to
    (b e - c d) / (a c - b^2) by the Binet-Cauchy identity but accurate for nearly parallel
    cables, where the Gram form loses half the digits. Parallel cables (n == 0) get s0 = 0, a
    valid choice; a cable of zero length is a point; no 0/0 or overflow occurs.

    Returns (dist, s, t, diff = C_i - C_j, n = u x v, D = |n|^2, a = |u|^2, c = |v|^2) with
    diff, n of shape (3, ...) and the rest of shape (...).
    """
    Z = np.stack(np.broadcast_arrays(u, v, w))  # (3 vectors, 3 components, ...)
    Z1, Z2 = Z[:, _R1], Z[:, _R2]
    nm = Z1[:2] * Z2[1:] - Z2[:2] * Z1[1:]  # (2, 3, ...): u x v, v x w
    G = (Z[:, None] * Z[None, :2]).sum(axis=2)  # G[k, l] = Z_k . Z_l for l in (u, v)
    return _solve(G[0, 0], G[0, 1], G[1, 1], G[2, 0], G[2, 1], nm, Z[0], Z[1], Z[2])


def _solve(a, b, c, d, e, nm, u, v, w):
    """The clamped solution from the products a = u.u, b = u.v, c = v.v, d = u.w, e = v.w and
    nm = (u x v, v x w) stacked (2, 3, ...); see `_kernel`."""
    n = nm[0]
    Dn = (nm * n).sum(axis=1)  # |n|^2, (v x w) . n
    D, num = Dn[0], Dn[1]
    # Guarded reciprocals: x + (x <= TINY) is x, or ~1 where x is zero or subnormal (whose
    # reciprocal would overflow); cheaper than np.where. A cable with |u|^2 <= TINY is a point.
    c0 = c <= _TINY
    inv_a = 1.0 / (a + (a <= _TINY))
    inv_c = 1.0 / (c + c0)
    # D <= TINY: n == 0 (parallel: any s is optimal, s_L = num = 0) or |n| so small that num is
    # as negligible; s_L stays finite. Otherwise s_L may be +-inf (clamped below), never NaN.
    s_L = num / (D + (D <= _TINY))
    s = np.minimum(np.maximum(s_L, 0.0), 1.0)
    # Cable j a point (c == 0): t = -1 sends it to the edge branch, which clamps t to 0 and
    # takes the point-segment optimum for s.
    t = (b * s + e) * inv_c - c0
    tc = np.minimum(np.maximum(t, 0.0), 1.0)
    # Then s = argmin of f(., t): Ericson's edge step where t was clamped. Where it was not,
    # (s, t) is already optimal and this returns the same s in exact arithmetic, but it also
    # repairs s where the line optimum is round-off: a cable j of (nearly) zero length, whose
    # tiny n and v leave s_L and t meaningless while (b t - d) / a ~ -d / a stays exact.
    s = np.minimum(np.maximum((b * tc - d) * inv_a, 0.0), 1.0)
    diff = w + s * u - tc * v
    dist = np.sqrt((diff * diff).sum(axis=0))
    return dist, s, tc, diff, n, D, a, c


def _gradient(dist, s, t, diff):
    """(t - s) (C_i - C_j) / d, zero where d == 0; (3, ...). Dividing diff by d (never
    multiplying by 1 / d) keeps it finite for subnormal d."""
    return diff / (dist + (dist == 0.0)) * (t - s)


def _line_side(s, t, diff, n, D, a, c):
    """Sign of the line signed distance sigma = (C_i - C_j) . n / |n| (any points of the two
    lines give the same value as u, v are normal to n), 0 where the cables are parallel
    (sin angle <= PARALLEL_SIN) or the lines touch; and whether the segments straddle (both
    closest points strictly inside their cables)."""
    sigma = (diff * n).sum(axis=0)
    defined = D > (PARALLEL_SIN * PARALLEL_SIN) * a * c
    side = np.sign(sigma * defined).astype(np.int8)
    straddle = (np.minimum(s, t) > 0.0) & (np.maximum(s, t) < 1.0)
    return side, straddle


# --- scalar reference API --------------------------------------------------------------------


def _point(value, name: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a point [x, y, z] in m, got {value!r}") from None
    if arr.shape != (3,):
        raise ValueError(f"{name} must be a point [x, y, z] in m (shape (3,)), got shape "
                         f"{arr.shape}: {value!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must have finite coordinates, got {value!r}")
    return arr


def _segments(b_i, a_i, b_j, a_j):
    Bi, Ai, Bj, Aj = (_point(x, nm) for x, nm in
                      ((b_i, "b_i"), (a_i, "a_i"), (b_j, "b_j"), (a_j, "a_j")))
    return _kernel(Ai - Bi, Aj - Bj, Bi - Bj)


def segment_distance(b_i, a_i, b_j, a_j) -> SegmentDistance:
    """Minimum distance (m) between cable i, from B_i to A_i, and cable j, from B_j to A_j.

    All four are WORLD points here (B_i = p + b_i), m. s = d_i*, t = d_j* in [0, 1]. Parallel or
    collinear cables have no unique minimiser: any valid one is returned.
    """
    dist, s, t, *_ = _segments(b_i, a_i, b_j, a_j)
    return SegmentDistance(float(dist), float(s), float(t))


def distance_gradient(b_i, a_i, b_j, a_j) -> np.ndarray:
    """d(distance)/dp (3,), m/m, when the platform translates by p (both B points move).

    (t - s) (C_i - C_j) / d; zero where d == 0 and where s == t. See the module docstring for
    the value returned where the gradient is undefined.
    """
    dist, s, t, diff, *_ = _segments(b_i, a_i, b_j, a_j)
    return _gradient(dist, s, t, diff)


# --- robot-level, vectorised over pairs (and positions) -------------------------------------


def _position(p) -> np.ndarray:
    try:
        p = np.asarray(p, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"platform position p must be [x, y, z] in m, got {p!r}") from None
    if p.ndim not in (1, 2) or p.shape[-1] != 3:
        raise ValueError(f"platform position p must have shape (3,) or (N, 3) in m, got shape "
                         f"{p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"platform position p must be finite, got {p.tolist()!r}")
    return p


_GEOMETRY = weakref.WeakKeyDictionary()


class _PairGeometry:
    """Per-pair constants of a robot. Only p changes per tick: u = A_i - B_i = U - p with
    U = a_i - b_i, v = V - p with V = a_j - b_j, and w = B_i - B_j = W = b_i - b_j. The
    products the kernel needs are then polynomials in p, evaluated by two matrix products:
        (a, b, c, d, e) = K0 + K1 p + |p|^2 (1, 1, 1, 0, 0),
        u x v = U x V + (V - U) x p,   v x w = V x W + W x p.
    The cancellation is no worse than in the direct products (errors ~ eps |U| |V|)."""

    def __init__(self, robot):
        i, j = robot.pair_index
        ab = robot.reels - robot.attachments
        U, V = ab[i], ab[j]  # (P, 3)
        W = robot.attachments[i] - robot.attachments[j]
        self.P = P = len(i)
        self.pairs = tuple(robot.pairs)
        self.U, self.V, self.W = (np.ascontiguousarray(x.T) for x in (U, V, W))  # (3, P)

        def dot(x, y):
            return (x * y).sum(axis=1)

        self.K0 = np.stack([dot(U, U), dot(U, V), dot(V, V), dot(U, W), dot(V, W)])  # (5, P)
        self.K1 = np.ascontiguousarray(
            np.stack([-2 * U, -(U + V), -2 * V, -W, -W]).reshape(5 * P, 3))
        self.C0 = np.stack([np.cross(U, V).T, np.cross(V, W).T])  # (2, 3, P)
        self.UVxW = np.ascontiguousarray(np.cross(U - V, W).T)  # (u - v) x w, (3, P)
        self.C1 = np.ascontiguousarray(
            np.stack([_skew(V - U), _skew(W)]).transpose(0, 2, 1, 3).reshape(6 * P, 3))


def _skew(x):
    """(P, 3) -> (P, 3, 3) matrices with S[k] @ p = x[k] x p."""
    S = np.zeros(x.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -x[..., 2], x[..., 1]
    S[..., 1, 0], S[..., 1, 2] = x[..., 2], -x[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -x[..., 1], x[..., 0]
    return S


def _geometry(robot) -> _PairGeometry:
    g = _GEOMETRY.get(robot)
    if g is None:
        g = _GEOMETRY[robot] = _PairGeometry(robot)
    return g


def _robot_kernel(geo, p):
    """`_kernel` for every watched pair at p (3,) or (N, 3); outputs (...) = (P,) or (N, P)."""
    P = geo.P
    if p.ndim == 1:
        G = (geo.K1 @ p).reshape(5, P) + geo.K0
        G[:3] += p @ p
        nm = (geo.C1 @ p).reshape(2, 3, P) + geo.C0
        pc = p[:, None]
        return _solve(*G, nm, geo.U - pc, geo.V - pc, geo.W)
    N = p.shape[0]
    G = (p @ geo.K1.T).reshape(N, 5, P).transpose(1, 0, 2) + geo.K0[:, None, :]
    G[:3] += (p * p).sum(axis=1)[:, None]
    nm = (p @ geo.C1.T).reshape(N, 2, 3, P).transpose(1, 2, 0, 3) + geo.C0[:, :, None, :]
    pc = p.T[:, :, None]  # (3, N, 1)
    return _solve(*G, nm, geo.U[:, None, :] - pc, geo.V[:, None, :] - pc, geo.W[:, None, :])


def pair_distances(robot, p) -> np.ndarray:
    """Minimum distance (m) of every watched cable pair, in `robot.pairs` order.

    p: platform centre (3,) or a batch (N, 3), base frame, m. Returns (P,) or (N, P) with
    P = robot.num_pairs (pairs excluded by the robot description are left out).
    """
    return _robot_kernel(_geometry(robot), _position(p))[0]


def translation_distance_bound(robot) -> np.ndarray:
    """g_ij (m) per watched pair, in `robot.pairs` order: the largest distance the pair can
    reach by translating the platform, sup over p of d_ij(p).

    With t = s, C_i(s) - C_j(s) = (1 - s)(b_i - b_j) + s (a_i - a_j) does not depend on p, so
    d_ij(p) <= g_ij = min over s in [0, 1] of that norm: the distance from the origin to the
    segment [b_i - b_j, a_i - a_j]. The bound is attained: with e = that closest vector and s*
    its parameter, every p on the plane e . p = e . (a_i - b_i) has (s*, s*) as a KKT point
    of the convex problem (10) (stationary for 0 < s* < 1; for s* = 0 or 1 the two end points
    there are closest), so d_ij = g_ij and grad d = (t - s) n_hat = 0 there. Gradient ascent
    of d therefore ends on that ridge at d = g_ij: a pair whose g_ij is below its d_u can never
    leave the active band by translation. g_ij = 0: the cables meet at every position.
    """
    i, j = robot.pair_index
    W = robot.attachments[i] - robot.attachments[j]  # (P, 3), the s = 0 end
    D = (robot.reels[i] - robot.reels[j]) - W        # from the s = 0 end to the s = 1 end
    DD = (D * D).sum(axis=1)
    s = np.clip(-(W * D).sum(axis=1) / (DD + (DD <= _TINY)), 0.0, 1.0)
    e = W + s[:, None] * D
    return np.sqrt((e * e).sum(axis=1))


def initial_side(robot, p) -> np.ndarray:
    """The crossing-side memory at start (P,) int8 in {-1, 0, +1}: the sign of each pair's
    line signed distance at p (0 where undefined). Assumes no pair starts crossed."""
    p = _position(p)
    if p.ndim != 1:
        raise ValueError(f"initial_side takes one position (3,), got shape {p.shape}")
    dist, s, t, diff, n, D, a, c = _robot_kernel(_geometry(robot), p)
    return _line_side(s, t, diff, n, D, a, c)[0]


def _side_rule(q: int, line_side: int, can_cross: bool) -> int:
    """One pair's memory transition (the table in the module docstring); can_cross: the
    segments straddle each other and d <= d_u."""
    o = (q > 0) - (q < 0)
    if line_side == 0:
        return q
    if o == 0:
        return line_side
    if abs(q) == 2:  # crossed: released only by the return to the remembered side
        return o if line_side == o else q
    if line_side == o:
        return q
    return 2 * o if can_cross else line_side


# The rule tabulated at index 6 q + 2 line_side + can_cross + 14 (0..29): one gather per tick.
_SIDE_TABLE = np.array([_side_rule(q, g, bool(x)) for q in range(-2, 3) for g in (-1, 0, 1)
                        for x in (0, 1)], dtype=np.int8)


def _update_side(q, line_side, can_cross):
    # q, line_side int8 (P,), can_cross bool (P,); the index fits int8 (max 29).
    new = _SIDE_TABLE[q * 6 + line_side * 2 + can_cross + 14]
    return new, new * new == 4


def update_side(side, line_side, straddle, near):
    """The side memory after one tick (pure function; see the module docstring).

    side: previous memory (P,) int8 in {-2, -1, 0, 1, 2}; line_side: (P,) in {-1, 0, 1};
    straddle: (P,) bool, both closest points strictly inside their cables; near: (P,) bool,
    d <= d_u. Returns (new memory (P,) int8, crossed (P,) bool).
    """
    q = _side_memory(side, np.shape(side))
    g = np.asarray(line_side)
    if g.size and not np.isin(g, (-1, 0, 1)).all():
        raise ValueError(f"line_side entries must be -1, 0 or 1, got {g!r}")
    return _update_side(q, g.astype(np.int8),
                        np.asarray(straddle, dtype=bool) & np.asarray(near, dtype=bool))


def _side_memory(side, shape) -> np.ndarray:
    """A side memory as int8 of the given shape; ValueError unless its entries are integers
    in -2..2."""
    q = np.asarray(side)
    if q.shape != shape:
        raise ValueError(f"side memory must have shape {shape}, one entry per watched pair, "
                         f"got shape {q.shape}")
    if q.dtype != np.int8:
        wide = q.astype(float)
        if q.size and (not np.all(wide == np.round(wide)) or np.abs(wide).max() > 2):
            raise ValueError(f"side memory entries must be integers in -2..2, got {q!r}")
        q = q.astype(np.int8)
    elif q.size and (q.min() < -2 or q.max() > 2):
        raise ValueError(f"side memory entries must be integers in -2..2, got {q!r}")
    return q


# --- intensity and force ----------------------------------------------------------------------


def _steepness(d_l, d_u, F_u, eps):
    """Eq. 28: b (1/m, negative) and the band centre (d_u + d_l)/2 (m)."""
    return 2.0 * np.log((F_u - eps) / eps) / (d_l - d_u), 0.5 * (d_u + d_l)


def _logistic(d, F_u, b, mid):
    # Eq. 26: F_u / (1 + exp(-b (d - mid))); the exponent is capped so exp cannot overflow
    # far above the band (the value there is F_u e^-700, zero for every purpose).
    return F_u / (1.0 + np.exp(np.minimum(b * (mid - d), 700.0)))


def logistic_intensity(d, d_l, d_u, F_u, eps):
    """Interference force intensity alpha_ij (N) at distance d (m), eqs. 26-28, vectorised.

    F_u - eps at d = d_l, eps at d = d_u, decreasing, tending to F_u as d -> -inf and 0 as
    d -> inf. Requires 0 <= d_l < d_u (m) and 0 < eps < F_u / 2 (N); ValueError otherwise.
    """
    d_l, d_u, F_u, eps = (np.asarray(x, dtype=float) for x in (d_l, d_u, F_u, eps))
    _check_logistic(d_l, d_u, F_u, eps, names=None)
    return _logistic(np.asarray(d, dtype=float), F_u, *_steepness(d_l, d_u, F_u, eps))


def _check_logistic(d_l, d_u, F_u, eps, names):
    """Raise ValueError naming the first offending parameter, its pair and its value."""
    d_l, d_u, F_u, eps = (np.ravel(x) for x in np.broadcast_arrays(d_l, d_u, F_u, eps))
    scalar = d_l.size == 1

    def where(k):
        if names is not None:
            return f" of pair {names[k]}"
        return "" if scalar else f" at index {k}"

    def value(arr, k):
        return arr[k].item()  # a Python float, so the message reads 0.05, not np.float64(0.05)

    for field, arr in (("d_l", d_l), ("d_u", d_u), ("F_u", F_u), ("eps", eps)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            k = int(bad[0])
            raise ValueError(f"{field}{where(k)} must be finite, got {value(arr, k)!r}")
    checks = (
        (d_l < 0, lambda k: f"d_l{where(k)} must be >= 0 m, got {value(d_l, k)!r}"),
        (d_u <= d_l, lambda k: f"d_u{where(k)} must be above d_l: got d_l = "
                               f"{value(d_l, k)!r} m, d_u = {value(d_u, k)!r} m"),
        (F_u <= 0, lambda k: f"F_u{where(k)} must be > 0 N, got {value(F_u, k)!r}"),
        ((eps <= 0) | (eps >= F_u / 2),
         lambda k: f"eps{where(k)} must lie in (0, F_u/2) = (0, {value(F_u, k) / 2!r}) N, "
                   f"got {value(eps, k)!r}"),
    )
    for bad, message in checks:
        bad = np.flatnonzero(bad)
        if bad.size:
            raise ValueError(message(int(bad[0])))


# eq=False: the fields are arrays, whose == is elementwise (identity comparison instead).
@dataclasses.dataclass(frozen=True, eq=False)
class InterferenceParams:
    """Logistic parameters per watched pair (arrays of length robot.num_pairs, in
    `robot.pairs` order): d_l, d_u (m), F_u, eps (N); F_max (N) clips |F_int| (eq. 30).

    `pairs` (1-based (i, j) per entry) names pairs in error messages and lets
    `interference_force` check that the parameters belong to its robot; `uniform` fills it.
    `gradient_floor` (m/m, in [0, 1]; beyond the paper): an uncrossed pair pushes along
    grad d / max(|grad d|, gradient_floor), so its force fades to zero where the gradient
    vanishes instead of flipping sign; 0 is the paper's unit gradient (module docstring).
    """

    d_l: np.ndarray
    d_u: np.ndarray
    F_u: np.ndarray
    eps: np.ndarray
    F_max: float
    pairs: tuple | None = None
    gradient_floor: float = DEFAULT_GRADIENT_FLOOR

    def __post_init__(self):
        arrays = {}
        for field in ("d_l", "d_u", "F_u", "eps"):
            value = getattr(self, field)
            try:
                arr = np.array(value, dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"{field} must be numbers, one per cable pair, got "
                                 f"{value!r}") from None
            if arr.ndim != 1:
                raise ValueError(f"{field} must be a 1-D array, one value per cable pair, got "
                                 f"{value!r}")
            arrays[field] = arr
        sizes = {f: a.size for f, a in arrays.items()}
        if len(set(sizes.values())) != 1:
            raise ValueError(f"d_l, d_u, F_u, eps must have one value per cable pair; got "
                             f"lengths {sizes}")
        size = sizes["d_l"]
        pairs = None if self.pairs is None else tuple(tuple(int(k) for k in pr)
                                                      for pr in self.pairs)
        if pairs is not None and len(pairs) != size:
            raise ValueError(f"pairs lists {len(pairs)} cable pairs but d_l, d_u, F_u, eps "
                             f"have {size} values")
        names = ([f"({i},{j})" for i, j in pairs] if pairs is not None
                 else [f"at index {k}" for k in range(size)])
        _check_logistic(arrays["d_l"], arrays["d_u"], arrays["F_u"], arrays["eps"], names)
        if not (_finite(self.F_max) and float(self.F_max) > 0):
            raise ValueError(f"F_max must be a finite value > 0 N, got {self.F_max!r}")
        # |grad d| = |t - s| <= 1, so a floor above 1 would only rescale every force.
        if not (_finite(self.gradient_floor) and 0.0 <= float(self.gradient_floor) <= 1.0):
            raise ValueError(f"gradient_floor must be a number in [0, 1] (m/m; 0 = the paper's "
                             f"unit gradient), got {self.gradient_floor!r}")
        for field, arr in arrays.items():
            arr.flags.writeable = False
            object.__setattr__(self, field, arr)
        object.__setattr__(self, "F_max", float(self.F_max))
        object.__setattr__(self, "gradient_floor", float(self.gradient_floor))
        object.__setattr__(self, "pairs", pairs)
        b, mid = _steepness(arrays["d_l"], arrays["d_u"], arrays["F_u"], arrays["eps"])
        object.__setattr__(self, "_b", b)
        object.__setattr__(self, "_mid", mid)

    @classmethod
    def uniform(cls, robot, d_l, d_u, F_u, eps=0.1, F_max=None,
                gradient_floor=DEFAULT_GRADIENT_FLOOR) -> "InterferenceParams":
        """The same d_l, d_u (m), F_u, eps (N) for every watched pair of `robot`;
        F_max (N) defaults to max(F_u), as in the paper; gradient_floor (m/m) as in the
        class docstring."""
        P = robot.num_pairs
        arrays = []
        for field, x in (("d_l", d_l), ("d_u", d_u), ("F_u", F_u), ("eps", eps)):
            try:
                arrays.append(np.broadcast_to(np.asarray(x, dtype=float), (P,)).copy())
            except (TypeError, ValueError):
                raise ValueError(f"{field} must be a number or one value per cable pair "
                                 f"({P} for robot {robot.name!r}), got {x!r}") from None
        if F_max is None:
            F_max = float(np.max(arrays[2])) if P else 1.0
        return cls(*arrays, F_max=F_max, pairs=tuple(robot.pairs),
                   gradient_floor=gradient_floor)


def _finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


@dataclasses.dataclass(frozen=True, eq=False)
class InterferenceResult:
    """One tick of the interference block. Per pair arrays follow `robot.pairs`."""

    force: np.ndarray       # (3,) N, total F_int after the norm clip (eqs. 29-30)
    distance: np.ndarray    # (P,) m
    s: np.ndarray           # (P,) closest-point parameter on cable i (0 at B_i, 1 at A_i)
    t: np.ndarray           # (P,) closest-point parameter on cable j
    gradient: np.ndarray    # (P, 3) m/m, d distance / dp
    intensity: np.ndarray   # (P,) N, alpha_ij; 0 for inactive pairs
    active: np.ndarray      # (P,) bool, d <= d_u or crossed
    side: np.ndarray        # (P,) int8, updated side memory, to store for the next tick
    crossed: np.ndarray     # (P,) bool, cables crossed relative to their remembered side
    # (P, 3) push direction per pair: unit, except within the gradient floor of an uncrossed
    # pair, where it is grad d / gradient_floor (norm < 1); zero row: none. F = sum intensity
    # * direction, before the clip.
    direction: np.ndarray


def interference_force(robot, p, params: InterferenceParams, side=None) -> InterferenceResult:
    """The interference force F_int (N) at platform position p (3,), base frame, m.

    Active pairs (d <= d_u) push with the logistic intensity (eq. 26) along the distance
    gradient divided by max(|gradient|, params.gradient_floor) (eq. 29 when the floor is 0:
    the unit gradient); crossed pairs push back to their remembered side at F_u along a unit
    direction, never floored. The sum (eq. 30) is clipped to norm F_max. `side` is the memory
    returned by the previous tick (None: `initial_side(robot, p)`).
    """
    geo = _geometry(robot)
    P, pairs = geo.P, geo.pairs
    if params.d_l.size != P or (params.pairs is not None and params.pairs != pairs):
        raise ValueError(f"interference parameters are for pairs "
                         f"{params.pairs if params.pairs is not None else params.d_l.size} "
                         f"but robot {robot.name!r} watches {list(pairs)}")
    p = _position(p)
    if p.ndim != 1:
        raise ValueError(f"interference_force takes one position (3,), got shape {p.shape}")
    dist, s, t, diff, n, D, a, c = _robot_kernel(geo, p)
    line_side, straddle = _line_side(s, t, diff, n, D, a, c)
    near = dist <= params.d_u
    q = line_side if side is None else _side_memory(side, (P,))
    new_side, crossed = _update_side(q, line_side, straddle & near)

    ts = t - s
    pos = dist > 0.0
    # n_hat = (C_i - C_j) / d: |diff_k| <= d, so this cannot overflow even for subnormal d
    # (a reciprocal 1 / d could); at d == 0 it is diff itself, i.e. zero.
    n_hat = diff / (dist + ~pos)
    grad = n_hat * ts
    floor = params.gradient_floor
    if floor > 0.0:
        # |grad| = |t - s|: grad / max(|grad|, floor) = n_hat (t - s) / max(|t - s|, floor),
        # continuous in p and exactly zero where t == s (no division by |grad|).
        direction = n_hat * (ts / np.maximum(np.abs(ts), floor))
    else:
        # The paper: the unit direction sign(t - s) n_hat.
        direction = n_hat * (np.sign(ts) * (np.abs(ts) > MIN_GRADIENT))
    intensity = _logistic(dist, params.F_u, params._b, params._mid) * near
    use_side = crossed | (straddle & ~pos)
    if use_side.any():
        # Gradient of o sigma: o (t_L - s_L) m_hat, with t_L - s_L = ((u - v) x w) . n / |n|^2
        # (t_L, s_L: the two lines' closest points); u - v = U - V and w = W do not depend on
        # p, so (u - v) x w is a per-pair constant and only its sign against n matters here.
        g = np.sign(new_side) * (geo.UVxW * n).sum(axis=0)
        has_n = D > 0.0
        m_hat = n / (np.sqrt(D) + ~has_n)
        toward = m_hat * (np.sign(g) * (np.abs(g) > MIN_GRADIENT * D))
        direction = np.where(use_side, toward, direction)
        intensity = np.where(crossed, params.F_u, intensity)
    force = direction @ intensity
    fn = math.sqrt(force[0] * force[0] + force[1] * force[1] + force[2] * force[2])
    if fn > params.F_max:
        force *= params.F_max / fn
    return InterferenceResult(force=force, distance=dist, s=s, t=t, gradient=grad.T,
                              intensity=intensity, active=near | crossed, side=new_side,
                              crossed=crossed, direction=direction.T)
