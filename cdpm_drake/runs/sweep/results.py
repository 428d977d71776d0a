"""A sweep's results: DIR/results.csv (its columns, one row per run) and DIR/runs/<run>/,
written atomically as runs finish, and read back."""

import csv
import io
import json
import os
import time
from pathlib import Path

from cdpm_drake.runs.sweep.cells import csv_cell, flow_yaml
from cdpm_drake.runs.sweep.errors import SweepError
from cdpm_drake.runs.sweep.metrics import METRICS
from cdpm_drake.runs.sweep.variants import Sweep, Variant


# A row's status: "ok"; "fault": the run stopped part-way, its metrics cover the ticks it
# logged; "error": it did not run (or its worker died), no metrics.
FAILED = ("fault", "error")


def columns_for(sweep: Sweep) -> list[str]:
    cols = ["run"] + list(sweep.fields)
    if sweep.has_overlays:
        cols.append("variant")
    cols += ["random_seed", "status", "error"]
    cols += list(METRICS) + ["scenario_hash"]
    return cols


def atomic_write(path: Path, data: bytes) -> None:
    """Write `path` whole or not at all: a killed sweep leaves the old file, never half a
    new one."""
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


class ResultStore:
    """DIR/results.csv and DIR/runs/<run>/: rows kept as they finish (row.json at once,
    results.csv rewritten atomically at most every `csv_period` s and at the end)."""

    def __init__(self, sweep: Sweep, out_dir: Path, csv_period: float = 1.0):
        self.sweep = sweep
        self.out = Path(out_dir)
        self.columns = columns_for(sweep)
        self.rows = {}  # run id -> row (as written)
        self._csv_period = csv_period
        self._last_csv = 0.0
        self._dirty = False

    def run_dir(self, run: str) -> Path:
        return self.out / "runs" / run

    def previous(self) -> dict:
        """Rows of earlier invocations found under DIR/runs/ (run id -> row)."""
        found = {}
        for v in self.sweep.variants:
            p = self.run_dir(v.run) / "row.json"
            if p.is_file():
                try:
                    found[v.run] = json.loads(p.read_text())
                except (OSError, ValueError):
                    continue  # half-written by a killed process: rerun
        return found

    def prepare(self, variant: Variant) -> None:
        d = self.run_dir(variant.run)
        d.mkdir(parents=True, exist_ok=True)
        atomic_write(d / "scenario.yaml", variant.scenario_yaml.encode())
        stale = d / "row.json"
        if stale.exists():
            stale.unlink()

    def keep(self, variant: Variant, row: dict) -> None:
        log = row.pop("_log_npz", None)
        row.pop("_task_s", None)
        row.pop("_cpu_s", None)
        full = self._full_row(variant, row)
        d = self.run_dir(variant.run)
        d.mkdir(parents=True, exist_ok=True)
        if log is not None:
            atomic_write(d / "log.npz", log)
        atomic_write(d / "row.json", json.dumps(full, indent=1).encode())
        self.rows[variant.run] = full
        self._dirty = True
        if time.monotonic() - self._last_csv >= self._csv_period:
            self.flush()

    def adopt(self, variant: Variant, row: dict) -> None:
        self.rows[variant.run] = self._full_row(variant, row)
        self._dirty = True

    def _full_row(self, variant: Variant, row: dict) -> dict:
        full = {c: "" for c in self.columns}
        for k, v in variant.values.items():
            full[k] = csv_cell(v)
        if self.sweep.has_overlays:
            full["variant"] = flow_yaml(variant.overlay) if variant.overlay is not None else ""
        full["random_seed"] = str(variant.random_seed)
        for k, v in row.items():
            if k in full and k not in variant.values:
                full[k] = v if isinstance(v, str) else csv_cell(v)
        full["run"] = variant.run
        full["scenario_hash"] = variant.scenario_hash
        return full

    def flush(self) -> Path:
        self.out.mkdir(parents=True, exist_ok=True)
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=self.columns, lineterminator="\n")
        w.writeheader()
        for v in self.sweep.variants:
            if v.run in self.rows:
                w.writerow(self.rows[v.run])
        path = self.out / "results.csv"
        atomic_write(path, buf.getvalue().encode())
        self._last_csv = time.monotonic()
        self._dirty = False
        return path


def read_results(path) -> tuple[list[str], list[dict]]:
    """(columns, rows) of DIR/results.csv (or the file itself); SweepError when missing."""
    path = Path(path)
    if path.is_dir():
        path = path / "results.csv"
    if not path.is_file():
        raise SweepError(f"no sweep results at {str(path)!r} (cdpm sweep writes "
                         "DIR/results.csv)")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
        cols = list(reader.fieldnames or [])
    if "run" not in cols or "random_seed" not in cols or "status" not in cols:
        raise SweepError(f"{str(path)!r} is not a results.csv written by cdpm sweep (it has "
                         f"the columns {cols})")
    return cols, rows


def swept_fields(columns: list[str]) -> list[str]:
    """The swept field columns: between `run` and `random_seed` (docs/SWEEP_FORMAT.md)."""
    return columns[columns.index("run") + 1:columns.index("random_seed")]
