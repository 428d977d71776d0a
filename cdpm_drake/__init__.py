"""cdpm_drake: interference-aware admittance control of cable-driven parallel mechanisms.

Layout (imports point down only):
  cli.py -> diagram.py / scenario.py -> systems/, hardware/ -> robot.py, kinematics.py,
  interference.py, limits.py, sensor.py, operators.py (numpy and numba, no Drake; the per-tick
  kernels are compiled once and cached by numba).
"""

__version__ = "0.1.0"
