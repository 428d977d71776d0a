"""cdpm sweep: the sweep file, field paths, metrics, local runs, resume, failures, signals.

Runs are 0.1-0.2 s of simulated time with few variants, to keep the suite fast.
"""

import csv
import functools
import math
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

import sweep_hooks
from conftest import default_signals
from cdpm_drake.runs import sweep as sw
from cdpm_drake.cli import main
from cdpm_drake.config import Interference, Logistic, PairLogistic, Scenario, load_scenario
from helpers_synthetic_log import TICK, synthetic_log

TESTS = Path(__file__).resolve().parents[1]
REPO = TESTS.parent

SMALL = """\
name: small
base: exp2_interaction
overlay: {duration: 0.2}
axes:
  - {field: interference.default.F_u, values: [2.0, 4.0]}
  - {field: admittance.damping, linspace: [5.0, 7.0, 2]}
"""


def write(tmp_path, text, name="sweep.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def csv_rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def without_timing(rows):
    return [{k: v for k, v in r.items() if k not in ("wall_s", "rtf")} for r in rows]


# --- The sweep file and its variants ---------------------------------------------------------


def test_grid_expands_to_the_product_in_order(tmp_path):
    s = sw.load_sweep(write(tmp_path, SMALL))
    # 2 values x linspace(5, 7, 2) = [5, 7]: four variants, the last axis fastest.
    assert [tuple(v.values.values()) for v in s.variants] == [
        (2.0, 5.0), (2.0, 7.0), (4.0, 5.0), (4.0, 7.0)]
    for v in s.variants:
        assert v.scenario.interference.default.F_u == v.values["interference.default.F_u"]
        assert v.scenario.admittance.damping == v.values["admittance.damping"]
        assert v.scenario.duration == 0.2  # the overlay reached every variant
        assert v.scenario.admittance.mass == 6.25  # untouched fields keep the base's
    assert len({v.run for v in s.variants}) == 4


def test_run_ids_follow_the_values_not_the_position(tmp_path):
    """Adding an axis value keeps the ids (and hashes) of the variants that were there."""
    a = sw.load_sweep(write(tmp_path, SMALL))
    b = sw.load_sweep(write(tmp_path, SMALL.replace("[2.0, 4.0]", "[1.0, 2.0, 4.0]"), "b.yaml"))
    ids_a = {v.run: v.scenario_hash for v in a.variants}
    ids_b = {v.run: v.scenario_hash for v in b.variants}
    assert len(ids_b) == 6 and all(ids_b[r] == h for r, h in ids_a.items())


def test_pair_override_path_creates_or_edits_the_override(tmp_path):
    base = tmp_path / "base.yaml"
    base.write_text("""\
name: with_pairs
swaps: [[1, 3]]
initial_position: [1.56, 3.24, 1.22]
duration: 0.2
interference:
  default: {d_l: 0.060, d_u: 0.062, F_u: 3.0, eps: 0.1}
  pairs: [{pair: [5, 7], d_u: 0.07}]
""")
    s = sw.load_sweep(write(tmp_path, """\
base: base.yaml
axes:
  - {field: "interference.pairs[1,3].d_u", values: [0.063, 0.064]}
  - {field: "interference.pairs[7,5].F_u", values: [2.5]}
"""))
    for v, d_u in zip(s.variants, (0.063, 0.064)):
        pairs = {tuple(p.pair): p for p in v.scenario.interference.pairs}
        assert pairs[(1, 3)].d_u == d_u and pairs[(1, 3)].F_u is None  # created
        # (5, 7) edited in place ([7,5] names the same pair): its d_u override is kept.
        assert pairs[(5, 7)].d_u == 0.07 and pairs[(5, 7)].F_u == 2.5
        assert v.scenario.interference.default.d_u == 0.062


def test_union_and_list_paths_keep_what_the_base_has(tmp_path):
    """operator.max_force edits the base's SpringHandOperator (an untagged overlay would
    replace it by the first operator type); initial_position[2] edits one coordinate; an
    integer field takes a linspace of whole numbers."""
    s = sw.load_sweep(write(tmp_path, """\
base: exp2_interaction
overlay: {duration: 0.2}
axes:
  - {field: operator.max_force, values: [4.0]}
  - {field: "initial_position[2]", values: [1.25]}
  - {field: sensor.filter_window, linspace: [4, 8, 2]}
"""))
    base = load_scenario("exp2_interaction")
    for v, window in zip(s.variants, (4, 8)):
        op = v.scenario.operator
        assert type(op).__name__ == "SpringHandOperator" and op.max_force == 4.0
        assert op.waypoints == base.operator.waypoints
        assert v.scenario.initial_position == [1.56, 3.24, 1.25]
        assert v.scenario.sensor.filter_window == window
        assert isinstance(v.scenario.sensor.filter_window, int)


def test_a_left_out_start_is_each_variant_s_own_robot_centre(tmp_path):
    # Issue 22, point 10: a base without initial_position starts every variant at the centre
    # of its robot's workspace box (robot files: paper_7cable [1.75, 2.4, 1.35] m,
    # cube_8cable [2.0, 1.5, 1.5] m), also when an axis changes the robot, and a coordinate
    # axis edits that centre.
    write(tmp_path, "name: free\nduration: 0.1\n", name="free.yaml")
    s = sw.load_sweep(write(tmp_path, "name: robots\nbase: free.yaml\naxes:\n"
                                      "  - {field: robot, values: [paper_7cable, cube_8cable]}\n"))
    assert [v.scenario.initial_position for v in s.variants] == [[1.75, 2.4, 1.35],
                                                                [2.0, 1.5, 1.5]]
    assert "initial_position: [2.0, 1.5, 1.5]" in s.variants[1].scenario_yaml  # as it ran
    s = sw.load_sweep(write(tmp_path, "name: z\nbase: free.yaml\naxes:\n"
                                      '  - {field: "initial_position[2]", values: [1.0]}\n'))
    assert s.variants[0].scenario.initial_position == [1.75, 2.4, 1.0]


def test_random_samples_are_seeded_and_in_range(tmp_path):
    text = """\
base: exp2_interaction
overlay: {duration: 0.2}
random: {count: 6, seed: 3, ranges: {admittance.mass: [2.0, 10.0], sensor.filter_window: [2, 5]}}
seeds: [1, 2]
"""
    a = sw.load_sweep(write(tmp_path, text))
    b = sw.load_sweep(write(tmp_path, text, "again.yaml"))
    assert len(a.variants) == 12  # 6 samples x 2 seeds
    assert [v.values for v in a.variants] == [v.values for v in b.variants]
    for v in a.variants:
        assert 2.0 <= v.scenario.admittance.mass <= 10.0
        assert v.scenario.sensor.filter_window in (2, 3, 4, 5)
    assert [v.random_seed for v in a.variants[:4]] == [1, 2, 1, 2]


def test_explicit_variants_cross_the_grid(tmp_path):
    s = sw.load_sweep(write(tmp_path, """\
base: exp2_interaction
overlay: {duration: 0.2}
axes: [{field: interference.default.F_u, values: [2.0, 3.0]}]
variants: [{admittance: {damping: 3.0}}, {limits: {max_velocity: 0.2}}]
"""))
    assert len(s.variants) == 4
    assert s.variants[0].scenario.admittance.damping == 3.0
    assert s.variants[1].scenario.limits.max_velocity == 0.2
    assert "variant" in sw.columns_for(s)


@pytest.mark.parametrize("text, expected", [
    (SMALL + "colour: red\n", "unknown field 'colour'"),
    (SMALL.replace("admittance.damping", "admittance.dampnig"),
     "unknown field 'dampnig'; did you mean 'damping'? (valid fields there: ['mass', "
     "'damping'])"),
    (SMALL.replace("linspace: [5.0, 7.0, 2]", "values: [5.0], linspace: [5.0, 7.0, 2]"),
     "needs exactly one of values, linspace, geomspace"),
    (SMALL.replace("[2.0, 4.0]", "[2.0, 2.0]"), "lists 2.0 twice"),
    (SMALL.replace("base: exp2_interaction", "base: exp9"), "unknown scenario 'exp9'"),
    (SMALL + "metric: speed\n", "metric 'speed' is not a metric"),
    (SMALL.replace("{duration: 0.2}", "{duration: 0.2, plant: !HardwareReels {}}"),
     "plant is !HardwareReels; a sweep simulates"),
    (SMALL + "metric: min_distance_pair\n", "valid metrics: ['min_distance', "),
    (SMALL + "seeds: [a]\n", "seeds[0] must be an integer, got 'a'"),
    (SMALL.replace("linspace: [5.0, 7.0, 2]", "linspace: [5.0, 7.0, 2.5]"),
     "must be [start, stop, count] with an integer count in 1..100,000"),
    # Issue 42: a count beyond the variants a sweep may have is refused before a single value
    # is made (np.linspace of 1e12 values: 8 TB).
    (SMALL.replace("linspace: [5.0, 7.0, 2]", "linspace: [5.0, 7.0, 1e12]"),
     "axes[1].linspace must be [start, stop, count] with an integer count in 1..100,000, got "
     "[5.0, 7.0, 1000000000000.0]"),
    (SMALL + "random: {count: 1000000000, seed: 1, ranges: {admittance.mass: [2.0, 10.0]}}\n",
     "random.count must be an integer in 1..100,000, got 1000000000"),
    # Its results go to runs/sweeps/<name>/: `../../x` would write two folders above.
    (SMALL.replace("name: small", "name: ../../x"),
     "name must be one folder name of letters, digits, '_', '-', '.' and '+' (it is written "
     "to runs/sweeps/<name>/; no '/', '\\', spaces or '..'), got '../../x'"),
    # Issue 22, point 5: an empty list is a list given, and a NaN value is spelled out.
    (SMALL.replace("linspace: [5.0, 7.0, 2]", "values: []"),
     "axes[1].values (admittance.damping) is empty: list at least one value"),
])
def test_bad_sweep_file_is_reported(tmp_path, text, expected):
    with pytest.raises(sw.SweepError) as e:
        sw.load_sweep(write(tmp_path, text))
    assert expected in str(e.value)


def test_rejected_value_names_the_variant_before_any_run(tmp_path, capsys):
    # F_u = -1 is rejected by the scenario's own check (InterferenceParams), for variant 2 only.
    path = write(tmp_path, SMALL.replace("[2.0, 4.0]", "[2.0, -1.0]"))
    out = tmp_path / "out"
    # Exit 1: an error in the sweep file (2 is for a malformed command line).
    assert main(["sweep", str(path), "--out", str(out), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "variant 3 (run r" in err
    assert "interference.default.F_u=-1.0, admittance.damping=5.0" in err
    assert "F_u" in err and "-1" in err
    assert not (out / "runs").exists() and not (out / "results.csv").exists()


def test_a_nan_axis_value_is_spelled_out_in_the_variant(tmp_path):
    # Issue 22, point 5: not `interference.default.F_u=` (an empty CSV cell).
    with pytest.raises(sw.SweepError) as e:
        sw.load_sweep(write(tmp_path, SMALL.replace("[2.0, 4.0]", "[2.0, .nan]")))
    assert "(run r" in str(e.value)
    assert "interference.default.F_u=nan, admittance.damping=5.0)" in str(e.value)
    assert "interference.default.F_u must be a finite number, got nan" in str(e.value)


def test_unknown_pair_names_the_robot_pairs(tmp_path):
    with pytest.raises(sw.SweepError) as e:
        sw.load_sweep(write(tmp_path, SMALL.replace(
            "admittance.damping, linspace: [5.0, 7.0, 2]",
            '"interference.pairs[1,9].d_u", values: [0.07]')))
    assert "[1, 9]" in str(e.value) and "not a cable pair of robot" in str(e.value)
    assert "variant 1" in str(e.value)


def test_shipped_sweep_is_valid_and_resolves_by_name():
    s = sw.load_sweep("exp2_du_Fu")
    assert s.fields == ["interference.default.d_u", "interference.default.F_u"]
    assert len(s.variants) >= 25
    assert (REPO / "cdpm_drake" / "data" / "sweeps" / "exp2_du_Fu.yaml").resolve() == s.path.resolve()


def test_shipped_dynamic_sweep_runs_every_variant_on_the_dynamic_plant():
    # Issue 21: exp2_du_Fu's grid on `!DynamicReels`; its first 10 s of the push.
    from cdpm_drake.config import DynamicReels

    s = sw.load_sweep("exp2_dynamic_du_Fu")
    kinematic = sw.load_sweep("exp2_du_Fu")
    assert s.fields == kinematic.fields
    assert [v.values for v in s.variants] == [v.values for v in kinematic.variants]
    for variant in s.variants:
        assert isinstance(variant.scenario.plant, DynamicReels)
        assert variant.scenario.duration == 10.0
    assert s.file.metric == "min_distance_true"  # the truth, from the rotated platform


# --- Metrics ---------------------------------------------------------------------------------


def _synthetic_scenario():
    """The interference parameters of helpers_synthetic_log: EXP1 everywhere, EXP3 on (5,7)."""
    return Scenario(swaps=[[1, 3]], interference=Interference(
        default=Logistic(d_l=0.050, d_u=0.061, F_u=2.0, eps=0.1),
        pairs=[PairLogistic(pair=[5, 7], d_l=0.057, d_u=0.062, F_u=2.0, eps=0.1)]))


@pytest.mark.parametrize("interference", [True, False])
def test_metrics_of_a_closed_form_log(interference):
    # d13 goes linearly from 45.1 mm to 70.1 mm over 1 s, so it is below d_l = 50 mm for
    # t < 0.196 s: ticks 0..97, 98 ticks of 2 ms (left sums). (5,7) stays above its 57 mm.
    log = synthetic_log(duration=1.0, d13=(0.0451, 0.0701), crossed_ticks=5,
                        interference=interference)
    log["velocity_admittance"][100:150] *= 2.0  # a limit "acts" on ticks 100..149
    m = sw.run_metrics(log, _synthetic_scenario())
    assert m["min_distance"] == pytest.approx(0.0451, abs=1e-15)
    assert m["min_distance_pair"] == "1-3"
    assert m["time_below_d_l"] == pytest.approx(98 * TICK, rel=1e-12)
    assert m["limit_time"] == pytest.approx(50 * TICK, rel=1e-12)
    # |F_H| = sqrt(45 + 28 sin^2(2 pi t)) N over one period; the left sum of a smooth periodic
    # function over whole periods is exact to round-off, so quad is the reference.
    effort, _ = quad(lambda t: math.sqrt(45.0 + 28.0 * math.sin(2 * math.pi * t) ** 2), 0, 1,
                     epsabs=1e-13)
    assert m["operator_effort"] == pytest.approx(effort, rel=1e-10)
    # The platform moves from [1.77, 3.65, 1.22] to [1.90, 3.55, 1.05] in 1 s at constant speed.
    assert m["peak_speed"] == pytest.approx(np.linalg.norm([0.13, -0.10, -0.17]), rel=1e-9)
    assert m["sim_s"] == pytest.approx(1.0)
    if interference:
        assert m["crossings"] == 1
    else:
        assert math.isnan(m["crossings"])  # no interference block: no crossing flags


def _dynamic_log():
    """synthetic_log (1 s, 501 ticks) with the dynamic plant's truth written in closed form:
    tensions 20 N but cable 6 at 3.25 N on tick 123; cables 2 and 7 slack together on ticks
    10-19 and cable 2 alone on ticks 15-29 (20 ticks with a slack cable, 35 cable-ticks);
    the platform level but at tick 300 rolled by 0.03 rad and pitched by 0.04 rad (a rotation
    of 0.05 rad from level, sqrt(0.03^2 + 0.04^2) to first order); pair 5-7 truly closest
    (41.5 mm at tick 250), pairs 1-3 and 2-4 truly crossed (1-3 on two separate spells)."""
    log = synthetic_log(duration=1.0)
    T, m = len(log["time"]), 7
    pairs = [tuple(p) for p in log["pairs"]]
    log["tensions"] = np.full((T, m), 20.0)
    log["tensions"][123, 5] = 3.25
    log["slack"] = np.zeros((T, m), dtype=bool)
    log["slack"][10:20, [1, 6]] = True
    log["slack"][15:30, 1] = True
    log["p_true"] = log["p"].copy()
    log["rpy_true"] = np.zeros((T, 3))
    log["rpy_true"][300] = [0.03, 0.04, 0.0]
    log["rpy_true"][301] = [0.01, 0.0, 0.0]
    log["pair_distances_true"] = np.full((T, len(pairs)), 0.2)
    log["pair_distances_true"][250, pairs.index((5, 7))] = 0.0415
    log["pair_distances_true"][400, pairs.index((1, 3))] = 0.0420
    log["crossed_true"] = np.zeros((T, len(pairs)), dtype=bool)
    log["crossed_true"][100:110, pairs.index((1, 3))] = True
    log["crossed_true"][200:205, pairs.index((1, 3))] = True
    log["crossed_true"][300, pairs.index((2, 4))] = True
    return log


def test_the_dynamic_plant_s_metrics_follow_their_definitions_and_units():
    # Issue 27: no test read these. Each from the closed form of _dynamic_log, in the unit
    # of docs/SWEEP_FORMAT.md: ticks (not cable-ticks, not seconds), N, degrees, m, pairs.
    log = _dynamic_log()
    m = sw.run_metrics(log, _synthetic_scenario())
    assert m["slack_ticks"] == 20 and isinstance(m["slack_ticks"], int)
    assert m["min_tension"] == 3.25
    # The rotation from level of R = Rz(0) Ry(0.04) Rx(0.03): its angle is
    # arccos((trace R - 1) / 2), trace R = cos 0.04 + cos 0.03 + cos 0.03 cos 0.04.
    trace = math.cos(0.04) + math.cos(0.03) + math.cos(0.03) * math.cos(0.04)
    angle = math.degrees(math.acos((trace - 1.0) / 2.0))
    assert angle == pytest.approx(2.8647, abs=1e-4)  # ~ sqrt(0.03^2 + 0.04^2) rad in degrees
    assert m["max_rotation"] == pytest.approx(angle, rel=1e-9)
    assert m["min_distance_true"] == 0.0415 and m["min_distance_true_pair"] == "5-7"
    assert m["crossings_true"] == 2  # pairs, not ticks (16) nor spells (3)
    # The controller's side of the same log: unchanged by the truth.
    assert m["min_distance"] == pytest.approx(0.045, abs=1e-12)
    assert m["min_distance_pair"] == "1-3"
    # Without the truth (the kinematic plant) every truth metric is empty.
    plain = sw.run_metrics(synthetic_log(duration=0.1), _synthetic_scenario())
    for key in ("slack_ticks", "min_tension", "max_rotation", "min_distance_true",
                "crossings_true"):
        assert math.isnan(plain[key]), key
    assert plain["min_distance_true_pair"] == ""


def test_the_peak_forces_and_speed_are_norms_of_the_logged_vectors():
    # The synthetic log's F_int is the logistic of the active pairs along fixed directions;
    # one tick made larger by hand in each force: the peak is that tick's norm (not a
    # component, not a sum over ticks).
    log = synthetic_log(duration=0.2)
    log["F_int"][37] = [0.0, 3.0, 4.0]
    log["F_d"][41] = [-12.0, 16.0, 0.0]
    log["velocity"][12] = [3.0, 0.0, -4.0]  # the path itself moves at 1.2 m/s
    m = sw.run_metrics(log, _synthetic_scenario())
    assert m["peak_F_int"] == 5.0 and m["peak_F_d"] == 20.0 and m["peak_speed"] == 5.0


def test_every_metric_s_unit_is_the_one_docs_sweep_format_gives():
    doc = (REPO / "docs" / "SWEEP_FORMAT.md").read_text()
    units = dict(re.findall(r"^\| `(\w+)` \| ([^|]+?) \|", doc, flags=re.M))
    for name, (unit, _, _) in sw.METRICS.items():
        assert units.get(name) == unit, (name, unit, units.get(name))


# --- Running ---------------------------------------------------------------------------------


def test_rows_equal_cdpm_simulate_of_their_resolved_scenario(tmp_path, capsys):
    path = write(tmp_path, SMALL)
    out = tmp_path / "out"
    assert sw.sweep_main(sweep=path, out_dir=out, workers=2, progress=False,
                         keep_logs=True) == 0
    rows = csv_rows(out / "results.csv")
    assert [r["status"] for r in rows] == ["ok"] * 4
    for row in rows[::3]:
        run_dir = out / "runs" / row["run"]
        sim_dir = tmp_path / f"sim_{row['run']}"
        assert main(["simulate", str(run_dir / "scenario.yaml"), "--out", str(sim_dir),
                     "--no-progress"]) == 0
        with np.load(sim_dir / "log.npz") as f:
            log = {k: f[k] for k in f.files}
        # Independent of run_metrics: the definitions of docs/SWEEP_FORMAT.md written out.
        dt = np.diff(log["time"])
        assert float(row["min_distance"]) == float(log["pair_distances"].min())
        assert float(row["peak_F_int"]) == float(np.linalg.norm(log["F_int"], axis=1).max())
        assert float(row["peak_F_d"]) == float(np.linalg.norm(log["F_d"], axis=1).max())
        assert float(row["peak_speed"]) == float(np.linalg.norm(log["velocity"], axis=1).max())
        assert float(row["operator_effort"]) == pytest.approx(
            float(np.sum(np.linalg.norm(log["F_H"], axis=1)[:-1] * dt)), rel=1e-12)
        below = np.any(log["pair_distances"] < log["d_l"], axis=1)[:-1]
        assert float(row["time_below_d_l"]) == pytest.approx(float(np.sum(below * dt)),
                                                             abs=1e-12)
        assert int(row["crossings"]) == int(np.any(log["crossed"], axis=0).sum())
        # The real-time factor: simulated seconds (the log's span) per wall second of the run.
        assert float(row["sim_s"]) == pytest.approx(float(log["time"][-1] - log["time"][0]))
        assert float(row["wall_s"]) > 0
        assert float(row["rtf"]) == pytest.approx(float(row["sim_s"]) / float(row["wall_s"]),
                                                  rel=1e-12)
        # And every metric is what run_metrics gives for the simulate log, to the last bit.
        scenario = load_scenario(run_dir / "scenario.yaml")
        expected = sw.run_metrics(log, scenario)
        for key in ("min_distance", "time_below_d_l", "peak_F_int", "peak_F_d", "peak_speed",
                    "operator_effort", "limit_time", "sim_s"):
            assert float(row[key]) == expected[key], key
        assert row["min_distance_pair"] == expected["min_distance_pair"]
        # The kept log is the same log.
        with np.load(run_dir / "log.npz") as f:
            np.testing.assert_array_equal(f["p"], log["p"])


def test_resume_skips_done_rows_and_reruns_what_changed(tmp_path):
    path = write(tmp_path, SMALL)
    out = tmp_path / "out"
    first = sw.run_sweep(sw.load_sweep(path), out, workers=2, progress=False)
    assert (first.ran, first.skipped) == (4, 0)
    again = sw.run_sweep(sw.load_sweep(path), out, workers=2, progress=False)
    assert (again.ran, again.skipped) == (0, 4)
    assert without_timing(again.rows) == without_timing(first.rows)
    # One more F_u value: only its two runs are new.
    path.write_text(SMALL.replace("[2.0, 4.0]", "[2.0, 3.0, 4.0]"))
    grown = sw.run_sweep(sw.load_sweep(path), out, workers=2, progress=False)
    assert (grown.ran, grown.skipped) == (2, 4)
    assert [r["interference.default.F_u"] for r in csv_rows(out / "results.csv")] == [
        "2.0", "2.0", "3.0", "3.0", "4.0", "4.0"]
    # A changed overlay changes every resolved scenario: all rerun.
    path.write_text(SMALL.replace("duration: 0.2", "duration: 0.1"))
    changed = sw.run_sweep(sw.load_sweep(path), out, workers=2, progress=False)
    assert (changed.ran, changed.skipped) == (4, 0)
    assert {r["sim_s"] for r in changed.rows} == {"0.1"}


def test_failing_and_dying_variants_are_error_rows_and_the_rest_finish(tmp_path):
    path = write(tmp_path, SMALL.replace("[2.0, 4.0]", "[2.0, 3.0, 4.0]"))
    s = sw.load_sweep(path)
    out = tmp_path / "out"

    # F_u = 3 kills its worker process outright; damping = 7 with F_u = 2 raises.
    kill = functools.partial(sweep_hooks.kill_worker_if, "interference.default.F_u", 3.0)
    outcome = sw.run_sweep(s, out, workers=2, progress=False, before_run=kill)
    rows = {(r["interference.default.F_u"], r["admittance.damping"]): r for r in outcome.rows}
    assert len(rows) == 6
    for key, r in rows.items():
        if key[0] == "3.0":
            assert r["status"] == "error"
            assert "worker process died (killed by SIGKILL)" in r["error"]
            assert r["min_distance"] == ""
        else:
            assert r["status"] == "ok" and float(r["min_distance"]) > 0
    # A resume does not rerun error rows unless asked; --retry-errors does (no hook now).
    again = sw.run_sweep(s, out, workers=2, progress=False)
    assert again.ran == 0
    fixed = sw.run_sweep(s, out, workers=2, progress=False, retry_errors=True,
                         before_run=functools.partial(sweep_hooks.raise_if,
                                                      "admittance.damping", 7.0))
    assert fixed.ran == 2
    by = {(r["interference.default.F_u"], r["admittance.damping"]): r for r in fixed.rows}
    assert by[("3.0", "5.0")]["status"] == "ok"
    assert by[("3.0", "7.0")]["status"] == "error"
    assert "RuntimeError: injected failure" in by[("3.0", "7.0")]["error"]


INTERRUPTED = SMALL.replace("[2.0, 4.0]", "[2.0, 3.0]")


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """results.csv rows of the INTERRUPTED sweep run in one go."""
    tmp = tmp_path_factory.mktemp("whole")
    sw.run_sweep(sw.load_sweep(write(tmp, INTERRUPTED)), tmp / "out", workers=2,
                 progress=False)
    return csv_rows(tmp / "out" / "results.csv")


@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130),
                                          (signal.SIGKILL, -signal.SIGKILL)])
def test_signal_mid_sweep_keeps_finished_rows_and_resume_completes(tmp_path, signum, code,
                                                                   uninterrupted):
    path = write(tmp_path, INTERRUPTED)
    out = tmp_path / "out"
    # The third run (F_u = 3, damping = 5) signals the parent as it starts; one worker, so
    # runs go in order and exactly the first two are finished.
    script = (
        "import functools, sys\n"
        f"sys.path.insert(0, {str(TESTS)!r})\n"
        "import sweep_hooks\n"
        "from cdpm_drake.runs.sweep import sweep_main\n"
        f"hook = functools.partial(sweep_hooks.signal_parent_if, "
        f"'interference.default.F_u', 3.0, {int(signum)})\n"
        f"sys.exit(sweep_main(sweep={str(path)!r}, out_dir={str(out)!r}, workers=1, "
        "progress=False, before_run=hook))\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, preexec_fn=default_signals)
    assert proc.returncode == code, proc.stderr
    if signum != signal.SIGKILL:
        assert "rerun the same command to resume" in proc.stderr
        kept = csv_rows(out / "results.csv")
        assert [(r["interference.default.F_u"], r["admittance.damping"]) for r in kept] == [
            ("2.0", "5.0"), ("2.0", "7.0")]
    # Killed outright, results.csv may lag by up to a second; each run's row.json does not.
    resumed = sw.run_sweep(sw.load_sweep(path), out, workers=2, progress=False)
    assert (resumed.ran, resumed.skipped) == (2, 2)
    assert without_timing(csv_rows(out / "results.csv")) == without_timing(uninterrupted)


# --- CLI and pictures ------------------------------------------------------------------------


def test_cli_sweep_plot_and_best_table(tmp_path, capsys):
    path = write(tmp_path, SMALL)
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--out", str(out), "--workers", "1", "--no-progress",
                 "--plot", "--metric", "operator_effort", "--top", "2"]) == 0
    text = capsys.readouterr().out
    assert "best runs by operator_effort (N s, smallest first)" in text
    rows = csv_rows(out / "results.csv")
    best = min(rows, key=lambda r: float(r["operator_effort"]))
    table = text.split("smallest first):")[1]
    assert table.splitlines()[3].startswith(best["run"])  # header, rule, then the best
    assert len([ln for ln in table.splitlines() if re.match(r"r[0-9a-f]{10} ", ln)]) == 2
    for name in ("operator_effort_heatmap.png", "pareto.png",
                 "operator_effort_vs_admittance_damping.png"):
        assert (out / name).stat().st_size > 1000
    drawn = {png.name: png.read_bytes() for png in out.glob("*.png")}
    # Issue 32: a second metric's pictures go beside the first one's, not over them.
    assert main(["plot", str(out)]) == 0
    assert (out / "min_distance_heatmap.png").is_file() and "best runs by min_distance" in \
        capsys.readouterr().out
    assert (out / "operator_effort_heatmap.png").read_bytes() == \
        drawn["operator_effort_heatmap.png"]


def test_cli_errors(tmp_path, capsys):
    assert main(["sweep", str(tmp_path / "nope.yaml")]) == 1  # an error, as for a scenario
    assert "sweep file" in capsys.readouterr().err
    assert main(["sweep", "exp2_du_Fu", "--workers", "0"]) == 2
    assert "--workers must be an integer >= 1, got 0" in capsys.readouterr().err
    assert main(["sweep", "exp2_du_Fu", "--dry-run"]) == 0
    assert "25 runs of 'exp2_interaction'" in capsys.readouterr().out


def test_the_readme_sweep_example_loads(tmp_path):
    """The guide's sweep block (docs/sweeps.md), verbatim: 3 x 3 x 2 grid points x 2 seeds, the
    pair (1,3) override created on a base that has none."""
    readme = (REPO / "docs" / "sweeps.md").read_text()
    block = next(b for b in re.findall(r"```yaml\n(.*?)```", readme, re.DOTALL)
                 if b.startswith("name: my_sweep"))
    s = sw.load_sweep(write(tmp_path, block))
    assert len(s.variants) == 36
    last = s.variants[-1].scenario
    assert [(p.pair, p.d_l) for p in last.interference.pairs] == [([1, 3], 0.060)]
    assert last.random_seed == 2 and last.duration == 5.0


def test_a_run_that_stops_part_way_is_a_fault_row_with_its_metrics(tmp_path, monkeypatch):
    """simulate() returns the log up to a failure with the exception in `error` (as when the
    forward kinematics finds no pose): the row says error, where, and why."""
    from cdpm_drake.runs import simulate as simulation

    real = simulation.simulate

    def stops_at_0_1(*, scenario, **kw):
        result = real(scenario=scenario, duration=0.1)
        result.error = RuntimeError("no platform pose fits the cable lengths")
        return result

    # The same run, 0.1 s long and ending normally.
    whole = sw.execute_run(sw.tasks_for([sw.load_sweep(write(
        tmp_path, SMALL.replace("{duration: 0.2}", "{duration: 0.1}"))).variants[0]])[0])
    assert whole["status"] == "ok"
    monkeypatch.setattr(simulation, "simulate", stops_at_0_1)
    v = sw.load_sweep(write(tmp_path, SMALL)).variants[0]
    row = sw.execute_run(sw.tasks_for([v])[0])
    assert row["status"] == "fault"
    assert row["error"] == ("the run stopped at t = 0.100 s: RuntimeError: no platform pose "
                            "fits the cable lengths")
    # Issue 22, point 3: the metrics of the ticks it logged, as the 0.1 s run has them.
    for metric in ("min_distance", "operator_effort", "peak_F_d", "time_below_d_l", "sim_s"):
        assert row[metric] == whole[metric], metric


# A sweep whose every run faults part-way: the dynamic plant's cables stretch, and the
# controller's kinematics stop the run once the lengths disagree with a rigid platform by more
# than max_length_residual (both values are reached within 0.8 s of experiment 2's push; the
# start's own misfit is 1.005 mm with the attachment points of issue 18, so the limits sit
# above it).
# The paper's open loop on the dynamic plant: its lengths drift, so the forward kinematics'
# residual grows past these limits within the second.
ALL_FAULT = """\
name: all_fault
base: exp2_interaction
overlay: {duration: 1.0, plant: !DynamicReels {tension_sensor: none}, controller: {length_gain: 0}}
axes:
  - {field: plant.max_length_residual, values: [1.1e-3, 1.2e-3]}
"""


def test_a_sweep_where_every_run_faults_draws_nothing_and_says_why(tmp_path, capsys):
    path = write(tmp_path, ALL_FAULT)
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--out", str(out), "--workers", "1", "--no-progress",
                 "--plot"]) == 1
    text, err = capsys.readouterr()
    assert "0 ok, 2 faulted, 0 error(s)" in text
    assert ("cdpm sweep: error: no pictures: none of the 2 runs finished ok (2 faulted, "
            "0 error(s)") in err, err
    assert not list(out.glob("*.png"))
    rows = csv_rows(out / "results.csv")
    for r in rows:  # faulted, with the metrics of the ticks logged up to the fault
        assert r["status"] == "fault" and "the run stopped at t = " in r["error"]
        assert 0 < float(r["sim_s"]) < 1.0 and float(r["min_distance"]) > 0.05
    # cdpm plot of that folder: the same reason, exit 1, no empty axes.
    assert main(["plot", str(out)]) == 1
    assert "no pictures: none of the 2 runs finished ok" in capsys.readouterr().err
    assert not list(out.glob("*.png"))


def test_nothing_to_draw_says_why():
    ok = {"status": "ok", "min_distance": "0.06", "crossings": ""}
    assert sw.nothing_to_draw([ok], "min_distance") == ""
    assert "none of the 1 ok runs has a value of crossings" in sw.nothing_to_draw([ok],
                                                                                 "crossings")
    assert "none of the 2 runs finished ok (1 faulted, 1 error(s)" in sw.nothing_to_draw(
        [{"status": "fault"}, {"status": "error"}], "min_distance")


def test_tables_show_distances_in_mm_with_even_digits():
    # Issue 27: the best-runs table showed d_u as 0.0605 / 0.061 m and min_distance as
    # 0.0598295 m beside summaries and pictures in mm. Rows as results.csv holds them (m).
    columns = ["run", "interference.default.d_u", "interference.default.F_u", "random_seed",
               "status", "min_distance", "operator_effort", "crossings"]
    rows = [{"run": "ra", "interference.default.d_u": "0.0605", "interference.default.F_u":
             "5.0", "random_seed": "0", "status": "ok", "min_distance": "0.0598295",
             "operator_effort": "28.3237", "crossings": "0"},
            {"run": "rb", "interference.default.d_u": "0.061", "interference.default.F_u":
             "2.5", "random_seed": "0", "status": "ok", "min_distance": "0.05975",
             "operator_effort": "30.6", "crossings": "1"}]
    lines = sw.best_table(columns, rows, "min_distance").splitlines()
    assert lines[0].split() == ["run", "interference.default.d_u", "(mm)",
                                "interference.default.F_u", "(N)", "random_seed",
                                "min_distance", "(mm)", "operator_effort", "(N", "s)",
                                "crossings", "(-)"]
    # d_u: one decimal shows both exactly; F_u likewise; 0.01 mm, 0.01 N s, whole counts.
    assert lines[2].split() == ["ra", "60.5", "5.0", "0", "59.83", "28.32", "0"]
    assert lines[3].split() == ["rb", "61.0", "2.5", "0", "59.75", "30.60", "1"]


def test_a_dry_run_says_where_the_results_would_go(tmp_path, capsys):
    path = write(tmp_path, SMALL)
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--out", str(out), "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert f"the results would go to {out / 'results.csv'}" in text
    assert "interference.default.F_u (N)" in text and "admittance.damping (N s/m)" in text
    assert not out.exists()


def test_the_lock_says_who_holds_it_and_is_gone_after_the_sweep(tmp_path):
    import os

    s = sw.load_sweep(write(tmp_path, SMALL))
    out = tmp_path / "out"
    out.mkdir()
    held = sw.acquire_lock(out)  # as a running cdpm sweep holds it
    try:
        assert (out / ".sweep.lock").read_text().startswith(f"pid {os.getpid()}, since ")
        with pytest.raises(sw.SweepError, match=rf"is in use by another cdpm sweep \(pid "
                                                rf"{os.getpid()}, since "):
            sw.run_sweep(s, out, workers=1, progress=False)
    finally:
        sw.release_lock(held, out)
    assert not (out / ".sweep.lock").exists()
    sw.run_sweep(s, out, workers=1, progress=False)
    assert (out / "results.csv").exists() and not (out / ".sweep.lock").exists()


def test_spaced_axes():
    # np.linspace / np.geomspace, both ends included, rounded to 12 significant digits.
    assert sw.axis_values(sw.Axis(field="x", linspace=[0.06, 0.062, 3])) == [0.06, 0.061, 0.062]
    assert sw.axis_values(sw.Axis(field="x", geomspace=[1.0, 100.0, 3])) == [1.0, 10.0, 100.0]


def test_a_second_sweep_on_the_same_directory_is_refused(tmp_path):
    import fcntl

    s = sw.load_sweep(write(tmp_path, SMALL))
    out = tmp_path / "out"
    out.mkdir()
    with open(out / ".sweep.lock", "a+") as held:  # as another cdpm sweep would hold it
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)
        with pytest.raises(sw.SweepError, match="is in use by another cdpm sweep"):
            sw.run_sweep(s, out, workers=1, progress=False)
    assert not (out / "results.csv").exists()
