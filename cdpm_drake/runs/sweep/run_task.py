"""One run of a sweep in a worker: the task it is handed (picklable) and the row it returns."""

import dataclasses
import io
import math
import time

import numpy as np

from cdpm_drake.config import Scenario
from cdpm_drake.runs.sweep.metrics import run_metrics


@dataclasses.dataclass
class RunTask:
    """What a worker needs for one run (picklable; a Ray task carries a list of them)."""

    run: str
    index: int
    values: dict
    scenario_yaml: str
    scenario_hash: str
    keep_log: bool = False


def tasks_for(variants, keep_logs: bool = False) -> list[RunTask]:
    return [RunTask(run=v.run, index=v.index, values=v.values, scenario_yaml=v.scenario_yaml,
                    scenario_hash=v.scenario_hash, keep_log=keep_logs) for v in variants]


def execute_run(task: RunTask, before_run=None) -> dict:
    """Run one variant: load its resolved scenario from its YAML (the file written beside the
    row), simulate it, and return its row (and the compressed log bytes with keep_log).
    Never raises for a failing run: the row says `error` (it did not run, or its worker
    died), or `fault` (it stopped part-way: the metrics are those of the ticks it logged)."""
    from pydrake.common.yaml import yaml_load_typed

    from cdpm_drake.runs.simulate import simulate

    row = {"run": task.run, "scenario_hash": task.scenario_hash, "status": "ok", "error": ""}
    start = time.perf_counter()
    cpu = time.process_time()
    log = None
    try:
        if before_run is not None:
            before_run(task)
        scenario = yaml_load_typed(schema=Scenario, data=task.scenario_yaml)
        result = simulate(scenario=scenario)
        wall = time.perf_counter() - start
        log = result.log
        metrics = run_metrics(log, scenario)
        row.update(metrics)  # a faulted run's too: what it logged up to the fault
        if result.error is not None:
            row.update(status="fault", error=f"the run stopped at t = {metrics['sim_s']:.3f} s: "
                                             f"{type(result.error).__name__}: {result.error}")
        row["wall_s"] = wall
        row["rtf"] = metrics["sim_s"] / wall if wall > 0 else math.nan
    except Exception as e:
        row.update(status="error", error=f"{type(e).__name__}: {e}",
                   wall_s=time.perf_counter() - start)
    # Internal (not a column): CPU seconds of the run, which bench_sweep.py sets against wall
    # time to tell a busy machine from overhead of ours.
    row["_cpu_s"] = time.process_time() - cpu
    if task.keep_log and log is not None:
        buf = io.BytesIO()
        np.savez_compressed(buf, **log)
        row["_log_npz"] = buf.getvalue()
    return row


def died_row(task: RunTask, why: str) -> dict:
    """The error row of a run whose worker died (a local process or a Ray worker)."""
    return {"run": task.run, "scenario_hash": task.scenario_hash, "status": "error",
            "error": why}
