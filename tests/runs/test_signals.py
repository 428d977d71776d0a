"""Signals on real processes (issue 10, points 2 and 8): SIGTERM is treated like Ctrl-C by
every command (the log, scenario.yaml and the plots asked for are written), and the exit codes
are 130 after SIGINT and 143 after SIGTERM, as a shell reports them (128 + the signal number).
"""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import default_signals

BIN = Path(sys.executable).parent


def _wait_for(proc, stream, needle: bytes, timeout: float = 60.0) -> bytes:
    """Read `stream` of `proc` until `needle` appears (or fail after `timeout` s)."""
    seen = b""
    deadline = time.monotonic() + timeout
    fd = stream.fileno()
    os.set_blocking(fd, False)
    while needle not in seen:
        if time.monotonic() > deadline or proc.poll() is not None:
            proc.kill()
            raise AssertionError(f"never saw {needle!r}; got {seen!r} (rc {proc.poll()})")
        try:
            chunk = os.read(fd, 4096)
        except BlockingIOError:
            chunk = b""
        if chunk:
            seen += chunk
        else:
            time.sleep(0.05)
    return seen


# Simulated seconds of the run a signal stops: paced at real time, it cannot end by itself
# before the signal however fast the host is; the test waits for the signal's effect only.
LONG_RUN = 600


@pytest.mark.parametrize("sig, code, name", [(signal.SIGTERM, 143, "SIGTERM"),
                                             (signal.SIGINT, 130, "Ctrl-C")])
def test_a_signal_during_cdpm_simulate_keeps_the_log_and_the_plots(tmp_path, sig, code, name):
    out_dir = tmp_path / "run"
    # The progress bar (on stderr) appears once the simulator is initialised, so the run is
    # under way when the signal comes, and (paced at real time) far from its end.
    proc = subprocess.Popen([str(BIN / "cdpm"), "simulate", "exp1_no_interaction", "--duration",
                             str(LONG_RUN), "--realtime", "1", "--out", str(out_dir), "--plot"],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=default_signals)
    try:
        _wait_for(proc, proc.stderr, f"/{LONG_RUN:.1f} s".encode(), timeout=300)
        proc.send_signal(sig)
        # Generous: the log and the plots are written after the signal, on a loaded host too.
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    err = err.decode(errors="replace")
    assert proc.returncode == code, err
    assert "interrupted at t = " in err and name in err, err
    with np.load(out_dir / "log.npz") as log:
        t_end = float(log["time"][-1])
        assert 0.0 <= t_end < LONG_RUN
        assert str(log["ending"]) == "interrupted"
    assert f"duration: {t_end}" in (out_dir / "scenario.yaml").read_text()
    assert (out_dir / "distances.png").is_file() and (out_dir / "forces.png").is_file()


def test_a_command_started_with_sigint_ignored_keeps_ignoring_it():
    # The Unix convention (interrupt.honoured): the handlers of cdpm sweep and cdpm run are
    # installed only for signals that are not ignored; SIGTERM is still theirs.
    from cdpm_drake.runs.interrupt import honoured, terminate_raises
    from cdpm_drake.runs.realtime import StopRequest

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        assert not honoured(signal.SIGINT) and honoured(signal.SIGTERM)
        with StopRequest(), terminate_raises():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            assert signal.getsignal(signal.SIGTERM) not in (signal.SIG_IGN, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        with StopRequest():
            assert signal.getsignal(signal.SIGINT) is not signal.default_int_handler
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, previous)


def test_sigterm_stops_the_emulator_with_its_summary(tmp_path):
    proc = subprocess.Popen([str(BIN / "cdpm"), "emulate", "--robot", "paper_7cable", "--port",
                             "0"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    try:
        _wait_for(proc, proc.stdout, b"period 2 ms")
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    out = out.decode(errors="replace")
    assert proc.returncode == 143, err
    assert "commands received" in out and "statuses sent" in out, out


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_during_cdpm_run_exits_130_or_143(tmp_path, capsys, sig, code):
    # In this process: the run's own handler catches the signal between ticks, zero velocity
    # is sent, the log is written; the exit code says which signal stopped it.
    from cdpm_drake.cli import main
    from cdpm_drake.emulator import ReelBridge, ReelBridgeServer
    from cdpm_drake.kernels.kinematics import cable_lengths
    from cdpm_drake.config import load_scenario, scenario_robot

    scenario = load_scenario("exp1_no_interaction")
    robot = scenario_robot(scenario)
    server = ReelBridgeServer(ReelBridge(robot, cable_lengths(
        robot, np.array(scenario.initial_position)), time_constant=0.0)).start()
    enabled = threading.Event()

    def signal_once_enabled():
        # The signal comes once the bridge has seen an enabled command, i.e. while the run is
        # under way, however long loading and building take on this host.
        deadline = time.monotonic() + 300
        while not enabled.is_set() and time.monotonic() < deadline:
            try:
                if server.commands[-1].enable:
                    enabled.set()
                    os.kill(os.getpid(), sig)
                    return
            except IndexError:
                pass
            time.sleep(0.01)

    timer = threading.Thread(target=signal_once_enabled, daemon=True)
    # The run's handler is installed only for a signal that is not ignored: a pytest started
    # with SIGINT ignored (in the background, without job control) must not skip this case.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer.start()
    try:
        rc = main(["run", "exp1_no_interaction", "--duration", "120", "--out",
                   str(tmp_path / "run"), "--scenario-text",
                   f"plant: !HardwareReels {{port: {server.address[1]}, watchdog_ticks: 25}}"])
    finally:
        enabled.set()
        timer.join()
        # The stop command is the run's last datagram: give the bridge time to read it
        # (waiting for the effect, not for a fixed time).
        deadline = time.monotonic() + 60
        while server.commands and server.commands[-1].enable and time.monotonic() < deadline:
            time.sleep(0.01)
        server.stop()
        signal.signal(signal.SIGINT, previous)
    out = capsys.readouterr().out
    assert rc == code, out
    assert f"run ended: interrupted by {signal.Signals(sig).name}" in out
    with np.load(tmp_path / "run" / "log.npz") as log:
        assert str(log["ending"]) == "interrupted" and 0 <= log["time"][-1] < 120
    last = list(server.commands)[-1]
    assert not last.enable and np.all(last.velocity == 0.0)
