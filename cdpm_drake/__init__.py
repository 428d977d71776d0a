"""cdpm_drake: interference-aware admittance control of cable-driven parallel mechanisms.

Layout (imports point down only):
  cli.py -> diagram.py / scenario.py -> systems/, hardware/ -> robot.py, kinematics.py,
  interference.py (numpy only).
"""

__version__ = "0.1.0"
