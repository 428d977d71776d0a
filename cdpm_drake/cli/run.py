"""`cdpm run`: a scenario run in real time against the reel bridge (or the emulator), with
live status on stderr and the end report: timing, packets, and the cables' summary."""

import sys

from cdpm_drake.cli.arguments import (check_duration_arg, check_duration_tick, duration_flag,
                                      load_scenario_arg, new_run_folder)
from cdpm_drake.cli.errors import CliError
from cdpm_drake.cli.meshcat import live_meshcat
from cdpm_drake.cli.summaries import (model_monitor_summary, print_overload,
                                      print_pair_summary, safety_filter_summary)


def run_main(*, scenario, duration=None, out_dir=None, out=None, on_status=None,
             on_view=None, force=False, runs_root=None, overlay_text=None,
             plots=False, lockstep=None) -> int:
    """Run on the reels in real time; print live status and the end report. The folder
    policy is simulate_main's. Exit code 0 when the run completed, 1 on a fault or when it
    never enabled the reels, 130 / 143 when Ctrl-C / SIGTERM stopped it. `plots`: the
    log's figures into the run folder afterwards, as `cdpm simulate --plot`. `lockstep`: as
    realtime.run's."""
    from cdpm_drake.runs.interrupt import exit_code
    from cdpm_drake.runs.realtime import report_lines, run
    from cdpm_drake.config import resolve_scenario

    out = sys.stdout if out is None else out
    resolved = resolve_scenario(scenario)
    scenario = resolved.scenario
    variant, folder, out_dir = new_run_folder(resolved, out_dir, force=force,
                                              runs_root=runs_root, overlay_text=overlay_text)
    tty = sys.stderr.isatty()

    def status(line):
        if on_status is not None:
            on_status(line)
        print(("\r" + line) if tty else line, end="" if tty else "\n", file=sys.stderr,
              flush=True)

    try:
        result = run(scenario=resolved, out_dir=out_dir, duration=duration, status=status,
                     on_view=on_view, lockstep=lockstep)
    except BaseException:
        folder.discard()
        raise
    if result.log_path is None:
        folder.discard()  # it never enabled: nothing on disk, nothing in the way of the next
    else:
        folder.finish()
    if tty:
        print(file=sys.stderr)
    plant = scenario.plant
    where = (f" at {plant.address}:{plant.port}" if hasattr(plant, "address") else
             f", CAN interface {plant.interface} channel {plant.channel!r}"
             if hasattr(plant, "interface") else "")
    print(f"scenario {scenario.name!r} ({', '.join(variant)}{where})", file=out)
    for line in report_lines(result):
        print(line, file=out)
    if result.log and len(result.log["time"]):  # what the cables did, as simulate says it
        print_pair_summary(result.log, out)
        if "filter_status" in result.log:
            print(safety_filter_summary(result.log), file=out)
        if "model_status" in result.log:
            print(model_monitor_summary(result.log, scenario.model_monitor), file=out)
        print_overload(result.log, scenario, out)
        if plots and result.log_path is not None:
            _plot(result.log, out_dir, out)
    if result.ending == "fault":
        print(f"cdpm run: error: {result.error}", file=sys.stderr)
        if not result.enabled and any(why in str(result.error) for why in (
                "do not fit robot", "outside the workspace box", "cannot hold")):
            from cdpm_drake.config import scenario_names
            which = (scenario.name if scenario.name in scenario_names()
                     else "<this run's scenario file>")
            print("cdpm run: hint: against cdpm emulate, the emulator may be playing another "
                  "scenario or robot (other start, swaps or cables); start it with this run's: "
                  f"cdpm emulate --scenario {which} ...", file=sys.stderr)
        if not result.enabled and "fault bits" in str(result.error):
            print("cdpm run: hint: fault bits stay set until the bridge is reset (power "
                  "cycle; restart cdpm emulate); COMMAND_TIMEOUT is the bridge's own watchdog "
                  "after a controller that stopped while enabled (killed)", file=sys.stderr)
        return 1
    if result.ending == "interrupted":
        return exit_code(result.signal)
    return 0


def _plot(log, out_dir, out) -> None:
    """The log's figures beside it; a log the figures cannot read is said, not raised (the
    run's exit code is the run's)."""
    from cdpm_drake.runs.log import LogError
    from cdpm_drake.views.plots import plot_log

    try:
        for png in plot_log(log, out_dir):
            print(f"plot: {png}", file=out)
    except LogError as e:
        print(f"cdpm run: error: plots: {e}", file=sys.stderr)


def cmd_run(args) -> int:
    """`cdpm run`: the options checked (and the priority set) before the run, then
    run_main."""
    check_duration_arg(args.duration)
    if args.rt_priority:
        from cdpm_drake.hardware.priority import PriorityError, set_realtime_priority
        try:
            set_realtime_priority(args.rt_priority)
        except (PriorityError, ValueError) as e:
            raise CliError(f"--rt-priority {args.rt_priority!r}: {e}") from None
    scenario = load_scenario_arg(args)
    check_duration_tick(args.duration, scenario)
    on_view = live_meshcat(scenario) if args.meshcat else None
    with duration_flag(args.duration):
        return run_main(scenario=scenario, duration=args.duration, out_dir=args.out,
                        on_view=on_view, force=args.force,
                        overlay_text=args.scenario_text, plots=args.plot,
                        lockstep=True if args.lockstep else None)
