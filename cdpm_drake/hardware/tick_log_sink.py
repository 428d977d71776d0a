"""TickLogSink: a Drake LeafSystem that streams its inputs to a tick log, one row per tick."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from .tick_log import TickLogWriter, row_dtype


class TickLogSink(LeafSystem):
    """Appends one row per periodic publish (period `time_step`, s) to the tick log at `path`;
    the row's tick is round(t / time_step), so a gap in ticks is a missed publish.

    signals: {name: size} or {name: (size, dtype)}; each becomes a vector input port of that
    size. writer_options go to TickLogWriter (flush_rows, blocks, metadata, fsync). The file
    is a resource, like a socket: it opens at the first publish and is never in the Context.
    Call `close()` after the run (rows not yet flushed are written then).

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
        self._T = float(time_step)
        self._options = writer_options
        self.writer = None
        self._ports = {}
        for name, spec in self._signals.items():
            size = spec if isinstance(spec, (int, np.integer)) else spec[0]
            self._ports[name] = self.DeclareVectorInputPort(name, int(size))
        self.DeclarePeriodicPublishEvent(self._T, 0.0, self._publish_row)

    def _publish_row(self, context):
        if self.writer is None:
            self.writer = TickLogWriter(self._path, self._signals, **self._options)
        t = context.get_time()
        self.writer.append(t, {name: port.Eval(context) for name, port in self._ports.items()},
                           tick=int(round(t / self._T)))

    def close(self) -> None:
        """Write the remaining rows and close the file."""
        if self.writer is not None:
            self.writer.close()
