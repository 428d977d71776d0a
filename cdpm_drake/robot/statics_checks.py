"""What a robot's cables can hold, said when it is loaded: the wrench matrix's rank, the
share of the workspace box where the level platform is held with every cable taut, and the
box's faces beyond the reels' frame. Messages name the robot and the cause."""

import logging

import numpy as np

from cdpm_drake.robot.model import SAME_POINT_TOL, Robot, plain

# The package's logger, not this module's: `cdpm info` filters it (a filter on a logger
# does not see its children's records) and tests capture it by that name.
_log = logging.getLogger("cdpm_drake.robot")


def frame_warnings(robot: "Robot") -> list[str]:
    """The faces of the workspace box that reach beyond the reels' frame, in words: past the
    last reel exit along x or y, or above the highest one, every cable pulls the platform
    back (or down), so nothing holds it there. Below the lowest exit is where a suspended
    robot's platform hangs (gravity pulls it down, the cables up): not a warning."""
    lo, hi = robot.workspace.lower, robot.workspace.upper
    a_lo, a_hi = robot.reels.min(axis=0), robot.reels.max(axis=0)
    out = []
    for axis, name in enumerate("xyz"):
        if axis < 2 and lo[axis] < a_lo[axis] - SAME_POINT_TOL:
            out.append(f"{robot.name}: the workspace box's lower {name} face, workspace.lower"
                       f"[{axis}] = {plain(lo[axis])!r} m, lies beyond the reels' frame: no "
                       f"reel exit is at {name} <= {plain(lo[axis])!r} m (the lowest at "
                       f"{plain(a_lo[axis])!r} m), so there every cable pulls the platform "
                       f"back along +{name} and nothing holds it")
        if hi[axis] > a_hi[axis] + SAME_POINT_TOL:
            pull = "down (with its weight)" if axis == 2 else f"back along -{name}"
            out.append(f"{robot.name}: the workspace box's upper {name} face, workspace.upper"
                       f"[{axis}] = {plain(hi[axis])!r} m, lies beyond the reels' frame: no "
                       f"reel exit is at {name} >= {plain(hi[axis])!r} m (the highest at "
                       f"{plain(a_hi[axis])!r} m), so there every cable pulls the platform "
                       f"{pull} and nothing holds it")
    return out


# Statics checked on load: the level platform (platform.mass at its centre) held with every
# cable >= STATICS_FLOOR N on an STATICS_GRID^3 grid of the workspace box. A robot whose box is
# held on less than STATICS_WARN_SHARE of it gets a warning naming the share and its likely
# cause. About 5 ms for 7 or 8 cables (kernels/tension.py's compiled closed forms), once per robot
# geometry and process.
STATICS_FLOOR = 5.0
STATICS_GRID = 11
STATICS_WARN_SHARE = 0.5
# A point platform held on this much more of the box than the real one: the moment balance
# (the attachment points) is what fails.
_MOMENT_BLAME = 0.25
# Points per axis of the point platform's grid (Clarabel per point, ~0.5 ms: only computed
# for a robot that gets the warning).
_POINT_GRID = 5
_STATICS: dict = {}
_AXES = ("force along x", "force along y", "force along z", "moment about x",
         "moment about y", "moment about z")


def _statics_entry(robot: "Robot"):
    """(statics.Statics, warnings) of a robot, computed once per geometry and mass."""
    from cdpm_drake.robot.statics import workspace_statics

    key = (robot.reels.tobytes(), robot.attachments.tobytes(), robot.workspace.lower.tobytes(),
           robot.workspace.upper.tobytes(), robot.dynamics.mass, robot.name)
    if key not in _STATICS:
        statics = workspace_statics(robot, STATICS_FLOOR, STATICS_GRID)
        _STATICS[key] = (statics, tuple(statics_warnings(robot, statics)))
    return _STATICS[key]


def robot_statics(robot: "Robot"):
    """statics.Statics of the robot's level platform (cached per geometry and mass)."""
    return _statics_entry(robot)[0]


def describe_wrench(direction) -> str:
    """The largest components of a unit wrench direction [force; moment], in words."""
    d = np.asarray(direction, dtype=float)
    order = np.argsort(-np.abs(d))
    parts = [_AXES[k] for k in order if abs(d[k]) >= 0.3 * abs(d[order[0]])]
    return " and ".join(parts[:2])


def _missing(robot: "Robot") -> str:
    """Every wrench direction the cables of the level platform at the workspace centre cannot
    resist, in words (robot.unresisted)."""
    from cdpm_drake.kernels.tension import wrench_matrix
    from cdpm_drake.robot.unresisted import unresisted_text

    return unresisted_text(wrench_matrix(robot, robot.workspace.center))


def statics_warnings(robot: "Robot", statics, *, grid: str | None = None, base=None,
                     base_share: float | None = None) -> list[str]:
    """What is wrong with a robot's statics, in words (empty when its box is mostly held).
    `grid` names the grid of `statics.share` (default: its n x n x n grid). `base` is the
    robot before its cable swaps (a scenario's, or `cdpm info --swaps`) and `base_share` its
    share on the same grid: when it alone is held on most of the box, the swaps are the
    cause, not the robot file."""
    out = []
    n = statics.n
    grid = f"{n}x{n}x{n} grid" if grid is None else grid
    m = robot.num_cables
    if m < 6:
        # Too few cables for six equations: the rank and the share only restate that.
        return [f"{robot.name}: {m} cables cannot hold the platform against all six force and "
                f"moment components (wrench matrix rank {statics.rank} at the workspace "
                f"centre: no cable tensions resist {_missing(robot)} there): a free platform "
                "would turn; the kinematic plant, and plant: !DynamicReels {lock_rotation: "
                "true}, model one that only translates (the free-rotating !DynamicReels "
                "refuses it)"]
    if statics.unreachable is not None:
        out.append(f"{robot.name}: the wrench matrix has rank {statics.rank} < 6 at the "
                   f"workspace centre {robot.workspace.center.tolist()!r} m: no cable tensions "
                   f"resist {_missing(robot)} there, so the platform cannot resist them: the "
                   "cables' lines of action leave it free to turn or slide")
    if statics.share < STATICS_WARN_SHARE:
        from cdpm_drake.robot.statics import point_platform_share

        if base is not None and base_share is not None and base_share >= STATICS_WARN_SHARE:
            # The paper swaps cables to provoke interference; the swapped attachment points
            # balance the moments worse. The robot file is not at fault.
            swapped = [f"{i + 1}-{j + 1}" for i, j in _swapped_cables(base, robot)]
            cause = (f"the swapped cables ({', '.join(swapped)}) are the cause: robot "
                     f"{base.name!r} without the swaps is held on {100 * base_share:.0f} % of "
                     "it")
        else:
            point = point_platform_share(robot, statics.floor, n=_POINT_GRID,
                                         mass=statics.mass)
            where = (f"{100 * point:.0f} % of the box (a coarser {_POINT_GRID}x{_POINT_GRID}"
                     f"x{_POINT_GRID} grid)")
            cause = ("the moment balance fails: a point platform (forces only) would be "
                     f"held on {where}, so the attachment points are the likely cause"
                     if point - statics.share >= _MOMENT_BLAME else
                     f"a point platform (forces only) would be held on {where} too, so the "
                     "reels cannot hold the platform there: the box reaches beyond "
                     "what the reels' layout supports")
        out.append(f"{robot.name}: the cables hold the level platform ({statics.mass:g} kg at "
                   f"its centre) with every cable >= {statics.floor:g} N on only "
                   f"{100 * statics.share:.0f} % of the workspace box ({grid}); {cause}")
    return out


def _swapped_cables(base: "Robot", robot: "Robot") -> list[tuple[int, int]]:
    """The 0-based cable pairs whose attachment points trade places from `base` to `robot`
    (each cable once, in order); a cable that moved otherwise is left out."""
    moved = [i for i in range(base.num_cables)
             if not np.array_equal(base.attachments[i], robot.attachments[i])]
    pairs = []
    for i in moved:
        for j in moved:
            if i < j and np.array_equal(base.attachments[i], robot.attachments[j]) \
                    and np.array_equal(base.attachments[j], robot.attachments[i]):
                pairs.append((i, j))
    return pairs


def report_statics(robot: "Robot") -> None:
    """Loading a robot says its statics: at INFO level always, as warnings when bad."""
    statics, warnings = _statics_entry(robot)
    n = statics.n
    _log.info("%s: wrench matrix rank %d at the workspace centre; level platform (%g kg) held "
              "with every cable >= %g N on %.1f %% of the workspace box (%dx%dx%d grid)",
              robot.name, statics.rank, statics.mass, statics.floor, 100 * statics.share,
              n, n, n)
    for message in warnings:
        _log.warning("%s", message)
