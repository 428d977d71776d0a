"""`cdpm sweep`: the variants of a sweep file run on local processes or on Ray, into a
results table."""

import sys

from cdpm_drake.cli.arguments import check_writable_dir
from cdpm_drake.cli.errors import CliError


def cmd_sweep(args) -> int:
    """`cdpm sweep`: the runner options checked, then the sweep."""
    from cdpm_drake.runs.sweep import SweepError, sweep_main

    if args.workers is not None and args.workers < 1:
        raise CliError(f"--workers must be an integer >= 1, got {args.workers!r}")
    if args.ray_chunk is not None and args.ray_chunk < 1:
        raise CliError(f"--ray-chunk must be an integer >= 1, got {args.ray_chunk!r}")
    if args.top < 1:
        raise CliError(f"--top must be an integer >= 1, got {args.top!r}")
    if args.out is not None:
        check_writable_dir(args.out, "--out", keep=not args.dry_run)
    plot = None
    if args.plot:
        from cdpm_drake.views.sweep_plots import plot_sweep as plot
    try:
        return sweep_main(sweep=args.sweep, out_dir=args.out, workers=args.workers,
                          ray=args.ray is not None, ray_address=args.ray or None,
                          ray_chunk=args.ray_chunk, keep_logs=args.keep_logs,
                          retry_errors=args.retry_errors, plot=plot, metric=args.metric,
                          top=args.top, dry_run=args.dry_run, progress=not args.no_progress)
    except SweepError as e:  # a bad sweep file or variant: an error (1), as for scenarios
        print(f"cdpm sweep: error: {e}", file=sys.stderr)
        return 1
