"""A robot as built, not as its file says, and `cdpm calibrate` on its runs.

References: the plant's truth as it logs it (reels_true, encoder_zero_error), closed-form cable
lengths, a brute-force segment distance, and the promise's bar on the true geometry."""

import numpy as np
import pytest
import yaml

from cdpm_drake.cli.cdpm import main as cdpm
from cdpm_drake.config import ScenarioError, load_scenario, resolve_scenario
from cdpm_drake.runs.log import load_log

ERROR = "{reels_std: 0.01, encoder_offset_std: 0.003}"


def _run(tmp_path, *args):
    code = cdpm(["simulate", *args, "--no-progress", "--out", str(tmp_path)])
    return code, load_log(tmp_path)


def _segment_distance(p1, q1, p2, q2, n=801):
    """Brute force: the smallest distance between points sampled on both segments, refined
    around the best pair (independent of the kernels' KKT solution)."""
    s = np.linspace(0, 1, n)[:, None]
    a = p1 + s * (q1 - p1)
    b = p2 + s * (q2 - p2)
    d = np.linalg.norm(a[:, None] - b[None], axis=2)
    i, j = np.unravel_index(np.argmin(d), d.shape)
    s2 = np.linspace(max(0, (i - 2) / (n - 1)), min(1, (i + 2) / (n - 1)), 201)[:, None]
    t2 = np.linspace(max(0, (j - 2) / (n - 1)), min(1, (j + 2) / (n - 1)), 201)[:, None]
    a = p1 + s2 * (q1 - p1)
    b = p2 + t2 * (q2 - p2)
    return float(np.min(np.linalg.norm(a[:, None] - b[None], axis=2)))


def test_a_plant_with_model_error_is_homed_on_the_file_and_judged_on_its_truth(tmp_path):
    code, log = _run(tmp_path, "exp2_interaction", "--duration", "2", "--scenario-text",
                     f"{{plant: !SimulatedReels {{model_error: {ERROR}}}}}")
    assert code == 0
    a, b = log["reels"], log["attachments"]
    a_true, b_true = log["reels_true"], log["attachments_true"]
    # The draw: about 1 cm per axis, not the file.
    moved = np.abs(a_true - a)
    assert 0.002 < moved.mean() < 0.02 and np.all(b_true == b)
    # The homing: at t = 0 the encoders read the FILE's rigid lengths of the start pose plus
    # each encoder's zero error (closed form), not the true robot's.
    p0 = np.asarray(log["initial_position"])
    file_lengths = np.linalg.norm(a - p0 - b, axis=1)
    true_lengths = np.linalg.norm(a_true - p0 - b_true, axis=1)
    np.testing.assert_allclose(log["lengths"][0], file_lengths + log["encoder_zero_error"],
                               atol=1e-9)
    assert np.abs(file_lengths - true_lengths).max() > 1e-3
    # The truth is the true robot's: at a few ticks, the pair's distance on the true geometry
    # at the true pose, by brute force.
    col = [list(p) for p in log["pairs"]].index([1, 3])
    i, j = 0, 2
    for k in (0, 500, len(log["time"]) - 1):
        p = log["p_true"][k]
        ref = _segment_distance(a_true[i], p + b_true[i], a_true[j], p + b_true[j])
        assert log["pair_distances_true"][k, col] == pytest.approx(ref, abs=2e-5)
    # ... and it is not the controller's view.
    assert np.abs(log["p_true"] - log["p"]).max() > 1e-4


@pytest.mark.parametrize("text, field", [
    ("{reels_std: -0.01}", "plant.model_error.reels_std"),
    ("{reels_std: 2.0}", "plant.model_error.reels_std"),
    ("{EA_rel_std: .nan}", "plant.model_error.EA_rel_std"),
    ("{seed: -3}", "plant.model_error.seed"),
])
def test_bad_model_error_is_refused_naming_the_field(text, field):
    with pytest.raises(ScenarioError, match=field.replace(".", r"\.")):
        resolve_scenario(load_scenario(
            "exp2_interaction", f"{{plant: !SimulatedReels {{model_error: {text}}}}}"))


def test_a_plant_robot_with_another_cable_count_is_refused():
    with pytest.raises(ScenarioError, match=r"plant\.robot 'cube_8cable' has 8 cables"):
        resolve_scenario(load_scenario("exp2_interaction",
                                       "{plant: !SimulatedReels {robot: cube_8cable}}"))


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    """The calibration motion on a robot whose exits are off by ~1 cm and whose
    encoders are off by ~3 mm after the homing, and `cdpm calibrate` on its log."""
    tmp = tmp_path_factory.mktemp("calibration")
    run = tmp / "run"
    assert cdpm(["simulate", "calibration_motion", "--no-progress",
                 "--out", str(run), "--scenario-text",
                 f"{{random_seed: 7, plant: !SimulatedReels {{model_error: {ERROR}}}}}"]) == 0
    out = tmp / "paper_7cable_calibrated.yaml"
    assert cdpm(["calibrate", str(run), "--robot", "paper_7cable", "--out", str(out)]) == 0
    return tmp, run, out


def test_calibration_finds_the_encoder_offsets_and_the_exits_in_their_frame(calibration):
    tmp, run, out = calibration
    log = load_log(run)
    written = yaml.safe_load(out.read_text())
    cal = written["calibration"]
    # The truth of the offsets: what the homing on the file made (file minus true rigid
    # lengths of the start pose) plus the zero errors.
    p0 = np.asarray(log["initial_position"])
    c_true = (np.linalg.norm(log["reels"] - p0 - log["attachments"], axis=1)
              - np.linalg.norm(log["reels_true"] - p0 - log["attachments_true"], axis=1)
              + log["encoder_zero_error"])
    assert np.abs(np.asarray(cal["encoder_offsets"]) - c_true).max() < 1e-3
    assert not any(n.startswith("encoder offset") for n in cal["not_identified"])
    # The exits: exact but for the turn about the homing pose lengths cannot see.
    a_fit, a_true = np.asarray(written["reels"]), log["reels_true"]
    r = a_true - log["attachments_true"] - p0
    A = np.vstack([[[0, r_[2], -r_[1]], [-r_[2], 0, r_[0]], [r_[1], -r_[0], 0]] for r_ in r])
    d = (a_fit - a_true).ravel()
    w, *_ = np.linalg.lstsq(A, d, rcond=None)
    assert np.linalg.norm(d - A @ w) < 1e-3
    # Their in-frame uncertainty is stated, and sub-millimetre; the file keeps its fields.
    assert np.asarray(cal["reels_std_in_frame"]).max() < 1e-3
    assert written["name"] == "paper_7cable" and "workspace" in written
    assert cal["calibrated_from"] == [str(run)]


def test_the_calibrated_file_keeps_the_promise_on_the_true_robot(calibration, tmp_path):
    """Experiment 2 (cables 1 and 3 swapped and pushed together), controller on the calibrated
    file, plant on the true robot: the true closest approach within 2 mm of d_l."""
    tmp, run, out = calibration
    log = load_log(run)
    true_file = tmp_path / "true.yaml"
    raw = yaml.safe_load(out.read_text())
    raw.pop("calibration")
    raw["reels"] = log["reels_true"].tolist()
    raw["name"] = "paper_7cable_as_built"
    true_file.write_text(yaml.safe_dump(raw))
    code, result = _run(tmp_path / "exp2", "exp2_interaction", "--duration", "12",
                        "--scenario-text",
                        f"{{robot: {out}, plant: !SimulatedReels {{robot: {true_file}}}}}")
    assert code == 0, "the calibrated file's run stopped"
    assert np.all(result["pair_distances_true"].min(axis=0) >= result["d_l"] - 2e-3)
    assert not result["crossed_true"].any()


def test_calibrate_refuses_a_log_of_another_robot_and_writes_nothing(calibration, tmp_path,
                                                                     capsys):
    tmp, run, _ = calibration
    out = tmp_path / "cube_calibrated.yaml"
    assert cdpm(["calibrate", str(run), "--robot", "cube_8cable", "--out", str(out)]) == 1
    assert "another robot" in capsys.readouterr().err and not out.exists()


def test_calibrate_never_overwrites(calibration, capsys):
    tmp, run, out = calibration
    before = out.read_text()
    assert cdpm(["calibrate", str(run), "--robot", "paper_7cable", "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and out.read_text() == before


def test_calibrate_refuses_a_misfit_above_the_encoders(calibration, tmp_path, capsys):
    """Claiming 1 um encoders on lengths the fit leaves at ~1-10 um: refused, the cable named,
    nothing written."""
    tmp, run, _ = calibration
    out = tmp_path / "x.yaml"
    code = cdpm(["calibrate", str(run), "--robot", "paper_7cable", "--out", str(out),
                 "--encoder-std", "1e-9"])
    err = capsys.readouterr().err
    assert code == 1 and "misfit after the fit" in err and "nothing written" in err
    assert not out.exists()


def test_a_calibrated_file_widens_the_pair_floor_by_its_uncertainty(calibration):
    """d_min gains 2 sigma of each pair's distance, sigma from the file's in-frame standard
    deviations (the larger end point's per cable, the two cables' in quadrature)."""
    tmp, run, out = calibration
    cal = yaml.safe_load(out.read_text())["calibration"]
    resolved = resolve_scenario(load_scenario("exp2_interaction", f"{{robot: {out}}}"))
    sigma = np.hypot(np.max(cal["reels_std_in_frame"], axis=1),
                     np.max(cal["attachments_std_in_frame"], axis=1))
    pairs = np.asarray(resolved.robot.pairs) - 1
    expected = 2.0 * np.hypot(sigma[pairs[:, 0]], sigma[pairs[:, 1]])
    np.testing.assert_allclose(resolved.d_min_margin, expected, rtol=1e-9)
    plain = resolve_scenario(load_scenario("exp2_interaction"))
    np.testing.assert_allclose(resolved.d_min, plain.d_min + expected, rtol=1e-12)


def test_the_shipped_calibration_motion_is_the_generators(tmp_path):
    """calibration_motion.yaml is what `cdpm calibrate --write-motion` writes for the built-in
    robot from its start; its poses are held by the cables (t* >= 8 N at each, statics.py)
    and spread over the box."""
    from cdpm_drake.data import SCENARIOS_DIR
    from cdpm_drake.robot import load_robot
    from cdpm_drake.robot.statics import holding_tension

    out = tmp_path / "motion.yaml"
    assert cdpm(["calibrate", "--write-motion", str(out), "--robot", "paper_7cable",
                 "--start", "1.75", "2.4", "1.35"]) == 0
    assert out.read_text() == (SCENARIOS_DIR / "calibration_motion.yaml").read_text()
    scenario = load_scenario(str(out))
    points = np.asarray(scenario.operator.waypoints)
    robot = load_robot("paper_7cable")
    assert holding_tension(robot, points).min() >= 8.0 - 1e-9
    span = points.max(axis=0) - points.min(axis=0)
    assert np.all(span >= 0.6 * (robot.workspace.upper - robot.workspace.lower))


def test_calibrate_refuses_a_correction_beyond_the_prior(calibration, tmp_path, capsys):
    """A file stated to be right within 1 mm per axis (--reels-prior 0.001) whose exits are
    off by ~1 cm: the fit's corrections exceed 4 x that, named per reel; nothing written."""
    tmp, run, _ = calibration
    out = tmp_path / "x.yaml"
    code = cdpm(["calibrate", str(run), "--robot", "paper_7cable", "--out", str(out),
                 "--reels-prior", "0.001"])
    err = capsys.readouterr().err
    assert code == 1 and "more than 4 x the prior's 1 mm" in err and not out.exists()


def test_a_calibrated_file_raises_the_kinetostatic_floor_by_its_tension_error(calibration):
    """The kinetostatic floor the filter keeps gains 2 x geometry_tension_error at the start
    pose (tests/kernels/test_kinetostatics.py checks that bound against perturbed robots)."""
    from cdpm_drake.diagram import kinetostatic_block_params
    from cdpm_drake.kernels.kinetostatics import geometry_tension_error, wrench_rows

    tmp, run, out = calibration
    resolved = resolve_scenario(load_scenario("exp2_interaction", f"{{robot: {out}}}"))
    plain = resolve_scenario(load_scenario("exp2_interaction"))
    robot = resolved.robot
    expected = 2.0 * geometry_tension_error(
        robot, np.asarray(resolved.scenario.initial_position), wrench_rows(robot),
        robot.uncertainty.cable_std(), float(resolved.scenario.controller.max_tension))
    assert resolved.kinetostatic_margin == pytest.approx(expected, rel=1e-12) and expected > 0
    assert plain.kinetostatic_margin == 0.0
    from cdpm_drake.kernels.kinetostatics import P_FLOOR

    floor = float(resolved.scenario.safety_filter.kinetostatic_floor)
    assert kinetostatic_block_params(resolved)[P_FLOOR] == pytest.approx(floor + expected)
    assert kinetostatic_block_params(plain)[P_FLOOR] == floor


def _dwell_poses(log, count=3, noise=2e-4, seed=0):
    """`count` of the shipped motion's holds (0.3 s before each departure), those where the
    plant's TRUE platform is still (< 2 mm/s), the set farthest apart (the largest triangle),
    as a laser tracker would measure them: the true position plus `noise` per axis."""
    import itertools

    from cdpm_drake.data import SCENARIOS_DIR

    times = np.asarray(load_scenario(str(SCENARIOS_DIR / "calibration_motion.yaml"))
                       .operator.times)[3::2] - 0.3
    t, p = log["time"], log["p_true"]
    k = np.array([int(np.argmin(np.abs(t - x))) for x in times])
    still = np.linalg.norm(p[k + 50] - p[k - 50], axis=1) / (t[k + 50] - t[k - 50]) < 2e-3
    k, times = k[still], times[still]
    best = max(itertools.combinations(range(len(k)), count),
               key=lambda c: np.linalg.norm(np.cross(p[k[c[1]]] - p[k[c[0]]],
                                                     p[k[c[2]]] - p[k[c[0]]])))
    rng = np.random.default_rng(seed)
    return [{"time": float(times[j]), "position": (p[k[j]] + rng.normal(0, noise, 3)).tolist(),
             "std": noise, "_true": p[k[j]]} for j in best]


def _write_poses(path, poses):
    path.write_text(yaml.safe_dump({"poses": [{k: v for k, v in x.items() if k != "_true"}
                                              for x in poses]}))
    return path


def test_measured_poses_identify_the_exits_absolutely(calibration, tmp_path):
    """Three poses measured off the plant's TRUE pose with 0.2 mm noise fix the frame's turn:
    every exit within 2 mm of the truth (the log's reels_true) and reported identified;
    without them the same fit leaves the turn at the file's and identifies none (the fit
    assumes its default 0.1 mm encoders; measured: errors 0.1-0.2 mm, stds 0.33-0.43 mm)."""
    from cdpm_drake.runs.calibrate import CalibrationSettings, calibrate_runs

    tmp, run, _ = calibration
    log = load_log(run)
    poses = _write_poses(tmp_path / "poses.yaml", _dwell_poses(log))
    settings = CalibrationSettings()
    with_poses = calibrate_runs([run], "paper_7cable", settings, poses)
    without = calibrate_runs([run], "paper_7cable", settings)
    err = np.linalg.norm(with_poses.result.reels - log["reels_true"], axis=1)
    assert err.max() < 2e-3, err
    assert with_poses.result.gauge == "homing+measured" and not with_poses.problems
    assert not [n for n in with_poses.result.unidentified if n.startswith("reel")]
    assert np.all(with_poses.result.reels_std <= 5e-4)
    # Without: the turn is held, every exit reported not identified (and 2-6 mm off).
    assert all(f"reel {i} x" in without.result.unidentified for i in range(1, 8))
    assert np.linalg.norm(without.result.reels - log["reels_true"], axis=1).max() > 2e-3
    # The encoder offsets stay within 1 mm of the homing's truth.
    p0 = np.asarray(log["initial_position"])
    c_true = (np.linalg.norm(log["reels"] - p0 - log["attachments"], axis=1)
              - np.linalg.norm(log["reels_true"] - p0 - log["attachments_true"], axis=1)
              + log["encoder_zero_error"])
    assert np.abs(with_poses.result.offsets[0] - c_true).max() < 1e-3


def test_measured_poses_file_is_written_into_the_calibrated_robot(calibration, tmp_path,
                                                                  capsys):
    """Through the command: the report says the measured poses define the frame; the
    calibrated file names the poses' file and lists no exit as not identified."""
    tmp, run, _ = calibration
    poses = _write_poses(tmp_path / "poses.yaml", _dwell_poses(load_log(run)))
    out = tmp_path / "cal.yaml"
    assert cdpm(["calibrate", str(run), "--robot", "paper_7cable", "--out", str(out),
                 "--measured-poses", str(poses)]) == 0
    assert "the base frame's turn is the measured poses'" in \
        capsys.readouterr().out
    cal = yaml.safe_load(out.read_text())["calibration"]
    assert cal["measured_poses"] == str(poses)
    assert not [n for n in cal["not_identified"] if n.startswith("reel")]


def _refusal(run, poses, tmp_path, capsys):
    out = tmp_path / "never.yaml"
    code = cdpm(["calibrate", str(run), "--robot", "paper_7cable", "--out", str(out),
                 "--measured-poses", str(poses)])
    assert code == 1 and not out.exists()
    return capsys.readouterr().err


def test_a_measured_pose_far_from_the_fit_is_named(calibration, tmp_path, capsys):
    """One coordinate mistyped by 5 mm (25 of its sigmas): refused, that pose named."""
    tmp, run, _ = calibration
    poses = _dwell_poses(load_log(run))
    poses[1]["position"][2] += 0.005
    err = _refusal(run, _write_poses(tmp_path / "p.yaml", poses), tmp_path, capsys)
    assert f"measured pose 2 (run 1, t = {poses[1]['time']:g} s) is" in err
    assert "outlier" in err and "measured pose 1 (" not in err


@pytest.mark.parametrize("change, message", [
    ({"time": 500.0}, r"measured pose 1: time 500 s is outside the log of run 1"),
    ({"std": 0}, r"poses\[0\]\.std must be a number > 0 \(m\), got 0"),
    ({"run": 2}, r"measured pose 1 \(run 2, .*\): run 2, but 1 run\(s\) given"),
])
def test_bad_measured_poses_are_refused_naming_the_field(calibration, tmp_path, capsys,
                                                         change, message):
    import re

    tmp, run, _ = calibration
    poses = _dwell_poses(load_log(run))
    poses[0].update(change)
    err = _refusal(run, _write_poses(tmp_path / "p.yaml", poses), tmp_path, capsys)
    assert re.search(message, err), err


def test_a_measured_pose_while_moving_is_refused(calibration, tmp_path, capsys):
    """A time where the platform travels (the log's fastest moment): not quasi-static."""
    tmp, run, _ = calibration
    log = load_log(run)
    poses = _dwell_poses(log)
    t = log["time"]
    speed = np.linalg.norm(np.gradient(log["p"], t, axis=0), axis=1)
    poses[2]["time"] = float(t[np.argmax(speed[100:-100]) + 100])
    err = _refusal(run, _write_poses(tmp_path / "p.yaml", poses), tmp_path, capsys)
    assert "measured pose 3" in err and "not quasi-static" in err


def test_two_measured_poses_on_a_line_with_the_homing_pose_are_refused(calibration,
                                                                        tmp_path, capsys):
    """The homing pose and two poses along one line: the turn about it stays held."""
    tmp, run, _ = calibration
    log = load_log(run)
    poses = _dwell_poses(log)[:2]
    p0 = np.asarray(log["initial_position"])
    for s, x in zip((0.3, 0.6), poses):
        x["position"] = (p0 + s * (poses[0]["_true"] - p0)).tolist()
    err = _refusal(run, _write_poses(tmp_path / "p.yaml", poses), tmp_path, capsys)
    assert "2 measured pose(s) with the homing pose reach 0.0 mm off one straight line" in err
    assert "would still be held" in err
