"""`cdpm export`: a log as CSV (one row per tick, one named column with its unit per value),
as a MATLAB .mat file (every key, with its unit) or as a ROS 2 bag in MCAP storage (joint
states, poses, wrenches, cable markers)."""

import sys
from pathlib import Path

from cdpm_drake.cli.arguments import check_writable_dir, is_sweep_dir
from cdpm_drake.cli.errors import CliError, InputError
from cdpm_drake.cli.recover import find_log

# Format: (default file name beside the log, the package it needs beyond the base install).
FORMATS = {"csv": ("log.csv", None), "mat": ("log.mat", None),
           "mcap": ("log.mcap", "rosbags")}
EXTRA = "pip install 'cdpm_drake[export]'"


def export_format(args) -> str:
    """The format asked for: csv (the default), mat or mcap."""
    return "mat" if args.mat else "mcap" if args.mcap else "csv"


def _check_package(fmt: str) -> None:
    """InputError naming the install command when the format's writer is not installed."""
    import importlib.util

    package = FORMATS[fmt][1]
    if package is not None and importlib.util.find_spec(package) is None:
        raise InputError(f"--{fmt} needs the {package} package, which is not installed: "
                         f"{EXTRA} (or pip install -e '.[export]' in a clone)")


def _out_path(args, fmt: str, target: Path) -> Path:
    """The file to write: --out, else the format's name beside the log; a usage error
    (exit 2) when it is a folder or its folder cannot be written."""
    path = args.out if args.out is not None else (
        (target if target.is_dir() else target.parent) / FORMATS[fmt][0])
    if path.is_dir():
        raise CliError(f"--out {str(path)!r} is a folder; give a file name, e.g. "
                       f"{str(path / FORMATS[fmt][0])!r}")
    check_writable_dir(path.parent if str(path.parent) else Path("."), "--out's folder")
    return path


def cmd_export(args) -> int:
    """`cdpm export`: the log as CSV (to a file or stdout), .mat or .mcap."""
    fmt = export_format(args)
    if is_sweep_dir(args.log):
        raise InputError(f"{str(args.log)!r} is a sweep's folder: its results.csv is the "
                         "table already (one row per run); export a run's log.npz")
    if fmt != "csv" and args.out is not None and str(args.out) == "-":
        raise CliError(f"--out - (stdout) is for --csv only; --{fmt} writes a binary file: "
                       "give a file name")
    _check_package(fmt)
    log, target = find_log(args.log, "export")
    if fmt == "csv" and args.out is not None and str(args.out) == "-":
        from cdpm_drake.views.log_csv import log_to_csv

        sys.stdout.write(log_to_csv(log))
        return 0
    _check_log(log, fmt, target)  # before --out's folder is made: a refusal leaves nothing
    path = _out_path(args, fmt, target)
    if fmt == "csv":
        _write_csv(log, path)
    elif fmt == "mat":
        _write_mat(log, path)
    else:
        _write_mcap(log, path)
    return 0


def _check_log(log, fmt: str, target: Path) -> None:
    """InputError (exit 1) naming the key when the format cannot be written of this log."""
    from cdpm_drake.views.log_mat import MatExportError, log_to_mat_dict
    from cdpm_drake.views.log_mcap import McapExportError, check_mcap_keys

    try:
        if fmt == "mat":
            log_to_mat_dict(log)
        elif fmt == "mcap":
            check_mcap_keys(log)
    except (MatExportError, McapExportError) as e:
        raise InputError(f"{str(target)!r}: {e}") from None


def _write_csv(log, path: Path) -> None:
    from cdpm_drake.views.log_csv import log_to_csv

    text = log_to_csv(log)
    path.write_text(text)
    header = text.partition("\n")[0]  # names hold no commas
    print(f"csv: {path} ({text.count(chr(10)) - 1} rows, one per tick; "
          f"{header.count(',') + 1} columns)")


def _write_mat(log, path: Path) -> None:
    from cdpm_drake.views.log_mat import write_log_mat

    write_log_mat(log, path)
    print(f"mat: {path} ({len(log)} log keys, each with its unit in the struct `units`; "
          f"{len(log['time'])} ticks; `cables` 1..{len(log['reels'])}); in MATLAB: "
          f"load('{path.name}')")


def _write_mcap(log, path: Path) -> None:
    from cdpm_drake.views.log_mcap import joint_efforts, write_log_mcap

    counts = write_log_mcap(log, path)
    _, effort = joint_efforts(log)
    print(f"mcap: {path} (a ROS 2 bag, {len(counts)} topics, {next(iter(counts.values()))} "
          f"messages each, one per tick, stamped from 0 s; joint effort: "
          f"{effort or 'none (no tensions logged)'}); open it in Foxglove or "
          "`ros2 bag info`")
