"""The dynamic plant `!DynamicReels`: the platform as a rigid body of a MultibodyPlant, hung on
elastic, tension-only cables that reel drives with friction pay out.

Behind the same ports as the other plants (`reel_velocity_command` in; `cable_lengths`,
`measured_force` out). Its ground truth (tensions, slack, true pose) is logged by a logger
inside the plant's sub-diagram (`log_truth`), never exported as ports the controller could
wire to.

Per plant step (1 ms by default) one Python call: `CableNet`, which calls the compiled step
(cables.cable_net_step: cables, generalized force, drives) and the operator model
(operators.operator_force_at). Everything else is C++: the MultibodyPlant takes the cables'
force through its generalized-force input, the drives' state is a one-step delay
(`reel_state`), the encoders a delay sampled at the control tick, and one Selector (`wiring`)
routes the pieces. Every system updates in the same discrete pass, so at each time all read
the platform's state at that time.
"""

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import DiscreteContactApproximation, MultibodyPlant
from pydrake.multibody.tree import (FixedOffsetFrame, PrismaticJoint, RotationalInertia,
                                    SpatialInertia)
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import Adder, ConstantVectorSource, VectorLogSink

from cdpm_drake.kernels.plant.cable_net import (cable_net_params, cable_net_step, cable_tensions, input_layout,
                      reel_step, state_layout, step_layout)
from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.plant.operators import ForceProfile, NoForce, SpringHand, operator_force_at
from cdpm_drake.kernels.rotation import rotation_from_rpy
from cdpm_drake.kernels.tension import unstretched_lengths
from cdpm_drake.kernels.plant.tension_sensor import (DRIVE_TORQUE, LOAD_CELL, sensor_layout,
                                                     sensor_params, tension_sensor_tick)
from cdpm_drake.systems.kernel_system import KernelSystem
from cdpm_drake.systems.wiring import unit_delay, wiring
from cdpm_drake.systems.plants.simulated_reels import add_encoder_offset, add_measured_force

# The plant's logged ground truth: the keys of the log (docs/LOG_FORMAT.md), in the order the
# plant's logger `log_truth` holds them (each a piece of the cables' step, cables.step_layout).
GROUND_TRUTH = ("tensions", "slack", "p_true", "rpy_true")
_TRUTH_PIECES = {"tensions": "tensions", "slack": "slack", "p_true": "p_WP_true",
                 "rpy_true": "rpy_true"}
TRUTH_LOG = "log_truth"


class CableNet(LeafSystem):
    """The cables, the reel drives and the person at the handle, one plant step per call
    (`cables.cable_net_step`): the hand force of the operator model (see `operators`) on the
    platform's true motion, each cable's length, stretch rate and tension, the generalized
    force they put on the platform for this step, and the drives' next state (the command
    scaled to the reel speed limit, one implicit step with friction); also the ground truth
    (tensions, slack, pose) and the force the sensor measures (the hand force). Stateless:
    the drives' state is held by a C++ delay fed back from `step`, the platform's by the
    MultibodyPlant.

    Platform state: quaternion floating body q = [qw qx qy qz x y z], v = [w_WB_W, v_WBo_W];
    with the rotation locked at R_WB, three prismatic joints q = p, v = p_dot. Its inputs
    arrive stacked by a C++ Selector (one evaluation from Python).

    .. pydrake_system::

        name: cables
        input_ports:
        - inputs ([platform state, L0 m, reel speeds m/s, reel_velocity_command m/s])
        output_ports:
        - step ([generalized force (N m, N), next L0 (m), next reel speeds (m/s), tensions
          (N), slack (1 where a cable carries no tension), p_WP_true (m), rpy_true (rad),
          hand force (N), drive force (N)]: cables.step_layout)
    """

    def __init__(self, robot, operator, *, time_step, max_reel_speed, locked_rotation=None,
                 inertia_error=0.0, friction_error=0.0):
        super().__init__()
        m = robot.num_cables
        locked = locked_rotation is not None
        self.nx, self.nv = (6, 3) if locked else (13, 6)
        self.state_layout = state_layout(m)
        self.inputs_layout = input_layout(m, self.nx)
        self.layout = step_layout(m, self.nv)
        n_in = sum(size for _, size in self.inputs_layout.values())
        n_out = sum(size for _, size in self.layout.values())
        d = robot.dynamics
        reels, attachments = owned(robot.reels), owned(robot.attachments)
        handle = owned(d.handle)
        params = owned(cable_net_params(d, time_step=time_step, max_reel_speed=max_reel_speed,
                                        locked=locked, inertia_error=inertia_error,
                                        friction_error=friction_error))
        # R_WB when locked; else the kernel's scratch for the state's rotation.
        R = owned(np.eye(3) if locked_rotation is None else locked_rotation)
        self._inputs = self.DeclareVectorInputPort("inputs", n_in)
        ip, iv = (0, 3) if locked else (4, 10)
        io = self.layout["hand_force"][0]
        # Compiled (or loaded) now, not in the first step; called with exactly these types.
        x0 = np.zeros(n_in)
        x0[0] = 1.0
        out0 = np.zeros(n_out)
        net = bind(cable_net_step, reels, attachments, handle, params, R, x0, out0)
        inputs = self._inputs.Eval

        # A closure over locals, not a method reading self: attribute lookups on a pybind
        # LeafSystem cost ~0.2 us each (scripts/bench/count_instructions.py).
        # The shipped models (exactly these classes: a subclass may change the force) are
        # ticked by a compiled kernel; any other model is called from Python.
        if type(operator) in (NoForce, ForceProfile, SpringHand):
            kind, times, rows, params_op = operator.compiled()
            kind, times, rows, params_op = int(kind), owned(times), owned(rows), owned(params_op)
            force_at = bind(operator_force_at, kind, times, rows, params_op, 0.0, x0, ip, iv,
                            out0, io)

            def calc_step(context, output):
                x = inputs(context)
                out = output.get_mutable_value()
                force_at(kind, times, rows, params_op, context.get_time(), x, ip, iv, out, io)
                net(reels, attachments, handle, params, R, x, out)
        else:
            def calc_step(context, output):
                x = inputs(context)
                out = output.get_mutable_value()
                out[io:io + 3] = operator.force(context.get_time(), x[ip:ip + 3].copy(),
                                                x[iv:iv + 3].copy())
                net(reels, attachments, handle, params, R, x, out)

        self.DeclareVectorOutputPort(
            "step", n_out, calc_step,
            prerequisites_of_calc={self.time_ticket(), self._inputs.ticket()})


def build_dynamic_plant(scenario, robot, operator, start_tensions, *, log_truth=True,
                        homing_offset=None):
    """The `!DynamicReels` plant as a Diagram named `reels`, with the ports in PLANT_PORTS.

    `operator` is the scenario's operator model (operators.py), `start_tensions` (m,) N the
    start tension distribution (scenario.check_dynamic_reels, which also checks the time
    step): the unstretched lengths are set so the platform starts in equilibrium at the
    scenario's initial_position and plant.initial_rpy. `log_truth=False` leaves out the
    ground-truth logger (a plant that runs for hours, as in the emulator, reads
    ground_truth_now instead). `homing_offset` (m,) m is added to every encoder reading (a
    homing on another robot's geometry: ResolvedScenario.homing_offset).
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
    # No contact here: TAMSI's step is the cheaper one, the same numbers. Output ports read
    # live from the state: the plant's step is a discrete update like every other, so at each
    # time the drives, the encoders, the sensor and the loggers all see the platform's state
    # at that time (sampled ports would make the plant an unrestricted update that runs
    # first: the controller would then measure the hand on the platform of one plant step
    # later than the one it logs).
    mbp.set_discrete_contact_approximation(DiscreteContactApproximation.kTamsi)
    mbp.SetUseSampledOutputPorts(False)
    I = d.inertia
    inertia = SpatialInertia.MakeFromCentralInertia(
        d.mass, np.asarray(d.com, dtype=float),
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
    sensor = cfg.tension_sensor
    if sensor not in ("drive_torque", "load_cell", "none"):
        raise ValueError(f"plant.tension_sensor must be drive_torque, load_cell or none, got "
                         f"{sensor!r}")
    drive = cfg.drive_torque
    cables = builder.AddNamedSystem("cables", CableNet(
        robot, operator, time_step=h, max_reel_speed=vmax,
        locked_rotation=R0 if cfg.lock_rotation else None,
        inertia_error=float(drive.inertia_error), friction_error=float(drive.friction_error)))
    # The drives' state [L0, reel speeds] in C++, fed back from the cables' step at the
    # plant's rate; the encoders: L0 plus their zero's offset (encoder_offset), sampled at
    # each control tick and held (the controller reads them at its own rate).
    drives = builder.AddNamedSystem("reel_state", unit_delay(
        2 * m, h, np.concatenate([L0, np.zeros(m)])))
    offset = encoder_offset(cfg, lengths0, L0)
    encoders = builder.AddNamedSystem("encoders", unit_delay(m, T, L0 + offset))
    # One C++ Selector stacks the cables' inputs and routes the pieces of the drives' state
    # and of the cables' step (one evaluation of the Python step per plant step, whoever reads
    # which piece).
    step = cables.layout
    # The tension sensor (none: a constant NaN): a compiled tick on the drives' force and
    # speeds or the true tensions, its state held by a delay sampled at the control tick as
    # the encoders are.
    sensing = sensor != "none"
    sensed = sensor_layout(m)
    n_sensed = sum(size for _, size in sensed.values())
    speeds_at = step["next_reels"][0] + m
    route = builder.AddNamedSystem("wiring", wiring(
        [("platform_state", cables.nx), ("reels", 2 * m), ("reel_velocity_command", m),
         ("step", sum(size for _, size in step.values()))]
        + ([("sensor_state", n_sensed)] if sensing else []),
        [("inputs", [("platform_state", 0, cables.nx), ("reels", 0, 2 * m),
                     ("reel_velocity_command", 0, m)]),
         ("generalized_force", [("step", *step["generalized_force"])]),
         ("next_reels", [("step", *step["next_reels"])]),
         ("unstretched_lengths", [("reels", *cables.state_layout["L0"])]),
         ("measured_force", [("step", *step["hand_force"])]),
         ("truth", [("step", *step[_TRUTH_PIECES[key]]) for key in GROUND_TRUTH])]
        + ([("sensor_inputs", [("step", *step["drive_force"]), ("step", speeds_at, m),
                               ("step", *step["tensions"]), ("sensor_state", 0, n_sensed)]),
            ("tension_measured", [("sensor_state", *sensed["tension_measured"])])]
           if sensing else [])))
    builder.Connect(mbp.get_state_output_port(), route.GetInputPort("platform_state"))
    builder.Connect(drives.get_output_port(), route.GetInputPort("reels"))
    builder.Connect(cables.GetOutputPort("step"), route.GetInputPort("step"))
    builder.Connect(route.GetOutputPort("inputs"), cables.GetInputPort("inputs"))
    builder.Connect(route.GetOutputPort("generalized_force"),
                    mbp.get_applied_generalized_force_input_port())
    builder.Connect(route.GetOutputPort("next_reels"), drives.get_input_port())
    if offset.any():
        zero = builder.AddNamedSystem("encoder_offset", ConstantVectorSource(offset))
        homed = builder.AddNamedSystem("encoders_homed", Adder(2, m))
        builder.Connect(route.GetOutputPort("unstretched_lengths"), homed.get_input_port(0))
        builder.Connect(zero.get_output_port(), homed.get_input_port(1))
        builder.Connect(homed.get_output_port(), encoders.get_input_port())
    else:
        builder.Connect(route.GetOutputPort("unstretched_lengths"), encoders.get_input_port())

    builder.ExportInput(route.GetInputPort("reel_velocity_command"), "reel_velocity_command")
    builder.ExportOutput(add_encoder_offset(builder, encoders.get_output_port(),
                                            homing_offset), "cable_lengths")
    add_measured_force(builder, route.GetOutputPort("measured_force"), scenario, T)
    # After measured_force: the plants' ports in one order (the real reels' too).
    if sensing:
        system, start = tension_sensor(scenario, robot, tensions0)
        tick = builder.AddNamedSystem("tension_sensor", system)
        held = builder.AddNamedSystem("tension_sensor_state", unit_delay(n_sensed, T, start))
        builder.Connect(route.GetOutputPort("sensor_inputs"), tick.get_input_port())
        builder.Connect(tick.get_output_port(), held.get_input_port())
        builder.Connect(held.get_output_port(), route.GetInputPort("sensor_state"))
        builder.ExportOutput(route.GetOutputPort("tension_measured"), "tension_measured")
    else:
        nan = builder.AddNamedSystem("tension_sensor", ConstantVectorSource(np.full(m, np.nan)))
        builder.ExportOutput(nan.get_output_port(), "tension_measured")
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


def encoder_offset(cfg, rigid0, L0) -> np.ndarray:
    """What the dynamic plant's encoders add to each reel's payout of unstretched cable, m:
    by cfg.encoder_zero (DynamicReels), homed: each cable's stretch at the start, rigid0 - L0
    (its rigid length at the start pose less its unstretched length: the encoders read the
    rigid lengths there, as a robot's after its homing); unstretched: 0."""
    if cfg.encoder_zero == "homed":
        return np.asarray(rigid0, dtype=float) - np.asarray(L0, dtype=float)
    return np.zeros(len(L0))


def tension_sensor(scenario, robot, tensions0):
    """The dynamic plant's tension sensor tick (a KernelSystem over
    tension_sensor.tension_sensor_tick) and its start state, for the scenario's
    plant.tension_sensor (drive_torque or load_cell), at start tensions (m,) N."""
    m = robot.num_cables
    params, bias, start = sensor_kernel(scenario, robot, tensions0,
                                        scenario.plant.tension_sensor)
    n = start.size
    params, bias = owned(params), owned(bias)
    kernel = bind(tension_sensor_tick, params, bias, np.zeros(3 * m + n),
                  np.empty(n))
    return KernelSystem(3 * m + n, n, kernel, (params, bias)), start


def sensor_kernel(scenario, robot, tensions0, kind: str):
    """tension_sensor_tick's (params, bias (m,) N, start state) for a `kind` of sensor
    (drive_torque or load_cell) with the scenario's plant settings (plant.drive_torque or
    plant.load_cell, random_seed), at start tensions (m,) N: what the dynamic plant's sensor
    runs, and what the emulator's dynamic bridge reports through (emulator/bridges.py)."""
    cfg = scenario.plant
    m = robot.num_cables
    T = scenario.time_step
    d = robot.dynamics
    seed = int(scenario.random_seed)
    if kind == "drive_torque":
        s = cfg.drive_torque
        params = sensor_params(DRIVE_TORQUE, time_step=T, seed=seed, noise_std=s.noise_std,
                               quantum=s.quantum, time_constant=s.filter_time_constant,
                               inertia=d.reel_inertia, viscous=d.viscous_friction,
                               coulomb=d.coulomb_friction, band=s.friction_band)
        bias = np.zeros(m)
        filtered = -np.asarray(tensions0, dtype=float)  # a drive holding a taut cable pulls in
    else:
        s = cfg.load_cell
        params = sensor_params(LOAD_CELL, time_step=T, seed=seed, noise_std=s.noise_std,
                               time_constant=1.0 / (2.0 * np.pi * s.bandwidth))
        # Each cell's offset, drawn once per run from the scenario's seed (not the noise's
        # stream: a stream of its own).
        bias = s.bias_std * np.random.default_rng([seed, 31]).standard_normal(m)
        filtered = np.asarray(tensions0, dtype=float)
    # The first reading (logged at t = 0): the start tensions as the sensor reads them.
    start = np.concatenate([np.asarray(tensions0, dtype=float) + bias, filtered, np.zeros(m),
                            [0.0]])
    return params, bias, start


def _plant_of(diagram):
    """The dynamic plant: `diagram` itself or its subsystem `reels`."""
    if not diagram.HasSubsystemNamed("cables") and diagram.HasSubsystemNamed("reels"):
        return diagram.GetSubsystemByName("reels")
    return diagram


def plant_state_now(diagram, context) -> dict:
    """The dynamic plant's drives now ({piece of cables.state_layout: values}: L0 m and the
    reel speeds m/s) in a diagram holding it as `reels` (or the plant itself), `context` the
    diagram's."""
    plant = _plant_of(diagram)
    cables = plant.GetSubsystemByName("cables")
    state = plant.GetSubsystemByName("reel_state")
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


def add_pose_truth_log(builder, p_true, time_step) -> None:
    """Log a translating plant's true position (the kinematic plant's, when it plays another
    robot than the controller's) in the ground-truth logger the dynamic plant has: its rows
    read back as p_true and a level rpy_true."""
    logger = builder.AddNamedSystem(TRUTH_LOG, VectorLogSink(3, time_step))
    builder.Connect(p_true, logger.get_input_port())


def _split_truth(rows: np.ndarray) -> dict:
    """{GROUND_TRUTH key: columns} of the logger's rows (T, 2 m + 6); a translating plant's
    (T, 3) rows are its position alone (add_pose_truth_log)."""
    if rows.shape[1] == 3:
        return {"p_true": rows, "rpy_true": np.zeros_like(rows)}
    m = (rows.shape[1] - 6) // 2
    out, k = {}, 0
    for key, width in _truth_widths(m).items():
        out[key] = rows[:, k:k + width]
        k += width
    return out


def reserve_ground_truth(diagram, context, ticks: int) -> None:
    """Make room in the plant's ground-truth logger for `ticks` rows (no-op without one)."""
    logger = _plant_logger(diagram)
    if logger is not None:
        logger.FindMutableLog(context).Reserve(int(ticks))


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
           "encoder_offset", "ground_truth_log", "ground_truth_now", "latest_ground_truth",
           "plant_state_now", "reel_step", "reserve_ground_truth", "unstretched_lengths"]
