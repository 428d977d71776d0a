"""Safety limits after the admittance (Fig. 5) and the workspace-wall force. Plain numpy.

Base frame, SI units: p in m, velocities in m/s, accelerations in m/s^2, forces in N.
"""

import math

import numpy as np


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
    # Three components: plain floats are several times faster than numpy at this size, and
    # this runs every tick.
    v = [float(x) for x in v_desired]
    prev = [float(x) for x in v_previous]
    speed = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if speed > max_velocity:
        v = [x * (max_velocity / speed) for x in v]
    if virtual_wall:
        caps = _wall_caps(p, lower, upper, max_acceleration, time_step)
        v = _clip(v, caps)
    dv = [x - y for x, y in zip(v, prev)]
    step = math.sqrt(dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2])
    max_step = max_acceleration * time_step
    if step > max_step:
        v = [y + d * (max_step / step) for y, d in zip(prev, dv)]
    if virtual_wall:
        v = _clip(v, caps)
    return np.array(v)


def _clip(v, caps):
    return [min(max(x, -lo), up) for x, (lo, up) in zip(v, caps)]


def _wall_caps(p, lower, upper, a, T):
    """Per axis (cap towards the lower face, cap towards the upper face), m/s, both >= 0."""
    # Each axis brakes on its own curve; at a/sqrt(3) per axis the vector deceleration stays
    # within a even where three faces meet (a corner), at the price of braking earlier at a face.
    a = a / math.sqrt(3.0)
    caps = []
    for x, lo, up in zip(p, lower, upper):
        gap_up = max(float(up) - float(x), 0.0)
        gap_lo = max(float(x) - float(lo), 0.0)
        # Braking curve and one-tick bound (no overshoot). The continuous curve sqrt(2 a gap)
        # is not enough at 500 Hz: braking by a T per tick from v covers T (v + (v - aT) +
        # ...), at most (v + aT/2)^2 / (2a), so the cap is sqrt(2 a gap) - aT/2; on it, the
        # next tick's cap is exactly v - aT.
        caps.append((max(min(math.sqrt(2.0 * a * gap_lo) - 0.5 * a * T, gap_lo / T), 0.0),
                     max(min(math.sqrt(2.0 * a * gap_up) - 0.5 * a * T, gap_up / T), 0.0)))
    return caps


def wall_force(p, lower, upper, *, margin, max_force) -> np.ndarray:
    """Beyond the paper: repulsion from the faces of the workspace box (N).

    Zero farther than `margin` (m) from every face; on each axis it grows as
    max_force * ((margin - gap) / margin)^2 towards the inside, `max_force` at the face and
    beyond. Smooth (C1) at the margin, so the operator feels no step.
    """
    p = np.asarray(p, dtype=float)
    gap_lo = p - np.asarray(lower)
    gap_up = np.asarray(upper) - p
    push_lo = np.clip((margin - gap_lo) / margin, 0.0, 1.0) ** 2
    push_up = np.clip((margin - gap_up) / margin, 0.0, 1.0) ** 2
    return max_force * (push_lo - push_up)
