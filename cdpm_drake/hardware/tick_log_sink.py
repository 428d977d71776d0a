"""TickLogSink: a Drake LeafSystem that streams its inputs to a tick log, one row per tick."""

import time

import numpy as np
from pydrake.systems.framework import LeafSystem

from cdpm_drake.hardware.tick_log import TickLogWriter, row_dtype


# The sink's own column: wall time of the tick's work, s (docs/LOG_FORMAT.md `compute`).
COMPUTE = "compute"


class TickLogSink(LeafSystem):
    """Appends one row per periodic publish (period `time_step`, s) to the tick log at `path`;
    the row's tick is round(t / time_step), so a gap in ticks is a missed publish.

    Each row also gets `compute`, s: the wall time from the start of the discrete updates at
    t_{k-1} to this row's append at t_k. Drake runs a step's updates (the reels read the bridge)
    and the next tick's publishes (the controller is evaluated, the command sent, this row
    appended) back to back, and paces in real time between steps, so this is the work of one
    tick; what is left of the period is headroom. NaN for tick 0 (published by
    initialisation, with no update before it).

    signals: {name: size} or {name: (size, dtype)}; each becomes a vector input port of that
    size. writer_options go to TickLogWriter (flush_rows, blocks, metadata, fsync). The file
    is a resource, like a socket: it opens at `open()` or else at the first publish, and is
    never in the Context. Call `close()` after the run (rows not yet flushed are written
    then).

    .. pydrake_system::

        name: tick_log
        input_ports:
        - <signal> (one per declared signal, its declared size)
    """

    def __init__(self, path, signals, time_step: float = 0.002, **writer_options):
        super().__init__()
        self._path = path
        self._signals = dict(signals)
        row_dtype(self._signals)  # reject bad declarations at build time, not at the first tick
        if not (np.isfinite(time_step) and time_step > 0):
            raise ValueError(f"time_step must be a finite number > 0 s, got {time_step!r}")
        if COMPUTE in self._signals:
            raise ValueError(f"signal name {COMPUTE!r} is the sink's own column")
        self._T = float(time_step)
        self._options = writer_options
        # time.monotonic() at the start of the last discrete update, s (a wall-clock stamp
        # in the Context, so a cloned context measures its own ticks).
        self._tick_start = self.DeclareDiscreteState(np.array([np.nan]))
        self.DeclarePeriodicDiscreteUpdateEvent(self._T, 0.0, self._update_tick_start)
        self.writer = None
        self._ports = {}
        for name, spec in self._signals.items():
            size = spec if isinstance(spec, (int, np.integer)) else spec[0]
            self._ports[name] = self.DeclareVectorInputPort(name, int(size))
        self.DeclarePeriodicPublishEvent(self._T, 0.0, self._publish_row)

    def _update_tick_start(self, context, discrete_state):
        discrete_state.get_mutable_vector(0).SetAtIndex(0, time.monotonic())

    def open(self) -> None:
        """Open the file and map the writer's row pool now. A real-time run calls this before
        the reels are enabled: mapping the pool (128 blocks of 50 rows, ~20 MB with the safety
        blocks' columns) took 6-34 ms in the first publish, after the enabling command, and
        with the rest of that publish it passed the bridge's 50 ms command timeout."""
        if self.writer is None:
            self.writer = TickLogWriter(self._path, {**self._signals, COMPUTE: 1},
                                        **self._options)

    def _publish_row(self, context):
        if self.writer is None:
            self.open()
        t = context.get_time()
        values = {name: port.Eval(context) for name, port in self._ports.items()}
        start = context.get_discrete_state(self._tick_start).GetAtIndex(0)
        values[COMPUTE] = time.monotonic() - start
        self.writer.append(t, values, tick=int(round(t / self._T)))

    def close(self) -> None:
        """Write the remaining rows and close the file."""
        if self.writer is not None:
            self.writer.close()
