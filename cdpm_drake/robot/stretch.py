"""How far a robot's measured cable lengths may miss its rigid model: the bound of the forward
kinematics' residual that a plant with elastic cables (the robot, the reel bridge, CANopen
drives) takes by default."""

import itertools

import numpy as np

# The lengths' misfit to the robot file beyond the cables' stretch: the encoders' zero and the
# geometry's errors, m (the reel plants' former fixed default).
LENGTH_TOLERANCE = 0.005
# The tension the stretch allowance is taken at where no controller names one, N: the
# controller's default tension ceiling (config's Controller.max_tension).
EXPECTED_TENSION = 100.0


def longest_cable(robot) -> float:
    """The longest cable (m) over the workspace box, level platform: a cable's length
    |a_i - p - b_i| is convex in p, so it is at a corner of the box."""
    corners = np.array(list(itertools.product(*zip(robot.workspace.lower,
                                                    robot.workspace.upper))))
    return max(float(np.linalg.norm(robot.reels - (c + robot.attachments), axis=1).max())
               for c in corners)


def derived_length_residual(robot, max_tension: float = EXPECTED_TENSION) -> float:
    """The default bound (m) of the forward kinematics' residual on the measured lengths:
    LENGTH_TOLERANCE plus the stretch max_tension (N) gives the longest cable anywhere in the
    workspace box, max_tension L_max / EA (EA N: the robot file's cables), which the
    translating, inextensible model sees as misfit."""
    return LENGTH_TOLERANCE + float(max_tension) * longest_cable(robot) / float(robot.dynamics.EA)
