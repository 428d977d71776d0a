"""The simulated reel plant of Fig. 5 and the simulated person at the handle."""

import numpy as np
from pydrake.systems.framework import Diagram, LeafSystem
from pydrake.systems.primitives import Demultiplexer

from ..kinematics import cable_lengths, forward_kinematics, simulated_reel_step
from ._wiring import sub_diagram, unit_delay


class ReelStep(LeafSystem):
    """The reels' next state from the command and the present state (an input): one call of
    `kinematics.simulated_reel_step` per tick; stateless.

    .. pydrake_system::

        name: step
        input_ports:
        - reel_velocity_command (m/s, one per cable)
        - state (lengths m, p m, v m/s, reel speeds m/s)
        output_ports:
        - next_state (same layout)
    """

    def __init__(self, robot, *, time_step, time_constant, max_reel_speed):
        super().__init__()
        self._robot = robot
        m = robot.num_cables
        self._offsets = np.ascontiguousarray(robot.attachments - robot.reels)
        self._T = float(time_step)
        self._lag = 1.0 - np.exp(-self._T / time_constant) if time_constant > 0 else 1.0
        self._vmax = float(max_reel_speed)
        self._command = self.DeclareVectorInputPort("reel_velocity_command", m)
        self._state = self.DeclareVectorInputPort("state", 2 * m + 6)
        self.DeclareVectorOutputPort(
            "next_state", 2 * m + 6, self._calc_next_state,
            prerequisites_of_calc={self._command.ticket(), self._state.ticket()})
        # Compile (or load) the kernel now, not in the first tick.
        simulated_reel_step(self._offsets, self._T, self._lag, self._vmax, np.zeros(m),
                            np.ones(2 * m + 6), np.empty(2 * m + 6))

    def _calc_next_state(self, context, output):
        state = self._state.Eval(context)
        out = output.get_mutable_value()
        if not simulated_reel_step(self._offsets, self._T, self._lag, self._vmax,
                                   self._command.Eval(context), state, out):
            # Gauss-Newton did not settle: the damped solver (and its error messages).
            m = self._robot.num_cables
            p = state[m:m + 3]
            p_new = forward_kinematics(self._robot, out[:m].copy(), p_guess=p,
                                       max_residual=np.inf)
            out[:m] = cable_lengths(self._robot, p_new)
            out[m:m + 3] = p_new
            out[m + 3:m + 6] = (p_new - p) / self._T


class SimulatedReels(Diagram):
    """Reels that integrate their velocity commands to cable lengths at the control rate.

    Each tick: the command is scaled down to the reel speed limit (all reels alike), passed
    through a first-order lag (time constant `time_constant`, s; 0 for ideal drives) and
    integrated over one step. Seven cables over-constrain a translating platform, so the
    integrated lengths are projected back onto the geometry (least-squares forward
    kinematics, then inverse kinematics): the platform settles where the cables agree best, as
    taut elastic cables make it do. The true platform position and velocity are outputs for
    the simulated operator only; the controller sees the cable lengths, as on the robot. The
    state (lengths, pose, lagged reel speeds) is held by a C++ one-tick delay.

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
        m = robot.num_cables
        p0 = np.asarray(initial_position, dtype=float)
        x0 = np.concatenate([cable_lengths(robot, p0), p0, np.zeros(3), np.zeros(m)])
        vmax = max_reel_speed if max_reel_speed is not None else robot.limits.max_reel_speed

        def build(builder):
            step = builder.AddNamedSystem("step", ReelStep(
                robot, time_step=time_step, time_constant=time_constant,
                max_reel_speed=vmax))
            state = builder.AddNamedSystem("state", unit_delay(2 * m + 6, time_step, x0))
            split = builder.AddNamedSystem("split", Demultiplexer([m, 3, 3, m]))
            builder.Connect(step.GetOutputPort("next_state"), state.get_input_port())
            builder.Connect(state.get_output_port(), step.GetInputPort("state"))
            builder.Connect(state.get_output_port(), split.get_input_port())
            builder.ExportInput(step.GetInputPort("reel_velocity_command"),
                                "reel_velocity_command")
            for k, name in enumerate(("cable_lengths", "p_WP_true", "v_WP_true")):
                builder.ExportOutput(split.get_output_port(k), name)

        sub_diagram(self, build)


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
        # The shipped models write into the output directly (operators.*.force_into).
        self._force_into = getattr(operator, "force_into", None)
        if self._force_into is not None:  # compile (or load) now, not in the first tick
            self._force_into(0.0, np.zeros(3), np.zeros(3), np.empty(3))
        self._p = self.DeclareVectorInputPort("p_WP_true", 3)
        self._v = self.DeclareVectorInputPort("v_WP_true", 3)
        self.DeclareVectorOutputPort(
            "hand_force", 3, self._calc_hand_force,
            prerequisites_of_calc={self.time_ticket(), self._p.ticket(), self._v.ticket()})

    def _calc_hand_force(self, context, output):
        t, p, v = context.get_time(), self._p.Eval(context), self._v.Eval(context)
        if self._force_into is not None:
            self._force_into(t, p, v, output.get_mutable_value())
        else:  # any model with force(t, p, v)
            output.SetFromVector(self._operator.force(t, p, v))


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
