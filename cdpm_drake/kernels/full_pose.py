"""The full-pose controller's per-tick math (controller.pose: full, tension_control): compiled
kernels, one per block, each on one stacked input vector as the blocks' C++ wiring delivers it.
numpy and numba, no Drake. Beyond the paper, whose platform only translates.

Base frame A, SI units. A pose is (p, R): p the platform centre (m), R = R_WB stored row-major
as 9 floats. Tensions in N, lengths in m.

- `pose_fk_tick` (forward_kinematics): the pose whose rigid lengths best fit the encoders'
  lengths L0 corrected for the cables' modelled stretch under the last tension estimate,
  l_i = L0_i (1 + T_i / EA); and the fit's residual. At the first tick it iterates the fit
  and the estimate below to agreement (the pretension it starts from is unknown).
- `tension_tick` (tension_distribution): the tension ESTIMATE and the target. With k = m - 6
  more cables than degrees of freedom the fit's residual along the wrench matrix's nullspace
  (an orthonormal basis N, m x k) is what a pose cannot explain, the internal tension. From
  r = lengths(pose) - l and l = L0 + D T_assumed (D = diag(L0 / EA)), N^T D T = N^T D
  T_assumed + N^T r; the true T = T_p + N lam balances the same wrench (T_p the minimum-norm
  one), so N^T D N lam = N^T (D (T_assumed - T_p) + r) (weighted least squares; for k = 1
  lam = (n . D (T_assumed - T_p) + n . r) / (n . D n)). The estimate is what the next tick's
  fit corrects the lengths by, so the pose stays fitted to the cables as they really are
  stretched. The target: a distribution at the estimated pose between a floor and a ceiling,
  never below a hard floor (rules (a)-(d) of `distribution_1d_bounded`; tension_tick's).
- `orientation_tick` (orientation_hold): an angular-velocity command back to the orientation
  held (the estimate's after the warm-up), w = K_R log(R_ref R^T).
- `pose_rates_tick` (jacobian_mapping): l_dot = J(p, R) [v; w] + K_l (l_d - L0), with l_d the
  unstretched lengths of the commanded pose (p_d, R_ref) under the commanded tensions
  (tension control) or its rigid lengths plus the offsets latched at the warm-up's end.
- `interference_posed_tick` (interference_force): the paper's interference tick on the cables
  of the estimated pose, attachment points at p + R b_i.
"""

import math

import numba
import numpy as np

from cdpm_drake.kernels.interference import interference_tick
from cdpm_drake.kernels.kinematics import add_scaled_corrections, dead_band_compensation
from cdpm_drake.kernels.pose import pose_fk, posed_cables, rotation_log, solve_spd, wrench_columns
from cdpm_drake.kernels.qp import QP_OPTIMAL, solve_qp
from cdpm_drake.kernels.nullspace import (RANK_TOL, lam_interval, null_vector,
                                          particular_solution, pivoted_qr)
from cdpm_drake.kernels.tension_path import lead_statics, ringing_cable
from cdpm_drake.kernels.tension import (BELOW_FLOOR, FEASIBLE, GENERAL, GRAVITY, max_min_1d,
                                        max_min_lines, max_min_lines_subject_to)

_jit = numba.njit(cache=True, error_model="numpy")

# Ticks the full-pose blocks wait, following the estimate, before they hold the orientation,
# integrate the commanded position and slew the tensions: the estimate of the pose and the
# tensions starts from a guess (the start's target distribution, which can be hundreds of
# newtons off the pretension the robot really has) and closes ~60 % of its error a tick.
WARMUP_TICKS = 25
# At most this many fit-and-estimate iterations at the first tick (pose_fk_tick); 0.4^40 of
# the first guess's error is left at worst.
START_ITERATIONS = 40

# pose_fk_tick's status.
FK_OK, FK_NOT_SETTLED, FK_INCONSISTENT = 0, 1, 2


def sizes(m: int) -> dict:
    """Input (x) and output (out) sizes of the kernels for m cables, and their memories."""
    return {
        "fk_x": 2 * m + 13, "fk_out": 2 * m + 16, "fk_memory": 13,
        "tension_x": 6 * m + 31, "tension_out": 5 * m + 16, "tension_memory": 2 * m + 13,
        "orientation_x": 19, "orientation_out": 22, "orientation_memory": 10,
        "rates_x": 5 * m + 31, "rates_out": 5 * m + 4, "rates_memory": 3 * m + 4,
    }


@_jit
def _rpy(R, out):
    """roll, pitch, yaw (rad) of R = Rz(yaw) Ry(pitch) Rx(roll) into out (3,)."""
    out[0] = math.atan2(R[2, 1], R[2, 2])
    out[1] = -math.asin(min(1.0, max(-1.0, R[2, 0])))
    out[2] = math.atan2(R[1, 0], R[0, 0])


@_jit
def _fit(reels, attachments, L0, T, EA, p_guess, R_guess, p, R, residual):
    """The pose fitted to L0 (1 + T / EA) (L0 alone for EA <= 0); False if it did not
    settle."""
    m = reels.shape[0]
    lengths = np.empty(m)
    for i in range(m):
        lengths[i] = L0[i] * (1.0 + T[i] / EA) if EA > 0.0 else L0[i]
    if pose_fk(reels, attachments, lengths, p_guess, R_guess, 1e-10, 8, p, R, residual):
        return True
    # Lengths far from any pose (slack or overstretched cables) slow Gauss-Newton down to a
    # linear rate: more steps, and a looser step at which it counts as settled.
    return pose_fk(reels, attachments, lengths, p_guess, R_guess, 1e-8, 50, p, R, residual)


@_jit
def held_wrench(R, params, F, a, w):
    """The wrench (6,) the cables balance: the platform's weight (params[0] kg), the hand
    force F (N) at the handle (params[1:4], platform frame) and the inertia of an
    acceleration a (m/s^2, d'Alembert), about the centre."""
    mass = params[0]
    hx = R[0, 0] * params[1] + R[0, 1] * params[2] + R[0, 2] * params[3]
    hy = R[1, 0] * params[1] + R[1, 1] * params[2] + R[1, 2] * params[3]
    hz = R[2, 0] * params[1] + R[2, 1] * params[2] + R[2, 2] * params[3]
    for k in range(3):
        w[k] = F[k] - mass * a[k]
    w[2] -= mass * GRAVITY
    w[3] = hy * F[2] - hz * F[1]
    w[4] = hz * F[0] - hx * F[2]
    w[5] = hx * F[1] - hy * F[0]


@_jit
def _estimate(reels, attachments, p, R, w, L0, r, T_assumed, EA, W, T_p, N, T_est):
    """The tensions of a platform in equilibrium under w at the pose (p, R) fitted to the
    lengths L0 (1 + T_assumed / EA) with residual r: T = T_p + N lam, the minimum-norm T_p of
    the wrench plus the internal force the redundant cables' residual measures, lam the
    weighted least-squares solution of N^T D N lam = N^T (D (T_assumed - T_p) + r), D =
    diag(L0 / EA) (module docstring). Writes W (6, m), T_p, N (m, m - 6: an orthonormal basis
    of W's nullspace, perpendicular to T_p) and T_est; returns True when W has rank 6 (else
    T_est = T_p, the minimum-norm distribution of the normal equations, N zero)."""
    m = reels.shape[0]
    k = N.shape[1]
    u, Rb, L = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    posed_cables(reels, attachments, p, R, u, Rb, L)
    wrench_columns(u, Rb, W)
    A, V = np.empty((m, 6)), np.empty((6, m))
    beta, perm = np.empty(6), np.empty(6, dtype=np.int64)
    if m == k + 6 and pivoted_qr(W, A, V, beta, perm) >= RANK_TOL:
        particular_solution(A, V, beta, perm, w, T_p)
        col = np.empty(m)
        for c in range(k):
            null_vector(V, beta, col, c)
            for i in range(m):
                N[i, c] = col[i]
        G, g, lam = np.zeros((k, k)), np.zeros(k), np.zeros(k)
        for i in range(m):
            d = L0[i] / EA
            for a in range(k):
                g[a] += N[i, a] * (d * (T_assumed[i] - T_p[i]) + r[i])
                for b in range(k):
                    G[a, b] += N[i, a] * N[i, b] * d
        if k == 1:
            lam[0] = g[0] / G[0, 0]
        elif k > 1 and not solve_spd(G, g, lam):
            for a in range(k):
                lam[a] = 0.0
        for i in range(m):
            total = T_p[i]
            for a in range(k):
                total += lam[a] * N[i, a]
            T_est[i] = total
        return True
    # W rank-deficient: the minimum-norm distribution by the normal equations.
    G = np.empty((6, 6))
    for a in range(6):
        for b in range(6):
            total = 0.0
            for i in range(m):
                total += W[a, i] * W[b, i]
            G[a, b] = total
    minus_w, y = np.empty(6), np.zeros(6)
    for a in range(6):
        minus_w[a] = -w[a]
    if not (m >= 6 and solve_spd(G, minus_w, y)):
        for a in range(6):
            y[a] = 0.0
    for i in range(m):
        total = 0.0
        for a in range(6):
            total += W[a, i] * y[a]
        T_p[i] = total
        T_est[i] = total
        for a in range(k):
            N[i, a] = 0.0
    return False


@_jit
def pose_fk_tick(reels, attachments, params, x, out):
    """params = [EA N, max_residual m, mass kg, handle (3, m, platform frame), start
    iterations]. x = [L0 (m), T_previous (m), memory: p (3), R (9), started (1)]; out = [p
    (3), R (9), started (1), rpy (3), residual (m), T_used (m)]: the pose fitted to the
    lengths corrected by the stretch under T_used (EA <= 0: no correction).

    T_used is the previous tick's tension estimate; at the first tick, whose estimate is only
    a guess (hundreds of newtons off where the pretension is unknown), the fit and the
    estimate of a platform at rest (weight only) are iterated to agreement first: the
    estimate closes ~60 % of its error an iteration. Returns FK_OK, FK_NOT_SETTLED, or
    FK_INCONSISTENT when the best fit leaves a residual above max_residual (m) on some cable
    (out then holds that fit)."""
    m = reels.shape[0]
    EA, max_residual = params[0], params[1]
    L0 = x[0:m]
    p = out[0:3]
    R = out[3:12].reshape((3, 3))
    residual = out[16:16 + m]
    T = out[16 + m:16 + 2 * m]
    for i in range(m):
        T[i] = x[m + i]
    p_guess = x[2 * m:2 * m + 3]
    R_guess = x[2 * m + 3:2 * m + 12].reshape((3, 3))
    if x[2 * m + 12] == 0.0 and EA > 0.0:
        W, T_p, T_next = np.empty((6, m)), np.empty(m), np.empty(m)
        N = np.empty((m, max(m - 6, 0)))
        w, zero = np.empty(6), np.zeros(3)
        for _ in range(int(params[6])):
            # A guess far off leaves lengths no pose fits well, where Gauss-Newton crawls:
            # its last step is good enough to improve the estimate; only the final fit must
            # settle.
            _fit(reels, attachments, L0, T, EA, p_guess, R_guess, p, R, residual)
            held_wrench(R, params[2:6], zero, zero, w)
            _estimate(reels, attachments, p, R, w, L0, residual, T, EA, W, T_p, N, T_next)
            change = 0.0
            for i in range(m):
                change = max(change, abs(T_next[i] - T[i]))
                T[i] = T_next[i]
            p_guess, R_guess = p, R
            if change < 1e-9:
                break
    if not _fit(reels, attachments, L0, T, EA, p_guess, R_guess, p, R, residual):
        return FK_NOT_SETTLED
    out[12] = 1.0
    _rpy(R, out[13:16])
    for i in range(m):
        if not abs(residual[i]) <= max_residual:
            return FK_INCONSISTENT
    return FK_OK


# Where the pose allows less than the floor, the target keeps every cable within this much
# (N) of the best minimum t*, least-norm among those: the max-min distribution is not unique
# where the weakest cable's nullspace share is near zero (cable 7 in exp2 near Fig. 12's
# poses), and picking one end of that flat maximum jumped the target up to 15 N a tick (exp2,
# dynamic plant: smallest tension 1.26 N; 2.03 N with the margin, 0.9 N a tick at most).
FLOOR_MARGIN = 0.05


# tension_tick's statuses beyond tension.py's FEASIBLE (0: every cable between min_tension
# and max_tension), BELOW_FLOOR (1: the floor lowered to what the pose and the ceiling allow,
# never below tension_floor) and GENERAL (2: the wrench matrix is rank-deficient, the
# minimum-norm distribution): CEILING_EXCEEDED (3: the ceiling and the hard floor conflict,
# the floor wins: a cable above max_tension) and FLOOR_UNREACHABLE (4: no distribution keeps
# every cable at tension_floor even without a ceiling: the max-min one, its weak cables
# raised to tension_floor, which no longer balances the wrench exactly).
CEILING_EXCEEDED, FLOOR_UNREACHABLE = 3, 4
# And HAND_TOO_FAST (5): the hand changes faster than the tension path can follow: the
# balanced command (the hand's led statics plus the internal force its slew allows) leaves a
# cable below the hard floor where the target keeps it above, or the hand's unsettled part
# may ring a cable of it slack (tension_path.py). Said before the cable is slack.
HAND_TOO_FAST = 5


@_jit
def _ceiling_interval(T_p, n, ceiling):
    """[a, b]: the lam with T_p[i] + n[i] lam <= ceiling for every cable (a > b: none)."""
    a, b = -math.inf, math.inf
    for i in range(T_p.size):
        if n[i] > 0.0:
            b = min(b, (ceiling - T_p[i]) / n[i])
        elif n[i] < 0.0:
            a = max(a, (ceiling - T_p[i]) / n[i])
        elif T_p[i] > ceiling:
            a, b = math.inf, -math.inf
    return a, b


@_jit
def _weakest(T):
    """The 1-based number of the cable with the smallest tension."""
    worst = 0
    for i in range(T.size):
        if T[i] < T[worst]:
            worst = i
    return worst + 1


@_jit
def _raise_to(T, floor):
    """Every T_i below floor raised to it; the 1-based cable raised most (0: none was)."""
    most, cable = 0.0, 0
    for i in range(T.size):
        if floor - T[i] > most:
            most, cable = floor - T[i], i + 1
        T[i] = max(T[i], floor)
    return cable


@_jit
def _floor_wins(T, t_star, hard_floor, ceiling):
    """Cases (c) and (d): every cable of T raised to hard_floor; returns (status, t*,
    hard_floor, cable): FLOOR_UNREACHABLE naming the cable raised most where t* <
    hard_floor, else CEILING_EXCEEDED naming the cable above the ceiling (the largest), or
    BELOW_FLOOR naming the weakest where none ended up above it."""
    raised = _raise_to(T, hard_floor)
    if t_star < hard_floor:
        return FLOOR_UNREACHABLE, t_star, hard_floor, raised
    top = 0
    for i in range(T.size):
        if T[i] > T[top]:
            top = i
    if T[top] > ceiling + 1e-9 * max(1.0, ceiling):
        return CEILING_EXCEEDED, t_star, hard_floor, top + 1
    return BELOW_FLOOR, t_star, hard_floor, _weakest(T)


@_jit
def distribution_1d_bounded(T_p, n, floor, hard_floor, ceiling, T):
    """The target tension distribution of a one-dimensional nullspace T = T_p + n lam (n a
    unit vector perpendicular to T_p: |T|^2 = |T_p|^2 + lam^2), in closed form, into T (N).
    Returns (status, t*, the floor used, cable): t* the pose's largest achievable minimum
    tension, unbounded above (tension.max_min_1d; +inf where an internal force raises every
    tension); cable 1-based (0: none). With best, the largest minimum tension with every
    cable <= ceiling (-inf where no lam keeps them all under it):
      (a) best >= floor: the least-norm T with floor <= T <= ceiling (FEASIBLE, cable 0);
      (b) best - FLOOR_MARGIN >= hard_floor: the least-norm T with best - FLOOR_MARGIN <= T
          <= ceiling (BELOW_FLOOR, the weakest cable);
      (c) else, t* >= hard_floor (the ceiling and the hard floor conflict; the floor wins):
          the least-norm T with hard_floor <= T <= the smallest largest tension of those
          with every T_i >= hard_floor, plus FLOOR_MARGIN, or the ceiling if that is higher
          (CEILING_EXCEEDED naming the cable above the ceiling; BELOW_FLOOR naming the
          weakest where none ends up above it);
      (d) else (t* < hard_floor): the same with the floor t* - FLOOR_MARGIN (the least-norm
          T within FLOOR_MARGIN of t*, its largest tension kept as in (c)), each cable then
          raised to hard_floor (FLOOR_UNREACHABLE, naming the cable raised most).
    Where hard_floor <= t* < hard_floor + FLOOR_MARGIN, (c) takes (d)'s floor too, and
    raises: an exact floor just under t* is reached only far out along the nullspace where
    the weakest cable's component is small (the flat maximum of FLOOR_MARGIN), a jump of
    the target by 14 N a tick on exp2. The floor used: min(floor, best - FLOOR_MARGIN) in
    (a) and (b) (continuous as best passes the floor), hard_floor in (c) and (d).

    Why a ceiling: where t* is +inf, or large, raising the weakest cable to the floor may take
    an internal force of hundreds of newtons through the others (a cable whose nullspace
    component is small); the ceiling trades that floor for sane tensions, down to the hard
    floor, never below: a cable commanded below it goes slack under the tension ripple."""
    m = T_p.size
    t_star, lam_star = max_min_1d(T_p, n)
    a, b = _ceiling_interval(T_p, n, ceiling)
    best, lam_best = -math.inf, 0.0
    if a <= b:
        # The best lam within [a, b]: m(lam) = min_i T_i(lam) is concave, so its maximiser
        # over the interval is the unconstrained one clipped (a direction when t* is +inf).
        if t_star == math.inf:
            lam_best = b if b < math.inf else (a if a > -math.inf else 0.0)
            # With every n_i of one sign, raising lam raises them all: the sign says which.
            s = 0.0
            for i in range(m):
                s += n[i]
            if s < 0.0:
                lam_best = a if a > -math.inf else (b if b < math.inf else 0.0)
        else:
            lam_best = min(max(lam_star, a), b)
        best = math.inf
        for i in range(m):
            best = min(best, T_p[i] + n[i] * lam_best)
    used = min(floor, best - FLOOR_MARGIN)  # continuous as best passes the floor
    if used >= hard_floor:  # (a), (b)
        lo, hi = lam_interval(T_p, n, used)
        lo, hi = max(lo, a), min(hi, b)
        lam = lam_best if lo > hi else min(max(0.0, lo), hi)  # |T|^2 = |T_p|^2 + lam^2
        for i in range(m):
            T[i] = T_p[i] + n[i] * lam
        if best >= floor:
            return FEASIBLE, t_star, used, 0
        return BELOW_FLOOR, t_star, used, _weakest(T)
    # (c), (d): the floor wins over the ceiling, and the FLOOR_MARGIN below t* over the
    # floor where t* is within it (the flat maximum: a weak cable that the internal force
    # barely moves, which an exact floor would reach only far out along the nullspace).
    floor_c = min(hard_floor, t_star - FLOOR_MARGIN)
    lo, hi = lam_interval(T_p, n, floor_c)
    # The smallest largest tension over [lo, hi]: max_i T_i(lam) is convex, so its
    # minimiser (the max-min of -T) clipped; with every n_i of one sign (t* = +inf) it falls
    # all the way towards the end where every cable drops.
    neg_top, lam_top = max_min_1d(-T_p, -n)
    if neg_top == math.inf:
        lam_top = lo if n[0] > 0.0 else hi
    lam_top = min(max(lam_top, lo), hi)
    top = -math.inf
    for i in range(m):
        top = max(top, T_p[i] + n[i] * lam_top)
    a, b = _ceiling_interval(T_p, n, max(ceiling, top + FLOOR_MARGIN))
    lo, hi = max(lo, a), min(hi, b)
    lam = lam_top if lo > hi else min(max(0.0, lo), hi)
    for i in range(m):
        T[i] = T_p[i] + n[i] * lam
    return _floor_wins(T, t_star, hard_floor, ceiling)


@_jit
def _least_norm(T_p, N, lo, hi, fallback, T):
    """T = T_p + N lam with the least-norm lam (|T|^2 = |T_p|^2 + |lam|^2, N orthonormal and
    perpendicular to T_p) with lo <= T_i <= hi (hi may be +inf), by qp.solve_qp; lam =
    fallback where the QP finds none (round-off at an empty set's edge)."""
    m, k = N.shape
    C, d = np.empty((2 * m, k)), np.empty(2 * m)
    count = 0
    for i in range(m):
        for c in range(k):
            C[count, c] = N[i, c]
        d[count] = lo - T_p[i]
        count += 1
        if hi < math.inf:
            for c in range(k):
                C[count, c] = -N[i, c]
            d[count] = T_p[i] - hi
            count += 1
    w, z0, z, u = np.ones(k), np.zeros(k), np.empty(k), np.empty(2 * m)
    status, _ = solve_qp(w, z0, C, d, count, z, u, 50 + 4 * count)
    if status != QP_OPTIMAL:
        for c in range(k):
            z[c] = fallback[c]
    for i in range(m):
        total = T_p[i]
        for c in range(k):
            total += N[i, c] * z[c]
        T[i] = total


@_jit
def distribution_bounded(T_p, N, floor, hard_floor, ceiling, T):
    """`distribution_1d_bounded`'s rules (a)-(d) for a nullspace of any dimension k (N (m,
    k) orthonormal, perpendicular to T_p; k = 0 too): t*, best and the smallest largest
    tension of case (c) by tension.max_min_lines(_subject_to) (the LP as a small QP, within
    ~1e-8 relative), each least-norm distribution by qp.solve_qp (exact). Same returns."""
    m, k = N.shape
    lam_star, lam = np.zeros(k), np.zeros(k)
    t_star = max_min_lines(T_p, N, lam_star)
    # best: the largest minimum with T_i <= ceiling, i.e. -N_i . lam >= T_p[i] - ceiling.
    E, f = np.empty((m, k)), np.empty(m)
    for i in range(m):
        for c in range(k):
            E[i, c] = -N[i, c]
        f[i] = T_p[i] - ceiling
    best = max_min_lines_subject_to(T_p, N, E, f, ceiling, lam)
    used = min(floor, best - FLOOR_MARGIN)
    if used >= hard_floor:  # (a), (b)
        _least_norm(T_p, N, used, ceiling, lam, T)
        if best >= floor:
            return FEASIBLE, t_star, used, 0
        return BELOW_FLOOR, t_star, used, _weakest(T)
    # (c), (d), as in distribution_1d_bounded. The smallest largest tension with every T_i >=
    # floor_c: minus the largest minimum of -T subject to N_i . lam >= floor_c - T_p[i].
    floor_c = min(hard_floor, t_star - FLOOR_MARGIN)
    minus_T_p = np.empty(m)
    for i in range(m):
        minus_T_p[i] = -T_p[i]
        f[i] = floor_c - T_p[i]
    top = -max_min_lines_subject_to(minus_T_p, E, N, f, -floor_c, lam)
    _least_norm(T_p, N, floor_c, max(ceiling, top + FLOOR_MARGIN), lam, T)
    return _floor_wins(T, t_star, hard_floor, ceiling)


# Without the tension path's rate time constant, the commanded acceleration the target's
# wrench takes in (tension_tick) is the command's low-passed with this time constant, s.
ACCELERATION_TIME = 0.1


@_jit
def tension_tick(reels, attachments, params, x, out):
    """params = [mass kg, handle (3, m, platform frame), EA N, floor N, ceiling N, time step
    s, slew rate N/s, warm-up ticks, hard floor N, fall rate N/s, ringing factor (0: off),
    lead s, rate time constant s, stretch speed m/s, settle time s, hand lag s, the modes
    (42: tension_path.modal_params; these three optional, 0: off; tension_path.py)].
    x = [p (3), R (9), F_H (3), v (3), residual (m), L0 (m), T_assumed (m: the tensions the
    forward kinematics corrected the lengths for), ringing (m, N^2: each measured tension's
    variance about the estimate, tension_damping.damping_tick; ignored with the factor 0),
    memory: T_estimate (m), v_slow (3: the command low-passed), ticks (1), T_command_previous
    (m), F_previous (3), F_rate (3: the hand force's rate, N/s, low-passed over rate time),
    F_settled (3: the hand ahead of the sensor's lag, low-passed over the settle time)].
    The hard floor is at least the ringing factor times the largest ringing's standard
    deviation (never above the floor).
    out = [T_command (m), T_estimate (m), T_target (m), t* (1), status (1), cable (1), next
    memory (2 m + 13)]: T_target the distribution at the pose (rules (a)-(d) of
    `distribution_1d_bounded`: closed form for one redundant cable, `distribution_bounded`
    for more) for the hand force led by its rate, F + lead F_rate (the tension path, the
    force's tick of age, the mapping's and the drives' 1/bandwidth, lags the hand by about
    `lead`: the target moves with the hand, not after it) and the commanded acceleration
    (low-passed over the rate time constant); the estimate takes the hand force as measured.

    T_command, what the lengths are stretched for, is the target's statics (its minimum-norm
    part, which the platform's own displacement brings) plus an internal force (its part
    along W's nullspace N, which only the reels make) moved from the last command's towards
    the target's: each cable's share N_i . dlam at most `slew rate` N/s up (and EA / L0_i
    times the stretch speed, the reel speed the motion leaves; 0: no such limit) and `fall
    rate` N/s down, the change scaled as a whole so that the command stays balanced (a cable
    clamped alone unbalances it, and the platform's stiffness takes the difference out of the
    others, the weak cable first). Up fast: the internal force that keeps a weak cable taut
    under a push loads the others 2-15 times as fast. Down slowly: a target that drops is
    where slack starts, and where the weakest cable's share is small the target flips between
    distributions tick by tick; but not where the slow fall would hold a rising cable (a
    negative share) below the hard floor. During the warm-up the command follows the
    estimate. A cable the balanced command leaves below the hard floor is raised to it; where
    the target keeps it above (the internal force could not keep up with the hand) or the
    hand's unsettled part may ring it slack, the status is HAND_TOO_FAST, naming the cable.
    status: FEASIBLE, BELOW_FLOOR, CEILING_EXCEEDED, FLOOR_UNREACHABLE, GENERAL (W
    rank-deficient: the minimum-norm distribution, raised to the hard floor) or
    HAND_TOO_FAST; cable the 1-based cable it names (0: none)."""
    m = reels.shape[0]
    EA, floor, ceiling = params[4], params[5], params[6]
    step, max_change, warmup = params[7], params[8] * params[7], params[9]
    hard_floor = params[10]
    max_fall = params[11] * step
    lead, rate_time, stretch_speed = params[13], params[14], params[15]
    p = x[0:3]
    R = x[3:12].reshape((3, 3))
    F = x[12:15]
    v = x[15:18]
    r = x[18:18 + m]
    L0 = x[18 + m:18 + 2 * m]
    T_assumed = x[18 + 2 * m:18 + 3 * m]
    mem = 18 + 4 * m
    # The hard floor clears the ringing the tension sensors measure (params[12] standard
    # deviations of the largest): a cable at the floor rings slack when it swings wider.
    if params[12] > 0.0:
        swing = 0.0
        for i in range(m):
            if x[18 + 3 * m + i] > swing:
                swing = x[18 + 3 * m + i]
        hard_floor = min(max(hard_floor, params[12] * math.sqrt(swing)), max(floor,
                                                                             hard_floor))
    v_slow = x[mem + m:mem + m + 3]
    ticks = x[mem + m + 3]
    T_before = x[mem + m + 4:mem + 2 * m + 4]
    F_before = x[mem + 2 * m + 4:mem + 2 * m + 7]
    F_rate = x[mem + 2 * m + 7:mem + 2 * m + 10]
    F_settled = x[mem + 2 * m + 10:mem + 2 * m + 13]
    settle = params[16] if params.shape[0] >= 60 else 0.0
    lag = params[17] if params.shape[0] >= 60 else 0.0
    started = ticks >= warmup
    # The commanded acceleration, from the command low-passed (over ACCELERATION_TIME, or
    # the tension path's time constant): a ramp's acceleration exactly, while a command that
    # alternates braking and accelerating tick by tick (the filter at a barrier), which
    # differenced moved every target ~5 N at 10 Hz and rang cables slack (171 slack ticks in
    # 10 s under a 20 N push along exp2's boundary; none low-passed), is cut ~7-fold. The
    # platform follows the command within the drives' lag (safety_filter.give_way_ramp).
    a, v_next = np.empty(3), np.empty(3)
    acc_time = rate_time if rate_time > 0.0 else ACCELERATION_TIME
    lowpass = step / acc_time
    # The hand force's rate, low-passed (the sensor's noise cut by sqrt(2 rate_time / step)).
    rate_next, F_lead, F_now, settled = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    gain = min(1.0, step / rate_time) if rate_time > 0.0 else 1.0
    for k in range(3):
        a[k] = (v[k] - v_slow[k]) / acc_time if ticks > 0.0 else 0.0
        v_next[k] = v_slow[k] + lowpass * (v[k] - v_slow[k]) if ticks > 0.0 else v[k]
        raw = (F[k] - F_before[k]) / step if ticks > 0.0 else 0.0
        rate_next[k] = F_rate[k] + gain * (raw - F_rate[k]) if ticks > 0.0 else 0.0
        F_lead[k] = F[k] + lead * rate_next[k]
        F_now[k] = F[k] + lag * raw  # what the sensor's average has not yet taken in
        settled[k] = F_settled[k] + min(1.0, step / settle) * (F_now[k] - F_settled[k]) if (
            ticks > 0.0 and settle > 0.0) else F_now[k]
    w, w_lead = np.empty(6), np.empty(6)
    held_wrench(R, params, F, a, w)
    held_wrench(R, params, F_lead, a, w_lead)
    T_cmd, T_est, T_target = out[0:m], out[m:2 * m], out[2 * m:3 * m]
    W, T_p, N = np.empty((6, m)), np.empty(m), np.empty((m, max(m - 6, 0)))
    balanced = _estimate(reels, attachments, p, R, w, L0, r, T_assumed, EA, W, T_p, N, T_est)
    T_hand = T_p.copy()  # the statics of the hand as measured (before the lead)
    if balanced and lead > 0.0:
        balanced = lead_statics(W, w, w_lead, T_p)
    if balanced:
        if N.shape[1] == 1:  # one redundant cable: closed form
            n = np.empty(m)
            for i in range(m):
                n[i] = N[i, 0]
            status, t_star, _, cable = distribution_1d_bounded(T_p, n, floor, hard_floor,
                                                               ceiling, T_target)
        else:
            status, t_star, _, cable = distribution_bounded(T_p, N, floor, hard_floor,
                                                            ceiling, T_target)
    else:
        status, t_star = GENERAL, math.inf
        for i in range(m):
            T_target[i] = T_p[i]
            t_star = min(t_star, T_p[i])
        cable = _raise_to(T_target, hard_floor)
    k_null = N.shape[1]
    if not started or not balanced:
        for i in range(m):
            before = T_before[i] if started else T_est[i]  # during the warm-up: the estimate
            T_cmd[i] = min(before + max_change, max(before - max_fall, T_target[i]))
    else:
        # The internal force of the last command and of the target (N orthonormal and
        # perpendicular to T_p), and the largest share of their difference each cable
        # allows.
        lam_before, dlam = np.zeros(k_null), np.zeros(k_null)
        for c in range(k_null):
            for i in range(m):
                lam_before[c] += N[i, c] * T_before[i]
                dlam[c] += N[i, c] * T_target[i]
            dlam[c] -= lam_before[c]
        # The scale the rising cables allow and the one the falling cables allow; the slow
        # fall gives way where it would hold a rising cable of the command below the floor
        # (an internal force held up by the fall limit starves the cables whose share of
        # it is negative).
        rise, fall = 1.0, 1.0
        for i in range(m):
            change = 0.0
            for c in range(k_null):
                change += N[i, c] * dlam[c]
            if change > 0.0:
                limit = max_change
                if stretch_speed > 0.0:
                    limit = min(limit, EA / L0[i] * stretch_speed * step)
                if change * rise > limit:
                    rise = limit / change
            elif -change * fall > max_fall:
                fall = max_fall / -change
        scale = min(rise, fall)
        if fall < rise:
            for i in range(m):
                total = T_p[i]
                for c in range(k_null):
                    total += N[i, c] * (lam_before[c] + scale * dlam[c])
                if total < hard_floor and T_target[i] > total:
                    scale = rise
                    break
        deepest, cable_fast = 1e-6, 0
        flag = status == FEASIBLE or status == BELOW_FLOOR or status == CEILING_EXCEEDED
        for i in range(m):
            total, aim = T_p[i], T_p[i]
            for c in range(k_null):
                total += N[i, c] * (lam_before[c] + scale * dlam[c])
                aim += N[i, c] * (lam_before[c] + dlam[c])
            # Named only where the hand takes the cable down (its lead lowers it) and the
            # balanced target keeps it at the floor (not a target raised off its balance).
            if (flag and hard_floor - total > deepest and aim >= hard_floor - 1e-9
                    and T_p[i] < T_hand[i]):
                deepest, cable_fast = hard_floor - total, i + 1
            T_cmd[i] = max(total, min(hard_floor, T_target[i]))
        # Said a lead ahead too: where the rising cables' limits hold the internal force back
        # and the hand, going on for another lead, would take a cable of this command below
        # the floor (the true tensions lag the command by about the lead); not where only the
        # slow fall does (slow hands along the kinetostatic limit, taut, were named).
        if cable_fast == 0 and rise < 1.0 and flag:
            for k in range(3):
                F_lead[k] = F[k] + 2.0 * lead * rate_next[k]
            held_wrench(R, params, F_lead, a, w)
            if lead_statics(W, w_lead, w, T_p):
                for i in range(m):
                    total, aim = T_p[i], T_p[i]
                    for c in range(k_null):
                        total += N[i, c] * (lam_before[c] + scale * dlam[c])
                        aim += N[i, c] * (lam_before[c] + dlam[c])
                    if (hard_floor - total > deepest and aim >= hard_floor - 1e-9
                            and T_p[i] < T_hand[i]):
                        deepest, cable_fast = hard_floor - total, i + 1
        if cable_fast > 0:
            status, cable = HAND_TOO_FAST, cable_fast
    if settle > 0.0 and balanced and (status == FEASIBLE or status == BELOW_FLOOR
                                      or status == CEILING_EXCEEDED):
        held_wrench(R, params, F_now, a, w)
        held_wrench(R, params, F_settled, a, w_lead)
        # The hand's unsettled part may ring a cable slack: from the first tick (warm-up too).
        cable_ring = ringing_cable(W, w, w_lead, T_cmd, L0, EA, params[18:60], T_hand)
        if cable_ring > 0:
            status, cable = HAND_TOO_FAST, cable_ring
    out[3 * m] = t_star
    out[3 * m + 1] = status
    out[3 * m + 2] = cable
    nxt = 3 * m + 3
    for i in range(m):
        out[nxt + i] = T_est[i]
        out[nxt + m + 4 + i] = T_cmd[i]
    for k in range(3):
        out[nxt + m + k] = v_next[k]
        out[nxt + 2 * m + 4 + k] = F[k]
        out[nxt + 2 * m + 7 + k] = rate_next[k]
        out[nxt + 2 * m + 10 + k] = settled[k]
    out[nxt + m + 3] = min(ticks + 1.0, warmup)
    return status


@_jit
def orientation_tick(gain, warmup, x, out):
    """x = [R (9), memory: R_ref (9), ticks (1)]; out = [w (3) rad/s, R_ref (9), next memory
    (10)]. The orientation held is the estimate's after `warmup` ticks (until then it follows
    the estimate, w = 0: the estimate settles first); then w = gain log(R_ref R^T) turns the
    platform back to it at `gain` 1/s."""
    R = x[0:9].reshape((3, 3))
    started = x[18] >= warmup
    ref = out[3:12].reshape((3, 3))
    for k in range(9):
        out[3 + k] = x[9 + k] if started else x[k]
    E = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            E[a, b] = ref[a, 0] * R[b, 0] + ref[a, 1] * R[b, 1] + ref[a, 2] * R[b, 2]
    ex, ey, ez = rotation_log(E)
    out[0], out[1], out[2] = gain * ex, gain * ey, gain * ez
    for k in range(9):
        out[12 + k] = out[3 + k]
    out[21] = min(x[18] + 1.0, warmup)


# The length loop's integral term may add at most this reel speed, m/s: enough to break the
# drives' stiction and take up their lag, never a runaway after a long stall.
MAX_INTEGRAL_SPEED = 0.05
@_jit
def pose_rates_tick(reels, attachments, params, x, out):
    """params = [gain 1/s, integral_gain 1/s^2, step s, EA N, tension (0 or 1), dead band
    m/s, warm-up ticks]. x = [p (3), R (9), v (3), w (3), R_ref (9), L0 (m), T_command (m), memory: p_d
    (3), delta (m), integral (m), started (1), T_command_previous (m)]; out = [l_dot (m), l_d
    (m), next memory (3 m + 4)].

    l_dot = J(p, R) [v; w] + s (gain e + integral_gain I + c(e)) (the drives' dead band made up,
    kinematics.dead_band_compensation; s the scale that keeps every correction within
    kinematics.MAX_CORRECTION, kinematics.add_scaled_corrections), e = l_d - L0, I its integral
    (m s, clipped so the term stays within MAX_INTEGRAL_SPEED): the twist through the m x 6
    Jacobian at the estimated pose plus the cable-length loop, a PI loop here so that the
    drives' stiction and lag leave no lasting length error (with 70 kN cables 0.1 mm is ~2 N of
    tension), and the drives' dead band (their Coulomb friction holds a reel commanded slower
    than dead_band) made up where the error asks for motion. l_d: the lengths of the commanded
    pose (p_d, R_ref) unstretched by the commanded tensions (`tension`: L EA / (EA + T)), else
    its rigid lengths plus the offsets delta latched at the first tick (the loop then starts
    with no error). p_d starts at the first tick's estimate and integrates v.

    With `tension`, the rate at which the commanded tensions unstretch l_d, L_d EA (1 / (EA
    + T) - 1 / (EA + T_previous)) / step, is fed forward beside the twist (after the
    warm-up): a tension command that ramps moves its lengths as it ramps, where through the
    loop alone it lagged by its rate over the gain (1000 N/s on a 2 m cable of 70 kN: 0.7 mm,
    25 N at 40 1/s) and was capped with the corrections (MAX_CORRECTION: ~1700 N/s)."""
    m = reels.shape[0]
    gain, integral_gain, step, EA = params[0], params[1], params[2], params[3]
    tension = params[4] != 0.0
    dead_band = params[5]
    warmup = params[6]
    p = x[0:3]
    R = x[3:12].reshape((3, 3))
    v = x[12:15]
    w = x[15:18]
    R_ref = x[18:27].reshape((3, 3))
    L0 = x[27:27 + m]
    T = x[27 + m:27 + 2 * m]
    mem = 27 + 2 * m
    ticks = x[mem + 2 * m + 3]
    started = ticks >= warmup
    limit = MAX_INTEGRAL_SPEED / integral_gain if integral_gain > 0.0 else 0.0
    u, Rb, L = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    posed_cables(reels, attachments, p, R, u, Rb, L)
    p_d = out[2 * m:2 * m + 3]
    for k in range(3):
        p_d[k] = x[mem + k] if started else p[k]
    ud, Rbd, Ld = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    posed_cables(reels, attachments, p_d, R_ref, ud, Rbd, Ld)
    twists = np.empty(m)
    T_previous = x[mem + 2 * m + 4:mem + 3 * m + 4]
    for i in range(m):
        feed = 0.0
        if tension:
            target = Ld[i] * EA / (EA + T[i])
            delta = 0.0
            if started:
                feed = Ld[i] * EA * (1.0 / (EA + T[i]) - 1.0 / (EA + T_previous[i])) / step
        else:
            delta = x[mem + 3 + i] if started else L0[i] - Ld[i]
            target = Ld[i] + delta
        out[4 * m + 4 + i] = T[i] if tension else 0.0
        out[2 * m + 3 + i] = delta
        out[m + i] = target
        twist = -(u[i, 0] * v[0] + u[i, 1] * v[1] + u[i, 2] * v[2]
                  + (Rb[i, 1] * u[i, 2] - Rb[i, 2] * u[i, 1]) * w[0]
                  + (Rb[i, 2] * u[i, 0] - Rb[i, 0] * u[i, 2]) * w[1]
                  + (Rb[i, 0] * u[i, 1] - Rb[i, 1] * u[i, 0]) * w[2])
        error = target - L0[i]
        integral = x[mem + 3 + m + i] + step * error if started else 0.0
        integral = min(limit, max(-limit, integral))
        out[3 * m + 3 + i] = integral
        out[i] = (gain * error + integral_gain * integral
                  + dead_band_compensation(dead_band, error))
        twists[i] = twist + feed
    add_scaled_corrections(twists, out)
    for k in range(3):
        p_d[k] += step * v[k]
    out[4 * m + 3] = min(ticks + 1.0, warmup)


@_jit
def posed_geometry(reels, attachments, pi, pj, R, geo):
    """The interference kernel's per-pair constants (interference.pair_geometry's layout:
    U = a_i - R b_i, V = a_j - R b_j, W = R (b_i - b_j), (U - V) x W) for orientation R."""
    for q in range(pi.shape[0]):
        i, j = pi[q], pj[q]
        for r in range(3):
            Ri = R[r, 0] * attachments[i, 0] + R[r, 1] * attachments[i, 1] + R[r, 2] * attachments[i, 2]
            Rj = R[r, 0] * attachments[j, 0] + R[r, 1] * attachments[j, 1] + R[r, 2] * attachments[j, 2]
            geo[q, r] = reels[i, r] - Ri
            geo[q, 3 + r] = reels[j, r] - Rj
            geo[q, 6 + r] = Ri - Rj
        ux, uy, uz = geo[q, 0] - geo[q, 3], geo[q, 1] - geo[q, 4], geo[q, 2] - geo[q, 5]
        wx, wy, wz = geo[q, 6], geo[q, 7], geo[q, 8]
        geo[q, 9] = uy * wz - uz * wy
        geo[q, 10] = uz * wx - ux * wz
        geo[q, 11] = ux * wy - uy * wx


@_jit
def interference_posed_tick(reels, attachments, pi, pj, par, floor, F_max, x, geo, out):
    """`interference.interference_tick` with the platform at (p, R): x = [p (3), R (9),
    previous side memory (P)]; geo (P, 12) scratch."""
    posed_geometry(reels, attachments, pi, pj, x[3:12].reshape((3, 3)), geo)
    interference_tick(geo, par, floor, F_max, x[0:3], x[12:], True, out)
