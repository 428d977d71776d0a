"""Cable-cable interference: exact segment distance, its gradient, the repulsive force.

numpy and numba, no Drake import (the Drake `InterferenceForce` block calls `interference_tick`). Paper
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

import numba
import numpy as np

# A cable direction is "parallel" to another when sin(angle) <= this: the side is undefined.
PARALLEL_SIN = 1e-6
# |t - s| (the gradient norm, m/m) below which a pair has no direction to push along.
MIN_GRADIENT = 1e-12
# Default gradient floor (m/m, see the module docstring). The paper's robot has |t - s| =
# 0.005..0.016 where its swapped pairs are active in the shipped experiments (re-measured for
# the attachment points of issue 18): 0.002 leaves the paper's force unchanged there (0.05
# would scale it down to 10-32 %) and still spreads the fade over tens of centimetres of
# platform motion around a ridge, far more than one tick's step.
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


# --- the compiled kernel ----------------------------------------------------------------------
# One implementation, numba-compiled once (cached next to this module, or in numba's user cache
# when that is read-only), serves the scalar API, the batch calls and the control loop's tick.
# error_model="numpy": a float division by zero gives inf/nan as numpy does, never an exception.

_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def closest_points(ux, uy, uz, vx, vy, vz, wx, wy, wz):
    """Closest points of cable i, B_i + s u, and cable j, B_j + t v (s, t in [0, 1]), with
    u = A_i - B_i, v = A_j - B_j, w = B_i - B_j (m).

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

    Returns (dist, s, t, diff = C_i - C_j (3 floats), n = u x v (3 floats), D = |n|^2,
    a = |u|^2, c = |v|^2).
    """
    a = ux * ux + uy * uy + uz * uz
    b = ux * vx + uy * vy + uz * vz
    c = vx * vx + vy * vy + vz * vz
    d = ux * wx + uy * wy + uz * wz
    e = vx * wx + vy * wy + vz * wz
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    mx, my, mz = vy * wz - vz * wy, vz * wx - vx * wz, vx * wy - vy * wx  # v x w
    D = nx * nx + ny * ny + nz * nz
    num = mx * nx + my * ny + mz * nz
    # Guarded reciprocals: x + (x <= TINY) is x, or ~1 where x is zero or subnormal (whose
    # reciprocal would overflow). A cable with |u|^2 <= TINY is a point.
    c0 = 1.0 if c <= _TINY else 0.0
    inv_a = 1.0 / (a + (1.0 if a <= _TINY else 0.0))
    inv_c = 1.0 / (c + c0)
    # D <= TINY: n == 0 (parallel: any s is optimal, s_L = num = 0) or |n| so small that num is
    # as negligible; s_L stays finite. Otherwise s_L may be +-inf (clamped below), never NaN.
    s_L = num / (D + (1.0 if D <= _TINY else 0.0))
    s = min(max(s_L, 0.0), 1.0)
    # Cable j a point (c == 0): t = -1 sends it to the edge branch, which clamps t to 0 and
    # takes the point-segment optimum for s.
    t = min(max((b * s + e) * inv_c - c0, 0.0), 1.0)
    # Then s = argmin of f(., t): Ericson's edge step where t was clamped. Where it was not,
    # (s, t) is already optimal and this returns the same s in exact arithmetic, but it also
    # repairs s where the line optimum is round-off: a cable j of (nearly) zero length, whose
    # tiny n and v leave s_L and t meaningless while (b t - d) / a ~ -d / a stays exact.
    s = min(max((b * t - d) * inv_a, 0.0), 1.0)
    dx, dy, dz = wx + s * ux - t * vx, wy + s * uy - t * vy, wz + s * uz - t * vz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    return dist, s, t, dx, dy, dz, nx, ny, nz, D, a, c


@_jit
def _sign(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@_jit
def _line_side(dx, dy, dz, nx, ny, nz, D, a, c):
    """Sign of the line signed distance sigma = (C_i - C_j) . n / |n| (any points of the two
    lines give the same value as u, v are normal to n), 0 where the cables are parallel
    (sin angle <= PARALLEL_SIN) or the lines touch."""
    if not D > (PARALLEL_SIN * PARALLEL_SIN) * a * c:
        return 0
    sigma = dx * nx + dy * ny + dz * nz
    return 1 if sigma > 0.0 else (-1 if sigma < 0.0 else 0)


@_jit
def _side_rule(q, line_side, can_cross):
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


@_jit
def _segment_kernel(u, v, w, out):
    """`closest_points` for one pair of WORLD segments: out (13,) = dist, s, t, the gradient
    (t - s) (C_i - C_j) / d (3; zero where d == 0), C_i - C_j (3), n (3), side."""
    dist, s, t, dx, dy, dz, nx, ny, nz, D, a, c = closest_points(
        u[0], u[1], u[2], v[0], v[1], v[2], w[0], w[1], w[2])
    # Dividing diff by d (never multiplying by 1 / d) keeps it finite for subnormal d.
    k = t - s
    den = dist + (1.0 if dist == 0.0 else 0.0)
    out[0], out[1], out[2] = dist, s, t
    out[3], out[4], out[5] = dx / den * k, dy / den * k, dz / den * k
    out[6], out[7], out[8] = dx, dy, dz
    out[9], out[10], out[11] = nx, ny, nz
    out[12] = _line_side(dx, dy, dz, nx, ny, nz, D, a, c)


@_jit
def pairs_kernel(geo, p, dist_out, side_out):
    """Distances (N, P) and line sides (N, P) of every watched pair at each row of p (N, 3).
    geo (P, 12): per pair U = a_i - b_i, V = a_j - b_j, W = b_i - b_j, (U - V) x W; only p
    moves: u = U - p, v = V - p, w = W."""
    for k in range(p.shape[0]):
        px, py, pz = p[k, 0], p[k, 1], p[k, 2]
        for j in range(geo.shape[0]):
            g = geo[j]
            dist, s, t, dx, dy, dz, nx, ny, nz, D, a, c = closest_points(
                g[0] - px, g[1] - py, g[2] - pz, g[3] - px, g[4] - py, g[5] - pz,
                g[6], g[7], g[8])
            dist_out[k, j] = dist
            side_out[k, j] = _line_side(dx, dy, dz, nx, ny, nz, D, a, c)


# Offsets of the fields in `interference_tick`'s flat output of 3 + 13 P floats; the Drake
# block exports the first five as its ports.
def result_layout(P: int) -> dict:
    """{field: (start, stop)} in the flat result vector of a robot with P watched pairs."""
    sizes = (("force", 3), ("distance", P), ("active", P), ("crossed", P), ("side", P),
             ("s", P), ("t", P), ("intensity", P), ("gradient", 3 * P),
             ("direction", 3 * P))
    out, k = {}, 0
    for name, n in sizes:
        out[name] = (k, k + n)
        k += n
    return out


@_jit
def interference_tick(geo, par, floor, F_max, p, side, has_side, out):
    """One tick of the interference block at p (3,): writes the flat result (see
    `result_layout`) into out (3 + 13 P,). par (P, 4): d_u, F_u, b, mid per pair; side (P,)
    float: the previous memory (ignored unless has_side: then each pair adopts its line
    side)."""
    P = geo.shape[0]
    o_d, o_act, o_cr, o_side = 3, 3 + P, 3 + 2 * P, 3 + 3 * P
    o_s, o_t, o_int, o_grad, o_dir = 3 + 4 * P, 3 + 5 * P, 3 + 6 * P, 3 + 7 * P, 3 + 10 * P
    px, py, pz = p[0], p[1], p[2]
    fx = fy = fz = 0.0
    for j in range(P):
        g = geo[j]
        dist, s, t, dx, dy, dz, nx, ny, nz, D, a, c = closest_points(
            g[0] - px, g[1] - py, g[2] - pz, g[3] - px, g[4] - py, g[5] - pz,
            g[6], g[7], g[8])
        line_side = _line_side(dx, dy, dz, nx, ny, nz, D, a, c)
        straddle = min(s, t) > 0.0 and max(s, t) < 1.0
        near = dist <= par[j, 0]
        q = int(side[j]) if has_side else line_side
        new_side = _side_rule(q, line_side, straddle and near)
        crossed = new_side * new_side == 4
        ts = t - s
        pos = dist > 0.0
        # n_hat = (C_i - C_j) / d: |diff_k| <= d, so this cannot overflow even for subnormal
        # d (a reciprocal 1 / d could); at d == 0 it is diff itself, i.e. zero.
        den = dist + (0.0 if pos else 1.0)
        hx, hy, hz = dx / den, dy / den, dz / den
        if floor > 0.0:
            # grad / max(|grad|, floor) = n_hat (t - s) / max(|t - s|, floor): continuous in
            # p and exactly zero where t == s (no division by |grad|).
            k = ts / max(abs(ts), floor)
        else:  # the paper: the unit direction sign(t - s) n_hat
            k = _sign(ts) if abs(ts) > MIN_GRADIENT else 0.0
        ex, ey, ez = hx * k, hy * k, hz * k
        F_u = par[j, 1]
        intensity = _logistic(dist, F_u, par[j, 2], par[j, 3])
        if not near:
            intensity = 0.0
        if crossed or (straddle and not pos):
            # Gradient of o sigma: o (t_L - s_L) m_hat, t_L - s_L = ((u - v) x w) . n / |n|^2;
            # (u - v) x w = (U - V) x W does not depend on p: only its sign against n matters.
            gs = _sign(new_side) * (g[9] * nx + g[10] * ny + g[11] * nz)
            dn = math.sqrt(D) + (0.0 if D > 0.0 else 1.0)
            k = _sign(gs) if abs(gs) > MIN_GRADIENT * D else 0.0
            ex, ey, ez = nx / dn * k, ny / dn * k, nz / dn * k
            if crossed:
                intensity = F_u
        fx += ex * intensity
        fy += ey * intensity
        fz += ez * intensity
        out[o_d + j] = dist
        out[o_act + j] = 1.0 if (near or crossed) else 0.0
        out[o_cr + j] = 1.0 if crossed else 0.0
        out[o_side + j] = new_side
        out[o_s + j] = s
        out[o_t + j] = t
        out[o_int + j] = intensity
        out[o_grad + 3 * j], out[o_grad + 3 * j + 1], out[o_grad + 3 * j + 2] = (
            hx * ts, hy * ts, hz * ts)
        out[o_dir + 3 * j], out[o_dir + 3 * j + 1], out[o_dir + 3 * j + 2] = ex, ey, ez
    fn = math.sqrt(fx * fx + fy * fy + fz * fz)
    if fn > F_max:
        k = F_max / fn
        fx, fy, fz = fx * k, fy * k, fz * k
    out[0], out[1], out[2] = fx, fy, fz


@_jit
def interference_tick_stacked(geo, par, floor, F_max, x, out):
    """`interference_tick` on one stacked input x (3 + P,) = [p, previous side memory]."""
    interference_tick(geo, par, floor, F_max, x[:3], x[3:], True, out)


@_jit
def _update_side_kernel(q, line_side, can_cross, out):
    for k in range(q.shape[0]):
        out[k] = _side_rule(int(q[k]), int(line_side[k]), can_cross[k])


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
    out = np.empty(13)
    _segment_kernel(Ai - Bi, Aj - Bj, Bi - Bj, out)
    return out


def segment_distance(b_i, a_i, b_j, a_j) -> SegmentDistance:
    """Minimum distance (m) between cable i, from B_i to A_i, and cable j, from B_j to A_j.

    All four are WORLD points here (B_i = p + b_i), m. s = d_i*, t = d_j* in [0, 1]. Parallel or
    collinear cables have no unique minimiser: any valid one is returned.
    """
    out = _segments(b_i, a_i, b_j, a_j)
    return SegmentDistance(float(out[0]), float(out[1]), float(out[2]))


def distance_gradient(b_i, a_i, b_j, a_j) -> np.ndarray:
    """d(distance)/dp (3,), m/m, when the platform translates by p (both B points move).

    (t - s) (C_i - C_j) / d; zero where d == 0 and where s == t. See the module docstring for
    the value returned where the gradient is undefined.
    """
    return _segments(b_i, a_i, b_j, a_j)[3:6].copy()


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


def pair_geometry(robot) -> np.ndarray:
    """Per-pair constants of a robot, (P, 12) in `robot.pairs` order: U = a_i - b_i,
    V = a_j - b_j, W = b_i - b_j and (U - V) x W. Only p changes per tick: u = A_i - B_i =
    U - p, v = V - p, w = B_i - B_j = W. Computed once per robot."""
    g = _GEOMETRY.get(robot)
    if g is None:
        i, j = robot.pair_index
        ab = robot.reels - robot.attachments
        U, V = ab[i], ab[j]  # (P, 3)
        W = robot.attachments[i] - robot.attachments[j]
        g = np.ascontiguousarray(np.hstack([U, V, W, np.cross(U - V, W)]).reshape(len(i), 12))
        g.flags.writeable = False
        _GEOMETRY[robot] = g
    return g


def _pairs_at(robot, p):
    """(distances, line sides) of every watched pair at p (3,) or (N, 3)."""
    geo = pair_geometry(robot)
    q = np.ascontiguousarray(np.atleast_2d(p))
    dist = np.empty((q.shape[0], geo.shape[0]))
    side = np.empty((q.shape[0], geo.shape[0]), dtype=np.int8)
    pairs_kernel(geo, q, dist, side)
    return (dist[0], side[0]) if p.ndim == 1 else (dist, side)


def pair_distances(robot, p) -> np.ndarray:
    """Minimum distance (m) of every watched cable pair, in `robot.pairs` order.

    p: platform centre (3,) or a batch (N, 3), base frame, m. Returns (P,) or (N, P) with
    P = robot.num_pairs (pairs excluded by the robot description are left out).
    """
    return _pairs_at(robot, _position(p))[0]


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


@_jit
def _posed_pairs_kernel(reels, attachments, pi, pj, p, R, near, dist_out, crossed_out):
    """Every pair's distance (N, P) and crossed flag (N, P) along a sequence of platform
    poses p (N, 3), R (N, 3, 3): cable i from p + R b_i to a_i. The crossing-side memory
    runs along the sequence with the controller's rule (`_side_rule`), a crossing counting
    where the line side flips while the segments straddle and d <= near (P,) m."""
    m, P = attachments.shape[0], pi.shape[0]
    side = np.zeros(P, dtype=np.int64)  # unknown: the first pose adopts the line sides
    B = np.empty((m, 3))
    for k in range(p.shape[0]):
        for i in range(m):
            for r in range(3):
                B[i, r] = p[k, r] + (R[k, r, 0] * attachments[i, 0]
                                     + R[k, r, 1] * attachments[i, 1]
                                     + R[k, r, 2] * attachments[i, 2])
        for q in range(P):
            i, j = pi[q], pj[q]
            dist, s, t, dx, dy, dz, nx, ny, nz, D, a, c = closest_points(
                reels[i, 0] - B[i, 0], reels[i, 1] - B[i, 1], reels[i, 2] - B[i, 2],
                reels[j, 0] - B[j, 0], reels[j, 1] - B[j, 1], reels[j, 2] - B[j, 2],
                B[i, 0] - B[j, 0], B[i, 1] - B[j, 1], B[i, 2] - B[j, 2])
            line = _line_side(dx, dy, dz, nx, ny, nz, D, a, c)
            straddle = 0.0 < s < 1.0 and 0.0 < t < 1.0
            side[q] = _side_rule(side[q], line, straddle and dist <= near[q])
            dist_out[k, q] = dist
            crossed_out[k, q] = side[q] * side[q] == 4


def posed_pair_distances(robot, p, R, near=None) -> tuple[np.ndarray, np.ndarray]:
    """The cable-cable distances of a platform that also rotates: every watched pair (in
    `robot.pairs` order) at each pose of a sequence, cable i running from p + R b_i to a_i.
    p (N, 3) m and R (N, 3, 3) (R_WB, base frame) in time order. Returns (distances (N, P) m,
    crossed (N, P) bool), crossed by the controller's crossing rule (module docstring)
    applied along the sequence from an uncrossed start, counting a side flip while the
    segments straddle and d <= near (P,) m (default: any distance). What the dynamic plant's
    true pose says, beside the controller's translating estimate."""
    p = np.ascontiguousarray(np.asarray(p, dtype=float).reshape(-1, 3))
    R = np.ascontiguousarray(np.asarray(R, dtype=float).reshape(-1, 3, 3))
    if R.shape[0] != p.shape[0]:
        raise ValueError(f"posed_pair_distances: {p.shape[0]} positions but {R.shape[0]} "
                         "rotations")
    i, j = robot.pair_index
    P = len(i)
    near = np.full(P, np.inf) if near is None else np.asarray(near, dtype=float).reshape(P)
    dist = np.empty((p.shape[0], P))
    crossed = np.zeros((p.shape[0], P), dtype=np.bool_)
    _posed_pairs_kernel(np.ascontiguousarray(robot.reels, dtype=float),
                        np.ascontiguousarray(robot.attachments, dtype=float),
                        np.ascontiguousarray(i, dtype=np.int64),
                        np.ascontiguousarray(j, dtype=np.int64), p, R,
                        np.ascontiguousarray(near), dist, crossed)
    return dist, crossed


def initial_side(robot, p) -> np.ndarray:
    """The crossing-side memory at start (P,) int8 in {-1, 0, +1}: the sign of each pair's
    line signed distance at p (0 where undefined). Assumes no pair starts crossed."""
    p = _position(p)
    if p.ndim != 1:
        raise ValueError(f"initial_side takes one position (3,), got shape {p.shape}")
    return _pairs_at(robot, p)[1]


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
    new = np.empty(q.shape, dtype=np.int8)
    _update_side_kernel(q, g.astype(np.int8),
                        np.asarray(straddle, dtype=bool) & np.asarray(near, dtype=bool), new)
    return new, new * new == 4


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


@_jit
def _logistic(d, F_u, b, mid):
    # Eq. 26: F_u / (1 + exp(-b (d - mid))); the exponent is capped so exp cannot overflow
    # far above the band (the value there is F_u e^-700, zero for every purpose).
    return F_u / (1.0 + math.exp(min(b * (mid - d), 700.0)))


@_jit
def _logistic_many(d, F_u, b, mid, out):
    for k in range(d.shape[0]):
        out[k] = _logistic(d[k], F_u[k], b[k], mid[k])


def logistic_intensity(d, d_l, d_u, F_u, eps):
    """Interference force intensity alpha_ij (N) at distance d (m), eqs. 26-28, vectorised.

    F_u - eps at d = d_l, eps at d = d_u, decreasing, tending to F_u as d -> -inf and 0 as
    d -> inf. Requires 0 <= d_l < d_u (m) and 0 < eps < F_u / 2 (N); ValueError otherwise.
    """
    d_l, d_u, F_u, eps = (np.asarray(x, dtype=float) for x in (d_l, d_u, F_u, eps))
    _check_logistic(d_l, d_u, F_u, eps, names=None)
    b, mid = _steepness(d_l, d_u, F_u, eps)
    d, F_u, b, mid = np.broadcast_arrays(np.asarray(d, dtype=float), F_u, b, mid)
    out = np.empty(d.shape)
    _logistic_many(*(np.ascontiguousarray(x).reshape(-1) for x in (d, F_u, b, mid)),
                   out.reshape(-1))
    return out if out.ndim else float(out)


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
        # (P, 4) d_u, F_u, b, mid per pair: what the compiled tick reads.
        packed = np.ascontiguousarray(np.column_stack([arrays["d_u"], arrays["F_u"], b, mid]))
        packed.flags.writeable = False
        object.__setattr__(self, "packed", packed)

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
    geo = pair_geometry(robot)
    P, pairs = geo.shape[0], tuple(robot.pairs)
    if params.d_l.size != P or (params.pairs is not None and params.pairs != pairs):
        raise ValueError(f"interference parameters are for pairs "
                         f"{params.pairs if params.pairs is not None else params.d_l.size} "
                         f"but robot {robot.name!r} watches {list(pairs)}")
    p = _position(p)
    if p.ndim != 1:
        raise ValueError(f"interference_force takes one position (3,), got shape {p.shape}")
    q = np.zeros(P) if side is None else _side_memory(side, (P,)).astype(float)
    out = np.empty(3 + 13 * P)
    interference_tick(geo, params.packed, params.gradient_floor, params.F_max, p, q,
                         side is not None, out)
    f = {name: out[a:b] for name, (a, b) in result_layout(P).items()}
    return InterferenceResult(
        force=f["force"], distance=f["distance"], s=f["s"], t=f["t"],
        gradient=f["gradient"].reshape(P, 3), intensity=f["intensity"],
        active=f["active"] > 0.5, side=f["side"].astype(np.int8), crossed=f["crossed"] > 0.5,
        direction=f["direction"].reshape(P, 3))
