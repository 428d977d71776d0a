"""scripts/bench/soak_realtime.py: its measurements from known datagram timelines, and a smoke run
end to end (one short run, normal scheduling: the suite assumes no root)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from helpers_scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "bench" / "soak_realtime.py"


@pytest.fixture(scope="module")
def soak():
    return load_script("bench/soak_realtime.py")


def _commands(rows):
    """(arrival s, sequence, echo, enable) rows, as the relay records them."""
    return np.array(rows, dtype=float)


def test_controller_latency_is_status_forwarded_to_the_first_command_answering_it(soak):
    # Statuses 1..5 forwarded at 0, 2, 4, 6, 10 ms (arrival, forwarded, sequence). Status 1
    # came during the start-up handshake (before the first enabled command, at 1 ms): left
    # out. The controller answers 2 at 3.5 ms, skips 3 (it took 3 and 4 together after a
    # stall) and answers 4 at 9 ms, which answers 3 too. Status 5, after the last command, is
    # left out.
    statuses = np.array([[0.000, 0.000, 1], [0.002, 0.002, 2], [0.004, 0.004, 3],
                         [0.006, 0.006, 4], [0.010, 0.010, 5]])
    commands = _commands([[0.0005, 1, 1, 0], [0.001, 2, 1, 1], [0.0035, 3, 2, 1],
                          [0.009, 4, 4, 1]])
    latency = soak.controller_latency(statuses, commands)
    np.testing.assert_allclose(latency, [0.0015, 0.005, 0.003], atol=1e-12)


def test_a_hold_is_a_stop_followed_by_enabling_again(soak):
    # Enabled commands, a stop burst of three at 10 ms, enabled again at 14 ms; the run's own
    # end (a final burst with nothing after it) is no hold. Statuses every 2 ms but none
    # from 6 to 13 ms: the longest gap around the hold is 7 ms.
    commands = _commands([[0.000, 1, -1, 0], [0.002, 2, 1, 1], [0.004, 3, 2, 1],
                          [0.010, 4, 3, 0], [0.0101, 5, 3, 0], [0.0102, 6, 3, 0],
                          [0.014, 7, 4, 1], [0.016, 8, 5, 1],
                          [0.018, 9, 6, 0], [0.0181, 10, 6, 0], [0.0182, 11, 6, 0]])
    arrivals = [0.000, 0.002, 0.004, 0.006, 0.013, 0.015, 0.017]
    statuses = np.array([[t, t, k + 1] for k, t in enumerate(arrivals)])
    host = np.array([[0.0065, 0.006, 1.0]])  # cpu 1 woke 6 ms late from 6.5 ms
    holds = soak._holds(commands, statuses, host)
    assert len(holds) == 1
    (hold,) = holds
    assert hold["at"] == pytest.approx(0.010)
    assert hold["stopped_ms"] == pytest.approx(4.0)
    assert hold["bridge_gap_ms"] == pytest.approx(7.0)
    assert hold["host_late"] == [(1, pytest.approx(6.0))]


def test_a_short_soak_runs_end_to_end(tmp_path):
    # One run of 0.5 s under normal scheduling: the emulator, the relay and the traced
    # controller start, and the report has the run's row. (How it ended depends on the host's
    # load, so the test reads the figures without judging them.)
    out = subprocess.run([sys.executable, str(SCRIPT), "--runs", "1", "--duration", "0.5",
                          "--rt-priority", "0", "--json", str(tmp_path / "soak.json")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode in (0, 1), out.stderr
    assert "controller-side latency max" in out.stdout, out.stdout + out.stderr
    (run,) = json.loads((tmp_path / "soak.json").read_text())
    assert run["ending"] in ("completed", "fault"), run
    if run["ending"] == "completed":
        assert run["ticks"] == 251  # 0.5 s at 500 Hz, ticks 0..250
        p50, p99, worst = run["latency"]
        assert 0 < p50 <= p99 <= worst
    assert "gc_in_run" in run and "holds" in run
