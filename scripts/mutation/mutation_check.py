"""Mutation check: does the test suite catch plausible one-line bugs?

Each mutant (scripts/mutation/mutants/, a module per layer) is (name, file, exact original snippet, replacement, reason, test files most
likely to kill it). For each, the tree is copied to a temporary directory (never the working
tree: every worker owns its own copy, and a mutant is undone there in a `finally`), the
snippet is replaced, and `pytest -x -q` runs first on the mutant's own test files, then, if
they all pass, on the rest of the suite. A failing run means the mutant is KILLED; a green
suite means it SURVIVED. A mutant whose original snippet is not found exactly once is STALE:
the code moved and its mutants module must be updated (a STALE mutant counts as a failure).

    python scripts/mutation/mutation_check.py            # all mutants, one worker
    python scripts/mutation/mutation_check.py --jobs 2   # two workers (two tree copies)
    python scripts/mutation/mutation_check.py --list     # the list, and which are stale
    python scripts/mutation/mutation_check.py --only admittance_mass_damping_swapped

Prints a table (mutant, result, where it was killed, seconds) and the score killed / total.
Exit code 0 when every mutant is killed, 1 otherwise. Refresh a stale mutant when its code
moves: keep the snippets short and on lines likely to stay.
"""

import argparse
import concurrent.futures
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# What a copy of the tree needs to run the suite (the package, the robot files, the tests and
# the files tests read); not the virtual environment, git, caches or run outputs.
COPY = ("cdpm_drake", "hardware", "tests", "scripts", "docs", "diagrams",
        "README.md", "pyproject.toml")
_IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", ".pytest_cache", "*.egg-info")


def IGNORE(folder, names):
    """What copytree leaves out: caches, and run outputs (a `runs` folder of run folders); not
    the package cdpm_drake/runs or the tests' tests/runs, which hold Python files."""
    skip = set(_IGNORE(folder, names))
    if "runs" in names and not any(Path(folder, "runs").glob("*.py")):
        skip.add("runs")
    return skip
# One pytest run may not take longer than this (a mutant that hangs the suite is killed).
TIMEOUT = 900.0


sys.path.insert(0, str(Path(__file__).resolve().parent))
from mutant import Mutant  # noqa: E402
from mutants import MUTANTS  # noqa: E402


def _check_unique_names():
    names = [m.name for m in MUTANTS]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise SystemExit(f"duplicate mutant names: {dupes}")


def stale_reason(mutant: Mutant, root: Path = ROOT) -> str | None:
    """None when the mutant applies (its snippet occurs exactly once), else why not."""
    path = root / mutant.file
    if not path.is_file():
        return f"{mutant.file} does not exist"
    n = path.read_text().count(mutant.original)
    if n != 1:
        return f"snippet found {n} times in {mutant.file}"
    return None


def copy_tree(dest: Path) -> Path:
    for name in COPY:
        src = ROOT / name
        if src.is_symlink():  # sweeps -> cdpm_drake/sweeps: a link in the copy too
            os.symlink(os.readlink(src), dest / name)
        elif src.is_dir():
            shutil.copytree(src, dest / name, ignore=IGNORE)
        elif src.is_file():
            shutil.copy2(src, dest / name)
    return dest


def _pytest(copy: Path, args: list[str], python: str) -> tuple[int, str]:
    env = dict(os.environ, PYTHONPATH=str(copy), PYTHONDONTWRITEBYTECODE="1",
               MPLBACKEND="Agg")
    cmd = [python, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
           "--rootdir", str(copy), *args]
    try:
        proc = subprocess.run(cmd, cwd=copy, env=env, capture_output=True, text=True,
                              timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return -1, "timeout"
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    failed = next((ln for ln in lines if ln.startswith(("FAILED", "ERROR"))), "")
    return proc.returncode, failed or (lines[-1] if lines else proc.stderr[-200:])


def run_mutant(mutant: Mutant, copy: Path, python: str) -> dict:
    """Apply the mutant in `copy`, run the tests, undo it; returns a result row."""
    start = time.perf_counter()
    why = stale_reason(mutant, copy)
    if why is not None:
        return dict(name=mutant.name, result="STALE", where=why, seconds=0.0)
    path = copy / mutant.file
    text = path.read_text()
    try:
        path.write_text(text.replace(mutant.original, mutant.replacement, 1))
        first = [t for t in mutant.tests if (copy / t).is_file()]
        stages = []
        if first:
            stages.append(("own tests", first))
        stages.append(("rest of suite",
                       ["tests"] + [f"--ignore={t}" for t in first]))
        for label, args in stages:
            code, line = _pytest(copy, args, python)
            if code != 0:
                where = f"{label}: {line}" if code != -1 else f"{label}: timeout"
                result = "killed"
                node = _failed_test(line)
                if node is not None:
                    # A kill counts only if that test passes without the mutant: on a busy
                    # host a timing test may fail by itself, which says nothing of the mutant.
                    path.write_text(text)
                    if _pytest(copy, [node], python)[0] != 0:
                        result, where = "FLAKY", f"{node} fails without the mutant too"
                return dict(name=mutant.name, result=result, where=where[:110],
                            seconds=time.perf_counter() - start)
        return dict(name=mutant.name, result="SURVIVED", where="the whole suite passed",
                    seconds=time.perf_counter() - start)
    finally:
        path.write_text(text)


def _failed_test(line: str) -> str | None:
    """The test node id of a pytest `FAILED path::name - message` line."""
    if not line.startswith(("FAILED ", "ERROR ")):
        return None
    node = line.split(" ", 1)[1].split(" - ", 1)[0].strip()
    return node if "::" in node else None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    parser.add_argument("--only", action="append", metavar="NAME",
                        help="run only this mutant (repeatable)")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="workers, each on its own copy of the tree (default 1)")
    parser.add_argument("--python", default=sys.executable,
                        help="the interpreter with the test dependencies (default: this one)")
    args = parser.parse_args(argv)
    _check_unique_names()
    if args.jobs < 1:
        parser.error(f"--jobs must be >= 1, got {args.jobs}")
    mutants = MUTANTS
    if args.only:
        known = {m.name for m in MUTANTS}
        unknown = [n for n in args.only if n not in known]
        if unknown:
            parser.error(f"unknown mutant(s) {unknown}; valid names: {sorted(known)}")
        mutants = [m for m in MUTANTS if m.name in args.only]
    if args.list:
        for m in mutants:
            why = stale_reason(m)
            print(f"{m.name:36s} {m.file:40s} {'STALE: ' + why if why else m.reason}")
        return 0

    rows = []
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="cdpm_mutants_") as tmp:
        copies = queue.Queue()
        for k in range(min(args.jobs, len(mutants))):
            copies.put(copy_tree(Path(tmp) / f"copy{k}"))

        def work(m):
            copy = copies.get()
            try:
                row = run_mutant(m, copy, args.python)
            finally:
                copies.put(copy)
            print(f"  {row['result']:8s} {m.name} ({row['seconds']:.0f} s)", flush=True)
            return row

        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, copies.qsize())) as ex:
            rows = list(ex.map(work, mutants))
    total = time.perf_counter() - started

    print()
    print(f"{'mutant':36s} {'result':8s} {'s':>5s}  where")
    for r in rows:
        print(f"{r['name']:36s} {r['result']:8s} {r['seconds']:5.0f}  {r['where']}")
    killed = sum(r["result"] == "killed" for r in rows)
    survived = [r["name"] for r in rows if r["result"] == "SURVIVED"]
    stale = [r["name"] for r in rows if r["result"] == "STALE"]
    flaky = [r["name"] for r in rows if r["result"] == "FLAKY"]
    print()
    print(f"score: {killed}/{len(rows)} killed ({100.0 * killed / max(1, len(rows)):.0f} %), "
          f"{len(survived)} survived, {len(stale)} stale, {len(flaky)} flaky; "
          f"{total / 60:.1f} min with {args.jobs} job(s)")
    if survived:
        print(f"survived: {survived}")
    if stale:
        print(f"stale (update the list): {stale}")
    if flaky:
        print(f"flaky (run them again with --only): {flaky}")
    return 0 if killed == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
