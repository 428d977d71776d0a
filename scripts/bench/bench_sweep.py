"""Sweep throughput: simulated seconds per wall second with 1 worker, with every core, and on a
local Ray; the scaling efficiency; Ray's per-task overhead; the projected wall time of 1000
runs of experiment 2 (30 s each) here and per added core.

    .venv/bin/python scripts/bench/bench_sweep.py [--runs-per-core 4] [--duration 10] [--no-ray]

Every configuration runs the same variants of experiment 2 (F_u spread over [2, 4] N, the
first `--duration` s of the push) through cdpm_drake.runs.sweep's runners, the code `cdpm sweep`
uses. Worker start-up (spawn, import pydrake) is paid once per sweep; it is measured apart
(a warm-up round of 0.05 s runs) and left out of the throughput, which is the steady state a
long sweep sees. The reference of every ratio is the 1-worker run of the same invocation.
Timings on a shared machine are noisy; run it on a quiet one for numbers to quote.
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from cdpm_drake.runs import sweep as sw  # noqa: E402
from cdpm_drake.text import format_table  # noqa: E402

EXP2_RUNS, EXP2_DURATION = 1000, 30.0


def _sweep(tmp: Path, runs: int, duration: float, name: str) -> sw.Sweep:
    path = tmp / f"{name}.yaml"
    values = ", ".join(f"{2.0 + 2.0 * k / max(1, runs - 1):.6f}" for k in range(runs))
    path.write_text(f"name: {name}\nbase: exp2_interaction\noverlay: {{duration: {duration}}}\n"
                    f"axes: [{{field: interference.default.F_u, values: [{values}]}}]\n")
    return sw.load_sweep(path)


def _timed(runner, tasks) -> tuple[float, list[dict]]:
    rows = []
    start = time.perf_counter()
    runner.run(tasks, rows.append, lambda: False)
    wall = time.perf_counter() - start
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"bench_sweep: a run failed: {bad[0]['error']}")
    return wall, rows


def measure_local(workers, warm, tasks):
    runner = sw.LocalRunner(workers)
    try:
        start = time.perf_counter()
        _timed(runner, warm[:workers])  # spawn + import + one tiny run per worker
        startup = time.perf_counter() - start
        wall, rows = _timed(runner, tasks)
    finally:
        runner.close()
    return startup, wall, rows


def measure_ray(cpus, warm, tasks, chunk=None):
    import ray

    start = time.perf_counter()
    ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False)
    try:
        runner = sw.RayRunner(chunk=1)
        _timed(runner, warm[:cpus])  # Ray's workers import cdpm_drake on their first task
        startup = time.perf_counter() - start

        @ray.remote
        def noop(x):
            return x

        ray.get(noop.remote(0))
        n = 200
        t0 = time.perf_counter()
        for k in range(n):
            ray.get(noop.remote(k))
        round_trip = (time.perf_counter() - t0) / n
        runner = sw.RayRunner(chunk=chunk)
        wall, rows = _timed(runner, tasks)
        stats = runner.task_stats
    finally:
        ray.shutdown()
    return startup, wall, rows, round_trip, stats


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs-per-core", type=int, default=4,
                        help="runs per core in each configuration (default 4)")
    parser.add_argument("--duration", type=float, default=10.0,
                        help="simulated seconds per run (default 10: the first 10 s of exp2)")
    parser.add_argument("--workers", type=int, default=sw.default_workers(),
                        help="'every core' (default: the cores this process may use)")
    parser.add_argument("--no-ray", action="store_true", help="skip the Ray measurement")
    args = parser.parse_args(argv)
    cores = max(1, args.workers)
    runs = max(cores, args.runs_per_core * cores)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        tasks = sw.tasks_for(_sweep(tmp, runs, args.duration, "bench").variants)
        warm = sw.tasks_for(_sweep(tmp, cores, 0.05, "warm").variants)
    sim = runs * args.duration
    print(f"{runs} runs of experiment 2, {args.duration:g} s simulated each ({sim:g} s in all); "
          f"{cores} cores (os.cpu_count() = {os.cpu_count()})")

    results = {}
    results["1 worker"] = (1,) + measure_local(1, warm, tasks)
    if cores > 1:
        results[f"{cores} workers"] = (cores,) + measure_local(cores, warm, tasks)
    ray_extra = None
    if not args.no_ray:
        try:
            import ray  # noqa: F401
        except ImportError:
            print("(ray is not installed: pip install -e '.[ray]'; skipping Ray)")
        else:
            startup, wall, rows, round_trip, stats = measure_ray(cores, warm, tasks)
            results[f"Ray, {cores} CPUs"] = (cores, startup, wall, rows)
            ray_extra = (round_trip, stats)

    ref = sim / results["1 worker"][2]
    table = []
    for name, (n, startup, wall, rows) in results.items():
        thr = sim / wall
        per_run = sum(r["wall_s"] for r in rows) / len(rows)
        cpu = sum(r["_cpu_s"] for r in rows)
        table.append([name, f"{startup:.2f}", f"{wall:.2f}", f"{thr:.2f}", f"{thr / ref:.2f}",
                      f"{100 * thr / (n * ref):.0f} %", f"{per_run:.3f}",
                      f"{cpu / len(rows):.3f}", f"{100 * cpu / (n * wall):.0f} %"])
    print(format_table(["runner", "start-up (s)", "wall (s)", "sim s / wall s",
                        "x 1 worker", "efficiency", "mean run (s)", "run CPU (s)",
                        "CPU busy"], table))
    print("efficiency = throughput / (workers x the 1-worker throughput), goal >= 90 % for "
          "1 -> 2 workers; CPU busy = CPU seconds of the runs / (workers x wall): well below "
          "100 % with an unchanged run CPU means other processes had the cores")

    if ray_extra is not None:
        round_trip, stats = ray_extra
        local_n = results[f"{cores} workers" if cores > 1 else "1 worker"]
        ray_wall = results[f"Ray, {cores} CPUs"][2]
        task_s = [s for _, s in stats]
        mean_task = sum(task_s) / len(task_s)
        per_task = [n for n, _ in stats]
        print(f"Ray: {len(stats)} tasks of {min(per_task)}-{max(per_task)} runs, "
              f"{mean_task:.2f} s of compute each; an empty task's round trip is "
              f"{1000 * round_trip:.2f} ms = {100 * round_trip / mean_task:.2f} % of a task "
              f"(goal < 5 %); Ray against {cores} local processes on the same runs: "
              f"{100 * (ray_wall / local_n[2] - 1):+.1f} % wall time")

    # Projection: 1000 runs of the full experiment 2 (30 s each). From the measured wall-clock
    # throughput per core and efficiency (assumed to hold past the cores measured here), and
    # from the runs' CPU time, which a busy machine does not inflate: what a quiet one gives.
    best_local = results[f"{cores} workers" if cores > 1 else "1 worker"]
    eff = (sim / best_local[2]) / (cores * ref)
    cpu_1 = sum(r["_cpu_s"] for r in results["1 worker"][3]) / sim  # CPU s per simulated s
    cpu_n = sum(r["_cpu_s"] for r in best_local[3]) / sim
    cpu_eff = min(1.0, cpu_1 / cpu_n)
    total = EXP2_RUNS * EXP2_DURATION
    print(f"\nrun CPU per simulated second: {cpu_1:.3f} s on 1 worker, {cpu_n:.3f} s on "
          f"{cores} (CPU-time efficiency {100 * cpu_1 / cpu_n:.0f} %: parallel runs cost no "
          "more CPU when this is ~100 %)")
    print(f"projected wall time of {EXP2_RUNS} runs of experiment 2 ({EXP2_DURATION:g} s "
          f"each, {total:g} s simulated): from the measured wall time ({ref:.2f} sim s / "
          f"wall s per core, {100 * eff:.0f} % efficiency past one core), and from the runs' "
          f"CPU time (a quiet machine, {100 * cpu_eff:.0f} % efficiency):")
    rows = []
    previous = None
    for k in sorted({1, 2, cores, 4, 8, 16, 32, 64}):
        wall = total / (ref * k * (eff if k > 1 else 1.0))
        quiet = total * cpu_1 / (k * (cpu_eff if k > 1 else 1.0))
        saved = "" if previous is None else f"{(previous[1] - quiet) / (k - previous[0]) / 60:.1f}"
        rows.append([f"{k}{' (here)' if k == cores else ''}", f"{wall / 3600:.2f}",
                     f"{quiet / 3600:.2f}", saved])
        previous = (k, quiet)
    print(format_table(["cores", "measured (h)", "from CPU time (h)",
                        "each added core saves (min, CPU-time column)"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
