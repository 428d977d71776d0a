"""Issue 27, bugs 2-5: a damaged log or tick stream, an output folder that cannot be written
and a duration whose log cannot fit end in one clear error naming the file, the folder or the
sizes, with the README's exit code, never in a traceback (cli.main would raise one here).

References: the file layouts (docs/LOG_FORMAT.md: log.npz is a zip archive; hardware/
tick_log.py: an 8-byte magic and a 4-byte header length before the JSON header); the log's
widths per docs/LOG_FORMAT.md for the bytes a tick."""

import os

import numpy as np
import pytest

from cdpm_drake import cli
from cdpm_drake.runs.log import LogTooLarge, check_log_fits


def run_cli(capsys, *args):
    code = cli.main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    """A real run folder of experiment 1 (0.2 s), written by `cdpm simulate`."""
    out = tmp_path_factory.mktemp("real") / "run"
    assert cli.main(["simulate", "exp1_no_interaction", "--duration", "0.2", "--out", str(out),
                     "--no-progress"]) == 0
    return out


# --- bug 2: a truncated or damaged log.npz ---------------------------------------------------


@pytest.mark.parametrize("command", [["plot"], ["export", "--csv"]])
def test_a_truncated_log_names_the_file(tmp_path, capsys, real_run, command):
    # The case: the first 1000 bytes of a real log (its zip directory, at the end,
    # is gone). Before: zipfile.BadZipFile, a traceback.
    bad = tmp_path / "cut" / "log.npz"
    bad.parent.mkdir()
    bad.write_bytes((real_run / "log.npz").read_bytes()[:1000])
    code, out, err = run_cli(capsys, command[0], str(bad), *command[1:])
    assert code == 1
    assert err.startswith(f"cdpm {command[0]}: error: '{bad}' is damaged or truncated (1000 "
                          "bytes): not a whole .npz archive"), err
    assert not (tmp_path / "cut" / "log.csv").exists()


def test_a_log_with_a_flipped_byte_names_the_file(tmp_path, capsys, real_run):
    # One byte flipped in the middle of the archive: a member's checksum (or its deflate
    # stream) no longer holds.
    data = bytearray((real_run / "log.npz").read_bytes())
    data[len(data) // 2] ^= 0xFF
    bad = tmp_path / "log.npz"
    bad.write_bytes(bytes(data))
    code, out, err = run_cli(capsys, "plot", str(bad))
    assert code == 1
    assert f"cdpm plot: error: '{bad}' is damaged or truncated ({len(data)} bytes)" in err, err


# --- bug 3: a truncated ticks.bin ------------------------------------------------------------


def _run_folder_with_ticks(tmp_path, real_run, ticks: bytes):
    folder = tmp_path / "killed"
    folder.mkdir()
    (folder / "scenario.yaml").write_text((real_run / "scenario.yaml").read_text())
    (folder / "ticks.bin").write_bytes(ticks)
    return folder


@pytest.mark.parametrize("size", [10, 0])
def test_a_tick_stream_cut_inside_its_first_bytes_is_called_truncated(tmp_path, capsys,
                                                                      real_run, size):
    # The case: cut to 10 bytes, the magic whole but the header's length cut. Before:
    # "is not a tick log (magic b'CDPMTICK', expected b'CDPMTICK')". The layout's fixed part
    # is 8 + 4 = 12 bytes.
    from cdpm_drake.hardware.tick_log import MAGIC

    folder = _run_folder_with_ticks(tmp_path, real_run, (MAGIC + b"\x40\x00")[:size])
    code, out, err = run_cli(capsys, "recover", str(folder))
    assert code == 1
    assert (f"'{folder / 'ticks.bin'}' is truncated: {size} bytes, where a tick log's header "
            "alone takes at least 12") in err, err
    assert "not a tick log" not in err


def test_a_tick_stream_cut_inside_its_header_says_how_long_the_header_is(tmp_path):
    from cdpm_drake.hardware.tick_log import (TickLogError, TickLogWriter, read_tick_log,
                                              tick_log_header)

    path = tmp_path / "ticks.bin"
    with TickLogWriter(path, {"x": 3}) as w:
        w.append(0.0, {"x": np.zeros(3)})
    whole = tick_log_header(path)["data_offset"]  # 12 + the padded JSON
    os.truncate(path, 30)
    with pytest.raises(TickLogError, match=rf"is truncated: 30 bytes, where its header takes "
                                           rf"{whole} \(header truncated: 18 of its "
                                           rf"{whole - 12} bytes of JSON\)"):
        read_tick_log(path)


def test_a_tick_stream_with_a_damaged_header_is_named(tmp_path):
    from cdpm_drake.hardware.tick_log import MAGIC, TickLogError, read_tick_log

    path = tmp_path / "ticks.bin"
    path.write_bytes(MAGIC + (4).to_bytes(4, "little") + b"{no}")
    with pytest.raises(TickLogError, match=r"the header is damaged \(JSONDecodeError"):
        read_tick_log(path)


# --- bug 4: an output folder found wanting after the report ----------------------------------


def test_info_checks_its_plot_folder_before_the_report(tmp_path, capsys):
    # Before: the report, then a FileNotFoundError traceback. The README: exit 2 for an output
    # that cannot be written.
    blocker = tmp_path / "file"
    blocker.write_text("")
    for where in ("/proc/xx", str(blocker / "pictures")):
        code, out, err = run_cli(capsys, "info", "exp2_interaction", "--plot", where)
        assert code == 2 and out == "", out
        assert err.startswith(f"cdpm info: error: --plot '{where}' is not a writable "
                              "directory"), err


@pytest.mark.parametrize("step, message", [
    ("0", "--grid must be a step in m > 0, got 0.0"),
    ("nan", "--grid must be a step in m > 0, got nan"),
    # paper_7cable's box is 2.5 x 3.2 x 2.1 m: 2501 x 3201 x 2101 points at 1 mm; the
    # smallest whole-mm step within 10^6 points is 26 mm (97 x 124 x 81 = 974,268; 25 mm:
    # 101 x 129 x 85 = 1,107,465).
    ("0.001", "--grid 0.001 m gives 2501 x 3201 x 2101 points on the workspace box of robot "
              "'paper_7cable', more than 1,000,000; give a step of at least 0.026 m"),
])
def test_info_refuses_a_grid_it_cannot_compute_before_the_report(capsys, step, message):
    code, out, err = run_cli(capsys, "info", "paper_7cable", "--grid", step)
    assert code == 2 and out == ""
    assert f"cdpm info: error: {message}" in err, err


def test_the_smallest_grid_step_suggested_fits(capsys, valid_spec, write_robot):
    # conftest's robot: a 2 x 2 x 2 m box. The cube root of 8 m^3 / 10^6 points is 20 mm,
    # but 20 mm gives 101^3 = 1,030,301 points (both faces); 21 mm: 96^3 = 884,736.
    path = write_robot(valid_spec)
    code, out, err = run_cli(capsys, "info", str(path), "--grid", "0.001")
    assert code == 2
    assert err.endswith("more than 1,000,000; give a step of at least 0.021 m\n"), err


# --- bug 5: a duration whose log cannot fit ----------------------------------------------------

# Values per tick of experiment 2's log (docs/LOG_FORMAT.md): 3-vectors p, F_H, F_int, F_d,
# velocity_admittance, velocity, F_measured; per cable (7) reel_velocity, lengths_commanded,
# lengths; per watched pair (21) pair_distances, active, crossed; and the time.
# The safety filter, the kinetostatic limit and the model monitor add velocity_limited and
# F_kin (3 each), filter_status, filter_binding, pair_margin, kappa, t_c, model_status and
# t_star_hand (1 each) and model_residual per cable (7); the plant's measured tensions (7,
# NaN on this plant).
EXP2_VALUES = 7 * 3 + 3 * 7 + 3 * 21 + 1 + (2 * 3 + 7 + 7) + 7
# The dynamic plant's ground truth adds tensions and slack per cable, p_true and rpy_true,
# logged with their own time; its tension damping its part of the reel command (7).
EXP2_DYNAMIC_VALUES = EXP2_VALUES + 2 * 7 + 3 + 3 + 1 + 7


@pytest.mark.parametrize("overlay, values, size", [
    # 5e11 ticks x 2,128 bytes (133 values, twice) = 1.06e15 bytes; x 2,576 = 1.29e15.
    ("{duration: 1e9}", EXP2_VALUES, "1.06 PB"),
    ("{duration: 1e9, plant: !DynamicReels {}}", EXP2_DYNAMIC_VALUES, "1.29 PB")])
def test_a_duration_whose_log_cannot_fit_is_refused_naming_the_size(tmp_path, capsys,
                                                                    monkeypatch, overlay,
                                                                    values, size):
    # Before: MemoryError: std::bad_alloc from the log's reserve. 1e9 s at 2 ms is
    # 500,000,000,001 ticks (both ends), each `values` float64s, held twice.
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, "simulate", "exp2_interaction", "--scenario-text", overlay,
                             "--no-progress")
    assert code == 1
    per_tick = 2 * 8 * values
    assert (f"cdpm simulate: error: duration 1e+09 s is 500,000,000,001 ticks, whose log needs "
            f"{size} ({per_tick:,} bytes a tick: {values} "
            f"logged values of 8 bytes, held 2 times over), more than the") in err, err
    assert not (tmp_path / "runs").exists()  # refused before the run: no folder


def test_a_duration_flag_whose_log_cannot_fit_is_bad_usage(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, "simulate", "exp2_interaction", "--duration", "1e9",
                             "--no-progress")
    assert code == 2
    assert err.startswith("cdpm simulate: error: --duration 1e+09 s is 500,000,000,001 ticks")


def test_cdpm_run_refuses_such_a_duration_before_it_greets_the_bridge(tmp_path, capsys,
                                                                      monkeypatch):
    # No bridge listens on the port: a run that got as far as greeting it would say "no valid
    # status". The tick log's row: the logged values of experiment 2 without the time, plus
    # tick, time, wall and compute.
    import socket

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, "run", "exp2_interaction", "--scenario-text",
                             f"{{duration: 1e9, plant: !HardwareReels {{port: {port}, "
                             "startup_timeout: 0.2}}")
    assert code == 1
    # The real reels log tension_measured and the tension damping's part (7 each) where
    # their protocol carries the drives' torques (HardwareReels.tension_sensor), else
    # neither: EXP2_VALUES (with the kinematic plant's NaN tension_measured) + 7 or - 7.
    import dataclasses

    from cdpm_drake.hardware.config import HardwareReels

    measured = "tension_sensor" in {f.name for f in dataclasses.fields(HardwareReels)}
    row = 8 * (EXP2_VALUES + (7 if measured else -7) - 1 + 4)
    assert (f"cdpm run: error: duration 1e+09 s is 500,000,000,001 ticks, whose log needs "
            f"{2 * row * 500_000_000_001 / 1e15:.3g} PB ({2 * row:,} bytes a tick") in err, err
    assert "no valid status" not in err
    assert not (tmp_path / "runs").exists()


def test_the_longest_duration_that_fits_is_exact():
    # 200 bytes a tick held twice: 10,000 bytes hold 25 ticks (ticks 0..24: 0.048 s at 2 ms);
    # 0.05 s is 26 ticks, 10,400 bytes.
    check_log_fits(0.048, 0.002, 200, memory=10_000)
    with pytest.raises(LogTooLarge, match=r"duration 0.05 s is 26 ticks, whose log needs "
                                          r"10.4 kB \(400 bytes a tick: 25 logged values of 8 "
                                          r"bytes, held 2 times over\), more than the 10 kB of "
                                          r"memory available; give a duration of at most "
                                          r"0.048 s here"):
        check_log_fits(0.05, 0.002, 200, memory=10_000)


def test_a_real_time_run_also_needs_the_disk_for_its_tick_stream(tmp_path):
    import shutil

    free = shutil.disk_usage(tmp_path).free
    ticks = free // 100 + 10  # rows of 100 bytes: just past the free space
    with pytest.raises(LogTooLarge, match=rf"of free disk at '{tmp_path}'"):
        check_log_fits((ticks - 1) * 0.002, 0.002, 1, memory=10**30, disk_dir=tmp_path,
                       disk_bytes_per_tick=100)
