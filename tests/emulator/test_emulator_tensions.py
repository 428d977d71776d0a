"""The emulator's protocol version 2 (issue 31): which version it answers in, what its plants
report of their drives (kinematic: no reading; dynamic: the force that moves each reel
against its true tension), `--protocol-version 1`, `--load-cells`, `--truth-log`, and `cdpm
run` against `cdpm emulate --plant dynamic` logging tension_measured, the exact conversion of
what the emulator sent, which follows the plant's true tensions (compared in lockstep)."""

import re
import select
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import default_signals

from cdpm_drake import emulator as E
from cdpm_drake.emulator import ReelBridge, ReelBridgeServer
from cdpm_drake.emulator.main import write_truth_log
from cdpm_drake.hardware.protocol import Command, decode_status, encode_command
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.robot import load_robot
from cdpm_drake.config import load_scenario

M = 7
# Runs of the real-time comparison against the emulator, at most (a busy host stalls some).
ATTEMPTS = 3


@pytest.fixture(scope="module")
def robot():
    return load_robot("paper_7cable")


@pytest.fixture(scope="module")
def p0(robot):
    return robot.workspace.center + np.array([0.1, -0.2, 0.05])


class _Controller:
    """A raw UDP socket speaking the protocol, as the controller would, in either version."""

    def __init__(self, server):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.server = server
        self.seq = 0

    def send(self, velocity, enable=True, version=1, restart=False):
        self.seq = 1 if restart else self.seq + 1
        self.sock.sendto(encode_command(Command(self.seq, 0.0, np.asarray(velocity, float),
                                                enable, None, version=version)),
                         self.server.address)

    def latest(self):
        """The newest status waiting, decoded in whichever version it came."""
        time.sleep(0.01)
        self.sock.setblocking(False)
        data = None
        try:
            while True:
                data = self.sock.recvfrom(4096)[0]
        except BlockingIOError:
            pass
        return decode_status(data, M)

    def close(self):
        self.sock.close()


@pytest.fixture
def serve(robot, p0):
    started = []

    def start(**kw):
        server = ReelBridgeServer(ReelBridge(robot, cable_lengths(robot, p0), time_constant=0),
                                  **kw).start()
        client = _Controller(server)
        started.append((server, client))
        return server, client

    yield start
    for server, client in started:
        client.close()
        server.stop()


def _wait(condition, timeout=2.0):
    end = time.monotonic() + timeout
    while not condition() and time.monotonic() < end:
        time.sleep(0.005)
    return condition()


# --- versions --------------------------------------------------------------------------------


def test_the_bridge_answers_in_version_1_until_a_version_2_command(serve):
    messages = []
    server, ctl = serve(log=messages.append)
    u = np.array([0.01, -0.02, 0.0, 0.005, 0.0, 0.0, -0.01])
    ctl.send(np.zeros(M), enable=False)
    assert ctl.latest().version == 1
    ctl.send(u, enable=True, version=2)
    status = ctl.latest()
    # The kinematic plant: its (ideal) reels' speeds are the command; no drive force and no
    # load cell (rigid cables carry no tension it could report).
    assert status.version == 2
    np.testing.assert_array_equal(status.reel_speed, u)
    assert np.isnan(status.drive_force).all() and np.isnan(status.load_cell).all()
    # Version 2 to the session's end, whatever version the commands carry after it.
    ctl.send(u, enable=True, version=1)
    assert ctl.latest().version == 2
    assert "session 1: speaking protocol version 2" in messages
    # A new session (a new `cdpm run`: from sequence 1, enable clear) starts in version 1.
    ctl.send(np.zeros(M), enable=False)
    assert _wait(lambda: not server.bridge.enabled)
    ctl.send(np.zeros(M), enable=False, restart=True)
    assert _wait(lambda: server.session == 2)
    assert ctl.latest().version == 1


def test_a_version_1_bridge_refuses_version_2_commands(serve):
    server, ctl = serve(protocol_version=1)
    ctl.send(np.full(M, 0.01), enable=True, version=2)
    assert _wait(lambda: server.counters["rejected"]["version"] == 1)
    assert not server.bridge.enabled
    ctl.send(np.zeros(M), enable=False, version=1)
    assert ctl.latest().version == 1 and server.counters["commands_received"] == 1


def test_the_protocol_version_must_be_known(robot, p0):
    with pytest.raises(ValueError, match=r"protocol_version must be one of \(1, 2\), got 3"):
        ReelBridgeServer(ReelBridge(robot, cable_lengths(robot, p0)), protocol_version=3)


# --- the dynamic plant's drives --------------------------------------------------------------


def _dynamic_resolved():
    """exp2's scenario (cables 1 and 3 swapped, its start) on the dynamic plant, a hand that
    pushes from 0.2 s on."""
    from cdpm_drake.config import resolve_scenario

    return resolve_scenario(load_scenario(
        "exp2_interaction", "{plant: !DynamicReels {}, operator: !ScriptedOperator "
        "{times: [0.0, 0.2], forces: [[0, 0, 0], [3.0, -2.0, 4.0]]}}"))


def test_dynamic_drives_hold_their_cables_at_rest():
    """At rest, before the plant starts (no speed, no acceleration, friction's sign 0 at zero
    speed), each drive holds its cable's tension: F = -T, the start tensions (5..25 N on
    exp2) as the sensor's start state reads them; the load cells read them plus each cell's
    bias (plant.load_cell.bias_std 0.5 N, drawn from the scenario's seed)."""
    from cdpm_drake.systems.plants.dynamic_plant import sensor_kernel

    resolved = _dynamic_resolved()
    bridge = E.DynamicBridge(resolved, load_cells=True)
    T = bridge.true_tensions()
    assert T.min() > 1.0
    np.testing.assert_allclose(bridge.drive_force(), -T, rtol=0, atol=1e-9)
    _, bias, _ = sensor_kernel(resolved.scenario, resolved.robot, T, "load_cell")
    assert 0.1 < np.abs(bias).max() < 2.5  # a bias, of the size bias_std says
    np.testing.assert_allclose(bridge.load_cell(), T + bias, rtol=0, atol=1e-9)
    assert np.isnan(E.DynamicBridge(_dynamic_resolved()).load_cell()).all()


@pytest.mark.parametrize("sensor", ["drive_torque", "load_cell"])
def test_the_emulators_sensors_are_the_simulated_plants(sensor):
    """The dynamic bridge's drive forces and load cells, read tick by tick under a moving
    command, are the simulated plant's tension sensor's (`cdpm simulate`'s, same scenario):
    the drive force converted back with the sensor's own model and the speeds' difference
    over the tick (the controller's conversion) gives the plant's tension_measured of the same
    tick bit for bit, the load cells equal it; and neither is the truth (the drives' model
    errors of 20 % / 30 %, 0.3 N noise, 0.02 N quantum; the cells' bias, 0.2 N noise)."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from cdpm_drake.config import check_dynamic_reels, resolve_scenario
    from cdpm_drake.kernels.drive_torque import tension_from_drive
    from cdpm_drake.systems.plants.dynamic_plant import build_dynamic_plant, sensor_kernel

    resolved = resolve_scenario(load_scenario(
        "exp2_interaction", f"{{plant: !DynamicReels {{tension_sensor: {sensor}}}}}"))
    sc, robot = resolved.scenario, resolved.robot
    u = 0.01 * np.sin(np.arange(M) + 1.0)
    builder = DiagramBuilder()
    plant = builder.AddSystem(build_dynamic_plant(
        sc, robot, resolved.operator, check_dynamic_reels(sc, robot).tensions, log_truth=False))
    source = builder.AddSystem(ConstantVectorSource(u))
    builder.Connect(source.get_output_port(), plant.GetInputPort("reel_velocity_command"))
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    port = plant.GetOutputPort("tension_measured")
    plant_context = plant.GetMyContextFromRoot(simulator.get_context())
    bridge = E.DynamicBridge(resolved, load_cells=sensor == "load_cell")
    bridge.set_command(u, enable=True)
    T = sc.time_step
    model = sensor_kernel(sc, robot, bridge.true_tensions(), "drive_torque")[0][6:10]
    previous, errors = None, []
    for k in range(60):
        force, speed = bridge.drive_force(), bridge.reel_speed()
        if sensor == "drive_torque":
            read = np.empty(M)
            tension_from_drive(force, speed, (speed - previous) / T if k else np.zeros(M),
                               *model, read)
        else:
            read = bridge.load_cell()
        previous = speed
        simulator.AdvanceTo((k + 1) * T)  # the plant's sensor's sample of tick k, held
        if k:  # (tick 0: no earlier speed for the conversion's acceleration)
            np.testing.assert_array_equal(read, port.Eval(plant_context))
        errors.append(read - bridge.true_tensions())
        bridge.step(T)
    assert np.sqrt(np.mean(np.square(errors))) > 0.1
    assert np.ptp(np.array(previous)) > 0.001  # the reels moved


# --- the command line ------------------------------------------------------------------------


def test_cli_protocol_version_and_dynamic_only_flags(capsys):
    args = E.build_parser().parse_args(["--port", "0", "--protocol-version", "1"])
    server = E.build_server(args)
    try:
        assert server.protocol_version == 1
    finally:
        server.stop()
    for flag in (["--load-cells"], ["--truth-log", "x.npz"]):
        assert E.main(["--port", "0", *flag]) == 2
        assert f"{flag[0]} needs --plant dynamic" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        E.build_parser().parse_args(["--protocol-version", "3"])


def test_the_truth_log_keeps_what_each_status_carried(tmp_path):
    """An in-process dynamic bridge answering a version-2 controller: the truth log holds one
    row per version-2 status, its drive forces as sent (what the controller decodes) beside
    the true tensions."""
    bridge = E.DynamicBridge(_dynamic_resolved())
    server = ReelBridgeServer(bridge, truth=1000).start()
    ctl = _Controller(server)
    try:
        ctl.send(np.zeros(M), enable=False, version=2)
        time.sleep(0.05)
        status = ctl.latest()
    finally:
        ctl.close()
        server.stop()
    path = tmp_path / "truth.npz"
    rows = write_truth_log(server, path)
    truth = np.load(path)
    assert rows == len(truth["time"]) >= 5
    assert truth["tensions"].shape == truth["drive_force"].shape == (rows, M)
    # At rest: the drives hold the cables (F = -T), and the last row is the last status sent.
    np.testing.assert_allclose(truth["drive_force"], -truth["tensions"], rtol=0, atol=1e-9)
    # Beside them, the platform's true pose and each watched pair's true distance there
    # (exp2's start: level, the pairs 60-ish mm and more apart).
    assert truth["p_true"].shape == truth["rpy_true"].shape == (rows, 3)
    np.testing.assert_allclose(truth["p_true"][-1], bridge.platform(), rtol=0, atol=1e-9)
    assert truth["pair_distances_true"].shape == (rows, len(truth["pairs"]))
    assert truth["pair_distances_true"].min() > 0.05
    assert status.version == 2
    assert np.any(np.all(truth["drive_force"] == status.drive_force, axis=1))


# --- cdpm run against cdpm emulate --plant dynamic -------------------------------------------


def _run_against_dynamic_emulator(tmp_path, extra=()):
    """`cdpm emulate --scenario exp2_interaction --plant dynamic --lockstep --truth-log` (a
    process of its own) and `cdpm run exp2_interaction --lockstep` against it for 2 s with
    tension_measured logged; returns (run's exit code, run folder, emulator stdout). In
    lockstep: this test is about the tensions, not the timing (the wall-clock runs' own
    tests are in tests/hardware and test_emulator.py)."""
    from cdpm_drake.cli import main

    out_dir, truth = tmp_path / "run", tmp_path / "truth.npz"
    emulator = subprocess.Popen(
        [sys.executable, "-m", "cdpm_drake.emulator", "--scenario", "exp2_interaction",
         "--plant", "dynamic", "--port", "0", "--duration", "300", "--command-timeout", "1.0",
         "--lockstep", "--truth-log", str(truth), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    code = None
    try:
        ready, _, _ = select.select([emulator.stdout], [], [], 180.0)
        assert ready, "the emulator did not start within 180 s"
        line = emulator.stdout.readline()
        port = int(re.search(r"on 127\.0\.0\.1:(\d+), period 2 ms", line).group(1))
        code = main(["run", "exp2_interaction", "--lockstep", "--duration", "2", "--out",
                     str(out_dir),
                     "--scenario-text", f"{{plant: !HardwareReels {{port: {port}, "
                     "watchdog_ticks: 500, ramp_time: 0.0}, "
                     # The sensor measured here, not damped: with the damping the truth
                     # moves too little for the comparison to say anything.
                     "controller: {tension_damping: {enabled: false}}}"])
    finally:
        emulator.send_signal(signal.SIGINT)
        out, err = emulator.communicate(timeout=120)
    assert emulator.returncode == 130, err
    return code, out_dir, line + out, truth


def _compare(log, truth, segments=4, lags=10):
    """tension_measured against the plant's true tensions on the plant's clock (0 at the
    first enabling command, as the run's log). The two clocks differ by the link's latency, a
    few ticks, and a host stall on either side shifts that offset, so each of `segments`
    equal stretches of the run takes its best of +-`lags` ticks of lag (the offset between two
    clocks, not a fit of values). Returns (RMS error N, largest error N, per-cable
    correlation, lags, rows compared)."""
    measured, t = log["tension_measured"], log["time"]
    pt, T = truth["plant_time"], truth["tensions"]
    ok = np.isfinite(measured).all(axis=1) & (t > 0.05) & (t < 1.9)
    rows = np.flatnonzero(ok)
    aligned, chosen = np.empty((rows.size, M)), []
    for part in np.array_split(np.arange(rows.size), segments):
        k = rows[part]
        best = None
        for lag in range(-lags, lags + 1):
            true = np.stack([np.interp(t[k] + lag * 0.002, pt, T[:, i]) for i in range(M)], 1)
            rms = np.sqrt(np.mean((measured[k] - true) ** 2))
            if best is None or rms < best[0]:
                best = (rms, lag, true)
        aligned[part] = best[2]
        chosen.append(best[1])
    error = measured[rows] - aligned
    corr = [np.corrcoef(measured[rows, i], aligned[:, i])[0, 1] for i in range(M)]
    return np.sqrt(np.mean(error ** 2)), np.abs(error).max(), corr, chosen, rows.size


def _conversions_matched(log, truth, robot, gaps=50):
    """How many of the run's finite tension_measured rows are exactly the conversion of
    statuses the emulator sent: the reel's equation of motion (written out here) on a status
    j's drive forces and speeds, with the acceleration from an earlier status j - s over their
    `time` fields (s <= `gaps`, 50 statuses: the 0.1 s beyond which the controller takes no
    acceleration; a busy host bunches statuses and the controller keeps the newest of those
    waiting, so it skips some: 7 in a row seen). Returns (matched, finite rows)."""
    d = robot.dynamics
    band = d.coulomb_friction / (d.bandwidth * d.reel_inertia)
    F, W, tt = truth["drive_force"], truth["reel_speed"], truth["time"]
    rows = log["tension_measured"][np.isfinite(log["tension_measured"]).all(axis=1)]
    matched = np.zeros(len(rows), dtype=bool)
    for gap in range(1, gaps + 1):
        a = (W[gap:] - W[:-gap]) / (tt[gap:] - tt[:-gap])[:, None]
        w = W[gap:]
        conversion = (d.reel_inertia * a + d.viscous_friction * w
                      + d.coulomb_friction * np.clip(w / band, -1, 1) - F[gap:])
        for chunk in np.array_split(np.arange(len(rows)), 10):
            diff = np.abs(rows[chunk, None, :] - conversion[None, :, :]).max(axis=2)
            matched[chunk] |= (diff < 1e-9 * (1 + np.abs(rows[chunk]).max())).any(axis=1)
    return int(matched.sum()), len(rows)


def test_cdpm_run_logs_tension_measured_that_follows_the_emulators_truth(tmp_path):
    """The drive-torque sensor end to end: the emulator's dynamic plant sends each drive's
    force as the simulated plant's sensor measures it, the controller converts it back with
    the robot file's reel model and logs it.

    Every logged value is the conversion of forces and speeds the emulator sent (exact, from
    its truth log). Against the plant's true tensions (`_compare`), as far off as `cdpm
    simulate`'s own sensor on the same scenario is (measured there: RMS 0.30 N, largest 1.2 N,
    correlation 0.76-0.99 per cable, mean error within 0.05 N; here 0.30 N, 1.3 N,
    0.53-0.99): RMS within 0.5 N, correlation above 0.5 (cable 1, whose truth moves least,
    has the lowest), unbiased within 0.2 N; and not the truth copied (RMS above 0.1 N: the
    model's 20 % / 30 % errors, 0.3 N noise). The ideal drive forces this emulator sent before
    gave an RMS of 0.05-0.11 N: a rehearsal more optimistic than the simulation."""
    from cdpm_drake.config import scenario_robot

    robot = scenario_robot(load_scenario("exp2_interaction"))
    code, out_dir, out, truth_path = _run_against_dynamic_emulator(tmp_path / "a")
    assert code == 0, out
    log, truth = np.load(out_dir / "log.npz"), np.load(truth_path)
    rms, worst, corr, lags, rows = _compare(log, truth)
    assert "session 1: speaking protocol version 2" in out
    # No NaN: the first status (reels at rest, no earlier speed) is read at zero acceleration.
    assert np.isfinite(log["tension_measured"]).all() and rows > 900
    # Every value after it the exact conversion of what was sent.
    matched, finite = _conversions_matched(log, truth, robot, gaps=1)
    assert matched == finite - 1 == len(log["time"]) - 1
    pt, T = truth["plant_time"], truth["tensions"]
    run = (pt > 0.05) & (pt < 1.9)
    # The truth moves (0.25-1.9 N std per cable measured: a comparison that says something).
    assert np.median(T[run].std(axis=0)) > 0.3
    assert 0.1 < rms < 0.5, (rms, worst, corr, lags)
    assert min(corr) > 0.5, (rms, worst, corr, lags)
    measured = log["tension_measured"]
    t = log["time"]
    mean_measured = np.nanmean(measured[(t > 0.05) & (t < 1.9)], axis=0)
    np.testing.assert_allclose(mean_measured, T[run].mean(axis=0), atol=0.2)
