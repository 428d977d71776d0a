"""The cable-length loop of the Jacobian velocity mapping: l_dot = J v + K_l (l_d - l).

Kernel cases check `kinematics.length_loop_tick` against independent numbers (the Jacobian by
finite differences of `cable_lengths`, closed-form decay of an error under ideal reels);
diagram cases check it on the plants (the kinematic plant's logs, the dynamic plant's
encoders), never against the controller's own estimate of where the platform is.
"""

import math

import numpy as np
import pytest

from cdpm_drake.kernels.kinematics import cable_lengths, length_loop_sizes, length_loop_tick
from cdpm_drake.robot import load_robot
from cdpm_drake.config import ScenarioError, load_scenario
from cdpm_drake.runs.simulate import simulate

T = 0.002
ROBOT = load_robot("paper_7cable")
M = ROBOT.num_cables
OFFSETS = np.ascontiguousarray(ROBOT.attachments - ROBOT.reels)
P = np.array([1.77, 2.4, 1.3])
V = np.array([0.12, -0.07, 0.2])


def fd_rates(p, v, h=1e-6):
    """J(p) v by central differences of the lengths (independent of the kernel's J)."""
    return (cable_lengths(ROBOT, p + h * v) - cable_lengths(ROBOT, p - h * v)) / (2 * h)


def tick(p_hat, v, lengths, memory, gain=20.0, dead_band=0.0):
    x = np.concatenate([p_hat, v, lengths, memory])
    out = np.empty(length_loop_sizes(M)["out"])
    length_loop_tick(OFFSETS, gain, T, dead_band, x, out)
    return out[:M], out[M:2 * M], out[2 * M:]


def test_sizes_follow_the_cable_count():
    assert length_loop_sizes(7) == {"inputs": 13, "memory": 11, "x": 24, "out": 25}


def test_the_first_tick_latches_the_measured_lengths_and_sends_the_feedforward():
    offset = np.linspace(-0.004, 0.003, M)  # encoders' zero and stretch: not on the geometry
    measured = cable_lengths(ROBOT, P) + offset
    command, commanded, memory = tick(P, V, measured, np.zeros(M + 4))
    np.testing.assert_allclose(command, fd_rates(P, V), rtol=0, atol=1e-9)
    np.testing.assert_array_equal(commanded, measured)  # no error at the start
    # p_d started at the estimate and advanced by one tick of v (its curvature term is
    # T^2 |v|^2 / L ~ 1e-8 m here).
    np.testing.assert_allclose(memory[:3], P + T * V, rtol=0, atol=1e-7)
    np.testing.assert_allclose(memory[3:3 + M], offset, rtol=0, atol=1e-12)
    assert memory[-1] == 1.0


def test_the_commanded_position_moves_as_ideal_reels_move_the_platform():
    """One tick: p_d advances to the rigid platform whose lengths best fit (least squares)
    the lengths of p_d plus T J v, which is what ideal reels given J v do to the platform.
    Reference: scipy's least_squares on the same lengths."""
    from scipy.optimize import least_squares

    _, _, memory = tick(P, V, cable_lengths(ROBOT, P), np.zeros(M + 4))
    target = cable_lengths(ROBOT, P) + T * fd_rates(P, V)
    fit = least_squares(lambda q: cable_lengths(ROBOT, q) - target, P, xtol=1e-15,
                        ftol=1e-15, gtol=1e-15).x
    np.testing.assert_allclose(memory[:3], fit, rtol=0, atol=1e-11)


def test_a_length_error_is_fed_back_with_the_gain():
    measured = cable_lengths(ROBOT, P)
    _, _, memory = tick(P, V, measured, np.zeros(M + 4), gain=13.5)
    # Tick 2: the encoders lag the commanded lengths by `lag` (m).
    p_d = memory[:3]
    l_d = cable_lengths(ROBOT, p_d) + memory[3:3 + M]
    lag = np.array([1.0, -2.0, 0.5, 0.0, 3.0, -0.25, 1.5]) * 1e-3
    command, commanded, _ = tick(P, V, l_d - lag, memory, gain=13.5)
    np.testing.assert_allclose(commanded, l_d, rtol=0, atol=1e-12)
    np.testing.assert_allclose(command, fd_rates(P, V) + 13.5 * lag, rtol=0, atol=1e-9)


def test_zero_gain_is_the_papers_open_loop_whatever_the_error():
    measured = cable_lengths(ROBOT, P)
    _, _, memory = tick(P, V, measured, np.zeros(M + 4), gain=0.0)
    command, _, _ = tick(P, V, measured + 0.01, memory, gain=0.0)
    open_loop = np.empty(M)
    from cdpm_drake.kernels.kinematics import reel_rates
    reel_rates(OFFSETS, P, V, open_loop)
    np.testing.assert_array_equal(command, open_loop)


def test_the_commanded_position_integrates_the_velocity():
    """Ideal reels and an exact estimate (p_hat = p_d every tick): after n ticks of a constant
    v the commanded position is p + n T v, up to the curvature of the lengths: each tick's
    fit misses the straight step by at most |J^+| sqrt(m) T^2 |v|^2 / (2 L_min) (the lengths'
    second-order terms through the least squares), and the commanded lengths are those of
    that position plus the start's offsets."""
    offset = np.full(M, 0.002)
    memory = np.zeros(M + 4)
    p_hat = P.copy()
    n = 500
    for _ in range(n):
        last = p_hat  # this tick's p_d (the memory's)
        _, commanded, memory = tick(p_hat, V, cable_lengths(ROBOT, p_hat) + offset, memory)
        p_hat = memory[:3].copy()
    from cdpm_drake.kernels.kinematics import jacobian
    L_min = float(cable_lengths(ROBOT, P + n * T * V).min())
    gain = max(np.linalg.norm(np.linalg.pinv(jacobian(ROBOT, q)), 2) for q in (P, memory[:3]))
    bound = n * gain * math.sqrt(M) * T * T * float(V @ V) / (2 * L_min)
    assert bound < 1e-3  # a bound that still says something
    np.testing.assert_allclose(memory[:3], P + n * T * V, rtol=0, atol=bound)
    np.testing.assert_allclose(commanded, cable_lengths(ROBOT, last) + offset, rtol=0,
                               atol=1e-12)


@pytest.mark.parametrize("gain", [5.0, 20.0, 125.0])
def test_a_length_disturbance_decays_geometrically_at_the_gain(gain):
    """At rest on ideal reels (l_{k+1} = l_k + T l_dot_k) a slip e_0 of the measured lengths
    decays as e_k = (1 - K_l T)^k e_0: the loop's closed form. The slip is 0.1 mm so that
    K_l e_0 (12.5 mm/s at 125 1/s) stays below MAX_CORRECTION, where the loop is linear."""
    memory = np.zeros(M + 4)
    lengths = cable_lengths(ROBOT, P)
    zero = np.zeros(3)
    command, _, memory = tick(P, zero, lengths, memory, gain)
    lengths = lengths + T * command
    slip = np.zeros(M)
    slip[4] = 0.0001
    lengths = lengths - slip  # cable 5 slips by 0.1 mm: the encoders read it
    errors = []
    for _ in range(50):
        command, commanded, memory = tick(P, zero, lengths, memory, gain)
        errors.append(commanded - lengths)
        lengths = lengths + T * command
    expected = [(1 - gain * T) ** k * slip for k in range(50)]
    np.testing.assert_allclose(errors, expected, rtol=0, atol=1e-12)


# --- the scenario field ------------------------------------------------------------------------


@pytest.mark.parametrize("value, why", [(-1.0, "below 0"), (500.0, "K_l T = 1"),
                                        (float("nan"), "NaN")])
def test_bad_gains_are_refused_naming_the_field(value, why):
    text = f"controller: {{length_gain: {'.nan' if math.isnan(value) else value}}}"
    with pytest.raises(ScenarioError, match=r"controller\.length_gain .*got"):
        load_scenario("exp2_interaction", text)


# --- on the plants ------------------------------------------------------------------------------


def test_on_the_ideal_kinematic_plant_the_loop_changes_nothing():
    """The reels integrate exactly what is sent and the commanded lengths advance as they
    do: l == l_d on every tick, so the paper's open loop and the default loop log the same
    run (the reference logs rest on this)."""
    text = "{duration: 3.0}"
    closed = simulate(scenario=load_scenario("exp2_interaction", text)).log
    opened = simulate(scenario=load_scenario(
        "exp2_interaction", "{duration: 3.0, controller: {length_gain: 0}}")).log
    np.testing.assert_array_equal(closed["lengths_commanded"], closed["lengths"])
    for key in ("p", "lengths", "reel_velocity", "F_d"):
        np.testing.assert_array_equal(closed[key], opened[key])


def test_lagging_drives_are_caught_up_by_the_loop():
    """Drives with a 50 ms lag (`plant.time_constant`) fall behind the commanded lengths; the
    loop keeps them within a fraction of what the open loop leaves (the plant's lengths,
    measured, against the commanded ones)."""
    lag = "plant: !SimulatedReels {time_constant: 0.05}"

    def worst(gain):
        log = simulate(scenario=load_scenario(
            "exp2_interaction", f"{{duration: 6.0, {lag}, controller: {{length_gain: {gain}}}, "
            # the paper's diagram: the safety filter (issue 26) would change the motion
            "safety_filter: {enabled: false}}")
        ).log
        return float(np.abs(log["lengths_commanded"] - log["lengths"]).max())

    open_loop, closed_loop = worst(0.0), worst(20.0)
    # A 50 ms lag at ~0.1 m/s is ~5 mm behind; the loop brings it to ~1/10 of that.
    assert open_loop > 2e-3
    assert closed_loop < 0.2 * open_loop


def test_the_drives_dead_band_is_made_up_where_the_error_asks_for_motion():
    """l_dot = J v + K_l e + 0.9 u_c tanh(e / 20 um): at rest with errors of 1 mm, 5 um and 0
    the extra speed is 0.9 u_c tanh(50), 0.9 u_c tanh(0.25) and exactly 0 (ideal reels, whose
    error is zero, see nothing of it)."""
    measured = cable_lengths(ROBOT, P)
    _, _, memory = tick(P, np.zeros(3), measured, np.zeros(M + 4), dead_band=0.005)
    errors = np.array([1e-3, 5e-6, 0.0, -1e-3, 0.0, 0.0, 0.0])
    l_d = cable_lengths(ROBOT, memory[:3]) + memory[3:3 + M]
    command, _, _ = tick(P, np.zeros(3), l_d - errors, memory, dead_band=0.005)
    expected = 20.0 * errors + 0.9 * 0.005 * np.tanh(errors / 2e-5)
    # (errors come back through lengths of ~3 m: 1e-16 relative of those)
    np.testing.assert_allclose(command, expected, rtol=0, atol=1e-12)
    assert command[2] == 0.0


def test_the_dead_band_is_the_robot_files_drives():
    d = ROBOT.dynamics
    # dynamic_plant's drive law: a reel at rest moves only when bandwidth x inertia x u
    # exceeds the Coulomb friction.
    assert d.dead_band == pytest.approx(d.coulomb_friction / (d.bandwidth * d.reel_inertia))
    from cdpm_drake.config import load_resolved_scenario
    dynamic = load_resolved_scenario("exp2_interaction", "plant: !DynamicReels {}")
    assert dynamic.dead_band == pytest.approx(d.dead_band)
    off = load_resolved_scenario("exp2_interaction", "{plant: !DynamicReels {}, controller: "
                                 "{friction_compensation: false}}")
    assert off.dead_band == 0.0
    assert load_resolved_scenario("exp2_interaction").dead_band == 0.0  # kinematic plant


def test_the_corrections_are_scaled_together_after_a_stall():
    """A stall leaves 15 mm of error on one cable and -0.5 mm on another: K_l e would be
    0.6 m/s and -0.02 m/s; both are scaled by MAX_CORRECTION / 0.6 m/s, so the largest is
    MAX_CORRECTION and the two keep their ratio (the direction of the length error). With no
    velocity command the feedforward is zero and the command is the correction alone."""
    from cdpm_drake.kernels.kinematics import MAX_CORRECTION

    measured = cable_lengths(ROBOT, P)
    _, _, memory = tick(P, np.zeros(3), measured, np.zeros(M + 4))
    l_d = cable_lengths(ROBOT, memory[:3]) + memory[3:3 + M]
    errors = np.zeros(M)
    errors[1], errors[4] = 0.015, -0.0005
    command, _, _ = tick(P, np.zeros(3), l_d - errors, memory, gain=40.0)
    scale = MAX_CORRECTION / (40.0 * 0.015)
    assert scale < 0.1  # the scale is what held it
    np.testing.assert_allclose(command, 40.0 * errors * scale, rtol=1e-9, atol=1e-12)
    # Below the bound nothing is scaled: 1 mm gives K_l e = 0.04 m/s.
    errors[1] = 0.001
    command, _, _ = tick(P, np.zeros(3), l_d - errors, memory, gain=40.0)
    np.testing.assert_allclose(command, 40.0 * errors, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["reeled_out", "reeled_in"])
def test_the_correction_bound_holds_for_cables_reeled_in_and_out(sign):
    """Issue 27: the bound was only pinned for a cable paid out (positive error). The largest
    correction may as well reel a cable in: 15 mm of error the other way on cable 2, 0.5 mm
    on cable 5 the first way: K_l e = -+0.6 and +-0.02 m/s, both scaled by MAX_CORRECTION /
    0.6 m/s (the largest in size, whatever its sign), so cable 2 gets -+MAX_CORRECTION."""
    from cdpm_drake.kernels.kinematics import MAX_CORRECTION

    measured = cable_lengths(ROBOT, P)
    _, _, memory = tick(P, np.zeros(3), measured, np.zeros(M + 4))
    l_d = cable_lengths(ROBOT, memory[:3]) + memory[3:3 + M]
    errors = np.zeros(M)
    errors[1], errors[4] = sign * 0.015, -sign * 0.0005
    command, _, _ = tick(P, np.zeros(3), l_d - errors, memory, gain=40.0)
    np.testing.assert_allclose(command, 40.0 * errors * MAX_CORRECTION / 0.6, rtol=1e-9,
                               atol=1e-12)
    assert command[1] == pytest.approx(sign * MAX_CORRECTION, rel=1e-9)
