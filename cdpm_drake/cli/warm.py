"""`cdpm warm`: compile every kernel the commands will need, in one step, with a line per group.

The per-tick math is numba, compiled on first use and cached (cdpm_drake.numba_cache_dir).
Each command otherwise compiles what it alone needs the first time it meets it (the dynamic
plant's cables, the full pose, the workspace statics), so a user's first runs each pause;
after `cdpm warm` none does. A group is warmed by doing what the command does, briefly: a
0.2 s simulation of a shipped scenario (numba compiles a whole kernel and its callees at its
first call, every branch included) or the workspace statics on a coarse grid."""

import io
import sys
import time

from cdpm_drake.cli.compile_notice import FIRST_COMPILE, listen_to_compiles

# (what the group is, the commands that need it, scenario, overlay); a scenario of None is
# the workspace statics of `cdpm info`. The other variants need nothing more (the paper's
# method, load cells, 8 cables: the same kernels, other branches), and the real reels
# (`cdpm run`, `cdpm emulate`) use the plants' kernels and the drive-torque conversion
# warmed here. Measured on a first install (2 cores): 158, 21, 26 and 1 kernels, 71 s of
# CPU in all, 350 s of wall clock with the host loaded by other jobs.
FULL_POSE = "controller: {pose: full, tension_control: true}"
GROUPS = (
    ("kinematic plant, the default controller", "simulate, run, sweep",
     "exp2_interaction", ""),
    ("dynamic plant, length loop", "simulate, emulate --plant dynamic",
     "exp2_interaction", "{plant: !DynamicReels {}}"),
    ("dynamic plant, full pose and tension control", "simulate, run, emulate --plant dynamic",
     "exp2_interaction", "{plant: !DynamicReels {}, " + FULL_POSE + "}"),
    ("workspace statics", "info", None, ""),
)
DURATION = 0.2  # s simulated per group: past the full pose's 50 ms warm-up


class _Counter:
    """Counts numba's compilations (cache misses; a load from the cache is not one)."""

    def __init__(self):
        self.count = 0

    def __enter__(self):
        self._installed = listen_to_compiles(self._count)
        return self

    def _count(self):
        self.count += 1

    def __exit__(self, *exc):
        self._installed.__exit__(*exc)


def warm_group(scenario: str | None, overlay: str) -> None:
    """Do what the group's command does, briefly, so that its kernels compile."""
    if scenario is None:
        from cdpm_drake.cli.info import info

        info(robot="paper_7cable", grid_step=0.2, out=io.StringIO())
        return
    from cdpm_drake.config import load_scenario
    from cdpm_drake.runs.simulate import simulate

    result = simulate(scenario=load_scenario(scenario, overlay or None), duration=DURATION)
    if result.error is not None:  # a shipped scenario's first 0.2 s: never expected
        raise result.error


def warm(out=None) -> list[tuple[str, int, float]]:
    """Compile every group's kernels (GROUPS), printing a line per group as it ends and the
    total; returns (group, kernels compiled, seconds) per group."""
    import logging

    out = sys.stdout if out is None else out
    print(f"cdpm warm: compiling the per-tick math of {len(GROUPS)} groups (numba, once: about "
          f"{FIRST_COMPILE}; seconds when already cached)", file=out, flush=True)
    done, start = [], time.monotonic()
    logging.disable(logging.WARNING)  # a scenario's own warnings are not news here
    try:
        for k, (what, commands, scenario, overlay) in enumerate(GROUPS, 1):
            t0 = time.monotonic()
            with _Counter() as counter:
                warm_group(scenario, overlay)
            seconds = time.monotonic() - t0
            done.append((what, counter.count, seconds))
            print(f"  [{k}/{len(GROUPS)}] {what} (cdpm {commands}): "
                  f"{counter.count} compiled, {seconds:.1f} s", file=out, flush=True)
    finally:
        logging.disable(logging.NOTSET)
    print(f"cdpm warm: done in {time.monotonic() - start:.1f} s; later runs load the kernels "
          "from the cache", file=out, flush=True)
    return done


def cmd_warm(args) -> int:
    warm()
    return 0
