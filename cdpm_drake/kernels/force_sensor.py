"""The handle's force sensor (Variense FSE103): its measuring range. numpy and numba, no Drake.

Forces in N, base frame.
"""

import math

import numba
import numpy as np

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


def clip_to_sensor_range(f, axis, axial_range, transverse_range) -> np.ndarray:
    """Saturate a force (N) as an FSE103 does: axial component to +-axial_range along the handle
    `axis` (unit), transverse part to transverse_range in norm."""
    out = np.empty(3)
    clip_into(np.asarray(f, dtype=float), np.asarray(axis, dtype=float), float(axial_range),
              float(transverse_range), out)
    return out


@_jit
def clip_into(f, axis, axial_range, transverse_range, out):
    """`clip_to_sensor_range` compiled, writing into out (3,): the sensor block's tick."""
    fx, fy, fz = f[0], f[1], f[2]
    ax, ay, az = axis[0], axis[1], axis[2]
    axial = fx * ax + fy * ay + fz * az
    tx, ty, tz = fx - axial * ax, fy - axial * ay, fz - axial * az
    n = math.sqrt(tx * tx + ty * ty + tz * tz)
    if n > transverse_range:
        k = transverse_range / n
        tx, ty, tz = tx * k, ty * k, tz * k
    axial = min(max(axial, -axial_range), axial_range)
    out[0], out[1], out[2] = axial * ax + tx, axial * ay + ty, axial * az + tz


def beyond_range(forces, axis, axial_range, transverse_range) -> np.ndarray:
    """For forces (..., 3) N: True where the sensor clips it (`clip_into` changes it): the
    axial component along the unit `axis` beyond +-axial_range, or the transverse part beyond
    transverse_range in norm. NaN is never beyond."""
    f = np.asarray(forces, dtype=float)
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    axial = f @ a
    transverse = np.linalg.norm(f - axial[..., None] * a, axis=-1)
    with np.errstate(invalid="ignore"):
        return (np.abs(axial) > axial_range) | (transverse > transverse_range)
