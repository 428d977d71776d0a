"""The lock of a sweep's output directory: one sweep writes it at a time."""

import os
import time
from pathlib import Path

from cdpm_drake.runs.sweep.errors import SweepError


LOCK_FILE = ".sweep.lock"


def acquire_lock(out_dir: Path):
    """An exclusive lock on DIR/.sweep.lock, which says who holds it (pid, start time): two
    sweeps writing one directory would run the same variants twice and race on results.csv.
    The file exists only while a sweep runs (`release_lock` removes it)."""
    path = out_dir / LOCK_FILE
    while True:
        f = open(path, "a+")
        try:
            import fcntl
        except ImportError:  # not POSIX: no lock
            return f
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.seek(0)
            holder = f.read().strip()
            f.close()
            raise SweepError(f"--out {str(out_dir)!r} is in use by another cdpm sweep"
                             + (f" ({holder})" if holder else "")
                             + "; wait for it or give another --out") from None
        # A sweep that finished between our open and our lock removed the file we hold:
        # lock the one at the path now, or a third sweep could take that one alongside.
        try:
            current = os.stat(path).st_ino == os.fstat(f.fileno()).st_ino
        except FileNotFoundError:
            current = False
        if current:
            f.seek(0)
            f.truncate()
            f.write(f"pid {os.getpid()}, since {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
            f.flush()
            return f
        f.close()


def release_lock(f, out_dir: Path) -> None:
    """Remove DIR/.sweep.lock while still holding it (a sweep waiting for it then finds it
    gone and takes a new one), then release it."""
    try:
        (out_dir / LOCK_FILE).unlink(missing_ok=True)
    finally:
        f.close()
