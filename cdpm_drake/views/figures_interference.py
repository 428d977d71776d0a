"""The paper's interference figures drawn from a log (docs/LOG_FORMAT.md): the distance
between the cables of each active pair with d_l and d_u (Fig. 10), and the interference force
intensity as the controller applies it (the logistic, eqs. 26-28, Fig. 8). Distances in mm,
forces in N, time in s; cables numbered 1..m.
"""

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from cdpm_drake.kernels.interference import logistic_intensity
from cdpm_drake.views.figure_keys import check_figure
from cdpm_drake.views.figure_layout import FAULT_COLOR, log_title, mark_fault_time, suptitle


def _pair_label(pair) -> str:
    """The legend label of a pair: "cables i-j" (1-based cable numbers)."""
    return f"cables {int(pair[0])}-{int(pair[1])}"


# --- Fig. 10: distances -------------------------------------------------------------------------


def figure_distances(log: Mapping) -> Figure:
    """Distance (mm) vs time (s) of each pair that was active at some tick, with the d_l and d_u
    lines of those pairs (Fig. 10). When no pair was ever active, the closest pair is shown."""
    check_figure(log, "distances")
    t = np.asarray(log["time"], dtype=float)
    d = np.asarray(log["pair_distances"], dtype=float).reshape(len(t), -1)
    pairs = np.asarray(log["pairs"]).reshape(-1, 2)
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    near = np.asarray(log["active"]).reshape(len(t), -1).any(axis=0)
    truth = None
    if "pair_distances_true" in log:
        # The plant's ground truth (the dynamic plant's true, rotated pose) beside the
        # controller's estimate: a pair truly within its d_u is shown even if the estimate
        # never was.
        truth = np.asarray(log["pair_distances_true"], dtype=float).reshape(len(t), -1)
        d_u = np.asarray(log["d_u"], dtype=float).reshape(-1)
        near = near | (truth <= np.where(np.isfinite(d_u), d_u, -np.inf)).any(axis=0)
    shown = np.flatnonzero(near)
    heading = "Distance between the cables of each active pair"
    if shown.size == 0 and d.shape[1] and len(t):
        shown = np.array([int(np.argmin((d if truth is None else truth).min(axis=0)))])
        heading = "No pair came within d_u; the closest pair"
    for n, k in enumerate(shown):
        color = f"C{n % 10}"
        label = _pair_label(pairs[k])
        if truth is None:
            ax.plot(t, 1000.0 * d[:, k], color=color, label=label)
            continue
        ax.plot(t, 1000.0 * truth[:, k], color=color, linewidth=2.2,
                label=f"{label} true (plant's pose)")
        ax.plot(t, 1000.0 * d[:, k], color=color, linewidth=1.2, linestyle="--",
                label=f"{label} controller's estimate")
    for key, style in (("d_l", "--"), ("d_u", ":")):
        values = np.asarray(log[key], dtype=float).reshape(-1)[shown] if shown.size else []
        for v in np.unique(np.asarray(values)[np.isfinite(values)]):
            ax.axhline(1000.0 * v, color="0.3", linestyle=style,
                       label=f"{key} = {1000.0 * v:g} mm")
    if "d_min" in log and "filter_status" in log and shown.size:
        # The safety filter's hard floor, where it differs from d_l (drawn there otherwise).
        d_l = np.asarray(log["d_l"], dtype=float).reshape(-1)[shown]
        d_min = np.asarray(log["d_min"], dtype=float).reshape(-1)[shown]
        for v in np.unique(d_min[np.isfinite(d_min) & (d_min != d_l)]):
            ax.axhline(1000.0 * v, color=FAULT_COLOR, linestyle="-", linewidth=0.8,
                       label=f"d_min = {1000.0 * v:g} mm (the safety filter's floor)")
    if d.shape[1] == 0:
        ax.text(0.5, 0.5, "the robot has no watched cable pairs", ha="center",
                transform=ax.transAxes)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance between cables (mm)")
    ax.set_title(f"{heading} (Fig. 10)", fontsize="medium")
    ax.grid(True, alpha=0.3)
    mark_fault_time(ax, log)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    suptitle(fig, log, log_title(log))
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


def applied_curve(d_l: float, d_u: float, F_u: float, eps: float, num: int = 400):
    """(distances m, intensity N) of what the interference block applies to an uncrossed pair
    over logistic_grid: the logistic (eq. 26) up to d_u and zero beyond, where the pair is
    not active (interference.py: `near = dist <= d_u`); d_u appears twice, with eps and with
    0, so that the step from eps to zero is drawn as the vertical it is."""
    d = logistic_grid(d_l, d_u, num)
    tol = 1e-9 * (d_u - d_l)  # a grid point at d_u up to round-off is the step's
    below, beyond = d[d < d_u - tol], d[d > d_u + tol]
    x = np.concatenate([below, [d_u, d_u], beyond])
    y = np.concatenate([logistic_intensity(below, d_l, d_u, F_u, eps),
                        [logistic_intensity(d_u, d_l, d_u, F_u, eps), 0.0],
                        np.zeros(beyond.size)])
    return x, y


def figure_logistic(log: Mapping) -> Figure:
    """Interference force intensity alpha (N) vs cable distance (mm), one axis per distinct set
    of logistic parameters of the log (eqs. 26-28, Fig. 8), as the controller applies it: the
    logistic up to d_u, zero beyond (the step at d_u that F_int takes, see forces.png), the
    logistic's own tail beyond d_u faint; d_l, d_u, F_u - eps and eps marked."""
    check_figure(log, "logistic")
    sets = logistic_sets(log)
    fig = Figure(figsize=(max(8, 5 * len(sets)), 4.5), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, max(1, len(sets)), squeeze=False)[0])
    for ax, ((d_l, d_u, F_u, eps), users) in zip(axes, sets):
        who = ("cables " + ", ".join(f"{i}-{j}" for i, j in users) if len(users) <= 4
               else f"{len(users)} cable pairs")
        d, alpha = applied_curve(d_l, d_u, F_u, eps)
        applied, = ax.plot(1000.0 * d, alpha, color="tab:blue", linewidth=1.8, zorder=3,
                           label=f"applied: F_u = {F_u:g} N, eps = {eps:g} N")
        applied.set_gid("applied")
        tail = d[d >= d_u]
        faint, = ax.plot(1000.0 * tail, logistic_intensity(tail, d_l, d_u, F_u, eps),
                         color="tab:blue", linewidth=1.0, linestyle=":", alpha=0.5,
                         label="eq. 26 beyond d_u (not applied)")
        faint.set_gid("beyond d_u")
        ax.axvline(1000.0 * d_l, color="0.3", linestyle="--", linewidth=0.8,
                   label=f"d_l = {1000 * d_l:g} mm")
        ax.axvline(1000.0 * d_u, color="0.3", linestyle=":", linewidth=0.8,
                   label=f"d_u = {1000 * d_u:g} mm")
        ax.axhline(F_u - eps, color="tab:red", linestyle="--", linewidth=0.6,
                   label=f"F_u - eps = {F_u - eps:g} N")
        ax.axhline(eps, color="tab:red", linestyle=":", linewidth=0.6, label=f"eps = {eps:g} N")
        marks, = ax.plot([1000.0 * d_l, 1000.0 * d_u], [F_u - eps, eps], linestyle="none",
                         marker="o", color="tab:red", zorder=4)
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
    suptitle(fig, log, f"{log_title(log)}\nInterference force intensity as applied: the "
              "logistic function (eqs. 26-28, Fig. 8) within d_u, zero beyond")
    return fig
