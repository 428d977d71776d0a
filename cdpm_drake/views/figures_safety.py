"""The safety filter's work over a run (beyond the paper), drawn from its log
(docs/LOG_FORMAT.md: `filter_status`, `filter_binding`, `velocity_limited`, `max_velocity`,
`kappa`, `t_star_hand`, `pair_margin`; a dynamic plant's `pair_distances_true`): what bound the
command, the speeds asked for and commanded and their difference (m/s), the kinetostatic
margins (N) and the closest pair above its d_min (mm), the truth's beside the estimate's.

The speed limit (`max_velocity`) and the lost-margin speed cap (which slows the platform
towards safety_filter.LOST_SPEED while a margin is lost) share one bit of `filter_binding`;
they are told apart as the run's summary tells them (cli/summaries.py): a tick bound below
max_velocity is the cap. A margin counts as lost below -1 um (or -1 uN): round-off at a
barrier is not a loss (runs.sweep.metrics.D_L_TOLERANCE).
"""

import textwrap
from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from cdpm_drake.kernels.safety_filter import LOST_SPEED
from cdpm_drake.views.figure_keys import check_figure
from cdpm_drake.views.figure_layout import (FAULT_COLOR, log_title, mark_fault_time, shade_spans,
                                           spans, spans_text, suptitle)

# filter_status codes (safety_filter.STATUS_TEXT) and filter_binding bits (BIND_TEXT), for the
# views; views read logs, never a block's insides. The speed bit is drawn on two rows: the
# speed limit, and the lost-margin cap below it.
FILTER_STATUS = ("passed", "modified", "lost margins held", "braking to a hold")
FILTER_BINDING = ((1, "cable pairs"), (2, "workspace box"), (4, "kinetostatic limit"),
                  (8, "speed limit"), (16, "acceleration limit"))
SPEED_BIT = 8
# Below this a margin is lost (m for a pair, N for kappa): round-off at a barrier is not.
LOST_TOLERANCE = 1e-6
# The shade of a lost margin, and of a t* that is +inf.
LOST_COLOR = "tab:red"
INF_COLOR = "tab:brown"
# Legend labels beside the axes are wrapped to this many characters, so that a long one (a
# lost margin's spans) does not squeeze the axes.
LEGEND_WIDTH = 40
# The speed limit is drawn as a line when the speeds reach this share of it, else named in
# a note: a line far above the speeds would squash them to the bottom of the axis.
SHOW_LIMIT_FROM = 0.4


def speed_split(log: Mapping, t) -> tuple[np.ndarray, np.ndarray, float]:
    """(ticks bound at the speed limit, ticks bound at the lost-margin cap below it, the
    speed limit m/s: `max_velocity`, else the fastest command of a log without it)."""
    binding = np.asarray(log["filter_binding"]).reshape(-1).astype(int)
    speed = np.linalg.norm(np.asarray(log["velocity"], dtype=float).reshape(len(t), -1),
                           axis=1)
    v_max = (float(log["max_velocity"]) if "max_velocity" in log
             else float(speed.max(initial=0.0)))
    at_speed = (binding & SPEED_BIT) != 0
    capped = at_speed & (speed < v_max * (1.0 - 1e-6))
    return at_speed & ~capped, capped, v_max


def _draw_binding(ax, log: Mapping, t, status) -> None:
    """One row per kind of constraint that bound, the speed bit split in two."""
    binding = np.asarray(log["filter_binding"], dtype=float).reshape(-1).astype(int)
    at_limit, capped, v_max = speed_split(log, t)
    rows = []
    for bit, name in FILTER_BINDING:
        if bit == SPEED_BIT:
            limit = f" ({v_max:g} m/s)" if "max_velocity" in log else ""
            rows += [(at_limit, f"speed limit{limit}"),
                     (capped, f"lost-margin speed cap (to {LOST_SPEED:g} m/s)")]
        else:
            rows.append(((binding & bit) != 0, name))
    for row, (mask, name) in enumerate(rows):
        band = ax.fill_between(t, row - 0.4, row + 0.4, where=mask, step="mid",
                               color=f"C{row}", linewidth=0)
        band.set_gid(f"bound: {name}")
    held = status >= 3
    if held.any():
        ax.fill_between(t, -0.6, len(rows) - 0.4, where=held, step="mid",
                        color=FAULT_COLOR, alpha=0.25, linewidth=0,
                        label="braking to a hold (no safe command)")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    ax.set_yticks(range(len(rows)), [name for _, name in rows], fontsize="small")
    ax.set_ylim(-0.6, len(rows) - 0.4)
    shares = ", ".join(f"{name} {100 * np.mean(status == k):.1f} %"
                       for k, name in enumerate(FILTER_STATUS) if np.any(status == k))
    ax.set_title(f"What bound the command\n(ticks {shares})", fontsize="small")


def _draw_speeds(ax, ax_d, log: Mapping, t) -> None:
    """The speeds asked for and commanded with the speed limit and the lost-margin cap where
    it acted (ax), and |asked - commanded| (ax_d), which the speeds alone hide where the
    filter turned the command without slowing it."""
    asked_v = np.asarray(log["velocity_limited"], dtype=float).reshape(len(t), 3)
    given_v = np.asarray(log["velocity"], dtype=float).reshape(len(t), 3)
    asked, given = np.linalg.norm(asked_v, axis=1), np.linalg.norm(given_v, axis=1)
    ax.plot(t, asked, color="0.55", linewidth=2.2, label="asked (admittance, limits)")
    ax.plot(t, given, color="black", linewidth=1.0, label="commanded (safety filter)")
    _, capped, v_max = speed_split(log, t)
    if "max_velocity" in log:
        what = f"speed limit max_velocity = {v_max:g} m/s"
        if max(asked.max(initial=0.0), given.max(initial=0.0)) >= SHOW_LIMIT_FROM * v_max:
            ax.axhline(v_max, color="tab:red", linestyle="--", linewidth=1.0,
                       label=what).set_gid("max_velocity")
        else:
            # Above the axes, where no curve runs.
            ax.set_title(f"{what}: far above these speeds", loc="right", fontsize="small",
                         color="tab:red").set_gid("max_velocity")
    if capped.any():
        line, = ax.plot(t, np.where(capped, given, np.nan), color="tab:orange", linewidth=2.6,
                        label=f"held at the lost-margin speed cap (slowing to {LOST_SPEED:g} "
                        f"m/s): {spans_text(spans(capped, t), int(capped.sum()))}")
        line.set_gid("lost-margin cap")
        for a, b in spans(capped, t):
            ax.hlines(LOST_SPEED, a, b, color="tab:orange", linestyle=":", linewidth=1.2,
                      gid="LOST_SPEED")
    ax.set_ylabel("speed (m/s)")
    diff, = ax_d.plot(t, np.linalg.norm(asked_v - given_v, axis=1), color="tab:red",
                      linewidth=1.0, label="|asked - commanded|: what the filter changed")
    diff.set_gid("asked - commanded")
    ax_d.set_ylabel("change (m/s)")


def _draw_kinetostatic(ax, log: Mapping, t) -> None:
    """kappa and t* with the measured hand (N); t* = +inf and kappa < 0 shaded with spans."""
    for key, label, color in (("kappa", "kinetostatic margin kappa", "tab:purple"),
                              ("t_star_hand", "t* with the measured hand", INF_COLOR)):
        values = np.asarray(log.get(key, np.zeros(0)), dtype=float).reshape(-1)
        if values.size != t.size:
            continue
        if np.isfinite(values).any():
            line, = ax.plot(t, np.where(np.isfinite(values), values, np.nan), color=color,
                            label=label)
            line.set_gid(key)
        inf = values == np.inf
        if key == "t_star_hand" and inf.any():
            shade_spans(ax, inf, t, "t* = +inf (an internal force raises every tension): "
                        + spans_text(spans(inf, t), int(inf.sum())), "t_star_hand +inf",
                        INF_COLOR, ymin=0.9, ymax=1.0, alpha=0.35, hatch="//")
        lost = values < -LOST_TOLERANCE
        if key == "kappa" and lost.any():
            shade_spans(ax, lost, t, "kappa < 0, margin lost: "
                        + spans_text(spans(lost, t), int(lost.sum())), "kappa lost",
                        LOST_COLOR, alpha=0.18)
    ax.axhline(0.0, color="0.3", linewidth=0.8)
    ax.set_ylabel("tension (N)")


def true_pair_margin(log: Mapping, T: int) -> np.ndarray | None:
    """The closest watched pair's TRUE distance above its d_min (m), signed as `pair_margin`
    is (a pair that truly crossed counts negative), from a dynamic plant's
    `pair_distances_true`, `crossed_true` and `d_min`; None for a log without them."""
    if "pair_distances_true" not in log or "d_min" not in log:
        return None
    d = np.asarray(log["pair_distances_true"], dtype=float).reshape(T, -1)
    if d.shape[1] == 0:
        return None
    if "crossed_true" in log:
        d = np.where(np.asarray(log["crossed_true"], dtype=bool).reshape(T, -1), -d, d)
    return (d - np.asarray(log["d_min"], dtype=float).reshape(1, -1)).min(axis=1)


def _draw_pairs(ax, log: Mapping, t) -> None:
    """The closest pair above its d_min (mm), the estimate's and (dynamic plant) the truth's,
    lost margins shaded with their spans."""
    margin = np.asarray(log.get("pair_margin", np.zeros(0)), dtype=float).reshape(-1)
    truth = true_pair_margin(log, t.size)
    for values, label, gid, style in (
            (margin, "closest pair above its d_min (controller's estimate)", "pair_margin",
             dict(color="tab:orange", linewidth=1.4)),
            (truth, "closest pair above its d_min (true, dynamic plant)", "pair_margin_true",
             dict(color="tab:blue", linewidth=1.0, linestyle="--"))):
        if values is None or values.size != t.size or not np.isfinite(values).any():
            continue
        line, = ax.plot(t, 1000.0 * np.where(np.isfinite(values), values, np.nan),
                        label=label if truth is not None else label.split(" (")[0], **style)
        line.set_gid(gid)
        lost = values < -LOST_TOLERANCE
        if lost.any():
            which = "estimate" if gid == "pair_margin" else "truth"
            shade_spans(ax, lost, t, f"pair margin lost ({which}): "
                        + spans_text(spans(lost, t), int(lost.sum())), f"{gid} lost",
                        style["color"] if gid == "pair_margin_true" else LOST_COLOR,
                        alpha=0.18, **({"hatch": "\\\\"} if gid == "pair_margin_true"
                                       else {}))
    ax.axhline(0.0, color="0.3", linewidth=0.8)
    ax.set_ylabel("distance (mm)")


def figure_safety(log: Mapping) -> Figure:
    """The safety filter over time: what bound the command (a band per kind of constraint,
    the speed limit apart from the lost-margin cap; where it braked to a hold), the speeds
    asked for and commanded (m/s) with the speed limit and the cap, |asked - commanded|
    (m/s), the kinetostatic margin kappa and t* with the measured hand (N), and the closest
    pair's distance above its d_min (mm), the truth's too on a dynamic plant."""
    check_figure(log, "safety")
    t = np.asarray(log["time"], dtype=float)
    status = np.asarray(log["filter_status"], dtype=float).reshape(-1)
    fig = Figure(figsize=(9, 11), layout="constrained")
    ax_b, ax_v, ax_d, ax_k, ax_p = fig.subplots(5, 1, sharex=True)
    _draw_binding(ax_b, log, t, status)
    _draw_speeds(ax_v, ax_d, log, t)
    _draw_kinetostatic(ax_k, log, t)
    _draw_pairs(ax_p, log, t)
    ax_p.set_xlabel("time (s)")
    for ax in (ax_b, ax_v, ax_d, ax_k, ax_p):
        ax.grid(True, alpha=0.3)
        mark_fault_time(ax, log)
        handles, labels = ax.get_legend_handles_labels()
        if ax is not ax_b and handles:
            ax.legend(handles, [textwrap.fill(text, LEGEND_WIDTH) for text in labels],
                      loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    suptitle(fig, log, f"{log_title(log)}\nThe safety filter: what it changed and the margins "
              "it kept")
    return fig
