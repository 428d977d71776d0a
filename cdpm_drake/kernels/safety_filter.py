"""The safety filter (beyond the paper): every tick, the twist closest to the one the
admittance and the limits command, subject to discrete-time control barrier functions that
keep every watched cable pair apart, the platform in its workspace box and the cables able to
hold it with the measured hand force. numpy and numba, no Drake.

The paper's interference force is soft: a hand that pushes harder than F_u drags the cables
across each other (its section 5.4). On an admittance-controlled robot the controller decides
every motion, so it can refuse the ones that break the promise. Base frame A, SI units. The
unknown is the twist u = (v, w) (m/s, rad/s; the translating controller: v alone):

    minimise  |v - v_d|^2 + |w - w_d|^2
    subject to, for each barrier h (h >= 0 is safe),
        grad_v h . v >= -rate(h)        (h(x + T u) >= h(x) - T rate(h), linearised)
        |v| <= v_max,  |v - v_prev| <= a_max T   (cutting planes, exact to 1e-9)

with rate(h) = min(gamma h / T, g cap(h / g)): at most the fraction gamma of the margin per
tick (the discrete-time CBF h(x + T u) >= (1 - gamma) h(x)), and no faster than a braking at
a_brake would stop the platform at the barrier (cap: limits.face_cap, the virtual wall's
braking curve, on the platform distance h / g to the barrier, g = |grad_v h|), so that a
barrier never asks for more than the acceleration limit. Where h < 0 (a margin already lost:
a start inside d_min, a hand force that changed) the barrier asks for a slow return instead,
grad h . u >= min(gamma |h| / T, g v_return). A barrier that jumps (an estimate that moves
with the platform's ringing, a hand force that changes the kinetostatic margin) would ask for
a step of the command: each row asks at most 0.9 g a_max T more than the previous command
gave it, so that a jump is met by braking near the acceleration limit, not by a jerk.

The barriers: every watched pair's distance above its d_min (signed: a pair the interference
block has seen cross counts negative; the gradient by the envelope theorem,
`pair_barrier`); each face of the workspace box; the kinetostatic margin kappa >= 0
(kinetostatics.py: a tension distribution between the floor and the ceiling holds the
platform's weight and the measured hand force), with its gradient from the kinetostatic
block.

When no twist meets them all, the filter gives up in this order, and says which in its status:
on a robot with mass the cap on the speed regained after a brake (`regain_cap`; status
unchanged), the returns of lost margins (each then only must not get worse, grad h . u >= 0:
STATUS_NO_RETURN), and then it holds the platform (STATUS_HOLD), braking to zero twist at the
acceleration limit. The acceleration limit is never given up: a step of the command is a jerk
of the platform, which on a robot with mass slackens cables (measured: a barrier met by a 0.2
m/s step in one tick slackened four cables of the dynamic plant).

The barriers are evaluated at the commanded pose: the estimated position and, for the full
pose, the orientation the orientation hold keeps (R_ref), not the estimated one. The estimate
of the orientation moves with the platform's ringing (its yaw mode rings at ~4 Hz, lightly
damped, and a pair's distance moves ~0.1 m per rad of tilt against ~0.01 m per m of
translation near the paper's boundary): barriers at the estimated orientation fed that ringing
back into the velocity command and rang it up until cables went slack (dynamic plant, an 8 N
push along the boundary: 275-326 slack ticks, against none at R_ref). At the commanded
orientation the barriers depend on the translation alone: the full pose's twist (6 unknowns)
keeps the orientation hold's angular velocity, which corrects towards R_ref and never moves
it.
"""

import math

import numba
import numpy as np

from cdpm_drake.kernels.interference import closest_points
from cdpm_drake.kernels.safety_limits import face_cap
from cdpm_drake.kernels.qp import QP_OPTIMAL, qp_scratch, solve_qp_in

_jit = numba.njit(cache=True, error_model="numpy")

# status output of `filter_tick`.
STATUS_PASS, STATUS_MODIFIED, STATUS_NO_RETURN, STATUS_HOLD = 0, 1, 2, 3
STATUS_TEXT = ("passed", "modified", "lost margins held, not restored",
               "braking to a hold (no safe twist)")
# Which kinds of barrier bind (have a positive multiplier) at the filter's solution: bits of
# the `binding` output.
BIND_PAIR, BIND_BOX, BIND_KINETOSTATIC, BIND_SPEED, BIND_ACCELERATION = 1, 2, 4, 8, 16
BIND_TEXT = ((BIND_PAIR, "cable pairs"), (BIND_BOX, "workspace box"),
             (BIND_KINETOSTATIC, "kinetostatic limit"), (BIND_SPEED, "speed limit"),
             (BIND_ACCELERATION, "acceleration limit"))

# Parameters (a flat array, `filter_params`).
(F_T, F_GAMMA, F_A_BRAKE, F_V_MAX, F_A_MAX, F_V_RETURN, F_DOF, F_KINETOSTATIC, F_BOX,
 F_SMOOTHING, F_CABLE_BRAKE, F_GIVE_WAY, F_SIZE) = range(13)
# Where `filter_tick`'s memory and its pass-through of v_d start in its output; the memory
# is [p_c (3), p_c valid (1), v_prev (3), w_prev (3), a_prev (3: the last command's
# acceleration, m/s^2)].
OUT_MEMORY, OUT_V_D, MEMORY = 11, 24, 13
# The memory's first BARRIER_STATE values, [p_c, valid, v_prev]: what `barrier_position`
# reads, and what the kinetostatic block takes (its input barrier_state_previous).
BARRIER_STATE = 7

# At most this many cutting planes of the speed and acceleration balls per solve: each cuts
# the violation of the last solution; 12 leave it below 1e-9 m/s in every case measured.
MAX_CUTS = 12
# The share of the acceleration limit a barrier's demand may grow by in a tick.
RAMP_SHARE = 0.9
# While a margin is lost by more than LOST_DEPTH of the platform's travel (m), the speed
# (m/s) is capped: from max_velocity at LOST_DEPTH down to LOST_SPEED at twice that depth.
LOST_SPEED = 0.05
LOST_DEPTH = 0.001
# The braking curve of a barrier assumes this share of a_brake, the ramp allows all of it:
# the curve is exact only for a barrier whose gradient does not change, and a pair's does as
# the closest points slide along the cables (a 5 N push on crossing_4cable overshot its d_min
# by 0.125 mm on the full curve).
CURVE_SHARE = 0.5
BALL_TOL = 1e-9


def filter_params(*, time_step, gamma, a_brake, max_velocity, max_acceleration,
                  return_speed, full_pose, kinetostatic, box: bool = True,
                  smoothing: float = 0.0, cable_brake: float | None = None,
                  give_way: float = math.inf) -> np.ndarray:
    """The filter's parameters: s, -, m/s^2, m/s, m/s^2, m/s; the full pose (a twist of 6)
    or not (3); the kinetostatic barrier on; the box's barriers on (off with the virtual
    wall: limits.virtual_wall false lets the platform leave the box); the time constant (s)
    of the position the barriers are evaluated at (`barrier_position`; 0: the estimate); the
    cable brake (m/s^2): the most the filter decelerates for the kinetostatic limit (its rows'
    ramps) and while a margin is lost (the slowdown) (None: RAMP_SHARE of max_acceleration;
    a robot with mass: a_brake, which its cables take without ringing; filter_tick says why);
    give_way (m/s^3): how fast the brakes for the cables may change the platform's
    acceleration (`give_way_ramp`; inf: at once, as on ideal reels)."""
    if cable_brake is None:
        cable_brake = RAMP_SHARE * max_acceleration
    return np.array([time_step, gamma, a_brake, max_velocity, max_acceleration,
                     return_speed, 6 if full_pose else 3, 1.0 if kinetostatic else 0.0,
                     1.0 if box else 0.0, smoothing, cable_brake, give_way], dtype=float)


def give_way_rate(cable_brake: float, lead: float) -> float:
    """How fast (m/s^3) the filter's brakes for the cables may change the platform's
    acceleration: the cable brake once per lag of the tension path (tension_path.lead_time),
    inf without one. A step of the acceleration by da changes the cables' force by m da at
    once, and the tension command, which takes the acceleration in, follows it only after
    that lag: a step from the hand's acceleration (the admittance under a fast hand: 2 m/s^2)
    to braking rang the weak cable slack (`give_way_ramp`)."""
    return cable_brake / lead if lead > 0.0 else math.inf


@_jit
def give_way_ramp(previous, rate, brake, T):
    """The most (m/s^2) a brake for the cables (the kinetostatic limit's rows, the lost-margin
    slowdown) may decelerate the platform along a direction this tick: the cable brake, and
    no more than `rate` T beyond the deceleration along it at the last tick (`previous`, m/s^2;
    negative where the platform was accelerating along it). Where the hand accelerates the
    platform faster than the tension path follows (a hand that takes the kinetostatic margin
    away), the filter gives way: the platform yields to the hand, its acceleration taken down
    at `rate`, instead of a step from accelerating to braking, which the cables take as a
    step of m da and ring (exp3's 40 N push across 1-3 at 100 N/s on the dynamic plant: the
    slowdown's step from +1.8 to -0.5 m/s^2 took cable 2 ~4 N below its command, slack for 7
    ticks where the statics held the hand)."""
    return min(brake, previous + rate * T)


@_jit
def regain_cap(prev, a_prev, rate, T):
    """The most speed (m/s) the command may have this tick on a robot with mass: the last
    command's speed (prev, m/s), grown by its acceleration along itself (a_prev, m/s^2; none
    where it was slowing) plus at most `rate` T more (rate: the give-way rate, m/s^3).

    Why: the brakes for the cables come on at the give-way rate (give_way_ramp), but they
    came off at once. Where a hand held the platform at the kinetostatic limit (exp2's
    40 N lift, no tension sensor), the lost-margin slowdown switched on and off as the
    margin hovered about LOST_DEPTH: the platform slowed at the cable brake, then the
    command stepped to the acceleration limit (steps of 1.7-2.5 m/s^2 in a tick, ~5 times
    a second), which rang cable 5 at the platform's ~12 Hz from 0 to 15 N, slack where the
    statics held the hand. So the acceleration along the motion comes back no faster than
    the brakes come on; a brake may still end at once (to no acceleration), which asks the
    cables for its own size only. It never asks the platform to slow down (the cap is at
    least the last speed), so it cannot make a brake or a barrier harder. filter_tick caps
    the speed so only while a margin is lost (h < 0, by any depth), where the slowdown
    switches: everywhere, a hand's step at t = 0 was met by a slower start and slackened
    more (exp2's 40 N across 1-3: 233 holdable slack ticks for 189)."""
    speed = math.sqrt(prev[0] * prev[0] + prev[1] * prev[1] + prev[2] * prev[2])
    along = -_slowing(prev, speed, a_prev) if speed > 0.0 else 0.0
    return speed + (max(along, 0.0) + rate * T) * T


@_jit
def _slowing(prev, speed, a_prev):
    """The deceleration (m/s^2) along the last command prev (its translation, speed m/s > 0)
    at the last tick, a_prev its acceleration: what `give_way_ramp` gives way from."""
    slowing = 0.0
    for c in range(3):
        slowing -= prev[c] / speed * a_prev[c]
    return slowing


def filter_sizes(P: int, full_pose: bool) -> dict:
    """Input (x) and output (out) sizes of `filter_tick` for P watched pairs, and the offset
    of its memory in x."""
    x = 11 + P + (12 if full_pose else 0)
    return {"x": x + MEMORY, "out": OUT_V_D + 3, "memory": MEMORY, "memory_at": x}


def filter_scratch(P: int, full_pose: bool):
    """`filter_tick`'s work arrays for P watched pairs, its QP's included, as two flat
    buffers (floats, integers) its block allocates once: a tick allocates nothing."""
    n = 6 if full_pose else 3
    rows = _rows(P)
    qf, qi = qp_scratch(rows, n)
    floats = 3 + 9 + 2 * n + 3 * rows + rows * n + 6 + 3 + n
    return (np.zeros(floats + qf.size), np.zeros(2 * rows + qi.size, dtype=np.int64))


@_jit
def _rows(P):
    """The most rows filter_tick's QP has: a barrier per pair, per box face, the kinetostatic
    limit and its look ahead, and the cutting planes."""
    return P + 6 + 2 + 2 * MAX_CUTS


@_jit
def barrier_position(p, memory, T, tau, out):
    """The position the barriers are evaluated at, into out (3, m): the last one advanced by
    the last command (p_c + T v_prev, where the commands put the platform) and drawn towards
    the estimate p with the time constant tau (s; p itself when 0, or on the first tick:
    memory[3] == 0). memory: the filter's [p_c (3), valid (1), v_prev (3), ...]. The
    kinetostatic block calls it on the same memory, so its margin is at the same position."""
    if tau <= 0.0 or memory[3] == 0.0:
        for c in range(3):
            out[c] = p[c]
        return
    k = min(1.0, T / tau)
    for c in range(3):
        ahead = memory[c] + T * memory[4 + c]
        out[c] = ahead + k * (p[c] - ahead)


@_jit
def pair_barrier(reels, attachments, i, j, p, R, grad):
    """The distance (m) between cables i and j of the pose (p, R) and its gradient with
    respect to the twist (v, w) into grad (6,): by the envelope theorem only the attachment
    points move, dB = v + w x R b, and d d = (1 - s) n . dB_i - (1 - t) n . dB_j with n the
    unit vector between the closest points (interference.py's module docstring; (t - s) n for
    the translation). Zero gradient where the cables touch (d == 0)."""
    for r in range(3):
        Rbi = Rbj = 0.0
        for c in range(3):
            Rbi += R[r, c] * attachments[i, c]
            Rbj += R[r, c] * attachments[j, c]
        grad[r] = Rbi  # R b_i, R b_j kept in grad's slots until the end
        grad[3 + r] = Rbj
    # The attachment points B = p + R b (scalars: no work array a call).
    bi0, bi1, bi2 = p[0] + grad[0], p[1] + grad[1], p[2] + grad[2]
    bj0, bj1, bj2 = p[0] + grad[3], p[1] + grad[4], p[2] + grad[5]
    dist, s, t, dx, dy, dz, _, _, _, _, _, _ = closest_points(
        reels[i, 0] - bi0, reels[i, 1] - bi1, reels[i, 2] - bi2,
        reels[j, 0] - bj0, reels[j, 1] - bj1, reels[j, 2] - bj2,
        bi0 - bj0, bi1 - bj1, bi2 - bj2)
    if dist == 0.0:
        for k in range(6):
            grad[k] = 0.0
        return dist
    nx, ny, nz = dx / dist, dy / dist, dz / dist
    ai, aj = 1.0 - s, 1.0 - t
    rix, riy, riz = grad[0], grad[1], grad[2]
    rjx, rjy, rjz = grad[3], grad[4], grad[5]
    k = ai - aj
    grad[0], grad[1], grad[2] = k * nx, k * ny, k * nz
    # w . (R b_i x (1 - s) n) - w . (R b_j x (1 - t) n)
    grad[3] = ai * (riy * nz - riz * ny) - aj * (rjy * nz - rjz * ny)
    grad[4] = ai * (riz * nx - rix * nz) - aj * (rjz * nx - rjx * nz)
    grad[5] = ai * (rix * ny - riy * nx) - aj * (rjx * ny - rjy * nx)
    return dist


@_jit
def barrier_rate(h, g, params):
    """rate(h) (units of h per s; module docstring): the largest decrease of a barrier at
    margin h >= 0 with |grad_v h| = g, or minus the return asked where h < 0."""
    T, gamma = params[F_T], params[F_GAMMA]
    if h < 0.0:
        back = gamma * (-h) / T
        if g > 0.0:
            back = min(back, g * params[F_V_RETURN])
        return -back
    rate = gamma * h / T
    if g > 0.0:
        rate = min(rate, g * face_cap(h / g, CURVE_SHARE * params[F_A_BRAKE], T))
    return rate


@_jit
def _add_row(C, d, kind, count, grad, n, rhs, k):
    for c in range(n):
        C[count, c] = grad[c]
    d[count] = rhs
    kind[count] = k
    return count + 1


@_jit
def _add_barrier(C, d, kind, lost, lost_by, count, grad, n, rhs, h, h_next, k, prev, ramp, T):
    """A barrier's row on the translation, grad_v . v >= rhs, asking at most `ramp` more
    than the previous command gave it (module docstring), but never letting a margin h >= 0
    go in one tick (h_next: the margin after a tick at the previous command; as the virtual
    wall's cap wins over the acceleration limit)."""
    lost[count] = h < 0.0
    trans = g2 = 0.0
    for c in range(3):
        trans += grad[c] * prev[c]
        g2 += grad[c] * grad[c]
    # How far the margin is lost in the platform's travel (-h / |grad_v h|, m; 0 where it is
    # not): beyond LOST_DEPTH not a tick's round-off at the barrier but a margin really gone.
    if h >= 0.0:
        lost_by[count] = 0.0
    elif g2 > 0.0:
        lost_by[count] = -h / math.sqrt(g2)
    else:
        lost_by[count] = math.inf
    for c in range(3, 6):
        grad[c] = 0.0
    rhs = min(rhs, trans + ramp)
    if h >= 0.0 and h_next >= 0.0:
        rhs = max(rhs, trans - h_next / T)
    return _add_row(C, d, kind, count, grad, n, rhs, k)


@_jit
def filter_tick(reels, attachments, pi, pj, d_min, bounds, params, scratch, x, out):
    """One tick of the safety filter. pi, pj (P,): the watched pairs (0-based cables); d_min
    (P,) m; bounds (2, 3): the workspace box's lower and upper corners, m; scratch:
    `filter_scratch(P, full pose)`, the block's work arrays.
    x = [v_d (3), p (3), crossed (P), kappa (1), grad kappa (3), look ahead (1), (the full
    pose only:) w_d (3), R (9), memory: p_c (3), p_c valid (1), v_prev (3), w_prev (3),
    a_prev (3)] (m/s, m, 0/1, N, N/m, m, rad/s, -, m, -, m/s, rad/s, m/s^2); the translating
    controller's platform is level (R = I); the barriers are evaluated at `barrier_position`;
    out = [v (3), w (3), status (1), binding (1), smallest pair margin h (1, m; +inf with
    no pair), kappa used (1, N; nan when the barrier is off or undefined), barriers (1: how
    many could bind this tick and went into the QP), next memory (MEMORY, at OUT_MEMORY), v_d
    (3: the velocity asked for, passed through for the log, at OUT_V_D)]. Returns the
    status."""
    P = pi.shape[0]
    n = int(params[F_DOF])
    T = params[F_T]
    v_max, a_max = params[F_V_MAX], params[F_A_MAX]
    memory = x[x.shape[0] - MEMORY:]
    rows = _rows(P)
    floats, ints = scratch
    p, R, target, w = floats[0:3], floats[3:12].reshape((3, 3)), floats[12:12 + n], \
        floats[12 + n:12 + 2 * n]
    o = 12 + 2 * n
    d, lost_by, u = floats[o:o + rows], floats[o + rows:o + 2 * rows], \
        floats[o + 2 * rows:o + 3 * rows]
    o += 3 * rows
    C = floats[o:o + rows * n].reshape((rows, n))
    o += rows * n
    grad, ahead, z = floats[o:o + 6], floats[o + 6:o + 9], floats[o + 9:o + 9 + n]
    o += 9 + n
    kind, lost = ints[:rows], ints[rows:2 * rows]
    qp_work = (floats[o:], ints[2 * rows:])
    barrier_position(x[3:6], memory, T, params[F_SMOOTHING], p)
    crossed = x[6:6 + P]
    kappa = x[6 + P]
    gk = x[7 + P:10 + P]
    ray = x[10 + P]
    for a in range(3):
        for b in range(3):
            R[a, b] = 1.0 if a == b else 0.0
    for c in range(n):
        w[c] = 1.0
    for c in range(3):
        target[c] = x[c]
    if n == 6:
        for c in range(3):
            target[3 + c] = x[11 + P + c]
        for a in range(3):
            for b in range(3):
                R[a, b] = x[14 + P + 3 * a + b]
    prev = memory[4:10]
    for r in range(rows):
        for c in range(n):
            C[r, c] = 0.0
        lost[r] = 0  # a barrier whose margin is already lost (h < 0)
        lost_by[r] = 0.0  # ... by how much of the platform's travel, m
    count = 0
    # A barrier may ask its rate to change by at most RAMP_SHARE a_max T a tick (per unit of
    # its translation gradient): feasible within the acceleration limit (all of it would make
    # the row tangent to the acceleration ball, a single point the cutting planes miss), and
    # about as much as the command asked for may change in a tick (the admittance's command
    # is limited to a_max T too). A smaller ramp (a_brake) let a hand that pushes into a
    # barrier accelerate the approach faster than the filter could take it back, and the
    # command cycled between braking and re-accelerating at ~15 Hz (10 N across exp3's pair
    # 1-3 on the dynamic plant: the platform rang, 716 slack ticks).
    ramp = RAMP_SHARE * params[F_A_MAX] * T
    # The kinetostatic limit's rows ramp at the cable brake: on a robot with mass (a_brake)
    # a hand that takes the margin away (exp2's 40 N corner pull: +7.7 to -7.7 N in 0.12 s)
    # was met by a return steered at 0.9 a_max, the platform's vertical speed reversed from
    # +0.05 to -0.03 m/s in 40 ms, and cable 5 went slack; the limit is there to keep the
    # cables taut, and a braking they cannot take defeats it. The pair and box barriers keep
    # the full ramp (the crossing is the hard promise).
    kin_brake = min(params[F_CABLE_BRAKE], RAMP_SHARE * params[F_A_MAX])
    give_way = params[F_GIVE_WAY]
    a_prev = memory[10:13]
    smallest = math.inf
    # Only barriers that could bind this tick: the most a velocity within the speed limit can
    # take off a margin is g v_max.
    v_bound = v_max
    for c in range(3):
        ahead[c] = p[c] + T * prev[c]
    for q in range(P):
        dist = pair_barrier(reels, attachments, pi[q], pj[q], p, R, grad)
        sign = 1.0
        if crossed[q] > 0.5:
            sign = -1.0
        h = sign * dist - d_min[q]
        smallest = min(smallest, h)
        gv = math.sqrt(grad[0] * grad[0] + grad[1] * grad[1] + grad[2] * grad[2])
        rate = barrier_rate(h, gv, params)
        if rate >= gv * v_bound:
            continue
        # Linearised about the position a tick at the previous command reaches, not about
        # p: a pair's distance is curved, and a platform sliding along its barrier (the
        # command tangent to the gradient at p) loses margin to the curvature every tick,
        # which a linearisation at p never sees; it then braked, re-accelerated and braked
        # again at 20 Hz (a 20 N push along exp2's boundary) and rang the platform.
        # h(x + T v) ~ h1 + g1 . T (v - v_prev) >= h - T rate(h).
        h1 = sign * pair_barrier(reels, attachments, pi[q], pj[q], ahead, R, grad) - d_min[q]
        trans = 0.0
        for c in range(3):
            grad[c] *= sign
            trans += grad[c] * prev[c]
        count = _add_barrier(C, d, kind, lost, lost_by, count, grad, n,
                             trans - rate + (h - h1) / T, h, h1, BIND_PAIR, prev, gv * ramp, T)
    for axis in range(3 if params[F_BOX] != 0.0 else 0):
        for side in range(2):
            h = p[axis] - bounds[0, axis] if side == 0 else bounds[1, axis] - p[axis]
            rate = barrier_rate(h, 1.0, params)
            if rate >= v_bound:
                continue
            for c in range(6):
                grad[c] = 0.0
            grad[axis] = 1.0 if side == 0 else -1.0
            count = _add_barrier(C, d, kind, lost, lost_by, count, grad, n, -rate, h,
                                 h + T * grad[axis] * prev[axis], BIND_BOX, prev, ramp, T)
    kappa_used = math.nan
    if params[F_KINETOSTATIC] != 0.0 and math.isfinite(kappa):
        gv = math.sqrt(gk[0] * gk[0] + gk[1] * gk[1] + gk[2] * gk[2])
        kappa_used = kappa
        for c in range(3):
            grad[c] = gk[c]
        k_next = kappa + T * (gk[0] * prev[0] + gk[1] * prev[1] + gk[2] * prev[2])
        # The braking it may ask for along its gradient gives way to the acceleration the
        # platform has (give_way_ramp).
        braking = kin_brake
        if gv > 0.0:
            braking = give_way_ramp((gk[0] * a_prev[0] + gk[1] * a_prev[1]
                                     + gk[2] * a_prev[2]) / gv, give_way, kin_brake, T)
        count = _add_barrier(C, d, kind, lost, lost_by, count, grad, n,
                             -barrier_rate(kappa, gv, params), kappa, k_next,
                             BIND_KINETOSTATIC, prev, gv * braking * T, T)
        speed = math.sqrt(prev[0] * prev[0] + prev[1] * prev[1] + prev[2] * prev[2])
        if ray < math.inf and speed > 0.0:
            # The look ahead (kinetostatics.kinetostatic_tick): the margin is lost `ray` m
            # along the last command; the speed along it brakes to stop there (the braking
            # curve), at most a_brake T a tick.
            along = 0.0
            for c in range(3):
                grad[c] = -prev[c] / speed
                along += prev[c] / speed * prev[c]
            cap = face_cap(ray, params[F_A_BRAKE], T)
            slowing = _slowing(prev, speed, a_prev)
            count = _add_barrier(C, d, kind, lost, lost_by, count, grad, n,
                                 -max(cap, along - give_way_ramp(slowing, give_way, kin_brake,
                                                                 T) * T),
                                 ray, ray - T * along, BIND_KINETOSTATIC, prev, 1e300, T)
    base = count
    # While a margin is lost (by more than a tick's round-off) the platform is at a limit its
    # model says it should not be at (a hand force that changed, a kink of the kinetostatic
    # margin): it slows towards LOST_SPEED there (braking at the acceleration limit), where a
    # gradient that turns from one tick to the next cannot swing the command about (40 N
    # across exp3's pair 5-7: 2885 slack ticks in 10 s before, 58 with).
    speed_cap = v_max
    depth = 0.0
    for r in range(base):
        depth = max(depth, lost_by[r])
    if depth > LOST_DEPTH:
        # The cap falls with the depth, not at once: a margin hovering about LOST_DEPTH (a
        # platform sliding along the curved kinetostatic limit loses ~0.05 N there, about a
        # millimetre) switched a step cap on and off, braking and speeding the platform up in
        # turn (50-120 mm/s at ~5 Hz), which rang the dynamic plant (a 20 N lift on exp2:
        # 1853 slack ticks in 10 s, 654 with the cap graded).
        share = min(1.0, (depth - LOST_DEPTH) / LOST_DEPTH)
        slow_to = v_max + share * (LOST_SPEED - v_max)
        # Slowing by the cable brake a tick: at most RAMP_SHARE of the acceleration limit, not
        # all of it: with all of it the speed and acceleration balls touch in a single point,
        # which the cutting planes never reach (the solve failed and the filter reported a
        # hold on 103 ticks of a 40 N push across exp3's pair 5-7, commanding that very
        # point). On a robot with mass it is a_brake: a hand that takes the kinetostatic
        # margin away faster than the platform moves (exp3's 20 N corner pull on the dynamic
        # plant: +12.9 to -0.9 N in 70 ms, the platform accelerating at the 2 m/s^2 limit)
        # met a slowdown at 1.8 m/s^2 the next tick, and that reversal rang cable 2 slack
        # within 20 ms.
        prev_speed = math.sqrt(prev[0] * prev[0] + prev[1] * prev[1] + prev[2] * prev[2])
        slowing = _slowing(prev, prev_speed, a_prev) if prev_speed > 0.0 else 0.0
        speed_cap = min(v_max, max(slow_to, prev_speed - give_way_ramp(
            slowing, give_way, kin_brake, T) * T))
    # The regain cap (regain_cap), while a margin is lost, is the first thing given up: a
    # barrier that needs the platform faster than it (a return) is kept.
    limits_cap = speed_cap
    if give_way < math.inf and memory[3] != 0.0 and depth > 0.0:
        speed_cap = min(speed_cap, regain_cap(prev, a_prev, give_way, T))
    status = STATUS_HOLD
    for stage in range(3):
        # Stage 0: everything; 1: without the regain cap; 2: lost margins only kept, not
        # restored.
        if stage == 1:
            if speed_cap >= limits_cap:
                continue
            speed_cap = limits_cap
        if stage == 2:
            relaxed = False
            for r in range(base):
                if lost[r] and d[r] > 0.0:
                    d[r] = 0.0
                    relaxed = True
            if not relaxed:
                break
        count = base
        ok = False
        for _ in range(MAX_CUTS + 1):
            qp_status, _ = solve_qp_in(w, target, C, d, count, z, u, 200, qp_work)
            if qp_status != QP_OPTIMAL:
                break
            speed = math.sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2])
            ex, ey, ez = z[0] - prev[0], z[1] - prev[1], z[2] - prev[2]
            step = math.sqrt(ex * ex + ey * ey + ez * ez)
            # Relative and absolute: the QP meets a cut to ~1e-12 m/s, and a cut again at
            # the same point changes nothing (0.05 m/s exceeded by 6e-11 failed all 12 cuts,
            # and the filter alternated between restoring a lost margin and not, a tick
            # each: a 1.8 m/s^2 square wave, exp3 with a 40 N spring hand across 5-7).
            over_speed = speed > speed_cap * (1.0 + BALL_TOL) + BALL_TOL
            over_step = step > a_max * T * (1.0 + BALL_TOL) + BALL_TOL
            if not (over_speed or over_step):
                ok = True
                break
            if count + 2 > rows:
                break
            for c in range(6):
                grad[c] = 0.0
            if over_speed:  # -(z / |z|) . v >= -speed cap
                grad[0], grad[1], grad[2] = -z[0] / speed, -z[1] / speed, -z[2] / speed
                count = _add_row(C, d, kind, count, grad, n, -speed_cap, BIND_SPEED)
            if over_step:  # -(e / |e|) . (v - v_prev) >= -a_max T
                grad[0], grad[1], grad[2] = -ex / step, -ey / step, -ez / step
                count = _add_row(C, d, kind, count, grad, n,
                                 -a_max * T + grad[0] * prev[0] + grad[1] * prev[1]
                                 + grad[2] * prev[2], BIND_ACCELERATION)
        if ok:
            status = (STATUS_PASS, STATUS_PASS, STATUS_NO_RETURN)[stage]
            break
    binding = 0
    if status == STATUS_HOLD:
        # Brake to a hold at the acceleration limit: a step to zero from speed would jerk
        # the platform (on a robot with mass, hard enough to slacken cables).
        speed = math.sqrt(prev[0] * prev[0] + prev[1] * prev[1] + prev[2] * prev[2])
        k = max(0.0, 1.0 - a_max * T / speed) if speed > 0.0 else 0.0
        for c in range(n):
            z[c] = prev[c] * k if c < 3 else 0.0
    else:
        for r in range(count):
            if u[r] > 0.0:
                binding |= kind[r]
        if status == STATUS_PASS:
            for c in range(n):
                if z[c] != target[c]:
                    status = STATUS_MODIFIED
    for c in range(6):
        out[c] = z[c] if c < n else 0.0
        out[OUT_MEMORY + 4 + c] = out[c]
    for c in range(3):
        out[OUT_MEMORY + c] = p[c]
        # The acceleration commanded (0 at the first tick: the platform starts at rest).
        out[OUT_MEMORY + 10 + c] = (z[c] - prev[c]) / T if memory[3] != 0.0 else 0.0
    out[OUT_MEMORY + 3] = 1.0
    out[6] = status
    out[7] = binding
    out[8] = smallest
    out[9] = kappa_used
    out[10] = base
    for c in range(3):
        out[OUT_V_D + c] = x[c]
    return status
