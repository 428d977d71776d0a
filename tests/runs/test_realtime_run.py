"""`cdpm run` end to end on loopback: the same diagram, in real time, against the emulated bridge.

Each test runs a few seconds of real time against a ReelBridgeServer thread on 127.0.0.1 (an
ephemeral port). The watchdog is widened to 25 ticks here: this shared 2-core host oversleeps
by several ms at times, and these tests are about the run, not the watchdog (the watchdog's own
tests are in test_hardware_reels.py).
"""

import contextlib
import os
import signal
import threading

import numpy as np
import pytest
from conftest import default_signals

from cdpm_drake.cli import main
from cdpm_drake.emulator import FaultPlan, ReelBridge, ReelBridgeServer
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.runs.realtime import run
from cdpm_drake.config import ScenarioError, load_scenario, scenario_operator, scenario_robot
from cdpm_drake.runs.simulate import simulate

DURATION = 5.0


def _server(scenario, faults=None):
    """The bridge of the scenario's robot at its start, ideal drives (as SimulatedReels's
    default), the scenario's operator; `faults` (a FaultPlan) from its `after` s after the
    first enabling command (ReelBridgeServer.inject on a running server would count from
    the injection instead: before the controller has even built its diagram)."""
    robot = scenario_robot(scenario)
    bridge = ReelBridge(robot, cable_lengths(robot, np.array(scenario.initial_position)),
                        force=scenario_operator(scenario).force, time_constant=0.0)
    return ReelBridgeServer(bridge, address=("127.0.0.1", 0), record=100_000,
                            faults=faults or FaultPlan()).start()


@contextlib.contextmanager
def _after_first_enable(server, seconds, action):
    """Within the block, action() is called `seconds` s of wall time after the bridge's first
    enabling command (not after run() is called: building the diagram took 0.4-0.8 s on this
    host), unless the block has ended first."""
    done = threading.Event()

    def wait():
        while server.first_enable_time is None and not done.wait(0.005):
            pass
        if not done.wait(seconds):
            action()

    thread = threading.Thread(target=wait, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def _hardware(scenario_name, server, extra=""):
    port = server.address[1]
    return load_scenario(scenario_name, overlay_text=(
        f"{{plant: !HardwareReels {{port: {port}, watchdog_ticks: 25, ramp_time: 0.0}}"
        f"{extra}}}"))



def _run_against(server, out, duration, *, watchdog_ticks=None):
    """`cdpm run exp1_no_interaction` for `duration` s into `out` against `server` (stopped
    afterwards, whatever happens); returns the exit code."""
    extra = "" if watchdog_ticks is None else f", watchdog_ticks: {watchdog_ticks}"
    try:
        return main(["run", "exp1_no_interaction", "--duration", str(duration), "--out",
                     str(out), "--scenario-text",
                     f"plant: !HardwareReels {{port: {server.address[1]}{extra}}}"])
    finally:
        server.stop()

ATTEMPTS = 3


def _host_stalled(text: str) -> bool:
    """Whether a run's error or report says a host stall ended it: the bridge stopped the reels
    after 50 ms without a command (COMMAND_TIMEOUT), or the controller heard nothing for its
    watchdog's limit. Both are the right response to a stall, not what these tests are about:
    such a run is repeated, up to ATTEMPTS in all."""
    return "COMMAND_TIMEOUT" in text or "no valid status" in text


def _cli_run_unstalled(tmp_path, duration, capsys):
    """`_run_against` a fresh bridge into tmp_path/run<attempt> (watchdog 25 ticks), repeated
    while a host stall ends the run; returns (server, run folder, exit code, stdout)."""
    scenario = load_scenario("exp1_no_interaction")
    for attempt in range(ATTEMPTS):
        server = _server(scenario)
        run_dir = tmp_path / f"run{attempt}"
        code = _run_against(server, run_dir, duration, watchdog_ticks=25)
        out = capsys.readouterr().out
        if code == 0 or not _host_stalled(out):
            break
    return server, run_dir, code, out


def test_a_run_against_the_emulator_matches_the_simulation(tmp_path):
    """Experiment 1 (the interference force alone moves the platform) for 5 s, on the emulated
    bridge and in pure simulation: positions agree within 1 mm at every tick. What differs is
    the bridge's 1-2 tick command latency and its per-reel integration (no projection onto the
    geometry): about 0.1 mm here. A host stall of tens of ms (this 2-core machine is shared)
    makes the bridge hold a command longer and can add a transient millimetre, so a run whose
    tick timing shows such a stall (or that a stall ended through the watchdog) is repeated,
    up to three times in all."""
    sim_scenario = load_scenario("exp1_no_interaction")
    sim = simulate(scenario=sim_scenario, duration=DURATION).log
    for attempt in range(3):
        server = _server(sim_scenario)
        try:
            result = run(scenario=_hardware("exp1_no_interaction", server),
                         out_dir=tmp_path / f"run{attempt}", duration=DURATION)
        finally:
            server.stop()
        if result.ending == "fault" and ("no valid status" in str(result.error)
                                         or "COMMAND_TIMEOUT" in str(result.error)):
            # The host starved the bridge thread past even 25 ticks, or this process past the
            # bridge's own 50 ms command timeout: run again.
            continue
        assert result.ending == "completed", result.error
        hw = result.log
        n = min(len(hw["time"]), len(sim["time"]))
        err = np.linalg.norm(hw["p"][:n] - sim["p"][:n], axis=1)
        # A stall on either side: a tick of this process, or a gap the bridge saw between
        # two commands (its thread or the socket held up), of 10 ms or more.
        received = np.array([c.time for c in server.commands if c.enable])
        gap = np.diff(received).max() if received.size > 1 else 0.0
        if err.max() < 1e-3 or (result.timing["max"] < 0.010 and gap < 0.010):
            break  # matched, or failed without a stall to blame
    assert result.ending == "completed", result.error
    # Ticks 0..2500 of 5 s at 500 Hz, as `cdpm simulate` logs them (issue 10, point 9: 2500
    # before the run loop counted its steps in whole ticks).
    assert len(hw["time"]) == len(sim["time"]) == round(DURATION / 0.002) + 1
    assert n >= DURATION / 0.002
    np.testing.assert_allclose(hw["time"][:n], sim["time"][:n], atol=1e-12)
    moved = np.linalg.norm(sim["p"][n - 1] - sim["p"][0])
    assert moved > 0.01  # the comparison means something: the platform moved > 1 cm
    # Three attempts all stalled (a busy host): a command held s seconds longer moves the
    # platform at most s times its speed further than the simulation, which the bound then
    # allows beyond the 1 mm (measured: a 20 ms gap on a loaded host took 1.07 mm). Without a
    # stall the bound is 1 mm.
    stall = max(gap, result.timing["max"])
    allowance = 0.0
    if stall >= 0.010:
        allowance = stall * float(np.linalg.norm(np.diff(sim["p"], axis=0), axis=1).max()
                                  / 0.002)
    assert err.max() < 1e-3 + allowance, (err.max(), gap, result.timing)
    # One row per tick, no gaps, in the stream and in log.npz.
    assert np.all(np.diff(hw["tick"]) == 1) and hw["tick"][0] == 0
    assert result.timing["missing_ticks"] == 0
    on_disk = np.load(result.log_path)
    np.testing.assert_array_equal(on_disk["p"], hw["p"])
    assert on_disk["pair_distances"].shape == (len(hw["time"]), 21)


def test_sigint_stops_the_run_with_zero_velocity_first(tmp_path):
    scenario = load_scenario("exp2_interaction")
    for attempt in range(ATTEMPTS):
        server = _server(scenario)
        # The run's handler is installed only for a signal that is not ignored: a pytest
        # started with SIGINT ignored (in the background, no job control) must not skip this.
        previous = signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            # The signal comes 1 s after the bridge's first enabling command.
            with _after_first_enable(server, 1.0, lambda: os.kill(os.getpid(), signal.SIGINT)):
                result = run(scenario=_hardware("exp2_interaction", server),
                             out_dir=tmp_path / f"run{attempt}", duration=20.0)
        finally:
            server.stop()
            signal.signal(signal.SIGINT, previous)
        if not (result.ending == "fault" and _host_stalled(str(result.error))):
            break
    assert result.ending == "interrupted", result.error
    # Stopped within a few steps of the signal, and the log is there up to the stop.
    assert 0.5 < result.log["time"][-1] < 2.0
    last = list(server.commands)[-1]
    assert not last.enable and np.all(last.velocity == 0.0)
    # The operator was pushing: the platform moved before the stop, with enabled commands.
    assert any(c.enable and np.any(c.velocity != 0.0) for c in server.commands)
    # hardware/PROTOCOL.md: the shutdown is shutdown_repeats (3) zero, enable-clear commands.
    assert _shutdown_burst(server) == 3


def test_a_bridge_that_goes_silent_ends_the_run_with_a_fault_and_keeps_the_log(tmp_path):
    scenario = load_scenario("exp1_no_interaction")
    server = _server(scenario)
    try:
        with _after_first_enable(server, 1.0, server.stop):  # the bridge goes silent
            result = run(scenario=_hardware("exp1_no_interaction", server), out_dir=tmp_path,
                         duration=10.0)
    finally:
        server.stop()
    assert result.ending == "fault"
    assert "no valid status" in str(result.error) and "zero reel velocity sent" in str(
        result.error)
    log = np.load(result.log_path)
    # The bridge stops 1 s (wall) after the first enabling command (counting from the timer's
    # start instead, a clean-clone run ended at 0.43 s: building the diagram took 0.57 s), and
    # the watchdog ends the run soon after.
    assert 0.9 < log["time"][-1] < 2.0
    assert np.all(np.diff(log["tick"]) == 1)
    # The fault is in the log: how the run ended, when (the last logged tick) and why.
    assert str(log["ending"]) == "fault"
    assert float(log["fault_time"]) == log["time"][-1]
    assert "no valid status" in str(log["fault_message"])


def _shutdown_burst(server) -> int:
    """The zero-velocity, enable-clear commands the bridge read after the last enabling one."""
    commands = list(server.commands)
    last_enabled = max(k for k, c in enumerate(commands) if c.enable)
    tail = commands[last_enabled + 1:]
    assert all(not c.enable and np.all(c.velocity == 0.0) for c in tail)
    return len(tail)


def test_a_completed_run_logs_compute_time_and_ends_with_one_shutdown_burst(tmp_path, capsys):
    server, run_dir, code, out = _cli_run_unstalled(tmp_path, 0.5, capsys)
    assert code == 0, out
    assert _shutdown_burst(server) == 3
    log = np.load(run_dir / "log.npz")
    assert len(log["time"]) == 251 and str(log["ending"]) == "completed"
    assert np.isnan(log["fault_time"]) and str(log["fault_message"]) == ""
    assert float(log["watchdog_limit"]) == pytest.approx(25 * 0.002)  # ticks x time_step
    compute = log["compute"]
    # Tick 0 is published by initialisation, with no update before it.
    assert np.isnan(compute[0]) and np.all(np.isfinite(compute[1:]))
    # The work of tick k starts after row k-1 was appended and ends at row k's append: it is
    # positive and shorter than the time between the two rows.
    assert np.all(compute[1:] > 0) and np.all(compute[1:] < np.diff(log["wall"]))
    c = 1e3 * np.percentile(compute[1:], [50, 99, 100])
    assert (f"compute per tick p50 {c[0]:.3f} ms, p99 {c[1]:.3f} ms, max {c[2]:.3f} ms of the "
            "2 ms tick") in out


def _free_port() -> int:
    import socket

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    return port


def test_a_run_without_a_bridge_writes_nothing_but_its_report(tmp_path, capsys, monkeypatch):
    # Issue 10, point 5: no log that `cdpm plot` would reject, no stream line for a file that
    # does not exist, no folder in the way of the next run.
    monkeypatch.chdir(tmp_path)
    code = main(["run", "exp1_no_interaction", "--duration", "1", "--scenario-text",
                 f"plant: !HardwareReels {{port: {_free_port()}, startup_timeout: 0.2}}"])
    captured = capsys.readouterr()
    assert code == 1
    assert "run ended: fault" in captured.out and "no valid status" in captured.err
    assert "no log written: the reels were never enabled" in captured.out
    assert "stream:" not in captured.out
    assert not (tmp_path / "runs").exists(), list((tmp_path / "runs").rglob("*"))


def test_refusing_to_enable_hints_at_an_emulator_playing_something_else(tmp_path, capsys):
    # Cable 3 reads 5 cm long (as from an emulator playing another robot): they do not fit.
    scenario = load_scenario("exp1_no_interaction")
    robot = scenario_robot(scenario)
    lengths = cable_lengths(robot, np.array(scenario.initial_position))
    lengths[2] += 0.05
    server = ReelBridgeServer(ReelBridge(robot, lengths, time_constant=0.0)).start()
    code = _run_against(server, tmp_path / "run", 1)
    err = capsys.readouterr().err
    assert code == 1
    assert "do not fit robot" in err
    assert "cdpm emulate --scenario exp1_no_interaction" in err
    assert not (tmp_path / "run").exists()


def test_cdpm_run_never_enables_with_the_platform_outside_the_box(tmp_path, capsys):
    # Issue 27, bug 1: against a bridge whose encoders put the platform at [10, 10, 10] m
    # (`cdpm emulate --start 10 10 10`), `cdpm run` ran to the end, exit 0. Refused now, before
    # any enabling command, naming the pose and the box (exp1's robot: paper_7cable_swap13).
    robot = scenario_robot(load_scenario("exp1_no_interaction"))
    server = ReelBridgeServer(ReelBridge(robot, cable_lengths(robot, np.array([10.0, 10, 10])),
                                         time_constant=0.0)).start()
    code = _run_against(server, tmp_path / "run", 1)
    err = capsys.readouterr().err
    assert code == 1
    assert ("cdpm run: error: refusing to enable the reels: the platform centre p = [10.000, "
            "10.000, 10.000] m (from the measured cable lengths) is outside the workspace box "
            "of robot 'paper_7cable_swap13'") in err, err
    assert "lower [0.500, 0.800, 0.300] m, upper [3.000, 4.000, 2.400] m" in err
    assert "cdpm emulate --scenario exp1_no_interaction" in err  # the emulator's hint
    assert not any(c.enable for c in server.commands)
    assert not (tmp_path / "run").exists()


def test_a_bridge_fault_at_startup_hints_at_a_reset(tmp_path, capsys):
    from cdpm_drake.hardware.protocol import FAULT_COMMAND_TIMEOUT

    server = _server(load_scenario("exp1_no_interaction"))
    server.bridge.raise_fault(FAULT_COMMAND_TIMEOUT)  # left by a controller killed earlier
    code = _run_against(server, tmp_path / "run", 1)
    err = capsys.readouterr().err
    assert code == 1
    assert "reports fault bits 0x0010 (COMMAND_TIMEOUT) at startup" in err
    assert "fault bits stay set until the bridge is reset" in err
    assert not (tmp_path / "run").exists()


def test_a_fault_log_is_plotted_and_a_killed_run_is_recovered(tmp_path, capsys):
    scenario = load_scenario("exp1_no_interaction")
    # The bridge goes silent 0.4 s after the first enabling command (injected into the running
    # server it went silent 0.4 s after its start, on CI before a slow build had enabled). On
    # a loaded host the controller can stall before it ever enables (its watchdog or the
    # bridge's command timeout ends the run then, as they should): such a run is repeated.
    for attempt in range(ATTEMPTS):
        server = _server(scenario, FaultPlan(stop=True, after=0.4))
        run_dir = tmp_path / f"run{attempt}"
        code = _run_against(server, run_dir, 5, watchdog_ticks=25)
        captured = capsys.readouterr()
        # A run that never enabled the reels is not what this test is about, whatever ended
        # it (a CI run once ended so, with output this test did not keep): repeated.
        if any(c.enable for c in server.commands):
            break
    assert any(c.enable for c in server.commands), (
        f"no enabling command in {ATTEMPTS} runs; the last printed:\n{captured.out}\n"
        f"{captured.err}")
    assert code == 1
    # The bridge went silent but still reads: one burst of 3 zero commands, although the
    # watchdog's update, the next publish and the run's clean-up each stop the reels (12
    # before).
    assert _shutdown_burst(server) == 3
    full = dict(np.load(run_dir / "log.npz"))
    # The bridge stops 0.4 s (wall) after the first enable (on a loaded host the controller
    # may lag that, or trip on a stall even earlier): a fault, some ticks before it.
    assert str(full["ending"]) == "fault" and 10 < len(full["time"]) < 751, \
        str(full["fault_message"])
    # A fault log is a complete log: `cdpm plot` takes it.
    assert main(["plot", str(run_dir)]) == 0
    assert (run_dir / "distances.png").is_file()
    # As after SIGKILL: no log.npz, and the stream's last row half written.
    (run_dir / "log.npz").unlink()
    data = (run_dir / "ticks.bin").read_bytes()
    (run_dir / "ticks.bin").write_bytes(data[:-10])
    assert main(["plot", str(run_dir)]) == 0
    err = capsys.readouterr().err
    assert "has ticks.bin but no log.npz" in err and "recovering first" in err
    T = len(full["time"])
    assert f"recovered {T - 1} ticks of 2501 (interrupted); the tail was cut" in err
    back = np.load(run_dir / "log.npz")
    np.testing.assert_array_equal(back["p"], full["p"][:T - 1])
    np.testing.assert_array_equal(back["tick"], full["tick"][:T - 1])
    assert str(back["ending"]) == "interrupted"
    # `cdpm recover` itself, on the whole stream; never over a log.npz that is there.
    (run_dir / "ticks.bin").write_bytes(data)
    assert main(["recover", str(run_dir)]) == 1  # an error, not bad usage (issue 22)
    assert "already has its log.npz" in capsys.readouterr().err
    (run_dir / "log.npz").unlink()
    assert main(["recover", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert f"recovered {T} ticks of 2501 (interrupted); the tail was whole" in out
    np.testing.assert_array_equal(np.load(run_dir / "log.npz")["p"], full["p"])


def test_recover_names_what_is_missing(tmp_path, capsys):
    assert main(["recover", str(tmp_path)]) == 1  # cannot be found: 1 (issue 22)
    assert "has no ticks.bin" in capsys.readouterr().err


def test_cdpm_run_of_a_simulated_plant_exits_1_and_leaves_no_folder(tmp_path, capsys,
                                                                    monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "exp1_no_interaction", "--duration", "1"]) == 1
    assert "needs plant: !HardwareReels" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def test_run_refuses_a_simulated_plant(tmp_path):
    with pytest.raises(ScenarioError, match="!HardwareReels"):
        run(scenario=load_scenario("exp1_no_interaction"), out_dir=tmp_path, duration=1.0)


def test_cdpm_run_cli_reports_timing_and_packets(tmp_path, capsys):
    _, tmp_path, code, out = _cli_run_unstalled(tmp_path, 1, capsys)  # the run that counts
    assert code == 0, out
    assert "run ended: completed" in out
    assert "tick period p50" in out and "packets: commands sent" in out
    assert (tmp_path / "log.npz").exists() and (tmp_path / "ticks.bin").exists()
    # Issue 27: the report names the variant first and ends with simulate's pair table: exp1's
    # pair (1,3) within d_u from the start (56 mm at the start, d_u 61 mm), its closest approach
    # from the log, d_l and d_u of the scenario's interference defaults.
    assert out.startswith("scenario 'exp1_no_interaction' (the hard promise: safety filter "
                          "on, hardware reels, translation only at 127.0.0.1:"), out
    with np.load(tmp_path / "log.npz") as log:
        k13 = [tuple(p) for p in log["pairs"]].index((1, 3))
        closest = 1000 * log["pair_distances"][:, k13].min()
        within = int(log["active"][:, k13].sum())
        d_l, d_u = 1000 * log["d_l"][k13], 1000 * log["d_u"][k13]
    assert "pair   min distance (mm)  d_l (mm)  d_u (mm)  ticks within d_u  crossed" in out, out
    row = next(line for line in out.splitlines() if line.startswith("(1,3)")).split()
    assert row == ["(1,3)", f"{closest:.2f}", f"{d_l:.2f}", f"{d_u:.2f}", str(within), "0"], row
    assert within > 0 and "pairs that crossed: 0" in out
    # A second run into the same directory would overwrite the robot's log: refused.
    code = main(["run", "exp1_no_interaction", "--duration", "1", "--out", str(tmp_path),
                 "--scenario-text", "plant: !HardwareReels {port: 9}"])
    assert code == 2
    assert f"--out {str(tmp_path)!r} is not empty" in capsys.readouterr().err
    assert np.load(tmp_path / "log.npz")["time"].size == 501  # untouched: 1 s at 500 Hz


def test_a_failing_log_writer_still_leaves_a_log_and_a_report(tmp_path, monkeypatch):
    # The disk fills up mid-run: the writer's error ends the run as a fault (zero velocity was
    # sent first), and what was written is still converted to log.npz with the link report.
    from cdpm_drake.hardware import tick_log

    real_write = tick_log.os.write
    calls = {"n": 0}

    def write_then_fail(fd, data):
        calls["n"] += 1
        if calls["n"] > 20:
            raise OSError(28, "No space left on device")
        return real_write(fd, data)

    scenario = load_scenario("exp1_no_interaction")
    server = _server(scenario)
    monkeypatch.setattr(tick_log.os, "write", write_then_fail)
    try:
        result = run(scenario=_hardware("exp1_no_interaction", server), out_dir=tmp_path,
                     duration=2.0)
    finally:
        monkeypatch.setattr(tick_log.os, "write", real_write)
        server.stop()
    assert result.ending == "fault"
    assert "No space left" in str(result.error)
    assert result.link.get("sent", 0) > 0
    log = np.load(tmp_path / "log.npz")
    assert len(log["time"]) > 0 and np.all(np.diff(log["tick"]) == 1)
    last = list(server.commands)[-1]
    assert not last.enable and np.all(last.velocity == 0.0)


def test_a_second_run_against_the_same_bridge_is_a_new_session(tmp_path):
    # The next `cdpm run` counts its commands from 1 again: the bridge, at rest after the first
    # run's enable-clear shutdown, must take that as a new session, not drop it as old.
    scenario = load_scenario("exp1_no_interaction")
    for attempt in range(ATTEMPTS):
        server = _server(scenario)
        try:
            for k in range(2):
                result = run(scenario=_hardware("exp1_no_interaction", server),
                             out_dir=tmp_path / f"attempt{attempt}" / f"run{k}", duration=0.5)
                if result.ending != "completed":
                    break
        finally:
            server.stop()
        if not (result.ending == "fault" and _host_stalled(str(result.error))):
            break
    assert result.ending == "completed", (k, result.error)
    assert server.counters["sessions"] == 1
    assert server.counters["rejected"]["sequence"] == 0


def _run_against_dynamic_emulator(out_dir):
    """`cdpm emulate --plant dynamic` (a process of its own) for exp2, and `cdpm run
    exp2_interaction` against it for 2 s; the emulator is stopped with Ctrl-C afterwards.
    Returns (run's exit code, the emulator's exit code and stdout, stderr). Both watchdogs are
    widened to 1 s: this shared host stalls a process for a quarter of a second at times, and
    this test is about the physics behind the bridge, not the watchdogs."""
    import re
    import select
    import subprocess
    import sys

    emulator = subprocess.Popen(
        [sys.executable, "-m", "cdpm_drake.emulator", "--scenario", "exp2_interaction",
         "--plant", "dynamic", "--port", "0", "--duration", "300", "--command-timeout", "1.0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    code, line = None, ""
    try:
        ready, _, _ = select.select([emulator.stdout], [], [], 180.0)
        assert ready, "the emulator did not start within 180 s"
        line = emulator.stdout.readline()
        port = int(re.search(r"on 127\.0\.0\.1:(\d+), period 2 ms", line).group(1))
        code = main(["run", "exp2_interaction", "--duration", "2", "--out", str(out_dir),
                     "--scenario-text", f"plant: !HardwareReels {{port: {port}, "
                     "watchdog_ticks: 500, ramp_time: 0.0}"])
    finally:
        emulator.send_signal(signal.SIGINT)
        out, err = emulator.communicate(timeout=120)
    return code, emulator.returncode, line + out, err  # its whole stdout, the first line too


def test_cdpm_run_against_the_emulated_dynamic_plant(tmp_path):
    """Issue 21: `cdpm emulate --plant dynamic` plays experiment 2's dynamic plant (mass,
    elastic cables, drive friction, the operator) behind the bridge; `cdpm run
    exp2_interaction` runs against it for 2 s. The encoders are zeroed at the start pose, so
    the controller's start-up check passes; the platform tilts and cables stretch, which the
    forward kinematics' default bound (derived from the robot's cables) allows for: nothing
    is set by hand.

    Reference: the same 2 s simulated (`!DynamicReels`, the same controller): the operator
    drags the platform ~0.2 m, the tensions stay within 4.9..25.0 N (0.9..29.3 N before the
    attachment points of issue 18). On the emulator the plant follows the bridge's clock (the
    operator starts with the first enabling command, a host stall holds a command longer), so
    the comparison is loose: the estimated position
    within 15 mm of the simulated true one (4.5 mm measured on a loaded host), the tensions'
    largest value within 10 N of the simulated one. A run whose ticks show a host stall of
    more than 20 ms (the emulator's plant then runs on with an old command) and misses, or
    whose emulator fell behind its own clock (fewer than 900 of the 1000 driven ticks: a host
    too busy to run the plant at 500 Hz), is repeated, up to three times in all. Behind on all
    three, the estimate is held to the simulated path instead of the simulated time (the
    emulated hand ran slower) and the test skips the rest, saying why: the late commands
    stretch the cables beyond anything the simulation says."""
    import re

    sim = simulate(scenario=load_scenario("exp2_interaction", "plant: !DynamicReels {}"),
                   duration=2.0).log
    assert np.linalg.norm(sim["p_true"][-1] - sim["p_true"][0]) > 0.15
    session = re.compile(r"session 1: dynamic plant over (\d+) ticks")
    behind_every_time = True
    for attempt in range(3):
        run_dir = tmp_path / f"run{attempt}"
        code, emulator_code, out, err = _run_against_dynamic_emulator(run_dir)
        log = np.load(run_dir / "log.npz") if (run_dir / "log.npz").exists() else None
        stalled = log is not None and len(log["time"]) > 1 and np.diff(log["wall"]).max() > 0.02
        error = (np.linalg.norm(log["p"] - sim["p_true"][:len(log["p"])], axis=1).max()
                 if log is not None else np.inf)
        driven = session.search(out)
        behind = driven is not None and int(driven.group(1)) < 900
        behind_every_time &= behind
        if (code == 0 and error < 0.015 or not stalled) and not behind:
            break
    assert emulator_code == 130, err  # Ctrl-C: the summary was printed first
    assert code == 0, out
    assert str(log["ending"]) == "completed" and len(log["time"]) == 1001
    if behind_every_time:
        # The emulator fell behind its 500 Hz on all three attempts (447 of 1000 ticks seen
        # at a load of 8 on 2 cores): its plant and hand ran slower than the controller's
        # clock, so the platform is where the simulation was earlier (54 mm from it at the
        # same tick). The estimate must still follow the simulated path: each estimated
        # position within 15 mm of the simulated true path, whenever it was there.
        path = sim["p_true"]
        error = max(np.linalg.norm(path - p, axis=1).min() for p in log["p"])
    assert error < 0.015, (error, np.diff(log["wall"]).max(), behind_every_time)
    if behind_every_time:
        # Held longer, the late commands stretch the cables beyond the simulation's (70.7 N
        # against 24.9 N seen): the tensions say nothing about the emulator's physics then.
        pytest.skip("the emulator fell behind its 500 Hz on all three attempts (a host too "
                    "busy to run the dynamic plant in real time): the run completed and the "
                    "estimate followed the simulated path; the tension comparison needs a "
                    "host that keeps the emulator's clock")
    # The emulator's closing summary: its compute per tick, and what the cables went through.
    assert re.search(r"compute per tick p50 [\d.]+ / p99 [\d.]+ / max [\d.]+ ms", out), out
    # Issue 27: its first line says which plant it plays; the summary is the session's.
    assert ("period 2 ms, plant: dynamic (!DynamicReels: time step 1 ms, reel speed limit 1 "
            "m/s, start tilt [0.0, 0.0, 0.0] rad, rotation free), start [1.560, 3.240, 1.220] "
            "m") in out.splitlines()[0], out
    found = re.search(r"session 1: dynamic plant over (\d+) ticks: tensions ([\d.]+)\.\.([\d.]+) "
                      r"N, slack ticks per cable (.*), largest tilt ([\d.]+) deg", out)
    assert found, out
    ticks, t_min, t_max = int(found.group(1)), float(found.group(2)), float(found.group(3))
    # The summary's first part is what the controller drove; the emulator's world runs on
    # until it is stopped, the drives braking the moving platform and the hand pulling (on CI
    # 38.8 N in those ticks, 25.1 N simulated): those ticks are reported apart, unchecked.
    assert ticks >= 900 and 0.0 <= t_min < sim["tensions"].min() + 10.0
    assert abs(t_max - sim["tensions"].max()) < 10.0, (t_max, sim["tensions"].max())
    assert float(found.group(5)) < 5.0  # barely tilted (0.20 deg simulated)


# --- nothing that can take milliseconds inside a tick (realtime.py's module docstring) --------


def _patient(scenario_name):
    """A bridge thread and a controller that wait long for each other (1 s): these tests are
    about where work happens, not about timing, and share a loaded host (and, the bridge
    being a thread here, the controller's GIL). The controller runs the paper's open loop
    (length_gain 0): the bridge holds a command until the next one, up to 1 s here where the
    real bridge's command timeout is 50 ms, and a length loop whose correction K_l e is held
    for longer than 2 / K_l (50 ms) overshoots. Measured (controller stalls of 0.1-0.2 s every
    60 ms of run): the lengths rang up to a 5-8 mm inconsistency and the forward kinematics
    stopped the run in 1 of 3 runs (3 of 3 before the corrections were bounded); with 0.1 s
    stalls, 0 of 3."""
    scenario = load_scenario(scenario_name)
    robot = scenario_robot(scenario)
    bridge = ReelBridge(robot, cable_lengths(robot, np.array(scenario.initial_position)),
                        force=scenario_operator(scenario).force, time_constant=0.0)
    server = ReelBridgeServer(bridge, address=("127.0.0.1", 0), command_timeout=1.0).start()
    hardware = load_scenario(scenario_name, overlay_text=(
        f"{{plant: !HardwareReels {{port: {server.address[1]}, watchdog_ticks: 500, "
        f"ramp_time: 0.0}}, controller: {{length_gain: 0.0}}}}"))
    return server, hardware


class _Node:
    me = None


def test_the_garbage_collector_runs_between_steps_only_and_is_restored(tmp_path):
    """During the loop the automatic collector is off and the objects alive at the start are
    frozen; garbage made meanwhile (cycles, here from the status thread) is collected by the
    loop's own collect() between steps; afterwards the collector is on and nothing is frozen."""
    import gc
    import sys
    import weakref

    server, hardware = _patient("exp1_no_interaction")
    in_loop, first_cycle, starts = [], [], []

    def status(line):
        in_loop.append((gc.isenabled(), gc.get_freeze_count() > 0,
                        bool(first_cycle) and first_cycle[0]() is None))
        for _ in range(1000):  # cyclic garbage (> the 700 of a young collection)
            cycle = _Node()
            cycle.me = cycle
        if not first_cycle:
            first_cycle.append(weakref.ref(cycle))

    def on_gc(phase, info):
        if phase == "start" and not gc.isenabled():
            starts.append(sys._getframe(1).f_code.co_name)

    gc.callbacks.append(on_gc)
    try:
        result = run(scenario=hardware, out_dir=tmp_path, duration=1.0, status=status,
                     status_period=0.05)
    finally:
        gc.callbacks.remove(on_gc)
        server.stop()
    assert result.ending == "completed", result.error
    assert len(in_loop) > 3
    assert all(not enabled and frozen for enabled, frozen, _ in in_loop), in_loop
    # The first status call's garbage was collected while the run went on.
    assert any(dead for _, _, dead in in_loop)
    # Every collection while the collector was off: start_realtime's full one before the
    # reels are enabled, and the loop's between steps (at least one: the garbage above
    # asked for it); none inside a tick, none in another thread.
    assert set(starts) <= {"start_realtime", "collect"}, starts
    assert "collect" in starts
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_a_status_line_that_blocks_does_not_hold_up_the_run(tmp_path):
    # A terminal that stops reading: the first status line never returns. The run goes on
    # (the line is printed by a thread of its own; later lines are dropped, not queued).
    server, hardware = _patient("exp1_no_interaction")
    release = threading.Event()
    callers = []

    def status(line):
        callers.append(threading.current_thread().name)
        release.wait(10)  # longer than the bridge's 1 s command timeout

    try:
        result = run(scenario=hardware, out_dir=tmp_path, duration=1.0, status=status,
                     status_period=0.1)
    finally:
        release.set()
        server.stop()
    assert result.ending == "completed", result.error
    assert len(result.log["time"]) == 501  # every tick of 1 s at 500 Hz
    # Only from the status thread: the blocked first line, and at most the one line waiting
    # when it was released.
    assert set(callers) == {"status-line"} and len(callers) <= 2, callers


def test_the_tick_log_is_written_by_its_writer_thread_only(tmp_path, monkeypatch):
    # Every os.write of the tick log, its header included, comes from the writer thread: the
    # loop's thread never waits for the file system.
    from cdpm_drake.hardware import tick_log

    real_write = os.write
    writers = []

    def write(fd, data):
        writers.append(threading.current_thread().name)
        return real_write(fd, data)

    server, hardware = _patient("exp1_no_interaction")
    monkeypatch.setattr(tick_log.os, "write", write)
    try:
        result = run(scenario=hardware, out_dir=tmp_path, duration=0.5)
    finally:
        monkeypatch.setattr(tick_log.os, "write", real_write)
        server.stop()
    assert result.ending == "completed", result.error
    # The header and 251 rows in blocks of 50 (the last one partial): at least 7 writes.
    assert len(writers) >= 7 and set(writers) == {"tick-log-writer"}, writers


def test_the_report_counts_the_watchdog_stops_that_resumed():
    from cdpm_drake.runs.realtime import RunResult, report_lines

    def lines(holds):
        link = {"sent": 10, "received": 9, "accepted": 9, "lost": 0, "rejected": {},
                "foreign": 0, "commands_lost_at_bridge": 0, "watchdog_holds": holds,
                "longest_hold": 0.0093}
        return report_lines(RunResult(log={}, timing={}, link=link, error=None,
                                      ending="completed", log_path=None, tick_log_path=None))

    assert ("watchdog: stopped the reels 2 time(s) for a silent bridge that answered within "
            "resume_within, and resumed (longest stop 9.3 ms)") in lines(2)
    assert not any(line.startswith("watchdog") for line in lines(0))
