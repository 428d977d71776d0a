"""The compiled kernels' cache is keyed by every module's source (cdpm_drake.numba_cache_dir):
numba alone would keep a kernel that calls another file's kernel (pose_control ->
kinematics, interference, pose, tension) compiled against the callee's old code after the
callee's file is edited."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numba

import cdpm_drake
from cdpm_drake import numba_cache_dir

PACKAGE = Path(cdpm_drake.__file__).parent


def _copy(tmp_path) -> Path:
    copy = tmp_path / "cdpm_drake"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.yaml"))
    return copy


def test_an_edit_of_any_module_moves_the_cache(tmp_path):
    copy = _copy(tmp_path)
    before = numba_cache_dir(copy)
    assert before == numba_cache_dir(copy)  # a pure function of the sources
    assert before.parent == copy / "__pycache__" / "numba"  # a writable package: its own
    kernels = sorted(p.relative_to(copy).as_posix() for p in (copy / "kernels").rglob("*.py")
                     if "numba.njit" in p.read_text())
    assert {"kernels/kinematics.py", "kernels/plant/cable_net.py"} <= set(kernels), kernels
    for name in kernels:
        path = copy / name
        text = path.read_text()
        path.write_text(text.replace("def ", "def  ", 1))  # one character, any callee
        assert numba_cache_dir(copy) != before, name
        path.write_text(text)
        assert numba_cache_dir(copy) == before
    (copy / "notes.txt").write_text("not a module")
    main = copy / "cli" / "__init__.py"
    main.write_text(main.read_text() + "\n# no kernel here\n")
    assert numba_cache_dir(copy) == before  # nothing a kernel compiles in changed


def test_the_kernels_are_cached_in_that_folder():
    if os.environ.get("NUMBA_CACHE_DIR") != os.environ.get("CDPM_DRAKE_NUMBA_CACHE_DIR"):
        return  # the user chose a folder (checked below, in a subprocess)
    from cdpm_drake.kernels import kinematics
    from cdpm_drake.kernels import full_pose as pose_control

    folder = str(numba_cache_dir())
    assert numba.config.CACHE_DIR == folder
    for kernel in (kinematics.length_loop_tick, pose_control.pose_rates_tick):
        assert kernel._cache._cache_path.startswith(folder), kernel._cache._cache_path


def _folder_in_subprocess(env) -> str:
    code = "import cdpm_drake, numba; print(numba.config.CACHE_DIR)"
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, check=True).stdout.strip()


def test_a_users_folder_is_kept_and_an_inherited_one_is_recomputed(tmp_path):
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "CDPM_DRAKE_NUMBA_CACHE_DIR")}
    mine = str(tmp_path / "mine")
    assert _folder_in_subprocess({**env, "NUMBA_CACHE_DIR": mine}) == mine
    # A folder our own parent process set (marked as ours) is for the parent's sources.
    stale = str(tmp_path / "parents")
    got = _folder_in_subprocess({**env, "NUMBA_CACHE_DIR": stale,
                                 "CDPM_DRAKE_NUMBA_CACHE_DIR": stale})
    assert got == str(numba_cache_dir())


def test_a_read_only_package_caches_in_the_users_cache_folder(tmp_path, monkeypatch):
    copy = _copy(tmp_path)
    monkeypatch.setattr(cdpm_drake.os, "access", lambda path, mode: False)  # as for a user
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    folder = numba_cache_dir(copy)
    assert folder.parent == tmp_path / "xdg" / "cdpm_drake" / "numba"
    monkeypatch.undo()
    assert folder.name == numba_cache_dir(copy).name  # the same sources, the same key
