"""The dynamic plant's tension sensors, per control tick: what the drives' currents or a load
cell per cable tell the controller about the true tensions. numpy and numba, no Drake.

Two sensors (params[0]): the reel drive's force (1: drive_torque), turned into a tension with
the controller's model of the drive (kernels/drive_torque.py), or a load cell (2). Each
sample's noise is a pure function of (seed, tick, cable), so a run repeats. SI units, forces
at the cable.
"""

import math

import numba
import numpy as np

from cdpm_drake.kernels.drive_torque import tension_from_drive

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")

DRIVE_TORQUE, LOAD_CELL = 1.0, 2.0


def sensor_layout(m: int) -> dict:
    """{piece: (offset, size)} of the sensor's state, which its kernel's output is (the next
    one) and a delay sampled at the control tick holds: the tension measured (N), the
    filter's state (N: the drive's force or the load cell's tension), the reel speeds of the
    last sample (m/s) and the tick count."""
    at, layout = 0, {}
    for name, size in (("tension_measured", m), ("filtered", m), ("speed_previous", m),
                       ("tick", 1)):
        layout[name] = (at, size)
        at += size
    return layout


def sensor_params(kind: float, *, time_step, seed, noise_std, quantum=0.0, time_constant=0.0,
                  inertia=0.0, viscous=0.0, coulomb=0.0, band=0.0) -> np.ndarray:
    """tension_sensor_tick's params: the sensor (DRIVE_TORQUE or LOAD_CELL), the tick s, the
    noise seed, noise std N, quantum N (0: none), the filter's gain per tick (from its time
    constant s, 0: none), and the controller's model of the drive: reel inertia kg, viscous
    N s/m, Coulomb N, friction band m/s (drive_torque.tension_from_drive)."""
    alpha = 1.0 - math.exp(-time_step / time_constant) if time_constant > 0 else 1.0
    return np.array([kind, time_step, float(seed), noise_std, quantum, alpha, inertia,
                     viscous, coulomb, band], dtype=float)


@_jit
def _mix(z):
    """splitmix64's finaliser: a well-mixed 64-bit word from z."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@_jit
def _uniform(seed, tick, index):
    """A uniform number in (0, 1), a pure function of (seed, tick, index)."""
    z = _mix(np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(0x632BE59BD9B4E019))
    z = _mix(z ^ (np.uint64(tick) * np.uint64(0xD1B54A32D192ED03)))
    z = _mix(z ^ (np.uint64(index) + np.uint64(0x8CB92BA72F3D8DD7)))
    return ((z >> np.uint64(11)) + np.uint64(1)) * (1.0 / 9007199254740993.0)


@_jit
def gaussian(seed, tick, cable):
    """A standard normal sample, a pure function of (seed, tick, cable) (Box-Muller)."""
    u1 = _uniform(seed, tick, 2 * cable)
    u2 = _uniform(seed, tick, 2 * cable + 1)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@_jit
def tension_sensor_tick(params, bias, x, out):
    """One control tick of the sensor. x = [drive force F (m) N, reel speeds w (m) m/s, true
    tensions (m) N, state (sensor_layout)]; out = the next state. bias (m,) N: the load
    cells' offsets.

    drive_torque: the current filter (first order) on F, plus noise, quantised: F_m; then
    T = J a + b w + F_c sgn(w) - F_m with the model's J, b, F_c (tension_from_drive), a the
    speed's difference over the tick. load_cell: the cell's first-order response to the
    true tension, plus its bias and noise.
    """
    m = bias.shape[0]
    kind, T, seed, std, quantum, alpha = (params[0], params[1], params[2], params[3],
                                          params[4], params[5])
    s = 3 * m
    tick = x[s + 3 * m]
    k = np.uint64(tick)
    sd = np.uint64(seed)
    for i in range(m):
        target = x[i] if kind == DRIVE_TORQUE else x[2 * m + i]
        y = x[s + m + i]
        y += alpha * (target - y)
        out[m + i] = y
        noisy = y + std * gaussian(sd, k, i) if std > 0.0 else y
        if kind == DRIVE_TORQUE:
            if quantum > 0.0:
                noisy = quantum * math.floor(noisy / quantum + 0.5)
            out[i] = noisy
        else:
            out[i] = noisy + bias[i]
        out[2 * m + i] = x[m + i]
    out[3 * m] = tick + 1.0
    if kind == DRIVE_TORQUE:
        speed = x[m:2 * m]
        accel = (speed - x[s + 2 * m:s + 3 * m]) / T
        tension_from_drive(out[0:m].copy(), speed, accel, params[6], params[7], params[8],
                           params[9], out[0:m])
