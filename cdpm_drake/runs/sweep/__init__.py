"""Sweeps: many variants of one scenario, run on every core or on a Ray cluster, tabulated.

A sweep file (docs/SWEEP_FORMAT.md) names a base scenario, an optional overlay, and axes
(a grid), random samples, explicit overlays and seeds. Each variant is a full scenario: the base
with YAML overlays applied through the scenario's own schema check, `yaml_load_typed` and
`check_scenario`, and run by `simulation.simulate` (the same `build_diagram` and Drake
Simulator as `cdpm simulate`). Every variant is resolved before the first run, so a bad field
or value stops the sweep before it starts, naming the variant.

Results go to DIR/results.csv (one row per run, rewritten atomically as runs finish) and
DIR/runs/<run>/ (the resolved scenario.yaml, row.json, and log.npz with keep_logs). A rerun
skips the rows whose run id and resolved-scenario hash are already there.

The modules, in the order a sweep uses them: `file` (the sweep file), `fields` (field paths
and the overlay on a scenario), `variants` (the expansion, each variant resolved), `run_task`
(one run in a worker) and `metrics` (what a run's log gives), `local_runner` and `ray_runner`,
`results` (results.csv and the run folders) and `lock`, `run` (run_sweep), `labels` and
`table` (units, the best runs), `main` (the commands). This package re-exports what the rest of
cdpm_drake, the tests and the scripts use; the modules import each other directly.
"""

from cdpm_drake.runs.sweep.errors import SweepError
from cdpm_drake.runs.sweep.file import Axis, axis_values, sweep_names
from cdpm_drake.runs.sweep.labels import UNIT_SCALE, field_axis
from cdpm_drake.runs.sweep.local_runner import LocalRunner, default_workers
from cdpm_drake.runs.sweep.lock import acquire_lock, release_lock
from cdpm_drake.runs.sweep.main import nothing_to_draw, plot_main, sweep_main
from cdpm_drake.runs.sweep.metrics import METRICS, NUMERIC_METRICS, run_metrics
from cdpm_drake.runs.sweep.ray_runner import RayRunner
from cdpm_drake.runs.sweep.results import columns_for, swept_fields
from cdpm_drake.runs.sweep.run import run_sweep
from cdpm_drake.runs.sweep.run_task import execute_run, tasks_for
from cdpm_drake.runs.sweep.table import best_table, metric_value
from cdpm_drake.runs.sweep.variants import Sweep, load_sweep

__all__ = [
    "Axis", "LocalRunner", "METRICS", "NUMERIC_METRICS", "RayRunner", "Sweep", "SweepError",
    "UNIT_SCALE", "acquire_lock", "axis_values", "best_table", "columns_for",
    "default_workers", "execute_run", "field_axis", "load_sweep", "metric_value",
    "nothing_to_draw", "plot_main", "release_lock", "run_metrics", "run_sweep", "swept_fields",
    "sweep_main", "sweep_names", "tasks_for",
]
