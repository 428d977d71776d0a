"""The dynamic plant `!DynamicReels`: the platform as a rigid body of a MultibodyPlant, hung on
elastic, tension-only cables that reel drives with friction pay out.

Behind the same ports as the other plants (`reel_velocity_command` in; `cable_lengths`,
`measured_force` out). Its ground truth (tensions, slack, true pose) is logged by a logger
inside the plant's sub-diagram (`log_truth`), never exported as ports the controller could
wire to.

Per plant step (1 ms by default) one Python call: `CableNet`, which calls the compiled step
(cables.cable_net_step: drives, cables, generalized force) and the operator model
(operators.operator_forces_at). Everything else is C++: the MultibodyPlant takes the cables'
force through its generalized-force input from a one-step delay (`plant_state`, which also
holds the drives' L0 and speeds), the encoders are a delay sampled at the control tick, and
one Selector (`wiring`) routes the pieces.
"""

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import DiscreteContactApproximation, MultibodyPlant
from pydrake.multibody.tree import (FixedOffsetFrame, PrismaticJoint, RotationalInertia,
                                    SpatialInertia)
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import VectorLogSink

from ..cables import (cable_net_params, cable_net_step, cable_tensions, input_layout,
                      reel_step, state_layout, step_layout)
from ..kernel_call import bind, owned
from ..operators import ForceProfile, NoForce, SpringHand, operator_forces_at
from ..rotation import rotation_from_rpy
from ..tension import unstretched_lengths
from ._leaf import LeafSystem
from ._wiring import unit_delay, wiring
from .simulated_reels import add_measured_force

# The plant's logged ground truth: the keys of the log (docs/LOG_FORMAT.md), in the order the
# plant's logger `log_truth` holds them (each a piece of the cables' step, cables.step_layout).
GROUND_TRUTH = ("tensions", "slack", "p_true", "rpy_true")
_TRUTH_PIECES = {"tensions": "tensions", "slack": "slack", "p_true": "p_WP_true",
                 "rpy_true": "rpy_true"}
TRUTH_LOG = "log_truth"


class CableNet(LeafSystem):
    """The reel drives, the cables and the person at the handle, one plant step per call
    (`cables.cable_net_step`): the drives' next speeds and unstretched lengths L0 (command
    scaled to the reel speed limit, one implicit step with friction), then, on the platform's
    state at the end of the step, the hand force of the operator model (see `operators`),
    each cable's length, stretch rate and tension, and the generalized force they put on the
    platform for its next step. Stateless: the result is held by a C++ delay (`plant_state`)
    whose output the MultibodyPlant reads, so no Python runs inside the platform's own step.

    The MultibodyPlant steps first at each time (its update is an unrestricted one), so this
    block, evaluated with the other discrete updates, reads the platform's state at the end
    of the step. It also gives the force the sensor measures: the operator model at the
    present time on the platform's present state (`measured_force`).

    Platform state: quaternion floating body q = [qw qx qy qz x y z], v = [w_WB_W, v_WBo_W];
    with the rotation locked at R_WB, three prismatic joints q = p, v = p_dot. Its inputs
    arrive stacked by a C++ Selector (one evaluation from Python).

    .. pydrake_system::

        name: cables
        input_ports:
        - inputs ([platform state, plant state (cables.state_layout), reel_velocity_command
          m/s])
        output_ports:
        - step ([next plant state, hand force on the next step (N), measured force (N)]:
          cables.step_layout)
    """

    def __init__(self, robot, operator, *, time_step, max_reel_speed, locked_rotation=None):
        super().__init__()
        m = robot.num_cables
        locked = locked_rotation is not None
        self.nx, self.nv = (6, 3) if locked else (13, 6)
        self.state_layout = state_layout(m, self.nv)
        self.inputs_layout = input_layout(m, self.nx, self.nv)
        self.layout = step_layout(m, self.nv)
        n_in = sum(size for _, size in self.inputs_layout.values())
        n_out = sum(size for _, size in self.layout.values())
        d = robot.dynamics
        reels, attachments = owned(robot.reels), owned(robot.attachments)
        handle = owned(d.handle)
        h = float(time_step)
        params = owned(cable_net_params(d, time_step=h, max_reel_speed=max_reel_speed,
                                        locked=locked))
        # R_WB when locked; else the kernel's scratch for the state's rotation.
        R = owned(np.eye(3) if locked_rotation is None else locked_rotation)
        self._inputs = self.DeclareVectorInputPort("inputs", n_in)
        ip, iv = (0, 3) if locked else (4, 10)
        io, im = self.layout["hand_force"][0], self.layout["measured_force"][0]
        # The shipped models (exactly these classes: a subclass may change the force) are
        # ticked by a compiled kernel; any other model is called from Python.
        if type(operator) in (NoForce, ForceProfile, SpringHand):
            kind, times, rows, params_op = operator.compiled()
            person = (int(kind), owned(times), owned(rows), owned(params_op))
        else:
            person = None
        # Compiled (or loaded) now, not in the first step; called with exactly these types.
        x0 = np.zeros(n_in)
        x0[0] = 1.0
        out0 = np.zeros(n_out)
        net = bind(cable_net_step, reels, attachments, handle, params, R, x0, out0)
        self._kernel = (net, reels, attachments, handle, params, R)
        self._person = person
        self._operator = operator
        self._at = (ip, iv, io, im)
        inputs = self._inputs.Eval

        # A closure over locals, not a method reading self: attribute lookups on a pybind
        # LeafSystem cost ~0.2 us each (scripts/count_instructions.py).
        if person is not None:
            kind, times, rows, params_op = person
            forces_at = bind(operator_forces_at, *person, 0.0, h, x0, ip, iv, out0, im, io)

            def calc_step(context, output):
                x = inputs(context)
                out = output.get_mutable_value()
                t = context.get_time()
                forces_at(kind, times, rows, params_op, t, t + h, x, ip, iv, out, im, io)
                net(reels, attachments, handle, params, R, x, out)
        else:
            def calc_step(context, output):
                x = inputs(context)
                out = output.get_mutable_value()
                t = context.get_time()
                p, v = x[ip:ip + 3].copy(), x[iv:iv + 3].copy()
                out[io:io + 3] = operator.force(t + h, p, v)
                out[im:im + 3] = operator.force(t, p, v)
                net(reels, attachments, handle, params, R, x, out)

        self.DeclareVectorOutputPort(
            "step", n_out, calc_step,
            prerequisites_of_calc={self.time_ticket(), self._inputs.ticket()})

    def initial_state(self, platform_state, L0) -> np.ndarray:
        """The plant state (cables.state_layout) at t = 0: the drives at rest paying out L0
        (m), and the tensions and generalized force on the platform's start state with the
        hand force of the operator at t = 0 (the same kernels, a step of 0 s)."""
        net, reels, attachments, handle, params, R = self._kernel
        ip, iv, io, im = self._at
        x = np.zeros(sum(size for _, size in self.inputs_layout.values()))
        x[:self.nx] = platform_state
        at, _ = self.state_layout["L0"]
        x[self.nx + at:self.nx + at + len(L0)] = L0
        out = np.zeros(sum(size for _, size in self.layout.values()))
        if self._person is not None:
            operator_forces_at(*self._person, 0.0, 0.0, x, ip, iv, out, im, io)
        else:
            out[io:io + 3] = out[im:im + 3] = self._operator.force(
                0.0, x[ip:ip + 3].copy(), x[iv:iv + 3].copy())
        at_rest = params.copy()
        at_rest[2] = 0.0  # h: the drives do not move
        cable_net_step(reels, attachments, handle, at_rest, R.copy(), x, out)
        start, size = self.layout["state"]
        return out[start:start + size].copy()


def build_dynamic_plant(scenario, robot, operator, start_tensions, *, log_truth=True):
    """The `!DynamicReels` plant as a Diagram named `reels`, with the ports in PLANT_PORTS.

    `operator` is the scenario's operator model (operators.py), `start_tensions` (m,) N the
    start tension distribution (scenario.check_dynamic_reels, which also checks the time
    step): the unstretched lengths are set so the platform starts in equilibrium at the
    scenario's initial_position and plant.initial_rpy. `log_truth=False` leaves out the
    ground-truth logger (a plant that runs for hours, as in the emulator, reads
    ground_truth_now instead).
    """
    cfg = scenario.plant
    d = robot.dynamics
    T = scenario.time_step
    h = float(cfg.time_step)
    p0 = np.asarray(scenario.initial_position, dtype=float)
    R0 = rotation_from_rpy(cfg.initial_rpy)
    rho0 = robot.reels - (p0 + robot.attachments @ R0.T)
    lengths0 = np.linalg.norm(rho0, axis=1)
    tensions0 = np.asarray(start_tensions, dtype=float)
    builder = DiagramBuilder()
    mbp = builder.AddNamedSystem("platform_plant", MultibodyPlant(time_step=h))
    # No contact here: TAMSI's step is the cheaper one (68 k instead of 74 k instructions a
    # step, scripts/bench_dynamic_plant.py), the same numbers. The output ports stay sampled
    # (the plant's step an unrestricted update, before the other updates of the same time):
    # the controller and the drives read the platform's state after its step, as they always
    # have (reference logs: tests/data/dynamic_reference/).
    mbp.set_discrete_contact_approximation(DiscreteContactApproximation.kTamsi)
    I = d.inertia
    inertia = SpatialInertia.MakeFromCentralInertia(
        d.mass, np.zeros(3),
        RotationalInertia(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]))
    body = mbp.AddRigidBody("platform", inertia)
    if cfg.lock_rotation:
        # The translation-only limit (the paper's and the kinematic plant's model): three
        # prismatic joints through massless sliders; the joints take the cables' moments.
        parent = mbp.world_frame()
        for axis, name in enumerate("xyz"):
            child = (mbp.AddRigidBody(f"slider_{name}", SpatialInertia.Zero()).body_frame()
                     if name != "z" else mbp.AddFrame(FixedOffsetFrame(
                         "platform_lock", body.body_frame(),
                         RigidTransform(RotationMatrix(R0).inverse()))))
            joint = mbp.AddJoint(PrismaticJoint(f"platform_{name}", parent, child,
                                                np.eye(3)[axis]))
            joint.set_default_translation(p0[axis])
            parent = child
    mbp.Finalize()
    if not cfg.lock_rotation:
        mbp.SetDefaultFloatingBaseBodyPose(body, RigidTransform(RotationMatrix(R0), p0))

    L0 = unstretched_lengths(lengths0, tensions0, d.EA)
    m = robot.num_cables
    vmax = (cfg.max_reel_speed if cfg.max_reel_speed is not None
            else robot.limits.max_reel_speed)
    cables = builder.AddNamedSystem("cables", CableNet(
        robot, operator, time_step=h, max_reel_speed=vmax,
        locked_rotation=R0 if cfg.lock_rotation else None))
    # The plant's state [generalized force, L0, reel speeds] in C++, fed back
    # from the cables' step at the plant's rate; the encoders: L0 sampled at each control
    # tick and held (the controller reads them at its own rate).
    x0 = mbp.GetPositionsAndVelocities(mbp.CreateDefaultContext())
    start = cables.initial_state(x0, L0)
    state = builder.AddNamedSystem("plant_state", unit_delay(start.size, h, start))
    encoders = builder.AddNamedSystem("encoders", unit_delay(m, T, L0))
    # One C++ Selector stacks the cables' inputs and routes the pieces of the plant's state
    # and of the cables' step (one evaluation of the Python step, whoever reads which piece).
    layout, n = cables.state_layout, start.size
    step = cables.layout
    route = builder.AddNamedSystem("wiring", wiring(
        [("platform_state", cables.nx), ("plant_state", n), ("reel_velocity_command", m),
         ("step", sum(size for _, size in step.values()))],
        [("inputs", [("platform_state", 0, cables.nx), ("plant_state", 0, n),
                     ("reel_velocity_command", 0, m)]),
         ("generalized_force", [("plant_state", *layout["generalized_force"])]),
         ("unstretched_lengths", [("plant_state", *layout["L0"])]),
         ("truth", [("step", *step[_TRUTH_PIECES[key]]) for key in GROUND_TRUTH]),
         ("next_state", [("step", *step["state"])]),
         ("measured_force", [("step", *step["measured_force"])])]))
    builder.Connect(mbp.get_state_output_port(), route.GetInputPort("platform_state"))
    builder.Connect(state.get_output_port(), route.GetInputPort("plant_state"))
    builder.Connect(cables.GetOutputPort("step"), route.GetInputPort("step"))
    builder.Connect(route.GetOutputPort("inputs"), cables.GetInputPort("inputs"))
    builder.Connect(route.GetOutputPort("generalized_force"),
                    mbp.get_applied_generalized_force_input_port())
    builder.Connect(route.GetOutputPort("unstretched_lengths"), encoders.get_input_port())
    builder.Connect(route.GetOutputPort("next_state"), state.get_input_port())

    builder.ExportInput(route.GetInputPort("reel_velocity_command"), "reel_velocity_command")
    builder.ExportOutput(encoders.get_output_port(), "cable_lengths")
    add_measured_force(builder, route.GetOutputPort("measured_force"), scenario, T)
    if log_truth:
        source = route.GetOutputPort("truth")
        logger = builder.AddNamedSystem(TRUTH_LOG, VectorLogSink(source.size(), T))
        builder.Connect(source, logger.get_input_port())
    plant = builder.Build()
    plant.set_name("reels")
    # For the overview picture (views/diagram_graph.py): the Selector is drawn as the
    # connections it makes, {output index: the input indices it reads}.
    inputs, outputs = route.wiring_spec
    index = {name: k for k, (name, _) in enumerate(inputs)}
    plant.fused_wiring = {"system": "wiring", "memory": None, "label_edges": True,
                          "reads": {k: sorted({index[src] for src, _, _ in pieces})
                                    for k, (_, pieces) in enumerate(outputs)}}
    return plant


def _plant_of(diagram):
    """The dynamic plant: `diagram` itself or its subsystem `reels`."""
    if not diagram.HasSubsystemNamed("cables") and diagram.HasSubsystemNamed("reels"):
        return diagram.GetSubsystemByName("reels")
    return diagram


def plant_state_now(diagram, context) -> dict:
    """The dynamic plant's state ({piece of cables.state_layout: values}: the generalized
    force on the platform's coming step, the drives' L0 m and speeds m/s) in a diagram
    holding it as `reels` (or the plant itself), `context` the diagram's."""
    plant = _plant_of(diagram)
    cables = plant.GetSubsystemByName("cables")
    state = plant.GetSubsystemByName("plant_state")
    values = state.GetMyContextFromRoot(context).get_discrete_state_vector().value()
    return {name: values[at:at + size].copy()
            for name, (at, size) in cables.state_layout.items()}


def ground_truth_now(diagram, context) -> dict:
    """The dynamic plant's ground truth ({GROUND_TRUTH key: values}) on the state of
    `context` (the diagram's): what the plant's logger would log now."""
    plant = _plant_of(diagram)
    cables = plant.GetSubsystemByName("cables")
    step = cables.GetOutputPort("step").Eval(cables.GetMyContextFromRoot(context))
    return {key: step[at:at + size].copy() for key, (at, size) in
            ((key, cables.layout[_TRUTH_PIECES[key]]) for key in GROUND_TRUTH)}


def _truth_widths(m: int) -> dict:
    return {"tensions": m, "slack": m, "p_true": 3, "rpy_true": 3}


def _plant_logger(diagram):
    """The dynamic plant's ground-truth logger in a diagram holding the plant as `reels`
    (or in the plant itself), else None."""
    plant = diagram
    if diagram.HasSubsystemNamed("reels"):
        plant = diagram.GetSubsystemByName("reels")
    if not hasattr(plant, "HasSubsystemNamed") or not plant.HasSubsystemNamed(TRUTH_LOG):
        return None
    return plant.GetSubsystemByName(TRUTH_LOG)


def _split_truth(rows: np.ndarray) -> dict:
    """{GROUND_TRUTH key: columns} of the logger's rows (T, 2 m + 6)."""
    m = (rows.shape[1] - 6) // 2
    out, k = {}, 0
    for key, width in _truth_widths(m).items():
        out[key] = rows[:, k:k + width]
        k += width
    return out


def ground_truth_log(diagram, context) -> dict:
    """The dynamic plant's logged ground truth ({GROUND_TRUTH key: (T, width)}) from a
    diagram holding it as its subsystem `reels`; {} for the other plants."""
    logger = _plant_logger(diagram)
    if logger is None:
        return {}
    rows = logger.FindLog(context).data().T
    return {key: columns.copy() for key, columns in _split_truth(rows).items()}


def latest_ground_truth(diagram, context) -> dict | None:
    """The last logged row of the dynamic plant's ground truth ({GROUND_TRUTH key: (width,)})
    in a diagram holding it as `reels`; None for the other plants or before the first row."""
    logger = _plant_logger(diagram)
    if logger is None:
        return None
    data = logger.FindLog(context).data()
    if not data.shape[1]:
        return None
    return {key: columns[0].copy() for key, columns in _split_truth(data[:, -1:].T).items()}


__all__ = ["CableNet", "GROUND_TRUTH", "build_dynamic_plant", "cable_tensions",
           "ground_truth_log", "ground_truth_now", "latest_ground_truth", "plant_state_now",
           "reel_step", "unstretched_lengths"]
