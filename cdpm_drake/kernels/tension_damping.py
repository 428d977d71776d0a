"""The tension damping block's per-tick math (issue 31): each reel a damper in series with
its cable, driven by the measured tension. numpy and numba, no Drake.

Law, per cable i (reel speeds m/s of cable, positive paying out; tensions N):

    u_i = u_map,i + kd (D_i - lowpass(D_i)) L_i / EA,   D_i = T_i - E_i

T_i the measured tension, E_i the tension the controller expects (damping_tick says why),
lowpass a first-order filter of time constant tau, L_i the cable's
(encoder) length, EA its axial stiffness. (T - lowpass T) L / EA is the stretch the tension's
fast part puts on the cable; paying it out at rate kd makes the reel a damper c_i = k_i / kd
(k_i = EA / L_i) in series with the cable's spring: a Maxwell element, whose loss per cycle
at frequency w is largest at kd = w (its loss factor kd w / (kd^2 + w^2), 1/2 there, 0.4 at
kd = w/2 or 2 w).

Gains (`damping_gains`, from the robot and the loop, never per robot by hand):
- the platform's modes at the start pose: K = W diag(EA / L) W^T (6 x 6, the cables' elastic
  stiffness, W the wrench matrix), M = diag(m I, I_c); w_1 <= w_2 <= ... from K v = w^2 M v.
  A hand's force excites the three lowest (the translations, mostly): kd = sqrt(w_1 w_3), the
  middle of that band on a log scale, where the Maxwell element's loss factor is >= 0.4 at
  both ends while w_3 <= 4 w_1;
- the loop's delays cap it: the command reaches the cable after the delay tau_d = 1.5 ticks
  (the sensor's sample held a tick, the command held over the next) + the sensor's lag
  (current filter or load cell bandwidth) + the drive's 1 / bandwidth. A damper whose force
  lags by phi = kd tau_d at its own corner is a damper of cos(phi) and a spring of sin(phi);
  kd <= pi / (4 tau_d) keeps phi <= 45 deg (half or more of its action damping). The loop's
  gain through one cable is kd times the share of that cable's stretch the platform does
  not take up (1 - k_i u_i^T K^-1 u_i, ~1/7 on average for 7 cables and 6 dof), so the
  tensions diverge only at several times the cap (measured: README, docs/dynamic_plant.md);
- the low-pass sits a factor 5 below the lowest mode, tau = 5 / w_1: the high-passed tension
  passes w_1 with 11 deg of phase lead and a hand's steady force (slower) not at all.
"""

import math

import numba
import numpy as np

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


def platform_modes(reels, attachments, p, EA, mass, inertia) -> np.ndarray:
    """The platform's natural angular frequencies (6,) rad/s, ascending, on its elastic
    cables at position p (m, level): reels (m, 3) m base frame, attachments (m, 3) m
    platform frame, EA N, mass kg, inertia (3, 3) kg m^2 about the centre."""
    A, _ = modal_problem(reels, attachments, p, EA, mass, inertia)
    lam = np.linalg.eigvalsh(A)
    return np.sqrt(np.clip(lam, 0.0, None))


def modal_problem(reels, attachments, p, EA, mass, inertia):
    """(A, C): K phi = w^2 M phi as the symmetric A y = w^2 y, y = C^T phi, C the Cholesky
    factor of M (K = W diag(EA / L) W^T, M = diag(mass I, inertia)), at position p (m, level);
    arguments as platform_modes'."""
    rho = np.asarray(reels, float) - (np.asarray(p, float) + np.asarray(attachments, float))
    L = np.linalg.norm(rho, axis=1)
    u = rho / L[:, None]
    W = np.vstack([u.T, np.cross(attachments, u).T])
    K = W @ np.diag(EA / L) @ W.T
    M = np.zeros((6, 6))
    M[:3, :3] = mass * np.eye(3)
    M[3:, 3:] = inertia
    C = np.linalg.cholesky(M)
    A = np.linalg.solve(C, np.linalg.solve(C, K).T)
    return 0.5 * (A + A.T), C


def damping_gains(modes, *, time_step, sensor_lag, drive_bandwidth, gain_scale=1.0):
    """(kd 1/s, low-pass time constant s) from the platform's modes (rad/s, ascending) and
    the loop's delays: the tick s, the sensor's lag s and the drives' bandwidth rad/s (the
    module's docstring derives them)."""
    modes = np.asarray(modes, dtype=float)
    # A robot whose cables cannot resist every motion (fewer than six, or a singular pose)
    # has modes without stiffness: nothing rings there; the band is its stiff modes'.
    stiff = modes[modes > 1e-6 * max(float(modes.max()), 1e-300)]
    if stiff.size == 0:
        return 0.0, math.inf
    w1, w3 = float(stiff[0]), float(stiff[min(2, stiff.size - 1)])
    delay = 1.5 * time_step + sensor_lag + 1.0 / drive_bandwidth
    kd = min(math.sqrt(w1 * w3), math.pi / (4.0 * delay))
    return gain_scale * kd, 5.0 / w1


def damping_params(kd, tau, *, time_step, EA, max_reel_speed, estimate=True,
                   loop_gain=0.0) -> np.ndarray:
    """damping_tick's params: [kd 1/s, the low-pass's gain per tick, EA N, reel speed limit
    m/s, 1 where the expected tensions E are an estimate (0: none, E taken as zero), the
    length loop's proportional gain 1/s downstream of which the damping's payout is held
    (0: none; damping_tick says why)]."""
    return np.array([kd, 1.0 - math.exp(-time_step / tau) if tau > 0 else 1.0, EA,
                     max_reel_speed,
                     1.0 if estimate else 0.0, float(loop_gain), float(time_step)],
                    dtype=float)


@_jit
def damping_tick(params, x, out):
    """x = [u (m) m/s the mapping's reel command, T (m) N measured tensions, E (m) N the
    tensions the controller expects (its estimate from the weight, the measured hand force,
    the commanded acceleration and the lengths; ignored without one, params[4] = 0), L (m) m
    cable lengths,
    memory: low-passed T - E (m) N, started (1), payout (m) m, ringing (m) N^2]; out = [u +
    damping (m) m/s, damping (m) m/s, next memory (3 m + 1)].

    What is damped is the measured tension's part the controller does not expect, T - E: a
    hand that pushes raises the tensions as the statics say (E follows it, from the force
    sensor), and paying that out would only make the platform yield to the hand (measured:
    a 40 N push across exp2's pair 1-3 went 5.2 mm below d_l with T alone, 1.2 mm without
    damping); the ringing the encoders cannot see is not in E. E is taken no lower than
    zero: a cable the estimate expects past slack is expected slack.

    The payout is held against the length loop: the mapping's loop (gain K_l =
    params[5]) measures the cable the damper paid out, x = sum of its speeds x tick, as a
    length error and reels it back at K_l x; below K_l (40 1/s: 6 Hz, the lowest modes of
    the shipped robots are 3.5-4.5 Hz) it cancelled most of the damping (exp2's 20 N lift
    rang at 3.3 Hz, 4 N, undamped). So the block adds K_l x to the command: the loop's
    reference moves with the damper. x stays bounded: the damper's speed is the tension's
    high-passed part, whose sum is tau times the low-passed one (no drift); the loop's
    integral takes up what lasts.

    The ringing is the variance of the high-passed T - E (the part damped), low-passed with
    the same filter: how far the tension swings about what the controller expects, which
    the tension target's floor must clear (full_pose.tension_tick).

    A cable whose tension is not finite (no sensor, a missing reading) gets no damping, its
    filter held and its payout let go over the filter's time; a command already beyond the
    reel speed limit passes unchanged (the plant scales it); else the sum is clipped to the
    limit. The filter starts at the first finite reading (no kick at the start)."""
    m = (x.shape[0] - 1) // 7
    kd, alpha, EA, vmax = params[0], params[1], params[2], params[3]
    expected = params[4] > 0.5
    loop_gain, step = params[5], params[6]
    started = x[5 * m] > 0.5
    out[3 * m] = x[5 * m]
    for i in range(m):
        u = x[i]
        # A cable carries no less than nothing: an estimate below zero (a hand the statics
        # say takes the cable past slack) expects a slack cable, not a push, else the slack
        # cable's missing push reads as a surplus and the damper pays it out further.
        T = x[m + i] - max(x[2 * m + i], 0.0) if expected else x[m + i]
        lp = x[4 * m + i]
        paid = x[5 * m + 1 + i]
        ringing = x[6 * m + 1 + i]
        d = 0.0
        if math.isfinite(T):
            if not (started and math.isfinite(lp)):
                lp = T
            lp += alpha * (T - lp)
            ringing += alpha * ((T - lp) * (T - lp) - ringing)
            if abs(u) <= vmax:
                damper = kd * (T - lp) * x[3 * m + i] / EA
                v = u + damper + loop_gain * paid
                v = vmax if v > vmax else (-vmax if v < -vmax else v)
                d = v - u
                paid += step * damper
            out[3 * m] = 1.0
        else:
            paid -= alpha * paid
        out[i] = u + d
        out[m + i] = d
        out[2 * m + i] = lp
        out[3 * m + 1 + i] = paid
        out[4 * m + 1 + i] = ringing
