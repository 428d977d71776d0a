"""The full-pose controller's per-tick math (controller.pose: full, tension_control): compiled
kernels, one per block, each on one stacked input vector as the blocks' C++ wiring delivers it.
numpy and numba, no Drake. Beyond the paper, whose platform only translates.

Base frame A, SI units. A pose is (p, R): p the platform centre (m), R = R_WB stored row-major
as 9 floats. Tensions in N, lengths in m.

- `pose_fk_tick` (forward_kinematics): the pose whose rigid lengths best fit the encoders'
  lengths L0 corrected for the cables' modelled stretch under the last tension estimate,
  l_i = L0_i (1 + T_i / EA); and the fit's residual.
- `tension_tick` (tension_distribution): the target distribution T* at the estimated pose for
  the platform's weight, the measured hand force at the handle and the commanded acceleration
  (floor `min_tension`, lowered to t* where the pose allows no more); and the tension ESTIMATE:
  with one more cable than degrees of freedom the fit's residual along the wrench matrix's
  nullspace n is the one thing a pose cannot explain, the internal tension. From
  r = lengths(pose) - l and l = L0 + D T_assumed (D = diag(L0 / EA)), n . D T = n . D T_assumed
  + n . r; the true T = T_p + lam n balances the same wrench (T_p the minimum-norm one), so
  lam = (n . D (T_assumed - T_p) + n . r) / (n . D n). A slow integral on lam* - lam (the
  target's internal level minus the measured one) trims the commanded tensions, so a wrong
  cable stiffness or a length offset cannot leave the internal tension off its target.
- `orientation_tick` (orientation_hold): an angular-velocity command back to the orientation
  held (latched at the first tick), w = K_R log(R_ref R^T).
- `pose_rates_tick` (jacobian_mapping): l_dot = J(p, R) [v; w] + K_l (l_d - L0), with l_d the
  unstretched lengths of the commanded pose (p_d, R_ref) under the commanded tensions
  (tension control) or its rigid lengths plus the offsets latched at the first tick.
- `interference_posed_tick` (interference_force): the paper's interference tick on the cables
  of the estimated pose, attachment points at p + R b_i.
"""

import math

import numba
import numpy as np

from .interference import interference_tick
from .pose import _solve6, pose_fk, posed_cables, rotation_log, wrench_columns
from .tension import (BELOW_FLOOR, FEASIBLE, GENERAL, GRAVITY, RANK_TOL, _null_vector,
                      _particular, _pivoted_qr, distribution_1d)

_jit = numba.njit(cache=True, error_model="numpy")

# pose_fk_tick's status.
FK_OK, FK_NOT_SETTLED, FK_INCONSISTENT = 0, 1, 2
# The internal-tension trim is clipped to this, N: it corrects model errors, not the target.
MAX_TRIM = 50.0


def sizes(m: int) -> dict:
    """Input (x) and output (out) sizes of the kernels for m cables, and their memories."""
    return {
        "fk_x": 2 * m + 12, "fk_out": 15 + m,
        "tension_x": 4 * m + 23, "tension_out": 5 * m + 7, "tension_memory": 2 * m + 5,
        "orientation_x": 19, "orientation_out": 22, "orientation_memory": 10,
        "rates_x": 4 * m + 31, "rates_out": 4 * m + 4, "rates_memory": 2 * m + 4,
    }


@_jit
def _rpy(R, out):
    """roll, pitch, yaw (rad) of R = Rz(yaw) Ry(pitch) Rx(roll) into out (3,)."""
    out[0] = math.atan2(R[2, 1], R[2, 2])
    out[1] = -math.asin(min(1.0, max(-1.0, R[2, 0])))
    out[2] = math.atan2(R[1, 0], R[0, 0])


@_jit
def pose_fk_tick(reels, attachments, EA, max_residual, x, out):
    """x = [L0 (m), T_assumed (m), p_previous (3), R_previous (9)]; out = [p (3), R (9),
    rpy (3), residual (m)]. EA (N) <= 0 turns the stretch correction off. Returns FK_OK,
    FK_NOT_SETTLED, or FK_INCONSISTENT when the best fit leaves a residual above
    max_residual (m) on some cable (out then holds that fit)."""
    m = reels.shape[0]
    lengths = np.empty(m)
    for i in range(m):
        lengths[i] = x[i] * (1.0 + x[m + i] / EA) if EA > 0.0 else x[i]
    p = out[0:3]
    R = out[3:12].reshape((3, 3))
    residual = out[15:15 + m]
    p_guess = x[2 * m:2 * m + 3]
    R_guess = x[2 * m + 3:2 * m + 12].reshape((3, 3))
    if not pose_fk(reels, attachments, lengths, p_guess, R_guess, 1e-10, 8, p, R, residual):
        # Lengths far from any pose (slack or overstretched cables) slow Gauss-Newton down to
        # a linear rate: more steps, and a looser step at which it counts as settled.
        if not pose_fk(reels, attachments, lengths, p_guess, R_guess, 1e-8, 50, p, R,
                       residual):
            return FK_NOT_SETTLED
    _rpy(R, out[12:15])
    for i in range(m):
        if not abs(residual[i]) <= max_residual:
            return FK_INCONSISTENT
    return FK_OK


@_jit
def tension_tick(reels, attachments, params, x, out):
    """params = [mass kg, handle (3, m, platform frame), EA N, floor N, trim gain 1/s, time
    step s, slew rate N/s]. x = [p (3), R (9), F_H (3), v (3), residual (m), L0 (m), memory:
    T_assumed (m), v_previous (3), trim (1), started (1), T_command_previous (m)]. out =
    [T_command (m), T_estimate (m), T_target (m), t* (1), status (1), next memory (2 m + 5)]:
    T_target the distribution, T_command the target plus the internal trim, moved towards
    at the slew rate. status:
    FEASIBLE, BELOW_FLOOR (the floor lowered to t*) or GENERAL (not one redundant cable:
    T_command and the estimate are the minimum-norm distribution, nothing is controlled).
    The command moves towards the target at most `slew rate` N/s per cable, from the
    estimate at the first tick: the plant's tensions when the controller takes over are
    whatever they are, and a jump to the target would shake the platform."""
    m = reels.shape[0]
    mass, EA, floor, gain, step = params[0], params[4], params[5], params[6], params[7]
    p = x[0:3]
    R = x[3:12].reshape((3, 3))
    F = x[12:15]
    v = x[15:18]
    r = x[18:18 + m]
    L0 = x[18 + m:18 + 2 * m]
    mem = 18 + 2 * m
    T_assumed = x[mem:mem + m]
    v_prev = x[mem + m:mem + m + 3]
    trim = x[mem + m + 3]
    started = x[mem + m + 4] != 0.0
    T_before = x[mem + m + 5:mem + 2 * m + 5]
    max_change = params[8] * step
    u, Rb, L = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    posed_cables(reels, attachments, p, R, u, Rb, L)
    W = np.empty((6, m))
    wrench_columns(u, Rb, W)
    # The wrench the cables must balance: weight, hand force at the handle, and the
    # commanded acceleration's inertia (d'Alembert).
    hx = R[0, 0] * params[1] + R[0, 1] * params[2] + R[0, 2] * params[3]
    hy = R[1, 0] * params[1] + R[1, 1] * params[2] + R[1, 2] * params[3]
    hz = R[2, 0] * params[1] + R[2, 1] * params[2] + R[2, 2] * params[3]
    w = np.empty(6)
    for k in range(3):
        a = (v[k] - v_prev[k]) / step if started else 0.0
        w[k] = F[k] - mass * a
    w[2] -= mass * GRAVITY
    w[3] = hy * F[2] - hz * F[1]
    w[4] = hz * F[0] - hx * F[2]
    w[5] = hx * F[1] - hy * F[0]
    T_cmd = out[0:m]
    T_est = out[m:2 * m]
    T_target = out[2 * m:3 * m]
    nxt = 3 * m + 2
    status, t_star = GENERAL, math.nan
    new_trim = 0.0
    A, V = np.empty((m, 6)), np.empty((6, m))
    beta, perm = np.empty(6), np.empty(6, dtype=np.int64)
    T_p, n = np.empty(m), np.empty(m)
    if m == 7 and _pivoted_qr(W, A, V, beta, perm) >= RANK_TOL:
        _particular(A, V, beta, perm, w, T_p)
        _null_vector(V, beta, n)
        status, t_star = distribution_1d(T_p, n, floor, T_target)
        num = den = target = 0.0
        for i in range(m):
            d = L0[i] / EA
            num += n[i] * (d * (T_assumed[i] - T_p[i]) + r[i])
            den += n[i] * n[i] * d
            target += n[i] * T_target[i]
        lam = num / den
        for i in range(m):
            T_est[i] = T_p[i] + lam * n[i]
        if started:
            new_trim = min(MAX_TRIM, max(-MAX_TRIM, trim + step * gain * (target - lam)))
        for i in range(m):
            T_cmd[i] = T_target[i] + new_trim * n[i]
    else:
        # No single redundant cable: the minimum-norm distribution by the normal equations.
        G = np.empty((6, 6))
        for a in range(6):
            for b in range(6):
                s = 0.0
                for i in range(m):
                    s += W[a, i] * W[b, i]
                G[a, b] = s
        minus_w, y = np.empty(6), np.zeros(6)
        for a in range(6):
            minus_w[a] = -w[a]
        if not (m >= 6 and _solve6(G, minus_w, y)):
            for a in range(6):
                y[a] = 0.0
        lowest = math.inf
        for i in range(m):
            s = 0.0
            for a in range(6):
                s += W[a, i] * y[a]
            T_cmd[i] = s
            T_est[i] = s
            T_target[i] = s
            lowest = min(lowest, s)
        t_star = lowest
    for i in range(m):
        before = T_before[i] if started else T_est[i]
        T_cmd[i] = min(before + max_change, max(before - max_change, T_cmd[i]))
    out[3 * m] = t_star
    out[3 * m + 1] = status
    for i in range(m):
        out[nxt + i] = T_est[i]
        out[nxt + m + 5 + i] = T_cmd[i]
    for k in range(3):
        out[nxt + m + k] = v[k]
    out[nxt + m + 3] = new_trim
    out[nxt + m + 4] = 1.0
    return status


@_jit
def orientation_tick(gain, x, out):
    """x = [R (9), memory: R_ref (9), started (1)]; out = [w (3) rad/s, R_ref (9), next memory
    (10)]. The orientation held is the first tick's; w = gain log(R_ref R^T) turns the platform
    back to it at `gain` 1/s."""
    R = x[0:9].reshape((3, 3))
    started = x[18] != 0.0
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
    out[21] = 1.0


# The length loop's integral term may add at most this reel speed, m/s: enough to break the
# drives' stiction and take up their lag, never a runaway after a long stall.
MAX_INTEGRAL_SPEED = 0.05
# The drives' dead band is compensated to this fraction (a drive whose friction the robot
# file overstates would otherwise hunt), and switched in smoothly over this length error, m.
FRICTION_SHARE = 0.9
FRICTION_ERROR = 2e-5


def drive_dead_band(dynamics) -> float:
    """The reel speed command (m/s of cable) below which a drive at rest does not move:
    its Coulomb friction over its velocity loop's gain (robot file reel_drives:
    coulomb_friction / (bandwidth x inertia); systems/dynamic_plant.reel_step's law)."""
    return float(dynamics.coulomb_friction) / (float(dynamics.bandwidth)
                                               * float(dynamics.reel_inertia))


@_jit
def pose_rates_tick(reels, attachments, params, x, out):
    """params = [gain 1/s, integral_gain 1/s^2, step s, EA N, tension (0 or 1), dead band
    m/s]. x = [p (3), R (9), v (3), w (3), R_ref (9), L0 (m), T_command (m), memory: p_d
    (3), delta (m), integral (m), started (1)]; out = [l_dot (m), l_d (m), next memory
    (2 m + 4)].

    l_dot = J(p, R) [v; w] + gain e + integral_gain I + FRICTION_SHARE dead_band
    tanh(e / FRICTION_ERROR), e = l_d - L0, I its integral (m s, clipped so the term stays
    within MAX_INTEGRAL_SPEED): the twist through the m x 6
    Jacobian at the estimated pose plus the cable-length loop, a PI loop here so that the
    drives' stiction and lag leave no lasting length error (with 70 kN cables 0.1 mm is ~2 N
    of tension), and the drives' dead band (their Coulomb friction holds a reel commanded
    slower than dead_band) made up where the error asks for motion. l_d: the lengths of the
    commanded pose (p_d, R_ref) unstretched by the
    commanded tensions (`tension`: L EA / (EA + T)), else its rigid lengths plus the offsets
    delta latched at the first tick (the loop then starts with no error). p_d starts at the
    first tick's estimate and integrates v."""
    m = reels.shape[0]
    gain, integral_gain, step, EA = params[0], params[1], params[2], params[3]
    tension = params[4] != 0.0
    friction = FRICTION_SHARE * params[5]
    p = x[0:3]
    R = x[3:12].reshape((3, 3))
    v = x[12:15]
    w = x[15:18]
    R_ref = x[18:27].reshape((3, 3))
    L0 = x[27:27 + m]
    T = x[27 + m:27 + 2 * m]
    mem = 27 + 2 * m
    started = x[mem + 2 * m + 3] != 0.0
    limit = MAX_INTEGRAL_SPEED / integral_gain if integral_gain > 0.0 else 0.0
    u, Rb, L = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    posed_cables(reels, attachments, p, R, u, Rb, L)
    p_d = out[2 * m:2 * m + 3]
    for k in range(3):
        p_d[k] = x[mem + k] if started else p[k]
    ud, Rbd, Ld = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    posed_cables(reels, attachments, p_d, R_ref, ud, Rbd, Ld)
    for i in range(m):
        if tension:
            target = Ld[i] * EA / (EA + T[i])
            delta = 0.0
        else:
            delta = x[mem + 3 + i] if started else L0[i] - Ld[i]
            target = Ld[i] + delta
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
        out[i] = (twist + gain * error + integral_gain * integral
                  + friction * math.tanh(error / FRICTION_ERROR))
    for k in range(3):
        p_d[k] += step * v[k]
    out[4 * m + 3] = 1.0


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
