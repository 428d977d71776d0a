"""The ringing the encoders cannot see, predicted from the command (no tension sensor): a
model of the platform's modes on its elastic cables, driven by the acceleration the reels
give it and by the measured hand force, and the swing it may put on each cable. numpy and
numba, no Drake.

Why: on a robot with mass the platform rings at its lightly damped modes (4-14 Hz on the
shipped robots), and the reel encoders do not see it (the drives' velocity loops are stiff:
the reels pay out what they are told, whatever the cables pull). The tension estimate comes
from the encoders, so a cable can ring slack while its estimate says it is taut. What rings
it is known to the controller: the commanded acceleration and the hand force. Where the safety filter switches
from the admittance's acceleration (up to limits.max_acceleration) to its braking, the
platform's acceleration steps by both; a step da of the acceleration moves the cables'
static force by m da and the tensions overshoot it by as much again (an undamped step
response), W^+ m da about the new statics.

The model, per tick of `step` s, in the platform's 6 coordinates (translation m, small
rotation rad) relative to the quasi-static pose (the pose the encoders measure):

    M d'' + C d' + K d = -M a + w_H,

M = diag(m I, R I_B R^T), K = W diag(EA / L) W^T (the cables' elastic stiffness; W the
wrench matrix at the estimated pose, L the cables' lengths), C = W diag(c) W^T (the cables'
damping c, N s/m), a the commanded twist's rate after the drives' first-order lag (time
constant 1 / bandwidth: the reels, and so the cables' ends, follow the command through it),
w_H the measured hand force's wrench about the centre (at the handle) less its value at
the first tick (the estimate holds the statics of both), integrated by the trapezoidal rule
(Newmark's average acceleration: unconditionally stable, no numerical damping). The ringing
is d less its quasi-static part d_s = K^-1 (-M a + w_H), and its
energy E = 1/2 (d - d_s)^T K (d - d_s) + 1/2 d'^T M d' bounds the swing of cable i's tension
(Cauchy-Schwarz in the K norm):

    A_i = k_i sqrt(2 E w_i^T K^-1 w_i),   k_i = EA / L_i, w_i the column of W.

A cable whose estimate less its swing A_i is below the floor the target keeps
(controller.tension_floor) may ring below it unseen: the block warns of it from the tick the
command or the hand rings it, before the cable is slack (measured: docs/dynamic_plant.md).
The bound is conservative where several modes share the energy (about twice the truth's
swing at a start from rest on cube_8cable) and can fall short where the truth rings from
more than the model sees (exp2's lift: 8 N of 11 N on cable 2).

What it does not model: the length loop's corrections, a hand force beyond what the sensor
measures (its noise counts as force), and numbers (mass, inertia, EA) off the robot's.
"""

import math

import numba
import numpy as np

from cdpm_drake.kernels.pose import (cholesky, cholesky_solve, posed_cables, solve_spd,
                                     wrench_columns)

_jit = numba.njit(cache=True, error_model="numpy")

# params layout.
(P_MASS, P_INERTIA, P_EA, P_DAMPING, P_BANDWIDTH, P_STEP, P_FLOOR, P_WARMUP, P_HANDLE) = (
    0, 1, 10, 11, 12, 13, 14, 15, 16)
PARAMS = 19
# The memory: ticks (1), the lagged command twist (6), d (6), d' (6), the hand force at the
# first tick (3).
MEMORY = 22


def ringing_params(dynamics, *, time_step: float, floor: float, warmup: int) -> np.ndarray:
    """The block's parameters: the platform (mass kg, inertia (3, 3) kg m^2 platform frame),
    the cables (EA N, damping N s/m), the drives' bandwidth (rad/s), the tick (s), the floor
    (N) a cable's estimate less its swing must stay above, and the ticks the estimate
    settles before anything is named."""
    p = np.zeros(PARAMS)
    p[P_MASS] = float(dynamics.mass)
    p[P_INERTIA:P_INERTIA + 9] = np.asarray(dynamics.inertia, dtype=float).ravel()
    p[P_EA] = float(dynamics.EA)
    p[P_DAMPING] = float(dynamics.damping)
    p[P_BANDWIDTH] = float(dynamics.bandwidth)
    p[P_STEP] = float(time_step)
    p[P_FLOOR] = float(floor)
    p[P_WARMUP] = float(warmup)
    p[P_HANDLE:P_HANDLE + 3] = np.asarray(dynamics.handle, dtype=float)
    return p


def ringing_sizes(m: int) -> dict:
    """x: p (3), R (9), v (3), w (3), F_H (3), T_estimate (m), memory (MEMORY); out: swing
    (m, N), warned (m, 0/1), next memory (MEMORY)."""
    return {"x": m + 21 + MEMORY, "out": 2 * m + MEMORY, "memory": MEMORY, "memory_at": 2 * m}


# The work arrays' floats: six (6, 6) matrices (K, C, M, the Newmark system, M's and K's
# Cholesky factors), nine 6-vectors, two 3-vectors, and per cable W's column (6), u (3),
# R b (3), k and L.
_FIXED, _PER_CABLE = 6 * 36 + 9 * 6 + 2 * 3, 6 + 3 + 3 + 1 + 1


def ringing_scratch(m: int) -> np.ndarray:
    """The work arrays of `ringing_tick` for m cables, one flat buffer allocated once per
    block (`_views` carves it): a tick allocates nothing."""
    return np.zeros(_FIXED + _PER_CABLE * m)


@_jit
def _take(buf, o, r, c):
    return buf[o:o + r * c].reshape((r, c)), o + r * c


@_jit
def _take1(buf, o, r):
    return buf[o:o + r], o + r


@_jit
def _views(scratch, m):
    """The work arrays in `ringing_scratch(m)`: (K, C, M, A, MF, KF) (6, 6), W (6, m),
    (u, Rb) (m, 3), (k, L) (m,), (a, f, rhs, acc0, d_next, ring, qs, col, y) (6,),
    (dF, h) (3,)."""
    K, o = _take(scratch, 0, 6, 6)
    C, o = _take(scratch, o, 6, 6)
    M, o = _take(scratch, o, 6, 6)
    A, o = _take(scratch, o, 6, 6)
    MF, o = _take(scratch, o, 6, 6)
    KF, o = _take(scratch, o, 6, 6)
    W, o = _take(scratch, o, 6, m)
    u, o = _take(scratch, o, m, 3)
    Rb, o = _take(scratch, o, m, 3)
    k, o = _take1(scratch, o, m)
    L, o = _take1(scratch, o, m)
    a, o = _take1(scratch, o, 6)
    f, o = _take1(scratch, o, 6)
    rhs, o = _take1(scratch, o, 6)
    acc0, o = _take1(scratch, o, 6)
    d_next, o = _take1(scratch, o, 6)
    ring, o = _take1(scratch, o, 6)
    qs, o = _take1(scratch, o, 6)
    col, o = _take1(scratch, o, 6)
    y, o = _take1(scratch, o, 6)
    dF, o = _take1(scratch, o, 3)
    h, o = _take1(scratch, o, 3)
    return ((K, C, M, A, MF, KF), W, (u, Rb), (k, L),
            (a, f, rhs, acc0, d_next, ring, qs, col, y), (dF, h))


@_jit
def _stiffness(reels, attachments, params, p, R, K, C, M, W, k, u, Rb, L):
    """K, C, M (6, 6), W (6, m) and k (m,) = EA / L at the pose (p, R) (module docstring);
    u, Rb (m, 3) and L (m,): the cables' work arrays."""
    m = reels.shape[0]
    posed_cables(reels, attachments, p, R, u, Rb, L)
    wrench_columns(u, Rb, W)
    c = params[P_DAMPING]
    for i in range(m):
        k[i] = params[P_EA] / L[i]
    for a in range(6):
        for b in range(6):
            sk, sc = 0.0, 0.0
            for i in range(m):
                sk += W[a, i] * W[b, i] * k[i]
                sc += W[a, i] * W[b, i] * c
            K[a, b], C[a, b], M[a, b] = sk, sc, 0.0
    for a in range(3):
        M[a, a] = params[P_MASS]
        for b in range(3):  # R I_B R^T
            total = 0.0
            for e in range(3):
                for f in range(3):
                    total += R[a, e] * params[P_INERTIA + 3 * e + f] * R[b, f]
            M[3 + a, 3 + b] = total


@_jit
def _factor(A, F):
    """F = A's Cholesky factor (A (6, 6) symmetric positive definite, kept); False where it
    is not."""
    for r in range(6):
        for c in range(6):
            F[r, c] = A[r, c]
    return cholesky(F)


@_jit
def ringing_tick(reels, attachments, params, scratch, x, out):
    """One tick (module docstring). x = [p (3) m, R (9), v (3) m/s, w (3) rad/s (the
    command), F_H (3) N (the measured hand force, at the handle), T_estimate (m) N, memory:
    ticks, v_lag (6), d (6), d' (6), F_H at the first tick (3)]; out = [swing (m) N, warned
    (m: 1 where the estimate less the swing is below the floor, after the warm-up), next
    memory (MEMORY)]; scratch: `ringing_scratch(m)`, the block's work arrays. Returns the
    1-based cable furthest below (0: none)."""
    m = reels.shape[0]
    p = x[0:3]
    R = x[3:12].reshape((3, 3))
    F = x[18:21]
    T = x[21:21 + m]
    mem = x[21 + m:21 + m + MEMORY]
    nxt = out[2 * m:2 * m + MEMORY]
    step = params[P_STEP]
    (K, C, M, A, MF, KF), W, (u, Rb), (k, L), vectors, (dF, h) = _views(scratch, m)
    a, f, rhs, acc0, d_next, ring, qs, col, y = vectors
    _stiffness(reels, attachments, params, p, R, K, C, M, W, k, u, Rb, L)
    # The command twist after the drives' lag, and its rate: the acceleration the reels give.
    first = mem[0] == 0.0
    g = 1.0 - math.exp(-step * params[P_BANDWIDTH])
    for j in range(6):
        command = x[12 + j]
        lagged = command if first else mem[1 + j] + g * (command - mem[1 + j])
        a[j] = 0.0 if first else (lagged - mem[1 + j]) / step
        nxt[1 + j] = lagged
    d, dd = mem[7:13], mem[13:19]
    # The force on the modes: the inertia of the reels' acceleration and the hand's wrench
    # (about the centre, at the handle) as it changed since the first tick (the estimate
    # holds the statics of both).
    for j in range(3):
        nxt[19 + j] = F[j] if first else mem[19 + j]
        dF[j] = F[j] - nxt[19 + j]
    for r in range(3):
        h[r] = (R[r, 0] * params[P_HANDLE] + R[r, 1] * params[P_HANDLE + 1]
                + R[r, 2] * params[P_HANDLE + 2])
    moment = (h[1] * dF[2] - h[2] * dF[1], h[2] * dF[0] - h[0] * dF[2],
              h[0] * dF[1] - h[1] * dF[0])
    for r in range(6):
        total = 0.0
        for j in range(6):
            total += M[r, j] * a[j]
        f[r] = (dF[r] if r < 3 else moment[r - 3]) - total
    # Newmark, average acceleration: the acceleration at the start of the tick, then the
    # displacement at its end from (K + 2/h C + 4/h^2 M) d_next = f + M (4/h^2 d + 4/h d' +
    # d'') + C (2/h d + d').
    for r in range(6):
        total = f[r]
        for j in range(6):
            total -= C[r, j] * dd[j] + K[r, j] * d[j]
        rhs[r] = total
    ok = _factor(M, MF)
    if ok:
        cholesky_solve(MF, rhs, acc0)
    for r in range(6):
        total = f[r]
        for j in range(6):
            A[r, j] = K[r, j] + 2.0 / step * C[r, j] + 4.0 / step ** 2 * M[r, j]
            total += (M[r, j] * (4.0 / step ** 2 * d[j] + 4.0 / step * dd[j] + acc0[j])
                      + C[r, j] * (2.0 / step * d[j] + dd[j]))
        rhs[r] = total
    for j in range(6):  # what a failed solve leaves
        d_next[j], qs[j] = 0.0, 0.0
    # K's factor once: the quasi-static displacement and every cable's w_i^T K^-1 w_i.
    ok = ok and solve_spd(A, rhs, d_next) and _factor(K, KF)
    if ok:
        cholesky_solve(KF, f, qs)
    for j in range(6):
        nxt[13 + j] = 2.0 / step * (d_next[j] - d[j]) - dd[j] if ok else 0.0
        nxt[7 + j] = d_next[j] if ok else 0.0
        ring[j] = nxt[7 + j] - qs[j]
    energy = 0.0
    for r in range(6):
        for j in range(6):
            energy += 0.5 * (ring[r] * K[r, j] * ring[j] + nxt[13 + r] * M[r, j] * nxt[13 + j])
    nxt[0] = min(mem[0] + 1.0, max(params[P_WARMUP], 1.0))
    settled = mem[0] >= params[P_WARMUP]
    cable, lowest = 0, params[P_FLOOR]
    for i in range(m):
        for r in range(6):
            col[r] = W[r, i]
        share = 0.0
        if ok:
            cholesky_solve(KF, col, y)
            for r in range(6):
                share += col[r] * y[r]
        out[i] = k[i] * math.sqrt(max(2.0 * energy * share, 0.0))
        below = settled and T[i] - out[i] < params[P_FLOOR]
        out[m + i] = 1.0 if below else 0.0
        if below and T[i] - out[i] < lowest:
            cable, lowest = i + 1, T[i] - out[i]
    return cable
