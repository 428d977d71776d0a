"""Safety limits after the admittance (Fig. 5) and the workspace-wall force. numpy and numba,
no Drake.

Base frame, SI units: p in m, velocities in m/s, accelerations in m/s^2, forces in N.
"""

import math

import numba
import numpy as np

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


def limit_velocity(v_desired, v_previous, p, lower, upper, *, max_velocity, max_acceleration,
                   time_step, virtual_wall=True) -> np.ndarray:
    """The platform velocity to command this tick.

    In order: the speed is capped at `max_velocity`; near a face of the workspace box the speed
    towards it is capped by the discrete braking curve sqrt(2 a gap) - a T / 2, from which
    braking by a T per tick stops within the gap (so following it never needs more than the
    acceleration limit), and by gap / time_step so one tick never leaves the box; the change from
    the previous command is capped at max_acceleration * time_step. The wall cap is applied
    again last: it wins over the acceleration limit (never leave the box).
    """
    out = np.empty(3)
    bounds = np.array([np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)])
    limit_velocity_into(np.asarray(v_desired, dtype=float), np.asarray(v_previous, dtype=float),
                        np.asarray(p, dtype=float), bounds, float(max_velocity),
                        float(max_acceleration), float(time_step), bool(virtual_wall), out)
    return out


@_jit
def limit_velocity_into(v_desired, v_previous, p, bounds, max_velocity, max_acceleration,
                        time_step, virtual_wall, out):
    """`limit_velocity` compiled, writing the command (3,) m/s into out; bounds (2, 3) is
    (lower, upper) of the workspace box, m. The safety limits block's tick."""
    vx, vy, vz = v_desired[0], v_desired[1], v_desired[2]
    speed = math.sqrt(vx * vx + vy * vy + vz * vz)
    if speed > max_velocity:
        k = max_velocity / speed
        vx, vy, vz = vx * k, vy * k, vz * k
    if virtual_wall:
        lx, ux_, ly, uy_, lz, uz_ = _wall_caps(p, bounds, max_acceleration, time_step)
        vx, vy, vz = _clip(vx, lx, ux_), _clip(vy, ly, uy_), _clip(vz, lz, uz_)
    ux, uy, uz = v_previous[0], v_previous[1], v_previous[2]
    dx, dy, dz = vx - ux, vy - uy, vz - uz
    step = math.sqrt(dx * dx + dy * dy + dz * dz)
    max_step = max_acceleration * time_step
    if step > max_step:
        k = max_step / step
        vx, vy, vz = ux + dx * k, uy + dy * k, uz + dz * k
    if virtual_wall:
        vx, vy, vz = _clip(vx, lx, ux_), _clip(vy, ly, uy_), _clip(vz, lz, uz_)
    out[0], out[1], out[2] = vx, vy, vz


@_jit
def _clip(x, cap_lower, cap_upper):
    return min(max(x, -cap_lower), cap_upper)


@_jit
def _wall_caps(p, bounds, a, T):
    """Per axis (cap towards the lower face, cap towards the upper face), m/s, both >= 0:
    (x lower, x upper, y lower, y upper, z lower, z upper). Scalars, not an array: no
    allocation per tick."""
    # Each axis brakes on its own curve; at a/sqrt(3) per axis the vector deceleration stays
    # within a even where three faces meet (a corner), at the price of braking earlier at a face.
    a = a / math.sqrt(3.0)
    return (face_cap(p[0] - bounds[0, 0], a, T), face_cap(bounds[1, 0] - p[0], a, T),
            face_cap(p[1] - bounds[0, 1], a, T), face_cap(bounds[1, 1] - p[1], a, T),
            face_cap(p[2] - bounds[0, 2], a, T), face_cap(bounds[1, 2] - p[2], a, T))


@_jit
def face_cap(gap, a, T):
    """The speed cap (m/s, >= 0) towards a face `gap` m away, per-axis deceleration a."""
    gap = max(gap, 0.0)
    # Braking curve and one-tick bound (no overshoot). The continuous curve sqrt(2 a gap)
    # is not enough at 500 Hz: braking by a T per tick from v covers T (v + (v - aT) +
    # ...), at most (v + aT/2)^2 / (2a), so the cap is sqrt(2 a gap) - aT/2; on it, the
    # next tick's cap is exactly v - aT.
    return max(min(math.sqrt(2.0 * a * gap) - 0.5 * a * T, gap / T), 0.0)


def wall_force(p, lower, upper, *, margin, max_force) -> np.ndarray:
    """Beyond the paper: repulsion from the faces of the workspace box (N).

    Zero farther than `margin` (m) from every face; on each axis it grows as
    max_force * ((margin - gap) / margin)^2 towards the inside, `max_force` at the face and
    beyond. Smooth (C1) at the margin, so the operator feels no step.
    """
    out = np.empty(3)
    bounds = np.array([np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)])
    wall_force_into(np.asarray(p, dtype=float), bounds, float(margin), float(max_force), out)
    return out


@_jit
def wall_force_into(p, bounds, margin, max_force, out):
    """`wall_force` compiled, into out (3,) N; bounds (2, 3) = (lower, upper), m."""
    for k in range(3):
        push_lo = min(max((margin - (p[k] - bounds[0, k])) / margin, 0.0), 1.0)
        push_up = min(max((margin - (bounds[1, k] - p[k])) / margin, 0.0), 1.0)
        out[k] = max_force * (push_lo * push_lo - push_up * push_up)


@_jit
def limit_velocity_stacked(x, bounds, max_velocity, max_acceleration, time_step, virtual_wall,
                           out):
    """`limit_velocity_into` on one stacked input x (9,) = [v_desired, p, v_previous] (m/s,
    m, m/s): the block reads its three inputs as one C++-multiplexed vector (one port
    evaluation from Python instead of three)."""
    limit_velocity_into(x[0:3], x[6:9], x[3:6], bounds, max_velocity, max_acceleration,
                        time_step, virtual_wall, out)
