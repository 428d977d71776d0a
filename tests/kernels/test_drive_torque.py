"""kernels/drive_torque.py: a cable's tension from its drive's force, against the reel's
equation of motion written out here (inertia a = F_drive + T - viscous w - coulomb sgn w)."""

import numpy as np

from cdpm_drake.kernels.drive_torque import drive_force_for_tension, friction_sign, tension_from_drive


def test_the_tension_is_the_reel_equation_of_motion_solved_for_it():
    rng = np.random.default_rng(3)
    m = 9
    J, b, Fc, band = 0.25, 0.25, 0.125, 0.002
    speed = rng.uniform(-0.5, 0.5, m)
    speed[:2] = [0.0, 0.001]  # at rest, and inside the friction band
    accel = rng.uniform(-3, 3, m)
    accel[0] = 0.0
    force = rng.uniform(-40, 0, m)
    out = np.empty(m)
    tension_from_drive(force, speed, accel, J, b, Fc, band, out)
    # The closed form: T = J a + b w + Fc s(w) - F, s the sign smoothed linearly over the band.
    s = np.clip(speed / band, -1.0, 1.0)
    np.testing.assert_allclose(out, J * accel + b * speed + Fc * s - force, rtol=0, atol=1e-12)
    # A drive holding a taut cable at rest pulls in with the tension: T = -F.
    assert out[0] == -force[0]
    # Paying out under the tension (w > 0) the friction resists the motion, so the drive's
    # force needs less pull: the tension reads above -F by b w + Fc.
    k = int(np.argmax(speed))
    assert out[k] > -force[k] + J * accel[k]


def test_the_force_for_a_tension_inverts_the_tension():
    rng = np.random.default_rng(4)
    T = rng.uniform(0, 80, 7)
    w, a = rng.uniform(-1, 1, 7), rng.uniform(-2, 2, 7)
    F = drive_force_for_tension(T, w, a, 0.3, 0.2, 0.1, 0.005)
    back = np.empty(7)
    tension_from_drive(F, w, a, 0.3, 0.2, 0.1, 0.005, back)
    np.testing.assert_allclose(back, T, rtol=0, atol=1e-12)
    # At rest, unaccelerated: the drive pulls with the tension.
    np.testing.assert_allclose(drive_force_for_tension(T, 0 * w, 0 * a, 0.3, 0.2, 0.1, 0.005),
                               -T, atol=0)


def test_friction_sign_is_the_sign_outside_the_band_and_linear_inside():
    assert friction_sign(0.3, 0.01) == 1.0 and friction_sign(-0.3, 0.01) == -1.0
    assert friction_sign(0.005, 0.01) == 0.5
    assert friction_sign(0.0, 0.0) == 0.0 and friction_sign(-1e-9, 0.0) == -1.0
