"""Command-line values several commands share, read and checked before a command's work
starts, so a bad one ends it with a usage error (CliError, exit 2) and no traceback: the
scenario argument, output folders, --html, --duration; and whether a LOG argument is a
sweep's folder."""

from pathlib import Path

import numpy as np

from cdpm_drake.cli.errors import CliError


def load_scenario_arg(args):
    """The scenario of a command's `scenario` and `--scenario-text` arguments, resolved."""
    from cdpm_drake.config import load_resolved_scenario

    # Resolved once here; the run, its view and its log all take this object.
    return load_resolved_scenario(args.scenario, overlay_text=args.scenario_text,
                                  method=getattr(args, "method", None))


def run_folder_step(action):
    """`action()` (a RunFolder step), its RunFolderError a usage error (--out, --force)."""
    from cdpm_drake.runs.run_folder import RunFolderError

    try:
        return action()
    except RunFolderError as e:
        raise CliError(str(e)) from None


def new_run_folder(resolved, out_dir, *, force, runs_root, overlay_text):
    """(words naming the run's variant, its RunFolder planned and created, the folder's path):
    `cdpm simulate`'s and `cdpm run`'s folder, `out_dir` or runs/<name>/<stamp>-<variant>
    (the variant's tag and the overlay's hash in the name)."""
    from cdpm_drake.runs.run_folder import RUNS_DIR, RunFolder, overlay_tag
    from cdpm_drake.runs.simulate import run_variant

    variant, tag = run_variant(resolved)
    tag = "-".join(t for t in (tag, overlay_tag(overlay_text)) if t)
    folder = RunFolder(resolved.scenario.name, out_dir, force=force,
                       root=RUNS_DIR if runs_root is None else runs_root, variant=tag)
    run_folder_step(folder.plan)
    # Before the run: a long run's log needs a place.
    return variant, folder, run_folder_step(folder.create)


def check_writable_dir(path: Path, field: str, keep: bool = True) -> None:
    """CliError unless `path` is (or can be made) a writable folder; `keep=False` removes the
    folders the check made (a dry run writes nothing)."""
    from cdpm_drake.runs.run_folder import RunFolderError, writable_dir

    made = []
    q = Path(path)
    while not q.exists() and q != q.parent:
        made.append(q)
        q = q.parent
    try:
        writable_dir(path, field)
    except RunFolderError as e:
        raise CliError(str(e)) from None
    if not keep:
        for q in made:
            q.rmdir()


def check_html(path) -> None:
    """--html FILE must be writable before a run starts, not found wanting after it."""
    if path is None:
        return
    if path.is_dir():
        raise CliError(f"--html {str(path)!r} is a folder; give a file name, e.g. "
                       f"{str(path / 'replay.html')!r}")
    check_writable_dir(path.parent if str(path.parent) else Path("."), "--html's folder")


def check_duration_arg(duration):
    """--duration, when given, a finite number of seconds > 0."""
    if duration is not None and not (duration > 0 and np.isfinite(duration)):
        raise CliError(f"--duration must be a number of seconds > 0, got {duration!r}")


class duration_flag:
    """A log too large for the duration given by --duration is a bad option value (exit 2);
    by the scenario's duration, an invalid scenario (1, as LogTooLarge is a ScenarioError)."""

    def __init__(self, duration):
        self._flag = duration is not None

    def __enter__(self):
        return self

    def __exit__(self, kind, e, tb):
        from cdpm_drake.runs.log import LogTooLarge

        if self._flag and isinstance(e, LogTooLarge):
            raise CliError(f"--{e}") from None
        return False


def check_duration_tick(duration, resolved) -> None:
    """--duration of at least one tick of the scenario's time_step."""
    from cdpm_drake.config import ScenarioError, check_duration

    if duration is not None:
        try:
            check_duration(duration, resolved.time_step, "--duration")
        except ScenarioError as e:
            raise CliError(str(e)) from None


def is_sweep_dir(path: Path) -> bool:
    """Whether a LOG argument is a sweep's folder (its results.csv, no log.npz)."""
    return path.is_dir() and (path / "results.csv").is_file() and not (path / "log.npz").exists()
