"""The tick timing of a real-time run (`cdpm run`), drawn from its log (docs/LOG_FORMAT.md:
`wall`, `compute`, `watchdog_limit`): tick period and compute time per tick, in ms, vs log
time in s.
"""

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from cdpm_drake.views.figure_keys import check_figure
from cdpm_drake.views.figure_layout import FAULT_COLOR, log_title, mark_fault_time, suptitle

# --- tick timing of a real-time run ---------------------------------------------------------------


def tick_periods(log: Mapping) -> tuple[np.ndarray, np.ndarray]:
    """Log time (s) of each tick after the first and the wall-clock time since the tick
    before it (s): the tick period of a `cdpm run` log."""
    t = np.asarray(log["time"], dtype=float).reshape(-1)
    wall = np.asarray(log["wall"], dtype=float).reshape(-1)
    return t[1:], np.diff(wall)


def _nominal_period(log: Mapping) -> float:
    t = np.asarray(log["time"], dtype=float).reshape(-1)
    return float(np.median(np.diff(t))) if t.size > 1 else float("nan")


def figure_timing(log: Mapping) -> Figure:
    """Tick period (ms, wall-clock time between consecutive ticks) and compute time per tick
    (ms) vs log time (s) of a real-time run, with the nominal period and the watchdog limit
    (`watchdog_limit`, s) drawn; only logs of `cdpm run` have these columns (`wall`; older
    ones lack `compute` and `watchdog_limit`, which are then left out)."""
    check_figure(log, "timing")
    t = np.asarray(log["time"], dtype=float).reshape(-1)
    t_p, period = tick_periods(log)
    compute = np.asarray(log.get("compute", np.full(len(t), np.nan)), dtype=float).reshape(-1)
    nominal = _nominal_period(log)
    limit = float(log["watchdog_limit"]) if "watchdog_limit" in log else float("nan")
    fig = Figure(figsize=(9, 6.5), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    top.plot(t_p, 1000.0 * period, color="tab:blue", linewidth=0.8, label="tick period")
    if np.any(np.isfinite(compute)):
        bottom.plot(t, 1000.0 * compute, color="tab:purple", linewidth=0.8,
                    label="compute time per tick")
    else:
        bottom.text(0.5, 0.5, "compute time not recorded in this log", ha="center",
                    transform=bottom.transAxes)
    for ax in (top, bottom):
        if np.isfinite(nominal):
            ax.axhline(1000.0 * nominal, color="0.2", linestyle="--", linewidth=1.0,
                       label=f"period {1000.0 * nominal:g} ms").set_gid("period")
        if np.isfinite(limit):
            ax.axhline(1000.0 * limit, color=FAULT_COLOR, linestyle=":", linewidth=1.2,
                       label=f"watchdog limit {1000.0 * limit:g} ms").set_gid("watchdog")
        ax.set_ylim(bottom=0.0)
        ax.grid(True, alpha=0.3)
        mark_fault_time(ax, log)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    top.set_ylabel("tick period (ms)")
    bottom.set_ylabel("compute per tick (ms)")
    bottom.set_xlabel("time (s)")
    stats = ""
    if period.size:
        p50, p99 = np.percentile(1000.0 * period, [50, 99])
        stats = (f": period p50 {p50:.2f} ms, p99 {p99:.2f} ms, "
                 f"max {1000.0 * period.max():.2f} ms")
    suptitle(fig, log, f"{log_title(log)}\nTick timing of the real-time run{stats}")
    return fig
