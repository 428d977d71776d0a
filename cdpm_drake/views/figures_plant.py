"""What the reels and the platform did, drawn from a log (docs/LOG_FORMAT.md): cable lengths
and reel speed commands; the cable tensions (the dynamic plant's truth, a tension-controlled
run's estimate, target and t*); the controller's pose estimate against the true platform (a
dynamic plant's log). Lengths in m, speeds in m/s, tensions in N, time in s; cables 1..m.
"""

import textwrap
from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from cdpm_drake.views.figure_keys import check_figure
from cdpm_drake.views.figure_layout import (log_title, mark_fault_time, shade_spans, spans,
                                           spans_text, suptitle)

# The tension target's floor and ceiling: neither a cable's colour nor the estimate's grey.
LIMIT_COLOR = "darkgoldenrod"
# The ceiling is drawn when a tension reaches this share of it, else named in a note: a line
# far above the tensions would squash them to the panels' bottoms.
SHOW_CEILING_FROM = 0.9
# Legend labels beside an axis are wrapped to this many characters (the axis keeps its width).
LEGEND_WIDTH = 40


# --- cable lengths and reel speeds ----------------------------------------------------------------

# Cable i's colour and style: ten colours, then the same colours dashed, so up to 20 cables
# stay distinguishable.
_CABLE_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown",
                 "tab:pink", "tab:gray", "tab:olive", "tab:cyan")


def cable_style(i: int) -> dict:
    """Line colour and style of cable i (1-based)."""
    return dict(color=_CABLE_COLORS[(i - 1) % 10],
                linestyle=("-", "--", ":")[min((i - 1) // 10, 2)])


def figure_cables(log: Mapping) -> Figure:
    """Cable lengths l_i (m) and reel speed commands l_dot_i (m/s, docs/LOG_FORMAT.md's
    reel_velocity) vs time (s), cables numbered 1..m."""
    check_figure(log, "cables")
    t = np.asarray(log["time"], dtype=float)
    lengths = np.asarray(log["lengths"], dtype=float).reshape(len(t), -1)
    speeds = np.asarray(log["reel_velocity"], dtype=float).reshape(len(t), -1)
    fig = Figure(figsize=(9, 6.5), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    for i in range(1, lengths.shape[1] + 1):
        top.plot(t, lengths[:, i - 1], label=f"cable {i}", linewidth=1.2, **cable_style(i))
    for i in range(1, speeds.shape[1] + 1):
        bottom.plot(t, speeds[:, i - 1], label=f"cable {i}", linewidth=1.0, **cable_style(i))
    top.set_ylabel("cable length l_i (m)")
    bottom.set_ylabel("reel speed command (m/s)")
    bottom.set_xlabel("time (s)")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
        mark_fault_time(ax, log)
    if lengths.shape[1]:
        top.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small",
                   ncol=1 if lengths.shape[1] <= 10 else 2)
    suptitle(fig, log, f"{log_title(log)}\nCable lengths and reel speeds")
    return fig


# --- The dynamic plant: tensions and pose error ---------------------------------------------


def figure_tensions(log: Mapping) -> Figure:
    """Each cable's tension (N) vs time (s). A dynamic plant's log without tension control:
    the true tensions on one axis, and below one row per cable (1..m) with a mark at every
    tick where it was slack, so that cables slack at the same time never hide each other. A
    tension-controlled run's log: one panel per cable (tensions_per_cable)."""
    check_figure(log, "tensions")
    if "tension_estimate" in log:
        return tensions_per_cable(log)
    t = np.asarray(log["time"], dtype=float)
    tensions = np.asarray(log["tensions"], dtype=float).reshape(len(t), -1)
    m = tensions.shape[1]
    fig = Figure(figsize=(9, 5.5 + 0.12 * m), layout="constrained")
    ax, rows = fig.subplots(2, 1, sharex=True,
                            gridspec_kw={"height_ratios": [3.0, 0.6 + 0.12 * m]})
    for i in range(1, m + 1):
        ax.plot(t, tensions[:, i - 1], linewidth=1.0, label=f"cable {i}", **cable_style(i))
    ax.set_ylabel("tension (N)")
    _slack_rows(rows, log, t, m)
    for a in (ax, rows):
        a.grid(True, alpha=0.3)
        mark_fault_time(a, log)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    suptitle(fig, log, f"{log_title(log)}\nCable tensions (dynamic plant)")
    return fig


def _slack_rows(rows, log: Mapping, t, m: int) -> None:
    """One row per cable (1 on top) with a mark at each tick it was slack."""
    slack = np.asarray(log["slack"]).reshape(len(t), -1) > 0.5
    for i in range(1, m + 1):
        n = int(slack[:, i - 1].sum())
        if n:
            ticks, = rows.plot(t[slack[:, i - 1]], np.full(n, i), "|",
                               color=cable_style(i)["color"], markersize=7,
                               label=f"cable {i} slack ({n} ticks)")
            ticks.set_gid(f"slack cable {i}")
    rows.set_yticks(range(1, m + 1), [str(i) for i in range(1, m + 1)])
    rows.set_ylim(m + 0.5, 0.5)  # cable 1 on top, as in the legend
    rows.set_ylabel("slack\n(cable)")
    if not slack.any():
        rows.text(0.5, 0.5, "no cable went slack", ha="center", va="center",
                  transform=rows.transAxes, color="0.4")


def floor_used(log: Mapping, T: int) -> np.ndarray | None:
    """The target's floor each tick (N): its weakest cable's target, `tension_target`'s
    smallest (controller.min_tension where the floor held, lower where the pose or the
    ceiling allow no more, never below controller.tension_floor); None without a target."""
    if "tension_target" not in log:
        return None
    return np.asarray(log["tension_target"], dtype=float).reshape(T, -1).min(axis=1)


def tensions_per_cable(log: Mapping) -> Figure:
    """A tension-controlled run (docs/LOG_FORMAT.md): one panel per cable (1..m), in that
    cable's colour, with the plant's true tension (solid, a dynamic plant's), the
    controller's estimate (dashed) and its target (dotted), and the target's floor as used
    each tick; below, the floor beside t*, the largest achievable minimum tension at the
    estimated pose (shaded where +inf), and on a dynamic plant the slack rows."""
    t = np.asarray(log["time"], dtype=float)
    T = len(t)
    estimate = np.asarray(log["tension_estimate"], dtype=float).reshape(T, -1)
    m = estimate.shape[1]
    series = {"true tension (plant)": (np.asarray(log["tensions"], dtype=float).reshape(T, -1)
                                       if "tensions" in log else None, "-", 1.3),
              "controller's estimate": (estimate, "--", 1.0),
              "target": (np.asarray(log["tension_target"], dtype=float).reshape(T, -1)
                         if "tension_target" in log else None, ":", 1.2)}
    floor = floor_used(log, T)
    grid_rows = (m + 1) // 2
    truth = "slack" in log and series["true tension (plant)"][0] is not None
    fig = Figure(figsize=(11, 2.0 * grid_rows + 2.6 + (0.8 + 0.1 * m if truth else 0.0)),
                 layout="constrained")
    ratios = [1.0] * grid_rows + [1.1] + ([0.4 + 0.06 * m] if truth else [])
    gs = fig.add_gridspec(len(ratios), 2, height_ratios=ratios)
    first = fig.add_subplot(gs[0, 0])
    panels = [first] + [fig.add_subplot(gs[k // 2, k % 2], sharex=first, sharey=first)
                        for k in range(1, m)]
    below = fig.add_subplot(gs[grid_rows, :], sharex=first)
    rows = fig.add_subplot(gs[grid_rows + 1, :], sharex=first) if truth else None
    ceiling = _ceiling(log, [v for v, _, _ in series.values() if v is not None])
    for i, ax in enumerate(panels, start=1):
        color = cable_style(i)["color"]
        for what, (values, style, width) in series.items():
            if values is not None:
                line, = ax.plot(t, values[:, i - 1], color=color, linestyle=style,
                                linewidth=width, label=what)
                line.set_gid(f"{what} cable {i}")
        if floor is not None:
            ax.plot(t, floor, color=LIMIT_COLOR, linewidth=1.0, gid="floor used")
        if ceiling is not None:
            ax.axhline(ceiling, color=LIMIT_COLOR, linestyle="-.", linewidth=1.0,
                       gid="controller_max_tension")
        ax.set_title(f"cable {i}", fontsize="small", pad=2)
        ax.tick_params(labelbottom=False)
    for ax in panels[::2]:
        ax.set_ylabel("tension (N)")
    _floor_and_t_star(below, log, t, floor, ceiling)
    if rows is not None:
        _slack_rows(rows, log, t, m)
    (rows or below).set_xlabel("time (s)")
    for a in panels + [below] + ([rows] if rows is not None else []):
        a.grid(True, alpha=0.3)
        mark_fault_time(a, log)
    _tension_legend(fig, series, floor is not None, ceiling)
    what = ("the plant's (solid), the controller's estimate (dashed) and target (dotted)"
            if truth else "the controller's estimate (dashed) and target (dotted)")
    suptitle(fig, log, f"{log_title(log)}\nCable tensions per cable: {what}; the target's "
             "floor as used and t*")
    return fig


def _ceiling(log: Mapping, values) -> float | None:
    """controller.max_tension when the tensions come near it (SHOW_CEILING_FROM of it), else
    None."""
    if "controller_max_tension" not in log:
        return None
    ceiling = float(log["controller_max_tension"])
    finite = [v[np.isfinite(v)] for v in values]
    top = max((float(v.max()) for v in finite if v.size), default=0.0)
    return ceiling if np.isfinite(ceiling) and top >= SHOW_CEILING_FROM * ceiling else None


def _floor_and_t_star(ax, log: Mapping, t, floor, ceiling) -> None:
    """The target's floor as used each tick beside t* at the estimated pose (N), with what
    the floor was set to (controller.min_tension) and the ceiling named."""
    lo = float(log["controller_min_tension"]) if "controller_min_tension" in log else None
    if floor is not None:
        text = f"target's floor as used (its weakest cable): lowest {floor.min():.2f} N"
        if lo is not None and np.isfinite(lo):
            text += f", set to min_tension = {lo:g} N"
        ax.plot(t, floor, color=LIMIT_COLOR, linewidth=1.4, label=text, gid="floor used")
    if "t_star" in log:
        t_star = np.asarray(log["t_star"], dtype=float).reshape(len(t), -1)[:, 0]
        if np.isfinite(t_star).any():
            shown = np.where(np.isfinite(t_star), t_star, np.nan)
            line, = ax.plot(t, shown, color="black", linewidth=1.2,
                            label="t* at the estimated pose")
            line.set_gid("t_star")
        inf = t_star == np.inf
        if inf.any():
            shade_spans(ax, inf, t, "t* = +inf (an internal force raises every tension): "
                        + spans_text(spans(inf, t), int(inf.sum())), "t_star +inf", "0.5",
                        ymin=0.88, ymax=1.0, alpha=0.35, hatch="//")
    if "controller_max_tension" in log and ceiling is None:
        ax.set_title(f"ceiling max_tension = {float(log['controller_max_tension']):g} N: "
                     "above the cables' panels", loc="right", fontsize="small",
                     color=LIMIT_COLOR).set_gid("controller_max_tension")
    ax.set_ylabel("tension (N)")
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, [textwrap.fill(text, LEGEND_WIDTH) for text in labels],
                  loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")


def _tension_legend(fig, series, floor: bool, ceiling) -> None:
    """One legend for the cable panels: each series' style, in grey (every cable has its own
    colour), only for what is drawn."""
    handles = [Line2D([], [], color="0.3", linestyle=style, linewidth=width, label=what)
               for what, (values, style, width) in series.items() if values is not None]
    if floor:
        handles.append(Line2D([], [], color=LIMIT_COLOR, linewidth=1.0,
                              label="target's floor as used"))
    if ceiling is not None:
        handles.append(Line2D([], [], color=LIMIT_COLOR, linestyle="-.", linewidth=1.0,
                              label=f"ceiling max_tension = {ceiling:g} N"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles),
               fontsize="small")


def pose_model(log: Mapping) -> str:
    """What the run's controller assumed of the pose, from the keys its log holds
    (docs/LOG_FORMAT.md): `rpy` only for `controller.pose: full`, `tension_estimate` only with
    its tension control (the one whose forward kinematics stretches the cables)."""
    if "rpy" not in log:
        return "translating platform, rigid cables"
    if "tension_estimate" in log:
        return "full pose, cables stretched under the estimated tensions"
    return "full pose, rigid cables"


def figure_pose_error(log: Mapping) -> Figure:
    """The controller's position estimate minus the true position (mm, per axis and its norm),
    and the platform's true roll, pitch, yaw (deg) beside the controller's own estimate of
    them (a full-pose controller's `rpy`; the translating one assumes a level platform), vs
    time (s) (a dynamic plant's log)."""
    check_figure(log, "pose_error")
    t = np.asarray(log["time"], dtype=float)
    error = 1000.0 * (np.asarray(log["p"], float) - np.asarray(log["p_true"], float))
    rpy = np.degrees(np.asarray(log["rpy_true"], dtype=float))
    estimate = (np.degrees(np.asarray(log["rpy"], dtype=float)).reshape(len(t), 3)
                if "rpy" in log else None)
    fig = Figure(figsize=(9, 6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    for c, axis in enumerate("xyz"):
        top.plot(t, error[:, c], linewidth=1.0, label=f"p_{axis} - p_true,{axis}")
    top.plot(t, np.linalg.norm(error, axis=1), color="black", linewidth=1.2, label="|p - p_true|")
    top.set_ylabel("position estimate error (mm)")
    for c, name in enumerate(("roll", "pitch", "yaw")):
        color = f"C{c}"
        if estimate is None:
            bottom.plot(t, rpy[:, c], color=color, linewidth=1.0, label=f"{name} (true)")
            continue
        # As in the distances figure: the truth wide and solid, the estimate thin and dashed
        # on top, so that both show where they coincide.
        bottom.plot(t, rpy[:, c], color=color, linewidth=2.2, alpha=0.6,
                    label=f"{name} (true)")
        bottom.plot(t, estimate[:, c], color=color, linewidth=1.0, linestyle="--",
                    label=f"{name} (controller's estimate)")
    bottom.set_ylabel("platform rotation (deg)")
    bottom.set_xlabel("time (s)")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
        mark_fault_time(ax, log)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    suptitle(fig, log, f"{log_title(log)}\nThe controller's pose estimate ({pose_model(log)}) "
              "against the true platform")
    return fig
