"""Roll-pitch-yaw angles and rotation matrices (Drake's convention). Plain numpy.

R = Rz(yaw) Ry(pitch) Rx(roll), as pydrake.math.RollPitchYaw; angles in rad.
"""

import numpy as np


def rotation_from_rpy(rpy) -> np.ndarray:
    """R_WB (3, 3) from [roll, pitch, yaw] (rad)."""
    r, p, y = (float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def rotations_from_rpy(rpy) -> np.ndarray:
    """R_WB (N, 3, 3) from rows [roll, pitch, yaw] (N, 3) rad, as `rotation_from_rpy` each."""
    a = np.asarray(rpy, dtype=float).reshape(-1, 3)
    cr, sr = np.cos(a[:, 0]), np.sin(a[:, 0])
    cp, sp = np.cos(a[:, 1]), np.sin(a[:, 1])
    cy, sy = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], axis=-1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], axis=-1),
        np.stack([-sp, cp * sr, cp * cr], axis=-1)], axis=-2)


def rotation_angle(R) -> np.ndarray:
    """The angle (rad) of the rotation R (..., 3, 3) from the identity."""
    R = np.asarray(R, dtype=float)
    c = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def rpy_from_rotation(R) -> np.ndarray:
    """[roll, pitch, yaw] (rad) of R_WB (3, 3), pitch in [-pi/2, pi/2] (as RollPitchYaw)."""
    R = np.asarray(R, dtype=float)
    pitch = np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0]))
    return np.array([np.arctan2(R[2, 1], R[2, 2]), pitch, np.arctan2(R[1, 0], R[0, 0])])
