"""The streaming tick log: round trips, truncated files, a writer killed with SIGKILL."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from cdpm_drake.hardware.tick_log import (TickLogError, TickLogWriter, read_tick_log,
                                          realtime_stats, tick_log_header)

SIGNALS = {"p": 3, "lengths": 7, "active": (2, "bool"), "faults": (1, "uint32")}


def _values(k):
    """Row k's content, a function of k only, so a reader can check every row it gets."""
    return {"p": np.array([k, 0.5 * k, -k], dtype=float),
            "lengths": np.arange(7) + 1e-3 * k,
            "active": np.array([k % 2 == 0, k % 3 == 0]),
            "faults": [k % 5]}


def _check_rows(log, rows):
    k = np.arange(rows)
    np.testing.assert_array_equal(log["tick"], k)
    np.testing.assert_array_equal(log["time"], 0.002 * k)
    np.testing.assert_array_equal(log["p"], np.stack([k, 0.5 * k, -k], axis=1))
    np.testing.assert_array_equal(log["lengths"], np.arange(7) + 1e-3 * k[:, None])
    np.testing.assert_array_equal(log["active"][:, 0], k % 2 == 0)
    np.testing.assert_array_equal(log["faults"][:, 0], k % 5)


def test_round_trip_keeps_every_row_and_dtype(tmp_path):
    path = tmp_path / "run.ticks"
    with TickLogWriter(path, SIGNALS, flush_rows=16, metadata={"robot": "paper_7cable"}) as w:
        for k in range(1000):
            w.append(0.002 * k, _values(k))
    log = read_tick_log(path)
    _check_rows(log, 1000)
    assert log["active"].dtype == bool and log["faults"].dtype == np.uint32
    assert log["lengths"].shape == (1000, 7)
    assert np.all(np.diff(log["wall"]) >= 0)  # time.monotonic at append
    assert tick_log_header(path)["metadata"] == {"robot": "paper_7cable"}
    assert w.flushed_rows == 1000


def test_a_truncated_file_gives_its_whole_rows(tmp_path):
    path = tmp_path / "run.ticks"
    with TickLogWriter(path, SIGNALS, flush_rows=10) as w:
        for k in range(100):
            w.append(0.002 * k, _values(k))
    header = tick_log_header(path)
    row = header["dtype"].itemsize
    # Cut 37 rows and a half in: the half row is dropped.
    os.truncate(path, header["data_offset"] + 37 * row + row // 2)
    _check_rows(read_tick_log(path), 37)
    os.truncate(path, header["data_offset"])
    assert read_tick_log(path)["tick"].shape == (0,)
    os.truncate(path, 20)
    with pytest.raises(TickLogError, match=r"header truncated"):
        read_tick_log(path)


def test_not_a_tick_log_is_named(tmp_path):
    path = tmp_path / "log.npz"
    path.write_bytes(b"PK\x03\x04 something else")
    with pytest.raises(TickLogError, match=r"is not a tick log \(magic b'PK\\x03\\x04 som'"):
        read_tick_log(path)


_CHILD = textwrap.dedent("""
    import sys, time
    import numpy as np
    from cdpm_drake.hardware.tick_log import TickLogWriter
    w = TickLogWriter(sys.argv[1], {"p": 3, "lengths": 7, "active": (2, "bool"),
                                    "faults": (1, "uint32")}, flush_rows=10)
    reported = 0
    k = 0
    while True:
        w.append(0.002 * k, {"p": np.array([k, 0.5 * k, -k], dtype=float),
                             "lengths": np.arange(7) + 1e-3 * k,
                             "active": np.array([k % 2 == 0, k % 3 == 0]),
                             "faults": [k % 5]})
        k += 1
        if w.flushed_rows != reported:
            reported = w.flushed_rows
            print(reported, flush=True)
        if k % 50 == 0:
            time.sleep(0.001)
""")


def test_a_writer_killed_with_sigkill_leaves_every_flushed_row(tmp_path):
    path = tmp_path / "killed.ticks"
    child = subprocess.Popen([sys.executable, "-c", _CHILD, str(path)],
                             stdout=subprocess.PIPE, text=True)
    try:
        flushed = 0
        deadline = time.monotonic() + 30
        while flushed < 2000 and time.monotonic() < deadline:
            line = child.stdout.readline()
            if not line:
                break
            flushed = int(line)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait(timeout=10)
    assert child.returncode == -signal.SIGKILL
    assert flushed >= 2000
    log = read_tick_log(path)
    rows = len(log["tick"])
    # Everything the writer reported as flushed before the kill is there, in order, no gap,
    # each row intact (the child may have flushed more after its last report).
    assert rows >= flushed
    _check_rows(log, rows)


@pytest.mark.parametrize("signals,match", [
    ({"time": 3}, r"signal name 'time' must be an identifier other than"),
    ({"2p": 3}, r"signal name '2p'"),
    ([("p", 3), ("p", 2)], r"signal 'p' is declared twice"),
    ({"p": 0}, r"signal 'p': size must be an integer >= 1, got 0"),
    ({"p": (3, "complex128")}, r"signal 'p': dtype 'complex128' must be bool, integer or "
                               r"float"),
])
def test_bad_declarations_are_named(tmp_path, signals, match):
    with pytest.raises(TickLogError, match=match):
        TickLogWriter(tmp_path / "x.ticks", signals)


def test_rows_that_do_not_match_are_named(tmp_path):
    with TickLogWriter(tmp_path / "x.ticks", {"p": 3, "v": 3}) as w:
        with pytest.raises(TickLogError, match=r"row 0 lacks signal 'v'; declared: \['p', 'v'\]"):
            w.append(0.0, {"p": np.zeros(3)})
        with pytest.raises(TickLogError, match=r"row 0: 'p' does not fit its declared size 3"):
            w.append(0.0, {"p": np.zeros(4), "v": np.zeros(3)})


def test_realtime_stats_from_a_known_schedule():
    # 11 ticks of 2 ms; tick 5 starts 3 ms late (period 5 ms, then 1 ms, back on schedule),
    # tick 8 is missing (time jumps by 4 ms, wall too).
    t = np.array([0, 2, 4, 6, 8, 10, 12, 14, 18, 20, 22], dtype=float) * 1e-3
    wall = 100.0 + t.copy()
    wall[5] += 3e-3
    tick = np.round(t / 2e-3).astype(int)
    s = realtime_stats({"wall": wall, "time": t, "tick": tick}, 0.002)
    assert s["ticks"] == 11 and s["missing_ticks"] == 1
    assert s["max"] == pytest.approx(5e-3)
    assert s["p50"] == pytest.approx(2e-3)
    assert s["overruns"] == 1  # only tick 5 started more than a period behind schedule


def test_sink_logs_one_row_per_tick(tmp_path):
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from cdpm_drake.hardware.tick_log_sink import TickLogSink

    path = tmp_path / "sink.ticks"
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource([1.0, 2.0, 3.0]))
    sink = builder.AddSystem(TickLogSink(path, {"p": 3}, time_step=0.002, flush_rows=8))
    builder.Connect(source.get_output_port(), sink.GetInputPort("p"))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.1)
    sink.close()
    log = read_tick_log(path)
    # Publishes at t = 0, 0.002, ..., 0.1: 51 ticks.
    np.testing.assert_array_equal(log["tick"], np.arange(51))
    np.testing.assert_allclose(log["time"], 0.002 * np.arange(51), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(log["p"], np.tile([1.0, 2.0, 3.0], (51, 1)))


def test_the_pool_is_allocated_and_mapped_before_the_first_append(tmp_path):
    """The control loop's appends touch no new memory: the blocks are the same arrays before
    and after many rows, and appending 3000 rows (2.2 MB of them here, 550 pages of 4 KiB)
    takes (almost) no page fault in the appending thread, where a pool of untouched zeros
    (np.zeros maps its pages at their first write) took one per page."""
    import resource

    signals = {"p": 3, "lengths": 7, "x": 80}  # rows of 3 + 90 float64: 744 bytes
    values = {"p": np.zeros(3), "lengths": np.zeros(7), "x": np.zeros(80)}
    with TickLogWriter(tmp_path / "pool.ticks", signals, flush_rows=50, blocks=64) as w:
        blocks = [(b.__array_interface__["data"][0], len(b)) for b in w._pool]
        w.append(0.0, values)
        before = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
        for k in range(1, 3001):
            w.append(0.002 * k, values)
        faults = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - before
        assert [(b.__array_interface__["data"][0], len(b)) for b in w._pool] == blocks
    assert len(blocks) == 64 and w.dtype.itemsize == 744
    assert faults < 10, faults
