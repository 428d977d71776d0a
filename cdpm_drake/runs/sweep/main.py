"""The two commands: `cdpm sweep` (load, run, tabulate, draw) and `cdpm plot SWEEP_DIR`."""

import math
import sys
from pathlib import Path

from cdpm_drake.config import ScenarioError
from cdpm_drake.runs.sweep.cells import csv_cell
from cdpm_drake.runs.sweep.errors import SweepError
from cdpm_drake.runs.sweep.file import load_sweep_file
from cdpm_drake.runs.sweep.labels import UNIT_SCALE
from cdpm_drake.runs.sweep.metrics import METRICS, NUMERIC_METRICS, better_direction
from cdpm_drake.runs.sweep.results import columns_for, read_results
from cdpm_drake.runs.sweep.run import run_sweep
from cdpm_drake.runs.sweep.table import best_table, field_column, metric_value
from cdpm_drake.runs.sweep.variants import load_sweep


def sweep_main(*, sweep, out_dir=None, workers=None, ray=False, ray_address=None,
               ray_chunk=None, keep_logs=False, retry_errors=False, plot=None, metric=None,
               top=5, dry_run=False, progress=True, out=None, before_run=None,
               ray_init=None) -> int:
    """`cdpm sweep`: load and check every variant, run what is not done, write the results,
    print the best runs. Exit code 0 (all ok), 1 (some runs failed), 130/143 (SIGINT/SIGTERM:
    every finished row is kept)."""
    out = sys.stdout if out is None else out

    def warn(message, n):
        print(f"cdpm sweep: warning ({n} variant{'s' if n != 1 else ''}): {message}",
              file=sys.stderr)

    s = load_sweep(sweep, on_warning=warn)
    metric = metric or s.file.metric
    if metric not in NUMERIC_METRICS:
        raise SweepError(f"--metric {metric!r} is not a metric that ranks runs; valid "
                         f"metrics: {NUMERIC_METRICS}")
    out_dir = Path(out_dir) if out_dir is not None else Path("runs") / "sweeps" / s.file.name
    total_sim = sum(v.scenario.duration for v in s.variants)
    print(f"sweep {s.file.name!r} ({s.path}): {len(s.variants)} runs of {s.base.name!r}, "
          f"{total_sim:g} s simulated in all; fields: {', '.join(s.fields) or '-'}", file=out)
    if dry_run:
        from cdpm_drake.text import format_table
        table = ([("run", [v.run for v in s.variants])]
                 + [field_column(f, [csv_cell(v.values[f]) for v in s.variants])
                    for f in s.fields]
                 + [("random_seed", [v.random_seed for v in s.variants])])
        print(format_table([h for h, _ in table], list(zip(*[c for _, c in table]))),
              file=out)
        print(f"dry run: nothing ran; the results would go to {out_dir / 'results.csv'} "
              f"(each run's scenario.yaml under {out_dir / 'runs'}/)", file=out)
        return 0
    outcome = run_sweep(s, out_dir, workers=workers, ray=ray, ray_address=ray_address,
                        ray_chunk=ray_chunk, ray_init=ray_init, keep_logs=keep_logs,
                        retry_errors=retry_errors, progress=progress, before_run=before_run)
    ok = sum(r["status"] == "ok" for r in outcome.rows)
    errors = [r for r in outcome.rows if r["status"] != "ok"]
    faults = sum(r["status"] == "fault" for r in errors)
    print(f"{outcome.ran} run(s) done now"
          + (f" on {outcome.runner}" if outcome.runner else "")
          + f", {outcome.skipped} already done (resumed), in {outcome.wall_s:.1f} s wall; "
          f"{ok} ok, {faults} faulted, {len(errors) - faults} error(s); results: "
          f"{outcome.results}", file=out)
    for r in errors[:10]:
        print(f"  {r['status']} {r['run']}: {r['error']}", file=out)
    if len(errors) > 10:
        print(f"  ... and {len(errors) - 10} more (see the error column)", file=out)
    columns = columns_for(s)
    if ok:
        shown = UNIT_SCALE.get(METRICS[metric][0], (1.0, METRICS[metric][0]))[1]
        print(f"best runs by {metric} ({shown}, "
              f"{'largest' if better_direction(metric) == 'max' else 'smallest'} first):", file=out)
        print(best_table(columns, outcome.rows, metric, top), file=out)
    if plot is not None:  # the views hang off the CLI, which passes them in
        why = nothing_to_draw(outcome.rows, metric)
        if why:
            print(f"cdpm sweep: error: no pictures: {why}", file=sys.stderr)
            errors = errors or [why]
        else:
            for png in plot(columns, outcome.rows, out_dir, metric=metric):
                print(f"plot: {png}", file=out)
    if outcome.ending == "interrupted":
        print(f"cdpm sweep: interrupted; {len(outcome.rows)} finished row(s) kept in "
              f"{outcome.results}; rerun the same command to resume", file=sys.stderr)
        return 130
    if outcome.ending == "terminated":
        print(f"cdpm sweep: terminated; {len(outcome.rows)} finished row(s) kept in "
              f"{outcome.results}; rerun the same command to resume", file=sys.stderr)
        return 143
    return 1 if errors else 0


def plot_main(*, sweep_dir, plot, out_dir=None, metric=None, out=None) -> int:
    """`cdpm plot SWEEP_DIR`: the sweep's pictures (`plot`, views.sweep_plots.plot_sweep) and
    its best runs, from results.csv."""
    out = sys.stdout if out is None else out
    sweep_dir = Path(sweep_dir)
    columns, rows = read_results(sweep_dir)
    if metric is None:
        metric = "min_distance"
        try:
            metric = load_sweep_file(sweep_dir / "sweep.yaml")[0].metric
        except (SweepError, ScenarioError):
            pass
    why = nothing_to_draw(rows, metric)
    if why:  # no empty axes: say why there is no picture
        raise SweepError(f"{str(sweep_dir)!r}: no pictures: {why}")
    for png in plot(columns, rows, out_dir or sweep_dir, metric=metric):
        print(f"plot: {png}", file=out)
    if any(r["status"] == "ok" for r in rows):
        print(f"best runs by {metric}:", file=out)
        print(best_table(columns, rows, metric), file=out)
    return 0


def nothing_to_draw(rows: list[dict], metric: str) -> str:
    """Why a sweep's pictures of `metric` would have nothing to draw ("" when they would
    not): they show the rows that finished ok with a value of the metric."""
    if not rows:
        return "results.csv has no rows yet"
    ok = [r for r in rows if r.get("status") == "ok"]
    if not ok:
        faults = sum(r.get("status") == "fault" for r in rows)
        return (f"none of the {len(rows)} runs finished ok ({faults} faulted, "
                f"{len(rows) - faults} error(s): see the status and error columns of "
                "results.csv)")
    if not any(math.isfinite(metric_value(r, metric)) for r in ok):
        return (f"none of the {len(ok)} ok runs has a value of {metric} (see docs/"
                "SWEEP_FORMAT.md; e.g. crossings needs the interference block)")
    return ""
