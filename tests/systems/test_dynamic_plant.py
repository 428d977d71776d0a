"""The dynamic plant (`plant: !DynamicReels`): the platform as a MultibodyPlant rigid body on
tension-only elastic cables, reel drives with friction.

References: statics (the platform's force and moment balance), linear elasticity of the
cable net (when a pull unloads a cable), energy conservation of the undamped plant, the
kinematic plant (`!SimulatedReels`) in the stiff-cable, ideal-drive, translation-only limit,
and the closed-form fixed points of the implicit reel-drive step.
"""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from cdpm_drake.diagram import PLANT_PORTS, BuildOptions, build_diagram, make_plant
from cdpm_drake.hardware.config import HardwareReels
from cdpm_drake.robot import ROBOTS_DIR, RobotError, load_robot
from cdpm_drake.kernels.rotation import rotation_from_rpy
from cdpm_drake.config import (DynamicReels, ScenarioError, check_dynamic_reels,
                                 load_scenario, scenario_robot)
from cdpm_drake.runs.log import collect_log
from cdpm_drake.runs.simulate import simulate
from cdpm_drake.systems.plants.dynamic_plant import cable_tensions, ground_truth_log, reel_step
from cdpm_drake.kernels.tension import GRAVITY, gravity_wrench, stable_time_step, wrench_matrix

PAPER_YAML = (ROBOTS_DIR / "paper_7cable.yaml").read_text()
# exp2's start is one where the paper robot's cables hold the platform level (t* = +inf:
# an internal force raises every tension; the start distribution sits on the 5 N floor).
EXP2_START = "initial_position: [1.56, 3.24, 1.22]"


def _robot_file(tmp_path, extra: str, name="robot.yaml") -> Path:
    path = tmp_path / name
    from helpers_robots import with_sections

    path.write_text(with_sections(PAPER_YAML, extra))
    return path


def _plant_only(scenario, command=None):
    """The scenario's dynamic plant alone, its reel command held at `command` (zeros)."""
    robot = scenario_robot(scenario)
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("reels", make_plant(scenario, robot))
    source = builder.AddSystem(ConstantVectorSource(
        np.zeros(robot.num_cables) if command is None else np.asarray(command, float)))
    builder.Connect(source.get_output_port(), plant.GetInputPort("reel_velocity_command"))
    return builder.Build(), robot


def _residual(robot, log, k):
    """|W(p, R) T + w_gravity| of row k of a log, N or N m."""
    R = rotation_from_rpy(log["rpy_true"][k])
    W = wrench_matrix(robot, log["p_true"][k], R)
    return np.max(np.abs(W @ log["tensions"][k] + gravity_wrench(robot.dynamics.mass)))


# --- The pieces ------------------------------------------------------------------------------



def _pretensioned(scenario):
    """(robot, robot.dynamics, check_dynamic_reels' distribution, p0 m, L0 m): the rest
    lengths that stretch each cable at p0 to its pretension (L = L0 (1 + T / EA)), computed
    here from the distribution, not taken from the plant."""
    robot = scenario_robot(scenario)
    d = robot.dynamics
    dist = check_dynamic_reels(scenario, robot)
    p0 = np.asarray(scenario.initial_position)
    L0 = np.linalg.norm(robot.reels - (p0 + robot.attachments), axis=1) * d.EA / (
        d.EA + dist.tensions)
    return robot, d, dist, p0, L0

def test_reel_step_fixed_points_are_the_drive_law_closed_forms():
    # inertia dw/dt = K (u - w) - b w - F_c sgn w, K = bandwidth * inertia. Running: the
    # fixed point w = (K u - F_c sgn u) / (K + b); stuck: |K u| <= F_c keeps w = 0.
    p = dict(bandwidth=100.0, inertia=0.25, viscous=0.25, coulomb=0.125)  # K = 25 N s/m
    K = 25.0
    for u in (0.1, -0.3, 0.02):
        w = np.zeros(1)
        for _ in range(5000):
            w = reel_step(w, np.array([u]), 1e-3, **p)
        assert w[0] == pytest.approx((K * u - 0.125 * np.sign(u)) / (K + 0.25), rel=1e-9)
    w = np.zeros(1)
    for _ in range(1000):  # K u = 0.1 N < F_c
        w = reel_step(w, np.array([0.004]), 1e-3, **p)
    assert w[0] == 0.0
    # No friction: first order with the loop's time constant, one implicit-Euler step.
    w = reel_step(np.zeros(1), np.array([1.0]), 1e-3, bandwidth=100.0, inertia=1.0,
                  viscous=0.0, coulomb=0.0)
    assert w[0] == pytest.approx(0.1 / 1.1)


def test_cable_tension_is_elastic_when_taut_and_zero_when_slack():
    L0 = np.array([2.0, 2.0, 2.0, 2.0])
    L = np.array([2.001, 1.999, 2.001, 2.0005])
    rate = np.array([0.0, 0.0, -1.0, 0.01])
    T = cable_tensions(L, rate, L0, EA=70000.0, damping=20.0)
    # k = EA / L0 = 35 kN/m: 35 N for 1 mm; slack: 0; 1 mm while unloading at 1 m/s:
    # 35 - 20 = 15 N; 0.5 mm while loading at 10 mm/s: 17.5 + 0.2 N.
    np.testing.assert_allclose(T, [35.0, 0.0, 15.0, 17.7], atol=1e-9)
    # Unloading fast enough, a damped cable would push (35 - 40 < 0): it does not.
    assert cable_tensions(np.array([2.001]), np.array([-2.0]), np.array([2.0]), 70000.0,
                          20.0)[0] == 0.0


@pytest.mark.parametrize("locked", [False, True])
def test_the_compiled_step_is_the_wrench_and_drive_laws_written_out(locked):
    # cables.cable_net_step on a random state, against the pieces written out here with numpy:
    # the wrench matrix of tension.py (column i: [u_i; (R b_i) x u_i]) times the tensions of
    # cable_tensions (stretch rate -u_i . (v + w x R b_i) - reel speed) plus the hand's wrench
    # at R h; the drives' step by reel_step on the command scaled to the speed limit; the pose.
    from cdpm_drake.kernels.plant import cable_net as cables
    from cdpm_drake.kernels.rotation import rpy_from_rotation

    robot = load_robot(ROBOTS_DIR / "paper_7cable.yaml")
    d = robot.dynamics
    m = robot.num_cables
    rng = np.random.default_rng(21 + locked)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x_, y, z = q
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x_ * y - z * w), 2 * (x_ * z + y * w)],
                  [2 * (x_ * y + z * w), 1 - 2 * (x_ * x_ + z * z), 2 * (y * z - x_ * w)],
                  [2 * (x_ * z - y * w), 2 * (y * z + x_ * w), 1 - 2 * (x_ * x_ + y * y)]])
    if locked:
        R = rotation_from_rpy([0.05, -0.1, 0.2])
    p = np.array([1.6, 3.3, 1.2]) + rng.normal(scale=0.01, size=3)
    v, omega = rng.normal(scale=0.05, size=3), (np.zeros(3) if locked else
                                                rng.normal(scale=0.2, size=3))
    L_rigid = np.linalg.norm(robot.reels - (p + robot.attachments @ R.T), axis=1)
    L0 = L_rigid - rng.uniform(-0.0002, 0.001, size=m)  # some cables slack
    speeds = rng.normal(scale=0.01, size=m)
    command = rng.normal(scale=0.5, size=m)
    command[2] = 1.6  # above the 1 m/s limit: everything scaled by 1/1.6
    F = np.array([3.0, -2.0, 4.5])
    state = np.concatenate([p, v]) if locked else np.concatenate([q, p, omega, v])
    x = np.concatenate([state, L0, speeds, command])
    nv = 3 if locked else 6
    layout = cables.step_layout(m, nv)
    out = np.zeros(sum(size for _, size in layout.values()))
    at = layout["hand_force"][0]
    out[at:at + 3] = F
    h = 0.001
    params = cables.cable_net_params(d, time_step=h, max_reel_speed=1.0, locked=locked)
    cables.cable_net_step(robot.reels, robot.attachments, d.handle, params,
                          R.copy() if locked else np.zeros((3, 3)), x, out)

    def piece(name):
        a, n = layout[name]
        return out[a:a + n]

    Rb = robot.attachments @ R.T
    rho = robot.reels - (p + Rb)
    u = rho / np.linalg.norm(rho, axis=1)[:, None]
    rate = -np.einsum("ij,ij->i", u, v + np.cross(omega, Rb)) - speeds
    T = cable_tensions(np.linalg.norm(rho, axis=1), rate, L0, d.EA, d.damping)
    assert 0 < np.count_nonzero(T == 0.0) < m  # the draw has slack and taut cables
    # Round-off: lengths agree to ~1e-15 m, times EA / L0 ~ 3e4 N/m.
    np.testing.assert_allclose(piece("tensions"), T, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(piece("slack"), (T <= 0).astype(float))
    wrench = wrench_matrix(robot, p, R) @ T + np.concatenate([F, np.cross(R @ d.handle, F)])
    expected = wrench[:3] if locked else np.concatenate([wrench[3:], wrench[:3]])
    np.testing.assert_allclose(piece("generalized_force"), expected, rtol=0, atol=1e-8)
    w_next = reel_step(speeds, command / 1.6, h, bandwidth=d.bandwidth, inertia=d.reel_inertia,
                       viscous=d.viscous_friction, coulomb=d.coulomb_friction)
    np.testing.assert_allclose(piece("next_reels"), np.concatenate([L0 + h * w_next, w_next]),
                               rtol=0, atol=1e-15)
    np.testing.assert_array_equal(piece("p_WP_true"), p)
    np.testing.assert_allclose(piece("rpy_true"), rpy_from_rotation(R), atol=1e-12)


# --- Statics, slack, energy ------------------------------------------------------------------


def _rest_run(plant, knock=None, duration=3.0):
    scenario = load_scenario("exp2_interaction", f"{{{EXP2_START}, operator: !NoOperator {{}}, "
                             f"interference: {{enabled: false}}, plant: !DynamicReels {plant}}}")
    robot = scenario_robot(scenario)
    diagram = build_diagram(scenario)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    if knock is not None:
        mbp = diagram.GetSubsystemByName("reels").GetSubsystemByName("platform_plant")
        mbp.SetVelocities(mbp.GetMyMutableContextFromRoot(context), knock)
    simulator.AdvanceTo(duration)
    return collect_log(diagram, context, scenario, robot), robot, scenario


def test_at_rest_without_a_hand_the_logged_tensions_balance_gravity():
    # The platform starts where the start distribution's stretched cables put it: it must stay
    # there (1 um), the reels still, and the logged tensions, pose and rotation must satisfy
    # the force and moment balance at every tick to 1e-6 m g.
    log, robot, scenario = _rest_run("{}", duration=2.0)
    mg = robot.dynamics.mass * GRAVITY
    assert max(_residual(robot, log, k) for k in range(0, len(log["time"]), 25)) < 1e-6 * mg
    np.testing.assert_allclose(log["p_true"], np.broadcast_to(scenario.initial_position,
                                                              log["p_true"].shape), atol=1e-6)
    assert np.abs(log["rpy_true"]).max() < 1e-6
    assert log["tensions"].min() >= scenario.plant.min_tension - 1e-6
    np.testing.assert_allclose(log["lengths"][-1], log["lengths"][0], atol=1e-12)


def test_knocked_translating_platform_settles_into_force_balance():
    # Knocked at 5 cm/s, the platform's translation modes (tens of Hz, ~5% damped by the
    # cables) die out within 3 s; the cables then carry its weight: sum T_i u_i = m g to
    # 1e-6 m g. (Free to rotate, the platform also twists about the vertical on the tensions'
    # small geometric stiffness, barely damped by cable stretch: that takes far longer.)
    log, robot, _ = _rest_run("{lock_rotation: true}", knock=[0.03, -0.02, 0.04])
    mg = robot.dynamics.mass * GRAVITY

    def force_residual(k):
        W = wrench_matrix(robot, log["p_true"][k])[:3]
        return np.max(np.abs(W @ log["tensions"][k] - [0, 0, mg]))

    assert force_residual(5) > 1e-2 * mg  # moving at first: the check can fail
    assert force_residual(-1) < 1e-6 * mg


def _rodrigues(theta):
    """R = exp([theta]x), a rotation vector theta (rad) as a rotation matrix."""
    angle = np.linalg.norm(theta)
    if angle < 1e-15:
        return np.eye(3)
    k = theta / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_a_pull_unloads_the_cable_statics_predicts_when_it_predicts():
    # A hand pulls the handle up with a force rising at 25 N/s; the reels are held still.
    # The pull is slow against the net's modes, so the plant passes through static
    # equilibria: the reference solves the cable net's statics (Newton on the platform's six
    # pose coordinates, tensions from the elastic law, finite-difference Jacobian) and
    # bisects for the force at which the first cable's tension reaches zero.
    rate = 25.0
    scenario = load_scenario("exp2_interaction", f"{{{EXP2_START}, operator: !ScriptedOperator "
                             "{times: [0.0, 4.0], forces: [[0, 0, 0], [0, 0, 100.0]]}, "
                             "plant: !DynamicReels {}}")
    robot, d, dist, p0, L0 = _pretensioned(scenario)

    def tensions(x):
        R = _rodrigues(x[3:])
        L = np.linalg.norm(robot.reels - (p0 + x[:3] + robot.attachments @ R.T), axis=1)
        return np.where(L > L0, d.EA / L0 * (L - L0), 0.0), R

    def residual(x, t):
        T, R = tensions(x)
        return (wrench_matrix(robot, p0 + x[:3], R) @ T
                + gravity_wrench(d.mass, [0, 0, rate * t], R @ d.handle))

    def equilibrium(t, x):
        for _ in range(30):
            J = np.column_stack([(residual(x + e, t) - residual(x - e, t)) / 2e-7
                                 for e in 1e-7 * np.eye(6)])
            step = np.linalg.solve(J, -residual(x, t))
            x = x + step
            if np.abs(step).max() < 1e-13:
                return x
        raise AssertionError("statics did not converge")

    def all_taut(t, x):
        try:
            x_t = equilibrium(t, x)
        except (AssertionError, np.linalg.LinAlgError):  # past slack the net is a mechanism
            return False, x
        return tensions(x_t)[0].min() > 0.0, x_t

    x = np.zeros(6)
    assert np.abs(residual(x, 0.0)).max() < 1e-9  # the start is in equilibrium
    lo, hi = 0.0, 3.0
    assert not all_taut(hi, x)[0]
    while hi - lo > 1e-4:  # continuation: each solve starts from the last taut equilibrium
        mid = 0.5 * (lo + hi)
        taut, x_mid = all_taut(mid, x)
        if taut:
            lo, x = mid, x_mid
        else:
            hi = mid
    t_expected = lo
    cable = int(np.argmin(tensions(x)[0]))
    assert 0.3 < t_expected < 2.5

    diagram, _ = _plant_only(scenario)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(t_expected + 0.1)
    truth = ground_truth_log(diagram, simulator.get_context())
    t = 0.002 * np.arange(truth["slack"].shape[0])
    slack = truth["slack"] > 0.5
    first = int(np.argmax(slack.any(axis=1)))
    assert slack[first, cable], f"cable {cable + 1} was to go slack first"
    assert slack[first:, cable].all()  # and stays slack as the pull grows
    # Within two ticks (the ramp excites the net a little; damping lags it).
    assert t[first] == pytest.approx(t_expected, abs=0.004)


def test_undamped_free_oscillation_keeps_its_energy_within_the_integration_error(tmp_path):
    # Damping zero, no friction, reels still: the plant is conservative. Its discrete
    # MultibodyPlant integrates by symplectic Euler, whose energy error oscillates, bounded by
    # ~ h omega_max times the oscillation energy, and does not grow.
    robot_file = _robot_file(tmp_path, "cables: {damping: 0.0}\nreel_drives: "
                             "{viscous_friction: 0.0, coulomb_friction: 0.0}")
    scenario = load_scenario("exp2_interaction", f"{{{EXP2_START}, robot: {robot_file}, "
                             "operator: !NoOperator {}, plant: !DynamicReels {}}")
    robot, d, dist, p0, L0 = _pretensioned(scenario)
    diagram, _ = _plant_only(scenario)
    mbp = diagram.GetSubsystemByName("reels").GetSubsystemByName("platform_plant")
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    mbp_context = mbp.GetMyMutableContextFromRoot(context)
    mbp.SetVelocities(mbp_context, [0.05, -0.04, 0.03, 0.004, -0.003, 0.005])  # w0, v0

    def energy():
        x = mbp.GetPositionsAndVelocities(mbp_context)
        R = mbp.EvalBodyPoseInWorld(mbp_context, mbp.GetBodyByName("platform")).rotation()
        R = R.matrix()
        p, w, v = x[4:7], x[7:10], x[10:13]
        L = np.linalg.norm(robot.reels - (p + robot.attachments @ R.T), axis=1)
        stretch = np.maximum(L - L0, 0.0)
        return (0.5 * d.mass * v @ v + 0.5 * w @ (R @ d.inertia @ R.T) @ w
                + d.mass * GRAVITY * p[2] + np.sum(0.5 * d.EA / L0 * stretch ** 2))

    E0 = energy()
    w0, v0 = np.array([0.05, -0.04, 0.03]), np.array([0.004, -0.003, 0.005])
    E_osc = 0.5 * d.mass * v0 @ v0 + 0.5 * w0 @ d.inertia @ w0  # all of it kinetic at t = 0
    errors = []
    for t in np.arange(0.01, 4.0 + 1e-9, 0.01):
        simulator.AdvanceTo(t)
        errors.append(energy() - E0)
    errors = np.abs(np.array(errors))
    h = scenario.plant.time_step
    omega_max = 2.0 / stable_time_step(robot, p0, np.eye(3), dist.tensions)
    bound = h * omega_max * E_osc
    assert errors.max() < bound, (errors.max(), bound)
    third = len(errors) // 3
    assert errors[-third:].max() < 1.2 * errors[:third].max() + 1e-12 * E0


# --- Against the kinematic plant -------------------------------------------------------------


def _stiff_robot(tmp_path):
    # 100 x the default EA (k ~ 2.8 MN/m: 10 um of stretch at 30 N), damping ~10% of
    # critical, an ideal drive (bandwidth 10^4 rad/s, no friction).
    return _robot_file(tmp_path, "cables: {EA: 7.0e6, damping: 200.0}\nreel_drives: "
                       "{bandwidth: 10000.0, viscous_friction: 0.0, coulomb_friction: 0.0}",
                       "stiff.yaml")


@pytest.mark.parametrize("name", ["exp1_no_interaction", "exp2_interaction", "exp3_two_pairs"])
def test_stiff_ideal_translating_plant_follows_the_kinematic_plant_within_1_mm(name, tmp_path):
    # The kinematic plant is this limit: cables that do not stretch, drives that track
    # exactly, a platform that only translates (lock_rotation: the paper robot's attachments
    # cannot hold the platform level at exp1's and exp3's starts). 2 s each here;
    # scripts/tools/dynamic_plant_report.py runs the full 30 s.
    duration = 2.0
    kinematic = simulate(scenario=load_scenario(name), duration=duration).log
    scenario = load_scenario(name, f"{{robot: {_stiff_robot(tmp_path)}, plant: !DynamicReels "
                             "{time_step: 0.0005, lock_rotation: true, min_tension: 1.0}}")
    result = simulate(scenario=scenario, duration=duration)
    assert result.error is None
    dynamic = result.log
    moved = np.linalg.norm(kinematic["p"][-1] - kinematic["p"][0])
    assert moved > 0.02  # the experiment does move the platform
    error = np.linalg.norm(dynamic["p_true"] - kinematic["p"], axis=1)
    assert error.max() < 1e-3
    assert not dynamic["slack"].any()


def test_the_default_paper_robot_turns_under_the_hand_at_its_handle():
    # exp2 starts level (held with every cable >= 5 N) and its hand pulls at the handle,
    # 0.15 m below the centre: the pull's moment turns the free platform (in the paper's open
    # loop: the cable-length loop would hold the lengths, and the tilt, closer to the start's).
    result = simulate(scenario=load_scenario(
        "exp2_interaction", "{plant: !DynamicReels {}, controller: {length_gain: 0}}"),
        duration=1.0)
    assert result.error is None
    rpy = result.log["rpy_true"]
    assert np.abs(rpy[0]).max() < 1e-9
    assert np.abs(rpy).max() > np.radians(0.5)


# --- Refusals --------------------------------------------------------------------------------


def test_the_level_starts_of_the_three_experiments_are_accepted():
    # Issue 18: the recalibrated robot holds each experiment's start level with every cable
    # >= plant.min_tension (5 N); before, exp1's and exp3's were refused.
    for name in ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs"):
        scenario = load_scenario(name, "plant: !DynamicReels {}")
        dist = check_dynamic_reels(scenario, scenario_robot(scenario))
        assert dist.feasible and dist.tensions.min() >= 5.0 - 1e-9


def test_a_start_pose_no_tension_distribution_holds_is_refused():
    # [1.4, 3.9, 1.2] m with cables 1 and 3 swapped: t* = 2.32 N (statics.holding_tension),
    # cables 5 and 6 tied at it; a 0.05 rad yaw holds the platform at >= 5 N.
    overlay = "{initial_position: [1.4, 3.9, 1.2], plant: !DynamicReels {%s}}"
    with pytest.raises(ScenarioError) as e:
        load_scenario("exp1_no_interaction", overlay % "")
    msg = str(e.value)
    assert "initial_position [1.4, 3.9, 1.2] m" in msg
    assert "cable(s) [5, 6] would go slack" in msg
    assert "leaves them at 2.32 N" in msg
    assert "plant.min_tension = 5 N" in msg
    assert "plant.initial_rpy [0.0, 0.0, -0.05]" in msg  # the tilt that would hold it
    # That tilt is accepted.
    tilt = msg.split("tilted by plant.initial_rpy ")[1].split(" rad")[0]
    load_scenario("exp1_no_interaction", overlay % f"initial_rpy: {tilt}")


def test_a_robot_whose_cables_cannot_balance_the_moments_is_refused_unless_locked(tmp_path):
    # Four cables to off-centre points: six equations, four tensions (rank 4); a free platform
    # turns under the moments the cables cannot give, so the run is refused before its start
    # is even tried (issue 31). Locked, the joints take the moments.
    robot_file = tmp_path / "four.yaml"
    robot_file.write_text((Path(__file__).parents[1] / "data" / "robots" / "hand_4cable.yaml")
                          .read_text())
    robot = load_robot(robot_file)
    p0 = robot.workspace.center.tolist()
    text = f"{{robot: {robot_file}, initial_position: {p0}, swaps: [], interference: " \
           "{enabled: false}, plant: !DynamicReels {%s}}"
    with pytest.raises(ScenarioError) as e:
        load_scenario("exp2_interaction", text % "")
    assert "(4 cables) cannot hold a platform that turns freely" in str(e.value)
    assert "rank 4 < 6" in str(e.value)
    assert "plant.lock_rotation: true" in str(e.value)
    # Locked: four cables, three force equations; the least-norm positive solution holds
    # the 2.5 kg (the floor cable 4 pulls down against).
    scenario = load_scenario("exp2_interaction", text % "lock_rotation: true, min_tension: 0.0")
    dist = check_dynamic_reels(scenario, scenario_robot(scenario))
    W = wrench_matrix(robot, p0)[:3]
    np.testing.assert_allclose(W @ dist.tensions, [0, 0, 2.5 * GRAVITY], atol=1e-9)
    assert dist.tensions.min() > 0


@pytest.mark.parametrize("plant,message", [
    ("{time_step: 0.0015}", "plant.time_step 0.0015 s must divide the control period"),
    ("{time_step: 0.0}", "plant.time_step must be a finite number > 0, got 0.0"),
    ("{min_tension: -1.0}", "plant.min_tension must be a finite number >= 0 N, got -1.0"),
    ("{initial_rpy: [0.0, 0.1]}", "plant.initial_rpy must be [roll, pitch, yaw] in rad, got "
                                  "[0.0, 0.1]"),
    ("{max_reel_speed: -1.0}", "plant.max_reel_speed must be a finite number > 0, got -1.0"),
    ("{max_length_residual: 0.0}", "plant.max_length_residual must be a finite number > 0"),
])
def test_bad_plant_settings_are_refused_naming_field_and_value(plant, message):
    with pytest.raises(ScenarioError, match=None) as e:
        load_scenario("exp2_interaction", f"plant: !DynamicReels {plant}")
    assert message in str(e.value)


def test_a_time_step_too_long_for_the_cables_is_refused(tmp_path):
    robot_file = _robot_file(tmp_path, "cables: {EA: 7.0e6}")
    with pytest.raises(ScenarioError) as e:
        load_scenario("exp2_interaction", f"{{robot: {robot_file}, plant: !DynamicReels {{}}}}")
    msg = str(e.value)
    assert "plant.time_step 0.001 s is too long" in msg and "cables.EA 7e+06 N" in msg


@pytest.mark.parametrize("section,message", [
    ("platform: {mass: -2.0}", "platform.mass must be a finite value > 0 kg, got -2.0"),
    ("platform: {mass: 0.0}", "platform.mass must be a finite value > 0 kg, got 0.0"),
    ("cables: {EA: 0.0}", "cables.EA must be a finite value > 0 N, got 0.0"),
    ("cables: {EA: -5.0}", "cables.EA must be a finite value > 0 N, got -5.0"),
    ("cables: {damping: -1.0}", "cables.damping must be a finite value >= 0 N s/m, got -1.0"),
    ("platform: {inertia: [[0.05, 0, 0], [0, 0.05, 0], [0, 0, 0]]}",
     "platform.inertia [[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.0]] kg m^2 is singular"),
    ("platform: {inertia: [[0.05, 0.01, 0], [0, 0.05, 0], [0, 0, 0.05]]}",
     "platform.inertia must be symmetric"),
    ("platform: {inertia: [[0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.05]]}",
     "triangle inequality"),
    ("platform: {inertia: [0.05, 0.05, 0.05]}", "platform.inertia must be a 3 x 3 matrix"),
    ("platform: {handle: [0, 0]}", "platform.handle must have 3 coordinates"),
    ("reel_drives: {bandwidth: 0.0}", "reel_drives.bandwidth must be a finite value > 0 rad/s"),
    ("reel_drives: {inertia: -1.0}", "reel_drives.inertia must be a finite value > 0 kg"),
    ("reel_drives: {coulomb_friction: -0.1}", "reel_drives.coulomb_friction must be a finite "
                                              "value >= 0 N, got -0.1"),
    ("reel_drives: {viscous_friction: .nan}", "reel_drives.viscous_friction must be a finite"),
    ("platform: {mas: 2.0}", "unknown field(s) ['platform.mas']"),
    ("cables: 5", "cables must be a mapping with fields ['EA', 'damping']"),
])
def test_unphysical_robot_parameters_are_refused_naming_field_and_value(section, message,
                                                                        tmp_path):
    with pytest.raises(RobotError) as e:
        load_robot(_robot_file(tmp_path, section))
    assert message in str(e.value)


# --- Wiring and log --------------------------------------------------------------------------


def _graph(diagram):
    systems = {s.get_name(): (
        tuple(s.get_input_port(k).get_name() for k in range(s.num_input_ports())),
        tuple(s.get_output_port(k).get_name() for k in range(s.num_output_ports())))
        for s in diagram.GetSystems()}
    edges = {(src.get_name(), src.get_output_port(i).get_name(), dst.get_name(),
              dst.get_input_port(j).get_name())
             for (dst, j), (src, i) in diagram.connection_map().items()}
    return systems, edges


def test_dynamic_and_hardware_diagrams_share_every_port_and_connection():
    scenario = load_scenario("exp2_interaction")
    # As built: the same blocks, ports and connections.
    plain = BuildOptions(fuse_wiring=False)
    dynamic = build_diagram(dataclasses.replace(scenario, plant=DynamicReels()), plain)
    hardware = build_diagram(dataclasses.replace(scenario, plant=HardwareReels()), plain)
    assert _graph(dynamic) == _graph(hardware)
    # As run, the same blocks with the same ports; only the fused callback differs: the
    # dynamic plant's hand force feeds through from the reel command (the plant samples the
    # hand in the step that takes it), so its model monitor keeps a callback of its own
    # (systems/fused_kernels.py).
    dynamic_fused, hardware_fused = (build_diagram(dataclasses.replace(scenario, plant=plant))
                                     for plant in (DynamicReels(), HardwareReels()))
    assert ({b: (list(i["inputs"]), list(i["outputs"])) for b, i in
             dynamic_fused.flat_blocks.items()}
            == {b: (list(i["inputs"]), list(i["outputs"])) for b, i in
                hardware_fused.flat_blocks.items()})
    assert (hardware_fused.fused_kernels["blocks"]
            == dynamic_fused.fused_kernels["blocks"] + ["model_monitor"])
    reels = dynamic.GetSubsystemByName("reels")
    ports = [reels.get_input_port(k).get_name() for k in range(reels.num_input_ports())] + [
        reels.get_output_port(k).get_name() for k in range(reels.num_output_ports())]
    # No ground-truth port to wire to: the measured tensions are a sensor's (issue 31).
    assert sorted(ports) == sorted(PLANT_PORTS + ("tension_measured",))


def test_the_log_has_the_ground_truth_for_the_dynamic_plant_only():
    scenario = load_scenario("exp2_interaction", "plant: !DynamicReels {}")
    log = simulate(scenario=scenario, duration=0.1).log
    T = log["time"].size
    assert T == 51  # ticks at 0, 2, ..., 100 ms
    assert log["tensions"].shape == (T, 7) and log["slack"].shape == (T, 7)
    assert log["slack"].dtype == bool
    assert log["p_true"].shape == (T, 3) and log["rpy_true"].shape == (T, 3)
    np.testing.assert_allclose(log["p_true"][0], scenario.initial_position, atol=1e-12)
    # Row 0 is the start distribution the scenario check computed.
    np.testing.assert_allclose(log["tensions"][0],
                               check_dynamic_reels(scenario, scenario_robot(scenario)).tensions,
                               rtol=1e-9)
    kinematic = simulate(scenario=load_scenario("exp2_interaction"), duration=0.1).log
    assert not {"tensions", "slack", "p_true", "rpy_true"} & set(kinematic)
    doc = (Path(__file__).resolve().parents[2] / "docs" / "LOG_FORMAT.md").read_text()
    for key in ("tensions", "slack", "p_true", "rpy_true"):
        assert f"`{key}`" in doc


def test_the_logged_desired_force_is_what_the_admittance_integrated_on_the_dynamic_plant():
    # What the user sees must be what the controller used: the admittance's recursion
    # v_{k+1} = A_d u_k + B_d F_d,k (make_admittance's zero-order-hold matrices, u the logged
    # commanded velocity) holds on the logged F_d to round-off, as on the kinematic plant
    # (tests/systems/test_diagram.py). Issue 21: with the MultibodyPlant's sampled output ports, its
    # step ran before the controller's update at each tick, so the controller measured the hand
    # on the platform of one plant step later than the F_d it logged (2.4e-7 m/s off here).
    from cdpm_drake.systems.admittance import make_admittance

    scenario = load_scenario("exp2_interaction", "plant: !DynamicReels {}")
    log = simulate(scenario=scenario, duration=1.0).log
    zoh = make_admittance(scenario.admittance.mass, scenario.admittance.damping,
                          scenario.time_step)
    A, B = zoh.A()[0, 0], zoh.B()[0, 0]
    v, u, F_d = log["velocity_admittance"], log["velocity"], log["F_d"]
    assert np.abs(B * F_d).max() > 1e-4  # the hand does push: a step's increment is 0.1 mm/s
    np.testing.assert_allclose(v[1:], A * u[:-1] + B * F_d[:-1], rtol=0, atol=1e-12)


# --- Views and cdpm info ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def dynamic_log():
    """0.2 s of exp2 on the dynamic plant, with a tilt and cable 3 marked slack at row 5 (the
    views draw what the log says; the plant's own slack is tested above)."""
    log = simulate(scenario=load_scenario("exp2_interaction", "plant: !DynamicReels {}"),
                   duration=0.2).log
    log = dict(log)
    log["rpy_true"] = log["rpy_true"].copy()
    log["rpy_true"][5] = [0.1, -0.2, 0.3]
    log["slack"] = log["slack"].copy()
    log["slack"][5, 2] = True
    return log


def test_plot_log_adds_tensions_and_pose_error_for_a_dynamic_log(dynamic_log, tmp_path):
    from cdpm_drake.views.figures_plant import figure_pose_error, figure_tensions
    from cdpm_drake.views.plots import plot_log

    names = [p.name for p in plot_log(dynamic_log, tmp_path, dpi=40)]
    # The safety filter's figure last (the default scenario runs the filter).
    assert names[-3:] == ["tensions.png", "pose_error.png", "safety.png"]
    fig = figure_tensions(dynamic_log)
    lines = [line for line in fig.axes[0].get_lines() if line.get_label().startswith("cable")
             and "slack" not in line.get_label()]
    assert len(lines) == 7
    np.testing.assert_allclose(lines[2].get_ydata(), dynamic_log["tensions"][:, 2])
    # Slack ticks on the row of each cable, below the tensions (issue 22).
    slack_marks = [line for line in fig.axes[1].get_lines() if "slack" in line.get_label()]
    assert [line.get_label() for line in slack_marks] == ["cable 3 slack (1 ticks)"]
    assert list(slack_marks[0].get_ydata()) == [3]
    fig = figure_pose_error(dynamic_log)
    norm = [line for line in fig.axes[0].get_lines() if line.get_label() == "|p - p_true|"][0]
    np.testing.assert_allclose(norm.get_ydata(), 1000 * np.linalg.norm(
        dynamic_log["p"] - dynamic_log["p_true"], axis=1))
    roll = [line for line in fig.axes[1].get_lines() if line.get_label() == "roll (true)"][0]
    assert roll.get_ydata()[5] == pytest.approx(np.degrees(0.1))


def test_the_dynamic_figures_mark_a_fault_like_the_others(dynamic_log):
    # A dynamic run can end on a fault (the controller's forward kinematics refusing lengths
    # a rotated platform gives): its time is marked on every time axis, its message titled.
    from cdpm_drake.views.figures_plant import figure_pose_error, figure_tensions

    log = dict(dynamic_log, ending=np.array("fault"), fault_time=np.array(0.1),
               fault_message=np.array("cable lengths are inconsistent"))
    for make in (figure_tensions, figure_pose_error):
        fig = make(log)
        assert "fault at t = 0.100 s: cable lengths are inconsistent" in fig.get_suptitle()
        for ax in fig.axes:
            marks = [line for line in ax.get_lines() if line.get_gid() == "fault"]
            assert len(marks) == 1 and list(marks[0].get_xdata()) == [0.1, 0.1]


def test_meshcat_draws_the_true_rotated_platform_and_slack_cables(dynamic_log):
    from helpers_meshcat import prop, transform

    from cdpm_drake.views import meshcat_view as mv

    meshcat = mv.make_meshcat(port=0)
    view = mv.CdpmMeshcatView.from_log(meshcat, dynamic_log)
    view.draw_row(dynamic_log, 5)
    R = rotation_from_rpy([0.1, -0.2, 0.3])
    X = transform(meshcat, "/cdpm/platform")
    np.testing.assert_allclose(X[:3, :3], R, atol=1e-6)
    p = dynamic_log["p_true"][5]
    np.testing.assert_allclose(X[:3, 3], p, atol=1e-6)
    for i in (1, 3):
        a = dynamic_log["reels"][i - 1]
        cable = transform(meshcat, view.cable_path(i))
        direction = p + R @ dynamic_log["attachments"][i - 1] - a
        np.testing.assert_allclose(cable[:3, 3], a, atol=1e-6)
        np.testing.assert_allclose(cable[:3, 2], direction / np.linalg.norm(direction),
                                   atol=1e-6)
    assert prop(meshcat, view.cable_slack_path(3), "visible") is True
    assert not any(prop(meshcat, view.cable_level_path(3, k), "visible")
                   for k in range(mv.LEVELS))
    assert prop(meshcat, view.cable_slack_path(1), "visible") is False
    view.draw_row(dynamic_log, 6)  # taut again: its distance colour is back
    assert prop(meshcat, view.cable_slack_path(3), "visible") is False


def test_cdpm_info_prints_the_wrench_feasibility_table(capsys):
    # Issue 27: the table is on the grid of the share line above it (one grid for one
    # quantity), so its 0 N row at the 5 N floor is that line's share. Each cell is checked
    # against wrench_feasibility on the whole grid for that force and floor, without the
    # table's shortcut (solving each force only where the smaller one held).
    from cdpm_drake import cli
    from cdpm_drake.cli.info import FEASIBILITY_FLOORS, FEASIBILITY_FORCES
    from cdpm_drake.kernels.tension import step_grid
    from cdpm_drake.robot.statics import wrench_feasibility

    assert cli.main(["info", "paper_7cable", "--grid", "0.25"]) == 0
    out = capsys.readouterr().out
    robot = load_robot("paper_7cable")
    d = robot.dynamics
    points = step_grid(robot.workspace.lower, robot.workspace.upper, 0.25)
    table = out.split("wrench feasibility")[1]
    assert table.startswith(" on the same grid (25 cm grid from the lower corner: 11 x 13 x 9 "
                            "points)"), table
    rows = {}
    for force in FEASIBILITY_FORCES:
        shares = [wrench_feasibility(robot, mass=d.mass, hand_force=force, handle=d.handle,
                                     min_tension=floor, points=points).share
                  for floor in FEASIBILITY_FLOORS]
        rows[force] = shares
        row = f"{force:g}" + "".join(f"  {100 * s:.1f}" for s in shares)
        assert " ".join(row.split()) in [" ".join(line.split()) for line in table.splitlines()]
    assert 0.0 < rows[20.0][1] < rows[5.0][1] < rows[0.0][1]  # the shortcut had work to skip
    share = re.search(r"held with every cable >= 5 N on ([0-9.]+) %", out)
    assert float(share[1]) == pytest.approx(100 * rows[0.0][1], abs=0.05)


def test_the_plant_diagram_graphviz_is_stable_across_builds():
    # The committed diagrams/plant_dynamic.dot is drawn from the plant alone, whose port
    # clusters Drake names after its system id (`clusters<id>in`).
    from cdpm_drake.views.diagram_graph import stable_graphviz

    scenario = load_scenario("exp2_interaction", "plant: !DynamicReels {}")
    first = stable_graphviz(build_diagram(scenario).GetSubsystemByName("reels"))
    build_diagram(scenario)  # more systems in between
    second = stable_graphviz(build_diagram(scenario).GetSubsystemByName("reels"))
    assert first == second and "clusters0in" in first


def test_the_live_view_follows_the_true_platform_of_a_dynamic_run(dynamic_log):
    # The ground truth sits in loggers inside the plant: the live view finds them there.
    from helpers_meshcat import transform

    from cdpm_drake.runs.latest_signals import latest_signals
    from cdpm_drake.views import meshcat_view as mv

    meshcat = mv.make_meshcat(port=0)
    view = mv.CdpmMeshcatView.from_log(meshcat, dynamic_log)
    scenario = load_scenario("exp2_interaction", "plant: !DynamicReels {}")
    result = simulate(scenario=scenario, duration=0.1, chunk=0.1,
                      on_chunk=mv.live_view_callback(view, latest_signals))
    X = transform(meshcat, "/cdpm/platform")
    np.testing.assert_allclose(X[:3, 3], result.log["p_true"][-1], atol=1e-9)
    np.testing.assert_allclose(X[:3, :3], rotation_from_rpy(result.log["rpy_true"][-1]),
                               atol=1e-6)
