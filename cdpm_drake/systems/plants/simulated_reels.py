"""The simulated reel plant of Fig. 5, with the simulated person at the handle."""

import numpy as np
from pydrake.systems.framework import Diagram, LeafSystem
from pydrake.systems.primitives import Adder, ConstantVectorSource

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.kinematics import cable_lengths, forward_kinematics, simulated_reel_step_stacked
from cdpm_drake.kernels.plant.operators import ForceProfile, NoForce, SpringHand, operator_force_on_state
from cdpm_drake.systems.wiring import sub_diagram, unit_delay, wiring


class ReelStep(LeafSystem):
    """The world's next state from the reel command and the present state: one call of
    `kinematics.simulated_reel_step` per tick, then the person's hand force at the next tick
    on the new pose (the force sensor's next sample); stateless. Its inputs arrive stacked by
    a C++ Selector (one evaluation from Python, not two).

    .. pydrake_system::

        name: simulated_reels
        input_ports:
        - inputs ([reel_velocity_command m/s (one per cable), state (see state_size)])
        output_ports:
        - next_state (same layout)
    """

    def __init__(self, robot, operator, *, time_step, time_constant, max_reel_speed):
        super().__init__()
        self._robot = robot
        m = self._m = robot.num_cables
        self._offsets = owned(robot.attachments - robot.reels)
        self._T = float(time_step)
        lag = 1.0 - np.exp(-self._T / time_constant) if time_constant > 0 else 1.0
        self._reel = owned([self._T, lag, float(max_reel_speed)])
        self._operator = operator
        self._force_into = getattr(operator, "force_into", None)
        # The shipped models (exactly these classes: a subclass may change the force) are
        # ticked by a compiled kernel; any other model is called from Python.
        if type(operator) in (NoForce, ForceProfile, SpringHand):
            kind, times, rows, params = operator.compiled()
            self._person = (int(kind), owned(times), owned(rows), owned(params))
        else:
            self._person = (-1, owned(np.zeros(1)), owned(np.zeros((1, 3))), owned(np.zeros(4)))
        self._inputs = self.DeclareVectorInputPort("inputs", m + state_size(m))
        # Compiled (or loaded) now, not in the first tick.
        # Two kernels, each in the file of the functions it calls: numba's cache does not see
        # a change in a function of another file (a kernel calling across files would keep
        # running the old code after an edit).
        step = bind(simulated_reel_step_stacked, self._offsets, self._reel,
                    np.ones(m + state_size(m)), np.empty(state_size(m)))
        person = bind(operator_force_on_state, *self._person, 0.0, np.zeros(state_size(m)), m)
        if self._person[0] < 0 and self._force_into is not None:  # ticked from Python
            self._force_into(0.0, np.zeros(3), np.zeros(3), np.empty(3))
        # The tick's callback is a closure over locals, not a method reading self: attribute
        # lookups on a pybind LeafSystem cost ~0.2 us each (scripts/bench/count_instructions.py).
        offsets, reel, T, inputs = self._offsets, self._reel, self._T, self._inputs.Eval
        kind, times, rows, params = self._person
        add_hand_force, unsettled = self._add_hand_force, self._finish_unsettled

        def calc_next_state(context, output):
            x = inputs(context)
            out = output.get_mutable_value()
            # The hand force is the sample the sensor reads at the next tick, t + T, on the
            # new pose.
            t_next = context.get_time() + T
            if not step(offsets, reel, x, out):
                unsettled(x, out)
            if kind >= 0:
                person(kind, times, rows, params, t_next, out, m)
            else:
                add_hand_force(t_next, out)

        self.DeclareVectorOutputPort(
            "next_state", state_size(m), calc_next_state,
            prerequisites_of_calc={self.time_ticket(), self._inputs.ticket()})

    def _finish_unsettled(self, x, out):
        """Gauss-Newton did not settle: the damped solver (and its error messages)."""
        m = self._m
        p = x[2 * m:2 * m + 3]
        p_new = forward_kinematics(self._robot, out[:m].copy(), p_guess=p, max_residual=np.inf)
        out[:m] = cable_lengths(self._robot, p_new)
        out[m:m + 3] = p_new
        out[m + 3:m + 6] = (p_new - p) / self._T

    def _add_hand_force(self, t, out):
        m = self._m
        hand_force(self._operator, self._force_into, t, out[m:m + 3], out[m + 3:m + 6],
                   out[2 * m + 6:])


def state_size(m: int) -> int:
    """The simulated world's state: cable lengths (m, m), platform p (3, m) and its velocity
    v (3, m/s), lagged reel speeds (m, m/s), the hand force at this tick (3, N)."""
    return 2 * m + 9


def hand_force(operator, force_into, t, p, v, out):
    """The operator model's force (N) at time t (s) on the pose p (m), v (m/s), into out."""
    if force_into is not None:
        force_into(t, p, v, out)
    else:  # any model with force(t, p, v)
        out[:] = operator.force(t, p, v)


def add_simulated_world(builder, robot, operator, *, initial_position, time_step,
                        time_constant, max_reel_speed):
    """Add the simulated reels and the person to `builder` (systems `simulated_reels`, the
    step of both, and `state`, `split`, `inputs`); returns (reel_velocity_command input port, {output name: port}) with outputs
    cable_lengths, p_WP_true, v_WP_true, hand_force. The state is held by a C++ one-tick
    delay; its start is the scenario's pose at rest and the force at t = 0 there."""
    m = robot.num_cables
    p0 = np.asarray(initial_position, dtype=float)
    x0 = np.concatenate([cable_lengths(robot, p0), p0, np.zeros(3), np.zeros(m), np.zeros(3)])
    step = builder.AddNamedSystem("simulated_reels", ReelStep(
        robot, operator, time_step=time_step, time_constant=time_constant,
        max_reel_speed=max_reel_speed))
    hand_force(operator, getattr(operator, "force_into", None), 0.0, p0, np.zeros(3),
               x0[2 * m + 6:])
    state = builder.AddNamedSystem("state", unit_delay(state_size(m), time_step, x0))
    n = state_size(m)
    pieces = {"cable_lengths": (0, m), "p_WP_true": (m, 3), "v_WP_true": (m + 3, 3),
              "hand_force": (2 * m + 6, 3)}
    # One C++ Selector stacks the command and the state for the step and splits the state.
    route = builder.AddNamedSystem("wiring", wiring(
        [("reel_velocity_command", m), ("state", n)],
        [("inputs", [("reel_velocity_command", 0, m), ("state", 0, n)])]
        + [(name, [("state", offset, count)]) for name, (offset, count) in pieces.items()]))
    builder.Connect(step.GetOutputPort("next_state"), state.get_input_port())
    builder.Connect(state.get_output_port(), route.GetInputPort("state"))
    builder.Connect(route.GetOutputPort("inputs"), step.GetInputPort("inputs"))
    return (route.GetInputPort("reel_velocity_command"),
            {name: route.GetOutputPort(name) for name in pieces})


class SimulatedReelsSystem(Diagram):
    """Reels that integrate their velocity commands to cable lengths at the control rate, and
    the person at the handle (an operator model, see `operators`; default: nobody).

    Each tick: the command is scaled down to the reel speed limit (all reels alike), passed
    through a first-order lag (time constant `time_constant`, s; 0 for ideal drives) and
    integrated over one step. Seven cables over-constrain a translating platform, so the
    integrated lengths are projected back onto the geometry (least-squares forward
    kinematics, then inverse kinematics): the platform settles where the cables agree best, as
    taut elastic cables make it do. The person's force is the model evaluated at the tick's
    time on the platform's true pose, sampled with the pose (so the hand costs no evaluation
    of its own). The true pose is output for analysis only; the controller sees the cable
    lengths and the force, as on the robot. The state is held by a C++ one-tick delay.

    .. pydrake_system::

        name: simulated_reels
        input_ports:
        - reel_velocity_command (m/s, one per cable)
        output_ports:
        - cable_lengths (m, one per cable)
        - p_WP_true (m, base frame)
        - v_WP_true (m/s, base frame)
        - hand_force (N, base frame)
    """

    def __init__(self, robot, *, initial_position, time_step=0.002, time_constant=0.0,
                 max_reel_speed=None, operator=None):
        super().__init__()
        vmax = max_reel_speed if max_reel_speed is not None else robot.limits.max_reel_speed

        def build(builder):
            command, outputs = add_simulated_world(
                builder, robot, NoForce() if operator is None else operator,
                initial_position=initial_position, time_step=time_step,
                time_constant=time_constant, max_reel_speed=vmax)
            builder.ExportInput(command, "reel_velocity_command")
            for name, port in outputs.items():
                builder.ExportOutput(port, name)

        sub_diagram(self, build)


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


def add_measured_force(builder, force, scenario, time_step):
    """Export `force` (the hand force, N) as the plant's `measured_force`, plus the simulated
    sensor's noise when the scenario asks for it (`sensor_noise` summed in `noisy_force`)."""
    if scenario.sensor.noise_std > 0:
        noise = builder.AddNamedSystem("sensor_noise", SensorNoise(
            std=scenario.sensor.noise_std, seed=scenario.random_seed, time_step=time_step))
        noisy = builder.AddNamedSystem("noisy_force", Adder(2, 3))
        builder.Connect(force, noisy.get_input_port(0))
        builder.Connect(noise.GetOutputPort("noise"), noisy.get_input_port(1))
        force = noisy.get_output_port()
    builder.ExportOutput(force, "measured_force")


def add_encoder_offset(builder, lengths, offset):
    """`lengths` (the encoders' output port) plus a constant `offset` (m,) m, the encoders'
    zero after a homing that does not match the plant's geometry; `lengths` itself when
    `offset` is None (no system added: the exact plant stays as it was)."""
    if offset is None:
        return lengths
    m = lengths.size()
    zero = builder.AddNamedSystem("homing_offset", ConstantVectorSource(
        np.asarray(offset, dtype=float).reshape(m)))
    homed = builder.AddNamedSystem("encoders_homed_on_file", Adder(2, m))
    builder.Connect(lengths, homed.get_input_port(0))
    builder.Connect(zero.get_output_port(), homed.get_input_port(1))
    return homed.get_output_port()
