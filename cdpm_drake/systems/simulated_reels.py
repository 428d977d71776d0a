"""The simulated reel plant of Fig. 5 and the simulated person at the handle."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from ..kinematics import cable_lengths, forward_kinematics


class SimulatedReels(LeafSystem):
    """Reels that integrate their velocity commands to cable lengths at the control rate.

    Each tick: the command is scaled down to the reel speed limit (all reels alike), passed through a first-order lag
    (time constant `time_constant`, s; 0 for ideal drives) and integrated over one step. Seven
    cables over-constrain a translating platform, so the integrated lengths are projected back
    onto the geometry (least-squares forward kinematics, then inverse kinematics): the platform
    settles where the cables agree best, as taut elastic cables make it do. The true platform
    position and velocity are outputs for the simulated operator only; the controller sees the
    cable lengths, as on the robot.

    .. pydrake_system::

        name: simulated_reels
        input_ports:
        - reel_velocity_command (m/s, one per cable)
        output_ports:
        - cable_lengths (m, one per cable)
        - p_WP_true (m, base frame)
        - v_WP_true (m/s, base frame)
    """

    def __init__(self, robot, *, initial_position, time_step=0.002, time_constant=0.0,
                 max_reel_speed=None):
        super().__init__()
        self._robot = robot
        m = robot.num_cables
        self._T = float(time_step)
        self._lag = 1.0 - np.exp(-self._T / time_constant) if time_constant > 0 else 1.0
        self._vmax = float(max_reel_speed if max_reel_speed is not None
                           else robot.limits.max_reel_speed)
        self._command = self.DeclareVectorInputPort("reel_velocity_command", m)
        p0 = np.asarray(initial_position, dtype=float)
        self._lengths = self.DeclareDiscreteState(cable_lengths(robot, p0))
        self._pose = self.DeclareDiscreteState(np.concatenate([p0, np.zeros(3)]))  # p, v
        self._reel_speed = self.DeclareDiscreteState(m)  # lagged actual reel velocity
        self.DeclareStateOutputPort("cable_lengths", self._lengths)
        self.DeclareVectorOutputPort(
            "p_WP_true", 3, lambda c, o: o.SetFromVector(self._pose_of(c)[:3]),
            prerequisites_of_calc={self.discrete_state_ticket(self._pose)})
        self.DeclareVectorOutputPort(
            "v_WP_true", 3, lambda c, o: o.SetFromVector(self._pose_of(c)[3:]),
            prerequisites_of_calc={self.discrete_state_ticket(self._pose)})
        self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0, self._update_reels)

    def _pose_of(self, context):
        return context.get_discrete_state(self._pose).get_value()

    def _update_reels(self, context, discrete_state):
        command = self._command.Eval(context)
        peak = float(np.max(np.abs(command))) if command.size else 0.0
        if peak > self._vmax:
            # Scale all reels alike, as the hardware plant does: the platform slows down but
            # keeps its direction (clipping one reel would steer it).
            command = command * (self._vmax / peak)
        speed = context.get_discrete_state(self._reel_speed).get_value()
        speed = speed + self._lag * (command - speed)
        lengths = context.get_discrete_state(self._lengths).get_value() + self._T * speed
        p = self._pose_of(context)[:3]
        p_new = forward_kinematics(self._robot, lengths, p_guess=p, max_residual=np.inf)
        discrete_state.get_mutable_vector(self._lengths).SetFromVector(
            cable_lengths(self._robot, p_new))
        discrete_state.get_mutable_vector(self._pose).SetFromVector(
            np.concatenate([p_new, (p_new - p) / self._T]))
        discrete_state.get_mutable_vector(self._reel_speed).SetFromVector(speed)


class SimulatedOperator(LeafSystem):
    """The person at the handle: an operator model (see `operators`) evaluated on the
    platform's true motion. Part of the simulated plant, never of the controller.

    .. pydrake_system::

        name: operator
        input_ports:
        - p_WP_true (m, base frame)
        - v_WP_true (m/s, base frame)
        output_ports:
        - hand_force (N, base frame)
    """

    def __init__(self, operator):
        super().__init__()
        self._operator = operator
        self._p = self.DeclareVectorInputPort("p_WP_true", 3)
        self._v = self.DeclareVectorInputPort("v_WP_true", 3)
        self.DeclareVectorOutputPort(
            "hand_force", 3, self._calc_hand_force,
            prerequisites_of_calc={self.time_ticket(), self._p.ticket(), self._v.ticket()})

    def _calc_hand_force(self, context, output):
        output.SetFromVector(self._operator.force(context.get_time(), self._p.Eval(context),
                                                  self._v.Eval(context)))


class SensorNoise(LeafSystem):
    """Gaussian force-sensor noise: std `std` (N) per axis, a new sample every tick, held in
    between. Part of the simulated plant.

    The sample of tick k is a pure function of (`seed`, k), so every block reads the same
    sample at tick k. Drake's RandomSource draws in an unrestricted update, which runs before
    the discrete updates of the same tick: the sensor filter and the admittance then
    integrate tick k+1's sample while tick k's is logged.

    .. pydrake_system::

        name: sensor_noise
        output_ports:
        - noise (N, base frame)
    """

    def __init__(self, *, std, seed=0, time_step=0.002):
        super().__init__()
        self._std = float(std)
        self._seed = int(seed)
        self._T = float(time_step)
        self.DeclareVectorOutputPort("noise", 3, self._calc_noise,
                                     prerequisites_of_calc={self.time_ticket()})

    def _calc_noise(self, context, output):
        k = int(np.floor(context.get_time() / self._T + 1e-9))
        rng = np.random.default_rng([self._seed, k])
        output.SetFromVector(self._std * rng.standard_normal(3))
