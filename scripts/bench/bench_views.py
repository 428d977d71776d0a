"""Benchmark of the views (figures, replay, Meshcat): what looking at a run costs next to making
it. One scenario (experiment 2 by default, its full 30 s) is simulated once; then, in the same
process, each view is made from its log: every figure of `cdpm plot` (PNG at 120 dpi), the
HTML replay at 50 frames/s (its size too), the live Meshcat view's construction (the static
scene with its text meshes) and one live frame (`draw`, the per-chunk cost of `--meshcat`).
Ratios are against the simulation's wall time, measured in the same run.

With --repeat N each view runs N times and keeps its fastest run (the least disturbed by other
load on the machine).

Usage: python scripts/bench/bench_views.py [--scenario exp2_interaction] [--duration S] [--repeat 1]
       [--fps 50]
"""

import argparse
import logging
import tempfile
import time
from pathlib import Path

from cdpm_drake.config import load_scenario
from cdpm_drake.runs.simulate import simulate
from cdpm_drake.text import format_table
from cdpm_drake.views import meshcat_view, plots
from cdpm_drake.views.figure_keys import OPTIONAL, has_keys


def fastest(repeat: int, work) -> float:
    """Fewest wall-clock seconds of `work()` over `repeat` runs."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        work()
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="exp2_interaction")
    parser.add_argument("--duration", type=float, default=None,
                        help="s of simulated time (default: the scenario's)")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--fps", type=float, default=50.0)
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error(f"--repeat must be an integer >= 1, got {args.repeat!r}")
    logging.getLogger("drake").setLevel(logging.WARNING)

    scenario = load_scenario(args.scenario)
    result = simulate(scenario=scenario, duration=args.duration)
    if result.error is not None:
        raise SystemExit(f"the simulation failed: {result.error}")
    log, reference = result.log, result.wall_time
    ticks = len(log["time"])
    meshcat = meshcat_view.make_meshcat(port=0)
    rows = [("simulation (reference)", f"{reference:.3f}", "1.00", f"{ticks} ticks")]

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for name, make in plots.FIGURES.items():
            if name in OPTIONAL and not has_keys(log, name):
                continue
            seconds = fastest(args.repeat, lambda: make(log).savefig(out / f"{name}.png",
                                                                     dpi=120))
            rows.append((f"figure {name}", f"{seconds:.3f}", f"{seconds / reference:.2f}",
                         f"{(out / f'{name}.png').stat().st_size / 1e3:.0f} kB"))
        html = out / "replay.html"
        seconds = fastest(args.repeat, lambda: meshcat_view.save_replay_html(
            log, html, meshcat=meshcat, fps=args.fps))
        frames = len(meshcat_view.replay_frames(log["time"], args.fps)[0])
        rows.append((f"HTML replay, {args.fps:g} frames/s", f"{seconds:.3f}",
                     f"{seconds / reference:.2f}",
                     f"{frames} frames, {html.stat().st_size / 1e6:.2f} MB"))

    view = None

    def build():
        nonlocal view
        view = meshcat_view.CdpmMeshcatView.from_log(meshcat, log)

    seconds = fastest(args.repeat, build)
    rows.append(("live view: build the scene", f"{seconds:.3f}", f"{seconds / reference:.2f}",
                 ""))
    k = ticks // 2
    n = 200
    seconds = fastest(args.repeat, lambda: [view.draw_row(log, k + (j % 2)) for j in range(n)])
    rows.append(("live view: one frame (draw)", f"{seconds / n * 1e3:.3f} ms",
                 f"{seconds / n / reference:.5f}", "alternating two ticks"))

    print(f"scenario {scenario.name!r}, {log['time'][-1]:.1f} s simulated; fastest of "
          f"{args.repeat} run(s); ratio = view time / simulation time")
    print(format_table(("what", "wall (s)", "ratio", "size"), rows))


if __name__ == "__main__":
    main()
