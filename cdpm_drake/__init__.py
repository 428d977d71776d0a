"""cdpm_drake: interference-aware admittance control of cable-driven parallel mechanisms.

Layout (imports point down only; tests/test_layering.py holds the rules):
  cli/ -> runs/ (simulate, realtime, sweep/), emulator/ -> diagram.py (the one builder),
  config/ -> systems/, hardware/ -> robot/ -> kernels/ (numpy and numba, no Drake; the
  per-tick math, compiled once and cached by numba). views/ read logs through runs/;
  data/ holds the shipped robots, scenarios and sweeps.
"""

import hashlib
import os
import sys
from pathlib import Path

__version__ = "0.1.0"


def numba_cache_dir(package: Path = Path(__file__).parent) -> Path:
    """Where the package's compiled kernels are cached: a folder named by a hash of the
    source of every module that defines numba kernels. numba invalidates a cached kernel only
    when the file that defines it changes; a kernel that calls another file's kernel
    (full_pose calls kinematics, interference, pose and tension) would otherwise keep
    running the callee's old code after an edit of the callee's file. Keyed by all the kernel
    modules in any folder, an edit of any of them starts a fresh cache; an edit elsewhere
    (cli/) keeps it."""
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        source = path.read_bytes()
        if b"numba.njit" in source:  # kernels, and the constants they compile in
            name = path.relative_to(package).as_posix()
            digest.update(name.encode() + b"\0" + source + b"\0")
    base = package / "__pycache__"
    if not os.access(package, os.W_OK) or (base.exists() and not os.access(base, os.W_OK)):
        # An installed, read-only package: the user's cache folder.
        base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "cdpm_drake"
    return base / "numba" / digest.hexdigest()[:16]


_OURS = "CDPM_DRAKE_NUMBA_CACHE_DIR"  # marks a NUMBA_CACHE_DIR this function set


def _use_numba_cache_dir() -> None:
    """Point numba's cache at `numba_cache_dir()` unless the user chose one (NUMBA_CACHE_DIR).
    Before numba is imported the environment variable does it; after, numba's config, read
    when a kernel is decorated. A subprocess inherits the variable marked as ours and computes
    its own folder (it may import another copy of the package, e.g. a mutated one)."""
    chosen = os.environ.get("NUMBA_CACHE_DIR")
    if chosen and chosen != os.environ.get(_OURS):
        return
    folder = str(numba_cache_dir())
    if "numba" in sys.modules:
        sys.modules["numba"].config.CACHE_DIR = folder
    os.environ["NUMBA_CACHE_DIR"] = os.environ[_OURS] = folder


_use_numba_cache_dir()
