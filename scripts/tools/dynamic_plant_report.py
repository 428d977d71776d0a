"""The paper's three experiments on the dynamic plant (`plant: !DynamicReels`) against the
kinematic plant (`!SimulatedReels`), at full length.

Per experiment and controller: how far the run got, the ticks with a slack cable, the smallest
and largest tension, the largest platform rotation (angle from level), the forward-kinematics
position error (|p - p_true|: the controller's estimate against the plant's truth), the
smallest TRUE distance of the pairs that interfere (from the plant's true, rotated pose:
`pair_distances_true`) beside the controller's estimate of it and the kinematic plant's
minimum, and the real-time factor. Controllers:

- `open loop`: the paper's Fig. 5 (controller.length_gain 0);
- `length loop`: the default, the cable-length loop in the Jacobian mapping;
- `full pose`: controller {pose: full, tension_control: true}, where the scenario accepts it;
- `stiff`: 100 x EA, ideal drives (bandwidth 1e4 rad/s, no friction), rotation locked: the
  kinematic plant's limit; its largest position difference must stay below 1 mm.

The robot file's dynamics (cdpm_drake/data/robots/paper_7cable.yaml) and the plant's defaults
(drive friction on), level starts.

    .venv/bin/python scripts/tools/dynamic_plant_report.py [--duration S] [--only exp2_interaction]
"""

import argparse
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from cdpm_drake.robot import ROBOTS_DIR
from cdpm_drake.kernels.rotation import rotation_angle, rotations_from_rpy
from cdpm_drake.config import ScenarioError, load_scenario
from cdpm_drake.runs.simulate import simulate
from cdpm_drake.text import format_table

EXPERIMENTS = ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs")
STIFF = ("cables: {EA: 7.0e6, damping: 200.0}\nreel_drives: {bandwidth: 10000.0, "
         "viscous_friction: 0.0, coulomb_friction: 0.0}\n")


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


def row(name, setting, kinematic, result, note=""):
    log = result.log
    T = len(log["time"])
    err = np.linalg.norm(log["p"] - log["p_true"], axis=1)
    tilt = np.degrees(rotation_angle(rotations_from_rpy(log["rpy_true"])))
    slack = int(np.any(log["slack"], axis=1).sum())
    active = np.asarray(kinematic["active"]).any(axis=0)
    if not active.any():  # no pair interferes: the closest one
        active = np.zeros_like(active)
        active[int(np.argmin(kinematic["pair_distances"].min(axis=0)))] = True
    d_kin = 1000 * float(np.min(kinematic["pair_distances"][:, active]))
    d_true = 1000 * float(np.min(log["pair_distances_true"][:, active]))
    d_est = 1000 * float(np.min(log["pair_distances"][:, active]))
    fault = (str(result.error)[:50] if result.error else "") + note
    return (name, setting, f"{log['time'][-1]:.1f}", f"{slack} ({100 * slack / T:.2f} %)",
            f"{log['tensions'].min():.2f}", f"{log['tensions'].max():.1f}", f"{tilt.max():.2f}",
            f"{1000 * err.max():.2f}", f"{d_true:.2f}", f"{d_est:.2f}", f"{d_kin:.2f}",
            f"{result.realtime_factor:.1f}", fault)


CONTROLLERS = (("open loop", "controller: {length_gain: 0}"),
               ("length loop", ""),
               ("full pose", "controller: {pose: full, tension_control: true}"))


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
        settings = [(label, "{plant: !DynamicReels {}" + (", " + text if text else "") + "}")
                    for label, text in CONTROLLERS]
        if not args.no_stiff:
            settings.append(("stiff", f"{{robot: {stiff_file}, plant: !DynamicReels "
                                      "{time_step: 0.0005, lock_rotation: true, "
                                      "min_tension: 1.0}}"))
        for setting, text in settings:
            try:
                scenario, note = dynamic_scenario(name, text)
            except ScenarioError as e:  # a controller this robot cannot run: say so
                rows.append((name, setting) + ("-",) * 10 + (str(e)[:50],))
                continue
            result = simulate(scenario=scenario, duration=args.duration)
            rows.append(row(name, setting, kinematic, result, note))
            if setting == "stiff":
                n = len(result.log["time"])
                worst_follow = max(worst_follow, float(np.max(np.linalg.norm(
                    result.log["p_true"] - kinematic["p"][:n], axis=1))))
            print(f"done {name} {setting}", file=sys.stderr)
        d_kin = 1000 * float(np.min(kinematic["pair_distances"]))
        rows.append((name, "kinematic", f"{kinematic['time'][-1]:.1f}", "-", "-", "-", "0", "0",
                     "-", "-", f"{d_kin:.2f}", f"{kinematic_result.realtime_factor:.1f}", ""))
    print(format_table(
        ["experiment", "controller", "t (s)", "slack ticks", "min T (N)", "max T (N)",
         "max rotation (deg)", "FK error (mm)", "min d true (mm)", "min d estimated (mm)",
         "min d kinematic (mm)", "RTF", "fault / note"], rows))
    print("min d: the pairs the kinematic run brought within d_u (else the closest pair)")
    if not args.no_stiff:
        print(f"stiff limit: largest |p_true - p_kinematic| {1000 * worst_follow:.3f} mm "
              f"({'within' if worst_follow < 1e-3 else 'NOT within'} 1 mm)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
