"""One named Drake system per block of the paper's Fig. 5.

A block is a small sub-diagram: one stateless Python LeafSystem calling the block's compiled
kernel (numba, in the math modules, bound once: kernel_call) once per tick, its state held
by C++ primitives fed back (ZeroOrderHold, a discrete LinearSystem), its inputs stacked and
its result split by a C++ Selector (_wiring.wiring); the admittance and the sliding average
are C++ LinearSystems. In the product diagram the blocks are added flat and their Selectors
fused into one (_wiring.fuse_wiring). Contexts clone and simulations repeat exactly: nothing
that changes lives in Python.
"""

from cdpm_drake.systems.admittance import Admittance, make_admittance
from cdpm_drake.systems.force_sensor import ForceSensorSource
from cdpm_drake.systems.forward_kinematics import ForwardKinematicsEstimator
from cdpm_drake.systems.interference_force import InterferenceForce
from cdpm_drake.systems.jacobian_mapping import JacobianVelocityMapping
from cdpm_drake.systems.safety_limits import SafetyLimits
from cdpm_drake.systems.plants.simulated_reels import SensorNoise, SimulatedReels, add_simulated_world
from cdpm_drake.systems.wall_force import WorkspaceWallForce

__all__ = [
    "Admittance", "ForceSensorSource", "ForwardKinematicsEstimator", "InterferenceForce",
    "JacobianVelocityMapping", "SafetyLimits", "SensorNoise", "add_simulated_world",
    "SimulatedReels", "WorkspaceWallForce", "make_admittance",
]
