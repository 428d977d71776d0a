"""A cable's tension from its reel drive's measured force: what every servo drive's current
says about the cable it winds. numpy and numba, no Drake.

All at the cable (the drive's torque over the drum radius): force N, reel speed and
acceleration m/s and m/s^2 of cable, positive paying cable out (the rest length grows). The
reel's equation of motion with the cable's tension T pulling cable off it:

    inertia dw/dt = F_drive + T - viscous w - coulomb sgn(w)

so T = inertia a + viscous w + coulomb sgn(w) - F_drive. A drive holding a taut cable at
rest pulls in: F_drive = -T. The controller's model of inertia and friction is never the
drive's exact one; its error is the sensor's bias.
"""

import numba
import numpy as np

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def friction_sign(w, band):
    """sgn(w) smoothed over |w| < band (m/s): a reel near rest sticks, and its static
    friction is anywhere in [-coulomb, coulomb], so the model takes the middle there."""
    if band <= 0.0:
        return 1.0 if w > 0.0 else (-1.0 if w < 0.0 else 0.0)
    s = w / band
    return 1.0 if s > 1.0 else (-1.0 if s < -1.0 else s)


@_jit
def tension_from_drive(force, speed, accel, inertia, viscous, coulomb, band, out):
    """Each cable's tension (N) into out (m,), from its drive's force (m,) N, the reel's
    speed (m,) m/s and acceleration (m,) m/s^2, with the model's reel inertia kg, viscous
    N s/m and Coulomb N friction at the cable and the friction's speed band m/s."""
    for i in range(force.shape[0]):
        w = speed[i]
        out[i] = (inertia * accel[i] + viscous * w + coulomb * friction_sign(w, band)
                  - force[i])


def drive_model(dynamics, cables: int | None = None) -> tuple:
    """The controller's model of its reel drives, tension_from_drive's (inertia kg, viscous
    N s/m, Coulomb N, band m/s) at the cable, from a robot's dynamics (robot file
    reel_drives; the band its dead band). With `cables`, tension_from_drive is compiled now
    for that many: a first call on a real-time path would take seconds."""
    model = (float(dynamics.reel_inertia), float(dynamics.viscous_friction),
             float(dynamics.coulomb_friction), float(dynamics.dead_band))
    if cables is not None:
        zeros = np.zeros(cables)
        tension_from_drive(zeros, zeros, zeros, *model, np.empty(cables))
    return model


def drive_force_for_tension(tension, speed, accel, inertia, viscous, coulomb, band):
    """The inverse: the drive force (N) that moves reels of speed and acceleration against
    cables of these tensions (N), as the drive's velocity loop supplies it. numpy arrays."""
    tension, speed, accel = (np.asarray(x, dtype=float) for x in (tension, speed, accel))
    out = np.empty(tension.shape[0])
    zero = np.zeros(tension.shape[0])
    tension_from_drive(zero, speed, accel, inertia, viscous, coulomb, band, out)
    return out - tension
