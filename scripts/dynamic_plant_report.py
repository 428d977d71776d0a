"""The paper's three experiments on the dynamic plant (`plant: !DynamicReels`) against the
kinematic plant (`!SimulatedReels`), at full length.

Per experiment: the largest platform rotation, the forward-kinematics position error (the
controller's FK assumes a translating platform on inextensible cables), the smallest true
cable-cable distance (from the true, rotated pose) against the kinematic plant's, the smallest
and largest tension, the slack ticks per cable, and the real-time factor. Two settings:

- `defaults`: the robot file's dynamics (hardware/robots/paper_7cable.yaml) and the plant's
  defaults. Where the cables cannot hold the platform level at the start (exp1, exp3 with the
  calibrated attachment points), it starts at the tilt the refusal suggests (plant.initial_rpy).
- `stiff`: 100 x EA, ideal drives (bandwidth 1e4 rad/s, no friction), rotation locked: the
  kinematic plant's limit; its largest position difference must stay below 1 mm.

    .venv/bin/python scripts/dynamic_plant_report.py [--duration S] [--only exp2_interaction]
"""

import argparse
import dataclasses
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from cdpm_drake.interference import pair_distances
from cdpm_drake.robot import ROBOTS_DIR
from cdpm_drake.rotation import rotation_from_rpy
from cdpm_drake.scenario import ScenarioError, load_scenario, scenario_robot
from cdpm_drake.simulation import simulate
from cdpm_drake.text import format_table

EXPERIMENTS = ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs")
STIFF = ("cables: {EA: 7.0e6, damping: 200.0}\nreel_drives: {bandwidth: 10000.0, "
         "viscous_friction: 0.0, coulomb_friction: 0.0}\n")


def true_min_distance(robot, log, every: int = 10) -> float:
    """Smallest cable-cable distance (m) over the run, from the true pose (every `every`
    ticks): the platform's attachments rotated by rpy_true, at p_true."""
    best = np.inf
    for k in range(0, len(log["time"]), every):
        R = rotation_from_rpy(log["rpy_true"][k])
        rotated = dataclasses.replace(robot, attachments=robot.attachments @ R.T)
        best = min(best, float(np.min(pair_distances(rotated, log["p_true"][k]))))
    return best


def dynamic_scenario(name: str, text: str):
    """The scenario with the dynamic plant `text`; a start refused level is retried at the
    tilt the refusal names. Returns (scenario, note)."""
    try:
        return load_scenario(name, text), ""
    except ScenarioError as e:
        found = re.search(r"tilted by plant.initial_rpy (\[[^\]]*\])", str(e))
        if not found:
            raise
        tilt = found.group(1)
        plant = text.split("plant: !DynamicReels {", 1)
        retried = f"{plant[0]}plant: !DynamicReels {{initial_rpy: {tilt}, {plant[1]}"
        retried = retried.replace(", }", "}")
        return load_scenario(name, retried), f"level start refused; tilted {tilt} rad"


def row(name, setting, kinematic, result, robot, note):
    log = result.log
    err = np.linalg.norm(log["p"] - log["p_true"], axis=1)
    follow = np.linalg.norm(log["p_true"] - kinematic["p"][:len(log["time"])], axis=1)
    d_kin = float(np.min(kinematic["pair_distances"])) if kinematic["pair_distances"].size else np.nan
    slack = log["slack"].sum(axis=0)
    slack_text = ", ".join(f"{i + 1}:{int(n)}" for i, n in enumerate(slack) if n) or "none"
    return (name, setting, f"{log['time'][-1]:.1f}", f"{np.degrees(np.abs(log['rpy_true']).max()):.2f}",
            f"{1000 * err.max():.2f}", f"{1000 * follow.max():.2f}",
            f"{1000 * true_min_distance(robot, log):.1f}", f"{1000 * d_kin:.1f}",
            f"{log['tensions'].min():.2f}", f"{log['tensions'].max():.1f}", slack_text,
            f"{result.realtime_factor:.2f}", (str(result.error)[:60] if result.error else "")
            + note)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=None,
                        help="seconds per run (default: each scenario's, 30 s)")
    parser.add_argument("--only", action="append", choices=EXPERIMENTS,
                        help="run only this experiment (repeatable)")
    parser.add_argument("--no-stiff", action="store_true", help="skip the stiff-limit runs")
    args = parser.parse_args(argv)
    stiff_file = Path(tempfile.mkdtemp()) / "paper_7cable_stiff.yaml"
    stiff_file.write_text((ROBOTS_DIR / "paper_7cable.yaml").read_text() + STIFF)
    rows, worst_follow = [], 0.0
    for name in args.only or EXPERIMENTS:
        kinematic_result = simulate(scenario=load_scenario(name), duration=args.duration)
        kinematic = kinematic_result.log
        settings = [("defaults", "plant: !DynamicReels {}")]
        if not args.no_stiff:
            settings.append(("stiff", f"{{robot: {stiff_file}, plant: !DynamicReels "
                                      "{time_step: 0.0005, lock_rotation: true, "
                                      "min_tension: 1.0}}"))
        for setting, text in settings:
            scenario, note = dynamic_scenario(name, text)
            robot = scenario_robot(scenario)
            result = simulate(scenario=scenario, duration=args.duration)
            rows.append(row(name, setting, kinematic, result, robot, note))
            if setting == "stiff":
                n = len(result.log["time"])
                worst_follow = max(worst_follow, float(np.max(np.linalg.norm(
                    result.log["p_true"] - kinematic["p"][:n], axis=1))))
            print(f"done {name} {setting}", file=sys.stderr)
        rows.append((name, "kinematic", f"{kinematic['time'][-1]:.1f}", "0", "0", "0",
                     f"{1000 * float(np.min(kinematic['pair_distances'])):.1f}",
                     f"{1000 * float(np.min(kinematic['pair_distances'])):.1f}", "-", "-", "-",
                     f"{kinematic_result.realtime_factor:.2f}", ""))
    print(format_table(
        ["experiment", "plant", "t (s)", "max rotation (deg)", "FK error (mm)",
         "vs kinematic (mm)", "min distance true (mm)", "min distance kinematic (mm)",
         "min T (N)", "max T (N)", "slack ticks per cable", "RTF", "note"], rows))
    if not args.no_stiff:
        print(f"stiff limit: largest |p_true - p_kinematic| {1000 * worst_follow:.3f} mm "
              f"({'within' if worst_follow < 1e-3 else 'NOT within'} 1 mm)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
