"""`cdpm export LOG --mat` (issue 32, "Logs people open"): a MATLAB .mat file with every log
key and its unit, read back by an independent reader, scipy.io.loadmat, and compared with the
log; the units against docs/LOG_FORMAT.md."""

import re
from pathlib import Path

import numpy as np
import pytest

from cdpm_drake.cli import main
from cdpm_drake.views.log_csv import COLUMNS, RUN_CONSTANTS, unit_of
from cdpm_drake.views.log_mat import MatExportError, log_to_mat_dict, write_log_mat
from helpers_synthetic_log import synthetic_log

sio = pytest.importorskip("scipy.io")

REPO = Path(__file__).resolve().parents[2]
DOC = (REPO / "docs" / "LOG_FORMAT.md").read_text()
# The doc's unit words as the exports spell them (a bool is a flag, 0/1; text has none).
SPELLING = {"bool": "0/1", "str": "-"}


def documented_units() -> dict:
    """{key: unit as docs/LOG_FORMAT.md writes it} of every key the doc lists: the table's
    rows (a row naming several keys gives each its unit, `m, m, N, N` in turn), the bulleted
    keys (`- \\`key\\`, (T, 3), rad:`; several keys on one bullet share the unit), and the keys
    of `cdpm run` in its prose. "" where the doc gives no unit (a status code)."""
    units = {}
    for keys, unit in re.findall(r"^\| (`\w+`(?:, `\w+`)*) \| \([^)]*\) \| ([^|]*) \|", DOC,
                                 flags=re.M):
        names = re.findall(r"`(\w+)`", keys)
        parts = [u.strip() for u in unit.split(",")]
        for k, name in enumerate(names):
            units[name] = parts[k] if len(parts) == len(names) else unit.strip()
    for keys, unit in re.findall(r"^- (`\w+`(?:, `\w+`)*), \([^)]*\)(?:, ([^:]+))?:", DOC,
                                 flags=re.M):
        for name in re.findall(r"`(\w+)`", keys):
            units[name] = unit.strip()
    # cdpm run's keys are prose: "as `tick` (T,)", "as `wall` (T,)", "`compute` (T,), s",
    # "`watchdog_limit` (), s".
    for key, unit in (("tick", "-"), ("wall", "s"), ("compute", "s"),
                      ("watchdog_limit", "s")):
        assert f"`{key}` (" in DOC, key
        units[key] = unit
    return units


def test_every_documented_log_key_has_its_unit_in_one_table():
    units = documented_units()
    # The parse found the table, both kinds of bullet and the prose.
    assert {"time", "d_l", "eps", "workspace_upper", "robot_name", "fault_time", "rpy_true",
            "controller_max_tension", "filter_status", "watchdog_limit"} <= units.keys()
    assert units["eps"] == "N" and units["d_min"] == "m" and units["rpy_true"] == "rad"
    for key, unit in units.items():
        assert unit_of(key) is not None, f"{key!r} of docs/LOG_FORMAT.md has no unit in code"
        if unit == "":  # a code or bits: the exports label it with its meaning
            assert unit_of(key).startswith(("code:", "bits:", "cable:")), key
        else:
            assert unit_of(key) == SPELLING.get(unit, unit), (key, unit, unit_of(key))
    # A key in one table only, never both (one place each).
    assert not set(COLUMNS) & set(RUN_CONSTANTS)


def _loaded(path) -> dict:
    return sio.loadmat(path)


def _text(value) -> str:
    """A char array as loadmat returns it (an array of one string, or empty)."""
    return "".join(np.asarray(value).reshape(-1).tolist())


def _compare(log, mat, key):
    """The .mat variable `key` against the log's value: same numbers (NaN where NaN), 1-D
    vectors as columns, flags as 0/1, text as text."""
    value = np.asarray(log[key])
    got = mat[key]
    if value.dtype.kind == "U":
        assert _text(got) == str(value), key
        return
    expected = value.reshape(-1, 1) if value.ndim <= 1 else value
    assert got.shape == expected.shape, (key, got.shape, expected.shape)
    np.testing.assert_array_equal(got.astype(float), expected.astype(float), err_msg=key)


def test_mat_holds_every_log_key_read_back_by_loadmat(tmp_path):
    log = synthetic_log(duration=0.1, realtime=True, fault_time=0.05)
    T, m = len(log["time"]), 7
    log["compute"][0] = np.nan  # as cdpm run logs tick 0
    log["t_star"] = np.linspace(-1.0, 1.0, T).reshape(T, 1)
    log["t_star"][3] = np.inf  # an internal force raises every tension
    log["tension_cable"] = np.arange(T).reshape(T, 1) % (m + 1)
    path = write_log_mat(log, tmp_path / "log.mat")
    assert [p.name for p in tmp_path.iterdir()] == ["log.mat"]  # no part file left
    mat = _loaded(path)
    for key in log:
        _compare(log, mat, key)
    # Time a column; cables 1..m; pairs 1-based as the log's (the paper's 21 pairs of 7).
    assert mat["time"].shape == (T, 1)
    np.testing.assert_array_equal(mat["cables"].ravel(), np.arange(1, m + 1))
    assert mat["pairs"].min() == 1 and mat["pairs"].max() == m
    assert mat["reels"].shape == (m, 3) and mat["lengths"].shape == (T, m)
    # Column 3 of lengths is cable 3: its length from its reel to the platform (p + b_3,
    # the translating platform), written out here from the log's geometry.
    b3, a3 = log["attachments"][2], log["reels"][2]
    np.testing.assert_allclose(mat["lengths"][:, mat["cables"].ravel() == 3].ravel(),
                               np.linalg.norm(log["p"] + b3 - a3, axis=1), rtol=1e-12)
    # NaN and inf kept; text as char arrays; flags logical.
    assert np.isnan(mat["compute"][0, 0]) and np.isposinf(mat["t_star"][3, 0])
    assert _text(mat["ending"]) == "fault"
    assert _text(mat["fault_message"]) == "bridge silent for 3 ticks"
    kinds = {name: kind for name, _, kind in sio.whosmat(path)}
    assert kinds["active"] == "logical" and kinds["crossed"] == "logical"
    assert kinds["robot_name"] == "char" and kinds["units"] == "struct"
    assert kinds["time"] == "double"
    # Nothing but the log's keys and the two added.
    assert set(k for k in mat if not k.startswith("__")) == set(log) | {"cables", "units"}


def test_mat_units_struct_names_every_key_with_the_doc_s_unit(tmp_path):
    log = synthetic_log(duration=0.02)
    T = len(log["time"])
    log["rpy_true"] = np.zeros((T, 3))
    log["filter_status"] = np.zeros((T, 1))
    log["future_key"] = np.zeros(T)  # a key a newer log may add: kept, no unit guessed
    mat = _loaded(write_log_mat(log, tmp_path / "log.mat"))
    units = mat["units"][0, 0]
    assert set(units.dtype.names) == set(log) | {"cables"}
    doc = documented_units()
    for key in log:
        got = _text(units[key])
        if key == "future_key":
            assert got == ""
        elif doc[key] == "":
            assert got.startswith("code:"), key  # filter_status: its codes spelled out
        else:
            assert got == SPELLING.get(doc[key], doc[key]), (key, got, doc[key])
    assert _text(units["p"]) == "m" and _text(units["F_H"]) == "N"
    assert _text(units["velocity"]) == "m/s" and _text(units["rpy_true"]) == "rad"
    assert _text(units["active"]) == "0/1" and _text(units["cables"]) == "-"


def test_a_key_matlab_cannot_name_is_refused_by_name():
    log = synthetic_log(duration=0.01)
    log["2nd_try"] = np.zeros(3)
    with pytest.raises(MatExportError, match="'2nd_try'"):
        log_to_mat_dict(log)


def test_cdpm_export_mat_of_a_dynamic_full_pose_run(tmp_path, capsys):
    # A real log (full pose, tension control, dynamic plant: its truth too), every key
    # compared after loadmat.
    run = tmp_path / "run"
    assert main(["simulate", "exp2_interaction", "--duration", "0.01", "--out", str(run),
                 "--no-progress", "--scenario-text",
                 "{controller: {pose: full, tension_control: true}, plant: !DynamicReels {}}"]
                ) == 0
    capsys.readouterr()
    assert main(["export", str(run), "--mat"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"mat: {run / 'log.mat'} (") and "6 ticks" in out
    mat = _loaded(run / "log.mat")
    with np.load(run / "log.npz") as data:
        log = {k: data[k] for k in data.files}
    assert {"p_true", "rpy", "tensions", "slack", "tension_status"} <= set(log)
    for key in log:
        _compare(log, mat, key)
    units = mat["units"][0, 0]
    assert set(units.dtype.names) == set(log) | {"cables"}
    assert all(_text(units[k]) for k in log), "a key of a real log without a unit"
    # --out elsewhere; an unwritable --out is bad usage (2) naming the option.
    other = tmp_path / "x" / "run.mat"
    assert main(["export", str(run), "--mat", "--out", str(other)]) == 0
    assert other.is_file()
    capsys.readouterr()
    (tmp_path / "FILE").write_text("")
    assert main(["export", str(run), "--mat", "--out", str(tmp_path / "FILE" / "a.mat")]) == 2
    assert "--out's folder" in capsys.readouterr().err
    assert main(["export", str(run), "--mat", "--out", "-"]) == 2
    assert "--csv only" in capsys.readouterr().err
