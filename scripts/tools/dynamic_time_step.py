"""Is a 2 ms plant step accurate enough? The dynamic plant at several time steps against its own
0.25 ms step, and its energy error.

1. Energy: the undamped, frictionless plant (cable damping 0, reels held) knocked at
   v = [4, -3, 5] mm/s, w = [0.05, -0.04, 0.03] rad/s, 4 s: the largest error of the total
   energy (kinetic, gravity, cable strain) relative to the oscillation's energy (the knock's
   kinetic energy). Symplectic Euler keeps it bounded, of order h * omega_max.
2. Accuracy: the dynamic reference runs (tests/data/dynamic_reference: the plant alone after a
   push; a hand force step and exp2's first 10 s through the controller, drive friction on) at
   each step against the 0.25 ms step: largest differences of the tensions, the true position
   and tilt, the controller's position estimate, slack ticks, and the closest approach of the
   watched cable pairs.
3. Speed: exp2 (10 s) real-time factor at each step (one run each, this process).

    .venv/bin/python scripts/tools/dynamic_time_step.py [--steps 0.00025 0.0005 0.001 0.002]
"""

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts" / "tools"))

from pydrake.systems.analysis import Simulator  # noqa: E402
from pydrake.systems.framework import DiagramBuilder  # noqa: E402
from pydrake.systems.primitives import ConstantVectorSource  # noqa: E402

import make_reference_logs as references  # noqa: E402
from cdpm_drake.diagram import make_plant  # noqa: E402
from cdpm_drake.config import check_dynamic_reels, load_scenario, scenario_robot  # noqa: E402
from cdpm_drake.runs.simulate import simulate  # noqa: E402
from cdpm_drake.kernels.tension import GRAVITY  # noqa: E402
from cdpm_drake.text import format_table  # noqa: E402

ROBOT = ROOT / "tests" / "data" / "robots" / "dynamic_reference_7cable.yaml"


def energy_error(h: float) -> tuple[float, float]:
    """(largest |E - E0| / E_knock, E_knock J) of the undamped plant knocked, over 4 s."""
    with tempfile.TemporaryDirectory() as tmp:
        robot_file = Path(tmp) / "undamped.yaml"
        # The file's cables and reel_drives sections replaced, not repeated (a robot file
        # refuses a key written twice).
        raw = yaml.safe_load(ROBOT.read_text())
        raw["cables"] = {**raw.get("cables", {}), "damping": 0.0}
        raw["reel_drives"] = {**raw.get("reel_drives", {}), "viscous_friction": 0.0,
                              "coulomb_friction": 0.0}
        robot_file.write_text(yaml.safe_dump(raw))
        scenario = load_scenario("exp2_interaction", f"{{robot: {robot_file}, swaps: [[1, 3]], "
                                 "operator: !NoOperator {}, interference: {enabled: false}, "
                                 f"plant: !DynamicReels {{time_step: {h}}}}}")
        robot = scenario_robot(scenario)
        d = robot.dynamics
        p0 = np.asarray(scenario.initial_position)
        T0 = check_dynamic_reels(scenario, robot).tensions
        L0 = np.linalg.norm(robot.reels - (p0 + robot.attachments), axis=1) * d.EA / (
            d.EA + T0)
        builder = DiagramBuilder()
        plant = builder.AddNamedSystem("reels", make_plant(scenario))
        hold = builder.AddSystem(ConstantVectorSource(np.zeros(robot.num_cables)))
        builder.Connect(hold.get_output_port(), plant.GetInputPort("reel_velocity_command"))
        diagram = builder.Build()
        mbp = plant.GetSubsystemByName("platform_plant")
        simulator = Simulator(diagram)
        context = mbp.GetMyMutableContextFromRoot(simulator.get_mutable_context())
        w0, v0 = np.array([0.05, -0.04, 0.03]), np.array([0.004, -0.003, 0.005])
        mbp.SetVelocities(context, np.concatenate([w0, v0]))

        def energy():
            x = mbp.GetPositionsAndVelocities(context)
            R = mbp.EvalBodyPoseInWorld(context, mbp.GetBodyByName("platform")).rotation()
            R = R.matrix()
            p, w, v = x[4:7], x[7:10], x[10:13]
            L = np.linalg.norm(robot.reels - (p + robot.attachments @ R.T), axis=1)
            stretch = np.maximum(L - L0, 0.0)
            return (0.5 * d.mass * v @ v + 0.5 * w @ (R @ d.inertia @ R.T) @ w
                    + d.mass * GRAVITY * p[2] + np.sum(0.5 * d.EA / L0 * stretch ** 2))

        E0 = energy()
        knock = 0.5 * d.mass * v0 @ v0 + 0.5 * w0 @ d.inertia @ w0
        worst = 0.0
        for t in np.arange(0.01, 4.0 + 1e-9, 0.01):
            simulator.AdvanceTo(t)
            worst = max(worst, abs(energy() - E0))
        return worst / knock, knock


def with_step(name: str, h: float) -> dict:
    """The reference run `name` with the plant's time step h (everything else as stored)."""
    return references.run_dynamic_reference(name, f"plant: !DynamicReels {{time_step: {h}}}")


def tilt(rpy):
    cr, cp, cy = np.cos(rpy[:, 0]), np.cos(rpy[:, 1]), np.cos(rpy[:, 2])
    sr, sp, sy = np.sin(rpy[:, 0]), np.sin(rpy[:, 1]), np.sin(rpy[:, 2])
    trace = cy * cp + (sy * sp * sr + cy * cr) + cp * cr
    return np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=float, nargs="+",
                        default=[0.00025, 0.0005, 0.001, 0.002], help="plant time steps, s")
    args = parser.parse_args(argv)
    steps = sorted(args.steps)
    fine = steps[0]

    rows = []
    for h in steps:
        error, knock = energy_error(h)
        rows.append([f"{1000 * h:g}", f"{100 * error:.2f} %", f"{1e3 * knock:.3f}"])
    print("1. energy of the undamped plant after a knock, 4 s (symplectic Euler: bounded)")
    print(format_table(["step (ms)", "largest |E - E0| / E_knock", "E_knock (mJ)"], rows))

    print()
    print(f"2. against the {1000 * fine:g} ms step (the dynamic reference runs)")
    for name in references.dynamic_names():
        logs = {h: with_step(name, h) for h in steps}
        ref = logs[fine]
        rows = []
        for h in steps:
            log = logs[h]
            dT = np.abs(log["tensions"] - ref["tensions"])
            row = [f"{1000 * h:g}", f"{dT.max():.3f}", f"{np.sqrt(np.mean(dT ** 2)):.4f}",
                   f"{1000 * np.linalg.norm(log['p_true'] - ref['p_true'], axis=1).max():.4f}",
                   f"{math.degrees(np.abs(tilt(log['rpy_true']) - tilt(ref['rpy_true'])).max()):.4f}",
                   f"{int(log['slack'].sum())} ({int(ref['slack'].sum())})"]
            if "p" in log:
                row += [f"{1000 * np.linalg.norm(log['p'] - ref['p'], axis=1).max():.4f}",
                        f"{1000 * log['pair_distances'].min():.3f}"]
            else:
                row += ["-", "-"]
            rows.append(row)
        print(f"{name} (tensions up to {ref['tensions'].max():.1f} N)")
        print(format_table(["step (ms)", "max |dT| (N)", "rms |dT| (N)", "max |dp_true| (mm)",
                            "max |d tilt| (deg)", "slack ticks (fine)", "max |dp| (mm)",
                            "closest pair (mm)"], rows))

    print()
    rows = []
    for h in steps:
        scenario = load_scenario("exp2_interaction",
                                 f"{{duration: 10.0, plant: !DynamicReels {{time_step: {h}}}}}")
        result = simulate(scenario=scenario)
        rows.append([f"{1000 * h:g}", f"{result.realtime_factor:.1f}x",
                     "" if result.error is None else str(result.error)[:60]])
    print("3. exp2, 10 s, one run each (this process, loggers on)")
    print(format_table(["step (ms)", "real-time factor", "error"], rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
