"""Running a sweep: skip the rows already done, run the rest on the local workers or on Ray,
keep every finished row when stopped by Ctrl-C or SIGTERM."""

import dataclasses
import signal
import sys
import time
from pathlib import Path

from cdpm_drake.runs.sweep.errors import SweepError
from cdpm_drake.runs.sweep.local_runner import LocalRunner, default_workers
from cdpm_drake.runs.sweep.lock import acquire_lock, release_lock
from cdpm_drake.runs.sweep.ray_runner import RayRunner
from cdpm_drake.runs.sweep.results import FAILED, ResultStore, atomic_write
from cdpm_drake.runs.sweep.run_task import tasks_for
from cdpm_drake.runs.sweep.variants import Sweep


@dataclasses.dataclass
class SweepOutcome:
    # "done", "interrupted" (SIGINT) or "terminated" (SIGTERM).
    ending: str
    rows: list[dict]
    skipped: int
    ran: int
    failed: int
    wall_s: float
    results: Path
    runner: str = ""


def run_sweep(sweep: Sweep, out_dir, *, workers: int | None = None, ray: bool = False,
              ray_address: str | None = None, ray_chunk: int | None = None,
              ray_init: dict | None = None, keep_logs: bool = False,
              retry_errors: bool = False, progress: bool = True,
              before_run=None) -> SweepOutcome:
    """Run every variant not already done in `out_dir`; return the rows in sweep order.

    `before_run(task)` is called in the worker before each run (an extension point; the
    tests use it to make a variant kill its worker). Ctrl-C and SIGTERM stop the sweep: the
    runs under way are abandoned (rerun next time), every finished row is kept."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    lock = acquire_lock(out_dir)
    try:
        return _run_sweep(sweep, out_dir, workers=workers, ray=ray, ray_address=ray_address,
                          ray_chunk=ray_chunk, ray_init=ray_init, keep_logs=keep_logs,
                          retry_errors=retry_errors, progress=progress, before_run=before_run)
    finally:
        release_lock(lock, out_dir)


def _run_sweep(sweep, out_dir, *, workers, ray, ray_address, ray_chunk, ray_init, keep_logs,
               retry_errors, progress, before_run) -> SweepOutcome:
    store = ResultStore(sweep, out_dir)
    atomic_write(out_dir / "sweep.yaml", sweep.path.read_bytes())
    previous = store.previous()
    todo = []
    for v in sweep.variants:
        row = previous.get(v.run)
        if row is not None and row.get("scenario_hash") == v.scenario_hash and (
                row.get("status") == "ok" or (row.get("status") in FAILED
                                              and not retry_errors)):
            store.adopt(v, row)
        else:
            todo.append(v)
    skipped = len(sweep.variants) - len(todo)
    store.flush()
    by_run = {v.run: v for v in sweep.variants}
    if ray:
        runner = RayRunner(address=ray_address, chunk=ray_chunk, before_run=before_run,
                           init_kwargs=ray_init)
    else:
        n = default_workers() if workers is None else int(workers)
        if n < 1:
            raise SweepError(f"--workers must be an integer >= 1, got {workers!r}")
        runner = LocalRunner(n, before_run=before_run)

    stop = {"signal": None}

    def on_signal(signum, frame):
        stop["signal"] = signum

    installed = {}
    import threading

    from cdpm_drake.runs.interrupt import honoured
    if threading.current_thread() is threading.main_thread():
        for s in (signal.SIGINT, signal.SIGTERM):
            if honoured(s):  # one ignored when the sweep started stays ignored
                installed[s] = signal.signal(s, on_signal)
    bar = None
    failed = [0]
    start = time.perf_counter()
    try:
        for v in todo:
            store.prepare(v)
        tasks = tasks_for(todo, keep_logs=keep_logs)
        if tasks and progress:
            from tqdm import tqdm
            bar = tqdm(total=len(tasks), desc=f"sweep {sweep.file.name}", unit="run",
                       file=sys.stderr, dynamic_ncols=True)
            bar.set_postfix(failed=0)

        def on_row(row):
            v = by_run[row["run"]]
            store.keep(v, row)
            if row.get("status") != "ok":
                failed[0] += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(failed=failed[0])

        if tasks:
            try:
                if ray:
                    runner.run(tasks, on_row, lambda: stop["signal"] is not None,
                               durations=[v.scenario.duration for v in todo])
                else:
                    runner.run(tasks, on_row, lambda: stop["signal"] is not None)
            finally:
                runner.close()
    finally:
        if bar is not None:
            bar.close()
        results = store.flush()
        for s, handler in installed.items():
            signal.signal(s, handler)
    ending = {None: "done", signal.SIGINT: "interrupted",
              signal.SIGTERM: "terminated"}[stop["signal"]]
    rows = [store.rows[v.run] for v in sweep.variants if v.run in store.rows]
    describe = runner.describe() if (tasks and (not ray or runner.cpus is not None)) else ""
    return SweepOutcome(ending=ending, rows=rows, skipped=skipped, ran=len(rows) - skipped,
                        failed=failed[0], wall_s=time.perf_counter() - start,
                        results=results, runner=describe)
