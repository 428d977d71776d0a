"""Where a run writes: one folder per run, never shared, never overwritten by accident.

By default `runs/<name>/<UTC timestamp>[-<variant>]/` (the variant: dynamic, hardware,
full-pose, tension-control, when not the default), with `runs/<name>/latest` a symlink to the
newest run (pointed there when the run starts, so a run killed half-way is the latest; back again if
the run writes nothing). `--out DIR` chooses the folder exactly; an existing, non-empty DIR is
refused unless `--force`, which empties it first (only when it holds a run: log.npz, ticks.bin
or scenario.yaml, so a mistyped --out cannot wipe an unrelated folder). The folder is created
only when the run starts and removed again if the run writes nothing. What a run writes there
(log.npz, scenario.yaml with copies of its robot file and force CSV: run_scenario.py)
makes the folder self-contained. No Drake import.
"""

import datetime
import os
import shutil
from pathlib import Path

RUNS_DIR = Path("runs")
LATEST = "latest"
# The files whose presence makes a folder a run's (and so one that --force may empty).
RUN_FILES = ("log.npz", "ticks.bin", "scenario.yaml")


class RunFolderError(ValueError):
    """An --out that cannot be used; the message names it and says what to do."""


def writable_dir(path: Path, field: str = "--out") -> None:
    """Make `path` (and its parents) and check a file can be written there; RunFolderError
    naming `field` and the path otherwise."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".cdpm_write_test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise RunFolderError(f"{field} {str(path)!r} is not a writable directory: "
                             f"{e.strerror or e}") from None


def utc_stamp(now: datetime.datetime | None = None) -> str:
    """e.g. 20261201T211039.123Z: sorts by time, no ':' (safe on every file system)."""
    now = datetime.datetime.now(datetime.timezone.utc) if now is None else now
    return now.strftime("%Y%m%dT%H%M%S.") + f"{now.microsecond // 1000:03d}Z"


class RunFolder:
    """The folder of one run. `plan()` checks before anything is created (an early error
    leaves nothing behind); `create()` makes it and points `latest` at it; `discard()` removes
    it again, and restores `latest`, if the run wrote nothing."""

    def __init__(self, name: str, out=None, force: bool = False, root=RUNS_DIR,
                 variant: str = ""):
        """`variant`: a tag appended to a default folder's name (<stamp>-<variant>), so that
        runs of a scenario on the dynamic plant or with the full pose stand out from the
        default's in a listing ("" for the default)."""
        self.name = name
        self.variant = variant
        self.explicit = out is not None
        self.force = force
        self.root = Path(root)
        self.path = Path(out) if out is not None else None
        self._planned = False
        self._created = []
        self._previous_latest = None  # where `latest` pointed before create() ("": nowhere)

    def plan(self) -> Path:
        """Choose the path and check it may be used (nothing is created)."""
        if self.explicit:
            p = self.path
            if p.exists() and not p.is_dir():
                raise RunFolderError(f"--out {str(p)!r} is not a writable directory: it is "
                                     "a file")
            if p.is_dir() and any(p.iterdir()):
                if not self.force:
                    raise RunFolderError(
                        f"--out {str(p)!r} is not empty ({_listing(p)}); give another --out, "
                        "or --force to empty it first")
                if not any((p / f).exists() for f in RUN_FILES):
                    raise RunFolderError(
                        f"--out {str(p)!r} holds no run ({_listing(p)}; a run folder has one "
                        f"of {list(RUN_FILES)}): --force only empties a run's folder")
        else:
            parent = self.root / self.name
            stamp = utc_stamp()
            tail = f"-{self.variant}" if self.variant else ""
            p = parent / f"{stamp}{tail}"
            n = 1
            while p.exists():  # two runs in the same millisecond: never share a folder
                n += 1
                p = parent / f"{stamp}-{n}{tail}"
            self.path = p
        self._planned = True
        return self.path

    def create(self) -> Path:
        """Make the folder (emptying an explicit one under --force); check it is writable."""
        p = self.path if self._planned else self.plan()
        if self.explicit and self.force and p.is_dir():
            for child in p.iterdir():
                if child.is_dir() and not child.is_symlink():
                    shutil.rmtree(child)
                else:
                    child.unlink()
        missing = []
        q = p
        while not q.exists():
            missing.append(q)
            q = q.parent
        writable_dir(p)
        self._created = missing
        self.finish()
        return p

    def finish(self) -> None:
        """Point runs/<name>/latest at this run (default folders only). create() does it
        already, so that a run killed half-way (its ticks.bin to recover) is the latest."""
        if self.explicit or self.path is None:
            return
        link = self.path.parent / LATEST
        if self._previous_latest is None:
            self._previous_latest = os.readlink(link) if link.is_symlink() else ""
        _point(link, self.path.name)

    def discard(self) -> None:
        """Remove the folders create() made, if they are (still) empty, and point `latest`
        back where it pointed before."""
        created, self._created = self._created, []
        if not created:
            return
        try:
            created[0].rmdir()  # the run's own folder: only if the run wrote nothing
        except OSError:
            return
        if self._previous_latest is not None:
            link = self.path.parent / LATEST
            if self._previous_latest:
                _point(link, self._previous_latest)
            else:
                link.unlink(missing_ok=True)
            self._previous_latest = None
        for q in created[1:]:  # runs/<name>, runs: if this run made them and they are empty
            try:
                q.rmdir()
            except OSError:
                break


def _point(link: Path, target: str) -> None:
    """Make `link` a symlink to `target` atomically (a reader never sees it missing)."""
    tmp = link.parent / f".{link.name}.{os.getpid()}"
    try:
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(target, target_is_directory=True)
        os.replace(tmp, link)
    except OSError:
        tmp.unlink(missing_ok=True)  # no symlinks here: the timestamped folder still is


def resolve_latest(path: Path) -> Path:
    """A run folder given as `runs/<name>` (the parent of timestamped runs): its `latest`."""
    path = Path(path)
    if path.is_dir() and not any((path / f).exists() for f in RUN_FILES) \
            and (path / LATEST).is_dir():
        return path / LATEST
    return path


def _listing(p: Path, limit: int = 4) -> str:
    names = sorted(c.name for c in p.iterdir())
    shown = ", ".join(names[:limit]) + (", ..." if len(names) > limit else "")
    return f"holds {shown}"


def overlay_tag(overlay_text) -> str:
    """A run folder's tag for a --scenario-text overlay: "text-" and 6 hex digits of its
    hash ("" without one), so runs of one scenario under different overlays are told apart
    in runs/<name>/ (the overlay itself is in the folder's scenario.yaml)."""
    import hashlib

    if not overlay_text or overlay_text.strip() in ("", "{}"):  # an overlay changing nothing
        return ""
    return "text-" + hashlib.sha1(overlay_text.encode("utf-8")).hexdigest()[:6]
