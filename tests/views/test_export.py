"""`cdpm export LOG --csv` (issue 22, point 18): one row per tick, named columns with units,
cables and pairs numbered from 1, values that read back exactly."""

import csv
import io
import re
from pathlib import Path

import numpy as np
import pytest

from cdpm_drake.cli import main
from cdpm_drake.views.log_csv import (CABLE_NUMBER, COLUMNS, FILTER_BINDING, FILTER_STATUS,
                                      MODEL_STATUS, TENSION_STATUS, csv_columns, log_to_csv)
from helpers_synthetic_log import synthetic_log


def _read(text):
    rows = list(csv.reader(io.StringIO(text)))
    return rows[0], rows[1:]


def _number(cell):
    return np.nan if cell == "" else float(cell)


def test_every_per_tick_value_is_a_named_column_that_reads_back_exactly():
    log = synthetic_log(duration=0.1, realtime=True)
    log["compute"][0] = np.nan  # as cdpm run logs tick 0 (docs/LOG_FORMAT.md)
    T, m, P = len(log["time"]), 7, 21  # the paper's robot: 7 cables, 21 pairs
    header, rows = _read(log_to_csv(log))
    assert len(rows) == T and all(len(r) == len(header) for r in rows)
    col = {name: k for k, name in enumerate(header)}
    # Units in the names; components x, y, z; cables 1..m; pairs i-j as in log["pairs"].
    for name in ("time [s]", "tick [-]", "wall [s]", "compute [s]", "p_x [m]", "F_H_z [N]",
                 "F_d_y [N]", "velocity_admittance_z [m/s]", "reel_velocity_7 [m/s]",
                 "lengths_1 [m]", "pair_distances_1-3 [m]", "active_5-7 [0/1]",
                 "crossed_6-7 [0/1]"):
        assert name in col, name
    assert [h for h in header if h.startswith("lengths_")] == [
        f"lengths_{i} [m]" for i in range(1, m + 1)]
    assert [h.split()[0][len("active_"):] for h in header if h.startswith("active_")] == [
        f"{i}-{j}" for i, j in log["pairs"]]
    assert len([h for h in header if h.startswith("pair_distances_")]) == P
    # Values: floats exactly (shortest repr), flags 0/1, NaN as an empty cell.
    data = np.array([[_number(c) for c in r] for r in rows])
    np.testing.assert_array_equal(data[:, col["time [s]"]], log["time"])
    np.testing.assert_array_equal(data[:, col["p_y [m]"]], log["p"][:, 1])
    k13 = [tuple(p) for p in log["pairs"]].index((1, 3))
    np.testing.assert_array_equal(data[:, col["pair_distances_1-3 [m]"]],
                                  log["pair_distances"][:, k13])
    np.testing.assert_array_equal(data[:, col["crossed_1-3 [0/1]"]],
                                  log["crossed"][:, k13].astype(float))
    np.testing.assert_array_equal(data[:, col["lengths_7 [m]"]], log["lengths"][:, 6])
    assert {r[col["active_1-3 [0/1]"]] for r in rows} <= {"0", "1"}
    assert rows[0][col["compute [s]"]] == "" and rows[1][col["compute [s]"]] == "0.0003"
    # The per-run constants are no columns.
    assert not any(h.startswith(("d_u", "reels", "attachments", "workspace")) for h in header)


def test_the_dynamic_plant_s_ground_truth_is_exported_too():
    log = synthetic_log(duration=0.02)
    T = len(log["time"])
    log["tensions"] = np.arange(T * 7, dtype=float).reshape(T, 7)
    log["slack"] = np.zeros((T, 7), dtype=bool)
    log["slack"][3, 6] = True
    log["rpy_true"] = np.full((T, 3), 0.25)
    header = [name for name, _ in csv_columns(log)]
    assert "tensions_7 [N]" in header and "slack_7 [0/1]" in header
    assert {"rpy_true_roll [rad]", "rpy_true_pitch [rad]", "rpy_true_yaw [rad]"} <= set(header)
    _, rows = _read(log_to_csv(log))
    assert rows[3][header.index("slack_7 [0/1]")] == "1"
    assert rows[3][header.index("tensions_2 [N]")] == repr(float(3 * 7 + 1))


def test_cdpm_export_writes_log_csv_beside_the_log(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["simulate", "exp1_no_interaction", "--duration", "0.02", "--out", str(run),
                 "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["export", str(run), "--csv"]) == 0
    assert f"csv: {run / 'log.csv'} (11 rows, one per tick;" in capsys.readouterr().out
    header, rows = _read((run / "log.csv").read_text())
    with np.load(run / "log.npz") as log:
        np.testing.assert_array_equal([float(r[header.index("F_d_x [N]")]) for r in rows],
                                      log["F_d"][:, 0])
    # To stdout, the same text.
    assert main(["export", str(run / "log.npz"), "--csv", "--out", "-"]) == 0
    assert capsys.readouterr().out == (run / "log.csv").read_text()


def test_cdpm_export_errors(tmp_path, capsys):
    # No log there: cannot be found (1); an unknown format: bad usage (2).
    assert main(["export", str(tmp_path / "nothing"), "--csv"]) == 1
    assert "does not exist" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["export", str(tmp_path), "--xlsx"])
    assert e.value.code == 2


# --- issue 27, part B: every column named and united alike ---------------------------------

REPO = Path(__file__).resolve().parents[2]


def _documented_per_tick_keys():
    """{key: unit as docs/LOG_FORMAT.md writes it} of every per-tick key ((T,), (T, ...)):
    the table's rows and the bulleted keys of the full pose and the dynamic plant, and the
    prose of cdpm run's `tick`, `wall` and `compute`."""
    doc = (REPO / "docs" / "LOG_FORMAT.md").read_text()
    keys = {}
    for key, unit in re.findall(r"^\| `(\w+)` \| \(T,[^)]*\) \| ([^|]*) \|", doc,
                                flags=re.M):
        keys[key] = unit.strip()
    for key, unit in re.findall(r"^- `(\w+)`, \(T,[^)]*\)(?:, ([^:]+))?:", doc,
                                flags=re.M):
        keys[key] = unit.strip()
    for key, unit in (("tick", "-"), ("wall", "s"), ("compute", "s")):
        assert f"`{key}` (T,)" in doc or f"as `{key}` (T,)" in doc, key
        keys[key] = unit
    return keys


# The keys the doc gives no unit: codes, bits and cable numbers, labelled with their meaning.
CODES = {"tension_status": TENSION_STATUS, "tension_cable": CABLE_NUMBER,
         "filter_status": FILTER_STATUS, "filter_binding": FILTER_BINDING,
         "model_status": MODEL_STATUS}


def test_every_documented_per_tick_key_has_its_unit_in_the_csv():
    # The doc's units, spelled as the CSV spells them: a bool is a flag, 0/1; a key with no
    # unit in the doc is a status code (CODES).
    keys = _documented_per_tick_keys()
    assert {"pair_distances_true", "crossed_true", "rpy", "t_star", "tension_status",
            "lengths_commanded", "omega", "filter_status", "F_kin", "kappa",
            "model_residual"} <= keys.keys()
    for key, unit in keys.items():
        assert key in COLUMNS, key
        expected = {"bool": "0/1", "": CODES.get(key)}.get(unit, unit)
        assert COLUMNS[key][0] == expected, (key, unit, COLUMNS[key])


def _full_pose_dynamic_log():
    """A synthetic log with every key a full-pose, tension-controlled run on the dynamic plant
    writes, each (T, n) key's column c filled with its own numbers, so that a column that
    holds another column's values cannot pass."""
    log = synthetic_log(duration=0.01)
    T, m, P = len(log["time"]), 7, 21
    rng = np.random.default_rng(27)
    for key, width in (("lengths_commanded", m), ("rpy", 3), ("omega", 3),
                       ("tension_estimate", m), ("tension_target", m), ("tension_command", m),
                       ("t_star", 1), ("tensions", m), ("p_true", 3), ("rpy_true", 3),
                       ("pair_distances_true", P),
                       # issue 31: the plant's measured tensions and the damping's part.
                       ("tension_measured", m), ("reel_velocity_damping", m),
                       # without a tension sensor: the unseen ringing's swing.
                       ("ringing_swing", m)):
        log[key] = rng.uniform(-1.0, 1.0, (T, width))
    for key, width in (("velocity_limited", 3), ("pair_margin", 1), ("F_kin", 3),
                       ("kappa", 1), ("t_c", 1), ("t_star_hand", 1), ("model_residual", m)):
        log[key] = rng.uniform(-1.0, 1.0, (T, width))
    log["tension_status"] = rng.integers(0, 3, (T, 1)).astype(float)
    log["tension_cable"] = rng.integers(0, m + 1, (T, 1)).astype(float)
    log["filter_status"] = rng.integers(0, 4, (T, 1)).astype(float)
    log["filter_binding"] = rng.integers(0, 32, (T, 1)).astype(float)
    log["model_status"] = np.zeros((T, 1))
    for key, width in (("slack", m), ("crossed_true", P), ("ringing_warned", m)):
        log[key] = rng.uniform(size=(T, width)) < 0.5
    for key in ("p", "F_H", "F_measured", "F_int", "F_wall", "F_d", "velocity_admittance",
                "velocity", "reel_velocity", "lengths", "pair_distances"):
        log[key] = rng.uniform(-1.0, 1.0, np.shape(log.get(key, log["p"])))
    for key in ("active", "crossed"):
        log[key] = rng.uniform(size=log[key].shape) < 0.5
    return log


def test_every_column_holds_the_log_value_its_name_says():
    # Issue 27, bug 7: pair_distances_true_2 held pair 1-3, tensions and rpy had no unit.
    # Each header is read back here by its own rules (docs/LOG_FORMAT.md: x y z, roll pitch
    # yaw in that order; cables 1..m; pairs by their cables, as log["pairs"] lists them) and
    # its cells compared with that entry of the log.
    log = _full_pose_dynamic_log()
    header, rows = _read(log_to_csv(log))
    data = np.array([[_number(c) for c in r] for r in rows])
    pairs = [f"{i}-{j}" for i, j in log["pairs"]]
    parts = {"x": 0, "y": 1, "z": 2, "roll": 0, "pitch": 1, "yaw": 2}
    seen = set()
    for col, name in enumerate(header):
        m = re.fullmatch(r"(\w+?)(?:_(x|y|z|roll|pitch|yaw|\d+-\d+|\d+))? \[([^\]]+)\]", name)
        assert m, f"column {name!r} lacks a unit in brackets"
        key, part, unit = m.groups()
        if key not in log:  # the greedy key ate a component: e.g. "F_H_z" -> "F_H", "z"
            key, _, part = name.split(" [")[0].rpartition("_")
        values = np.asarray(log[key])
        if part is None:
            expected = values.reshape(len(values), -1)[:, 0]
        elif part in parts:
            expected = values[:, parts[part]]
        elif "-" in part:
            expected = values[:, pairs.index(part)]
        else:
            expected = values[:, int(part) - 1]
        np.testing.assert_array_equal(data[:, col], expected.astype(float), err_msg=name)
        if values.dtype == bool:
            assert unit == "0/1", name
        seen.add(key)
    # Every per-tick key is exported: 235 columns for 7 cables and 21 pairs (25 of time and
    # the eight 3-vectors, 10 x 7 per cable, 5 x 21 per pair, 4 x 3 orientations and vectors,
    # t_star and tension_status; and the safety filter's and the monitor's: tension_cable,
    # velocity_limited and F_kin (2 x 3), filter_status, filter_binding, pair_margin, kappa,
    # t_c, t_star_hand, model_status (7 x 1), model_residual (7)); 14 more without a tension
    # sensor: ringing_swing and ringing_warned (2 x 7).
    assert seen == set(_documented_per_tick_keys()) - {"tick", "wall", "compute"}
    assert len(header) == 25 + 10 * 7 + 5 * 21 + 4 * 3 + 2 + 1 + 6 + 7 + 7 + 2 * 7 == 249
    # The names the issue asked for, verbatim.
    for name in ("pair_distances_true_1-3 [m]", "crossed_true_5-7 [0/1]", "rpy_roll [rad]",
                 "rpy_true_yaw [rad]", "omega_z [rad/s]", "tensions_7 [N]", "slack_1 [0/1]",
                 "tension_estimate_3 [N]", "lengths_commanded_7 [m]", "t_star [N]",
                 f"tension_status [{TENSION_STATUS}]"):
        assert name in header, name
    # Flags and codes as integers.
    status = header.index(f"tension_status [{TENSION_STATUS}]")
    assert {r[status] for r in rows} <= {"0", "1", "2"}
    assert {r[header.index("crossed_true_1-3 [0/1]")] for r in rows} == {"0", "1"}


def test_cdpm_export_of_a_full_pose_dynamic_run_names_every_column(tmp_path, capsys):
    # A real log of the full pose with tension control on the dynamic plant, exported without
    # --csv (CSV is the default and only format): the 235 columns counted in the synthetic
    # test above (a full-pose dynamic run logs every per-tick key), each with its unit.
    run = tmp_path / "run"
    assert main(["simulate", "exp2_interaction", "--duration", "0.01", "--out", str(run),
                 "--no-progress", "--scenario-text",
                 "{controller: {pose: full, tension_control: true}, plant: !DynamicReels {}}"]
                ) == 0
    capsys.readouterr()
    assert main(["export", str(run)]) == 0
    assert "(6 rows, one per tick; 235 columns)" in capsys.readouterr().out
    header, rows = _read((run / "log.csv").read_text())
    assert len(header) == 235
    # The summary counts columns from the header line, so no name may hold a comma.
    assert not [name for name in header if "," in name]
    assert all(re.search(r" \[[^\]]+\]$", name) for name in header), header
    k13 = [tuple(p) for p in np.load(run / "log.npz")["pairs"]].index((1, 3))
    with np.load(run / "log.npz") as log:
        np.testing.assert_array_equal(
            [float(r[header.index("pair_distances_true_1-3 [m]")]) for r in rows],
            log["pair_distances_true"][:, k13])
        np.testing.assert_array_equal(
            [float(r[header.index("rpy_pitch [rad]")]) for r in rows], log["rpy"][:, 1])
