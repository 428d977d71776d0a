"""The paper's result figures (Figs. 8-16) drawn from a log.npz (docs/LOG_FORMAT.md).

Each `figure_*` function returns a `matplotlib.figure.Figure` built without pyplot, so no global
figure state leaks between calls and tests can read the plotted data back from the artists;
`plot_log` writes them all as PNGs. Distances are shown in mm (as in the paper), forces in N,
positions in m, time in s; cables are numbered 1..m.
"""

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..interference import logistic_intensity

# What each figure reads from the log (docs/LOG_FORMAT.md).
_NEEDS = {
    "distances": ("time", "pair_distances", "active", "pairs", "d_l", "d_u"),
    "forces": ("time", "F_H", "F_int", "F_d"),
    "trajectory": ("time", "p", "active", "crossed", "reels", "attachments", "pairs"),
    "logistic": ("pairs", "d_l", "d_u", "F_u", "eps"),
    # The dynamic plant's ground truth (plant: !DynamicReels); plotted only when logged.
    "tensions": ("time", "tensions", "slack"),
    "pose_error": ("time", "p", "p_true", "rpy_true"),
}
LOG_KEYS = ("time", "p", "F_H", "F_int", "F_wall", "F_d", "velocity_admittance", "velocity",
            "reel_velocity", "lengths", "pair_distances", "active", "crossed", "pairs", "d_l",
            "d_u", "F_u", "eps", "F_max", "reels", "attachments", "workspace_lower",
            "workspace_upper", "robot_name", "scenario_name")

# Fig. 12's colour code, used for the force plots too.
FORCE_COLORS = {"F_H": "tab:blue", "F_int": "black", "F_d": "tab:red", "F_wall": "tab:green"}
FIGURE_FILES = {"distances": "distances.png", "forces": "forces.png",
                "trajectory": "trajectory.png", "logistic": "logistic.png"}


class LogError(ValueError):
    """A log file or dictionary does not follow docs/LOG_FORMAT.md."""


def load_log(path) -> dict:
    """Read DIR/log.npz (or the .npz file itself) into a dict of arrays; LogError when a key of
    docs/LOG_FORMAT.md is missing."""
    path = Path(path)
    if path.is_dir():
        path = path / "log.npz"
    if not path.is_file():
        raise LogError(f"log file {str(path)!r} does not exist (give a run directory holding "
                       "log.npz, or the .npz file)")
    try:
        with np.load(path, allow_pickle=False) as data:
            if not hasattr(data, "files"):  # a bare .npy array, not an archive
                raise ValueError("a single array, not an .npz archive")
            log = {k: data[k] for k in data.files}
    except (OSError, ValueError) as e:
        why = ("not a NumPy .npz archive" if "pickle" in str(e) or "allow_pickle" in str(e)
               else str(e))
        raise LogError(f"{str(path)!r} is not a log written by cdpm simulate or cdpm run "
                       f"(docs/LOG_FORMAT.md): {why}") from None
    missing = [k for k in LOG_KEYS if k not in log]
    if missing:
        raise LogError(f"{str(path)!r} lacks the key(s) {missing!r} of docs/LOG_FORMAT.md; "
                       f"it holds {sorted(log)!r}")
    return log


def _check(log: Mapping, figure: str) -> None:
    missing = [k for k in _NEEDS[figure] if k not in log]
    if missing:
        raise LogError(f"the {figure} plot needs log key(s) {missing!r} (docs/LOG_FORMAT.md); "
                       f"the log holds {sorted(log)!r}")
    if "time" in _NEEDS[figure]:
        T = len(log["time"])
        for key in _NEEDS[figure]:
            arr = np.asarray(log[key])
            if key in ("time", "p", "F_H", "F_int", "F_d", "pair_distances", "active",
                       "crossed", "tensions", "slack", "p_true", "rpy_true") and (arr.ndim == 0 or arr.shape[0] != T):
                raise LogError(f"log key {key!r} has shape {arr.shape!r}; expected one row per "
                               f"tick ({T} rows, as 'time')")


def _title(log: Mapping) -> str:
    scen = str(log["scenario_name"]) if "scenario_name" in log else ""
    robot = str(log["robot_name"]) if "robot_name" in log else ""
    return f"{scen} ({robot})" if scen and robot else scen or robot


def _pair_label(pair) -> str:
    return f"cables {int(pair[0])}-{int(pair[1])}"


# --- Fig. 10: distances -------------------------------------------------------------------------


def figure_distances(log: Mapping) -> Figure:
    """Distance (mm) vs time (s) of each pair that was active at some tick, with the d_l and d_u
    lines of those pairs (Fig. 10). When no pair was ever active, the closest pair is shown."""
    _check(log, "distances")
    t = np.asarray(log["time"], dtype=float)
    d = np.asarray(log["pair_distances"], dtype=float).reshape(len(t), -1)
    pairs = np.asarray(log["pairs"]).reshape(-1, 2)
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    shown = np.flatnonzero(np.asarray(log["active"]).reshape(len(t), -1).any(axis=0))
    heading = "Distance between the cables of each active pair"
    if shown.size == 0 and d.shape[1] and len(t):
        shown = np.array([int(np.argmin(d.min(axis=0)))])
        heading = "No pair came within d_u; the closest pair"
    for k in shown:
        ax.plot(t, 1000.0 * d[:, k], label=_pair_label(pairs[k]))
    for key, style in (("d_l", "--"), ("d_u", ":")):
        values = np.asarray(log[key], dtype=float).reshape(-1)[shown] if shown.size else []
        for v in np.unique(np.asarray(values)[np.isfinite(values)]):
            ax.axhline(1000.0 * v, color="0.3", linestyle=style,
                       label=f"{key} = {1000.0 * v:g} mm")
    if d.shape[1] == 0:
        ax.text(0.5, 0.5, "the robot has no watched cable pairs", ha="center",
                transform=ax.transAxes)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance between cables (mm)")
    ax.set_title(f"{heading} (Fig. 10)", fontsize="medium")
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best")
    fig.suptitle(_title(log))
    return fig


# --- Figs. 11, 13, 16: forces -------------------------------------------------------------------


def figure_forces(log: Mapping) -> Figure:
    """x, y, z components (N) of F_H, F_int and F_d vs time (s), one axis per component
    (Figs. 11, 13, 16); F_wall too when the virtual wall pushed at some tick."""
    _check(log, "forces")
    t = np.asarray(log["time"], dtype=float)
    names = ["F_H", "F_int", "F_d"]
    if "F_wall" in log and np.any(np.asarray(log["F_wall"]) != 0):
        names.insert(2, "F_wall")
    fig = Figure(figsize=(9, 7), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    for c, (ax, axis) in enumerate(zip(axes, "xyz")):
        for name in names:
            ax.plot(t, np.asarray(log[name], dtype=float)[:, c], color=FORCE_COLORS[name],
                    label=f"{name},{axis}", linewidth=1.0)
        ax.set_ylabel(f"F_{axis} (N)")
        ax.grid(True, alpha=0.3)
        # Beside the axes, so it never hides the end of a curve.
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{_title(log)}\nForces on the platform (Figs. 11, 13, 16)")
    return fig


# --- Figs. 9, 15: trajectory --------------------------------------------------------------------


def _box_edges(lower, upper) -> np.ndarray:
    """The 12 edges of an axis-aligned box as one polyline with NaN breaks; (36, 3), m."""
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    corners = np.array([[(hi if (n >> a) & 1 else lo)[a] for a in range(3)] for n in range(8)])
    rows = []
    for n in range(8):
        for a in range(3):
            if not (n >> a) & 1:
                rows += [corners[n], corners[n | (1 << a)], [np.nan] * 3]
    return np.array(rows)


def figure_trajectory(log: Mapping) -> Figure:
    """Platform path p (m) in 3D with the reels A_i, the ticks where a pair was active (dots) or
    crossed (crosses), and the cables at the first interference tick, the cables of the active
    pairs in red (Figs. 9, 15)."""
    _check(log, "trajectory")
    t = np.asarray(log["time"], dtype=float)
    p = np.asarray(log["p"], dtype=float).reshape(-1, 3)
    reels = np.asarray(log["reels"], dtype=float).reshape(-1, 3)
    b = np.asarray(log["attachments"], dtype=float).reshape(-1, 3)
    pairs = np.asarray(log["pairs"]).reshape(-1, 2)
    active = np.asarray(log["active"], dtype=bool).reshape(len(t), -1)
    crossed = np.asarray(log["crossed"], dtype=bool).reshape(len(t), -1)

    fig = Figure(figsize=(8, 7), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    ax.plot(p[:, 0], p[:, 1], p[:, 2], color="tab:blue", label="platform path p")
    events = active.any(axis=1)
    ax.plot(p[events, 0], p[events, 1], p[events, 2], linestyle="none", marker="o",
            markersize=3, color="tab:orange", label="a pair within d_u")
    cross = crossed.any(axis=1)
    ax.plot(p[cross, 0], p[cross, 1], p[cross, 2], linestyle="none", marker="x",
            markersize=7, color="tab:red", label="a pair crossed")
    if len(p):
        ax.plot(*p[0], linestyle="none", marker="s", color="tab:green", label="start")
        ax.plot(*p[-1], linestyle="none", marker="D", color="tab:purple", label="end")
    ax.plot(reels[:, 0], reels[:, 1], reels[:, 2], linestyle="none", marker="^",
            color="black", label="reels A_i")
    for i, a in enumerate(reels):
        ax.text(*a, f" A{i + 1}", fontsize="small")
    if "workspace_lower" in log and "workspace_upper" in log:
        box = _box_edges(log["workspace_lower"], log["workspace_upper"])
        ax.plot(box[:, 0], box[:, 1], box[:, 2], color="tab:green", alpha=0.4,
                linewidth=0.8, label="workspace (virtual wall)")

    # The posture of Figs. 9 and 15: the first tick with interference, else the start.
    if len(p):
        k = int(np.argmax(events)) if events.any() else 0
        hot = {int(c) for pair in pairs[active[k]] for c in pair}
        for i in range(len(reels)):
            end = p[k] + b[i]
            line, = ax.plot(*np.stack([reels[i], end]).T, linewidth=1.2 if i + 1 in hot else 0.7,
                            color="red" if i + 1 in hot else "0.55")
            line.set_gid(f"cable {i + 1}")
        ax.plot([], [], color="red", label=f"cables of active pairs at t = {t[k]:.2f} s")

    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    span = np.ptp(np.vstack([reels, p]) if len(p) else reels, axis=0)
    ax.set_box_aspect(np.maximum(span, 1e-3))
    ax.set_title("Platform trajectory, interference events and reels (Figs. 9, 15)")
    ax.legend(loc="upper left", fontsize="small")
    fig.suptitle(_title(log))
    return fig


# --- Fig. 8: logistic curve ---------------------------------------------------------------------


def logistic_sets(log: Mapping) -> list[tuple[tuple[float, float, float, float], list]]:
    """The distinct finite (d_l, d_u, F_u, eps) of the log, in order of first use, each with the
    1-based pairs that use it."""
    pairs = np.asarray(log["pairs"]).reshape(-1, 2)
    rows = np.stack([np.asarray(log[k], dtype=float).reshape(-1)
                     for k in ("d_l", "d_u", "F_u", "eps")], axis=1)
    sets: dict = {}
    for pair, row in zip(pairs, rows):
        if np.all(np.isfinite(row)):
            sets.setdefault(tuple(float(x) for x in row), []).append(
                (int(pair[0]), int(pair[1])))
    return list(sets.items())


def logistic_grid(d_l: float, d_u: float, num: int = 400) -> np.ndarray:
    """Distances (m) the Fig. 8 curve is drawn over: the band [d_l, d_u] and as much again on
    each side (never below 0)."""
    w = d_u - d_l
    return np.linspace(max(0.0, d_l - w), d_u + w, num)


def figure_logistic(log: Mapping) -> Figure:
    """Interference force intensity alpha (N) vs cable distance (mm), one axis per distinct set
    of logistic parameters of the log (eqs. 26-28, Fig. 8), with d_l, d_u, F_u - eps and eps
    marked."""
    _check(log, "logistic")
    sets = logistic_sets(log)
    fig = Figure(figsize=(max(8, 5 * len(sets)), 4.5), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, max(1, len(sets)), squeeze=False)[0])
    for ax, ((d_l, d_u, F_u, eps), users) in zip(axes, sets):
        d = logistic_grid(d_l, d_u)
        who = ("cables " + ", ".join(f"{i}-{j}" for i, j in users) if len(users) <= 4
               else f"{len(users)} cable pairs")
        ax.plot(1000.0 * d, logistic_intensity(d, d_l, d_u, F_u, eps), color="tab:blue",
                label=f"F_u = {F_u:g} N, eps = {eps:g} N")
        ax.axvline(1000.0 * d_l, color="0.3", linestyle="--", linewidth=0.8,
                   label=f"d_l = {1000 * d_l:g} mm")
        ax.axvline(1000.0 * d_u, color="0.3", linestyle=":", linewidth=0.8,
                   label=f"d_u = {1000 * d_u:g} mm")
        ax.axhline(F_u - eps, color="tab:red", linestyle="--", linewidth=0.6,
                   label=f"F_u - eps = {F_u - eps:g} N")
        ax.axhline(eps, color="tab:red", linestyle=":", linewidth=0.6, label=f"eps = {eps:g} N")
        marks, = ax.plot([1000.0 * d_l, 1000.0 * d_u], [F_u - eps, eps], linestyle="none",
                         marker="o", color="tab:red")
        marks.set_gid("conditions (27)")
        ax.set_title(who, fontsize="medium")
        ax.set_xlabel("distance between cables $d_{ij}$ (mm)")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    if not sets:
        axes[0].text(0.5, 0.5, "interference disabled in this run: no logistic parameters",
                     ha="center", transform=axes[0].transAxes)
        axes[0].set_xlabel("distance between cables $d_{ij}$ (mm)")
    axes[0].set_ylabel(r"force intensity $\alpha_{ij}$ (N)")
    fig.suptitle(f"{_title(log)}\nInterference force intensity, logistic function "
                 "(eqs. 26-28, Fig. 8)")
    return fig


# --- The dynamic plant: tensions and pose error ---------------------------------------------


def figure_tensions(log: Mapping) -> Figure:
    """Each cable's tension (N) vs time (s), with the ticks where it was slack marked (a dynamic
    plant's log)."""
    _check(log, "tensions")
    t = np.asarray(log["time"], dtype=float)
    tensions = np.asarray(log["tensions"], dtype=float).reshape(len(t), -1)
    slack = np.asarray(log["slack"]).reshape(len(t), -1) > 0.5
    fig = Figure(figsize=(9, 4.5), layout="constrained")
    ax = fig.add_subplot()
    for i in range(tensions.shape[1]):
        (line,) = ax.plot(t, tensions[:, i], linewidth=1.0, label=f"cable {i + 1}")
        if slack[:, i].any():
            ax.plot(t[slack[:, i]], np.zeros(int(slack[:, i].sum())), "|",
                    color=line.get_color(), markersize=8,
                    label=f"cable {i + 1} slack ({int(slack[:, i].sum())} ticks)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("tension (N)")
    ax.set_title("Cable tensions (dynamic plant)", fontsize="medium")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    fig.suptitle(_title(log))
    return fig


def figure_pose_error(log: Mapping) -> Figure:
    """The controller's position estimate minus the true position (mm, per axis and its norm),
    and the platform's true roll, pitch, yaw (deg), vs time (s) (a dynamic plant's log)."""
    _check(log, "pose_error")
    t = np.asarray(log["time"], dtype=float)
    error = 1000.0 * (np.asarray(log["p"], float) - np.asarray(log["p_true"], float))
    rpy = np.degrees(np.asarray(log["rpy_true"], dtype=float))
    fig = Figure(figsize=(9, 6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    for c, axis in enumerate("xyz"):
        top.plot(t, error[:, c], linewidth=1.0, label=f"p_{axis} - p_true,{axis}")
    top.plot(t, np.linalg.norm(error, axis=1), color="black", linewidth=1.2, label="|p - p_true|")
    top.set_ylabel("FK estimate error (mm)")
    top.set_title("Forward kinematics (translating, rigid cables) vs the true platform",
                  fontsize="medium")
    for c, name in enumerate(("roll", "pitch", "yaw")):
        bottom.plot(t, rpy[:, c], linewidth=1.0, label=name)
    bottom.set_ylabel("platform rotation (deg)")
    bottom.set_xlabel("time (s)")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    fig.suptitle(_title(log))
    return fig


FIGURES = {"distances": figure_distances, "forces": figure_forces,
           "trajectory": figure_trajectory, "logistic": figure_logistic}
# Drawn only from logs that hold their keys (the dynamic plant's).
OPTIONAL_FIGURES = {"tensions": figure_tensions, "pose_error": figure_pose_error}
FIGURE_FILES.update({"tensions": "tensions.png", "pose_error": "pose_error.png"})


def plot_log(log: Mapping[str, np.ndarray], out_dir, dpi: int = 120) -> list[Path]:
    """Write the four figures as PNGs in out_dir (created if needed); returns their paths in the
    order distances, forces, trajectory, logistic (then tensions and pose_error, for a log of
    the dynamic plant)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, make in FIGURES.items():
        path = out / FIGURE_FILES[name]
        make(log).savefig(path, dpi=dpi)
        paths.append(path)
    for name, make in OPTIONAL_FIGURES.items():
        if all(k in log for k in _NEEDS[name]):
            path = out / FIGURE_FILES[name]
            make(log).savefig(path, dpi=dpi)
            paths.append(path)
    return paths
