"""Runs on this machine's cores: a pool of spawned worker processes, one run each at a time."""

import os
import signal
import time

from cdpm_drake.runs.sweep.run_task import RunTask, died_row, execute_run


def _worker_main(conn, before_run):
    """A local worker: imported once (warm start), then runs tasks until told to stop."""
    # Ctrl-C reaches the whole process group; the parent decides what stops and when.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    from cdpm_drake.runs import simulate as simulation  # noqa: F401  (the warm start: pydrake and the blocks, once)
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        conn.send(execute_run(task, before_run))


def _describe_exit(code) -> str:
    if code is None:
        return "still running"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


class LocalRunner:
    """One spawned process per worker, each fed one run at a time over its own pipe, so a
    worker that dies is known to have died on that run (its error row), and is replaced.
    The pool lives from the first `run` to `close` (a benchmark warms it up once)."""

    def __init__(self, workers: int, before_run=None):
        import multiprocessing
        self.workers = int(workers)
        self._ctx = multiprocessing.get_context("spawn")
        self._before_run = before_run
        self._pool = []

    def describe(self) -> str:
        return f"{self.workers} local worker process{'es' if self.workers != 1 else ''}"

    def _start(self):
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_worker_main, args=(child, self._before_run),
                                 daemon=True, name="cdpm-sweep-worker")
        proc.start()
        child.close()
        return {"conn": parent, "proc": proc, "task": None}

    def run(self, tasks: list[RunTask], on_row, should_stop) -> None:
        """Run the tasks; returns when all are done, or as soon as should_stop() is true (the
        runs under way are then abandoned: close() stops their workers)."""
        from multiprocessing.connection import wait

        pending = list(reversed(tasks))
        pool = self._pool
        while len(pool) < min(self.workers, len(tasks)):
            pool.append(self._start())
        while pending or any(w["task"] is not None for w in pool):
            if should_stop():
                return
            for w in pool:
                if w["task"] is None and pending:
                    w["task"] = pending.pop()
                    w["conn"].send(w["task"])
            busy = [w for w in pool if w["task"] is not None]
            wait([w["conn"] for w in busy] + [w["proc"].sentinel for w in busy], timeout=0.25)
            for k, w in enumerate(pool):
                if w["task"] is None:
                    continue
                row = None
                try:
                    if w["conn"].poll():
                        row = w["conn"].recv()
                except (EOFError, OSError):
                    row = None
                if row is not None:
                    w["task"] = None
                    on_row(row)
                elif not w["proc"].is_alive():
                    w["proc"].join()
                    on_row(died_row(w["task"], "the worker process died "
                                                f"({_describe_exit(w['proc'].exitcode)}) "
                                                "while running this variant"))
                    w["conn"].close()
                    pool[k] = self._start()

    def close(self) -> None:
        """Stop every worker: idle ones are told to quit, busy ones are terminated."""
        pool, self._pool = self._pool, []
        for w in pool:
            try:
                if w["task"] is None and w["proc"].is_alive():
                    w["conn"].send(None)
            except OSError:
                pass
        deadline = time.monotonic() + 2.0
        for w in pool:
            if w["task"] is not None:
                w["proc"].terminate()
            w["proc"].join(timeout=max(0.0, deadline - time.monotonic()))
            if w["proc"].is_alive():
                w["proc"].kill()
                w["proc"].join()
            w["conn"].close()


def default_workers() -> int:
    """The CPUs this process may run on: one worker each."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)
