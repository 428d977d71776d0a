"""`cdpm simulate`: a scenario simulated with Drake's Simulator into a run folder, its log
summarised; optionally paced, drawn live in Meshcat, plotted and saved as an HTML replay."""

import sys

import numpy as np

from cdpm_drake.cli.arguments import (check_duration_arg, check_duration_tick, check_html,
                                      duration_flag, load_scenario_arg, new_run_folder)
from cdpm_drake.cli.errors import CliError
from cdpm_drake.cli.meshcat import live_meshcat, save_replay
from cdpm_drake.cli.summaries import (model_monitor_summary, print_overload,
                                      print_clipped, print_dynamic_summary,
                                      print_pair_summary, safety_filter_summary,
                                      tension_control_summary)


def simulate_main(*, scenario, duration=None, out_dir=None, progress=True, out=None,
                  on_chunk=None, html=None, plots=False, realtime_rate=None,
                  chunk=0.5, force=False, runs_root=None, overlay_text=None) -> int:
    """Simulate, write DIR/log.npz and DIR/scenario.yaml, print a summary. DIR is `out_dir`
    if given (it must be empty, or hold a run and `force` be set), else a new
    runs/<name>/<UTC timestamp>/ (run_folder.py). Returns an exit code: 0; 1 when the run
    ended on an error; 130 / 143 after Ctrl-C / SIGTERM (the log up to then is written all the
    same, and the plots and replay asked for)."""
    from cdpm_drake.config import resolve_scenario
    from cdpm_drake.runs.log import save_log
    from cdpm_drake.runs.simulate import simulate

    out = sys.stdout if out is None else out
    resolved = resolve_scenario(scenario)
    scenario = resolved.scenario
    variant, folder, out_dir = new_run_folder(resolved, out_dir, force=force,
                                              runs_root=runs_root, overlay_text=overlay_text)
    try:
        result = simulate(scenario=resolved, duration=duration, progress=progress,
                          on_chunk=on_chunk, realtime_rate=realtime_rate, chunk=chunk)
    except BaseException:
        folder.discard()  # an early error (bad scenario, bad plant) leaves no folder
        raise
    log = result.log
    path = save_log(log, out_dir, resolved)
    folder.finish()
    T = log["time"].size
    print(f"scenario {scenario.name!r} ({', '.join(variant)}): {T} ticks, "
          f"{log['time'][-1] if T else 0:.3f} s simulated "
          f"in {result.wall_time:.2f} s wall ({result.realtime_factor:.1f}x real time)", file=out)
    print_pair_summary(log, out)
    print_clipped(log, scenario, out)
    if T and "tension_status" in log:  # controller.tension_control
        print(tension_control_summary(log), file=out)
    if T and "filter_status" in log:  # safety_filter.enabled
        print(safety_filter_summary(log), file=out)
    if T and "model_status" in log:  # model_monitor.enabled
        print(model_monitor_summary(log, scenario.model_monitor), file=out)
    if T and "tensions" in log:  # the dynamic plant's ground truth
        print_dynamic_summary(log, out)
    if T:
        print_overload(log, scenario, out)
    print(f"log: {path}", file=out)
    # A second Ctrl-C / SIGTERM while the outputs are written must not lose them: the first
    # one already decided the exit code.
    with _signals_ignored(result.error is not None):
        if plots:
            from cdpm_drake.runs.log import LogError
            from cdpm_drake.views.plots import plot_log
            try:
                for png in plot_log(log, out_dir):
                    print(f"plot: {png}", file=out)
            except LogError as e:  # the log is written; say why the figures are not
                print(f"cdpm simulate: error: plots: {e}", file=sys.stderr)
                return 1
        if html is not None:
            print(f"3D replay: {save_replay(log, html)} (open it in a browser)", file=out)
    stopped = f"t = {log['time'][-1] if T else 0:.3f} s"
    if isinstance(result.error, KeyboardInterrupt):
        from cdpm_drake.runs.interrupt import Terminated, exit_code
        what = "SIGTERM" if isinstance(result.error, Terminated) else "Ctrl-C"
        print(f"cdpm simulate: interrupted at {stopped} ({what}); the log up to there is "
              "written", file=sys.stderr)
        return exit_code(result.error)
    if result.error is not None:
        cause = f"; {result.diagnosis}" if result.diagnosis else ""
        print(f"cdpm simulate: error: the run stopped at {stopped}: {result.error}{cause}",
              file=sys.stderr)
        return 1
    return 0


class _signals_ignored:
    """Ignore SIGINT and SIGTERM within the block, if `active` (and in the main thread)."""

    def __init__(self, active: bool):
        self._active = active
        self._previous = {}

    def __enter__(self):
        import signal
        import threading
        if self._active and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, signal.SIG_IGN)
        return self

    def __exit__(self, *exc):
        import signal
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def cmd_simulate(args) -> int:
    """`cdpm simulate`: the options checked before the run, then simulate_main."""
    check_duration_arg(args.duration)
    on_chunk = None
    realtime = args.realtime
    if realtime is not None and not (realtime > 0 and np.isfinite(realtime)):
        raise CliError(f"--realtime must be a rate > 0 (1: real time), got {realtime!r}")
    scenario = load_scenario_arg(args)
    check_duration_tick(args.duration, scenario)
    check_html(args.html)
    if args.meshcat:
        on_chunk = live_meshcat(scenario)
        # Something to watch: paced at real time unless told otherwise.
        realtime = 1.0 if realtime is None else realtime
    with duration_flag(args.duration):
        code = simulate_main(scenario=scenario, duration=args.duration, out_dir=args.out,
                             progress=not args.no_progress, on_chunk=on_chunk,
                             html=args.html, plots=args.plot, realtime_rate=realtime,
                             chunk=0.04 if args.meshcat else 0.5, force=args.force,
                             overlay_text=args.scenario_text)
    if args.meshcat and not args.no_wait and sys.stdin.isatty():
        try:
            input("Meshcat is still serving the last frame; press Enter to quit. ")
        except EOFError:
            pass
    return code
