"""`cdpm simulate`: the log.npz contract of docs/LOG_FORMAT.md, the resolved scenario beside
it, the summary, every shipped scenario through the CLI, the run-folder policy, exit codes and
signals."""

import re
import subprocess
import sys
from contextlib import redirect_stdout
from io import StringIO
from pathlib import Path

import numpy as np
import pytest

from cdpm_drake import cli
from cdpm_drake.cli.simulate import simulate_main
from cdpm_drake.cli.summaries import tension_control_summary
from cdpm_drake.config import load_scenario, scenario_names

LOG_FORMAT = Path(__file__).resolve().parents[2] / "docs" / "LOG_FORMAT.md"
T = 0.002


def log_contract():
    """{key: shape string} from the table in docs/LOG_FORMAT.md, e.g. 'p': '(T, 3)'."""
    contract = {}
    for line in LOG_FORMAT.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 2 or not cells[0].startswith("`"):
            continue
        for key in re.findall(r"`([^`]+)`", cells[0]):
            contract[key] = cells[1]
    return contract


def expected_shape(text, T_, m, P):
    names = {"T": T_, "m": m, "P": P}
    inner = text.strip("()").strip()
    if not inner:
        return ()
    return tuple(names[x] if x in names else int(x)
                 for x in (s.strip() for s in inner.split(",")) if x)


def simulate_cli(capsys, *args):
    code = cli.main(["simulate", *args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def exp1_run(tmp_path_factory):
    """One 0.2 s run of experiment 1 through the CLI, shared by the contract tests."""
    out_dir = tmp_path_factory.mktemp("exp1")
    buffer = StringIO()
    with redirect_stdout(buffer):
        code = cli.main(["simulate", "exp1_no_interaction", "--duration", "0.2", "--out",
                         str(out_dir), "--no-progress"])
    return code, buffer.getvalue(), out_dir


def test_contract_table_parses():
    contract = log_contract()
    assert {"time", "p", "F_H", "pair_distances", "pairs", "d_l", "robot_name"} <= set(contract)
    assert contract["pair_distances"] == "(T, P)"


def test_simulate_writes_every_key_of_the_log_format_with_its_shape(exp1_run):
    code, _, out_dir = exp1_run
    assert code == 0
    with np.load(out_dir / "log.npz") as data:
        log = {k: data[k] for k in data.files}
    m, P = 7, 21  # paper_7cable, no excluded pairs
    T_ = 101  # 0.2 s / 2 ms + the row at t = 0
    for key, shape in log_contract().items():
        assert key in log, f"log.npz lacks {key!r} of docs/LOG_FORMAT.md"
        assert log[key].shape == expected_shape(shape, T_, m, P), key
    np.testing.assert_allclose(log["time"], T * np.arange(T_), rtol=0, atol=1e-12)
    assert log["active"].dtype == bool and log["crossed"].dtype == bool
    assert str(log["scenario_name"]) == "exp1_no_interaction"
    assert [tuple(r) for r in log["pairs"][:3]] == [(1, 2), (1, 3), (1, 4)]
    # exp1 swaps cables 1 and 3 on the platform: the logged attachments say so.
    from cdpm_drake.robot import load_robot
    b = load_robot("paper_7cable").attachments
    np.testing.assert_array_equal(log["attachments"][[0, 2]], b[[2, 0]])


def test_resolved_scenario_is_written_beside_the_log_and_loads_back(exp1_run):
    _, _, out_dir = exp1_run
    back = load_scenario(out_dir / "scenario.yaml")
    # Everything as shipped but the duration, which is what the log covers (--duration 0.2).
    assert back == load_scenario("exp1_no_interaction", overlay_text="duration: 0.2")


def test_a_run_folder_moves_and_reruns_bit_for_bit(capsys, tmp_path, write_robot, valid_spec):
    # Issue 22, point 14: the robot file and the force CSV are copied into the run folder and
    # its scenario.yaml refers to the copies, so the folder alone reruns the run exactly.
    src = tmp_path / "src"
    src.mkdir()
    write_robot(valid_spec, "src/tetra.yaml")
    (src / "push.csv").write_text("t,fx,fy,fz\n0,0,0,0\n0.1,2,1,0\n0.3,-1,2,1\n")
    (src / "push.yaml").write_text("name: push\nrobot: tetra.yaml\ninitial_position: "
                                   "[2.0, 1.5, 1.5]\nduration: 0.3\noperator: !CsvOperator "
                                   "{path: push.csv}\nsensor: {noise_std: 0.5}\n")
    first = tmp_path / "first"
    assert simulate_cli(capsys, str(src / "push.yaml"), "--out", str(first),
                        "--no-progress")[0] == 0
    text = (first / "scenario.yaml").read_text()
    assert "robot: robot.yaml" in text and "path: force.csv" in text
    assert str(tmp_path) not in text and "base_dir" not in text  # nothing points outside
    assert (first / "robot.yaml").read_bytes() == (src / "tetra.yaml").read_bytes()
    assert (first / "force.csv").read_bytes() == (src / "push.csv").read_bytes()
    # Moved, with the originals gone, and rerun from another directory.
    moved = tmp_path / "elsewhere" / "shared"
    moved.parent.mkdir()
    first.rename(moved)
    for f in src.iterdir():
        f.unlink()
    src.rmdir()
    again = tmp_path / "again"
    assert simulate_cli(capsys, str(moved / "scenario.yaml"), "--out", str(again),
                        "--no-progress")[0] == 0
    with np.load(moved / "log.npz") as a, np.load(again / "log.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert (again / "scenario.yaml").read_text() == text
    # Into its own folder, with --force (which empties it first): the copies are kept.
    assert simulate_cli(capsys, str(moved / "scenario.yaml"), "--out", str(moved), "--force",
                        "--no-progress")[0] == 0
    assert (moved / "robot.yaml").is_file() and (moved / "scenario.yaml").read_text() == text


def test_summary_reports_ticks_and_the_logged_minimum_distances(exp1_run):
    _, out, out_dir = exp1_run
    assert re.search(r"scenario 'exp1_no_interaction' \(the hard promise: safety filter on, "
                     r"kinematic plant, translation only\): 101 ticks, 0\.200 s simulated", out), out
    assert f"log: {out_dir / 'log.npz'}" in out
    with np.load(out_dir / "log.npz") as log:
        pairs = [f"({i},{j})" for i, j in log["pairs"]]
        d_min = 1000 * log["pair_distances"].min(axis=0)
        active = log["active"].any(axis=0)
        within = log["active"].sum(axis=0)
        d_l, d_u = 1000 * log["d_l"], 1000 * log["d_u"]
    # Issue 27: "ticks active" was never defined; each pair's band is printed beside it.
    assert "pair   min distance (mm)  d_l (mm)  d_u (mm)  ticks within d_u  crossed" in out
    rows = re.findall(r"^\s*(\(\d+,\d+\))\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+(\d+)\s+([01])\s*$",
                      out, re.MULTILINE)
    assert rows  # exp1 starts with cables 1 and 3 at 57 mm, inside d_u = 61 mm
    assert {r[0] for r in rows} == {p for p, a in zip(pairs, active) if a}
    for pair, dist, low, up, ticks, _ in rows:
        k = pairs.index(pair)
        assert float(dist) == pytest.approx(d_min[k], abs=0.005)  # 0.01 mm
        # exp1's interference defaults: d_l 50 mm, d_u 61 mm (scenario file).
        assert (low, up) == (f"{d_l[k]:.2f}", f"{d_u[k]:.2f}") == ("50.00", "61.00")
        assert int(ticks) == within[k]


@pytest.mark.parametrize("name", scenario_names())
def test_every_shipped_scenario_runs_through_the_cli(capsys, tmp_path, name):
    code, out, err = simulate_cli(capsys, name, "--duration", "0.1", "--out", str(tmp_path),
                                  "--no-progress")
    assert code == 0, err
    assert (tmp_path / "log.npz").is_file() and (tmp_path / "scenario.yaml").is_file()
    assert (f"scenario {name!r} (the hard promise: safety filter on, kinematic plant, "
            "translation only): 51 ticks") in out


def test_scenario_text_overlay_reaches_the_run(capsys, tmp_path):
    code, _, err = simulate_cli(capsys, "exp2_interaction", "--duration", "0.1", "--out",
                                str(tmp_path), "--no-progress", "--scenario-text",
                                "{interference: {enabled: false}, random_seed: 9}")
    assert code == 0, err
    s = load_scenario(tmp_path / "scenario.yaml")
    assert s.interference.enabled is False and s.random_seed == 9
    with np.load(tmp_path / "log.npz") as log:
        assert not log["F_int"].any()  # no interference block: F_int is zero
        assert np.isnan(log["d_u"]).all()


def test_each_default_run_gets_its_own_folder_and_latest_points_at_the_newest(
        capsys, tmp_path, monkeypatch):
    # Issue 10, point 4: a second run never overwrites the first one's log nor shares its
    # folder (the first one's PNGs stay with the first log only).
    monkeypatch.chdir(tmp_path)
    code, out1, err = simulate_cli(capsys, "exp1_no_interaction", "--duration", "0.05",
                                   "--no-progress", "--plot")
    assert code == 0, err
    code, out2, err = simulate_cli(capsys, "exp1_no_interaction", "--duration", "0.1",
                                   "--no-progress")
    assert code == 0, err
    parent = tmp_path / "runs" / "exp1_no_interaction"
    runs = sorted(p for p in parent.iterdir() if p.name != "latest")
    assert len(runs) == 2
    first, second = runs  # UTC timestamps sort in time order
    assert f"log: {Path('runs', 'exp1_no_interaction', first.name, 'log.npz')}" in out1
    assert f"log: {Path('runs', 'exp1_no_interaction', second.name, 'log.npz')}" in out2
    with np.load(first / "log.npz") as a, np.load(second / "log.npz") as b:
        assert len(a["time"]) == 26 and len(b["time"]) == 51  # 0.05 s, 0.1 s at 500 Hz
    assert list(first.glob("*.png")) and not list(second.glob("*.png"))
    latest = parent / "latest"
    assert latest.is_symlink() and latest.resolve() == second.resolve()
    # `cdpm plot runs/<name>` plots the latest run.
    assert cli.main(["plot", str(parent)]) == 0
    assert list(second.glob("*.png"))


def test_a_non_empty_out_needs_force_which_empties_it(capsys, tmp_path):
    out_dir = tmp_path / "mine"
    code, _, err = simulate_cli(capsys, "exp1_no_interaction", "--duration", "0.05",
                                "--no-progress", "--out", str(out_dir), "--plot")
    assert code == 0, err
    assert list(out_dir.glob("*.png"))
    code, _, err = simulate_cli(capsys, "exp1_no_interaction", "--duration", "0.1",
                                "--no-progress", "--out", str(out_dir))
    assert code == 2
    assert f"--out {str(out_dir)!r} is not empty" in err and "--force" in err
    with np.load(out_dir / "log.npz") as log:
        assert len(log["time"]) == 26  # untouched
    code, _, err = simulate_cli(capsys, "exp1_no_interaction", "--duration", "0.1",
                                "--no-progress", "--out", str(out_dir), "--force")
    assert code == 0, err
    with np.load(out_dir / "log.npz") as log:
        assert len(log["time"]) == 51
    assert not list(out_dir.glob("*.png"))  # the earlier run's plots went with it
    # --force empties a run's folder only, never an unrelated one.
    other = tmp_path / "notes"
    other.mkdir()
    (other / "thesis.tex").write_text("precious")
    code, _, err = simulate_cli(capsys, "exp1_no_interaction", "--duration", "0.05",
                                "--no-progress", "--out", str(other), "--force")
    assert code == 2 and "holds no run" in err
    assert (other / "thesis.tex").read_text() == "precious"


@pytest.mark.parametrize("args", [
    ("--scenario-text", "plant: !HardwareReels {}"),          # fails inside simulate()
    ("--scenario-text", "{admittance: {mas: 1}}"),             # fails loading
    ("--duration", "-1"),                                      # a bad flag
])
def test_an_early_error_leaves_no_run_folder(capsys, tmp_path, monkeypatch, args):
    monkeypatch.chdir(tmp_path)
    code, _, err = simulate_cli(capsys, "exp1_no_interaction", "--no-progress", *args)
    assert code in (1, 2) and "error:" in err
    assert not (tmp_path / "runs").exists(), list((tmp_path / "runs").rglob("*"))


@pytest.mark.parametrize("duration", ["-1", "0", "nan", "inf"])
def test_bad_duration_exits_2_with_a_clear_message(capsys, tmp_path, duration):
    code, out, err = simulate_cli(capsys, "exp1_no_interaction", "--duration", duration,
                                  "--out", str(tmp_path), "--no-progress")
    assert code == 2
    assert "cdpm simulate: error: --duration must be a number of seconds > 0, got" in err
    assert not (tmp_path / "log.npz").exists()


def test_unknown_scenario_exits_1_listing_the_built_in_ones(capsys, tmp_path):
    # Exit 1: an error (the scenario cannot be loaded), not a malformed command line (2).
    code, out, err = simulate_cli(capsys, "exp7_teleport", "--out", str(tmp_path),
                                  "--no-progress")
    assert code == 1
    assert "unknown scenario 'exp7_teleport'" in err
    for name in ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs"):
        assert name in err
    assert "Traceback" not in err


def test_bad_overlay_exits_1_naming_the_field(capsys, tmp_path):
    code, _, err = simulate_cli(capsys, "exp1_no_interaction", "--out", str(tmp_path),
                                "--no-progress", "--scenario-text", "{admittance: {mas: 1}}")
    assert code == 1
    assert "unknown field 'admittance.mas'" in err


def test_simulate_help_through_the_installed_entry_point():
    cdpm = Path(sys.executable).parent / "cdpm"
    result = subprocess.run([str(cdpm), "simulate", "--help"], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    for option in ("--duration", "--out", "--no-progress", "--scenario-text"):
        assert option in result.stdout
    for name in ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs"):
        assert name in result.stdout


def test_an_unwritable_out_dir_is_refused_before_the_run(tmp_path, capsys):
    # A file where the directory should be: refused at once, naming the option and the path,
    # instead of losing the log of a finished run.
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    code = cli.main(["simulate", "exp1_no_interaction", "--out", str(blocker), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert "--out" in err and str(blocker) in err and "not a writable directory" in err


def test_ctrl_c_during_a_simulation_keeps_the_log(tmp_path, capsys):
    # KeyboardInterrupt raised from inside the run (here by the progress callback after the
    # first chunk, as Ctrl-C would): the ticks simulated so far are written, exit code 130.
    from cdpm_drake.config import load_scenario

    calls = {"n": 0}

    def interrupt(diagram, context):
        calls["n"] += 1
        raise KeyboardInterrupt

    scenario = load_scenario("exp1_no_interaction")
    code = simulate_main(scenario=scenario, duration=5.0, out_dir=tmp_path, progress=False,
                             on_chunk=interrupt)
    assert code == 130 and calls["n"] == 1
    assert "interrupted at t = " in capsys.readouterr().err
    log = np.load(tmp_path / "log.npz")
    assert 0.0 < log["time"][-1] < 5.0
    # The scenario written beside it says how long the log is, so it reproduces the run.
    assert f"duration: {log['time'][-1]}" in (tmp_path / "scenario.yaml").read_text()


def test_meshcat_runs_log_the_last_tick_too(capsys, tmp_path):
    # Issue 10, point 7: --meshcat advances in 0.04 s chunks; summed in floating point they
    # ended a hair short of 10 s and the last tick was never logged (5000 rows, not 5001).
    code, out, err = simulate_cli(capsys, "exp1_no_interaction", "--meshcat", "--no-wait",
                                  "--realtime", "1000", "--duration", "10", "--out",
                                  str(tmp_path), "--no-progress")
    assert code == 0, err
    assert "Meshcat: open http://" in err
    assert "5001 ticks" in out  # ticks 0..5000
    with np.load(tmp_path / "log.npz") as log:
        assert log["time"].size == 5001 and log["time"][-1] == pytest.approx(10.0, abs=1e-12)


@pytest.mark.parametrize("duration, chunk", [(25.0, 0.04), (5.0, 0.02), (10.0, 0.5),
                                             (0.0031, 0.5)])
def test_tick_targets_end_exactly_on_the_last_whole_tick(duration, chunk):
    from cdpm_drake.runs.simulate import tick_targets

    targets = tick_targets(duration, T, chunk)
    n = int(np.floor(duration / T + 1e-9))  # the last whole tick inside the duration
    assert targets[-1] == n * T  # exactly: Drake then handles tick n's events
    assert np.all(np.diff(targets) > 0)
    assert np.allclose(np.diff(targets)[:-1], max(1, round(chunk / T)) * T)


def test_latest_points_at_a_run_as_it_starts_and_back_if_it_writes_nothing(tmp_path):
    from cdpm_drake.runs.run_folder import RunFolder

    root = tmp_path / "runs"
    first = RunFolder("exp", root=root)
    a = first.create()
    (a / "log.npz").write_bytes(b"x")
    latest = root / "exp" / "latest"
    assert latest.resolve() == a.resolve()
    second = RunFolder("exp", root=root)
    b = second.create()
    # While it runs (and if it is killed), the newest run is the latest.
    assert latest.resolve() == b.resolve() and a != b
    second.discard()  # it wrote nothing
    assert not b.exists() and latest.resolve() == a.resolve()
    first.discard()  # wrote a log: kept
    assert a.is_dir()
    # A lone run that writes nothing leaves no runs/ at all.
    lone = RunFolder("other", root=tmp_path / "fresh")
    lone.create()
    lone.discard()
    assert not (tmp_path / "fresh").exists()


@pytest.mark.parametrize("overlay, words, tag", [
    ("{}", "the hard promise: safety filter on, kinematic plant, translation only", ""),
    # Issue 32: the paper's method in one word, named first and in the folder.
    ("method: paper", "the paper's method: no safety filter, kinematic plant, translation only",
     "-paper"),
    ("safety_filter: {enabled: false}", "safety filter off, kinematic plant, translation only",
     "-no-filter"),
    ("plant: !DynamicReels {}", "the hard promise: safety filter on, dynamic plant, "
     "translation only", "-dynamic"),
    ("{plant: !DynamicReels {}, controller: {pose: full}}", "the hard promise: safety filter "
     "on, dynamic plant, full pose", "-dynamic-full-pose"),
    ("{plant: !DynamicReels {}, controller: {pose: full, tension_control: true}}",
     "the hard promise: safety filter on, dynamic plant, full pose, tension control",
     "-dynamic-full-pose-tension-control")])
def test_a_runs_variant_is_named_in_its_summary_and_its_folder(capsys, tmp_path, monkeypatch,
                                                              overlay, words, tag):
    # Issue 27: runs of the dynamic plant or the full pose were indistinguishable from the
    # default's in runs/<scenario>/; `latest` still points at the newest.
    monkeypatch.chdir(tmp_path)
    code, out, err = simulate_cli(capsys, "exp2_interaction", "--duration", "0.01",
                                  "--no-progress", "--scenario-text", overlay)
    assert code == 0, err
    assert out.startswith(f"scenario 'exp2_interaction' ({words}): 6 ticks"), out
    (folder,) = [p for p in (tmp_path / "runs" / "exp2_interaction").iterdir()
                 if p.name != "latest"]
    # Issue 32: an overlay shows in the name too (its hash: the overlay is in scenario.yaml).
    from cdpm_drake.runs.run_folder import overlay_tag
    text = overlay_tag(overlay)
    assert (text == "") == (overlay == "{}")
    tag = tag + (f"-{text}" if text else "")
    assert re.fullmatch(r"\d{8}T\d{6}\.\d{3}Z" + re.escape(tag), folder.name), folder.name
    latest = tmp_path / "runs" / "exp2_interaction" / "latest"
    assert latest.resolve() == folder.resolve()
    assert f"log: runs/exp2_interaction/{folder.name}/log.npz" in out


def test_two_runs_in_one_millisecond_keep_their_variant_last(tmp_path, monkeypatch):
    from cdpm_drake.runs import run_folder

    monkeypatch.setattr(run_folder, "utc_stamp", lambda: "20261201T211039.123Z")
    first = run_folder.RunFolder("exp", root=tmp_path, variant="dynamic").create()
    second = run_folder.RunFolder("exp", root=tmp_path, variant="dynamic").create()
    assert (first.name, second.name) == ("20261201T211039.123Z-dynamic",
                                         "20261201T211039.123Z-2-dynamic")


def test_a_hand_force_beyond_the_sensor_range_is_warned_once_and_counted(capsys, tmp_path):
    # Issue 22, point 12. The CSV ramps the force along x from 0 N at t = 0 to 1e9 N at 1 s and
    # back to 1 N at 2 s (held after): beyond the sensor's 80 N across its axis (z) from the
    # first tick after 0 (2e6 N at 2 ms) to t < 2 - 79 / (1e9 - 1) s, i.e. ticks 1 to 999.
    (tmp_path / "big.csv").write_text("t,fx,fy,fz\n0,0,0,0\n1,1e9,0,0\n2,1,0,0\n")
    code, out, err = simulate_cli(capsys, "exp1_no_interaction", "--duration", "3",
                                  "--no-progress", "--out", str(tmp_path / "run"),
                                  "--scenario-text", "operator: !CsvOperator {path: "
                                  f"{tmp_path / 'big.csv'}}}")
    assert code == 0
    assert err.count("beyond the sensor's range") == 1, err  # warned once, before the run
    assert f"'{tmp_path / 'big.csv'}' line 3: the hand force [1000000000.0, 0.0, 0.0] N is " \
           "beyond the sensor's range (axial 100 N, transverse 80 N)" in err, err
    assert ("hand force beyond the sensor's range (axial 100 N, transverse 80 N), clipped: "
            "999 of 1501 ticks, the first at t = 0.002 s" in out), out
    with np.load(tmp_path / "run" / "log.npz") as log:
        assert log["F_measured"][250, 0] == pytest.approx(5e8)  # raw, at 0.5 s: logged
        assert np.abs(log["F_H"]).max() <= 80.0 + 1e-9  # what the controller saw: clipped
    # Within the range: no warning, no summary line.
    code, out, err = simulate_cli(capsys, "exp2_interaction", "--duration", "0.1",
                                  "--no-progress", "--out", str(tmp_path / "calm"))
    assert code == 0 and "sensor's range" not in out + err


def test_the_tension_summary_counts_each_status_and_names_its_cables():
    """A synthetic log of 10 ticks: statuses 0 0 1 1 1 3 3 4 2 0 naming cables 0 0 7 7 6 2 2
    5 0 0 (1-based, 0 none), t* per tick as below (inf where an internal force raises every
    tension; -1.5 N outside the wrench-feasible workspace). Counted by hand: held 3 of 10;
    lowered 3 (smallest t* 4.00 N; cable 7 twice, 6 once); ceiling 2 (t* inf: none printed;
    cable 2 twice); unreachable 1 (t* -1.50; cable 5); rank-deficient 1 (nothing raised:
    none named); one tick below t* = 0."""
    log = {"tension_status": np.array([0, 0, 1, 1, 1, 3, 3, 4, 2, 0], dtype=float)[:, None],
           "tension_cable": np.array([0, 0, 7, 7, 6, 2, 2, 5, 0, 0], dtype=float)[:, None],
           "t_star": np.array([20, 20, 4, 5, 6, np.inf, np.inf, -1.5, 3, 20.0])[:, None],
           "tension_estimate": np.array([[2.5, 40.0]] * 10)}
    assert tension_control_summary(log) == (
        "tension control: the floor held on 3 of 10 ticks; lowered to what the pose and the "
        "ceiling allow on 3 (smallest t* 4.00 N; weakest cable: 7 (2 ticks), 6 (1 tick)); "
        "above controller.max_tension to keep every cable at controller.tension_floor on 2 "
        "(cable above the ceiling: 2 (2 ticks)); the pose cannot hold every cable at "
        "controller.tension_floor (t* below it), weak cables raised to it on 1 (smallest t* "
        "-1.50 N; cable raised most: 5 (1 tick)); the wrench matrix rank-deficient "
        "(minimum-norm target) on 1 (smallest t* 3.00 N; cable raised most: none named); NO "
        "tension distribution held on 1 ticks (t* < 0: outside the wrench-feasible "
        "workspace, a cable must go slack); estimated tensions 2.50 to 40.0 N")

def test_plot_html_keeps_the_figures_already_drawn_from_the_log(capsys, tmp_path):
    # Issue 27: `cdpm plot LOG --html FILE` redrew every PNG. Now the replay is written and
    # only the figures missing (cables.png, deleted) or older than the log (forces.png) are
    # drawn; the others keep their bytes and times.
    import os

    run = tmp_path / "run"
    assert cli.main(["simulate", "exp1_no_interaction", "--duration", "0.02", "--out",
                     str(run), "--no-progress", "--plot"]) == 0
    log_time = (run / "log.npz").stat().st_mtime
    pngs = sorted(run.glob("*.png"))
    assert len(pngs) == 6  # the paper's five and the safety filter's
    for png in pngs:  # drawn 100 s after the log: no file system's clock can tie that
        os.utime(png, (log_time + 100.0, log_time + 100.0))
    os.utime(run / "forces.png", (log_time - 100.0, log_time - 100.0))
    (run / "cables.png").unlink()
    capsys.readouterr()
    assert cli.main(["plot", str(run), "--html", str(tmp_path / "replay.html")]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "replay.html").stat().st_size > 10_000
    assert f"plot: 4 figure(s) already drawn from this log kept in {run}" in out
    assert sorted(re.findall(r"^plot: (\S+\.png)$", out, flags=re.M)) == [
        str(run / "cables.png"), str(run / "forces.png")]
    for name in ("distances.png", "trajectory.png", "logistic.png", "safety.png"):
        assert (run / name).stat().st_mtime == log_time + 100.0, name
    assert (run / "forces.png").stat().st_mtime > log_time
    # Without --html, `cdpm plot` draws them all, as before.
    assert cli.main(["plot", str(run)]) == 0
    assert len(re.findall(r"^plot: ", capsys.readouterr().out, flags=re.M)) == 6


def test_safety_filter_and_model_monitor_summaries_count_each_code():
    """Synthetic log of 6 ticks: statuses 0, 1, 1, 2, 3, 0 with binding bits 0, 1|8, 4, 1,
    0, 0 (safety_filter.BIND_*: pairs 1, kinetostatic 4, speed 8); pair margins down to
    -0.5 mm; a true distance 1.25 mm below d_min on one tick; kappa down to -0.25 N. The
    monitor: slack from tick 4 (t = 0.008 s), the largest residual -3 mm on cable 2."""
    from cdpm_drake.cli.summaries import model_monitor_summary, safety_filter_summary

    log = {"time": np.arange(6) * 0.002,
           "filter_status": np.array([[0], [1], [1], [2], [3], [0]]),
           "filter_binding": np.array([[0], [9], [4], [1], [0], [0]]),
           "pair_margin": np.array([[0.01], [0.002], [-0.0005], [0.0], [0.001], [0.003]]),
           "kappa": np.array([[5.0], [2.0], [-0.25], [np.nan], [1.0], [3.0]]),
           "d_min": np.array([0.05, 0.06]),
           "pair_distances_true": np.full((6, 2), 0.1),
           # At the speed limit on the tick that binds it (a cap below it is named apart).
           "velocity": np.tile([0.5, 0.0, 0.0], (6, 1)), "max_velocity": np.array(0.5)}
    log["pair_distances_true"][2, 1] = 0.06 - 0.00125
    assert safety_filter_summary(log) == (
        "safety filter: passed 2 of 6 ticks, changed 2 (bound: cable pairs 2, kinetostatic "
        "limit 1, speed limit 1), held a lost margin (not restored) on 1, braked to a hold on "
        "1; pair margin LOST on 1 tick (from 0.004 to 0.004 s), down to -0.50 mm; kinetostatic "
        "margin LOST on 1 tick (from 0.004 to 0.004 s), down to -0.25 N; smallest pair margin "
        "above d_min -0.50 mm (true -1.25 mm); smallest kinetostatic margin -0.25 N")
    residual = np.zeros((6, 3))
    residual[3, 1] = -0.003
    residual[1, 2] = 0.001
    monitor = {"time": log["time"], "model_status": np.array([[0], [0], [0], [0], [1], [1]]),
               "model_residual": residual}
    assert model_monitor_summary(monitor) == (
        "model monitor: slack cable at t = 0.008 s (2 of 6 ticks); largest length residual "
        "-3.00 mm (cable 2)")
    monitor["model_status"][:] = 0
    assert model_monitor_summary(monitor).startswith(
        "model monitor: the model fitted on all 6 ticks;")


def test_the_smallest_pair_margin_names_its_pair_and_its_distance_beside_the_table():
    # A hardware summary printed a minimum distance of 58.03 mm in the pair table beside
    # "smallest pair margin above d_min 0.81 mm": two different numbers with no word of which
    # is which. The margin is a distance less the pair's d_min (here pair (5,7)'s 50 mm, under
    # its d_l), the table's the distance itself; the line now names the pair closest to its
    # d_min with its distance. Two pairs: (1,3) down to 58.03 mm against d_min 50 mm (8.03 mm
    # above), (5,7) down to 50.83 mm against d_min 50 mm (0.83 mm above, at t = 0.004 s).
    from cdpm_drake.cli.summaries import safety_filter_summary

    log = {"time": np.arange(4) * 0.002, "filter_status": np.zeros((4, 1)),
           "filter_binding": np.zeros((4, 1)),
           "pair_margin": np.array([[0.01], [0.002], [0.00081], [0.003]]),
           "kappa": np.full((4, 1), 5.0), "velocity": np.zeros((4, 3)),
           "max_velocity": np.array(0.5), "pairs": np.array([[1, 3], [5, 7]]),
           "d_min": np.array([0.05, 0.05]),
           "pair_distances": np.array([[0.06, 0.06], [0.05803, 0.055], [0.059, 0.05083],
                                       [0.06, 0.052]])}
    text = safety_filter_summary(log)
    assert ("smallest pair margin above d_min 0.81 mm (a distance less its pair's d_min, at "
            "the filter's smoothed position; the pair table's distances are the distances "
            "themselves: the closest to its d_min was (5,7), 50.83 mm at t = 0.004 s against "
            "d_min 50.00 mm)") in text, text
