"""`cdpm export`: a log as CSV, one row per tick, one named column (with its unit) per
value."""

import sys
from pathlib import Path

from cdpm_drake.cli.arguments import check_writable_dir, is_sweep_dir
from cdpm_drake.cli.errors import CliError, InputError
from cdpm_drake.cli.recover import find_log


def cmd_export(args) -> int:
    """`cdpm export`: the log as CSV, to a file or stdout."""
    from cdpm_drake.views.log_csv import log_to_csv

    if is_sweep_dir(args.log):
        raise InputError(f"{str(args.log)!r} is a sweep's folder: its results.csv is the "
                         "table already (one row per run); export a run's log.npz")
    log, target = find_log(args.log, "export")
    text = log_to_csv(log)
    if args.out is not None and str(args.out) == "-":
        sys.stdout.write(text)
        return 0
    path = args.out if args.out is not None else (
        (target if target.is_dir() else target.parent) / "log.csv")
    if path.is_dir():
        raise CliError(f"--out {str(path)!r} is a folder; give a file name, e.g. "
                       f"{str(path / 'log.csv')!r}")
    check_writable_dir(path.parent if str(path.parent) else Path("."), "--out's folder")
    path.write_text(text)
    header = text.partition("\n")[0]  # names hold no commas
    print(f"csv: {path} ({text.count(chr(10)) - 1} rows, one per tick; "
          f"{header.count(',') + 1} columns)")
    return 0
