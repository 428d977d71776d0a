"""The dynamic plant's cables and reel drives, per plant step. numpy and numba, no Drake.

Elastic, tension-only cables between the reel exits a_i (base frame) and the attachment points
b_i (platform frame) of a rigid platform at p with orientation R_WB; reel drives that pay out
the cables' unstretched lengths L0 through a velocity loop with viscous and Coulomb friction.
`cable_net_step` is the whole step of systems/dynamic_plant.py in one compiled call: the
tensions, the generalized force they and the hand put on the platform, the drives' next state
and the plant's ground truth. SI units: m, m/s, N, rad.
"""

import math

import numba
import numpy as np

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def _reel_speed(w, u, h, bandwidth, inertia, viscous, coulomb):
    """One implicit step (h s) of a reel drive: inertia dw/dt = K (u - w) - b w - F_c sgn w,
    K = bandwidth * inertia, from speed w under command u (m/s of cable). Viscous terms are
    implicit, so any bandwidth is stable; Coulomb friction is the implicit set-valued law: a
    reel whose drive force cannot overcome F_c within the step stops (sticks)."""
    K = bandwidth * inertia
    denominator = inertia + h * (K + viscous)
    free = (inertia * w + h * K * u) / denominator
    grip = h * coulomb / denominator
    if abs(free) <= grip:
        return 0.0
    return free - np.sign(free) * grip


@_jit
def reel_step(w, u, h, bandwidth, inertia, viscous, coulomb):
    """The reels' speeds (m,) m/s after one step of h s from speeds w under commands u
    (`_reel_speed` per reel)."""
    out = np.empty(w.shape[0])
    for i in range(w.shape[0]):
        out[i] = _reel_speed(w[i], u[i], h, bandwidth, inertia, viscous, coulomb)
    return out


@_jit
def _tension(L, stretch_rate, L0, EA, damping):
    """Tension-only spring-damper (N): max(0, k (L - L0) + c dL), k = EA/L0, zero while slack
    (L <= L0). dL is the stretch rate d(L - L0)/dt, m/s: the rate the cable material sees."""
    stretch = L - L0
    if not stretch > 0.0:
        return 0.0
    T = EA / L0 * stretch + damping * stretch_rate
    return T if T > 0.0 else 0.0


@_jit
def cable_tensions(L, stretch_rate, L0, EA, damping):
    """`_tension` of every cable: lengths L (m,) m, stretch rates (m,) m/s, rest lengths L0
    (m,) m; (m,) N."""
    out = np.empty(L.shape[0])
    for i in range(L.shape[0]):
        out[i] = _tension(L[i], stretch_rate[i], L0[i], EA, damping)
    return out


# The reel drives' state (the systems/dynamic_plant.py delay `reel_state` holds it), for m
# cables: [unstretched lengths L0 (m) | reel speeds (m)].
def state_layout(m: int) -> dict:
    """{piece: (offset, size)} of the drives' state cable_net_step steps."""
    return _layout((("L0", m), ("reel_speeds", m)))


def step_layout(m: int, nv: int) -> dict:
    """{piece: (offset, size)} of cable_net_step's output, for nv generalized velocities (6
    for a free platform: moment about its centre, then force, base frame; 3 with the rotation
    locked: the force): the generalized force on the platform for this step, the drives' next
    state (state_layout), and the ground truth now (tensions N, slack: 1.0 where a cable
    carries no tension, p_WP m, rpy rad) with the hand force (N, base frame) on entry; last
    the force each reel drive supplies in this step (N at the cable, as drive_torque.py:
    what its current measures)."""
    return _layout((("generalized_force", nv), ("next_reels", 2 * m), ("tensions", m),
                    ("slack", m), ("p_WP_true", 3), ("rpy_true", 3), ("hand_force", 3),
                    ("drive_force", m)))


def input_layout(m: int, nx: int) -> dict:
    """{piece: (offset, size)} of cable_net_step's stacked input: the platform's state (nx:
    [qw qx qy qz x y z, w_WB, v_WBo] free, [x y z, v] locked), the drives' state
    (state_layout) and the reel velocity command (m/s)."""
    return _layout((("platform_state", nx), ("reels", 2 * m), ("command", m)))


def _layout(pieces) -> dict:
    layout, at = {}, 0
    for name, size in pieces:
        layout[name] = (at, size)
        at += size
    return layout


@_jit
def cable_net_step(reels, attachments, handle, params, R, inputs, out):
    """One plant step of the cables and the reel drives, into out (step_layout).

    reels (m, 3) a_i and attachments (m, 3) b_i, m; handle (3,) m, platform frame;
    params [EA N, damping N s/m, h s, bandwidth rad/s, reel inertia kg, viscous N s/m,
    Coulomb N, reel speed limit m/s, locked (1.0: rotation locked), the drives' true inertia
    and friction over those (the drive force's scales)]; R (3, 3): R_WB when
    locked, else scratch (R_WB of the state is written there); inputs as input_layout; out's
    hand force (N, base frame) must be set on entry.

    On the platform's state and the drives' present L0 and speeds, the cables' tensions and
    the generalized force they and the hand put on the platform (`_cable_forces`), with the
    ground truth; then the drives' step: the command scaled to the speed limit (all reels
    alike), one `_reel_speed` step of h s, L0 += h w; and each drive's force.

    The drive force: the velocity loop is stiff against its load (the reel moves as
    `_reel_speed` says, whatever the cable pulls), so the drive supplies what that motion
    takes against the cable: F = J a + b w + f - T (drive_torque.py), a = (w_next - w) / h,
    w = w_next, f the Coulomb force of the step (in [-F_c, F_c] while stuck), T the tension
    now; with true inertia and friction scaled by params[9], params[10] from the ones that
    move the reel (1, 1: F = K (u - w_next) - T exactly).
    """
    m = reels.shape[0]
    locked = params[8] > 0.5
    nx = 6 if locked else 13
    nv = 3 if locked else 6
    iL0, iw, iu = nx, nx + m, nx + 2 * m
    o_next = nv
    oT = nv + 2 * m
    o_slack, o_p, o_rpy = oT + m, oT + 2 * m, oT + 2 * m + 3
    o_hand = o_rpy + 3
    o_drive = o_hand + 3
    if not locked:
        _rotation_into(inputs, R)
    _cable_forces(reels, attachments, handle, params, R, inputs, iL0, iw, out, o_hand, 0, oT,
                  o_slack)
    out[o_p], out[o_p + 1], out[o_p + 2] = ((inputs[0], inputs[1], inputs[2]) if locked
                                            else (inputs[4], inputs[5], inputs[6]))
    # Roll, pitch, yaw of R (as pydrake's RollPitchYaw, pitch in [-pi/2, pi/2]).
    out[o_rpy] = math.atan2(R[2, 1], R[2, 2])
    out[o_rpy + 1] = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    out[o_rpy + 2] = math.atan2(R[1, 0], R[0, 0])
    # The drives: the command scaled to the speed limit, then one implicit step.
    h = params[2]
    peak = 0.0
    for i in range(m):
        peak = max(peak, abs(inputs[iu + i]))
    scale = params[7] / peak if peak > params[7] else 1.0
    J, b = params[4], params[5]
    K = params[3] * J
    for i in range(m):
        u = inputs[iu + i] * scale if scale != 1.0 else inputs[iu + i]
        w = _reel_speed(inputs[iw + i], u, h, params[3], J, b, params[6])
        out[o_next + m + i] = w
        out[o_next + i] = inputs[iL0 + i] + h * w
        a = (w - inputs[iw + i]) / h
        coulomb = K * (u - w) - J * a - b * w
        out[o_drive + i] = (params[9] * J * a + params[10] * (b * w + coulomb)
                            - out[oT + i])


@_jit
def _cable_forces(reels, attachments, handle, params, R, x, iL0, iw, out, o_hand, o_generalized,
                  o_tensions, o_slack):
    """The cables' tensions (into out[o_tensions:]), their slack flags (out[o_slack:]) and the
    generalized force (out[o_generalized:]: moment about the centre, then force; the force
    alone when locked) that they and the hand force out[o_hand:o_hand + 3] put on the
    platform of state x (R: its R_WB), with the drives' L0 = x[iL0:iL0 + m] and speeds
    x[iw:iw + m].

    Each cable: L_i = |a_i - (p + R b_i)|, u_i its unit vector towards the reel, stretch rate
    -u_i . (v + w x R b_i) - (reel speed); tension by `_tension`. The platform gets
    sum T_i u_i + F_hand at its centre and sum (R b_i) x T_i u_i + (R h) x F_hand about it.
    """
    m = reels.shape[0]
    EA, damping = params[0], params[1]
    locked = params[8] > 0.5
    if locked:
        px, py, pz = x[0], x[1], x[2]
        vx, vy, vz = x[3], x[4], x[5]
        wx = wy = wz = 0.0
    else:
        px, py, pz = x[4], x[5], x[6]
        wx, wy, wz = x[7], x[8], x[9]
        vx, vy, vz = x[10], x[11], x[12]
    fx = fy = fz = nx_ = ny_ = nz_ = 0.0
    for i in range(m):
        bx = R[0, 0] * attachments[i, 0] + R[0, 1] * attachments[i, 1] + R[0, 2] * attachments[i, 2]
        by = R[1, 0] * attachments[i, 0] + R[1, 1] * attachments[i, 1] + R[1, 2] * attachments[i, 2]
        bz = R[2, 0] * attachments[i, 0] + R[2, 1] * attachments[i, 1] + R[2, 2] * attachments[i, 2]
        rx = reels[i, 0] - (px + bx)
        ry = reels[i, 1] - (py + by)
        rz = reels[i, 2] - (pz + bz)
        L = math.sqrt(rx * rx + ry * ry + rz * rz)
        ux, uy, uz = rx / L, ry / L, rz / L
        # Velocity of the attachment point: v + w x (R b).
        ax = vx + (wy * bz - wz * by)
        ay = vy + (wz * bx - wx * bz)
        az = vz + (wx * by - wy * bx)
        L_dot = -(ux * ax + uy * ay + uz * az)
        T = _tension(L, L_dot - x[iw + i], x[iL0 + i], EA, damping)
        out[o_tensions + i] = T
        out[o_slack + i] = 1.0 if T <= 0.0 else 0.0
        gx, gy, gz = T * ux, T * uy, T * uz
        fx += gx
        fy += gy
        fz += gz
        nx_ += by * gz - bz * gy
        ny_ += bz * gx - bx * gz
        nz_ += bx * gy - by * gx
    Fx, Fy, Fz = out[o_hand], out[o_hand + 1], out[o_hand + 2]
    o = o_generalized
    if locked:
        out[o], out[o + 1], out[o + 2] = fx + Fx, fy + Fy, fz + Fz
    else:
        # (R h) x F_hand: the hand's moment about the centre.
        hx = R[0, 0] * handle[0] + R[0, 1] * handle[1] + R[0, 2] * handle[2]
        hy = R[1, 0] * handle[0] + R[1, 1] * handle[1] + R[1, 2] * handle[2]
        hz = R[2, 0] * handle[0] + R[2, 1] * handle[1] + R[2, 2] * handle[2]
        out[o] = nx_ + (hy * Fz - hz * Fy)
        out[o + 1] = ny_ + (hz * Fx - hx * Fz)
        out[o + 2] = nz_ + (hx * Fy - hy * Fx)
        out[o + 3], out[o + 4], out[o + 5] = fx + Fx, fy + Fy, fz + Fz


@_jit
def _rotation_into(x, R):
    """R_WB from a free body's state x (unit quaternion qw, qx, qy, qz first), normalised."""
    n = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
    w, a, b, c = x[0] / n, x[1] / n, x[2] / n, x[3] / n
    R[0, 0], R[0, 1], R[0, 2] = 1 - 2 * (b * b + c * c), 2 * (a * b - c * w), 2 * (a * c + b * w)
    R[1, 0], R[1, 1], R[1, 2] = 2 * (a * b + c * w), 1 - 2 * (a * a + c * c), 2 * (b * c - a * w)
    R[2, 0], R[2, 1], R[2, 2] = 2 * (a * c - b * w), 2 * (b * c + a * w), 1 - 2 * (a * a + b * b)


def cable_net_params(dynamics, *, time_step: float, max_reel_speed: float,
                     locked: bool, inertia_error: float = 0.0,
                     friction_error: float = 0.0) -> np.ndarray:
    """cable_net_step's params from a robot's dynamics (robot.Dynamics). The errors are the
    drives' true inertia and friction over the robot file's, less one (0.2: 20 % more): the
    force the drives supply is the true drives'; the robot file's values (what the
    controller's model takes) move the reels."""
    d = dynamics
    return np.array([d.EA, d.damping, time_step, d.bandwidth, d.reel_inertia,
                     d.viscous_friction, d.coulomb_friction, max_reel_speed,
                     1.0 if locked else 0.0, 1.0 + inertia_error, 1.0 + friction_error],
                    dtype=float)
