"""Runs on a Ray cluster (or a local Ray): runs grouped into Ray tasks."""

import math
import time

import numpy as np

from cdpm_drake.runs.sweep.errors import SweepError
from cdpm_drake.runs.sweep.run_task import RunTask, died_row, execute_run


def _ray_chunk(tasks, before_run):
    """A Ray task: several runs in one go, so Ray's per-task cost is spread over them."""
    from cdpm_drake.runs import simulate as simulation  # noqa: F401
    rows = []
    for task in tasks:
        start = time.perf_counter()
        row = execute_run(task, before_run)
        row["_task_s"] = time.perf_counter() - start
        rows.append(row)
    return rows


class RayRunner:
    """Runs grouped into Ray tasks. `address` None starts a local Ray (unless one is already
    initialised, as in the tests); a cluster's nodes need cdpm_drake installed."""

    def __init__(self, address=None, chunk=None, before_run=None, init_kwargs=None):
        self.address = address
        self.chunk = chunk
        self._before_run = before_run
        self._init_kwargs = dict(init_kwargs or {})
        self._started = False
        self.cpus = None
        self.chunks = 0
        self.task_stats = []

    def describe(self) -> str:
        where = self.address or "a local Ray"
        return f"Ray ({where}, {self.cpus:g} CPUs, {self.chunks} tasks)"

    def connect(self):
        try:
            import ray
        except ImportError:
            raise SweepError("--ray needs Ray: pip install -e '.[ray]' (or pip install "
                             "'ray>=2.9')") from None
        if not ray.is_initialized():
            kwargs = {"include_dashboard": False, "log_to_driver": False, **self._init_kwargs}
            if self.address:
                kwargs["address"] = self.address
            try:
                ray.init(**kwargs)
            except Exception as e:
                raise SweepError(f"--ray {self.address or ''}: cannot start or reach Ray: "
                                 f"{e}") from None
            self._started = True
        self.cpus = float(ray.cluster_resources().get("CPU", 1.0))
        return ray

    def chunk_size(self, tasks: list[RunTask], durations: list[float]) -> int:
        """Runs per task: enough that a task lasts >= 2 s of estimated compute (Ray's
        per-task cost is a few ms, so < 1 % then), yet >= 3 tasks per CPU for balance."""
        if self.chunk:
            return max(1, int(self.chunk))
        n = len(tasks)
        # 5x real time is what one run of the shipped experiments does here (bench_sweep.py).
        est = max(1e-3, float(np.mean(durations)) / 5.0) if durations else 1.0
        by_time = math.ceil(2.0 / est)
        by_balance = max(1, n // max(1, int(3 * self.cpus)))
        return max(1, min(by_time, by_balance))

    def run(self, tasks: list[RunTask], on_row, should_stop, durations=()) -> None:
        ray = self.connect()
        import ray.exceptions as rex

        remote = ray.remote(max_retries=0)(_ray_chunk)
        size = self.chunk_size(tasks, list(durations))
        refs = {}

        def submit(group):
            refs[remote.remote(group, self._before_run)] = group

        for k in range(0, len(tasks), size):
            submit(tasks[k:k + size])
        self.chunks = len(refs)
        while refs:
            if should_stop():
                for ref in refs:
                    ray.cancel(ref, force=True)
                return
            done, _ = ray.wait(list(refs), num_returns=1, timeout=0.25)
            for ref in done:
                group = refs.pop(ref)
                try:
                    rows = ray.get(ref)
                except (rex.WorkerCrashedError, rex.RayTaskError, rex.TaskCancelledError,
                        rex.NodeDiedError, rex.ObjectLostError) as e:
                    if len(group) > 1:  # find the run that kills: one task each
                        for task in group:
                            submit([task])
                        self.chunks += len(group)
                        continue
                    rows = [died_row(group[0], "the Ray worker died while running this "
                                                f"variant ({type(e).__name__})")]
                # (runs in the task, seconds of compute inside it): for bench_sweep.py.
                self.task_stats.append((len(rows), sum(r.get("_task_s", 0.0) for r in rows)))
                for row in rows:
                    on_row(row)

    def close(self) -> None:
        """Shut Ray down if this runner started it (a Ray the caller started stays up)."""
        if self._started:
            import ray
            ray.shutdown()
            self._started = False
