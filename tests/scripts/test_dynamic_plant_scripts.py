"""Smoke runs of the dynamic plant's scripts (issue 21): the benchmark prints its table with
every row, and the time-step report says what a coarser step costs."""

import re
import subprocess
import sys
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


def run(script, *args):
    return subprocess.run([sys.executable, str(SCRIPTS / script), *args], capture_output=True,
                          text=True, timeout=600)


def test_benchmark_prints_every_row_beside_the_kinematic_plant():
    out = run("bench/bench_dynamic_plant.py", "--duration", "0.1", "--repeats", "1")
    assert out.returncode == 0, out.stderr
    rows = {}
    for line in out.stdout.splitlines():
        cells = re.split(r"\s{2,}", line.strip())
        if len(cells) == 5 and cells[1].endswith("x"):
            rows[cells[0]] = cells
    assert set(rows) == {"kinematic plant (reference)", "dynamic plant, 1 ms step (product)",
                         "dynamic plant, 2 ms step", "dynamic plant, 0.5 ms step",
                         "floor: dynamic, Python math as no-ops",
                         "floor: MultibodyPlant alone, 1 ms"}
    # The reference's ratio is 1 by definition; per plant step = per tick / steps per tick.
    assert rows["kinematic plant (reference)"][4] == "1.00"
    product = rows["dynamic plant, 1 ms step (product)"]
    assert abs(float(product[3]) - float(product[2]) / 2) <= 0.06
    assert "goal >= 25x real time for the product" in out.stdout


def test_time_step_report_orders_the_errors_by_step():
    out = run("tools/dynamic_time_step.py", "--steps", "0.0005", "0.002")
    assert out.returncode == 0, out.stderr
    energy = dict(re.findall(r"^(0\.5|2)\s+([\d.]+) %", out.stdout, flags=re.M))
    # Symplectic Euler: the energy error grows with the step (first order).
    assert 0.0 < float(energy["0.5"]) < float(energy["2"]) < 50.0
    # Against the finer step, the 2 ms step's tensions and positions differ, the fine one's
    # own row is zero.
    tables = re.findall(r"^2\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)", out.stdout, flags=re.M)
    assert len(tables) >= 3 and all(float(dT) > 0 for dT, _, _ in tables)
    assert re.search(r"^0\.5\s+0\.000\s+0\.0000\s+0\.0000", out.stdout, flags=re.M)


def test_unseen_slack_pose_recomputes_the_truth_from_the_log():
    # At t = 0 the estimate starts at the true pose, so the script's truth (the pair's distance
    # and the length residuals recomputed at the plant's true pose) must equal what it
    # computes at the estimate, to the printed digit; later the hand separates them.
    out = run("bench/unseen_slack_pose.py", "--duration", "0.12", "--every", "30")
    assert out.returncode == 0, out.stderr
    rows = [line.split("|")[1:-1] for line in out.stdout.splitlines()
            if re.match(r"^\| \d", line)]
    assert [float(r[0]) for r in rows] == [0.0, 0.06, 0.12]
    true0, est0 = (float(x) for x in rows[0][1].split("/"))
    assert true0 == est0 and 1.0 < true0 < 3.0  # exp3's start: 2.18 mm above d_l = 57 mm
    assert rows[0][8].strip() == rows[0][9].strip()
    assert "smallest singular value of the length Jacobian" in out.stdout


def test_hand_compliance_puts_paper_7cable_s_pair_1_3_within_reach_of_a_40_n_tilt():
    # exp2's start: pair 1-3 at d_l + 1.86 mm (the level pose's pair distance, computed here
    # independently); a 40 N push across it tilts the platform on its taut elastic cables
    # by ~1.4 deg, which moves the pair ~6 mm, while the position moves it < 0.1 mm.
    import numpy as np

    from cdpm_drake.config import load_resolved_scenario
    from cdpm_drake.kernels.interference import pair_distances

    out = run("bench/hand_compliance.py", "--force", "40")
    assert out.returncode == 0, out.stderr
    row = next(line for line in out.stdout.splitlines() if line.startswith("| exp2"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    resolved = load_resolved_scenario("exp2_interaction")
    robot = resolved.robot
    d0 = pair_distances(robot, np.asarray(resolved.scenario.initial_position, dtype=float))
    assert float(cells[2]) == round(1000 * d0[robot.pair_position(1, 3)], 2)
    by_position, by_tilt = (float(x) for x in cells[5].split("/"))
    assert abs(by_position) < 0.1 and -7.0 < by_tilt < -5.0


def test_step_probe_s_modal_statics_equal_the_compliance_solve():
    # The step probe's elastic prediction sums the platform's modes, phi_k phi_k^T / w_k^2;
    # with mass-normalised modes that sum is K^-1, so its statics must equal
    # hand_compliance's direct solve x = K^-1 dw (position's and tilt's parts of the pair's
    # change) at the same pose; the step starts from rest (zero change at t = 0) and, undamped,
    # overshoots the statics.
    import importlib
    import numpy as np

    from cdpm_drake.config import load_resolved_scenario

    sys.path.insert(0, str(SCRIPTS / "bench"))
    probe = importlib.import_module("step_tilt_probe")
    compliance = importlib.import_module("hand_compliance")
    for scenario in ("exp2_interaction", "exp3_two_pairs"):
        resolved = load_resolved_scenario(scenario)
        p0 = np.asarray(resolved.scenario.initial_position, dtype=float)
        static, tilt, low, when, hz = probe.elastic(scenario, p0)
        _, _, _, by_position, by_tilt = compliance.deflection(resolved, (1, 3), 40.0)
        assert abs(static - (by_position + by_tilt)) < 1e-6
        assert abs(tilt - by_tilt) < 1e-6
        assert low < static < 0.0 and 0.0 < when < 200.0
        assert hz.shape == (6,) and np.all(np.diff(hz) >= 0.0) and 3.0 < hz[0] < 5.0
