"""The scenario a run folder keeps: DIR/scenario.yaml, the resolved scenario that ran, with
copies of the robot file and force CSV it reads, so the folder reruns alone."""

import dataclasses
from pathlib import Path

from cdpm_drake.config import resolve_scenario, scenario_to_yaml


# The copies of a scenario's own files in the run folders (write_run_scenario).
RUN_ROBOT_FILE = "robot.yaml"
RUN_FORCE_FILE = "force.csv"
RUN_PLANT_ROBOT_FILE = "plant_robot.yaml"


def write_run_scenario(out_dir, scenario, **changes) -> Path:
    """Write DIR/scenario.yaml, the resolved scenario (with `changes`, e.g. the duration that
    ran), and copies of the robot file and force CSV it reads, DIR/robot.yaml and
    DIR/force.csv, which it refers to instead of the originals: the folder can be moved,
    shared and rerun alone. The copies are of the files as the run loaded them (a
    ResolvedScenario's `files`), so a rerun into its own folder with --force (which empties
    it first) still has them. Returns the scenario.yaml path."""
    resolved = resolve_scenario(scenario)
    out = Path(out_dir)
    recorded = dataclasses.replace(resolved.scenario, **changes)
    names = {"robot": RUN_ROBOT_FILE, "operator.path": RUN_FORCE_FILE,
             "plant.robot": RUN_PLANT_ROBOT_FILE}
    for field, data in resolved.files.items():
        (out / names[field]).write_bytes(data)
    if "robot" in resolved.files:
        recorded = dataclasses.replace(recorded, robot=RUN_ROBOT_FILE)
    if "operator.path" in resolved.files:
        recorded = dataclasses.replace(recorded, operator=dataclasses.replace(
            recorded.operator, path=RUN_FORCE_FILE))
    if "plant.robot" in resolved.files:
        recorded = dataclasses.replace(recorded, plant=dataclasses.replace(
            recorded.plant, robot=RUN_PLANT_ROBOT_FILE))
    path = out / "scenario.yaml"
    path.write_text(scenario_to_yaml(recorded))
    return path
