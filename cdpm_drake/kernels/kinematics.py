"""Loop-closure kinematics of a translating CDPM (paper eqs. 1-3). numpy and numba, no Drake.

Every function takes one platform position p (3,) or a batch (N, 3), base frame, m, and
returns arrays with the same leading batch shape. `robot` is any object with the fields read
here (a robot.Robot): `reels` and `attachments` (m, 3) m, `num_cables`, `workspace` (its
`center`, m) and `name`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


class KinematicsError(RuntimeError):
    """Forward kinematics failed: lengths inconsistent with the robot, or no convergence."""


def cable_vectors(robot, p) -> np.ndarray:
    """rho_i = p + b_i - a_i (eq. 1), from reel exit A_i to attachment B_i; (..., m, 3), m."""
    p = np.asarray(p, dtype=float)
    return p[..., None, :] + robot.attachments - robot.reels


def cable_lengths(robot, p) -> np.ndarray:
    """||rho_i|| (eq. 2); (..., m), m."""
    return _batch(robot, p, 1)


def jacobian(robot, p) -> np.ndarray:
    """J with l_dot = J @ p_dot (eq. 3): row i is rho_i^T / ||rho_i||; (..., m, 3)."""
    return _batch(robot, p, 3)


def _batch(robot, p, width):
    """cable_lengths (width 1) or jacobian (width 3) by the compiled kernel, any batch shape."""
    p = np.asarray(p, dtype=float)
    m = robot.num_cables
    q = np.ascontiguousarray(p.reshape(-1, 3))
    out = np.empty((q.shape[0], m, width))
    _cable_kernel(np.ascontiguousarray(robot.attachments - robot.reels), q, out)
    shape = p.shape[:-1] + ((m,) if width == 1 else (m, 3))
    return out.reshape(shape)


@_jit
def _cable_kernel(offsets, p, out):
    """Per row of p (N, 3): lengths ||p + b_i - a_i|| (out width 1) or unit rows (width 3)."""
    for k in range(p.shape[0]):
        for i in range(offsets.shape[0]):
            x = p[k, 0] + offsets[i, 0]
            y = p[k, 1] + offsets[i, 1]
            z = p[k, 2] + offsets[i, 2]
            n = math.sqrt(x * x + y * y + z * z)
            if out.shape[2] == 1:
                out[k, i, 0] = n
            else:
                out[k, i, 0], out[k, i, 1], out[k, i, 2] = x / n, y / n, z / n


@_jit
def reel_rates(offsets, p, v, out):
    """l_dot = J(p) v (eq. 3) into out (m,), m/s: offsets (m, 3) = b_i - a_i, p (3,) m,
    v (3,) m/s. The Jacobian block's tick."""
    for i in range(offsets.shape[0]):
        x, y, z = p[0] + offsets[i, 0], p[1] + offsets[i, 1], p[2] + offsets[i, 2]
        n = math.sqrt(x * x + y * y + z * z)
        out[i] = (x * v[0] + y * v[1] + z * v[2]) / n


def forward_kinematics(robot, lengths, p_guess=None, tol: float = 1e-10,
                       max_iterations: int = 50, max_residual: float = 1e-6) -> np.ndarray:
    """Platform position p (base frame, m) whose cable lengths match `lengths` (m).

    Levenberg-Marquardt on r(p) = ||p + b_i - a_i|| - l_i, started from `p_guess` (default:
    the workspace centre). Converged when the step is below `tol` m. Raises KinematicsError
    naming the residual when the lengths are inconsistent with the robot (the best fit leaves
    a residual above `max_residual` m) or the iteration does not converge.
    """
    lengths = np.asarray(lengths, dtype=float)
    single = lengths.ndim == 1
    L = np.atleast_2d(lengths)
    m = robot.num_cables
    if L.shape[-1] != m:
        raise KinematicsError(f"expected {m} cable lengths for robot {robot.name!r}, "
                              f"got {L.shape[-1]}")
    bad = ~np.isfinite(L)
    if bad.any():
        row, cable = np.argwhere(bad)[0]
        raise KinematicsError(f"cable {cable + 1} length is {L[row, cable]!r} m, "
                              "not a finite number")
    if single and p_guess is not None:
        # The control loop's case: one position, warm-started a tick away. Plain Gauss-Newton
        # converges in two or three steps; anything harder falls through to the damped solver.
        p = np.empty(3)
        if gauss_newton_warm(np.ascontiguousarray(robot.attachments - robot.reels), lengths,
                             np.asarray(p_guess, dtype=float), tol, float(max_residual),
                             min(8, max_iterations), p):
            return p
    if p_guess is None:
        p = np.broadcast_to(robot.workspace.center, (L.shape[0], 3)).copy()
    else:
        p = np.array(np.broadcast_to(np.asarray(p_guess, dtype=float), (L.shape[0], 3)))
    offsets = robot.attachments - robot.reels  # (m, 3)
    lam = np.full(L.shape[0], 1e-6)
    eye = np.eye(3)

    def residual(q):
        rho = q[:, None, :] + offsets
        n = np.linalg.norm(rho, axis=-1)
        return rho, n, n - L

    rho, n, r = residual(p)
    cost = np.einsum("ij,ij->i", r, r)
    converged = np.zeros(L.shape[0], dtype=bool)
    for _ in range(max_iterations):
        J = rho / np.maximum(n, 1e-300)[..., None]
        JtJ = np.einsum("nki,nkj->nij", J, J)
        Jtr = np.einsum("nki,nk->ni", J, r)
        A = JtJ + lam[:, None, None] * (np.einsum("nii->ni", JtJ)[:, :, None] * eye + 1e-12 * eye)
        step = -np.linalg.solve(A, Jtr[..., None])[..., 0]
        step[converged] = 0.0
        trial = p + step
        rho_t, n_t, r_t = residual(trial)
        cost_t = np.einsum("ij,ij->i", r_t, r_t)
        better = cost_t <= cost
        p = np.where(better[:, None], trial, p)
        rho = np.where(better[:, None, None], rho_t, rho)
        n = np.where(better[:, None], n_t, n)
        r = np.where(better[:, None], r_t, r)
        cost = np.where(better, cost_t, cost)
        lam = np.where(better, np.maximum(lam / 10.0, 1e-12), lam * 10.0)
        converged |= np.linalg.norm(step, axis=-1) < tol
        converged |= cost == 0.0
        if converged.all():
            break
    worst = np.max(np.abs(r), axis=-1)
    # Only a converged fit proves the lengths inconsistent; one cut short by max_iterations
    # is reported as not converging.
    failed = (worst > max_residual) & converged
    if failed.any():
        k = int(np.argmax(np.where(failed, worst, -np.inf)))
        cable = int(np.argmax(np.abs(r[k])))
        raise KinematicsError(
            f"cable lengths are inconsistent with robot {robot.name!r}: the best-fit platform "
            f"position {np.round(p[k], 6).tolist()} m leaves a residual of "
            f"{_mm(worst[k])} on cable {cable + 1} (allowed {_mm(max_residual)})")
    if not converged.all():
        k = int(np.argmin(converged))
        raise KinematicsError(
            f"forward kinematics did not converge in {max_iterations} iterations "
            f"(residual {_mm(worst[k])}, last position {p[k].tolist()} m)")
    return p[0] if single else p


@_jit
def gauss_newton_warm(offsets, L, p_guess, tol, max_residual, max_iterations, out):
    """Undamped Gauss-Newton from a close guess (the control loop's forward kinematics):
    offsets (m, 3) = b_i - a_i, L (m,) m, p_guess (3,) m. Writes p (m) into out (3,) and
    returns True when it settles (step below tol m) within max_iterations with every residual
    at most max_residual m; False otherwise (out then holds no answer)."""
    m = offsets.shape[0]
    px, py, pz = p_guess[0], p_guess[1], p_guess[2]
    for _ in range(max_iterations):
        # J^T J (symmetric: a d e / c f / k) and J^T r, J_i = rho_i / |rho_i|, r_i = |rho_i| - L_i.
        a = d = e = c = f = kk = 0.0
        gx = gy = gz = 0.0
        for i in range(m):
            x, y, z = px + offsets[i, 0], py + offsets[i, 1], pz + offsets[i, 2]
            n = math.sqrt(x * x + y * y + z * z)
            r = n - L[i]
            x, y, z = x / n, y / n, z / n
            a += x * x
            d += x * y
            e += x * z
            c += y * y
            f += y * z
            kk += z * z
            gx += x * r
            gy += y * r
            gz += z * r
        # x with A x = g for the symmetric 3x3 A, by cofactors; give up when A is singular
        # to working precision.
        c00, c01, c02 = c * kk - f * f, e * f - d * kk, d * f - c * e
        det = a * c00 + d * c01 + e * c02
        if not abs(det) > 1e-14 * (abs(a) + abs(c) + abs(kk)) ** 3:
            return False
        c11, c12, c22 = a * kk - e * e, d * e - a * f, a * c - d * d
        sx = (c00 * gx + c01 * gy + c02 * gz) / det
        sy = (c01 * gx + c11 * gy + c12 * gz) / det
        sz = (c02 * gx + c12 * gy + c22 * gz) / det
        px, py, pz = px - sx, py - sy, pz - sz
        if sx * sx + sy * sy + sz * sz < tol * tol:
            worst = 0.0
            for i in range(m):
                x, y, z = px + offsets[i, 0], py + offsets[i, 1], pz + offsets[i, 2]
                worst = max(worst, abs(math.sqrt(x * x + y * y + z * z) - L[i]))
            if not worst <= max_residual:
                return False
            out[0], out[1], out[2] = px, py, pz
            return True
    return False


def _mm(metres: float) -> str:
    """A length for a message, in mm with enough digits that a value just above a limit
    does not print as the limit (0.0200312 m -> '20.031 mm', never '0.02 m')."""
    return f"{1000.0 * float(metres):.4g} mm" if metres < 1e-3 else f"{1000.0 * float(metres):.3f} mm"


def condition_number(robot, p) -> float:
    """2-norm condition number of J at p (how evenly cable speeds map to platform speeds)."""
    return float(np.linalg.cond(jacobian(robot, p)))


@_jit
def simulated_reel_step(offsets, time_step, lag, max_reel_speed, command, state, out):
    """One tick of the simulated reels (plants.simulated_reels.SimulatedReelsSystem), compiled.

    state and out (2 m + 6,): cable lengths (m), platform p (3, m), its velocity (3, m/s),
    lagged reel speeds (m, m/s). The command (m,) m/s is scaled down to max_reel_speed (all
    reels alike), lagged (factor `lag`), integrated over time_step, and the lengths projected
    onto the geometry (warm Gauss-Newton forward kinematics, then the lengths of that p).
    Returns False when Gauss-Newton does not settle: out then holds the new speeds and the
    integrated (unprojected) lengths, and the caller finishes with the damped solver."""
    m = offsets.shape[0]
    peak = 0.0
    for i in range(m):
        peak = max(peak, abs(command[i]))
    scale = max_reel_speed / peak if peak > max_reel_speed else 1.0
    for i in range(m):
        # Scale all reels alike, as the hardware plant does: the platform slows down but
        # keeps its direction (clipping one reel would steer it).
        c = command[i] * scale if peak > max_reel_speed else command[i]
        speed = state[m + 6 + i] + lag * (c - state[m + 6 + i])
        out[m + 6 + i] = speed
        out[i] = state[i] + time_step * speed
    p = out[m:m + 3]  # a view: no allocation per tick
    if not gauss_newton_warm(offsets, out[:m], state[m:m + 3], 1e-10, np.inf, 8, p):
        return False
    for i in range(m):
        x, y, z = p[0] + offsets[i, 0], p[1] + offsets[i, 1], p[2] + offsets[i, 2]
        out[i] = math.sqrt(x * x + y * y + z * z)
    for k in range(3):
        out[m + 3 + k] = (p[k] - state[m + k]) / time_step
    return True


@_jit
def gauss_newton_warm_stacked(offsets, x, tol, max_residual, max_iterations, out):
    """`gauss_newton_warm` on one stacked input x (m + 3,) = [lengths, p_guess] (m)."""
    m = offsets.shape[0]
    return gauss_newton_warm(offsets, x[:m], x[m:], tol, max_residual, max_iterations, out)


@_jit
def simulated_reel_step_stacked(offsets, reel, x, out):
    """`simulated_reel_step` on one stacked input x = [command (m), state]; reel =
    [time_step s, lag factor, max_reel_speed m/s]."""
    m = offsets.shape[0]
    return simulated_reel_step(offsets, reel[0], reel[1], reel[2], x[:m], x[m:], out)


# The cable-length loop's memory after the stacked inputs [p, v, lengths] of
# `length_loop_tick`: the commanded position p_d (3, m), the start's length offsets delta
# (m, m) and a started flag (1).
def length_loop_sizes(m: int) -> dict:
    """Sizes of `length_loop_tick`'s input x and output out, and where its memory sits."""
    return {"inputs": 6 + m, "memory": m + 4, "x": 2 * m + 10, "out": 3 * m + 4}


# The length loops make up the drives' dead band to this share (a drive whose friction the
# robot file overstates would otherwise hunt), switched in smoothly over this length error, m.
FRICTION_SHARE = 0.9
FRICTION_ERROR = 2e-5


# The most the length loops add to a reel's command, m/s of cable. A command is held until
# the next one arrives: a stall (the controller late, the bridge holding the last command)
# that holds K_l e for longer than 2 / K_l (50 ms at 40 1/s) returns more than the error, and
# repeated stalls ring up (measured: three 0.1-0.2 s controller stalls on the emulated bridge
# took the reels to 0.38 m/s and the lengths 1.6 mm apart from any pose). The corrections are
# scaled together (`correction_scale`), not clipped one by one: scaled, they keep the
# direction of the length error (a motion of the platform, to first order); clipped one by
# one, cables with large errors would lag the others and pull against them.
MAX_CORRECTION = 0.05


@_jit
def correction_scale(largest):
    """The factor (<= 1) on every cable's correction when the largest is `largest` m/s, so
    that none exceeds MAX_CORRECTION."""
    return 1.0 if largest <= MAX_CORRECTION else MAX_CORRECTION / largest


@_jit
def add_scaled_corrections(base, out):
    """out[i] = base[i] + s out[i] for i < base.size: out holds a length loop's corrections
    (m/s), base the reel speeds they add to; s = correction_scale of the largest |out[i]|."""
    largest = 0.0
    for i in range(base.shape[0]):
        largest = max(largest, abs(out[i]))
    scale = correction_scale(largest)
    for i in range(base.shape[0]):
        out[i] = base[i] + scale * out[i]


@_jit
def dead_band_compensation(dead_band, error):
    """The reel speed (m/s) that makes up a drive's dead band (m/s) where the length error
    (m) asks for motion: FRICTION_SHARE dead_band tanh(error / FRICTION_ERROR), zero at zero
    error (so ideal reels, whose error is zero, see none of it)."""
    return FRICTION_SHARE * dead_band * math.tanh(error / FRICTION_ERROR)


@_jit
def length_loop_tick(offsets, gain, time_step, dead_band, x, out):
    """The Jacobian block's tick (eq. 3) with the cable-length loop (beyond the paper):

        l_dot = J(p_hat) v + s (K_l e + c(e)),   e = l_d - l,   l_d = lengths(p_d) + delta,

    with c the drives' dead band made up (`dead_band_compensation`; dead_band m/s, 0: off)
    and s the scale that keeps every correction within MAX_CORRECTION
    (`add_scaled_corrections`):
    a drive whose Coulomb friction holds it still under a command slower than its dead band
    would otherwise leave e at up to dead_band / K_l (0.25 mm, ~6 N of tension, with the
    default drives) wherever it stops or turns.

    x (2 m + 10,) = [p_hat (3, m: the forward kinematics' estimate), v (3, m/s: the velocity
    command), l (m, m: the measured lengths), memory: p_d (3, m), delta (m, m), started (1)].
    out (3 m + 4,) = [l_dot (m, m/s), l_d (m, m), the next memory (m + 4)].

    The commanded lengths l_d are those of a rigid platform at the commanded position p_d,
    plus the offsets delta = l - lengths(p_hat) latched at the first tick (started == 0), so
    the loop starts with no error whatever the encoders' zero and the cables' stretch. p_d
    advances as ideal reels would move the platform under the feedforward J v: the lengths
    of p_d plus time_step J v, fitted back to a rigid platform (the least squares of the
    forward kinematics). So l_d stays a set of lengths some pose has (a loop fed lengths no
    pose has would stretch the cables against each other), and on ideal reels l == l_d to
    round-off: the loop corrects only what the reels did not do (lag, friction, stretch).
    gain K_l in 1/s (0: the paper's open loop), time_step in s."""
    m = offsets.shape[0]
    started = x[2 * m + 9] != 0.0
    for k in range(3):
        out[2 * m + k] = x[6 + m + k] if started else x[k]
    pdx, pdy, pdz = out[2 * m], out[2 * m + 1], out[2 * m + 2]
    target = out[m:2 * m]  # scratch until l_d is written over it below
    feedforwards = np.empty(m)
    for i in range(m):
        # Feedforward at the estimate (eq. 3).
        xx, yy, zz = x[0] + offsets[i, 0], x[1] + offsets[i, 1], x[2] + offsets[i, 2]
        n = math.sqrt(xx * xx + yy * yy + zz * zz)
        feedforward = (xx * x[3] + yy * x[4] + zz * x[5]) / n
        xx, yy, zz = pdx + offsets[i, 0], pdy + offsets[i, 1], pdz + offsets[i, 2]
        rigid = math.sqrt(xx * xx + yy * yy + zz * zz)
        delta = x[9 + m + i] if started else x[6 + i] - rigid
        out[2 * m + 3 + i] = delta
        error = rigid + delta - x[6 + i]
        out[i] = gain * error + dead_band_compensation(dead_band, error)
        feedforwards[i] = feedforward
        target[i] = rigid + time_step * feedforward
    add_scaled_corrections(feedforwards, out)
    p_next = out[2 * m:2 * m + 3]  # a view: no allocation per tick
    # gauss_newton_warm reads its guess before it writes: the guess may be its output.
    if not gauss_newton_warm(offsets, target, p_next, 1e-10, np.inf, 8, p_next):
        p_next[0] = pdx + time_step * x[3]
        p_next[1] = pdy + time_step * x[4]
        p_next[2] = pdz + time_step * x[5]
    for i in range(m):
        xx, yy, zz = pdx + offsets[i, 0], pdy + offsets[i, 1], pdz + offsets[i, 2]
        out[m + i] = math.sqrt(xx * xx + yy * yy + zz * zz) + out[2 * m + 3 + i]
    out[3 * m + 3] = 1.0


@_jit
def reel_rates_stacked(offsets, x, out):
    """`reel_rates` on one stacked input x (6,) = [p m, v m/s]."""
    reel_rates(offsets, x[:3], x[3:], out)
