"""The forward-kinematics block of Fig. 5: cable lengths back to the platform position."""

import numpy as np
from pydrake.systems.framework import Diagram

from cdpm_drake.kernels.call import bind, owned
from cdpm_drake.kernels.kinematics import forward_kinematics, gauss_newton_warm_stacked
from cdpm_drake.systems.kernel_system import KernelSystem
from cdpm_drake.systems.wiring import stack, sub_diagram, unit_delay


class ForwardKinematicsSolve(KernelSystem):
    """p from the lengths, warm-started at the previous estimate; stateless. Its inputs
    arrive stacked by a C++ Selector (one evaluation from Python, not two).

    .. pydrake_system::

        name: solve
        input_ports:
        - inputs ([cable_lengths m (one per cable), p_WP_previous m (base frame)])
        output_ports:
        - p_WP (m, base frame)
    """

    def __init__(self, robot, *, max_residual):
        m = robot.num_cables
        offsets = owned(robot.attachments - robot.reels)
        residual = float(max_residual)
        # Compiled (or loaded) now, not in the first tick.
        solve = bind(gauss_newton_warm_stacked, offsets, np.ones(m + 3), 1e-10, residual, 8,
                     np.empty(3))

        def failed(status, x, out):
            # Plain Gauss-Newton from a tick away converges in two or three steps; where it
            # does not, the damped solver (and every error message) of
            # kinematics.forward_kinematics.
            out[:] = forward_kinematics(robot, x[:m], p_guess=x[m:], max_residual=residual)

        super().__init__(m + 3, 3, solve, (offsets,), (1e-10, residual, 8), ok=True,
                         failed=failed, output_name="p_WP")


class ForwardKinematicsEstimator(Diagram):
    """p from the measured cable lengths, warm-started from the previous estimate (held by a
    C++ one-tick delay), so one or two Gauss-Newton steps suffice at 500 Hz.

    Lengths that no platform position explains within `max_residual` (m) raise
    KinematicsError: on the robot that is a fault (slack or broken cable, bad encoder).

    .. pydrake_system::

        name: forward_kinematics
        input_ports:
        - cable_lengths (m, one per cable)
        output_ports:
        - p_WP (m, base frame)
    """

    def __init__(self, robot, *, initial_position, max_residual=1e-6, time_step=0.002):
        super().__init__()
        sub_diagram(self, lambda builder: build_forward_kinematics(
            builder, robot, initial_position=initial_position, max_residual=max_residual,
            time_step=time_step))


# The system a flat build (FlatBlock) names after the block.
FORWARD_KINEMATICS_MAIN = "solve"


def build_forward_kinematics(builder, robot, *, initial_position, max_residual=1e-6,
                             time_step=0.002):
    """ForwardKinematicsEstimator's systems and exported ports, into `builder` (a
    DiagramBuilder or a FlatBlock)."""
    solve = builder.AddNamedSystem("solve", ForwardKinematicsSolve(
        robot, max_residual=max_residual))
    previous = builder.AddNamedSystem("previous", unit_delay(
        3, time_step, np.asarray(initial_position, dtype=float)))
    inputs = builder.AddNamedSystem("inputs", stack([robot.num_cables, 3]))
    builder.Connect(solve.GetOutputPort("p_WP"), previous.get_input_port())
    builder.Connect(previous.get_output_port(), inputs.get_input_port(1))
    builder.Connect(inputs.get_output_port(), solve.GetInputPort("inputs"))
    builder.ExportInput(inputs.get_input_port(0), "cable_lengths")
    builder.ExportOutput(solve.GetOutputPort("p_WP"), "p_WP")
