"""Bad input a new user gave the command line, each once a traceback or silently accepted: now a
clear message naming the field or option and the value, the exit code of docs/running.md
(1 an invalid input, 2 bad usage, 130 Ctrl-C), and nothing written that was not asked for."""

import sys
import types

import numpy as np
import pytest
from helpers_synthetic_log import synthetic_log

from cdpm_drake import cli
from cdpm_drake.config import Scenario, ScenarioError, scenario_robot
from cdpm_drake.runs.sweep.metrics import run_metrics
from cdpm_drake.text import format_number


def _main(argv):
    try:
        return cli.main(argv)
    except SystemExit as e:  # argparse's usage errors
        return e.code


def test_diagram_to_a_folder_that_cannot_be_made_is_bad_usage(tmp_path, capsys):
    # --out under a regular file cannot be a folder (as /proc/x cannot): refused before the
    # diagrams are built, exit 2, no FileNotFoundError traceback.
    (tmp_path / "file").write_text("")
    assert _main(["diagram", "--out", str(tmp_path / "file" / "x")]) == 2
    assert "--out" in capsys.readouterr().err


def _short_time_log(tmp_path):
    log = synthetic_log(duration=0.1)
    log["time"] = log["time"][:-5]  # 5 rows fewer than every other per-tick key
    path = tmp_path / "short.npz"
    np.savez(path, **log)
    return path


def test_plot_of_a_log_whose_rows_do_not_line_up_is_refused_and_writes_nothing(tmp_path,
                                                                               capsys):
    out = tmp_path / "figures"
    assert _main(["plot", str(_short_time_log(tmp_path)), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and "expected one row per tick" in err and "'p'" in err
    assert not out.exists()  # no empty output folder left behind


def test_plot_of_a_log_with_nan_positions_says_so(tmp_path, capsys):
    log = synthetic_log(duration=0.1)
    log["p"] = np.array(log["p"], dtype=float)
    log["p"][3:7] = np.nan  # 4 rows
    path = tmp_path / "nan.npz"
    np.savez(path, **log)
    assert _main(["plot", str(path), "--out", str(tmp_path / "figures")]) == 0
    err = capsys.readouterr().err
    assert "log key 'p' is NaN on 4 of" in err, err


def test_emulator_port_out_of_range_is_bad_usage(capsys):
    assert _main(["emulate", "--port", "99999"]) == 2
    err = capsys.readouterr().err
    assert "--port" in err and "99999" in err and "OverflowError" not in err


def test_ctrl_c_while_the_command_imports_is_exit_130_without_traceback(monkeypatch, capsys):
    # main's first imports (pydrake, the kernels) take about a second: a Ctrl-C there must end
    # as one anywhere else does. A module whose attribute lookup raises stands in for the
    # interrupted import.
    class Interrupted(types.ModuleType):
        def __getattr__(self, name):
            if name.startswith("__"):  # what inspect and pytest look up
                raise AttributeError(name)
            raise KeyboardInterrupt

    monkeypatch.setitem(sys.modules, "cdpm_drake.hardware.tick_log",
                        Interrupted("cdpm_drake.hardware.tick_log"))
    assert cli.main(["list"]) == 130
    assert "interrupted" in capsys.readouterr().err


def test_info_reads_a_yaml_without_robot_fields_as_a_scenario(tmp_path, capsys):
    # Neither robot, initial_position nor operator: `cdpm simulate` runs it as a scenario of
    # paper_7cable, so `cdpm info` must read it as one, not as a robot file lacking reels.
    path = tmp_path / "s.yaml"
    path.write_text("duration: 2.0\nadmittance: {mass: 3.0}\n")
    assert _main(["info", str(path), "--grid", "0.25"]) == 0
    assert capsys.readouterr().out.startswith("scenario 'unnamed': robot 'paper_7cable'")


def test_time_below_d_l_ignores_round_off_at_the_barrier():
    # The filter holds a pair at d_l: 1.5 nm below it is round-off, 2 um below is below.
    scenario = Scenario()
    log = synthetic_log(duration=0.1, d13=(0.2, 0.2), d57=(0.2, 0.2))
    d_l = np.asarray(log["d_l"], dtype=float)
    T = len(log["time"])
    for below, expected in ((1.5e-9, 0.0), (2e-6, (T - 1) * 0.002)):
        d = np.array(log["pair_distances"], dtype=float)
        d[:, 0] = d_l[0] - below
        log["pair_distances"] = d
        assert run_metrics(log, scenario)["time_below_d_l"] == pytest.approx(expected), below


@pytest.mark.parametrize("x, digits, sign, text", [
    (-1.5e-6, 2, False, "0.00"), (-0.004, 2, True, "+0.00"), (-0.006, 2, False, "-0.01"),
    (0.004, 2, True, "+0.00"), (1.234, 1, True, "+1.2"), (-2.5, 2, False, "-2.50")])
def test_numbers_that_round_to_zero_print_without_a_sign(x, digits, sign, text):
    assert format_number(x, digits, sign) == text


@pytest.mark.parametrize("swaps, words", [
    ([[1, 1]], "swaps cable 1 with itself"),
    ([[1, 3], [3, 1]], "swaps[0] = [1, 3], swaps[1] = [3, 1] undo each other"),
    ([[2, 4], [1, 3], [4, 2]], "swaps[0] = [2, 4], swaps[2] = [4, 2] undo each other")])
def test_swaps_that_swap_nothing_are_refused(swaps, words):
    with pytest.raises(ScenarioError) as e:
        scenario_robot(Scenario(swaps=swaps))
    assert words in str(e.value)


def test_swaps_that_chain_are_a_permutation_not_an_error():
    # 1-3 then 3-5: cable 1 gets 3's attachment, 3 gets 5's, 5 gets 1's (a cycle, no cable
    # back where it was), the same as moving the attachments by hand.
    base = scenario_robot(Scenario())
    r = scenario_robot(Scenario(swaps=[[1, 3], [3, 5]]))
    expected = base.with_swapped_attachments(1, 3).with_swapped_attachments(3, 5)
    np.testing.assert_array_equal(r.attachments, expected.attachments)
    assert not np.array_equal(r.attachments[[0, 2, 4]], base.attachments[[0, 2, 4]])


def test_info_swaps_option_that_swaps_nothing_is_bad_usage(capsys):
    assert _main(["info", "paper_7cable", "--swaps", "1-3", "3-1"]) == 2
    assert "undo each other" in capsys.readouterr().err
    assert _main(["info", "paper_7cable", "--swaps", "1-9"]) == 2
    assert "cannot swap cable 9" in capsys.readouterr().err


def test_a_key_written_twice_is_refused_with_both_lines(tmp_path, capsys):
    path = tmp_path / "dup.yaml"
    path.write_text("duration: 0.01\nadmittance:\n  mass: 3.0\n  damping: 5.0\n  mass: 4.0\n")
    assert _main(["simulate", str(path), "--out", str(tmp_path / "run")]) == 1
    err = capsys.readouterr().err
    assert "'mass' (admittance.mass) on lines 3 and 5" in err
    assert not (tmp_path / "run").exists()
    assert _main(["simulate", "exp1_no_interaction", "--scenario-text",
                  "duration: 0.01\nduration: 0.02", "--out", str(tmp_path / "run2")]) == 1
    assert "'duration' (duration) on lines 1 and 2" in capsys.readouterr().err



def _filter_log():
    """20 ticks of 2 ms: kappa below 0 on ticks 5-9 (to -0.11 N) and 14-15; the speed ball
    binding at max_velocity 0.5 m/s on ticks 0-1, at the lost-margin cap (0.05 m/s) on 6-9;
    the pairs binding on 6-9 as well (a tick bound two ways)."""
    from cdpm_drake.kernels.safety_filter import (BIND_PAIR, BIND_SPEED, STATUS_MODIFIED,
                                                  STATUS_PASS)

    T = 20
    kappa = np.full(T, 2.0)
    kappa[5:10] = [-0.01, -0.05, -0.11, -0.08, -0.02]
    kappa[14:16] = -0.03
    status = np.full(T, STATUS_PASS)
    binding = np.zeros(T, dtype=int)
    velocity = np.zeros((T, 3))
    status[[0, 1]] = STATUS_MODIFIED
    binding[[0, 1]] = BIND_SPEED
    velocity[[0, 1], 0] = 0.5
    status[6:10] = STATUS_MODIFIED
    binding[6:10] = BIND_SPEED | BIND_PAIR
    velocity[6:10, 0] = 0.05
    return {"time": 0.002 * np.arange(T), "filter_status": status, "filter_binding": binding,
            "velocity": velocity, "kappa": kappa, "pair_margin": np.full(T, 0.004),
            "max_velocity": np.array(0.5)}


def test_the_filter_summary_says_when_a_margin_was_lost_and_names_the_cap():
    from cdpm_drake.cli.summaries import safety_filter_summary

    text = safety_filter_summary(_filter_log())
    # 7 ticks below 0 in two spans, 14 ms (7 x 2 ms), the first from tick 5 to 9.
    assert ("kinetostatic margin LOST on 7 ticks (0.014 s in 2 spans, the first from 0.010 to "
            "0.018 s), down to -0.11 N") in text, text
    assert "speed limit 2," in text and "lost-margin speed cap (towards 0.05 m/s) 4" in text
    assert "cable pairs 4" in text
    # 2 + 4 + 4 bound against 6 ticks changed: the summary says why they add up to more.
    assert "a tick can bind several ways" in text
    assert "changed 6" in text


@pytest.mark.parametrize("text, words", [
    ("", "the file is empty"),
    ("# only a comment\n", "the file is empty"),
    ("- 1\n- 2\n", "a scenario is a mapping of fields"),
    ("duration: .nan\n", "line 1: duration must be a finite number > 0, got nan"),
    ("duration: 0.1\nadmittance:\n  mass: -1.0\n", "line 3: admittance.mass must be a finite "
                                                   "number > 0, got -1.0")])
def test_a_bad_scenario_file_is_named_with_its_line_not_python_class_names(tmp_path, capsys,
                                                                          text, words):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    assert _main(["simulate", str(path), "--no-progress", "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert words in err and str(path) in err and "<class" not in err, err


def test_a_bad_value_in_an_overlay_is_named_with_the_overlays_line(tmp_path, capsys):
    assert _main(["simulate", "exp1_no_interaction", "--scenario-text",
                  "duration: 0.1\nadmittance: {mass: -2}", "--out", str(tmp_path / "o")]) == 1
    assert "--scenario-text 'duration: 0.1\\nadmittance: {mass: -2}': line 2: admittance.mass" \
        in capsys.readouterr().err


def test_a_robot_given_as_a_folder_says_so(tmp_path, capsys):
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "mine.yaml").write_text("name: x\n")
    path = tmp_path / "s.yaml"
    path.write_text("robot: robots/\nduration: 0.01\n")
    assert _main(["simulate", str(path), "--out", str(tmp_path / "o")]) == 1
    assert "is a folder, not a robot file: give the .yaml file itself (it holds ['mine.yaml'])" \
        in capsys.readouterr().err


def test_recover_of_a_folder_that_does_not_exist_says_so(tmp_path, capsys):
    assert _main(["recover", str(tmp_path / "nodir")]) == 1
    assert "does not exist" in capsys.readouterr().err


def _tick_stream(run_dir, rows=51):
    """A `cdpm run` folder as a killed run leaves it: scenario.yaml and a ticks.bin of `rows`
    whole rows (exp1 on the reel bridge; the position, hand force, lengths and distances
    written as the real-time loop's sink writes them, tick = t / time_step)."""
    from cdpm_drake.config import load_scenario, scenario_robot, scenario_to_yaml
    from cdpm_drake.hardware.tick_log import TickLogWriter, tick_log_header

    scenario = load_scenario("exp1_no_interaction", "plant: !HardwareReels {}\nduration: 0.1")
    run_dir.mkdir()
    (run_dir / "scenario.yaml").write_text(scenario_to_yaml(scenario))
    P = scenario_robot(scenario).num_pairs
    with TickLogWriter(run_dir / "ticks.bin", {"p": 3, "F_H": 3, "lengths": 7,
                                               "pair_distances": P}) as writer:
        for k in range(rows):
            writer.append(k * scenario.time_step, {"p": [1.5, 2.0, 1.0], "F_H": [0, 0, 0],
                                                   "lengths": np.ones(7),
                                                   "pair_distances": np.full(P, 0.1)}, tick=k)
    return tick_log_header(run_dir / "ticks.bin")


def test_recover_counts_the_rows_the_damage_garbled(tmp_path, capsys):
    # Three rows in the middle overwritten with 0xFF bytes (NaN floats, tick -1): before,
    # "the tail was whole" and nothing else, the NaN rows passed as data.
    run_dir = tmp_path / "run"
    header = _tick_stream(run_dir)
    data = bytearray((run_dir / "ticks.bin").read_bytes())
    row = header["dtype"].itemsize
    start = header["data_offset"] + 20 * row
    data[start:start + 3 * row] = b"\xff" * (3 * row)
    (run_dir / "ticks.bin").write_bytes(bytes(data))
    assert _main(["recover", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert ("recovered 51 ticks of 51 (completed); the tail was whole (no partial row); but 3 "
            "of the 51 rows are DAMAGED (tick counter, clock or position/force/lengths "
            "unreadable: rows 20, 21, 22)") in out, out


def test_recover_of_an_undamaged_stream_says_only_that_the_tail_was_whole(tmp_path, capsys):
    run_dir = tmp_path / "run"
    _tick_stream(run_dir)
    assert _main(["recover", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert "the tail was whole (no partial row); log:" in out and "DAMAGED" not in out


def test_a_scenario_name_never_puts_the_run_folder_outside_runs(tmp_path, capsys,
                                                                monkeypatch):
    # `name: ../../etc/x` wrote runs/../../etc/x/<stamp>/: two levels above runs/.
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    (work / "s.yaml").write_text("name: ../../etc/x\nduration: 0.01\n")
    assert _main(["simulate", "s.yaml", "--no-progress"]) == 1
    assert "name must be one folder name" in capsys.readouterr().err
    assert not (tmp_path / "etc").exists() and not (work / "runs").exists()


def test_a_null_overlay_says_it_is_empty(capsys):
    assert _main(["simulate", "exp1_no_interaction", "--scenario-text", "null",
                  "--duration", "0.01", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "the overlay is empty" in err and "NoneType" not in err, err
