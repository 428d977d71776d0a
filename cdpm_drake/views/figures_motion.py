"""The paper's figures of the platform's motion drawn from a log (docs/LOG_FORMAT.md): the
forces on the platform (Figs. 11, 13, 16) and its trajectory with the interference events and
the robot (Figs. 9, 15). Forces in N, positions in m, time in s; cables numbered 1..m.
"""

import warnings
from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from cdpm_drake.views.figure_keys import check_figure
from cdpm_drake.views.figure_layout import log_title, mark_fault_time, run_stop, suptitle

# Fig. 12's colour code, used for the force plots too.
FORCE_COLORS = {"F_H": "tab:blue", "F_int": "black", "F_d": "tab:red", "F_wall": "tab:green",
                "F_kin": "tab:purple"}
# Every force plot axis spans at least this much (N), so a component that is numerical noise
# (1e-6 N) reads as the flat zero it is.
MIN_FORCE_SPAN = 0.5
# Line style per force, widest first and drawn first: when two series coincide (F_int = F_d
# when nobody pushes) the narrower one on top leaves the wider one visible on both sides, and
# the dashes let the one below show through.
FORCE_STYLES = {"F_H": dict(linestyle="-", linewidth=3.4, zorder=2.0),
                "F_wall": dict(linestyle="-.", linewidth=2.7, zorder=2.1),
                "F_kin": dict(linestyle=":", linewidth=2.4, zorder=2.15),
                "F_int": dict(linestyle="--", linewidth=2.1, zorder=2.2),
                "F_d": dict(linestyle="-", linewidth=1.0, zorder=2.3)}
# Transparency of the dots where a pair was within d_u: one dot per tick, many on top of each
# other, so the path shows through where they are sparse.
EVENT_ALPHA = 0.35


# --- Figs. 11, 13, 16: forces -------------------------------------------------------------------


def force_spans(log: Mapping, names) -> tuple[np.ndarray, float]:
    """Centre of each component's data (3,) and the one y span (N) every force axis gets: the
    largest component range, at least MIN_FORCE_SPAN, so equal heights mean equal forces."""
    data = np.stack([np.asarray(log[n], dtype=float).reshape(-1, 3) for n in names])
    finite = np.where(np.isfinite(data), data, np.nan)
    if finite.size == 0 or np.all(np.isnan(finite)):
        return np.zeros(3), MIN_FORCE_SPAN
    with warnings.catch_warnings():  # a component with no finite value: drawn around 0
        warnings.simplefilter("ignore", RuntimeWarning)
        lo, hi = np.nanmin(finite, axis=(0, 1)), np.nanmax(finite, axis=(0, 1))
    lo, hi = np.where(np.isfinite(lo), lo, 0.0), np.where(np.isfinite(hi), hi, 0.0)
    return 0.5 * (lo + hi), max(float(np.max(hi - lo)), MIN_FORCE_SPAN)


def figure_forces(log: Mapping) -> Figure:
    """x, y, z components (N) of F_H, F_int and F_d vs time (s), one axis per component
    (Figs. 11, 13, 16); F_wall too when the virtual wall pushed at some tick, and F_kin when
    the kinetostatic cue did (beyond the paper: the safety filter). Every axis spans
    the same number of newtons (force_spans), and the series differ in style and width
    (FORCE_STYLES) so that coinciding ones stay visible."""
    check_figure(log, "forces")
    t = np.asarray(log["time"], dtype=float)
    names = ["F_H", "F_int", "F_d"]
    if "F_wall" in log and np.any(np.asarray(log["F_wall"]) != 0):
        names.insert(2, "F_wall")
    if "F_kin" in log and np.any(np.asarray(log["F_kin"]) != 0):
        names.insert(-1, "F_kin")  # the kinetostatic cue, beside F_int (safety filter)
    centre, span = force_spans(log, names)
    fig = Figure(figsize=(9, 7), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    for c, (ax, axis) in enumerate(zip(axes, "xyz")):
        for name in names:
            ax.plot(t, np.asarray(log[name], dtype=float)[:, c], color=FORCE_COLORS[name],
                    label=f"{name},{axis}", **FORCE_STYLES[name])
        half = 0.55 * span  # 5 % margin above and below
        ax.set_ylim(centre[c] - half, centre[c] + half)
        ax.set_ylabel(f"F_{axis} (N)")
        ax.grid(True, alpha=0.3)
        mark_fault_time(ax, log)
        # Beside the axes, so it never hides the end of a curve.
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    axes[-1].set_xlabel("time (s)")
    suptitle(fig, log, f"{log_title(log)}\nForces on the platform (Figs. 11, 13, 16), "
              f"every axis {1.1 * span:.3g} N high")
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


def motion_limits(p, min_span: float = 0.05, margin: float = 0.15) -> np.ndarray:
    """Axis limits (3, 2), m, of a cube around the path p (T, 3): the largest extent of the
    motion plus `margin` of it on each side, at least `min_span` m, centred on the motion;
    one span for all three axes so that the zoomed view keeps the path's true shape."""
    p = np.asarray(p, dtype=float).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) == 0:
        return np.array([[-0.5, 0.5]] * 3) * min_span
    lo, hi = p.min(axis=0), p.max(axis=0)
    span = max(float(np.max(hi - lo)) * (1.0 + 2.0 * margin), min_span)
    centre = 0.5 * (lo + hi)
    return np.stack([centre - 0.5 * span, centre + 0.5 * span], axis=1)


def figure_trajectory(log: Mapping) -> Figure:
    """Platform path p (m) in 3D (Figs. 9, 15), two panels: the motion, zoomed to the path,
    with the ticks where a pair was within d_u (dots, under the path) or crossed (crosses), and
    a dynamic plant's true path p_true (dashed) beside the controller's estimate; and
    the robot as context: reels A_i, workspace box, the path, the zoomed region and the cables
    at the first interference tick, those of the active pairs in red. One legend below the
    panels lists only what was drawn."""
    check_figure(log, "trajectory")
    t = np.asarray(log["time"], dtype=float)
    p = np.asarray(log["p"], dtype=float).reshape(-1, 3)
    reels = np.asarray(log["reels"], dtype=float).reshape(-1, 3)
    b = np.asarray(log["attachments"], dtype=float).reshape(-1, 3)
    pairs = np.asarray(log["pairs"]).reshape(-1, 2)
    active = np.asarray(log["active"], dtype=bool).reshape(len(t), -1)
    crossed = np.asarray(log["crossed"], dtype=bool).reshape(len(t), -1)
    events, cross = active.any(axis=1), crossed.any(axis=1)
    stop = run_stop(log)  # a fault, or where an interrupted run stopped
    k_fault = (int(np.clip(np.searchsorted(t, stop[1]), 0, len(t) - 1))
               if stop is not None and np.isfinite(stop[1]) and len(t) else None)

    fig = Figure(figsize=(13, 6.8), layout="constrained")
    zoom = fig.add_subplot(1, 2, 1, projection="3d")
    robot = fig.add_subplot(1, 2, 2, projection="3d")
    handles = {}

    def keep(label, artist):
        handles.setdefault(label, artist)

    # The zoomed panel: artists drawn in the zorder given, not by depth, so the path stays
    # above the event dots it runs through.
    zoom.computed_zorder = False
    if events.any():
        dots, = zoom.plot(*p[events].T, linestyle="none", marker="o", markersize=6,
                          color="tab:orange", alpha=EVENT_ALPHA, markeredgewidth=0, zorder=1,
                          label="a pair within d_u")
        dots.set_gid("within d_u")
        # The dots overlap along the path and read as solid orange: the legend shows the
        # colour they are seen in, not one translucent dot.
        proxy = Line2D([], [], linestyle="none", marker="o", markersize=6, color="tab:orange",
                       markeredgewidth=0, label=dots.get_label())
        keep(proxy.get_label(), proxy)
    truth = (np.asarray(log["p_true"], dtype=float).reshape(-1, 3) if "p_true" in log
             else None)
    path, = zoom.plot(*p.T, color="tab:blue", linewidth=1.8, zorder=3,
                      label="platform path p" if truth is None else
                      "platform path p (controller's estimate)")
    path.set_gid("path")
    keep(path.get_label(), path)
    if truth is not None:  # a dynamic plant's: where the platform really went
        true_path, = zoom.plot(*truth.T, color="black", linewidth=1.0, linestyle="--",
                               zorder=3.5, label="true path p_true (dynamic plant)")
        true_path.set_gid("true path")
        keep(true_path.get_label(), true_path)
    if cross.any():
        marks, = zoom.plot(*p[cross].T, linestyle="none", marker="x", markersize=7,
                           color="tab:red", zorder=4, label="a pair crossed")
        keep(marks.get_label(), marks)
    if len(p):
        for ax in (zoom, robot):
            start, = ax.plot(*p[0], linestyle="none", marker="s", color="tab:green", zorder=5,
                             label="start")
            end, = ax.plot(*p[-1], linestyle="none", marker="D", color="tab:purple",
                           zorder=5, label="end")
        keep("start", start)
        keep("end", end)
    if k_fault is not None:
        gid, color = stop[0], stop[3]
        for ax in (zoom, robot):
            at, = ax.plot(*p[k_fault], linestyle="none", marker="*", markersize=13,
                          color=color, zorder=6, label=f"{gid} (t = {t[k_fault]:.3f} s)")
            at.set_gid(gid)
        keep(at.get_label(), at)
    limits = motion_limits(p if truth is None else np.vstack([p, truth]))
    zoom.set(xlim=limits[0], ylim=limits[1], zlim=limits[2])
    zoom.set_box_aspect((1, 1, 1))
    apart = ""
    if truth is not None and len(p):
        error = np.linalg.norm(p - truth, axis=1)
        if np.isfinite(error).any():
            apart = f"; the estimate at most {1000 * np.nanmax(error):.2f} mm from the truth"
    zoom.set_title(f"The motion ({1000 * (limits[0, 1] - limits[0, 0]):.0f} mm cube{apart})",
                   fontsize="medium")

    # The robot panel: the whole robot as context.
    robot.plot(*p.T, color="tab:blue", linewidth=1.2)
    a_i, = robot.plot(*reels.T, linestyle="none", marker="^", color="black", label="reels A_i")
    keep(a_i.get_label(), a_i)
    for i, a in enumerate(reels):
        robot.text(*a, f" A{i + 1}", fontsize="small")
    if "workspace_lower" in log and "workspace_upper" in log:
        box = _box_edges(log["workspace_lower"], log["workspace_upper"])
        wall, = robot.plot(*box.T, color="tab:green", alpha=0.5, linewidth=0.8,
                           label="workspace (virtual wall)")
        keep(wall.get_label(), wall)
    region = _box_edges(limits[:, 0], limits[:, 1])
    shown, = robot.plot(*region.T, color="tab:blue", alpha=0.6, linewidth=0.8, linestyle=":",
                        label="zoomed region (left)")
    shown.set_gid("zoomed region")
    keep(shown.get_label(), shown)
    # The posture of Figs. 9 and 15: the first tick with interference, else the start.
    if len(p):
        k = int(np.argmax(events)) if events.any() else 0
        hot = {int(c) for pair in pairs[active[k]] for c in pair}
        for i in range(len(reels)):
            line, = robot.plot(*np.stack([reels[i], p[k] + b[i]]).T,
                               linewidth=1.2 if i + 1 in hot else 0.7,
                               color="red" if i + 1 in hot else "0.55")
            line.set_gid(f"cable {i + 1}")
        cable, = robot.plot([], [], color="0.55", linewidth=0.7,
                            label=f"cables at t = {t[k]:.2f} s")
        keep(cable.get_label(), cable)
        if hot:
            red, = robot.plot([], [], color="red", linewidth=1.2,
                              label="cables of the active pairs")
            keep(red.get_label(), red)
    span = np.ptp(np.vstack([reels, p]) if len(p) else reels, axis=0)
    robot.set_box_aspect(np.maximum(span, 1e-3))
    robot.set_title("The robot: reels, workspace and cables", fontsize="medium")

    for ax in (zoom, robot):
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
    # Below both panels, never over the data.
    fig.legend(list(handles.values()), list(handles.keys()), loc="outside lower center",
               ncol=min(5, len(handles)), fontsize="small")
    suptitle(fig, log, f"{log_title(log)}\nPlatform trajectory, interference events and reels "
              "(Figs. 9, 15)")
    return fig
