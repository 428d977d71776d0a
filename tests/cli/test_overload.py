"""A cable pulled above the controller's ceiling (controller.max_tension) is never passed
over in silence: above it the summaries of `cdpm simulate` (and `cdpm run`, which prints the
same line from its log) warn, naming each cable (1-based), its peak, when, and its ticks above;
above model_monitor.overload times it, for model_monitor.ticks ticks, the model monitor stops
the run (zero reel velocity, as every fault). A synthetic log whose numbers are set here, and
exp2 on the dynamic plant with a 15 N ceiling (its drive-torque sensor reads 21-27 N on
cables 2, 3 and 7 within the first second), every expected number read from its own log."""

import re

import numpy as np

from cdpm_drake import cli
from cdpm_drake.cli.summaries import overload_summary


def test_the_warning_names_each_cable_its_peak_when_and_its_ticks():
    T = np.full((6, 3), 20.0)
    T[2:5, 1] = [120.0, 203.0, 150.0]  # cable 2: 3 ticks above 100 N, 203 N at t = 0.006 s
    T[5, 2] = 100.5
    T[0, 0] = np.nan  # no reading: never above
    log = {"time": np.arange(6) * 0.002, "tension_measured": T}
    assert overload_summary(log, 100.0, 150.0) == (
        "WARNING: a cable's measured tension went ABOVE the ceiling controller.max_tension = "
        "100 N on 4 of 6 ticks: cable 2 up to 203.0 N at t = 0.006 s (3 ticks), cable 3 up to "
        "100.5 N at t = 0.010 s (1 tick); the model monitor stops a run at 150 N "
        "(model_monitor.overload)")
    assert overload_summary(log, 300.0) == ""
    # Nothing measured (the kinematic plant's NaN): the dynamic plant's truth if logged.
    truth = {"time": log["time"], "tension_measured": np.full((6, 3), np.nan), "tensions": T}
    assert overload_summary(truth, 200.0).startswith(
        "WARNING: a cable's true (the dynamic plant's) tension went ABOVE the ceiling "
        "controller.max_tension = 200 N on 1 of 6 ticks: cable 2 up to 203.0 N")
    assert overload_summary({"time": log["time"],
                             "tension_measured": np.full((6, 3), np.nan)}, 10.0) == ""


_LOW_CEILING = "plant: !DynamicReels {}\ncontroller: {max_tension: 15}\n"


def test_simulate_warns_of_a_measured_tension_above_the_ceiling(tmp_path, capsys):
    out_dir = tmp_path / "run"
    assert cli.main(["simulate", "exp2_interaction", "--scenario-text",
                     _LOW_CEILING + "model_monitor: {overload: 0}", "--duration", "0.2",
                     "--out", str(out_dir), "--no-progress"]) == 0
    out = capsys.readouterr().out
    with np.load(out_dir / "log.npz") as log:
        T, time = log["tension_measured"], log["time"]
    above = T > 15.0
    assert above.any()
    cables = []
    for i in np.flatnonzero(above.any(axis=0)):
        k = int(np.argmax(T[:, i]))
        n = int(above[:, i].sum())
        cables.append(f"cable {i + 1} up to {T[k, i]:.1f} N at t = {time[k]:.3f} s "
                      f"({n} tick{'s' if n != 1 else ''})")
    line = (f"WARNING: a cable's measured tension went ABOVE the ceiling controller.max_tension "
            f"= 15 N on {int(above.any(axis=1).sum())} of {len(time)} ticks: "
            f"{', '.join(cables)}\n")
    assert line in out, out


def test_a_cable_measured_above_the_overload_stops_the_run(tmp_path, capsys):
    # overload 1.1 x 15 N = 16.5 N: exp2's start already pulls cable 2 to ~23 N, so the
    # monitor stops the run after model_monitor.ticks (5) ticks, naming cable 2.
    out_dir = tmp_path / "run"
    assert cli.main(["simulate", "exp2_interaction", "--scenario-text",
                     _LOW_CEILING + "model_monitor: {overload: 1.1}", "--duration", "0.2",
                     "--out", str(out_dir), "--no-progress"]) == 1
    captured = capsys.readouterr()
    with np.load(out_dir / "log.npz") as log:
        T, time = log["tension_measured"], log["time"]
        assert str(log["ending"]) == "fault"
    m = re.search(r"cdpm simulate: error: the run stopped at t = ([0-9.]+) s: cable (\d) is "
                  r"overloaded: its measured tension is ([0-9.]+) N, above 16\.5 N "
                  r"\(model_monitor\.overload x controller\.max_tension\) for 5 ticks "
                  r"\(10 ms\)", captured.err)
    assert m, captured.err
    # The log ends on the tick before the fault's; the cable named was above 16.5 N on every
    # logged tick (a fault needs 5 in a row), and the run stopped within 5 ticks.
    assert float(m.group(1)) == round(float(time[-1]), 3) and len(time) <= 5
    assert (T[:, int(m.group(2)) - 1] > 16.5).all() and float(m.group(3)) > 16.5
    assert "the model monitor stops a run at 16.5 N (model_monitor.overload)" in captured.out


def test_cdpm_runs_summary_repeats_the_warning(tmp_path, capsys, monkeypatch):
    # `cdpm run`'s report is made from its log as simulate's is: a log whose cable 4 read
    # 140 N (ceiling 100 N, overload 200 N: no fault) at t = 0.018 s ends "completed" with the
    # warning (the rehearsal reached 203 N and said only "run ended: completed").
    from helpers_synthetic_log import synthetic_log

    from cdpm_drake.cli.run import run_main
    from cdpm_drake.config import load_scenario
    from cdpm_drake.runs import realtime

    log = synthetic_log(duration=0.1, realtime=True)
    T = np.full((len(log["time"]), 7), 30.0)
    T[8:12, 3] = [110.0, 140.0, 120.0, 101.0]
    log["tension_measured"] = T

    def fake_run(**kwargs):
        return realtime.RunResult(log=log, timing={}, link={"sent": 51, "rejected": {}},
                                  error=None, ending="completed", log_path=None,
                                  tick_log_path=None)

    monkeypatch.setattr(realtime, "run", fake_run)
    scenario = load_scenario("exp1_no_interaction", "plant: !HardwareReels {}")
    assert run_main(scenario=scenario, out_dir=tmp_path / "run") == 0
    out = capsys.readouterr().out
    assert "run ended: completed" in out
    assert ("WARNING: a cable's measured tension went ABOVE the ceiling controller.max_tension "
            "= 100 N on 4 of 51 ticks: cable 4 up to 140.0 N at t = 0.018 s (4 ticks); the "
            "model monitor stops a run at 200 N (model_monitor.overload)") in out, out
