"""One Drake LeafSystem per block of the paper's Fig. 5; each a thin wrapper of numpy math."""

from .admittance import Admittance, make_admittance
from .force_sensor import ForceSensorSource
from .forward_kinematics import ForwardKinematicsEstimator
from .interference_force import InterferenceForce
from .jacobian_mapping import JacobianVelocityMapping
from .safety_limits import SafetyLimits
from .simulated_reels import SensorNoise, SimulatedOperator, SimulatedReels
from .wall_force import WorkspaceWallForce

__all__ = [
    "Admittance", "ForceSensorSource", "ForwardKinematicsEstimator", "InterferenceForce",
    "JacobianVelocityMapping", "SafetyLimits", "SensorNoise", "SimulatedOperator",
    "SimulatedReels", "WorkspaceWallForce", "make_admittance",
]
