"""A streaming per-tick log for real-time runs: nothing lost but the last unflushed rows.

The control loop appends fixed-size rows into preallocated blocks (no allocation, no growing
lists); a writer thread writes each full block with os.write, so a row is in the kernel's
page cache, and survives the process being killed, at most `flush_rows` ticks after it was
appended. Each row holds `tick` (int64), `time` (the loop's clock, s), `wall`
(time.monotonic() at append, s) and the caller's named signals.

Only the writer thread writes to the file (the header too): the thread that appends, the
real-time loop, never waits for the disk, unless the writer falls a whole pool behind
(`blocks` x `flush_rows` rows, 12.8 s at 500 Hz by default; counted in `stalls`). The pool is
one array allocated and written to (so its pages are mapped) when the writer is created: an
append touches no new memory. The writer writes straight from the pool's memory (no copy).

File layout: b"CDPMTICK", uint32 little-endian header length, a JSON header (format version,
numpy dtype of a row, caller metadata) padded with spaces to a multiple of 8 bytes, then the
rows back to back. `read_tick_log` reads every whole row, also from a truncated file.

`tick_log_sink.TickLogSink` is the Drake wrapper; this module does not import Drake.
"""

import json
import os
import queue
import struct
import threading
import time

import numpy as np

MAGIC = b"CDPMTICK"
FORMAT_VERSION = 1
RESERVED = ("tick", "time", "wall")
_LEN = struct.Struct("<I")


class TickLogError(ValueError):
    """A bad signal declaration, a row that does not match it, or a file that is no tick log."""


def row_dtype(signals) -> np.dtype:
    fields = [("tick", "<i8"), ("time", "<f8"), ("wall", "<f8")]
    items = signals.items() if isinstance(signals, dict) else signals
    for item in items:
        name, spec = item
        size, dtype = (spec, "<f8") if isinstance(spec, (int, np.integer)) else spec
        if not isinstance(name, str) or not name.isidentifier() or name in RESERVED:
            raise TickLogError(f"signal name {name!r} must be an identifier other than "
                               f"{list(RESERVED)}")
        if any(name == f[0] for f in fields):
            raise TickLogError(f"signal {name!r} is declared twice")
        if not (isinstance(size, (int, np.integer)) and size >= 1):
            raise TickLogError(f"signal {name!r}: size must be an integer >= 1, got {size!r}")
        try:
            dt = np.dtype(dtype)
        except TypeError:
            raise TickLogError(f"signal {name!r}: unknown dtype {dtype!r}") from None
        if dt.kind not in "biuf":
            raise TickLogError(f"signal {name!r}: dtype {dtype!r} must be bool, integer or "
                               f"float")
        fields.append((name, dt.newbyteorder("<").str, (int(size),)))
    return np.dtype(fields)


class TickLogWriter:
    """Append rows from the control loop; a writer thread streams them to `path`.

    signals: {name: size} or {name: (size, dtype)} (default dtype float64). flush_rows: rows
    per block handed to the writer (the most a SIGKILL can lose). blocks: blocks in the pool;
    if the writer falls that far behind (a disk stalled for blocks x flush_rows ticks),
    append waits for it (counted in `stalls`) rather than dropping rows. metadata:
    JSON-serialisable dict stored in the header. fsync: also fsync each block (survives power
    loss, costs disk latency in the writer thread only).
    """

    def __init__(self, path, signals, *, flush_rows: int = 50, blocks: int = 128,
                 metadata: dict | None = None, fsync: bool = False):
        if not (isinstance(flush_rows, int) and flush_rows >= 1):
            raise TickLogError(f"flush_rows must be an integer >= 1, got {flush_rows!r}")
        if not (isinstance(blocks, int) and blocks >= 2):
            raise TickLogError(f"blocks must be an integer >= 2, got {blocks!r}")
        self.dtype = row_dtype(signals)
        self.signals = {name: self.dtype[name].shape[0] for name in self.dtype.names[3:]}
        header = json.dumps({"format": "cdpm tick log", "version": FORMAT_VERSION,
                             "dtype": self.dtype.descr, "metadata": metadata or {}},
                            allow_nan=False).encode()
        pad = (-(len(MAGIC) + _LEN.size + len(header))) % 8
        header += b" " * pad
        self.path = str(path)
        self._fsync = fsync
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._flush_rows = flush_rows
        # One array for the whole pool, written once so that every page is mapped now, not
        # at a tick's first write into it; the blocks are views into it.
        memory = np.empty(blocks * flush_rows, dtype=self.dtype)
        memory.view(np.uint8).fill(0)
        self._pool = [memory[k * flush_rows:(k + 1) * flush_rows] for k in range(blocks)]
        self._bytes = [block.view(np.uint8) for block in self._pool]
        self._free = queue.SimpleQueue()
        for k in range(1, blocks):
            self._free.put(k)
        self._full = queue.SimpleQueue()
        self._full.put(MAGIC + _LEN.pack(len(header)) + header)  # the writer's first write
        self._current = 0
        self._n = 0
        self.rows = 0            # rows appended
        self.flushed_rows = 0    # rows written to the file
        self.stalls = 0          # appends that had to wait for the writer
        self._error = None
        self._written = threading.Condition()
        self._thread = threading.Thread(target=self._writer, name="tick-log-writer",
                                        daemon=True)
        self._thread.start()

    def append(self, time_s: float, values: dict, tick: int | None = None) -> None:
        """One row: `time_s` in s, `values[name]` with the declared size for every signal.
        `tick` defaults to the row count."""
        if self._error is not None:
            raise self._error
        block = self._pool[self._current]
        i = self._n
        block["tick"][i] = self.rows if tick is None else tick
        block["time"][i] = time_s
        block["wall"][i] = time.monotonic()
        try:
            for name in self.signals:
                block[name][i] = values[name]
        except KeyError as e:
            raise TickLogError(f"row {self.rows} lacks signal {e.args[0]!r}; declared: "
                               f"{list(self.signals)}") from None
        except ValueError as e:
            raise TickLogError(f"row {self.rows}: {name!r} does not fit its declared size "
                               f"{self.signals[name]}: {e}") from None
        self._n = i + 1
        self.rows += 1
        if self._n == self._flush_rows:
            self._hand_off()

    def _hand_off(self) -> None:
        self._full.put((self._current, self._n))
        self._n = 0
        try:
            self._current = self._free.get_nowait()
        except queue.Empty:
            self.stalls += 1
            self._current = self._free.get()

    def flush(self, timeout: float = 10.0) -> None:
        """Hand the partial block to the writer and wait until every row is in the file."""
        if self._n:
            self._hand_off()
        target = self.rows
        with self._written:
            self._written.wait_for(lambda: self.flushed_rows >= target or self._error,
                                   timeout=timeout)
        if self._error is not None:
            raise self._error

    def close(self) -> None:
        """Flush, stop the writer thread and close the file. Idempotent."""
        if self._fd is None:
            return
        try:
            self.flush()
        finally:
            self._full.put(None)
            self._thread.join(timeout=10.0)
            os.close(self._fd)
            self._fd = None

    def _write_all(self, data) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            view = view[n:]

    def _writer(self) -> None:
        itemsize = self.dtype.itemsize
        while True:
            item = self._full.get()
            if item is None:
                return
            if isinstance(item, bytes):  # the header
                try:
                    self._write_all(item)
                except OSError as e:
                    self._error = TickLogError(f"writing {self.path!r} failed: {e}")
                continue
            k, n = item
            try:
                self._write_all(self._bytes[k][:n * itemsize])
                if self._fsync:
                    os.fsync(self._fd)
            except OSError as e:
                self._error = TickLogError(f"writing {self.path!r} failed: {e}")
            self._free.put(k)
            with self._written:
                self.flushed_rows += n
                self._written.notify_all()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def tick_log_header(path) -> dict:
    """The header of a tick log: {'dtype', 'metadata', 'version', 'data_offset'}."""
    fixed = len(MAGIC) + _LEN.size  # the magic and the header's length: 12 bytes
    with open(path, "rb") as f:
        head = f.read(fixed)
        if head[:len(MAGIC)] != MAGIC[:len(head)]:
            raise TickLogError(f"{str(path)!r} is not a tick log (magic {head[:8]!r}, "
                               f"expected {MAGIC!r})")
        if len(head) < fixed:  # what there is agrees with the magic: cut short
            raise TickLogError(f"{str(path)!r} is truncated: {len(head)} bytes, where a tick "
                               f"log's header alone takes at least {fixed} (the magic "
                               f"{MAGIC!r} and the header's length) plus its JSON")
        (n,) = _LEN.unpack_from(head, len(MAGIC))
        raw = f.read(n)
    if len(raw) < n:
        raise TickLogError(f"{str(path)!r} is truncated: {fixed + len(raw)} bytes, where its "
                           f"header takes {fixed + n} (header truncated: {len(raw)} of its "
                           f"{n} bytes of JSON)")
    try:
        header = json.loads(raw.decode())
        header["dtype"]
    except (UnicodeDecodeError, json.JSONDecodeError, TypeError, KeyError) as e:
        raise TickLogError(f"{str(path)!r}: the header is damaged ({type(e).__name__}: "
                           f"{e}); not a tick log this reader can use") from None
    if header.get("version") != FORMAT_VERSION:
        raise TickLogError(f"{str(path)!r}: tick log version {header.get('version')!r}, this "
                           f"reader knows version {FORMAT_VERSION}")
    descr = [tuple(tuple(x) if isinstance(x, list) else x for x in field)
             for field in header["dtype"]]
    header["dtype"] = np.dtype(descr)
    header["data_offset"] = len(MAGIC) + _LEN.size + n
    return header


def read_tick_log(path) -> dict[str, np.ndarray]:
    """Every whole row of a tick log, as {'tick', 'time', 'wall', signal...}: arrays with one
    row per tick. A partial last row (the writer was killed mid-write) is left out."""
    header = tick_log_header(path)
    dtype = header["dtype"]
    with open(path, "rb") as f:
        f.seek(header["data_offset"])
        data = f.read()
    rows = len(data) // dtype.itemsize
    table = np.frombuffer(data, dtype=dtype, count=rows)
    return {name: np.array(table[name]) for name in dtype.names}


def damaged_rows(table: dict, time_step: float, finite=("p", "F_H", "lengths")) -> np.ndarray:
    """A bool per row of a read tick log (read_tick_log): True where the row cannot be what
    the writer wrote: its tick out of the sequence the other rows keep (tick k + the
    median offset), its time not the tick's (tick x time_step, within half a tick) or not
    finite, its wall clock not finite, or NaN in a signal of `finite` (the position, the
    hand force and the lengths are numbers on every tick a run logs). Bytes overwritten in
    the file's middle read as such rows; read_tick_log keeps them as they read."""
    tick = np.asarray(table.get("tick", np.zeros(0)), dtype=np.int64).reshape(-1)
    n = tick.size
    if not n:
        return np.zeros(0, dtype=bool)
    offset = int(np.median(tick - np.arange(n)))
    bad = tick != np.arange(n) + offset
    t = np.asarray(table["time"], dtype=float).reshape(-1)
    with np.errstate(invalid="ignore", over="ignore"):
        bad |= ~np.isfinite(t) | ~(np.abs(t - tick * time_step) <= time_step / 2)
        bad |= ~np.isfinite(np.asarray(table["wall"], dtype=float).reshape(-1))
    for key in finite:
        if key in table:
            values = np.asarray(table[key], dtype=float).reshape(n, -1)
            bad |= np.isnan(values).any(axis=1)
    return bad


def tick_log_tail(path) -> dict:
    """{'ticks': whole rows in the file, 'cut_bytes': bytes of a partial last row (a writer
    killed mid-write), which read_tick_log leaves out}."""
    header = tick_log_header(path)
    size = os.path.getsize(path) - header["data_offset"]
    rows, cut = divmod(max(0, size), header["dtype"].itemsize)
    return {"ticks": int(rows), "cut_bytes": int(cut)}


def realtime_stats(log: dict, time_step: float) -> dict:
    """Tick timing of a real-time run from its log: period percentiles (s), overruns (ticks
    that started more than one period behind the schedule set by the first tick) and missing
    ticks (gaps in the tick column)."""
    wall, t, tick = log["wall"], log["time"], log["tick"]
    if len(wall) < 2:
        return {"ticks": int(len(wall)), "p50": np.nan, "p99": np.nan, "p99.9": np.nan,
                "max": np.nan, "overruns": 0, "missing_ticks": 0}
    period = np.diff(wall)
    lateness = (wall - wall[0]) - (t - t[0])
    gaps = np.diff(tick)
    return {
        "ticks": int(len(wall)),
        "p50": float(np.percentile(period, 50)),
        "p99": float(np.percentile(period, 99)),
        "p99.9": float(np.percentile(period, 99.9)),
        "max": float(period.max()),
        "overruns": int(np.count_nonzero(lateness > time_step)),
        "missing_ticks": int(np.sum(gaps[gaps > 1] - 1)),
    }
