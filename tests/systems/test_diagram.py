"""The Fig. 5 diagram as a whole: structure, the admittance in the loop, the safety limits in
scripted runs, kinematic consistency of the logs, repeatability, an 8-cable robot.

Timing of the logs (derived from Drake's Simulator and checked by the admittance test): row k
is published at t_k = k T after the k-th round of discrete updates, so it shows the state after
k updates and the outputs computed from it. The operator force and the sensor with
filter_window 1 are feedthrough, so F_H_k and F_d_k act at tick k (no delay); the admittance
output is its state, so velocity_k = v_k of the ZOH recursion v_{k+1} = a v_k + b F_d_k; the
reels integrate velocity_k into lengths_{k+1}, so p lags velocity by one tick.
"""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from cdpm_drake.diagram import (PLANT_PORTS, BuildOptions, block_output_port, build_diagram,
                                has_block, logged_ports)
from cdpm_drake.kernels.kinematics import forward_kinematics
from cdpm_drake.config import load_scenario, scenario_robot
from cdpm_drake.runs.log import collect_log
from cdpm_drake.runs.simulate import simulate

T = 0.002
M = C = 6.25  # the paper's virtual mass (kg) and damping (N s/m)
A = np.exp(-T * C / M)  # ZOH of 1/(M s + C): v_{k+1} = A v_k + B F_k
B = (1.0 - A) / C

# These tests pin the paper's Fig. 5 blocks (admittance, limits, F_d): without issue 26's
# safety filter (which would modify the limited command, and add its kinetostatic cue to F_d)
# and model monitor (which stops runs where the cables could not hold the platform: starts
# near the box's corners).
FIG_5 = "safety_filter: {enabled: false}, model_monitor: {enabled: false}, "
NO_INTERFERENCE = "interference: {enabled: false}, " + FIG_5
HIGH_LIMITS = "limits: {max_velocity: 10, max_acceleration: 1000}, "


def scripted(times, forces, extra="", name="exp1_no_interaction"):
    """exp1's robot and start with a scripted operator and the given overlay."""
    table = "{times: %s, forces: %s}" % (np.asarray(times, float).tolist(),
                                         np.asarray(forces, float).tolist())
    return load_scenario(name, overlay_text="{%s operator: !ScriptedOperator %s}"
                         % (extra, table))


def run(scenario, duration):
    result = simulate(scenario=scenario, duration=duration)
    assert result.error is None, result.error
    return result.log


# --- Structure ---------------------------------------------------------------------------------


def test_system_names_follow_fig_5():
    diagram = build_diagram(load_scenario("exp2_interaction"))
    names = {s.get_name() for s in diagram.GetSystems()}
    # Each a system or a flat block of systems, some of them computed in the safety blocks'
    # fused callback (systems/fused_kernels.py): a block of the diagram either way.
    blocks = names | set(diagram.flat_blocks)
    assert {"reels", "force_sensor", "interference_force", "F_d_adder", "admittance",
            "safety_limits", "jacobian_mapping", "forward_kinematics"} <= blocks
    assert all(has_block(diagram, block) for block in blocks)
    # One logger, of every logged signal whose block exists (no wall force in exp2); its
    # input stacked by the fused wiring (see tests/systems/test_fast_calls.py).
    assert {"log", "wiring"} <= names
    width = sum(block_output_port(diagram, system, port).size()
                for _, system, port in logged_ports(diagram))
    assert diagram.GetSubsystemByName("log").get_input_port().size() == width


def test_plant_exposes_exactly_the_hardware_port_names():
    diagram = build_diagram(load_scenario("exp2_interaction"))
    plant = diagram.GetSubsystemByName("reels")
    inputs = {plant.get_input_port(k).get_name() for k in range(plant.num_input_ports())}
    outputs = {plant.get_output_port(k).get_name() for k in range(plant.num_output_ports())}
    assert inputs == {"reel_velocity_command"}
    assert outputs == {"cable_lengths", "measured_force", "tension_measured"}
    assert inputs | outputs == set(PLANT_PORTS) | {"tension_measured"}


def test_build_options_drop_the_interference_block_and_the_loggers():
    scenario = load_scenario("exp2_interaction")
    names = {s.get_name() for s in build_diagram(
        scenario, BuildOptions(interference=False, loggers=False)).GetSystems()}
    assert "interference_force" not in names
    assert not any(n.startswith("log") for n in names)
    assert scenario.interference.enabled  # the builder did not modify the scenario


def test_full_loop_simulates_without_an_algebraic_loop():
    # Python outputs are feedthrough unless declared otherwise: an undeclared dependency would
    # make Drake report an algebraic loop when the loop is first evaluated.
    log = run(load_scenario("exp2_interaction"), 0.1)
    assert log["time"].shape == (51,)
    np.testing.assert_allclose(np.diff(log["time"]), T, rtol=0, atol=1e-12)


def test_eight_cable_robot_simulates_and_logs_its_widths():
    scenario = load_scenario("exp1_no_interaction", overlay_text=(
        "{robot: cube_8cable, swaps: [], initial_position: [2.0, 1.5, 1.5], "
        "operator: !ScriptedOperator {times: [0], forces: [[3.0, -2.0, 1.0]]}}"))
    log = run(scenario, 0.2)
    n = 101
    assert log["lengths"].shape == (n, 8) and log["reel_velocity"].shape == (n, 8)
    for key in ("pair_distances", "active", "crossed"):
        assert log[key].shape == (n, 28), key  # 8 * 7 / 2 pairs
    assert log["pairs"].shape == (28, 2) and log["d_u"].shape == (28,)
    assert log["reels"].shape == (8, 3)
    # It moved the way it was pushed.
    dp = log["p"][-1] - log["p"][0]
    assert dp @ np.array([3.0, -2.0, 1.0]) > 0.9 * np.linalg.norm(dp) * np.sqrt(14)


# --- The admittance in the loop ---------------------------------------------------------------


def test_constant_force_gives_the_exact_zoh_velocity():
    """F = (1, -0.5, 0.25) N from t = 0, no filter, no interference, limits out of the way:
    velocity_k = F/C (1 - exp(-k T C / M)) with no index offset (module docstring), for the
    admittance output and the limited command alike."""
    F = np.array([1.0, -0.5, 0.25])
    log = run(scripted([0.0], [F], NO_INTERFERENCE + HIGH_LIMITS + "sensor: {filter_window: 1},"),
              0.5)
    k = np.arange(log["time"].size)[:, None]
    expected = F / C * (1.0 - np.exp(-k * T * C / M))
    np.testing.assert_array_equal(log["F_H"], np.broadcast_to(F, log["F_H"].shape))
    np.testing.assert_allclose(log["velocity_admittance"], expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(log["velocity"], expected, rtol=0, atol=1e-9)


def test_sliding_average_feeds_the_admittance_a_ramp():
    """filter_window 10: F_H_k = F min(k + 1, 10) / 10 (the history starts at zero), and the
    admittance integrates exactly that: the scalar recursion v_{k+1} = A v_k + B F_H_k."""
    F = np.array([2.0, 0.0, -1.0])
    log = run(scripted([0.0], [F], NO_INTERFERENCE + HIGH_LIMITS + "sensor: {filter_window: 10},"),
              0.2)
    n = log["time"].size
    ramp = np.minimum(np.arange(n) + 1, 10)[:, None] / 10 * F
    np.testing.assert_allclose(log["F_H"], ramp, rtol=0, atol=1e-12)
    v = np.zeros((n, 3))
    for k in range(n - 1):
        v[k + 1] = A * v[k] + B * ramp[k]
    np.testing.assert_allclose(log["velocity_admittance"], v, rtol=0, atol=1e-12)


def test_logged_desired_force_is_what_the_admittance_integrates_with_noise():
    scenario = load_scenario("exp1_no_interaction", overlay_text=(
        "{interference: {enabled: false}, sensor: {noise_std: 2.0, filter_window: 5}, " + FIG_5 +
        "operator: !ScriptedOperator {times: [0, 1], forces: [[0, 0, 0], [3, 1, -2]]}}"))
    log = run(scenario, 0.2)
    v, F = log["velocity_admittance"], log["F_d"]
    np.testing.assert_allclose(v[1:], A * v[:-1] + B * F[:-1], rtol=0, atol=1e-12)


def test_desired_force_is_the_sum_of_hand_interference_and_wall_forces():
    """Eq. 22 (plus the optional wall force): F_d = F_H + F_int + F_wall at every tick, with all
    three non-zero: a 1 N push, 5 cm from the lower x face (box 0.5..3.0 m, wall force 1 N
    there), cables 1 and 3 (swapped) about 60 mm apart, inside d_u = 61 mm."""
    scenario = load_scenario("exp1_no_interaction", overlay_text=(
        "{wall_force: {enabled: true, margin: 0.1}, initial_position: [0.55, 1.85, 2.2], " + FIG_5
        +
        "operator: !ScriptedOperator {times: [0], forces: [[0.0, 1.0, 0.0]]}}"))
    log = run(scenario, 0.1)
    for key in ("F_H", "F_int", "F_wall"):
        assert np.abs(log[key]).max() > 0.01, key
    np.testing.assert_allclose(log["F_d"], log["F_H"] + log["F_int"] + log["F_wall"],
                               rtol=0, atol=1e-12)


# --- Safety limits in scripted runs -----------------------------------------------------------


@pytest.mark.parametrize("start,force,axis,face", [
    ([2.8, 3.65, 1.22], [60.0, 0.0, 0.0], 0, "upper"),
    ([1.77, 3.65, 0.55], [0.0, 0.0, -60.0], 2, "lower"),
    ([1.77, 1.0, 1.22], [0.0, -60.0, 0.0], 1, "lower"),
])
def test_pushing_into_a_face_stops_at_it_within_every_limit(start, force, axis, face):
    """60 N (terminal admittance speed F/C = 9.6 m/s) towards a face with the robot's limits
    (0.5 m/s, 2 m/s^2): every logged p stays inside the box, the platform ends on the face at
    rest, the commanded speed never exceeds 0.5 m/s nor changes by more than a T per tick.

    The braking curve assumes p moves by T v per tick; the plant moves it by T v (1 + e),
    e = O(T |v| / l) ~ 1e-4 (Euler on the cable lengths, as real reels do), so the braking
    deceleration may exceed a by that factor: tolerance 1e-3."""
    scenario = scripted([0.0], [force], NO_INTERFERENCE
                        + f"initial_position: {start}, sensor: {{filter_window: 1}},")
    log, (lower, upper), (v_max, a_max) = _run_against_the_wall(scenario)
    p, v = log["p"], log["velocity"]
    assert np.all(p >= lower - 1e-9) and np.all(p <= upper + 1e-9)
    assert np.all(np.linalg.norm(v, axis=1) <= v_max * (1 + 1e-12))
    dv = np.linalg.norm(np.diff(v, axis=0), axis=1) / T
    assert dv.max() <= a_max * (1 + 1e-3), dv.max()
    target = (upper if face == "upper" else lower)[axis]
    assert abs(p[-1, axis] - target) < 1e-5
    np.testing.assert_allclose(v[-50:, axis], 0.0, atol=1e-12)  # stopped, and stays there
    # Anti-windup: at rest on the face the admittance integrates from the commanded 0, so its
    # velocity is one tick of the force, B_d F = F (1 - exp(-T C/M)) / C, not F/C = 9.6 m/s.
    one_tick = force[axis] * (1 - np.exp(-T * 6.25 / 6.25)) / 6.25
    assert log["velocity_admittance"][-1, axis] == pytest.approx(one_tick, rel=1e-9)


def test_pulling_away_from_the_wall_leaves_it_at_once_and_a_release_coasts_m_over_c():
    """The admittance integrates from the limited command (back-calculation), so holding the
    platform against the wall or at the speed limit winds nothing up: 40 N into the x face
    for 2 s, then 40 N away; the platform leaves within a few ticks (the acceleration limit
    builds speed from 0). Then a release at full speed: the velocity decays with M/C = 1 s, so
    the platform coasts about v_max M/C = 0.5 m (plus the acceleration limit's share)."""
    scenario = scripted([0.0, 2.0, 2.002, 3.0, 3.002], [[40.0, 0, 0], [40.0, 0, 0],
                                                        [-40.0, 0, 0], [-40.0, 0, 0],
                                                        [0.0, 0, 0]],
                        NO_INTERFERENCE + "initial_position: [2.7, 3.65, 1.22], "
                        "sensor: {filter_window: 1},", name="exp2_interaction")
    log = run(scenario, 8.0)
    t, x, v = log["time"], log["p"][:, 0], log["velocity"][:, 0]
    upper = scenario_robot(scenario).workspace.upper[0]
    at_wall = np.flatnonzero(np.abs(x - upper) < 1e-6)
    assert at_wall.size and t[at_wall[0]] < 2.0  # reached the wall during the push
    left = np.flatnonzero((t > 2.0) & (x < upper - 1e-6))[0]
    assert t[left] - 2.0 < 0.02, t[left]  # off the wall within 10 ticks of pulling away
    # Released at 3 s moving at -0.5 m/s: it coasts 0.5 m M/C plus at most a few cm.
    released = np.searchsorted(t, 3.0)
    assert v[released] == pytest.approx(-0.5, abs=1e-9)
    coast = x[released] - x[-1]
    assert 0.45 < coast < 0.55, coast


def test_pushing_into_an_edge_keeps_the_acceleration_limit():
    scenario = scripted([0.0], [[40.0, 30.0, 0.0]], NO_INTERFERENCE
                        + "initial_position: [2.8, 3.85, 1.22], sensor: {filter_window: 1},")
    log, (lower, upper), (v_max, a_max) = _run_against_the_wall(scenario)
    p, v = log["p"], log["velocity"]
    assert np.all(p >= lower - 1e-9) and np.all(p <= upper + 1e-9)  # this part holds
    dv = np.linalg.norm(np.diff(v, axis=0), axis=1) / T
    assert dv.max() <= a_max * (1 + 1e-3), dv.max()


def _run_against_the_wall(scenario):
    robot = scenario_robot(scenario)
    log = run(scenario, 1.5)
    return (log, (robot.workspace.lower, robot.workspace.upper),
            (robot.limits.max_velocity, robot.limits.max_acceleration))


# --- Kinematic consistency of the log ---------------------------------------------------------


def test_position_is_the_forward_kinematics_of_the_lengths_and_the_integral_of_velocity():
    """A 3 s scripted push that changes direction: the logged p equals FK(lengths) (solved
    again from the workspace centre) within 1e-9 m, and the integral of the commanded velocity
    p_0 + T sum_{i<k} velocity_i within 1e-3 m (p lags velocity by one tick). The plant's
    projection onto the geometry makes the difference: O(T^2 |v|^2 / l) per tick."""
    scenario = scripted([0.0, 1.0, 2.0, 3.0],
                        [[2.0, 0.0, 0.0], [0.0, 2.5, -1.0], [-2.0, -1.0, 2.0], [1.0, 1.0, 1.0]],
                        NO_INTERFERENCE, name="exp2_interaction")
    log = run(scenario, 3.0)
    robot = scenario_robot(scenario)
    p = log["p"]
    np.testing.assert_allclose(forward_kinematics(robot, log["lengths"]), p, rtol=0, atol=1e-9)
    integrated = p[0] + T * np.vstack([np.zeros(3), np.cumsum(log["velocity"][:-1], axis=0)])
    assert np.linalg.norm(p[-1] - p[0]) > 0.2  # it did move
    np.testing.assert_allclose(p, integrated, rtol=0, atol=1e-3)
    step_error = np.diff(p, axis=0) - T * log["velocity"][:-1]
    assert np.abs(step_error).max() < 1e-6


def test_reel_velocity_is_the_jacobian_map_of_the_command():
    from cdpm_drake.kernels.kinematics import jacobian
    scenario = scripted([0.0], [[1.0, 2.0, -1.0]], NO_INTERFERENCE)
    log = run(scenario, 0.3)
    robot = scenario_robot(scenario)
    expected = np.einsum("kij,kj->ki", jacobian(robot, log["p"]), log["velocity"])
    np.testing.assert_allclose(log["reel_velocity"], expected, rtol=0, atol=1e-12)
    # And the lengths integrate it, up to the plant's projection onto the geometry:
    # O(T^2 |v|^2 / l) ~ 4e-6 * 0.01 / 2 = 2e-8 m per tick at |v| ~ 0.1 m/s.
    np.testing.assert_allclose(np.diff(log["lengths"], axis=0), T * log["reel_velocity"][:-1],
                               rtol=0, atol=1e-7)


# --- Repeatability ----------------------------------------------------------------------------


def logs(diagram, context, scenario):
    return collect_log(diagram, context, scenario, scenario_robot(scenario))


def assert_same_logs(a, b):
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_running_the_same_context_twice_gives_identical_logs():
    """exp2 (interference on, crossing memory in state, spring hand): a second Simulator on a
    fresh default context, and the first context reset with SetDefaultContext, both replay
    the first run exactly."""
    scenario = load_scenario("exp2_interaction")
    diagram = build_diagram(scenario)
    default = diagram.CreateDefaultContext()

    first = Simulator(diagram, default.Clone())
    first.AdvanceTo(0.4)
    log_1 = logs(diagram, first.get_context(), scenario)
    assert log_1["time"].size == 201

    second = Simulator(diagram, diagram.CreateDefaultContext())
    second.AdvanceTo(0.4)
    assert_same_logs(log_1, logs(diagram, second.get_context(), scenario))

    context = first.get_mutable_context()
    diagram.SetDefaultContext(context)
    context.SetTime(0.0)
    diagram.GetSubsystemByName("log").FindMutableLog(context).Clear()  # rows live there
    first.Initialize()
    first.AdvanceTo(0.4)
    assert_same_logs(log_1, logs(diagram, context, scenario))


def test_sensor_noise_repeats_with_its_seed_and_differs_with_another():
    def noisy(seed):
        scenario = scripted([0.0], [[1.0, 0.0, 0.0]], NO_INTERFERENCE
                            + f"sensor: {{noise_std: 1.0}}, random_seed: {seed},")
        return run(scenario, 0.2)

    a, b, c = noisy(3), noisy(3), noisy(4)
    assert_same_logs(a, b)
    assert np.abs(a["F_H"] - c["F_H"]).max() > 0.1
    assert not np.array_equal(a["p"], c["p"])
