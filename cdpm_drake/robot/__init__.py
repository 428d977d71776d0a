"""Robot descriptions: reels, platform attachment points, workspace box, limits.

Plain numpy; no Drake import here except for the YAML loader, which is imported lazily so the
math stays testable alone. All positions are in metres. The base frame is the paper's frame A
(reels), the platform frame is frame B with its origin at the platform centre; the platform
only translates, so B is parallel to A.

Cables are numbered 1..m in everything a user sees (files, messages); arrays are 0-based.

    model.py           the validated Robot, its Workspace, RobotLimits and Dynamics
    schema.py          the robot file's YAML schema (RobotSchema and its sections)
    file.py            robot files by name or path: load_robot and the raw-field checks
    statics_checks.py  what the cables can hold, said on load
    statics.py         t*, the holding tension and wrench feasibility over the workspace
    tension_program.py t* and tension distributions of any nullspace (Drake's Clarabel)

The names below are the package's API for the other layers. Everything here logs to the
logger "cdpm_drake.robot".
"""

from cdpm_drake.data import ROBOTS_DIR
from cdpm_drake.robot.file import (is_path_like, load_robot, resolve_named_yaml,
                                   resolve_robot_path, robot_from_schema, robot_names)
from cdpm_drake.robot.model import Dynamics, Robot, RobotError, RobotLimits, Workspace
from cdpm_drake.robot.schema import (CablesSchema, LimitsSchema, PlatformSchema,
                                     ReelDrivesSchema, RobotSchema, WorkspaceSchema)
from cdpm_drake.robot.statics_checks import (STATICS_FLOOR, STATICS_GRID, STATICS_WARN_SHARE,
                                             describe_wrench, frame_warnings, robot_statics,
                                             statics_warnings)

__all__ = [
    # The model (model.py).
    "Robot", "Workspace", "RobotLimits", "Dynamics", "RobotError",
    # The file (schema.py, file.py); ROBOTS_DIR holds the shipped robots.
    "RobotSchema", "WorkspaceSchema", "LimitsSchema", "PlatformSchema", "CablesSchema",
    "ReelDrivesSchema", "ROBOTS_DIR", "robot_names", "is_path_like", "resolve_named_yaml",
    "resolve_robot_path", "load_robot", "robot_from_schema",
    # The statics checks at load (statics_checks.py; statics.py holds the statics over the
    # workspace they use, tension_program.py the Clarabel program beyond the kernels).
    "robot_statics", "statics_warnings", "describe_wrench", "frame_warnings", "STATICS_FLOOR",
    "STATICS_GRID", "STATICS_WARN_SHARE",
]
