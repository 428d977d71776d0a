"""Every option of `cdpm simulate`, `run`, `emulate`, `plot`, `diagram` and `info` reaches the
run: each is asserted from its effect (the log's length for --duration, the folder for
--out, the wall time for --realtime, the files written, the bridge built), not from what the
command prints. `test_every_cli_option_has_a_case` walks the argparse parsers and fails on an
option with no case here.

Where a run's files land is found by the helpers `run_folder` / `run_log` only (today
runs/<name>/<UTC timestamp>/ with a `latest` link), so that a change of the folder layout is
adapted in one place.
"""

import argparse
import builtins
import importlib
import socket
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import case_registry

from cdpm_drake import cli
from cdpm_drake.cli.cdpm import build_parser
from cdpm_drake import emulator as E
from cdpm_drake.emulator import FaultPlan, ReelBridge, ReelBridgeServer
from cdpm_drake.hardware.protocol import Command, encode_command
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.robot import load_robot
from cdpm_drake.config import load_scenario, scenario_robot

T = 0.002
# The figures every log gets (views/plots.py may add more).
PAPER_FIGURES = {"distances.png", "forces.png", "trajectory.png", "logistic.png"}
CASES: dict[str, str] = {}
# Registers the options a test checks: "<command> --option", or "<command> <dest>" for a
# positional argument.
covers = case_registry(CASES)


# --- where a run's files are (one place to adapt when the layout changes) ------------------


def run_folder(root: Path, name: str) -> Path:
    """The folder of the latest run named `name` under `root` (the working directory of the
    command) when no --out is given."""
    base = Path(root) / "runs" / name
    latest = base / "latest"
    return latest if latest.exists() else base


def run_log(folder: Path) -> dict:
    with np.load(Path(folder) / "log.npz") as data:
        return {k: data[k] for k in data.files}


def cdpm(*args) -> int:
    return cli.main([str(a) for a in args])


def settle(server, quiet=0.1, timeout=3.0):
    """Wait until an in-process bridge has read every command sent to it (none new for
    `quiet` s): on a busy host its thread may lag behind the run that just returned."""
    deadline = time.monotonic() + timeout
    count, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        n = server.counters["commands_received"]
        if n != count:
            count, since = n, time.monotonic()
        elif time.monotonic() - since >= quiet:
            return
        time.sleep(0.01)


def _scenario_file(tmp_path, name="cli_wire", duration=0.1, extra=""):
    """exp1's robot and start, no operator, under a name only these tests use."""
    path = tmp_path / f"{name}.yaml"
    path.write_text(f"name: {name}\nrobot: paper_7cable\nswaps: [[1, 3]]\n"
                    f"initial_position: [1.77, 3.65, 1.22]\nduration: {duration}\n"
                    f"operator: !NoOperator {{}}\n{extra}")
    return path


# --- the parser walk ---------------------------------------------------------------------------


def _options(parser, command):
    keys = []
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        if action.option_strings:
            keys.append(f"{command} {max(action.option_strings, key=len)}")
        else:
            keys.append(f"{command} <{action.dest}>")
    return keys


def all_cli_options():
    """Every option of every cdpm command; `emulate` hands its arguments to the emulator's own
    parser, whose options are listed instead."""
    parser = build_parser()
    keys = [k for k in _options(parser, "cdpm")]
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for command, p in sub.choices.items():
        if command == "emulate":
            keys += _options(E.build_parser(), "emulate")
        else:
            keys += _options(p, command)
    return keys


def test_every_cli_option_has_a_case():
    options = all_cli_options()
    assert "simulate --duration" in options and "emulate --fault-after" in options
    missing = sorted(set(options) - set(CASES))
    stale = sorted(set(CASES) - set(options))
    assert not missing, f"CLI options with no wiring case in {__file__}: {missing}"
    assert not stale, f"wiring cases for options that no longer exist: {stale}"


# --- simulate ------------------------------------------------------------------------------------


@covers("simulate <scenario>")
def test_simulate_runs_the_scenario_given_into_runs_slash_its_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cdpm("simulate", _scenario_file(tmp_path, duration=0.03), "--no-progress") == 0
    log = run_log(run_folder(tmp_path, "cli_wire"))
    assert str(log["scenario_name"]) == "cli_wire"
    assert len(log["time"]) == 16  # 0.03 s / 2 ms + 1 rows


@covers("simulate --scenario-text")
def test_simulate_scenario_text_overlays_the_run(tmp_path):
    out = tmp_path / "o"
    text = "{duration: 0.02, admittance: {damping: 3.7}, interference: {default: {F_u: 3.1}}}"
    assert cdpm("simulate", _scenario_file(tmp_path), "--scenario-text", text, "--out", out,
                "--no-progress") == 0
    log = run_log(out)
    assert len(log["time"]) == 11
    np.testing.assert_array_equal(log["F_u"], 3.1)
    assert load_scenario(out / "scenario.yaml").admittance.damping == 3.7


@covers("simulate --method", "diagram --method")
def test_method_paper_runs_and_draws_fig_5_without_the_filter(tmp_path):
    out = tmp_path / "o"
    assert cdpm("simulate", _scenario_file(tmp_path), "--method", "paper", "--out", out,
                "--no-progress") == 0
    assert "filter_status" not in run_log(out)
    assert cdpm("diagram", _scenario_file(tmp_path), "--method", "paper", "--out",
                tmp_path / "d", "--no-svg") == 0
    assert cdpm("diagram", _scenario_file(tmp_path), "--out", tmp_path / "p", "--no-svg") == 0
    paper = (tmp_path / "d" / "controller_simulated.dot").read_text()
    promise = (tmp_path / "p" / "controller_simulated.dot").read_text()
    assert "safety_filter" not in paper and "safety_filter" in promise


@covers("simulate --duration")
def test_simulate_duration_sets_the_log_length(tmp_path):
    # The scenario says 0.1 s; --duration 0.046 s gives 0.046 / 0.002 + 1 = 24 rows.
    out = tmp_path / "o"
    assert cdpm("simulate", _scenario_file(tmp_path), "--duration", 0.046, "--out", out,
                "--no-progress") == 0
    log = run_log(out)
    assert len(log["time"]) == 24 and log["time"][-1] == pytest.approx(0.046)
    assert load_scenario(out / "scenario.yaml").duration == pytest.approx(0.046)


@covers("simulate --out")
def test_simulate_out_is_the_folder_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "exactly" / "here"
    assert cdpm("simulate", _scenario_file(tmp_path, duration=0.01), "--out", out,
                "--no-progress") == 0
    assert sorted(p.name for p in out.iterdir()) == ["log.npz", "scenario.yaml"]
    assert not (tmp_path / "runs").exists()


@covers("simulate --force")
def test_simulate_force_replaces_an_earlier_run_in_out(tmp_path):
    # A second run into the same --out is refused (exit 2, the first log kept) unless --force,
    # which gives the second run's log (0.03 s: 16 rows instead of 11).
    scenario = _scenario_file(tmp_path, duration=0.02)
    out = tmp_path / "o"
    assert cdpm("simulate", scenario, "--out", out, "--no-progress") == 0
    assert cdpm("simulate", scenario, "--out", out, "--duration", 0.03, "--no-progress") == 2
    assert len(run_log(out)["time"]) == 11
    assert cdpm("simulate", scenario, "--out", out, "--duration", 0.03, "--no-progress",
                "--force") == 0
    assert len(run_log(out)["time"]) == 16


@covers("simulate --no-progress")
def test_simulate_no_progress_removes_the_progress_bar(tmp_path, capsys):
    scenario = _scenario_file(tmp_path, duration=0.02)
    assert cdpm("simulate", scenario, "--out", tmp_path / "a") == 0
    with_bar = capsys.readouterr().err
    assert cdpm("simulate", scenario, "--out", tmp_path / "b", "--no-progress") == 0
    without = capsys.readouterr().err
    # tqdm's bar on stderr, named after the scenario.
    assert "cli_wire:" in with_bar and "100%|" in with_bar
    assert "%|" not in without


def _elapsed(*args):
    start = time.monotonic()
    code = cdpm(*args)
    return code, time.monotonic() - start


@covers("simulate --realtime")
def test_simulate_realtime_paces_the_run(tmp_path):
    """0.2 s simulated at rate 0.5 takes at least 0.4 s of wall time; unpaced it takes far less
    (the 0.2 s run itself is ~0.05 s of work)."""
    scenario = _scenario_file(tmp_path)
    code, paced = _elapsed("simulate", scenario, "--duration", 0.2, "--realtime", 0.5,
                           "--out", tmp_path / "a", "--no-progress")
    assert code == 0 and paced >= 0.4 * 0.98
    assert len(run_log(tmp_path / "a")["time"]) == 101


class _CountingView:
    """Wraps meshcat_view.live_view_callback to count the frames a live view was given."""

    def __init__(self, monkeypatch):
        from cdpm_drake.views import meshcat_view

        self.calls = 0
        real = meshcat_view.live_view_callback

        def wrapped(view, read_latest):
            inner = real(view, read_latest)

            def on_chunk(diagram, context):
                self.calls += 1
                inner(diagram, context)

            return on_chunk

        monkeypatch.setattr(meshcat_view, "live_view_callback", wrapped)


@covers("simulate --meshcat")
def test_simulate_meshcat_draws_live_and_paces_at_real_time(tmp_path, monkeypatch):
    # 0.2 s with --meshcat: drawn every 0.04 s (5 frames or more) and paced at rate 1.0, so
    # at least 0.2 s of wall time.
    view = _CountingView(monkeypatch)
    code, wall = _elapsed("simulate", _scenario_file(tmp_path), "--duration", 0.2,
                          "--meshcat", "--no-wait", "--out", tmp_path / "o", "--no-progress")
    assert code == 0 and view.calls >= 5 and wall >= 0.2 * 0.98
    assert len(run_log(tmp_path / "o")["time"]) == 101


@covers("simulate --no-wait")
def test_simulate_no_wait_skips_the_prompt_at_the_end(tmp_path, monkeypatch):
    """On a terminal --meshcat waits for Enter at the end (the view keeps serving); --no-wait
    does not ask."""

    class Tty:
        def isatty(self):
            return True

    asked = []
    monkeypatch.setattr(sys, "stdin", Tty())
    monkeypatch.setattr(builtins, "input", lambda prompt="": asked.append(prompt) or "")
    scenario = _scenario_file(tmp_path, duration=0.02)
    args = ("simulate", scenario, "--meshcat", "--realtime", 100, "--no-progress")
    assert cdpm(*args, "--out", tmp_path / "a") == 0
    assert len(asked) == 1
    assert cdpm(*args, "--no-wait", "--out", tmp_path / "b") == 0
    assert len(asked) == 1


@covers("simulate --html")
def test_simulate_html_writes_a_replay_file(tmp_path):
    html = tmp_path / "replay" / "r.html"
    html.parent.mkdir()
    assert cdpm("simulate", _scenario_file(tmp_path, duration=0.02), "--html", html,
                "--out", tmp_path / "o", "--no-progress") == 0
    text = html.read_text()
    assert text.lstrip().lower().startswith("<!doctype html") or "<html" in text[:2000].lower()
    assert len(text) > 10_000  # the scene and its animation, not an empty page


@covers("simulate --plot")
def test_simulate_plot_writes_the_figures_beside_the_log(tmp_path):
    out = tmp_path / "o"
    assert cdpm("simulate", _scenario_file(tmp_path, duration=0.02), "--plot", "--out", out,
                "--no-progress") == 0
    pngs = {p.name for p in out.glob("*.png")}
    assert PAPER_FIGURES <= pngs
    assert all((out / p).stat().st_size > 1000 for p in pngs)


# --- run (against an in-process emulated bridge) ----------------------------------------------


@pytest.fixture
def bridge():
    """A bridge for exp1's robot and start; yields a function giving the overlay that points
    a scenario at it."""
    scenario = load_scenario("exp1_no_interaction")
    robot = scenario_robot(scenario)
    server = ReelBridgeServer(ReelBridge(
        robot, cable_lengths(robot, np.array(scenario.initial_position)), time_constant=0.0),
        address=("127.0.0.1", 0), command_timeout=5.0).start()
    server.overlay = ("{plant: !HardwareReels {port: %d, watchdog_ticks: 500, ramp_time: 0.0}}"
                      % server.address[1])
    yield server
    server.stop()


@covers("run <scenario>", "run --scenario-text")
def test_run_drives_the_bridge_named_in_the_overlay(tmp_path, monkeypatch, bridge):
    monkeypatch.chdir(tmp_path)
    scenario = _scenario_file(tmp_path, name="cli_run", duration=0.1)
    assert cdpm("run", scenario, "--scenario-text", bridge.overlay) == 0
    folder = run_folder(tmp_path, "cli_run")
    log = run_log(folder)
    assert str(log["scenario_name"]) == "cli_run"
    assert len(log["time"]) == 51
    settle(bridge)
    assert bridge.counters["commands_received"] >= 50


@covers("run --duration")
def test_run_duration_sets_the_run_length(tmp_path, bridge):
    # The scenario says 10 s; --duration 0.13 s: 66 ticks logged, and the bridge saw about as
    # many commands (not six times more).
    scenario = _scenario_file(tmp_path, duration=10.0)
    out = tmp_path / "o"
    assert cdpm("run", scenario, "--scenario-text", bridge.overlay, "--duration", 0.13,
                "--out", out) == 0
    log = run_log(out)
    assert len(log["time"]) == 66 and log["time"][-1] == pytest.approx(0.13)
    # The resolved scenario beside the log records the duration that ran.
    assert load_scenario(out / "scenario.yaml").duration == pytest.approx(0.13)
    settle(bridge)
    assert bridge.counters["commands_received"] < 200


@covers("run --out", "run --force")
def test_run_out_is_the_folder_and_force_overwrites_it(tmp_path, monkeypatch, bridge):
    monkeypatch.chdir(tmp_path)
    scenario = _scenario_file(tmp_path, duration=0.04)
    out = tmp_path / "exact"
    assert cdpm("run", scenario, "--scenario-text", bridge.overlay, "--out", out) == 0
    assert {"log.npz", "ticks.bin", "scenario.yaml"} <= {p.name for p in out.iterdir()}
    assert not (tmp_path / "runs").exists()
    assert len(run_log(out)["time"]) == 21
    # A second run into the same folder is refused (exit 2) and leaves the first log alone...
    assert cdpm("run", scenario, "--scenario-text", bridge.overlay, "--out", out,
                "--duration", 0.06) == 2
    assert len(run_log(out)["time"]) == 21
    # ... unless --force: then it is the second run's log.
    assert cdpm("run", scenario, "--scenario-text", bridge.overlay, "--out", out,
                "--duration", 0.06, "--force") == 0
    assert len(run_log(out)["time"]) == 31


@covers("run --method")
def test_run_method_paper_runs_without_the_filter(tmp_path, bridge):
    out = tmp_path / "o"
    assert cdpm("run", _scenario_file(tmp_path, duration=0.02), "--scenario-text",
                bridge.overlay, "--method", "paper", "--out", out) == 0
    log = run_log(out)
    assert "filter_status" not in log and len(log["time"]) == 11


@covers("run --plot")
def test_run_plot_writes_the_figures_beside_the_log(tmp_path, bridge):
    out = tmp_path / "o"
    assert cdpm("run", _scenario_file(tmp_path, duration=0.04), "--scenario-text",
                bridge.overlay, "--plot", "--out", out) == 0
    from cdpm_drake.views.plots import FIGURE_FILES, figures_of
    expected = {FIGURE_FILES[name] for name in figures_of(run_log(out))}
    assert expected and expected <= {p.name for p in out.glob("*.png")}


@covers("run --rt-priority")
def test_run_rt_priority_reaches_the_scheduler_call(tmp_path, monkeypatch, bridge):
    from cdpm_drake.hardware import priority

    asked = []
    monkeypatch.setattr(priority, "set_realtime_priority", asked.append)
    assert cdpm("run", _scenario_file(tmp_path, duration=0.02), "--scenario-text",
                bridge.overlay, "--rt-priority", 37, "--out", tmp_path / "o") == 0
    assert asked == [37]


@covers("run --lockstep", "emulate --lockstep")
def test_run_and_emulate_lockstep_tick_together(tmp_path, capsys):
    """`cdpm emulate --lockstep`'s server steps once per command; `cdpm run --lockstep`
    waits for each answer: the emulator's ticks are the run's commands, one for one (the
    start-up greeting, ticks 0..25 of 0.05 s, the final stop's copies), and the run folder's
    scenario says lockstep."""
    server = _server_from("--scenario", "exp1_no_interaction", "--port", 0, "--lockstep")
    assert server.lockstep
    server.start()
    try:
        out = tmp_path / "o"
        assert cdpm("run", _scenario_file(tmp_path, duration=0.05), "--scenario-text",
                    "{plant: !HardwareReels {port: %d, ramp_time: 0.0}}" % server.address[1],
                    "--lockstep", "--out", out) == 0
        assert "lockstep: each tick waited for the bridge's answer" in capsys.readouterr().out
        settle(server)
    finally:
        server.stop()
    log = run_log(out)
    assert len(log["time"]) == 26
    assert server.tick == server.counters["commands_received"] == 1 + 26 + 3
    assert "lockstep: true" in (out / "scenario.yaml").read_text()


@covers("run --meshcat")
def test_run_meshcat_draws_while_it_runs(tmp_path, monkeypatch, bridge):
    view = _CountingView(monkeypatch)
    assert cdpm("run", _scenario_file(tmp_path, duration=0.3), "--scenario-text",
                bridge.overlay, "--meshcat", "--out", tmp_path / "o") == 0
    assert view.calls >= 2  # every 0.1 s of a 0.3 s run


# --- emulate -------------------------------------------------------------------------------------


def _emulator_main():
    """The module emulator/main.py, where build_server and main look their names up (the
    package's attribute `main` is the function it re-exports)."""
    return importlib.import_module("cdpm_drake.emulator.main")


def _server_from(*args) -> ReelBridgeServer:
    """The bridge `cdpm emulate ARGS` serves (its own parser and builder), not yet started."""
    return E.build_server(E.build_parser().parse_args([str(a) for a in args]))


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@covers("emulate --scenario", "emulate --scenario-text")
def test_emulate_scenario_and_overlay_set_robot_start_and_operator(tmp_path):
    scenario = _scenario_file(tmp_path)
    text = ("{initial_position: [1.8, 3.6, 1.25], operator: !ScriptedOperator "
            "{times: [0], forces: [[0.7, -0.2, 0.1]]}}")
    server = _server_from("--scenario", scenario, "--scenario-text", text, "--port", 0)
    try:
        robot = scenario_robot(load_scenario(scenario))  # cables 1 and 3 swapped
        assert server.bridge.robot.name == robot.name == "paper_7cable_swap13"
        np.testing.assert_allclose(server.bridge.lengths,
                                   cable_lengths(robot, np.array([1.8, 3.6, 1.25])), atol=1e-12)
        np.testing.assert_allclose(server.bridge.force_fn(0.0, np.zeros(3), np.zeros(3)),
                                   [0.7, -0.2, 0.1])
    finally:
        server.stop()


def test_emulate_listens_where_the_scenario_plant_says():
    # No --address / --port: the scenario's !HardwareReels address and port are used, so
    # `cdpm run` and `cdpm emulate` given the same scenario meet.
    port = _free_port()
    text = "{plant: !HardwareReels {address: 127.0.0.6, port: %d}}" % port
    server = _server_from("--scenario", "exp1_no_interaction", "--scenario-text", text)
    try:
        assert server.address == ("127.0.0.6", port)
    finally:
        server.stop()


@covers("emulate --robot", "emulate --start", "emulate --length-offset")
def test_emulate_robot_start_and_length_offset_set_the_reels(tmp_path, write_robot,
                                                             valid_spec):
    path = write_robot(valid_spec)
    server = _server_from("--robot", path, "--start", 2.1, 1.4, 1.6, "--length-offset", 3,
                          0.017, "--length-offset", 1, -0.004, "--port", 0)
    try:
        robot = load_robot(path)
        expected = cable_lengths(robot, np.array([2.1, 1.4, 1.6]))
        expected[2] += 0.017  # cable 3 is row 2
        expected[0] -= 0.004
        assert server.bridge.robot.name == "tetra_4cable"
        np.testing.assert_allclose(server.bridge.lengths, expected, atol=1e-12)
    finally:
        server.stop()


@covers("emulate --force", "emulate --time-constant")
def test_emulate_force_and_time_constant_set_the_bridge_physics():
    server = _server_from("--force", 1.5, -2.5, 0.25, "--time-constant", 0.037, "--port", 0)
    try:
        np.testing.assert_array_equal(server.bridge.force_fn(0.3, np.ones(3), np.ones(3)),
                                      [1.5, -2.5, 0.25])
        assert server.bridge.time_constant == 0.037
    finally:
        server.stop()


@covers("emulate --plant")
def test_emulate_plant_dynamic_plays_the_scenarios_dynamic_plant():
    # --plant dynamic: the bridge is the dynamic plant of the scenario (start, robot, operator;
    # the encoders zeroed at the start pose: they read the rigid lengths there), --force and
    # --length-offset reach it; --plant kinematic (the default) is the first-order lag.
    server = _server_from("--scenario", "exp2_interaction", "--plant", "dynamic", "--force",
                          0.5, 0.0, 1.0, "--length-offset", 2, 0.003, "--port", 0)
    try:
        bridge = server.bridge
        assert isinstance(bridge, E.DynamicBridge)
        scenario = load_scenario("exp2_interaction")
        expected = cable_lengths(scenario_robot(scenario), np.array(scenario.initial_position))
        expected[1] += 0.003
        np.testing.assert_allclose(bridge.lengths, expected, atol=1e-12)
        np.testing.assert_allclose(bridge.force(), [0.5, 0.0, 1.0], atol=1e-12)
    finally:
        server.stop()
    kinematic = _server_from("--scenario", "exp2_interaction", "--port", 0)
    try:
        assert isinstance(kinematic.bridge, ReelBridge)
        assert kinematic.bridge.time_constant == 0.02
    finally:
        kinematic.stop()
    # The dynamic plant's drives come from the robot file: a lag for them is refused.
    assert cdpm("emulate", "--plant", "dynamic", "--time-constant", 0.01, "--port", 0,
                "--duration", 0.01) == 2


@covers("emulate --address", "emulate --port")
def test_emulate_address_and_port_are_where_it_listens():
    port = _free_port()
    server = _server_from("--address", "127.0.0.5", "--port", port)
    try:
        assert server.address == ("127.0.0.5", port)
    finally:
        server.stop()


@covers("emulate --controller")
def test_emulate_controller_ignores_every_other_commander():
    server = _server_from("--port", 0, "--controller", "127.0.0.1:9")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        server.start()
        m = server.bridge.robot.num_cables
        sock.sendto(encode_command(Command(sequence=1, time=0.0, velocity=np.zeros(m),
                                           enable=False, echo_sequence=None)), server.address)
        deadline = time.monotonic() + 2.0
        while server.counters["commands_foreign"] == 0 and time.monotonic() < deadline:
            time.sleep(0.002)
        assert server.counters["commands_foreign"] == 1
        assert server.counters["commands_received"] == 0
    finally:
        sock.close()
        server.stop()


@covers("emulate --period", "emulate --command-timeout")
def test_emulate_period_and_command_timeout_reach_the_server():
    server = _server_from("--port", 0, "--period", 0.004, "--command-timeout", 0.09)
    try:
        assert server.period == 0.004 and server.command_timeout == 0.09
    finally:
        server.stop()


FAULT_FLAGS = [
    (("--drop", 0.125), dict(drop=0.125)),
    (("--delay", 0.0031), dict(delay=0.0031)),
    (("--duplicate", 0.25), dict(duplicate=0.25)),
    (("--reorder", 0.375), dict(reorder=0.375)),
    (("--corrupt", 0.0625), dict(corrupt=0.0625)),
    (("--freeze",), dict(freeze=True)),
    (("--nan",), dict(nan=True)),
    (("--stop",), dict(stop=True)),
    (("--fault-bits", "0x4"), dict(fault_bits=4)),
]


@covers("emulate --drop", "emulate --delay", "emulate --duplicate", "emulate --reorder",
        "emulate --corrupt", "emulate --freeze", "emulate --nan", "emulate --stop",
        "emulate --fault-bits", "emulate --fault-after")
@pytest.mark.parametrize("flag, plan", FAULT_FLAGS)
def test_emulate_fault_flags_make_the_fault_plan(flag, plan):
    server = _server_from("--port", 0, "--fault-after", 1.25, *flag)
    try:
        assert server.faults == FaultPlan(after=1.25, **plan)
    finally:
        server.stop()


@covers("emulate --seed")
def test_emulate_seed_reaches_the_server(monkeypatch):
    seen = []
    real = E.ReelBridgeServer

    def recording(*args, **kwargs):
        seen.append(kwargs.get("seed"))
        return real(*args, **kwargs)

    monkeypatch.setattr(_emulator_main(), "ReelBridgeServer", recording)
    _server_from("--port", 0, "--seed", 913).stop()
    assert seen == [913]


@covers("emulate --duration")
def test_emulate_duration_bounds_the_serving_time():
    code, wall = _elapsed("emulate", "--port", 0, "--duration", 0.3)
    assert code == 0 and 0.3 <= wall < 5.0


@covers("emulate --rt-priority")
def test_emulate_rt_priority_reaches_the_scheduler_call(monkeypatch):
    asked = []
    monkeypatch.setattr(_emulator_main(), "set_realtime_priority", asked.append)
    assert cdpm("emulate", "--port", 0, "--duration", 0.01, "--rt-priority", 41) == 0
    assert asked == [41]


@covers("emulate --protocol-version", "emulate --load-cells", "emulate --truth-log")
def test_emulate_protocol_version_load_cells_and_truth_log_reach_the_server(tmp_path):
    # Issue 31: the version spoken, load cells on the dynamic plant (the simulated plant's),
    # and the truth log written when the emulator stops (no status sent here: zero rows).
    v1 = _server_from("--port", 0, "--protocol-version", 1)
    try:
        assert v1.protocol_version == 1
    finally:
        v1.stop()
    server = _server_from("--scenario", "exp2_interaction", "--plant", "dynamic",
                          "--load-cells", "--truth-log", tmp_path / "t.npz", "--port", 0)
    try:
        assert server.protocol_version == 2 and server.truth is not None
        # The simulated plant's load cells: the true tensions plus each cell's bias (at
        # rest, before the plant starts).
        import dataclasses

        from cdpm_drake.config import DynamicReels
        from cdpm_drake.systems.plants.dynamic_plant import sensor_kernel
        true = server.bridge.true_tensions()
        exp2 = load_scenario("exp2_interaction")
        _, bias, _ = sensor_kernel(dataclasses.replace(exp2, plant=DynamicReels()),
                                   scenario_robot(exp2), true, "load_cell")
        np.testing.assert_allclose(server.bridge.load_cell(), true + bias, rtol=0, atol=1e-9)
    finally:
        server.stop()
    truth = tmp_path / "truth.npz"
    assert cdpm("emulate", "--scenario", "exp2_interaction", "--plant", "dynamic", "--port", 0,
                "--duration", 0.05, "--truth-log", truth) == 0
    assert len(np.load(truth)["time"]) == 0


# --- plot ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    folder = tmp_path_factory.mktemp("logged")
    scenario = _scenario_file(folder, duration=0.04)
    assert cdpm("simulate", scenario, "--out", folder / "run", "--no-progress") == 0
    return folder / "run"


@covers("plot <log>")
@pytest.mark.parametrize("as_file", [False, True])
def test_plot_writes_the_figures_beside_the_log(tmp_path, logged, as_file):
    import shutil

    folder = tmp_path / "copy"
    shutil.copytree(logged, folder)
    assert cdpm("plot", folder / "log.npz" if as_file else folder) == 0
    assert PAPER_FIGURES <= {p.name for p in folder.glob("*.png")}
    assert not list(tmp_path.glob("*.png"))


@covers("plot --out", "plot --html")
def test_plot_out_and_html_are_where_the_files_go(tmp_path, logged):
    out = tmp_path / "figs"
    html = tmp_path / "replay.html"
    assert cdpm("plot", logged, "--out", out, "--html", html) == 0
    assert PAPER_FIGURES <= {p.name for p in out.glob("*.png")}
    assert not list(logged.glob("*.png"))
    assert html.stat().st_size > 10_000


# --- export ---------------------------------------------------------------------------------------


@covers("export <log>", "export --csv")
@pytest.mark.parametrize("as_file", [False, True])
def test_export_csv_writes_log_csv_beside_the_log(tmp_path, logged, as_file):
    import shutil

    folder = tmp_path / "copy"
    shutil.copytree(logged, folder)
    assert cdpm("export", folder / "log.npz" if as_file else folder, "--csv") == 0
    lines = (folder / "log.csv").read_text().splitlines()
    assert lines[0].startswith("time [s],p_x [m]") and len(lines) == 1 + 21  # 0.04 s: 21 ticks


@covers("export --out")
def test_export_out_is_where_the_csv_goes(tmp_path, logged):
    out = tmp_path / "elsewhere" / "table.csv"
    assert cdpm("export", logged, "--csv", "--out", out) == 0
    assert out.read_text().startswith("time [s],") and not (logged / "log.csv").exists()


@covers("export --mat", "export --mcap")
def test_export_mat_and_mcap_write_their_files(tmp_path, logged):
    # Issue 32: the format flags choose the writer (the files' contents: tests/views/
    # test_export_mat.py and test_export_mcap.py). The .mat's magic text and the .mcap's.
    pytest.importorskip("scipy")
    pytest.importorskip("rosbags")
    assert cdpm("export", logged, "--mat", "--out", tmp_path / "a.mat") == 0
    assert (tmp_path / "a.mat").read_bytes().startswith(b"MATLAB 5.0 MAT-file")
    assert cdpm("export", logged, "--mcap", "--out", tmp_path / "a.mcap") == 0
    assert (tmp_path / "a.mcap").read_bytes().startswith(b"\x89MCAP0\r\n")


def test_plot_logistic_curve_spans_the_band_and_never_negative_distances(logged):
    """Fig. 8 is drawn over [max(0, d_l - w), d_u + w] with w = d_u - d_l: for d_l = 10 mm,
    d_u = 30 mm that is 0..50 mm (d_l - w would be -10 mm)."""
    from cdpm_drake.views.figures_interference import figure_logistic

    log = run_log(logged)
    for key, value in (("d_l", 0.010), ("d_u", 0.030)):
        log[key] = np.full_like(log[key], value)
    ax = figure_logistic(log).axes[0]
    x = ax.lines[0].get_xdata()
    assert x.min() == 0.0 and x.max() == pytest.approx(50.0)


# --- diagram --------------------------------------------------------------------------------------


@covers("diagram <scenario>", "diagram --scenario-text", "diagram --out")
def test_diagram_draws_the_scenario_given_into_out(tmp_path):
    """The wall-force block exists only when the scenario enables it: given by the scenario
    file or by the overlay, it appears in both .dot files written to --out."""
    plain = _scenario_file(tmp_path)
    walled = _scenario_file(tmp_path, name="walled", extra="wall_force: {enabled: true}\n")
    for k, args in enumerate([(plain,), (walled,),
                              (plain, "--scenario-text", "{wall_force: {enabled: true}}")]):
        out = tmp_path / f"d{k}"
        assert cdpm("diagram", *args, "--out", out, "--no-svg") == 0
        dots = [out / "controller_simulated.dot", out / "controller_hardware.dot"]
        assert all(("wall_force" in p.read_text()) == (k > 0) for p in dots), k


@covers("diagram --depth", "diagram --no-svg")
def test_diagram_depth_expands_the_plant_and_no_svg_skips_svg(tmp_path):
    # At depth 1 the simulated plant is one box; by default (full depth) and at depth 2 its
    # inside (simulated_reels, operator) is drawn.
    scenario = _scenario_file(tmp_path)
    assert cdpm("diagram", scenario, "--out", tmp_path / "d1", "--no-svg", "--depth", 1) == 0
    assert cdpm("diagram", scenario, "--out", tmp_path / "d2", "--depth", 2) == 0
    assert cdpm("diagram", scenario, "--out", tmp_path / "full", "--no-svg") == 0
    assert (tmp_path / "full" / "controller_simulated.dot").read_text() == (
        tmp_path / "d2" / "controller_simulated.dot").read_text()
    shallow = (tmp_path / "d1" / "controller_simulated.dot").read_text()
    deep = (tmp_path / "d2" / "controller_simulated.dot").read_text()
    assert "simulated_reels" not in shallow and "simulated_reels" in deep
    assert list((tmp_path / "d1").glob("*.dot")) and not list((tmp_path / "d1").glob("*.svg"))
    assert {p.stem for p in (tmp_path / "d2").glob("*.svg")} == {
        p.stem for p in (tmp_path / "d2").glob("*.dot")}


# --- sweep ---------------------------------------------------------------------------------


def _sweep_file(tmp_path, name="wire_sweep"):
    """Two runs of a 0.02 s scenario, admittance.damping 3.0 and 4.5 N s/m."""
    base = _scenario_file(tmp_path, name="sweep_base", duration=0.02)
    path = tmp_path / f"{name}.yaml"
    path.write_text(f"name: {name}\nbase: {base}\n"
                    "axes:\n  - {field: admittance.damping, values: [3.0, 4.5]}\n")
    return path


def _results(out):
    import csv

    with open(out / "results.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@covers("sweep <sweep>", "sweep --out", "sweep --keep-logs", "sweep --plot", "sweep --metric",
        "sweep --top", "sweep --no-progress")
def test_sweep_writes_rows_logs_and_pictures_where_asked(tmp_path, monkeypatch, capsys):
    """The sweep given runs its two variants into exactly --out (nothing under runs/), keeps
    each run's log, draws the metric asked for, lists --top 1 best run, without a bar; the
    same sweep run without --no-progress shows the bar."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "exact"
    args = ("sweep", _sweep_file(tmp_path), "--out", out, "--workers", 1, "--keep-logs",
            "--plot", "--metric", "peak_speed", "--top", 1)
    assert cdpm(*args, "--no-progress") == 0
    printed = capsys.readouterr()
    rows = _results(out)
    assert [float(r["admittance.damping"]) for r in rows] == [3.0, 4.5]
    assert all(r["status"] == "ok" for r in rows)
    assert not (tmp_path / "runs").exists()
    for r in rows:
        log = run_log(out / "runs" / r["run"])
        assert len(log["time"]) == 11  # 0.02 s at 2 ms
    assert (out / "peak_speed_vs_admittance_damping.png").stat().st_size > 1000
    assert not list(out.glob("min_distance_vs_*.png"))
    best = [ln for ln in printed.out.splitlines() if ln.startswith(tuple(r["run"] for r in rows))]
    assert len(best) == 1
    assert "%|" not in printed.err
    # The contrast: the same sweep into another folder, without --no-progress, shows a bar.
    assert cdpm("sweep", _sweep_file(tmp_path), "--out", tmp_path / "other",
                "--workers", 1) == 0
    assert "%|" in capsys.readouterr().err


@covers("sweep --dry-run")
def test_sweep_dry_run_runs_nothing(tmp_path):
    out = tmp_path / "o"
    assert cdpm("sweep", _sweep_file(tmp_path), "--out", out, "--dry-run") == 0
    assert not (out / "results.csv").exists() and not (out / "runs").exists()


@covers("sweep --workers", "sweep --ray", "sweep --ray-chunk", "sweep --retry-errors")
def test_sweep_runner_options_reach_the_sweep(tmp_path, monkeypatch):
    """Where the runs go (local workers, a Ray address, runs per Ray task) and whether error
    rows rerun: handed to cdpm_drake.runs.sweep.sweep_main as given (Ray itself and error rows are
    exercised in test_sweep.py and test_sweep_ray.py)."""
    from cdpm_drake.runs import sweep

    seen = []
    monkeypatch.setattr(sweep, "sweep_main", lambda **kw: seen.append(kw) or 0)
    path = _sweep_file(tmp_path)
    assert cdpm("sweep", path, "--workers", 3, "--retry-errors") == 0
    assert cdpm("sweep", path, "--ray", "ray://head:10001", "--ray-chunk", 4) == 0
    assert cdpm("sweep", path, "--ray") == 0
    local, cluster, here = seen
    assert (local["workers"], local["retry_errors"], local["ray"]) == (3, True, False)
    assert (cluster["ray"], cluster["ray_address"], cluster["ray_chunk"]) == (
        True, "ray://head:10001", 4)
    assert not cluster["retry_errors"]
    assert here["ray"] and not here["ray_address"]


# --- recover, --version ------------------------------------------------------------------------


@covers("recover <run_dir>")
def test_recover_rebuilds_the_log_from_the_tick_stream(tmp_path, bridge):
    """A run whose log.npz is lost (killed before writing it): `cdpm recover DIR` writes it
    again from DIR/ticks.bin, row for row."""
    out = tmp_path / "o"
    assert cdpm("run", _scenario_file(tmp_path, duration=0.06), "--scenario-text",
                bridge.overlay, "--out", out) == 0
    before = run_log(out)
    (out / "log.npz").unlink()
    assert cdpm("recover", out) == 0
    after = run_log(out)
    assert len(after["time"]) == len(before["time"]) == 31
    np.testing.assert_array_equal(after["p"], before["p"])


@covers("cdpm --version")
def test_version_is_the_package_version(capsys):
    import cdpm_drake

    with pytest.raises(SystemExit) as done:
        cdpm("--version")
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"cdpm {cdpm_drake.__version__}"


# --- info ----------------------------------------------------------------------------------------


@covers("info --swaps", "info --grid", "info --plot")
def test_info_statics_options_reach_the_output(capsys, tmp_path):
    """--swaps 1-3 swaps rows 1 and 3 of the attachment column, --grid 0.5 is the grid the
    statics line names (0.5 m steps over paper_7cable's 2.5 x 3.2 x 2.1 m box: 6 x 7 x 5
    points), --plot writes the two pictures there (tests/cli/test_info_statics.py checks their
    numbers)."""
    assert cdpm("info", "paper_7cable", "--swaps", "1-3", "--grid", "0.5", "--plot",
                tmp_path) == 0
    out = capsys.readouterr().out
    b = load_robot("paper_7cable").attachments
    row1 = next(line for line in out.splitlines() if line.startswith("1 "))
    assert f"[{b[2, 0]:.3f}, {b[2, 1]:.3f}, {b[2, 2]:.3f}]" in row1  # cable 1 ends at b_3
    assert "(50 cm grid from the lower corner: 6 x 7 x 5 points)" in out
    for name in ("workspace_wrench.png", "workspace_interference.png"):
        assert (tmp_path / name).stat().st_size > 20_000


@covers("info <robot>")
def test_info_describes_the_robot_given(capsys, write_robot, valid_spec):
    """`info` only prints: its effect is the table, checked against lengths computed here
    (|c + b_i - a_i| at the box centre [2, 1.5, 1.5])."""
    path = write_robot(valid_spec)
    assert cdpm("info", path) == 0
    out = capsys.readouterr().out
    assert "'tetra_4cable'" in out and "4 cables" in out
    c = np.array([2.0, 1.5, 1.5])
    for a, b in zip(valid_spec["reels"], valid_spec["attachments"]):
        assert f"{np.linalg.norm(c + b - np.array(a)):.4f}" in out


# --- calibrate -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def calibration_log(tmp_path_factory):
    """The calibration motion on a robot whose exits are off by ~1 cm: a run folder to
    calibrate from (tests/runs/test_calibration_run.py checks the fit's numbers; here, that
    each option reaches it)."""
    folder = tmp_path_factory.mktemp("calibrate") / "run"
    assert cdpm("simulate", "calibration_motion", "--no-progress",
                "--out", folder, "--scenario-text",
                "{plant: !SimulatedReels {max_length_residual: 0.04, model_error: "
                "{reels_std: 0.01, encoder_offset_std: 0.003}}}") == 0
    return folder


@pytest.fixture
def spy_settings(monkeypatch):
    """The CalibrationSettings each calibrate call received (the real fit still runs)."""
    import cdpm_drake.runs.calibrate as C

    seen = []
    real = C.calibrate_runs

    def spy(paths, robot_ref, settings, measured_poses=None):
        seen.append((paths, robot_ref, settings))
        return real(paths, robot_ref, settings, measured_poses)

    monkeypatch.setattr(C, "calibrate_runs", spy)
    return seen


@covers("calibrate <runs>", "calibrate --robot")
def test_calibrate_reads_the_runs_against_the_robot_given(calibration_log, tmp_path, capsys):
    """The run's exits are paper_7cable's: against cube_8cable it is another robot."""
    assert cdpm("calibrate", calibration_log, "--robot", "cube_8cable", "--out",
                tmp_path / "c.yaml") == 1
    assert "another robot" in capsys.readouterr().err
    assert cdpm("calibrate", calibration_log, "--robot", "paper_7cable", "--dry-run") == 0
    out = capsys.readouterr().out
    assert "robot 'paper_7cable'" in out and "from 1 run(s)" in out


@covers("calibrate --out", "calibrate --force", "calibrate --dry-run")
def test_calibrate_writes_where_asked_and_only_then(calibration_log, tmp_path, capsys):
    out = tmp_path / "cal.yaml"
    assert cdpm("calibrate", calibration_log, "--robot", "paper_7cable", "--out", out,
                "--dry-run") == 0
    assert not out.exists() and "would write" in capsys.readouterr().out
    assert cdpm("calibrate", calibration_log, "--robot", "paper_7cable", "--out", out) == 0
    assert load_robot(out).uncertainty is not None
    out.write_text("# changed by hand\n" + out.read_text())
    assert cdpm("calibrate", calibration_log, "--robot", "paper_7cable", "--out", out) == 2
    assert out.read_text().startswith("# changed by hand")
    assert cdpm("calibrate", calibration_log, "--robot", "paper_7cable", "--out", out,
                "--force") == 0
    assert not out.read_text().startswith("# changed by hand")


@covers("calibrate --encoder-std", "calibrate --reels-prior", "calibrate --attachments-prior",
        "calibrate --offsets-prior", "calibrate --max-poses", "calibrate --min-spacing",
        "calibrate --max-speed", "calibrate --attachments")
def test_calibrate_settings_reach_the_fit(calibration_log, spy_settings, capsys):
    # (40 poses of 0.2 mm readings may identify too little to write: exit 1 then.)
    assert cdpm("calibrate", calibration_log, "--robot", "paper_7cable", "--dry-run",
                "--encoder-std", "2e-4", "--reels-prior", "0.03", "--attachments-prior",
                "0.01", "--offsets-prior", "0.02", "--max-poses", "40", "--min-spacing",
                "0.05", "--max-speed", "0.2", "--attachments") in (0, 1)
    (_, ref, s), = spy_settings
    assert ref == "paper_7cable"
    assert (s.encoder_std, s.prior.reels_std, s.prior.attachments_std, s.prior.offsets_std,
            s.max_poses, s.min_spacing, s.max_speed, s.fit_attachments) == (
        2e-4, 0.03, 0.01, 0.02, 40, 0.05, 0.2, True)
    out = capsys.readouterr().out
    # At most 40 poses; the attachments are fitted only with the full pose (this log is the
    # translating controller's), so the report lists none.
    poses = int(out.split(" poses from")[0].split()[-1])
    assert poses <= 40 and "attachment 1:" not in out and "encoder noise 0.2 mm" in out


@covers("calibrate --measured-poses")
def test_calibrate_reads_the_measured_poses_given(calibration_log, tmp_path, capsys):
    """One measured pose (its time in the log's hold at the start) cannot fix the frame's
    turn: the refusal says so, which only the file's poses reaching the fit can cause."""
    poses = tmp_path / "poses.yaml"
    poses.write_text("poses:\n  - {time: 0.5, position: [1.75, 2.4, 1.35], std: 0.0002}\n")
    assert cdpm("calibrate", calibration_log, "--robot", "paper_7cable", "--dry-run",
                "--measured-poses", poses) == 1
    assert "1 measured pose(s)" in capsys.readouterr().err


@covers("calibrate --write-motion", "calibrate --start")
def test_calibrate_writes_a_motion_from_the_start_given(tmp_path):
    out = tmp_path / "m.yaml"
    assert cdpm("calibrate", "--write-motion", out, "--robot", "cube_8cable", "--start",
                "1.0", "1.1", "1.2") == 0
    scenario = load_scenario(str(out))
    assert scenario.initial_position == [1.0, 1.1, 1.2]
    assert scenario.operator.waypoints[0] == [1.0, 1.1, 1.2]
    assert scenario_robot(scenario).name == "cube_8cable"
