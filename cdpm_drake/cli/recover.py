"""`cdpm recover`: a killed run's tick stream (ticks.bin) turned into its log.npz; and the
LOG argument of `cdpm plot` and `cdpm export`, found (a run folder, runs/<name>) and
recovered first when the run was killed before writing its log."""

import sys
from pathlib import Path

from cdpm_drake.cli.errors import InputError


def find_log(path: Path, command: str):
    """(the log, the run folder or .npz it came from) for a command's LOG argument: a
    log.npz, its run folder, runs/<name> (its latest run); a folder with only ticks.bin is
    recovered first."""
    from cdpm_drake.runs.run_folder import resolve_latest
    from cdpm_drake.runs.log import LogError, load_log

    target = resolve_latest(path)
    if target.is_dir() and not (target / "log.npz").exists() and (target / "ticks.bin").exists():
        print(f"cdpm {command}: {str(target)!r} has ticks.bin but no log.npz (the run was "
              "killed before converting it): recovering first", file=sys.stderr)
        recover_log(target)
    try:
        return load_log(target), target
    except LogError as e:
        raise InputError(str(e)) from None


def recover_log(run_dir, out=None) -> None:
    """Recover `run_dir`'s log.npz from its ticks.bin and say what was kept on `out` (stderr
    by default)."""
    from cdpm_drake.runs.realtime import RecoverError, recover

    out = sys.stderr if out is None else out
    try:
        path, tail = recover(run_dir)
    except RecoverError as e:
        raise InputError(str(e)) from None
    cut = (f"the tail was cut: a partial last row of {tail['cut_bytes']} bytes left out"
           if tail["cut_bytes"] else "the tail was whole (no partial row)")
    damaged = tail.get("damaged", 0)
    if damaged:  # rows the file's damage garbled: said, never passed as data
        rows = tail["damaged_ticks"]
        shown = ", ".join(str(k) for k in rows[:5]) + (", ..." if len(rows) > 5 else "")
        cut += (f"; but {damaged} of the {tail['ticks']} rows are DAMAGED (tick counter, "
                f"clock or position/force/lengths unreadable: rows {shown}), kept as read "
                "(NaN or wrong values there): the file was damaged, not only cut short")
    print(f"recovered {tail['ticks']} ticks of {tail['expected']} ({tail['ending']}); {cut}; "
          f"log: {path}", file=out)


def cmd_recover(args) -> int:
    """`cdpm recover`: a run folder (or runs/<name>'s latest run) recovered."""
    from cdpm_drake.runs.run_folder import resolve_latest

    recover_log(resolve_latest(args.run_dir), out=sys.stdout)
    return 0
