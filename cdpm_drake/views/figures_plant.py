"""What the reels and the platform did, drawn from a log (docs/LOG_FORMAT.md): cable lengths
and reel speed commands; the cable tensions (the dynamic plant's truth, a tension-controlled
run's estimate, target and t*); the controller's pose estimate against the true platform (a
dynamic plant's log). Lengths in m, speeds in m/s, tensions in N, time in s; cables 1..m.
"""

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from cdpm_drake.views.figure_keys import check_figure
from cdpm_drake.views.figure_layout import log_title, mark_fault_time, suptitle

# The tension target's floor and ceiling: neither a cable's colour nor the estimate's grey.
LIMIT_COLOR = "darkgoldenrod"


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
    """Each cable's tension (N) vs time (s): the dynamic plant's true tensions, and below one
    row per cable (1..m) with a mark at every tick where it was slack, so that cables slack at
    the same time never hide each other. A tension-controlled run's log adds, in the same
    colours, the controller's estimate of each tension (dashed; alone on the robot, where the
    log has no truth), the target's floor and ceiling (controller.min_tension, max_tension:
    log keys controller_min_tension, controller_max_tension) and t*, the largest achievable
    minimum tension at the estimated pose (where it is below the floor, the floor is
    lowered to it; where it is +inf, not drawn)."""
    check_figure(log, "tensions")
    t = np.asarray(log["time"], dtype=float)
    truth = "tensions" in log and "slack" in log
    estimate = (np.asarray(log["tension_estimate"], dtype=float).reshape(len(t), -1)
                if "tension_estimate" in log else None)
    tensions = (np.asarray(log["tensions"], dtype=float).reshape(len(t), -1) if truth
                else estimate)
    m = tensions.shape[1]
    fig = Figure(figsize=(9, 5.5 + 0.12 * m), layout="constrained")
    if truth:
        ax, rows = fig.subplots(2, 1, sharex=True,
                                gridspec_kw={"height_ratios": [3.0, 0.6 + 0.12 * m]})
    else:
        ax, rows = fig.subplots(), None
    for i in range(1, m + 1):
        style = cable_style(i)
        if truth:
            ax.plot(t, tensions[:, i - 1], linewidth=1.0, label=f"cable {i}", **style)
        if estimate is not None:
            line, = ax.plot(t, estimate[:, i - 1], color=style["color"],
                            linewidth=0.9 if truth else 1.0,
                            linestyle="--" if truth else style["linestyle"],
                            label="_" if truth else f"cable {i} (estimate)")
            line.set_gid(f"estimate cable {i}")
    if estimate is not None:
        if truth:  # one legend entry for the dashes of every cable
            ax.plot([], [], color="0.3", linestyle="--", linewidth=0.9,
                    label="controller's estimate (dashed)")
        for key, style, what in (("controller_min_tension", "--", "floor min_tension"),
                                 ("controller_max_tension", "-.", "ceiling max_tension")):
            if key in log and np.isfinite(float(log[key])):
                value = float(log[key])
                ax.axhline(value, color=LIMIT_COLOR, linestyle=style, linewidth=1.4,
                           label=f"{what} = {value:g} N").set_gid(key)
        if "t_star" in log:
            t_star = np.asarray(log["t_star"], dtype=float).reshape(len(t), -1)[:, 0]
            shown = np.where(np.isfinite(t_star), t_star, np.nan)
            line, = ax.plot(t, shown, color="black", linewidth=1.6, alpha=0.8,
                            label="t* at the estimated pose")
            line.set_gid("t_star")
    ax.set_ylabel("tension (N)")
    if rows is not None:
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
        rows.set_xlabel("time (s)")
        if not slack.any():
            rows.text(0.5, 0.5, "no cable went slack", ha="center", va="center",
                      transform=rows.transAxes, color="0.4")
    else:
        ax.set_xlabel("time (s)")
    for a in (ax, rows):
        if a is not None:
            a.grid(True, alpha=0.3)
            mark_fault_time(a, log)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    what = ("Cable tensions (dynamic plant)" if estimate is None else
            "Cable tensions: the plant's (solid) and the controller's estimate (dashed), the "
            "target's floor and ceiling, t*" if truth else
            "Cable tensions as the controller estimates them, the target's floor and ceiling, t*")
    suptitle(fig, log, f"{log_title(log)}\n{what}")
    return fig


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
