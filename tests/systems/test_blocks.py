"""The Fig. 5 blocks one by one, each in a tiny diagram or with fixed inputs, against closed
forms, finite differences or the numpy function it wraps."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource, VectorLogSink
from pydrake.trajectories import PiecewisePolynomial

from cdpm_drake.kernels.kinematics import KinematicsError, cable_lengths, jacobian
from cdpm_drake.kernels.safety_limits import limit_velocity, wall_force
from cdpm_drake.kernels.plant.operators import ForceProfile
from cdpm_drake.robot import Robot, RobotLimits, Workspace, load_robot
from cdpm_drake.systems.admittance import make_admittance
from cdpm_drake.systems.force_sensor import ForceSensorSource, clip_to_sensor_range
from cdpm_drake.systems.forward_kinematics import ForwardKinematicsEstimator
from cdpm_drake.systems.jacobian_mapping import JacobianVelocityMapping
from cdpm_drake.systems.plants.simulated_reels import SensorNoise, SimulatedReelsSystem
from cdpm_drake.systems.safety_limits import SafetyLimits
from cdpm_drake.systems.wall_force import WorkspaceWallForce

T = 0.002


def run_chain(source, system, ticks, output="y0", input_name=None):
    """source -> system -> logger; simulate `ticks` ticks; the logged rows (ticks + 1, n)."""
    builder = DiagramBuilder()
    builder.AddSystem(source)
    builder.AddSystem(system)
    sink = system.GetInputPort(input_name) if input_name else system.get_input_port(0)
    builder.Connect(source.get_output_port(0), sink)
    out = system.GetOutputPort(output)
    logger = builder.AddSystem(VectorLogSink(out.size(), T))
    builder.Connect(out, logger.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(ticks * T)
    log = logger.FindLog(simulator.get_context())
    np.testing.assert_allclose(log.sample_times(), T * np.arange(ticks + 1), atol=1e-12)
    return log.data().T


# --- Admittance -------------------------------------------------------------------------------


@pytest.mark.parametrize("mass,damping", [(6.25, 6.25), (2.0, 5.0)])
def test_admittance_alone_is_the_exact_zero_order_hold_solution(mass, damping):
    """A constant F from t = 0 into 1/(M s + C): the exact ZOH solution v_k = F/C (1 - exp(-k T
    C/M)). Row k of the log is the state after k updates (the output is the state; no direct
    feedthrough), so there is no index offset."""
    F = np.array([3.0, -1.5, 0.5])
    v = run_chain(ConstantVectorSource(F), make_admittance(mass, damping, T), 200)
    k = np.arange(v.shape[0])[:, None]
    expected = F / damping * (1.0 - np.exp(-k * T * damping / mass))
    np.testing.assert_allclose(v, expected, rtol=0, atol=1e-12)


def test_admittance_has_no_direct_feedthrough():
    # That is what breaks the Fig. 5 loop without an algebraic loop.
    admittance = make_admittance(6.25, 6.25, T)
    assert not admittance.HasAnyDirectFeedthrough()
    assert admittance.get_input_port().size() == 3
    assert admittance.get_output_port().size() == 3


# --- Force sensor -----------------------------------------------------------------------------

AXIS = np.array([0.0, 0.0, 1.0])


def test_sensor_range_saturates_axial_at_100_and_transverse_at_80_newtons():
    clip = lambda f, axis=AXIS: clip_to_sensor_range(np.array(f, float), axis, 100.0, 80.0)
    np.testing.assert_array_equal(clip([10.0, -20.0, 30.0]), [10.0, -20.0, 30.0])  # in range
    np.testing.assert_array_equal(clip([0.0, 0.0, 150.0]), [0.0, 0.0, 100.0])
    np.testing.assert_array_equal(clip([0.0, 0.0, -150.0]), [0.0, 0.0, -100.0])
    # Transverse (60, 80) N has norm 100 > 80: scaled by 0.8 to (48, 64) N, direction kept.
    np.testing.assert_allclose(clip([60.0, 80.0, -120.0]), [48.0, 64.0, -100.0], atol=1e-12)
    # Axis along x: now x is axial (range 100 N) and z transverse (range 80 N).
    x = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(clip([90.0, 0.0, 90.0], x), [90.0, 0.0, 80.0], atol=1e-12)


def test_sensor_axis_is_normalised():
    # An axis given as [0, 0, 2] must act like [0, 0, 1]: a 150 N axial push reads 100 N.
    sensor = ForceSensorSource(axial_axis=[0.0, 0.0, 2.0], window=1, time_step=T)
    context = sensor.CreateDefaultContext()
    sensor.GetInputPort("measured_force").FixValue(context, [0.0, 0.0, 150.0])
    np.testing.assert_allclose(sensor.GetOutputPort("F_H").Eval(context), [0.0, 0.0, 100.0])


@pytest.mark.parametrize("window", [1, 4, 10])
def test_sliding_average_turns_a_step_into_a_ramp_over_the_window(window):
    """A step of F at t = 0.101 s (between ticks 50 and 51): tick k averages samples
    k-W+1..k, so F_H_k = F * clip(k - 51 + 1, 0, W) / W: a ramp of W ticks, F at tick 50+W."""
    F = np.array([2.0, -4.0, 6.0])
    step = PiecewisePolynomial.ZeroOrderHold([0.0, 0.101, 1.0],
                                             np.column_stack([np.zeros(3), F, F]))
    sensor = ForceSensorSource(axial_axis=AXIS, window=window, time_step=T)
    F_H = run_chain(TrajectorySource(step), sensor, 100, output="F_H")
    k = np.arange(F_H.shape[0])[:, None]
    expected = F * np.clip(k - 51 + 1, 0, window) / window
    np.testing.assert_allclose(F_H, expected, rtol=0, atol=1e-12)


def test_sliding_average_of_saturated_samples():
    # The range is applied to each sample before averaging: 200 N axial reads 100 N.
    sensor = ForceSensorSource(axial_axis=AXIS, window=5, time_step=T)
    F_H = run_chain(ConstantVectorSource([0.0, 0.0, 200.0]), sensor, 10, output="F_H")
    np.testing.assert_allclose(F_H[4:, 2], 100.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(F_H[:4, 2], 100.0 * np.arange(1, 5) / 5, rtol=0, atol=1e-12)


@pytest.mark.parametrize("window", [1, 10])
def test_sensor_noise_statistics_through_the_filter(window):
    """Gaussian noise of std sigma per axis, then the W-sample average: mean ~ 0, std ~
    sigma / sqrt(W), lag-1 autocorrelation (W - 1) / W (white noise: 0). Tolerances: 3000
    samples of which ~3000 / W independent give standard errors of the std of
    ~sqrt(W / 6000) (<= 4 %) and of the autocorrelation of ~sqrt(W / 3000) (<= 6 %); the
    bounds allow four of those."""
    sigma = 2.0
    ticks = 3000
    sensor = ForceSensorSource(axial_axis=AXIS, window=window, time_step=T)
    F_H = run_chain(SensorNoise(std=sigma, seed=11, time_step=T), sensor, ticks,
                    output="F_H", input_name="measured_force")[window:]
    n_eff = F_H.shape[0] / window
    assert np.all(np.abs(F_H.mean(axis=0)) < 4 * sigma / np.sqrt(window) / np.sqrt(n_eff))
    np.testing.assert_allclose(F_H.std(axis=0), sigma / np.sqrt(window),
                               rtol=4 * np.sqrt(window / (2 * ticks)))
    x = F_H - F_H.mean(axis=0)
    lag1 = (x[1:] * x[:-1]).sum(axis=0) / (x * x).sum(axis=0)
    np.testing.assert_allclose(lag1, (window - 1) / window, atol=4 * np.sqrt(window / ticks))


def test_sensor_noise_is_held_within_a_tick_and_repeatable_per_seed():
    noise = SensorNoise(std=2.0, seed=5, time_step=T)
    context = noise.CreateDefaultContext()

    def at(t, system=noise, ctx=context):
        ctx.SetTime(t)
        return system.get_output_port().Eval(ctx).copy()

    np.testing.assert_array_equal(at(0.010), at(0.0119))  # tick 5 held until tick 6
    assert not np.array_equal(at(0.010), at(0.012))
    again = SensorNoise(std=2.0, seed=5, time_step=T)
    other = SensorNoise(std=2.0, seed=6, time_step=T)
    np.testing.assert_array_equal(at(0.5), at(0.5, again, again.CreateDefaultContext()))
    assert not np.array_equal(at(0.5), at(0.5, other, other.CreateDefaultContext()))


# --- Jacobian mapping -------------------------------------------------------------------------


def test_jacobian_mapping_matches_finite_differences_of_the_lengths():
    """l_dot = J(p) v: compared with the central difference (l(p + h v) - l(p - h v)) / 2h."""
    robot = load_robot("paper_7cable")
    mapping = JacobianVelocityMapping(robot)
    context = mapping.CreateDefaultContext()
    p = np.array([1.77, 3.65, 1.22])
    v = np.array([0.12, -0.07, 0.2])
    mapping.GetInputPort("p_WP").FixValue(context, p)
    mapping.GetInputPort("velocity_command").FixValue(context, v)
    # Measured lengths 3 mm off the geometry: the first tick latches them (the length loop
    # starts with no error), so the command is J v alone, whatever the encoders' zero.
    mapping.GetInputPort("cable_lengths").FixValue(context, cable_lengths(robot, p) + 0.003)
    out = mapping.GetOutputPort("reel_velocity_command").Eval(context)
    h = 1e-6
    fd = (cable_lengths(robot, p + h * v) - cable_lengths(robot, p - h * v)) / (2 * h)
    assert out.shape == (7,)
    np.testing.assert_allclose(out, fd, rtol=0, atol=1e-9)


# --- Simulated reels --------------------------------------------------------------------------

# Three cables: any three nearby lengths are reachable, so the plant's projection onto the
# geometry is the identity and its lengths are exactly the integrated commands.
TRIPOD = Robot(name="tripod", reels=[[0.0, 0.0, 3.0], [4.0, 0.0, 3.0], [2.0, 3.0, 3.0]],
               attachments=np.zeros((3, 3)),
               workspace=Workspace(np.array([0.5, 0.5, 0.2]), np.array([3.5, 2.5, 2.5])),
               limits=RobotLimits(max_velocity=0.5, max_acceleration=2.0, max_reel_speed=1.0))
P0 = np.array([2.0, 1.2, 1.0])


def reels_log(command, ticks, **kwargs):
    reels = SimulatedReelsSystem(TRIPOD, initial_position=P0, time_step=T, **kwargs)
    return run_chain(ConstantVectorSource(command), reels, ticks, output="cable_lengths")


def test_ideal_reels_integrate_the_command_and_scale_it_to_the_reel_speed():
    # 1.5 m/s on cable 3 is above max_reel_speed = 1 m/s: the whole command is scaled by
    # 1/1.5 (direction kept, as the hardware plant does): (0.2, -0.3, 1.5) / 1.5.
    command = np.array([0.2, -0.3, 1.5])
    lengths = reels_log(command, 50)
    k = np.arange(51)[:, None]
    expected = cable_lengths(TRIPOD, P0) + k * T * command / 1.5
    np.testing.assert_allclose(lengths, expected, rtol=0, atol=1e-9)
    # max_reel_speed from the scenario overrides the robot's: scaled by 0.25 / 1.5.
    lengths = reels_log(command, 50, max_reel_speed=0.25)
    expected = cable_lengths(TRIPOD, P0) + k * T * command * (0.25 / 1.5)
    np.testing.assert_allclose(lengths, expected, rtol=0, atol=1e-9)
    # Within the limit nothing changes.
    lengths = reels_log(np.array([0.2, -0.3, 0.5]), 50)
    expected = cable_lengths(TRIPOD, P0) + k * T * np.array([0.2, -0.3, 0.5])
    np.testing.assert_allclose(lengths, expected, rtol=0, atol=1e-9)


def test_reel_lag_is_the_discrete_first_order_response():
    """Speed after n updates: c (1 - q^n), q = exp(-T/tau); lengths after n updates:
    l0 + T c (n - q (1 - q^n) / (1 - q)) (the sum of those speeds)."""
    tau = 0.05
    command = np.array([0.1, -0.2, 0.3])
    lengths = reels_log(command, 100, time_constant=tau)
    q = np.exp(-T / tau)
    n = np.arange(101)[:, None]
    expected = cable_lengths(TRIPOD, P0) + T * command * (n - q * (1 - q**n) / (1 - q))
    np.testing.assert_allclose(lengths, expected, rtol=0, atol=1e-9)


def test_reels_report_the_true_pose_consistent_with_the_lengths():
    reels = SimulatedReelsSystem(TRIPOD, initial_position=P0, time_step=T)
    context = reels.CreateDefaultContext()
    v = np.array([0.1, 0.05, -0.08])
    reels.GetInputPort("reel_velocity_command").FixValue(context, jacobian(TRIPOD, P0) @ v)
    context.SetDiscreteState(reels.EvalUniquePeriodicDiscreteUpdate(context))
    p = reels.GetOutputPort("p_WP_true").Eval(context)
    # One Euler step of l_dot = J v moves p by T v up to O(T^2 |v|^2 / l).
    np.testing.assert_allclose(p, P0 + T * v, rtol=0, atol=1e-6)
    np.testing.assert_allclose(reels.GetOutputPort("v_WP_true").Eval(context), (p - P0) / T,
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(reels.GetOutputPort("cable_lengths").Eval(context),
                               cable_lengths(TRIPOD, p), rtol=0, atol=1e-12)


# --- Forward kinematics -----------------------------------------------------------------------


def test_forward_kinematics_block_recovers_the_position_and_warm_starts():
    robot = load_robot("paper_7cable")
    p0 = np.array([1.77, 3.65, 1.22])
    fk = ForwardKinematicsEstimator(robot, initial_position=p0, time_step=T)
    context = fk.CreateDefaultContext()
    p = p0 + np.array([0.01, -0.02, 0.005])
    fk.GetInputPort("cable_lengths").FixValue(context, cable_lengths(robot, p))
    np.testing.assert_allclose(fk.GetOutputPort("p_WP").Eval(context), p, rtol=0, atol=1e-9)
    # The update stores the estimate as the next tick's starting guess.
    state = fk.EvalUniquePeriodicDiscreteUpdate(context)
    np.testing.assert_allclose(state.get_vector(0).CopyToVector(), p, rtol=0, atol=1e-9)


def test_forward_kinematics_block_rejects_inconsistent_lengths():
    robot = load_robot("paper_7cable")
    p0 = np.array([1.77, 3.65, 1.22])
    fk = ForwardKinematicsEstimator(robot, initial_position=p0, time_step=T)
    context = fk.CreateDefaultContext()
    lengths = cable_lengths(robot, p0)
    lengths[2] += 0.05  # cable 3 slack by 5 cm: no position explains that
    fk.GetInputPort("cable_lengths").FixValue(context, lengths)
    with pytest.raises(KinematicsError, match="residual"):
        fk.GetOutputPort("p_WP").Eval(context)


# --- Safety limits, wall force, simulated operator --------------------------------------------

LOWER, UPPER = np.array([0.5, 0.8, 0.3]), np.array([3.0, 4.0, 2.4])


def test_safety_limits_block_wraps_limit_velocity_and_remembers_its_command():
    limits = SafetyLimits(lower=LOWER, upper=UPPER, max_velocity=0.5, max_acceleration=2.0,
                          time_step=T)
    context = limits.CreateDefaultContext()
    p = np.array([2.99, 2.0, 1.0])  # 1 cm below the upper x face
    v_desired = np.array([0.4, 0.3, 0.0])
    limits.GetInputPort("velocity_desired").FixValue(context, v_desired)
    limits.GetInputPort("p_WP").FixValue(context, p)
    v_previous = np.zeros(3)
    for _ in range(5):
        out = limits.GetOutputPort("velocity_command").Eval(context)
        expected = limit_velocity(v_desired, v_previous, p, LOWER, UPPER, max_velocity=0.5,
                                  max_acceleration=2.0, time_step=T)
        np.testing.assert_array_equal(out, expected)
        context.SetDiscreteState(limits.EvalUniquePeriodicDiscreteUpdate(context))
        v_previous = expected
    # The wall clips the x component of the desired (0.4, 0.3) to sqrt(2 a' 0.01) - a' T / 2
    # with a' = a / sqrt(3) (per-axis braking, limits._wall_cap) = 0.150812 m/s; from rest,
    # five ticks of a T = 0.004 m/s each along (0.150812, 0.3) make 0.02 m/s that way.
    cap = np.sqrt(0.04 / np.sqrt(3.0)) - 0.002 / np.sqrt(3.0)
    direction = np.array([cap, 0.3, 0.0]) / np.hypot(cap, 0.3)
    np.testing.assert_allclose(v_previous, 0.02 * direction, atol=1e-15)


def test_wall_force_block_wraps_wall_force():
    block = WorkspaceWallForce(lower=LOWER, upper=UPPER, margin=0.1, max_force=4.0)
    context = block.CreateDefaultContext()
    p = np.array([0.55, 3.97, 1.0])
    block.GetInputPort("p_WP").FixValue(context, p)
    out = block.GetOutputPort("F_wall").Eval(context)
    np.testing.assert_array_equal(out, wall_force(p, LOWER, UPPER, margin=0.1, max_force=4.0))
    # 5 cm from the lower x face: 4 (1/2)^2 = 1 N inwards; 3 cm from the upper y face:
    # 4 (7/10)^2 = 1.96 N inwards.
    np.testing.assert_allclose(out, [1.0, -1.96, 0.0], atol=1e-12)


def test_simulated_person_is_the_model_at_each_tick_on_the_true_pose():
    """The reels' hand_force at tick k is the operator model at t_k = k T on that tick's true
    pose, for a scripted ramp (no pose dependence: exactly the table) and for a spring hand
    (pose dependent: K (target - p) - D v, the model evaluated independently here)."""
    from cdpm_drake.kernels.plant.operators import SpringHand

    ramp = ForceProfile([0.0, 1.0], [[0.0, 0.0, 0.0], [2.0, -4.0, 8.0]])
    v = np.array([0.1, 0.05, -0.08])
    for model in (ramp, SpringHand([P0, P0 + [0.2, 0.0, 0.0]], [0.0, 1.0], 60.0, 6.0, 5.0)):
        reels = SimulatedReelsSystem(TRIPOD, initial_position=P0, time_step=T, operator=model)
        builder = DiagramBuilder()
        builder.AddSystem(reels)
        source = builder.AddSystem(ConstantVectorSource(jacobian(TRIPOD, P0) @ v))
        builder.Connect(source.get_output_port(), reels.GetInputPort("reel_velocity_command"))
        loggers = {}
        for name in ("hand_force", "p_WP_true", "v_WP_true"):
            port = reels.GetOutputPort(name)
            loggers[name] = builder.AddSystem(VectorLogSink(port.size(), T))
            builder.Connect(port, loggers[name].get_input_port())
        diagram = builder.Build()
        simulator = Simulator(diagram)
        simulator.AdvanceTo(50 * T)
        rows = {name: log.FindLog(simulator.get_context()) for name, log in loggers.items()}
        times = rows["hand_force"].sample_times()
        force, p, v_true = (rows[n].data().T for n in ("hand_force", "p_WP_true", "v_WP_true"))
        expected = np.array([model.force(t, pk, vk) for t, pk, vk in zip(times, p, v_true)])
        np.testing.assert_allclose(force, expected, rtol=0, atol=1e-12)
        if model is ramp:
            np.testing.assert_allclose(force[25], [0.1, -0.2, 0.4], atol=1e-12)  # t = 0.05 s
