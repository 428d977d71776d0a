"""The safety filter's work over a run (beyond the paper), drawn from its log
(docs/LOG_FORMAT.md: `filter_status`, `filter_binding`, `velocity_limited`, `kappa`,
`t_star_hand`, `pair_margin`): what bound the command, the speeds asked for and commanded
(m/s), the kinetostatic margins (N) and the closest pair above its d_min (mm).
"""

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from cdpm_drake.views.figure_keys import check_figure
from cdpm_drake.views.figure_layout import FAULT_COLOR, log_title, mark_fault_time, suptitle

# --- the safety filter (beyond the paper) -------------------------------------------------------

# filter_status codes (safety_filter.STATUS_TEXT) and filter_binding bits (BIND_TEXT), for the
# views; views read logs, never a block's insides.
FILTER_STATUS = ("passed", "modified", "lost margins held", "braking to a hold")
FILTER_BINDING = ((1, "cable pairs"), (2, "workspace box"), (4, "kinetostatic limit"),
                  (8, "speed limit"), (16, "acceleration limit"))


def figure_safety(log: Mapping) -> Figure:
    """The safety filter over time: what it did to the command (which kinds of barrier bound,
    as bands, and where it braked to a hold), the speeds asked for and commanded (m/s), the
    kinetostatic margin kappa and t* with the measured hand (N), and the closest pair's
    distance above its d_min (mm)."""
    check_figure(log, "safety")
    t = np.asarray(log["time"], dtype=float)
    status = np.asarray(log["filter_status"], dtype=float).reshape(-1)
    binding = np.asarray(log["filter_binding"], dtype=float).reshape(-1).astype(int)
    fig = Figure(figsize=(9, 9), layout="constrained")
    ax_b, ax_v, ax_k, ax_p = fig.subplots(4, 1, sharex=True,
                                          height_ratios=(1.0, 1.0, 1.0, 1.0))
    for row, (bit, name) in enumerate(FILTER_BINDING):
        ax_b.fill_between(t, row - 0.4, row + 0.4, where=(binding & bit) != 0, step="mid",
                          color=f"C{row}", linewidth=0)
    held = status >= 3
    if held.any():
        ax_b.fill_between(t, -0.6, len(FILTER_BINDING) - 0.4, where=held, step="mid",
                          color=FAULT_COLOR, alpha=0.25, linewidth=0,
                          label="braking to a hold (no safe command)")
        ax_b.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    ax_b.set_yticks(range(len(FILTER_BINDING)), [name for _, name in FILTER_BINDING],
                    fontsize="small")
    ax_b.set_ylim(-0.6, len(FILTER_BINDING) - 0.4)
    shares = ", ".join(f"{name} {100 * np.mean(status == k):.1f} %"
                       for k, name in enumerate(FILTER_STATUS) if np.any(status == k))
    ax_b.set_title(f"What bound the command\n(ticks {shares})", fontsize="small")
    asked = np.linalg.norm(np.asarray(log["velocity_limited"], dtype=float), axis=1)
    given = np.linalg.norm(np.asarray(log["velocity"], dtype=float), axis=1)
    ax_v.plot(t, asked, color="0.55", linewidth=2.2, label="asked (admittance, limits)")
    ax_v.plot(t, given, color="black", linewidth=1.0, label="commanded (safety filter)")
    ax_v.set_ylabel("speed (m/s)")
    for key, label, color in (("kappa", "kinetostatic margin kappa", "tab:purple"),
                              ("t_star_hand", "t* with the measured hand", "tab:brown")):
        values = np.asarray(log.get(key, np.zeros(0)), dtype=float).reshape(-1)
        if values.size == t.size and np.isfinite(values).any():
            # (t* is +inf where an internal force raises every tension: not drawn there.)
            ax_k.plot(t, np.where(np.isfinite(values), values, np.nan), color=color,
                      label=label)
    ax_k.axhline(0.0, color="0.3", linewidth=0.8)
    ax_k.set_ylabel("tension (N)")
    margin = np.asarray(log.get("pair_margin", np.zeros(0)), dtype=float).reshape(-1)
    if margin.size == t.size and np.isfinite(margin).any():
        ax_p.plot(t, 1000.0 * np.where(np.isfinite(margin), margin, np.nan),
                  color="tab:orange", label="closest pair above its d_min")
    ax_p.axhline(0.0, color="0.3", linewidth=0.8)
    ax_p.set_ylabel("distance (mm)")
    ax_p.set_xlabel("time (s)")
    for ax in (ax_b, ax_v, ax_k, ax_p):
        ax.grid(True, alpha=0.3)
        mark_fault_time(ax, log)
        if ax is not ax_b and ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    suptitle(fig, log, f"{log_title(log)}\nThe safety filter: what it changed and the margins "
              "it kept")
    return fig
