"""The dynamic plant `!DynamicReels`: the platform as a rigid body of a MultibodyPlant, hung on
elastic, tension-only cables that reel drives with friction pay out.

Behind the same ports as the other plants (`reel_velocity_command` in; `cable_lengths`,
`measured_force` out). Its ground truth (tensions, slack, true pose) is logged by loggers
inside the plant's sub-diagram, never exported as ports the controller could wire to.
"""

import math

import numpy as np
from pydrake.common.value import Value
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce, MultibodyPlant
from pydrake.multibody.tree import (FixedOffsetFrame, PrismaticJoint, RotationalInertia,
                                    SpatialInertia)
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import VectorLogSink

from ..rotation import rotation_from_rpy, rpy_from_rotation
from ..tension import unstretched_lengths
from ._tick_cache import declare_tick_cache
from .simulated_reels import add_measured_force

# The plant's logged ground truth: (log key, system, output port), collected by name.
GROUND_TRUTH = (
    ("tensions", "cables", "tensions"),
    ("slack", "cables", "slack"),
    ("p_true", "cables", "p_WP_true"),
    ("rpy_true", "cables", "rpy_true"),
)


class SimulatedOperator(LeafSystem):
    """The person at the handle: an operator model (see `operators`) evaluated on the
    platform's true motion. Part of the dynamic plant, never of the controller (the kinematic
    plant samples the person inside its own step).

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


def reel_step(w, u, h, *, bandwidth, inertia, viscous, coulomb):
    """One implicit step (h s) of the reel drives: inertia dw/dt = K (u - w) - b w - F_c sgn w,
    K = bandwidth * inertia. Velocities w, u in m/s of cable, b N s/m, F_c N. Viscous terms
    are implicit, so any bandwidth is stable; Coulomb friction is the implicit set-valued
    law: a reel whose drive force cannot overcome F_c within the step stops (sticks)."""
    K = bandwidth * inertia
    denominator = inertia + h * (K + viscous)
    free = (inertia * w + h * K * u) / denominator
    grip = h * coulomb / denominator
    return np.where(np.abs(free) <= grip, 0.0, free - np.sign(free) * grip)


def cable_tensions(L, L_dot_stretch, L0, EA, damping):
    """Tension-only spring-dampers (N): T_i = max(0, k_i (L_i - L0_i) + c dL_i), k_i = EA/L0_i,
    zero while slack (L_i <= L0_i). dL is the stretch rate d(L - L0)/dt, m/s: the rate the
    cable material sees (the issue's L_dot when the reels stand still)."""
    stretch = L - L0
    T = EA / L0 * stretch + damping * L_dot_stretch
    return np.where(stretch > 0.0, np.maximum(T, 0.0), 0.0)


class ReelDrives(LeafSystem):
    """Reel drives tracking the commanded cable velocity through a first-order velocity loop
    with viscous and Coulomb friction (`reel_step`), paying out the unstretched lengths L0.

    The command is first scaled to the reel speed limit (all reels alike, as the other plants
    do).

    .. pydrake_system::

        name: reel_drives
        input_ports:
        - reel_velocity_command (m/s, one per cable)
        output_ports:
        - unstretched_lengths (m: L0)
        - reel_speeds (m/s)
    """

    def __init__(self, *, initial_lengths, dynamics, time_step, max_reel_speed):
        super().__init__()
        L0 = np.asarray(initial_lengths, dtype=float)
        m = L0.size
        self._h = float(time_step)
        self._vmax = float(max_reel_speed)
        d = dynamics
        self._params = dict(bandwidth=d.bandwidth, inertia=d.reel_inertia,
                            viscous=d.viscous_friction, coulomb=d.coulomb_friction)
        self._command = self.DeclareVectorInputPort("reel_velocity_command", m)
        self._L0 = self.DeclareDiscreteState(L0)
        self._speed = self.DeclareDiscreteState(m)
        self.DeclareStateOutputPort("unstretched_lengths", self._L0)
        self.DeclareStateOutputPort("reel_speeds", self._speed)
        self.DeclarePeriodicDiscreteUpdateEvent(self._h, 0.0, self._update_reels)

    def _update_reels(self, context, discrete_state):
        u = self._command.Eval(context)
        peak = float(np.max(np.abs(u))) if u.size else 0.0
        if peak > self._vmax:
            u = u * (self._vmax / peak)
        w = reel_step(context.get_discrete_state(self._speed).get_value(), u, self._h,
                      **self._params)
        L0 = context.get_discrete_state(self._L0).get_value() + self._h * w
        discrete_state.get_mutable_vector(self._L0).SetFromVector(L0)
        discrete_state.get_mutable_vector(self._speed).SetFromVector(w)


class Encoders(LeafSystem):
    """The reel encoders, read once per control tick: L0 at the tick, held until the next
    (the controller reads them at its own rate, and its blocks are not re-evaluated at the
    plant's finer steps).

    .. pydrake_system::

        name: encoders
        input_ports:
        - unstretched_lengths (m)
        output_ports:
        - cable_lengths (m)
    """

    def __init__(self, initial_lengths, period):
        super().__init__()
        L0 = np.asarray(initial_lengths, dtype=float)
        self._input = self.DeclareVectorInputPort("unstretched_lengths", L0.size)
        self._held = self.DeclareDiscreteState(L0)
        self.DeclareStateOutputPort("cable_lengths", self._held)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update_held)

    def _update_held(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._held).SetFromVector(self._input.Eval(context))


class CableForces(LeafSystem):
    """The cables' tensions and the hand force, as one spatial force on the platform.

    Reads the platform's state (quaternion floating body: q = [qw qx qy qz x y z], v =
    [w_WB_W, v_WBo_W]; with `locked_rotation` R_WB, three prismatic joints: q = p, v = p_dot),
    computes each cable's length L_i = |a_i - (p + R b_i)| and stretch
    rate, its tension (`cable_tensions`), and applies sum T_i u_i + F_hand at the centre with
    the moment sum (R b_i) x T_i u_i + (R h) x F_hand (h the handle point). Also the true
    pose and velocity for the simulated operator and the loggers.

    .. pydrake_system::

        name: cables
        input_ports:
        - platform_state (q, v of the platform body)
        - unstretched_lengths (m)
        - reel_speeds (m/s)
        - hand_force (N, base frame)
        output_ports:
        - spatial_forces (on the platform, about its centre, base frame)
        - tensions (N, one per cable)
        - slack (1 where a cable carries no tension)
        - p_WP_true (m, base frame)
        - v_WP_true (m/s, base frame)
        - rpy_true (rad: roll, pitch, yaw of the platform)
    """

    def __init__(self, robot, *, body_index, locked_rotation=None):
        super().__init__()
        m = robot.num_cables
        self._locked = None if locked_rotation is None else np.asarray(locked_rotation, float)
        # Where p and v sit in the state.
        self._ip, self._iv = (slice(4, 7), slice(10, 13)) if self._locked is None else (
            slice(0, 3), slice(3, 6))
        self._a = robot.reels.copy()
        self._b = robot.attachments.copy()
        d = robot.dynamics
        self._EA, self._c = float(d.EA), float(d.damping)
        self._handle = np.asarray(d.handle, dtype=float)
        self._body = body_index
        self._state = self.DeclareVectorInputPort("platform_state",
                                                  13 if self._locked is None else 6)
        self._L0 = self.DeclareVectorInputPort("unstretched_lengths", m)
        self._speed = self.DeclareVectorInputPort("reel_speeds", m)
        self._hand = self.DeclareVectorInputPort("hand_force", 3)
        pose_deps = {self._state.ticket()}
        cable_deps = {self._state.ticket(), self._L0.ticket(), self._speed.ticket()}
        # One evaluation per plant step, shared by the force and the logged outputs.
        self._cache = declare_tick_cache(self, "cables", self._compute_cables, cable_deps)
        self.DeclareAbstractOutputPort(
            "spatial_forces", lambda: Value[list[ExternallyAppliedSpatialForce]](),
            self._calc_spatial_forces, prerequisites_of_calc=cable_deps | {self._hand.ticket()})
        self.DeclareVectorOutputPort("tensions", m, self._calc_tensions,
                                     prerequisites_of_calc=cable_deps)
        self.DeclareVectorOutputPort("slack", m, self._calc_slack,
                                     prerequisites_of_calc=cable_deps)
        self.DeclareVectorOutputPort(
            "p_WP_true", 3, lambda c, o: o.SetFromVector(self._state.Eval(c)[self._ip]),
            prerequisites_of_calc=pose_deps)
        self.DeclareVectorOutputPort(
            "v_WP_true", 3, lambda c, o: o.SetFromVector(self._state.Eval(c)[self._iv]),
            prerequisites_of_calc=pose_deps)
        self.DeclareVectorOutputPort(
            "rpy_true", 3,
            lambda c, o: o.SetFromVector(rpy_from_rotation(self._rotation_of(self._state.Eval(c)))),
            prerequisites_of_calc=pose_deps)

    def _rotation_of(self, x):
        return _rotation(x) if self._locked is None else self._locked

    def _cables(self, context):
        return self._cache.Eval(context)

    def _compute_cables(self, context):
        """Tensions T (m,), unit vectors u (m, 3) attachment -> reel, R b (m, 3) and R."""
        x = self._state.Eval(context)
        R = self._rotation_of(x)
        p, v = x[self._ip], x[self._iv]
        w = x[7:10] if self._locked is None else np.zeros(3)
        Rb = self._b @ R.T
        rho = self._a - (p + Rb)
        L = np.sqrt(np.einsum("ij,ij->i", rho, rho))
        u = rho / L[:, None]
        wx, wy, wz = (float(c) for c in w)
        # v_B = v + w x (R b), the cross product as a matrix product over all cables.
        v_B = v + Rb @ np.array([[0.0, wz, -wy], [-wz, 0.0, wx], [wy, -wx, 0.0]])
        L_dot = -np.einsum("ij,ij->i", u, v_B)
        T = cable_tensions(L, L_dot - self._speed.Eval(context), self._L0.Eval(context),
                           self._EA, self._c)
        return T, u, Rb, R

    def _calc_tensions(self, context, output):
        output.SetFromVector(self._cables(context)[0])

    def _calc_slack(self, context, output):
        output.SetFromVector((self._cables(context)[0] <= 0.0).astype(float))

    def _calc_spatial_forces(self, context, output):
        T, u, Rb, R = self._cables(context)
        F_hand = self._hand.Eval(context)
        Tu = T[:, None] * u
        f = Tu.sum(axis=0) + F_hand
        # sum_i (R b_i) x (T_i u_i) + (R h) x F_hand, as sums of products of columns.
        r, g = Rb.T, Tu.T
        tau = np.array([r[1] @ g[2] - r[2] @ g[1], r[2] @ g[0] - r[0] @ g[2],
                        r[0] @ g[1] - r[1] @ g[0]]) + np.cross(R @ self._handle, F_hand)
        force = ExternallyAppliedSpatialForce()
        force.body_index = self._body
        force.p_BoBq_B = np.zeros(3)
        force.F_Bq_W = SpatialForce(tau=tau, f=f)
        output.set_value([force])


def _rotation(x) -> np.ndarray:
    """R_WB from a floating body's state (unit quaternion qw, qx, qy, qz first)."""
    w, x_, y, z = x[0:4] / math.sqrt(float(x[0:4] @ x[0:4]))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x_ * y - z * w), 2 * (x_ * z + y * w)],
        [2 * (x_ * y + z * w), 1 - 2 * (x_ * x_ + z * z), 2 * (y * z - x_ * w)],
        [2 * (x_ * z - y * w), 2 * (y * z + x_ * w), 1 - 2 * (x_ * x_ + y * y)]])


def build_dynamic_plant(scenario, robot, operator, start_tensions):
    """The `!DynamicReels` plant as a Diagram named `reels`, with the ports in PLANT_PORTS.

    `operator` is the scenario's operator model (operators.py), `start_tensions` (m,) N the
    start tension distribution (scenario.check_dynamic_reels, which also checks the time
    step): the unstretched lengths are set so the platform starts in equilibrium at the
    scenario's initial_position and plant.initial_rpy.
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
    drives = builder.AddNamedSystem("reel_drives", ReelDrives(
        initial_lengths=L0, dynamics=d, time_step=h,
        max_reel_speed=cfg.max_reel_speed if cfg.max_reel_speed is not None
        else robot.limits.max_reel_speed))
    encoders = builder.AddNamedSystem("encoders", Encoders(L0, T))
    builder.Connect(drives.GetOutputPort("unstretched_lengths"),
                    encoders.GetInputPort("unstretched_lengths"))
    cables = builder.AddNamedSystem("cables", CableForces(
        robot, body_index=body.index(), locked_rotation=R0 if cfg.lock_rotation else None))
    builder.Connect(mbp.get_state_output_port(), cables.GetInputPort("platform_state"))
    builder.Connect(drives.GetOutputPort("unstretched_lengths"),
                    cables.GetInputPort("unstretched_lengths"))
    builder.Connect(drives.GetOutputPort("reel_speeds"), cables.GetInputPort("reel_speeds"))
    builder.Connect(cables.GetOutputPort("spatial_forces"),
                    mbp.get_applied_spatial_force_input_port())

    person = builder.AddNamedSystem("operator", SimulatedOperator(operator))
    builder.Connect(cables.GetOutputPort("p_WP_true"), person.GetInputPort("p_WP_true"))
    builder.Connect(cables.GetOutputPort("v_WP_true"), person.GetInputPort("v_WP_true"))
    builder.Connect(person.GetOutputPort("hand_force"), cables.GetInputPort("hand_force"))

    builder.ExportInput(drives.GetInputPort("reel_velocity_command"), "reel_velocity_command")
    builder.ExportOutput(encoders.GetOutputPort("cable_lengths"), "cable_lengths")
    force = person.GetOutputPort("hand_force")
    add_measured_force(builder, force, scenario, T)
    for key, system, port in GROUND_TRUTH:
        source = builder.GetSubsystemByName(system).GetOutputPort(port)
        logger = builder.AddNamedSystem(f"log_{key}", VectorLogSink(source.size(), T))
        builder.Connect(source, logger.get_input_port())
    plant = builder.Build()
    plant.set_name("reels")
    return plant


def ground_truth_log(diagram, context) -> dict:
    """The dynamic plant's logged ground truth ({GROUND_TRUTH key: (T, width)}) from a
    diagram holding it as its subsystem `reels`; {} for the other plants."""
    if not diagram.HasSubsystemNamed("reels"):
        return {}
    plant = diagram.GetSubsystemByName("reels")
    if not hasattr(plant, "HasSubsystemNamed"):
        return {}
    out = {}
    for key, _, _ in GROUND_TRUTH:
        if plant.HasSubsystemNamed(f"log_{key}"):
            out[key] = plant.GetSubsystemByName(f"log_{key}").FindLog(context).data().T.copy()
    return out


__all__ = ["CableForces", "Encoders", "GROUND_TRUTH", "ReelDrives", "SimulatedOperator",
           "build_dynamic_plant",
           "cable_tensions", "ground_truth_log", "reel_step",
           "unstretched_lengths"]
