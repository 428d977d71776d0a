"""kernels/tension_damping.py: the damping law against its closed form, and its gains
against the platform's modes written out for a robot whose modes are known by hand."""

import math

import numpy as np

from cdpm_drake.kernels.tension_damping import (damping_gains, damping_params, damping_tick,
                                                platform_modes)

M = 3
KD, TAU, T, EA, VMAX = 50.0, 0.2, 0.002, 70000.0, 1.0


def _tick(u, tensions, lengths, memory, loop_gain=0.0):
    params = damping_params(KD, TAU, time_step=T, EA=EA, max_reel_speed=VMAX,
                            loop_gain=loop_gain)
    x = np.concatenate([u, tensions, np.zeros(M), lengths, memory])
    out = np.empty(5 * M + 1)
    damping_tick(params, x, out)
    return out[:M], out[M:2 * M], out[2 * M:]


def _memory(lowpassed, started=1.0, paid=None):
    """The block's memory: low-passed T - E (M), started, payout (M), ringing (M)."""
    paid = np.zeros(M) if paid is None else paid
    return np.concatenate([lowpassed, [started], paid, np.zeros(M)])


def _run(u, tensions_per_tick, lengths):
    memory = np.zeros(3 * M + 1)
    rows = []
    for tensions in tensions_per_tick:
        command, damping, memory = _tick(u, tensions, lengths, memory)
        rows.append((command, damping))
    return rows


def test_nan_tensions_pass_the_command_through_unchanged():
    u = np.array([0.1, -0.3, 0.0])
    rows = _run(u, [np.full(M, np.nan)] * 5, np.full(M, 2.0))
    for command, damping in rows:
        assert np.array_equal(command, u) and np.all(damping == 0.0)
    # One cable without a reading, the others damped.
    command, damping, _ = _tick(u, np.array([np.nan, 10.0, 10.0]), np.full(M, 2.0),
                                _memory(np.array([0.0, 5.0, 5.0])))
    assert damping[0] == 0.0 and command[0] == u[0] and np.all(damping[1:] > 0)


def test_constant_tensions_are_not_damped():
    u = np.array([0.05, 0.0, -0.02])
    rows = _run(u, [np.array([12.0, 30.0, 7.5])] * 50, np.full(M, 2.5))
    for command, damping in rows:
        assert np.array_equal(command, u) and np.all(damping == 0.0)


def test_a_rising_tension_pays_out_cable_by_the_closed_form():
    u = np.zeros(M)
    L = np.array([2.0, 3.0, 1.5])
    steady = np.full(M, 20.0)
    rows = _run(u, [steady, steady, steady + np.array([5.0, 0.0, -5.0])], L)
    _, damping = rows[-1]
    # Paying out (positive: the rest length grows) where the tension rose, reeling in where
    # it fell: kd (T - lowpass T) L / EA, the low-pass having moved alpha of the step.
    alpha = 1.0 - math.exp(-T / TAU)
    expected = KD * (1 - alpha) * np.array([5.0, 0.0, -5.0]) * L / EA
    np.testing.assert_allclose(damping, expected, rtol=1e-12, atol=0)
    assert damping[0] > 0 > damping[2]


def test_the_command_stays_inside_the_reel_speed_limit():
    L = np.full(M, 2.0)
    # A huge tension jump asks for far more than the limit.
    u = np.array([0.9, -0.9, 1.5])
    memory = _memory(np.full(M, 10.0))
    command, damping, _ = _tick(u, np.array([5e4, -5e4, 5e4]), L, memory)
    assert command[0] == VMAX and command[1] == -VMAX
    # A command already beyond the limit (the plant scales all reels alike) passes unchanged.
    assert command[2] == u[2] and damping[2] == 0.0


def test_modes_of_a_platform_on_three_axis_cable_pairs():
    # Six cables along +-x, +-y, +-z to a point platform at the origin, each L = 2 m: each
    # translation sees two springs EA / L (the other four are perpendicular: no first-order
    # stretch), so w = sqrt(2 EA / (L m)); the rotations have no stiffness (no lever).
    reels = 2.0 * np.vstack([np.eye(3), -np.eye(3)])
    modes = platform_modes(reels, np.zeros((6, 3)), np.zeros(3), EA, 2.5, 0.05 * np.eye(3))
    np.testing.assert_allclose(modes[:3], 0.0, atol=1e-4)
    np.testing.assert_allclose(modes[3:], math.sqrt(2 * EA / (2.0 * 2.5)), rtol=1e-12)


def test_the_gains_are_the_mode_band_capped_by_the_delays():
    modes = np.array([20.0, 40.0, 80.0, 200.0, 300.0, 400.0])
    kd, tau = damping_gains(modes, time_step=0.002, sensor_lag=0.002, drive_bandwidth=100.0)
    # sqrt(20 * 80) = 40 < pi / (4 x 15 ms) = 52.4; tau = 5 / w_1.
    assert kd == 40.0 and tau == 0.25
    slow = damping_gains(modes, time_step=0.002, sensor_lag=0.02, drive_bandwidth=100.0)[0]
    assert slow == math.pi / (4 * (0.003 + 0.02 + 0.01))
    assert damping_gains(modes, time_step=0.002, sensor_lag=0.002, drive_bandwidth=100.0,
                         gain_scale=3.0)[0] == 120.0


def test_a_tension_change_the_controller_expects_is_not_damped():
    # A hand's push raises the tensions as the statics say, and the estimate E with them:
    # only T - E is damped, so the reels do not yield to the hand.
    params = damping_params(KD, TAU, time_step=T, EA=EA, max_reel_speed=VMAX)
    L = np.full(M, 2.0)
    memory = np.zeros(3 * M + 1)
    for k in range(20):
        tensions = np.array([20.0, 30.0, 10.0]) + 0.5 * k  # rising 250 N/s
        x = np.concatenate([np.zeros(M), tensions, tensions - 3.0, L, memory])
        out = np.empty(5 * M + 1)
        damping_tick(params, x, out)
        memory = out[2 * M:]
        assert np.all(out[M:2 * M] == 0.0)
    # The same rise unexpected (E held) is damped, paying out.
    x = np.concatenate([np.zeros(M), tensions + 0.5, tensions - 3.0, L, memory])
    damping_tick(params, x, out)
    assert np.all(out[M:2 * M] > 0)


def test_modes_without_stiffness_are_left_out_of_the_band():
    # Three cables in a plane hold no motion out of it: zero modes. The band is the stiff
    # modes' (here the first two), and a robot with none gets no damping.
    modes = np.array([0.0, 0.0, 0.0, 30.0, 120.0, 300.0])
    kd, tau = damping_gains(modes, time_step=0.002, sensor_lag=0.0, drive_bandwidth=1e9)
    assert kd == math.sqrt(30.0 * 300.0) and tau == 5.0 / 30.0
    assert damping_gains(np.zeros(6), time_step=0.002, sensor_lag=0.0,
                         drive_bandwidth=100.0) == (0.0, math.inf)
    assert damping_params(0.0, math.inf, time_step=0.002, EA=EA, max_reel_speed=1.0)[1] == 0.0


def test_the_payout_is_held_against_the_length_loop():
    # After a tension step the damper pays out d per tick; the block adds K_l times what it
    # has paid out (the sum of d x tick), so that the mapping's length loop, which sees that
    # cable as a length error K_l x, does not reel it back. By hand over three ticks.
    K_l = 40.0
    L = np.full(M, 2.0)
    alpha = 1.0 - math.exp(-T / TAU)
    memory = _memory(np.zeros(M))
    step = np.array([6.0, 0.0, -3.0])
    lp, paid = np.zeros(M), np.zeros(M)
    for _ in range(3):
        command, damping, memory = _tick(np.zeros(M), step, L, memory, loop_gain=K_l)
        lp = lp + alpha * (step - lp)
        damper = KD * (step - lp) * L / EA
        np.testing.assert_allclose(damping, damper + K_l * paid, rtol=1e-12, atol=1e-15)
        paid = paid + T * damper
        np.testing.assert_allclose(memory[M + 1:2 * M + 1], paid, rtol=1e-12, atol=1e-15)
    # Held steady, the payout is tau times the low-passed step's share times kd L / EA:
    # bounded, the sum of a high-passed signal.
    for _ in range(5000):
        _, _, memory = _tick(np.zeros(M), step, L, memory, loop_gain=K_l)
    bound = KD * (TAU + T) * np.abs(step) * L / EA
    assert np.all(np.abs(memory[M + 1:2 * M + 1]) <= bound)


def test_without_a_reading_the_payout_is_let_go():
    memory = _memory(np.zeros(M), paid=np.full(M, 1e-3))
    for _ in range(2000):  # 4 s, 20 filter times
        _, damping, memory = _tick(np.zeros(M), np.full(M, np.nan), np.full(M, 2.0), memory,
                                   loop_gain=40.0)
        assert np.all(damping == 0.0)
    assert np.all(np.abs(memory[M + 1:2 * M + 1]) < 1e-10)


def test_the_ringing_is_the_variance_of_the_swing_about_the_estimate():
    # A tension ringing at 8 Hz about its estimate, amplitudes 4, 1 and 0 N: after 3 s (16
    # filter times) the block's ringing is the sine's variance a^2 / 2 within 5 % (its
    # high-pass passes 8 Hz whole: the filter's corner is 0.8 Hz); the estimate's own
    # change (E follows a hand) is not ringing.
    memory = np.zeros(3 * M + 1)
    a = np.array([4.0, 1.0, 0.0])
    params = damping_params(KD, TAU, time_step=T, EA=EA, max_reel_speed=VMAX)
    out = np.empty(5 * M + 1)
    for k in range(1500):
        E = np.full(M, 20.0) + 0.02 * k
        tensions = E + a * math.sin(2 * math.pi * 8.0 * k * T)
        x = np.concatenate([np.zeros(M), tensions, E, np.full(M, 2.0), memory])
        damping_tick(params, x, out)
        memory = out[2 * M:]
    np.testing.assert_allclose(memory[2 * M + 1:], a ** 2 / 2, rtol=0.05, atol=1e-12)


def test_a_cable_expected_past_slack_is_not_paid_out():
    # A hand the statics say takes cable 1 below zero (E from 20 N down to -40 N) slackens it:
    # its measured tension falls to 0 with the estimate, not below. A cable carries no less
    # than nothing, so T - E is damped with E at 0 there: the slack cable is not paid out
    # (the damper reading the missing -40 N as a surplus paid a slack cable out at 50-80 mm/s).
    params = damping_params(KD, TAU, time_step=T, EA=EA, max_reel_speed=VMAX)
    L = np.full(M, 2.0)
    memory = np.zeros(3 * M + 1)
    payout = np.zeros(M)
    for k in range(60):
        expected = np.array([max(20.0 - 3.0 * k, -40.0), 30.0, 10.0])
        measured = np.array([max(expected[0], 0.0), 30.0, 10.0])
        x = np.concatenate([np.zeros(M), measured, expected, L, memory])
        out = np.empty(5 * M + 1)
        damping_tick(params, x, out)
        memory = out[2 * M:]
        payout += out[M:2 * M] * T
    # Measured as expected, clamped: nothing unexpected, nothing damped.
    np.testing.assert_array_equal(payout, 0.0)
