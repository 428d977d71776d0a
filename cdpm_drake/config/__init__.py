"""The typed scenario: everything one run needs, loaded from YAML with yaml_load_typed.

A scenario names a robot, the cable swaps, the start, the admittance, the logistic parameters
per cable pair, the limits, the operator, the force sensor and the plant (simulated reels or the
real ones). Shipped scenarios live in `cdpm_drake/data/scenarios/` and resolve by name from any
directory; `--scenario-text` overlays a YAML snippet for one-off changes.

    scenario.py       the Scenario dataclass and its nested configs (the YAML schema)
    plants.py         the plant configs: SimulatedReels, DynamicReels (HardwareReels: hardware/)
    yaml_io.py        raw YAML checked against the schema, its errors, the YAML writer
    load.py           a scenario file by name or path, with an overlay
    resolve.py        a scenario checked and resolved once: ResolvedScenario
    checks.py         the field checks beyond their types
    load_warnings.py  what a loaded scenario is warned about before a run

The names below are the package's API for the other layers.
"""

from cdpm_drake.config.checks import (UnholdableRobot, check_duration, check_dynamic_reels,
                                      homing_tensions)
from cdpm_drake.config.load import (load_resolved_scenario, load_scenario, resolve_scenario_path,
                                    scenario_names)
from cdpm_drake.config.load_warnings import (sensor_range_text, warn_reel_saturation,
                                             warn_unreachable_d_u)
from cdpm_drake.config.plants import (DriveTorqueSensor, DynamicReels, LoadCellSensor,
                                      PlantConfig, SimulatedReels)
from cdpm_drake.config.resolve import (ResolvedScenario, check_scenario, interference_params,
                                       resolve_scenario, scenario_operator, scenario_robot)
from cdpm_drake.config.scenario import (Admittance, Controller, Interference, KinetostaticForce,
                                        Limits, Logistic, ModelMonitor, OperatorConfig,
                                        PairLogistic, SafetyFilter, Scenario, ScenarioError,
                                        Sensor, TensionDamping, WallForce)
from cdpm_drake.config.yaml_io import (INTERNAL_FIELDS, check_yaml, explain_load_error,
                                       scenario_to_yaml, with_line)

__all__ = [
    # The schema (scenario.py, plants.py).
    "Scenario", "Admittance", "Logistic", "PairLogistic", "Interference", "Limits",
    "WallForce", "Sensor", "Controller", "TensionDamping", "KinetostaticForce", "SafetyFilter",
    "ModelMonitor",
    "OperatorConfig", "SimulatedReels", "DynamicReels", "DriveTorqueSensor", "LoadCellSensor",
    "PlantConfig", "ScenarioError",
    # Loading and resolving (load.py, resolve.py).
    "scenario_names", "resolve_scenario_path", "load_scenario", "load_resolved_scenario",
    "ResolvedScenario", "resolve_scenario", "check_scenario", "scenario_robot",
    "scenario_operator", "interference_params",
    # Checks and warnings (checks.py, load_warnings.py).
    "check_duration", "check_dynamic_reels", "homing_tensions", "UnholdableRobot",
    "warn_reel_saturation", "warn_unreachable_d_u", "sensor_range_text",
    # YAML (yaml_io.py).
    "INTERNAL_FIELDS", "check_yaml", "with_line", "explain_load_error", "scenario_to_yaml",
]
