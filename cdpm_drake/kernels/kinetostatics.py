"""The kinetostatic limit (beyond the paper, which names it as future work in sections 2.3 and
6): at a pose, with the measured hand force at the handle and the platform's weight, can the
cables hold the platform with every tension between a floor and a ceiling? Its margin, the
margin's gradient, and the logistic cue the hand feels near it. numpy and numba, no Drake.

Base frame A, SI units; a pose is (p, R), R = R_WB. The margin at a pose is

    kappa = max over tensions T with W T + w = 0 of  min( min_i T_i - floor, ceiling - max_i T_i )

(N): kappa >= 0 exactly when a distribution with floor <= T_i <= ceiling balances the wrench
w (the weight and the hand force at the handle, moments about the centre). In the nullspace
form T = T_p + N lam it is the max-min of 2m lines (`tension.max_min_lines`). t_c = kappa +
floor is the largest minimum tension the cables can have under the ceiling; it is t* (the
statics' one measure, tension.py) wherever the ceiling does not bind.

A robot whose wrench matrix has rank 6 (six cables or more, attachment points that give
moments) is judged on the full wrench (`rows` 6); one with fewer or coplanar attachments can
only translate its platform (robot.py's validation says so) and is judged on the forces alone
(`rows` 3), the moments being the platform's own business.

The soft margin (a robot with mass: the full pose with tension control). The max-min has
kinks where the cable that binds changes, and its gradient jumps there; the safety filter's
barrier and the cue follow the gradient, so at a kink they turned the command within a few
ticks (an 8-26 tick steer or hold at the 2 m/s^2 acceleration limit), an impulse that rang
the platform's elastic modes until a cable went slack a quarter period later (dynamic plant,
20 N lifts and corner pulls on paper_7cable and long_8cable). The soft margin replaces the
minimum over the lines by the soft minimum -mu log sum exp(-line / mu), whose maximum over
lam is smooth: the gradient turns over a band of lines within a few mu of each other instead
of at once. It is below the hard margin by at most mu log 2m (conservative: a soft margin >= 0
has a hard one >= 0). The temperature mu (N) is the tension swing of the filter's own braking
onset, 2 m a_brake max_i |W^+_i| (`braking_swing`): the true tensions differ from the static
lines by that much whenever the filter brakes, so lines closer than it cannot be told apart
as "the one that binds" anyway.
"""

import math

import numba
import numpy as np

from cdpm_drake.kernels.pose import matrix_view, posed_cables, solve_spd, wrench_columns
from cdpm_drake.kernels.full_pose import held_wrench
from cdpm_drake.kernels.safety_filter import BARRIER_STATE, barrier_position
from cdpm_drake.kernels.nullspace import RANK_TOL, null_vector, particular_solution, pivoted_qr
from cdpm_drake.kernels.ray_bound import ray_floor, ray_work_size
from cdpm_drake.kernels.tension import max_min_1d, max_min_lines

_jit = numba.njit(cache=True, error_model="numpy")

# Finite-difference step of the margin's gradient, m: the margin is piecewise smooth (the
# lines that bind change), and round-off of the margin (1e-8 relative, the QP form of
# max_min_lines) stays below 1e-3 of a gradient of ~10 N/m.
FD_STEP_P = 1e-4
# At most this many Newton steps of the soft margin (soft_max_min_lines) from the hard
# maximiser; it converges in 2-5 where measured.
SOFT_ITERATIONS = 20


def ringing_deceleration(robot, p, rows: int, swing: float) -> float:
    """The largest step of the platform's acceleration (m/s^2) after which no cable's tension
    swings by more than `swing` (N), at the level platform at p: a step of the acceleration
    by da changes the cables' force by m da, which the tensions take up as W^+ m da
    (the wrench matrix's first `rows` rows, minimum-norm) and, the platform's modes being
    lightly damped, overshoot to twice that. Hence swing / (2 m max_i |W^+_i|) over the
    directions (the rows of W^+'s force columns). Measured on paper_7cable's exp2 (dynamic
    plant, no tension sensor): a braking onset of 1.1 m/s^2 took cable 2 from 6.6 to 0.53 N,
    as this predicts (5.6 N per m/s^2); inf for a robot without mass."""
    mass = float(robot.dynamics.mass)
    share = _force_share(robot, p, rows)
    if not (mass > 0.0 and share > 0.0):
        return math.inf
    return swing / (2.0 * mass * share)


def braking_swing(robot, p, rows: int, a: float) -> float:
    """The largest swing of a cable's tension (N) when the level platform at p starts
    braking at a (m/s^2): 2 m a max_i |W^+_i| (`ringing_deceleration`'s bound, inverted);
    0 for a robot without mass."""
    mass = float(robot.dynamics.mass)
    if not (mass > 0.0 and math.isfinite(a)):
        return 0.0
    return 2.0 * mass * _force_share(robot, p, rows) * float(a)


def geometry_tension_error(robot, p, rows: int, sigma, ceiling: float) -> float:
    """How far the cables' tensions computed on the file's geometry may be off the true ones,
    N, at the level platform at p, to first order, when each cable's line is known to sigma
    (m,) m and every tension is at most `ceiling` N: a line moved by sigma_j turns its unit
    vector by sigma_j / L_j, so the wrench of the tensions is off by at most sum_j ceiling
    sigma_j / L_j, which the tensions take up through W^+ (max_i |W^+_i| over the wrench
    matrix's first `rows` rows)."""
    from cdpm_drake.kernels.tension import wrench_matrix

    p = np.asarray(p, dtype=float)
    W = wrench_matrix(robot, p)[:rows]
    share = float(np.linalg.norm(np.linalg.pinv(W), axis=1).max())
    L = np.linalg.norm(robot.reels - (p + robot.attachments), axis=1)
    return share * float(np.sum(float(ceiling) * np.asarray(sigma, dtype=float) / L))


def _force_share(robot, p, rows: int) -> float:
    """max_i |W^+_i| over the force columns (N of tension per N of force on the platform, the
    level platform at p; the wrench matrix's first `rows` rows, minimum-norm)."""
    from cdpm_drake.kernels.tension import wrench_matrix

    W = wrench_matrix(robot, np.asarray(p, dtype=float))[:rows]
    return float(np.linalg.norm(np.linalg.pinv(W)[:, :3], axis=1).max())


def wrench_rows(robot) -> int:
    """6 when the robot's wrench matrix at its workspace centre (level platform) has rank 6,
    else 3 (a platform the cables can only translate: its statics on the forces alone)."""
    from cdpm_drake.kernels.tension import wrench_matrix

    W = wrench_matrix(robot, robot.workspace.center)
    s = np.linalg.svd(W, compute_uv=False)
    return 6 if s.size >= 6 and s[5] > RANK_TOL * s[0] else 3


@_jit
def soft_max_min_lines(a, C, lam, mu, work):
    """max over lam (k,) of the soft minimum -mu log sum_j exp(-(a_j + C_j . lam) / mu) of
    the lines (a (K,), C (K, k); temperature mu > 0, units of a), by Newton's method from
    lam, a maximiser of the hard max-min (`tension.max_min_lines`), which it overwrites with
    the soft one. The soft minimum is concave in lam and below the minimum, so the result is
    smooth in a and C and lies within [hard - mu log K, hard]. For a bounded max-min only (a
    floor and a ceiling line per cable). work: (lines (>= K,), wts (>= K,), g, trial, step
    (>= k,), H (>= k, >= k)), the caller's (no allocation); wts ends as the lines' softmax
    weights at the maximiser (`margin_gradient` reads them)."""
    K, k = C.shape
    lines, wts, g, trial, step, H = work
    lines, wts, g, trial, step, H = lines[:K], wts[:K], g[:k], trial[:k], step[:k], H[:k, :k]
    f = _soft_min(a, C, lam, mu, lines, wts)
    for _ in range(SOFT_ITERATIONS):
        for c in range(k):
            s = 0.0
            for j in range(K):
                s += wts[j] * C[j, c]
            g[c] = s
        for c in range(k):
            for e in range(k):
                s = 0.0
                for j in range(K):
                    s += wts[j] * C[j, c] * C[j, e]
                H[c, e] = (s - g[c] * g[e]) / mu
            H[c, c] += 1e-12
        if k == 0:
            break
        if k == 1:  # paper_7cable's case
            step[0] = g[0] / H[0, 0]
        elif not solve_spd(H, g, step):  # H: a weighted covariance, positive definite
            break
        gain = 0.0
        for c in range(k):
            gain += g[c] * step[c]
        if not gain > 1e-26 * mu:
            break
        if gain < 1e-8 * mu:
            # Newton's quadratic range: the full step gains gain / 2, below the soft
            # minimum's round-off, which a line search would take for a loss; the slope g it
            # removes is what margin_gradient's envelope theorem needs at zero.
            for c in range(k):
                lam[c] += step[c]
            f = _soft_min(a, C, lam, mu, lines, wts)
            continue
        t = 1.0
        for _ in range(30):
            for c in range(k):
                trial[c] = lam[c] + t * step[c]
            ft = _soft_min(a, C, trial, mu, lines, wts)
            if ft >= f:
                break
            t *= 0.5
        if not ft >= f:
            _soft_min(a, C, lam, mu, lines, wts)
            break
        for c in range(k):
            lam[c] = trial[c]
        f = ft
    return f


@_jit
def _soft_min(a, C, lam, mu, lines, wts):
    """The soft minimum of the lines at lam; their softmax weights into wts."""
    K, k = C.shape
    low = math.inf
    for j in range(K):
        s = a[j]
        for c in range(k):
            s += C[j, c] * lam[c]
        lines[j] = s
        low = min(low, s)
    total = 0.0
    for j in range(K):
        wts[j] = math.exp(-(lines[j] - low) / mu)
        total += wts[j]
    for j in range(K):
        wts[j] /= total
    return low - mu * math.log(total)


@_jit
def margin(reels, attachments, rows, p, R, w, floor, ceiling, scratch, soft=0.0):
    """(kappa, t*) at the pose (p, R) under the wrench w (6,) (module docstring): kappa the
    margin of the floor and ceiling (N; with soft > 0 the soft margin of that temperature,
    N: `soft_max_min_lines`), t* the largest achievable minimum tension without a
    ceiling (+inf where an internal force raises every tension). -inf for both where the
    wrench matrix's first `rows` rows are rank-deficient (a pose where the cables cannot
    produce some wrench: nothing holds there). scratch: `margin_scratch(m)`."""
    return margin_in(reels, attachments, rows, p, R, w, floor, ceiling,
                     scratch_views(scratch), soft)


# What margin_in computes: kappa, t* or both (the other is nan; each is a max-min of its own).
MARGIN_KAPPA, MARGIN_T_STAR, MARGIN_BOTH = 1, 2, 3


@_jit
def margin_in(reels, attachments, rows, p, R, w, floor, ceiling, views, soft=0.0,
              parts=MARGIN_BOTH):
    """`margin` on the work arrays already carved (`scratch_views`): a kernel that takes
    several margins a tick carves them once (carving costs ~1 us a call). parts: what to
    compute, MARGIN_KAPPA, MARGIN_T_STAR or MARGIN_BOTH (the one left out is nan): the look
    ahead needs kappa alone and the monitor t* alone, each the same numbers as with both."""
    u, Rb, L, W6, W, A, V, beta, perm, T_p, n, N, a, C, lam, lam2, C1 = views[:17]
    m = reels.shape[0]
    posed_cables(reels, attachments, p, R, u, Rb, L)
    wrench_columns(u, Rb, W6)
    if m < rows:
        return -math.inf, -math.inf
    Wr, Vr, br, pr = W[:rows], V[:rows], beta[:rows], perm[:rows]
    for r in range(rows):
        for i in range(m):
            Wr[r, i] = W6[r, i]
    if pivoted_qr(Wr, A, Vr, br, pr) < RANK_TOL:
        return -math.inf, -math.inf
    particular_solution(A, Vr, br, pr, w[:rows], T_p)
    k = m - rows
    for c in range(k):
        null_vector(Vr, br, n, c)
        for i in range(m):
            N[i, c] = n[i]
    kappa = t_star = math.nan
    if parts & MARGIN_KAPPA:
        for i in range(m):
            a[i] = T_p[i] - floor
            a[m + i] = ceiling - T_p[i]
            for c in range(k):
                C[i, c] = N[i, c]
                C[m + i, c] = -N[i, c]
        kappa = max_min_lines(a, C[:, :k], lam[:k])
        if soft > 0.0 and math.isfinite(kappa):
            kappa = soft_max_min_lines(a, C[:, :k], lam[:k], soft, views[17])
    if parts & MARGIN_T_STAR:
        t_star = max_min_lines(T_p, N[:, :k], lam2[:k])
    return kappa, t_star


def margin_scratch(m: int):
    """The work arrays of `margin`, `margin_gradient` and `kinetostatic_tick` for m cables,
    allocated once per block (a tick allocates nothing) as two flat buffers, floats and
    integers, that `scratch_views` carves: a call from Python unboxes each array argument
    (~0.1 us each, a tuple's members too), so two buffers cost what 36 arrays did not."""
    K = 2 * m
    size = (6 * m + 6 * m + m + 6 * m * 4 + 6 + 2 * m + m * m + K + K * m + 3 * m
            + 2 * K + 3 * m + m * m + K + (m + 1) * (m + 2) + 36 + 12 + (m + 1)
            + 3 + 9 + 6 + 3 + 3 + 3 + m + 3 + ray_work_size(m))
    ints = np.zeros(1 + 6 + m + 1 + m, dtype=np.int64)
    ints[0] = m
    return np.zeros(size), ints


@_jit
def _take(buf, o, r, c):
    return matrix_view(buf, o, r, c), o + r * c


@_jit
def _take1(buf, o, r):
    return buf[o:o + r], o + r


@_jit
def scratch_views(scratch):
    """The work arrays in `margin_scratch`'s buffers (views): u, Rb, L, W6, W, A, V, beta,
    perm, T_p, n, N, a, C, lam, lam2, C1 (margin's), then soft_max_min_lines' work,
    margin_gradient's and kinetostatic_tick's (tuples), the column order of
    `margin_by_elimination` and the look ahead's bound's work (T (m), e (3), then
    ray_bound.ray_floor's)."""
    buf, ints = scratch
    m = ints[0]
    K = 2 * m
    o = 0
    u, o = _take(buf, o, m, 3)
    Rb, o = _take(buf, o, m, 3)
    L, o = _take1(buf, o, m)
    W6, o = _take(buf, o, 6, m)
    W, o = _take(buf, o, 6, m)
    A, o = _take(buf, o, m, 6)
    V, o = _take(buf, o, 6, m)
    beta, o = _take1(buf, o, 6)
    T_p, o = _take1(buf, o, m)
    n, o = _take1(buf, o, m)
    N, o = _take(buf, o, m, m)
    a, o = _take1(buf, o, K)
    C, o = _take(buf, o, K, m)
    lam, o = _take1(buf, o, m)
    lam2, o = _take1(buf, o, m)
    C1, o = _take1(buf, o, m)
    lines, o = _take1(buf, o, K)
    wts, o = _take1(buf, o, K)
    g, o = _take1(buf, o, m)
    trial, o = _take1(buf, o, m)
    step, o = _take1(buf, o, m)
    H, o = _take(buf, o, m, m)
    y, o = _take1(buf, o, K)
    M, o = _take(buf, o, m + 1, m + 2)
    G, o = _take(buf, o, 6, 6)
    nu, o = _take1(buf, o, 6)
    rhs, o = _take1(buf, o, 6)
    sol, o = _take1(buf, o, m + 1)
    p, o = _take1(buf, o, 3)
    R, o = _take(buf, o, 3, 3)
    w, o = _take1(buf, o, 6)
    zero, o = _take1(buf, o, 3)
    q, o = _take1(buf, o, 3)
    grad, o = _take1(buf, o, 3)
    ray = buf[o:]
    perm = ints[1:7]
    J = ints[7:8 + m]
    cols = ints[8 + m:8 + 2 * m]
    return (u, Rb, L, W6, W, A, V, beta, perm, T_p, n, N, a, C, lam, lam2, C1,
            (lines, wts, g, trial, step, H), (y, M, J, G, nu, rhs, sol),
            (p, R, w, zero, q, grad), cols, ray)


# Lines within this of the hard margin (relative to 1 + |kappa|, N) are its active set: the
# one-cable max-min is exact to round-off, the QP form of k >= 2 to ~1e-8 relative.
ACTIVE_TOL = 1e-7


@_jit
def margin_gradient(scratch, rows, kappa, soft, grad):
    """The gradient (3,) N/m of the margin kappa of the last `margin` call on this scratch
    (finite, at the pose (p, R), wrench w, temperature soft) in the position p, written into
    grad. Exact, by the envelope theorem in the tensions: kappa is the max over T with
    W(p) T + w = 0 of g(T) (the soft or hard minimum of the 2m lines T_i - floor,
    ceiling - T_i), so d kappa / dp = nu . (dW/dp T*) at the maximiser T* with W^T nu =
    -dg/dT: dg/dT_i = y_i - y_(m+i), y the lines' weights (the softmax weights; for the hard
    margin the LP's multipliers, from its k + 1 active lines: sum_J y_j C_j = 0, sum y = 1).
    A column of W is [u_i; R b_i x u_i] with du_i/dp = -(I - u_i u_i^T) / L_i, hence
    grad = -sum_i T*_i / L_i (I - u_i u_i^T) (nu_f + nu_m x R b_i). False (grad unset) where
    the hard margin is not differentiable as far as its active set says (other than k + 1
    active lines, or multipliers not >= 0): a kink."""
    return margin_gradient_in(scratch_views(scratch), rows, kappa, soft, grad)


@_jit
def margin_gradient_in(views, rows, kappa, soft, grad):
    """`margin_gradient` on the carved work arrays (`margin_in`'s)."""
    u, Rb, L, W6 = views[0], views[1], views[2], views[3]
    T_p, N, a, C, lam = views[9], views[11], views[12], views[13], views[14]
    wts = views[17][1]
    y, M, J, G, nu, rhs, sol = views[18]
    m = u.shape[0]
    k = m - rows
    K = 2 * m
    if soft > 0.0:
        for j in range(K):
            y[j] = wts[j]
    else:
        tol = ACTIVE_TOL * (1.0 + abs(kappa))
        n = 0
        for j in range(K):
            y[j] = 0.0
            s = a[j]
            for c in range(k):
                s += C[j, c] * lam[c]
            if s - kappa <= tol:
                if n > k:
                    return False
                J[n] = j
                n += 1
        if n != k + 1:
            return False
        # [C_J^T; 1^T] y_J = [0; 1] by Gaussian elimination with partial pivoting.
        for r in range(k + 1):
            for c in range(k + 1):
                M[r, c] = C[J[c], r] if r < k else 1.0
            M[r, k + 1] = 1.0 if r == k else 0.0
        for c in range(k + 1):
            best = c
            for r in range(c + 1, k + 1):
                if abs(M[r, c]) > abs(M[best, c]):
                    best = r
            if not abs(M[best, c]) > 1e-12:
                return False
            for e in range(k + 2):
                M[c, e], M[best, e] = M[best, e], M[c, e]
            for r in range(c + 1, k + 1):
                f = M[r, c] / M[c, c]
                for e in range(c, k + 2):
                    M[r, e] -= f * M[c, e]
        for c in range(k, -1, -1):
            s = M[c, k + 1]
            for e in range(c + 1, k + 1):
                s -= M[c, e] * sol[e]
            sol[c] = s / M[c, c]
            if sol[c] < -1e-9:  # a multiplier < 0: not the LP's optimum as far as it says
                return False
        for c in range(k + 1):
            y[J[c]] = sol[c]
    # nu: (W W^T) nu = -W dg/dT, the tensions' gradient being in W's row space at T*.
    for r in range(rows):
        s = 0.0
        for i in range(m):
            s -= W6[r, i] * (y[i] - y[m + i])
        rhs[r] = s
        for e in range(rows):
            s = 0.0
            for i in range(m):
                s += W6[r, i] * W6[e, i]
            G[r, e] = s
    if not solve_spd(G[:rows, :rows], rhs[:rows], nu[:rows]):
        return False
    grad[0] = grad[1] = grad[2] = 0.0
    for i in range(m):
        t = T_p[i]
        for c in range(k):
            t += N[i, c] * lam[c]
        z0, z1, z2 = nu[0], nu[1], nu[2]
        if rows == 6:  # nu_m x R b_i
            z0 += nu[4] * Rb[i, 2] - nu[5] * Rb[i, 1]
            z1 += nu[5] * Rb[i, 0] - nu[3] * Rb[i, 2]
            z2 += nu[3] * Rb[i, 1] - nu[4] * Rb[i, 0]
        d = u[i, 0] * z0 + u[i, 1] * z1 + u[i, 2] * z2
        f = -t / L[i]
        grad[0] += f * (z0 - d * u[i, 0])
        grad[1] += f * (z1 - d * u[i, 1])
        grad[2] += f * (z2 - d * u[i, 2])
    return True


# The kinetostatic block's parameters (a flat array, `kinetostatic_params`).
P_MASS, P_HANDLE, P_FLOOR, P_CEILING, P_ROWS, P_BARRIER = 0, 1, 4, 5, 6, 7
P_T_L, P_T_U, P_F_U, P_B, P_MID, P_FORCE, P_A_BRAKE, P_T, P_RIPPLE, P_SMOOTHING, P_SOFT = \
    range(8, 19)
# kinetostatic_tick's input x: [p (3), F_H (3), the safety filter's barrier state (BARRIER_STATE:
# p_c (3), valid (1), v_prev (3)) at X_STATE, and for the full pose R (9) at X_R].
X_STATE = 6
X_R = X_STATE + BARRIER_STATE


def kinetostatic_params(robot, *, floor, ceiling, rows, barrier, t_l, t_u, F_u, eps,
                        force: bool, a_brake: float, time_step: float,
                        ripple: float = 0.0, smoothing: float = 0.0,
                        soft: float = 0.0) -> np.ndarray:
    """The kinetostatic block's parameters: the platform's mass (kg) and handle (m, platform
    frame), the floor and ceiling (N), the wrench rows (3 or 6), whether the safety filter's
    barrier needs the gradient and the look ahead, the cue's logistic t_l, t_u (N), F_u (N),
    its steepness b (1/N, eq. 28 in tensions) and centre (N), whether the cue is on, the
    deceleration the filter brakes with (m/s^2), the time step (s), the floor's rise per
    newton of hand (N/N), the filter's position_smoothing (s: the margin is evaluated
    where the filter evaluates its barriers, safety_filter.barrier_position) and the soft
    margin's temperature (N; 0: the hard margin; the module docstring says why)."""
    b = 2.0 * math.log((F_u - eps) / eps) / (t_l - t_u)
    d = robot.dynamics
    return np.array([d.mass, *d.handle, floor, ceiling, rows, 1.0 if barrier else 0.0,
                     t_l, t_u, F_u, b, 0.5 * (t_l + t_u), 1.0 if force else 0.0, a_brake,
                     time_step, ripple, smoothing, soft], dtype=float)


@_jit
def cue_intensity(t_c, params):
    """The cue's intensity (N) at t_c = kappa + floor (N): the paper's logistic (eqs. 26-28)
    in tensions, F_u - eps at t_l, eps at t_u, and zero above t_u (as the paper's force is
    zero above d_u)."""
    if not t_c <= params[P_T_U]:
        return 0.0
    return params[P_F_U] / (1.0 + math.exp(min(params[P_B] * (params[P_MID] - t_c), 700.0)))


# kinetostatic_tick's output layout: F_kin (3, N), kappa (N), its gradient (3, N/m), t_c (N),
# t* (N), status (0: finite; 1: a pose the cables cannot hold at all), the look ahead (m).
KIN_OUT = 11
# The look ahead samples the stopping distance at this many points, then bisects this often.
RAY_SAMPLES = 4
RAY_BISECTIONS = 5
# The look ahead looks for the margin falling below min(kappa, 0) by more than this (N): a
# drop at a kink, not the slow fall of a curved limit that the gradient's row follows tick by
# tick; it then ends where the margin first falls below min(kappa, 0). Looking for a fall
# below 0 alone, a platform sliding along the limit (kappa = +-1e-6 N) saw a drop right ahead
# on every tick with kappa >= 0 and none with kappa < 0: it braked and sped up in turn, a 5 Hz
# cycle of 5-135 mm/s that rang the dynamic plant's yaw mode (a 20 N lift on exp2: 2082
# slack ticks in 10 s).
RAY_TOLERANCE = 0.5


@_jit
def _margin_at(reels, attachments, params, views, p, R, w, floor):
    rows = int(params[P_ROWS])
    if params[P_SOFT] == 0.0 and reels.shape[0] == rows + 1:
        return margin_by_elimination(reels, attachments, rows, p, R, w, floor,
                                     params[P_CEILING], views)
    return margin_in(reels, attachments, rows, p, R, w, floor, params[P_CEILING], views,
                     params[P_SOFT], MARGIN_KAPPA)[0]


@_jit
def margin_by_elimination(reels, attachments, rows, p, R, w, floor, ceiling, views):
    """The hard margin kappa of `margin` for a robot with one internal force (m = rows + 1),
    by Gaussian elimination with complete pivoting instead of the pivoted QR: the margin
    is the max-min of the lines over the line of tensions {T: W T = -w}, whichever point
    T_p and direction n describe it (max_min_1d is exact and invariant to both), and the
    elimination costs a quarter of the QR's flops. Equal to `margin`'s kappa to round-off
    (1e-9 relative where tested); -inf where the elimination's last pivot is below RANK_TOL
    of its first (as the QR's rank test, on the same matrix). The look ahead's samples."""
    if not tension_line(reels, attachments, rows, p, R, w, views):
        return -math.inf
    T_p, a, C, lam = views[9], views[12], views[13], views[14]
    m = reels.shape[0]
    for i in range(m):
        a[i] = T_p[i] - floor
        a[m + i] = ceiling - T_p[i]
        C[i, 0] = lam[i]
        C[m + i, 0] = -lam[i]
    return max_min_1d(a[:2 * m], C[:2 * m, 0])[0]


# Inlined where it is called (numba's IR): a call passes the work arrays' tuple by value, its
# ~35 arrays' fields copied (3.6 k instructions a tick more in the look ahead, measured).
@numba.njit(cache=True, error_model="numpy", inline="always")
def tension_line(reels, attachments, rows, p, R, w, views):
    """The line of tensions {T: W T = -w} of a robot with one internal force (m = rows + 1)
    at the pose (p, R), by Gaussian elimination with complete pivoting of W's first `rows`
    rows: a point into T_p (views[9]: the free cable at zero) and a direction into lam
    (views[14]: the free cable at one), the cables posed in views[:3] (L in views[2]).
    False where the elimination's last pivot is below RANK_TOL of its first (as the QR's
    rank test, on the same matrix): nothing holds there."""
    u, Rb, L, W6, W = views[0], views[1], views[2], views[3], views[4]
    beta, T_p, n, lam, x = views[7], views[9], views[10], views[14], views[16]
    cols = views[20]
    m = reels.shape[0]
    posed_cables(reels, attachments, p, R, u, Rb, L)
    wrench_columns(u, Rb, W6)
    for r in range(rows):  # [W | -w] in W and beta, eliminated in place
        for i in range(m):
            W[r, i] = W6[r, i]
        beta[r] = -w[r]
    for i in range(m):
        cols[i] = i
    first = 0.0
    for k in range(rows):
        bi, bj, big = k, k, -1.0
        for i in range(k, rows):
            for j in range(k, m):
                if abs(W[i, j]) > big:
                    bi, bj, big = i, j, abs(W[i, j])
        if k == 0:
            first = big
        if not big > RANK_TOL * first:
            return False
        if bi != k:
            for j in range(m):
                W[k, j], W[bi, j] = W[bi, j], W[k, j]
            beta[k], beta[bi] = beta[bi], beta[k]
        if bj != k:
            for i in range(rows):
                W[i, k], W[i, bj] = W[i, bj], W[i, k]
            cols[k], cols[bj] = cols[bj], cols[k]
        for i in range(k + 1, rows):
            f = W[i, k] / W[k, k]
            for j in range(k, m):
                W[i, j] -= f * W[k, j]
            beta[i] -= f * beta[k]
    # T_p: the free cable at zero; n: the free cable at one, the others by back substitution.
    for i in range(rows - 1, -1, -1):
        s, t = beta[i], -W[i, rows]
        for j in range(i + 1, rows):
            s -= W[i, j] * x[j]
            t -= W[i, j] * n[j]
        x[i] = s / W[i, i]
        n[i] = t / W[i, i]
    for i in range(rows):
        T_p[cols[i]] = x[i]
        lam[cols[i]] = n[i]
    T_p[cols[rows]] = 0.0
    lam[cols[rows]] = 1.0
    return True


@_jit
def _ray_floor(views, rows, v, speed, reach, kappa, soft, floor, ceiling):
    """ray_bound.ray_floor on the margin just computed (`margin_in`'s work arrays: the
    cables posed at p, the maximiser T_p + N lam) along v / speed."""
    u, Rb, L, T_p, N, lam, ray = views[0], views[1], views[2], views[9], views[11], \
        views[14], views[21]
    m = u.shape[0]
    T, e = ray[:m], ray[m:m + 3]
    for i in range(m):
        t = T_p[i]
        for c in range(m - rows):
            t += N[i, c] * lam[c]
        T[i] = t
    for c in range(3):
        e[c] = v[c] / speed
    return ray_floor(u, Rb, L, T, rows, e, reach, kappa, soft, floor, ceiling, ray[m + 3:])


@_jit
def gradient_by_differences(reels, attachments, params, views, p, R, w, floor, kappa, q,
                            out):
    """kappa's forward differences (FD_STEP_P) in p into out[4:7] (0 where the step leaves
    the poses the cables can hold)."""
    for k in range(3):
        for c in range(3):
            q[c] = p[c]
        q[k] += FD_STEP_P
        # By the QR, as kappa: a difference of two methods' round-off over 0.1 mm is noise.
        kq = margin_in(reels, attachments, int(params[P_ROWS]), q, R, w, floor,
                       params[P_CEILING], views, params[P_SOFT], MARGIN_KAPPA)[0]
        out[4 + k] = (kq - kappa) / FD_STEP_P if math.isfinite(kq) else 0.0


@_jit
def kinetostatic_tick(reels, attachments, params, scratch, x, out):
    """One tick of the kinetostatic block. x = [p (3) m: the estimate, F_H (3) N, the
    safety filter's memory (BARRIER_STATE: p_c m, valid, v m/s the velocity commanded last),
    and for the full pose R (9, R_WB row-major: the orientation held); else the platform is
    level]. The pose is the filter's (safety_filter.barrier_position of p on that memory).
    Writes (KIN_OUT) the margin kappa at the pose under the
    weight and the hand force F_H at the handle, t_c = kappa + floor, t* (no ceiling), and
    the cue F_kin = intensity(t_c) grad / |grad| (N, base frame) towards more margin; for the
    safety filter's barrier also kappa's gradient in the position (`margin_gradient`, exact;
    forward differences of 0.1 mm at a kink of the hard margin) and the look ahead: where the margin drops (below min(kappa, 0) by more than
    RAY_TOLERANCE) along v within the distance the filter needs to stop from |v|, how far it
    stays >= min(kappa, 0) (inf: no drop).

    Why the look ahead: kappa is a max-min of lines, piecewise smooth with kinks where the
    binding cables change, and the ceiling gives it ridges; near a kink the gradient says
    nothing of the drop beyond it. A platform pushed along another barrier at 0.47 m/s met
    such a drop (kappa from +3.5 to -1.4 N in 0.2 s, the braking curve on the gradient being
    too late) and ended where kappa has a local maximum below zero, from which no gradient
    leads back (dynamic plant, 40 N along the 1-3 boundary). Sampling ahead along the
    velocity sees the drop before the platform is in it. Where a bound from this pose's own
    solution proves that no sample can drop (ray_bound.py: most ticks of exp2, 500 of 500
    on ticks 500-1000 on either plant), the samples are not taken: the result is the same,
    inf, for ~6 k instructions instead of the samples' ~38 k (hard margin) or ~110 k (soft)."""
    views = scratch_views(scratch)  # carved once a tick
    p, R, w, zero, q, grad = views[19]
    barrier_position(x[0:3], x[X_STATE:X_R], params[P_T], params[P_SMOOTHING], p)
    F = x[3:6]
    full = x.shape[0] >= X_R + 9
    for a in range(3):
        for b in range(3):
            R[a, b] = x[X_R + 3 * a + b] if full else (1.0 if a == b else 0.0)
    floor = params[P_FLOOR] + params[P_RIPPLE] * math.sqrt(F[0] * F[0] + F[1] * F[1]
                                                         + F[2] * F[2])
    held_wrench(R, params[P_MASS:P_MASS + 4], F, zero, w)
    kappa, t_star = margin_in(reels, attachments, int(params[P_ROWS]), p, R, w, floor,
                              params[P_CEILING], views, params[P_SOFT])
    for k in range(KIN_OUT):
        out[k] = 0.0
    out[3] = kappa
    out[7] = kappa + floor
    out[8] = t_star
    out[10] = math.inf
    if not math.isfinite(kappa):
        out[9] = 1.0
        return
    v = x[X_STATE + 4:X_STATE + 7]
    speed = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    look = params[P_BARRIER] != 0.0 and speed > 1e-9
    # A drop is where the margin falls below `level` by more than RAY_TOLERANCE; the look
    # ahead then ends where it first falls below `level` (RAY_TOLERANCE above).
    level = min(kappa, 0.0)
    a, T = params[P_A_BRAKE], params[P_T]
    # The distance to stop from |v| at a (braking curve) plus two ticks and 5 mm.
    reach = speed * speed / (2.0 * a) + 2.0 * speed * T + 0.005
    # Whether no sample can drop (ray_bound.py): decided on this pose's solution, which the
    # gradient's differences (at a kink) would overwrite.
    clear = look and _ray_floor(views, int(params[P_ROWS]), v, speed, reach, kappa,
                                params[P_SOFT], floor,
                                params[P_CEILING]) >= level - RAY_TOLERANCE
    if params[P_BARRIER] != 0.0 or params[P_FORCE] != 0.0:
        if margin_gradient_in(views, int(params[P_ROWS]), kappa, params[P_SOFT], grad):
            out[4], out[5], out[6] = grad[0], grad[1], grad[2]
        else:  # a kink of the hard margin: forward differences (one-sided, as before)
            gradient_by_differences(reels, attachments, params, views, p, R, w, floor,
                                    kappa, q, out)
    if params[P_FORCE] != 0.0:
        gx, gy, gz = out[4], out[5], out[6]
        g = math.sqrt(gx * gx + gy * gy + gz * gz)
        if g > 0.0:
            alpha = cue_intensity(kappa + params[P_FLOOR], params)
            out[0], out[1], out[2] = alpha * gx / g, alpha * gy / g, alpha * gz / g
    if not look or clear:
        return
    lo, hi, drop = 0.0, -1.0, False
    for k in range(1, RAY_SAMPLES + 1):
        s = reach * k / RAY_SAMPLES
        for c in range(3):
            q[c] = p[c] + s * v[c] / speed
        m = _margin_at(reels, attachments, params, views, q, R, w, floor)
        if hi < 0.0 and not m >= level:
            hi = s
        if not m >= level - RAY_TOLERANCE:
            drop = True
            break
        if hi < 0.0:
            lo = s
    if not drop:
        return
    for _ in range(RAY_BISECTIONS):
        s = 0.5 * (lo + hi)
        for c in range(3):
            q[c] = p[c] + s * v[c] / speed
        if _margin_at(reels, attachments, params, views, q, R, w, floor) >= level:
            lo = s
        else:
            hi = s
    out[10] = lo
