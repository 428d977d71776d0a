"""`cdpm plot`: a log's figures (the paper's Figs. 8-16) as PNGs and, asked, its HTML
replay; given a sweep's folder, the sweep's pictures from its results.csv."""

import sys
from pathlib import Path

from cdpm_drake.cli.arguments import check_html, check_writable_dir, is_sweep_dir
from cdpm_drake.cli.meshcat import save_replay
from cdpm_drake.cli.recover import find_log


def cmd_plot(args) -> int:
    """`cdpm plot`: a log's figures and replay, or a sweep's pictures."""
    from cdpm_drake.views.plots import plot_log

    if is_sweep_dir(args.log):
        return _plot_sweep(args)
    log, target = find_log(args.log, "plot")
    if args.out is not None:
        check_writable_dir(args.out, "--out")
    check_html(args.html)
    out_dir = args.out if args.out is not None else (
        target if target.is_dir() else target.parent)
    only = None
    if args.html is not None:
        # Asked for the replay: the figures already drawn from this log stay as they are;
        # only those missing (or older than the log) are drawn.
        from cdpm_drake.views.plots import FIGURE_FILES, figures_of
        log_file = target / "log.npz" if target.is_dir() else target
        only = [name for name in figures_of(log)
                if _older(Path(out_dir) / FIGURE_FILES[name], log_file)]
        kept = len(figures_of(log)) - len(only)
        if kept:
            print(f"plot: {kept} figure(s) already drawn from this log kept in {out_dir}")
    from cdpm_drake.runs.log import nan_rows
    for warning in nan_rows(log):
        print(f"cdpm plot: warning: {warning}", file=sys.stderr)
    for png in plot_log(log, out_dir, only=only):
        print(f"plot: {png}")
    if args.html is not None:
        print(f"3D replay: {save_replay(log, args.html)} (open it in a browser)")
    return 0


def _older(path: Path, than: Path) -> bool:
    """Whether `path` is missing or was written before `than` (a figure before its log)."""
    try:
        return path.stat().st_mtime < than.stat().st_mtime
    except OSError:
        return True


def _plot_sweep(args) -> int:
    from cdpm_drake.runs.sweep import SweepError, plot_main
    from cdpm_drake.views.sweep_plots import plot_sweep

    if args.out is not None:
        check_writable_dir(args.out, "--out")
    try:
        return plot_main(sweep_dir=args.log, plot=plot_sweep, out_dir=args.out)
    except SweepError as e:  # a bad sweep file or results: an error (1), as for scenarios
        print(f"cdpm plot: error: {e}", file=sys.stderr)
        return 1
