"""The tension path's numbers, derived from the robot: how far the tension target leads the
hand, how fast each cable's internal force may rise, and from those the fastest hand the
robot can follow. numpy, no Drake (full_pose.tension_tick uses them; `cdpm info` and the run
summary print the fastest hand).

The path from the hand to the cables' tensions: the hand force is taken a tick old (the
dynamic plant computes it in the step that takes the reel command), the Jacobian mapping's
reel command acts a tick later, and the drives' velocity loop follows it with the time
constant 1 / bandwidth. So the target leads the hand by

    lead = 2 time_step + 1 / bandwidth                     (14 ms on the shipped robots)

along the hand force's rate, low-passed with the drives' own time constant (rate_time = 1 /
bandwidth: a faster filter passes the force sensor's noise, a slower one lags the ramp).

The statics of the hand (the minimum-norm part of the distribution) come by themselves: the
platform moves the micrometres that stretch the cables for them. The internal force (the part
along the wrench matrix's nullspace) only the reels make, stretching cable i by L_i / EA per
newton; the reel speed the platform's motion leaves is max_reel_speed - max_velocity, so cable
i's internal share may rise at most

    S_i = EA / L_i (max_reel_speed - max_velocity)    N/s  (17 kN/s on a 2 m, 70 kN cable).

A hand along u asks cable i for |N_i . dlam/dF| N/s per N/s of hand (lam the target's internal
force, dlam/dF its derivative along u: finite differences of the target itself); the fastest
hand the robot follows along u is the smallest S_i over that, over the hand's magnitudes up to
a bound (the target's regime changes with the hand: where no cable is at the floor the internal
force does not move).

What rings the cables beyond that: the platform takes a change of the hand as its own
displacement, and a change faster than its slowest mode overshoots. With K = W diag(EA/L) W^T
and M = diag(m I, I_c), the mass-normalised modes phi_k, w_k^2 (K phi = w^2 M phi), a step
dw of the hand's wrench moves mode k by phi_k . dw / w_k^2 (1 - cos w_k t), and cable i's
tension by EA / L_i (W_i . phi_k) times that: about its new statics by at most

    swing_i = sum_k |EA / L_i (W_i . phi_k) (phi_k . dw)| / w_k^2

(one mode: the statics' change itself, a step overshooting to twice it; more: a cable the
modes load in turn swings wider, cube_8cable's cable 3 ~1.8 times its statics under a 40 N
step). A ramp at rate r leaves r / w_1 unsettled. So the part of the hand the platform has not
settled to, the hand now less the hand low-passed over

    settle = 1 / w_1                                        (38 ms on paper_7cable)

rings each cable by up to that swing (`ringing_cable`, the modes of the start pose,
`modal_params`); where it is more than the command holds the cable by, the hand is faster
than the tension path can follow, from the first tick it is measured. The hand now: the
force sensor's sliding average lags a ramp by (window - 1) / 2 ticks (`hand_lag`), and its
rate over one tick times that lag is what the average has not yet taken in (a step of s
shows as s (k + 4.5) / 10 k ticks in with the default 10 samples: 55 % at its first tick).
"""

import math

import numba
import numpy as np

from cdpm_drake.kernels.pose import solve_spd
from cdpm_drake.kernels.tension_damping import modal_problem

_jit = numba.njit(cache=True, error_model="numpy")

# Hand magnitudes (N) the fastest hand is taken over, and the finite-difference step (N).
HAND_STEPS = 17
HAND_DELTA = 0.05


def lead_time(time_step: float, bandwidth: float) -> float:
    """How far (s) the tension target leads the measured hand force (module docstring)."""
    return 2.0 * float(time_step) + 1.0 / float(bandwidth)


def rate_time(bandwidth: float) -> float:
    """The time constant (s) of the hand force rate's low-pass: the drives' (1 / bandwidth)."""
    return 1.0 / float(bandwidth)


def stretch_speed(max_reel_speed: float, max_velocity: float) -> float:
    """The reel speed (m/s) the platform's motion leaves for stretching the cables; > 0 (a
    robot whose motion takes every reel's speed still gets a tenth of it)."""
    return max(float(max_reel_speed) - float(max_velocity), 0.1 * float(max_reel_speed))


def _modes(robot, position):
    """(w^2 (6,), Phi (6, 6) mass-normalised, columns the modes) at `position` (m, level)."""
    d = robot.dynamics
    A, C = modal_problem(robot.reels, robot.attachments, position, d.EA, d.mass, d.inertia)
    lam, V = np.linalg.eigh(A)
    return np.clip(lam, 0.0, None), np.linalg.solve(C.T, V)


def settle_time(robot, position) -> float:
    """1 / w_1 (s): the platform's slowest mode on its elastic cables at `position` (m, level),
    the time constant over which it settles to a hand (module docstring); 0 for a robot whose
    cables resist no motion."""
    lam, _ = _modes(robot, position)
    stiff = lam[lam > 1e-12 * max(float(lam.max()), 1e-300)]
    return 1.0 / math.sqrt(float(stiff[0])) if stiff.size else 0.0


def modal_params(robot, position) -> np.ndarray:
    """[w_k^2 (6), Phi (36, row-major: Phi[a, k] the k-th mode's a-th component)] at
    `position` (m, level): what `ringing_cable` takes as `modes`."""
    lam, Phi = _modes(robot, position)
    return np.concatenate([lam, Phi.ravel()])


def hand_lag(filter_window: int, time_step: float) -> float:
    """How far (s) the force sensor's sliding average of `filter_window` samples of
    `time_step` s lags the hand: (window - 1) / 2 samples."""
    return 0.5 * (int(filter_window) - 1) * float(time_step)


def _target(T_p, N, floor, hard_floor, ceiling):
    from cdpm_drake.kernels.full_pose import distribution_1d_bounded, distribution_bounded

    T = np.empty(T_p.size)
    if N.shape[1] == 1:
        distribution_1d_bounded(T_p, np.ascontiguousarray(N[:, 0]), floor, hard_floor,
                                ceiling, T)
    else:
        distribution_bounded(T_p, np.ascontiguousarray(N), floor, hard_floor, ceiling, T)
    return T


def internal_rate(W, wrench_of, N, floor, hard_floor, ceiling, F):
    """dlam/dF (k,): the target's internal force (N^T T_target, N orthonormal (m, k)) per N
    of hand, by central differences of the target (the distribution of
    full_pose.tension_tick) at the hand force F (3,) N; wrench_of(F) -> the wrench (6,)."""
    from cdpm_drake.kernels.nullspace import nullspace_form

    lam = []
    for sign in (-1.0, 1.0):
        T_p, _, _ = nullspace_form(W, wrench_of(F * (1.0 + sign * HAND_DELTA / max(
            np.linalg.norm(F), 1e-12))))
        lam.append(N.T @ _target(np.ascontiguousarray(T_p), N, floor, hard_floor, ceiling))
    return (lam[1] - lam[0]) / (2.0 * HAND_DELTA)


def fastest_hand(W, lengths, EA, wrench_of, direction, *, floor, hard_floor, ceiling,
                 speed, max_hand=40.0):
    """The fastest hand (N/s) along `direction` (3,) the tension path follows at a pose whose
    wrench matrix is W (6, m) and cable lengths `lengths` (m,): min over hands F = f u (f up
    to max_hand N) and cables i of S_i / |N_i . dlam/dF| (module docstring), S_i = EA /
    L_i speed; inf where the internal force never has to move."""
    from cdpm_drake.kernels.nullspace import nullspace_form

    u = np.asarray(direction, dtype=float)
    u = u / np.linalg.norm(u)
    _, N, _ = nullspace_form(W, wrench_of(np.zeros(3)))
    if N.shape[1] == 0:
        return math.inf
    S = float(EA) / np.asarray(lengths, dtype=float) * float(speed)
    best = math.inf
    for f in np.linspace(1.0, max_hand, HAND_STEPS):
        need = np.abs(N @ internal_rate(W, wrench_of, N, floor, hard_floor, ceiling, f * u))
        with np.errstate(divide="ignore"):
            best = min(best, float(np.min(np.where(need > 1e-9, S / need, np.inf))))
    return best


@_jit
def lead_statics(W, w, w_lead, T_p):
    """T_p (the minimum-norm distribution of w, W (6, m) of rank 6) moved to w_lead's: T_p -
    W^T (W W^T)^-1 (w_lead - w), linear in the wrench (W T + w = 0); False (T_p untouched)
    where W W^T cannot be factored."""
    m = W.shape[1]
    G, dw, y = np.empty((6, 6)), np.empty(6), np.zeros(6)
    for a in range(6):
        dw[a] = w_lead[a] - w[a]
        for b in range(6):
            total = 0.0
            for i in range(m):
                total += W[a, i] * W[b, i]
            G[a, b] = total
    if not solve_spd(G, dw, y):
        return False
    for i in range(m):
        total = 0.0
        for a in range(6):
            total += W[a, i] * y[a]
        T_p[i] -= total
    return True


@_jit
def ringing_cable(W, w, w_slow, T_command, L0, EA, modes, swing):
    """The cable (1-based; 0: none) the hand's unsettled part may ring slack: swing (m,) N
    becomes sum_k |EA / L0_i (W_i . phi_k) (phi_k . (w - w_slow))| / w_k^2 (the module
    docstring's bound; W (6, m) at the pose, L0 (m,) m, `modes` modal_params', w and w_slow
    the wrenches of the hand now and of the hand the platform has settled to), and the
    cable named is the one whose swing exceeds its command T_command (m,) N most."""
    m = W.shape[1]
    for i in range(m):
        swing[i] = 0.0
    for k in range(6):
        if not modes[k] > 0.0:
            continue  # a mode without stiffness: nothing rings there
        q = 0.0
        for a in range(6):
            q += modes[6 + 6 * a + k] * (w[a] - w_slow[a])
        q /= modes[k]
        for i in range(m):
            share = 0.0
            for a in range(6):
                share += W[a, i] * modes[6 + 6 * a + k]
            swing[i] += abs(EA / L0[i] * share * q)
    deepest, cable = 0.0, 0
    for i in range(m):
        if swing[i] - T_command[i] > deepest:
            deepest, cable = swing[i] - T_command[i], i + 1
    return cable
