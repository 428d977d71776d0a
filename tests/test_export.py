"""`cdpm export LOG --csv` (issue 22, point 18): one row per tick, named columns with units,
cables and pairs numbered from 1, values that read back exactly."""

import csv
import io

import numpy as np
import pytest

from cdpm_drake.cli import main
from cdpm_drake.views.log_csv import csv_columns, log_to_csv
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
    # No log there: cannot be found (1); no format: bad usage (2).
    assert main(["export", str(tmp_path / "nothing"), "--csv"]) == 1
    assert "does not exist" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["export", str(tmp_path)])
    assert e.value.code == 2
    assert "one of the arguments --csv is required" in capsys.readouterr().err
