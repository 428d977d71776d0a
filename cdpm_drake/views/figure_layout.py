"""What every figure of a log shares: its title (the scenario and robot, wrapped to the
figure's width) and the mark of a run that did not complete.

A run that ended on a fault (log keys `ending`, `fault_time`, `fault_message`) has the fault
marked in every figure: a vertical line with its label on every time axis (mark_fault_time),
a marker on the trajectory, its message as the title's last lines (suptitle). Stretches of
ticks (a lost margin, an infinite t*) are shaded with their times (shade_spans). An interrupted
run is marked the same way in grey. Logs without those keys (older logs) read as completed.
"""

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from cdpm_drake.runs.log import run_fault, run_interrupted

# A fault's mark: its line and label on the time axes, its marker on the trajectory.
FAULT_COLOR = "crimson"
# An interrupted run (Ctrl-C, SIGTERM) is marked as a fault is, in a neutral dark grey: it is
# where the log ends, not an error (and orange is the trajectory's "within d_u").
INTERRUPT_COLOR = "0.2"
# Most lines of a fault message in a title; the rest is cut with "...".
TITLE_FAULT_LINES = 6


def log_title(log: Mapping) -> str:
    """The scenario and robot the log names: "scenario (robot)"."""
    scen = str(log["scenario_name"]) if "scenario_name" in log else ""
    robot = str(log["robot_name"]) if "robot_name" in log else ""
    return f"{scen} ({robot})" if scen and robot else scen or robot


def run_stop(log: Mapping) -> tuple[str, float, str, str] | None:
    """How a run that did not complete is marked: (gid "fault" or "interrupted", time s (NaN
    when unknown), the title's line, colour), or None for a completed run."""
    fault = run_fault(log)
    if fault is not None:
        when, message = fault
        at = f" at t = {when:.3f} s" if np.isfinite(when) else ""
        return "fault", when, f"fault{at}: {message}", FAULT_COLOR
    when = run_interrupted(log)
    if when is not None:
        at = f" at t = {when:.3f} s" if np.isfinite(when) else ""
        return ("interrupted", when, f"interrupted{at} (Ctrl-C or SIGTERM): the log ends "
                "there", INTERRUPT_COLOR)
    return None


def mark_fault_time(ax, log: Mapping) -> None:
    """A vertical line at the fault (or where an interrupted run stopped) on a time axis,
    labelled at its top."""
    stop = run_stop(log)
    if stop is None or not np.isfinite(stop[1]):
        return
    gid, when, _, color = stop
    # Left of the line (a run ends at its fault: the right is axis margin), as high as it
    # goes without covering a curve or a level line (d_u, a limit) drawn there.
    label = ax.text(when, 0.97, f"{gid} ", color=color, fontsize="small", ha="right",
                    va="top", transform=ax.get_xaxis_transform(), gid=f"{gid} label",
                    zorder=6, bbox=dict(facecolor="white", edgecolor="none", alpha=0.8,
                                        pad=0.5))
    label.set_y(_free_top(ax, when, label))
    line = ax.axvline(when, color=color, linestyle="-", linewidth=1.4, zorder=5)
    line.set_gid(gid)


def _free_top(ax, when: float, text) -> float:
    """The highest top (axes fraction, 0.97 down) for `text`, right-aligned at x = when, whose
    box no line of the axes crosses; 0.97 when there is none. Lines are sampled in axes
    fractions (data lines and level lines alike), the box measured in the figure's font."""
    from matplotlib.backends.backend_agg import RendererAgg

    ax.get_xlim(), ax.get_ylim()  # apply a pending autoscale: transData is lazy
    fig = ax.figure
    renderer = RendererAgg(fig.bbox.width, fig.bbox.height, fig.dpi)
    box = text.get_window_extent(renderer)
    # Constrained layout shrinks the axes afterwards: their size now is an upper bound.
    width = 1.2 * box.width / max(ax.bbox.width, 1.0)
    height = 1.3 * box.height / max(ax.bbox.height, 1.0)
    to_axes = ax.transAxes.inverted()
    x_right = to_axes.transform(ax.transData.transform((when, 0.0)))[0]
    xs = np.linspace(x_right - width, x_right, 24)
    samples = []
    for line in ax.get_lines():
        xy = np.column_stack([np.asarray(line.get_xdata(), float),
                              np.asarray(line.get_ydata(), float)])
        if len(xy) == 0:
            continue
        frac = to_axes.transform(line.get_transform().transform(xy))
        x, y = frac[:, 0], frac[:, 1]
        ok = np.isfinite(x) & np.isfinite(y)
        x, y = x[ok], y[ok]
        if x.size == 0 or np.ptp(x) == 0.0:
            continue  # a vertical line: not one that a label left of the mark can cover
        order = np.argsort(x, kind="stable")
        x, y = x[order], y[order]
        inside = (xs >= x[0]) & (xs <= x[-1])
        samples.append(np.interp(xs[inside], x, y))
        samples.append(y[(x >= xs[0]) & (x <= xs[-1])])
    taken = np.concatenate(samples) if samples else np.zeros(0)
    pad = 0.04  # a wide line's own width, and some air
    for top in np.arange(0.97, height, -0.01):
        if not np.any((taken <= top + pad) & (taken >= top - height - pad)):
            return float(top)
    return 0.97


def spans(mask, t) -> list[tuple[float, float]]:
    """(first, last) time (s) of each run of True ticks in `mask`."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(int)))
    return [(float(t[a]), float(t[b - 1])) for a, b in zip(edges[::2], edges[1::2])]


def spans_text(runs, n: int) -> str:
    """'10.26-11.56 s' (one span), '0.10-0.20 s, 0.50-0.52 s' (two), '... and k more'."""
    shown = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in runs[:2])
    more = f" and {len(runs) - 2} more" if len(runs) > 2 else ""
    return f"{shown}{more} ({n} tick{'s' if n != 1 else ''})"


def shade_spans(ax, mask, t, label: str, gid: str, color: str, ymin=0.0, ymax=1.0,
                **style) -> None:
    """An axvspan over each run of True ticks of `mask` (half a tick wider on each side, so a
    single tick shows), the first one labelled `label`, each with `gid`."""
    half = 0.5 * float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    for k, (a, b) in enumerate(spans(mask, t)):
        patch = ax.axvspan(a - half, b + half, ymin=ymin, ymax=ymax, color=color,
                           linewidth=0, label=label if k == 0 else "_", **style)
        patch.set_gid(gid)


def suptitle(fig: Figure, log: Mapping, text: str) -> None:
    """The figure's title, with the fault's (or the interruption's) time and message as its
    last lines when the run did not complete (every figure, with a time axis or not). Every
    line is wrapped to the figure's width, measured in its font: a centred title wider than
    the figure loses both its ends."""
    stop = run_stop(log)
    # A fault's message can be long: the title a size smaller then, so that it takes less
    # of the figure's height.
    title = fig.suptitle(text, fontsize="large" if stop is None else "medium")
    width = 0.96 * fig.bbox.width  # a little margin on each side
    measure = _text_width(fig, title.get_fontproperties())
    lines = wrap_to_width(text, measure, width)
    if stop is not None:
        extra = wrap_to_width(stop[2], measure, width)
        if len(extra) > TITLE_FAULT_LINES:
            extra = extra[:TITLE_FAULT_LINES]
            extra[-1] = _cut_to_width(extra[-1], "...", measure, width)
        lines += extra
    title.set_text("\n".join(lines))


def _text_width(fig: Figure, font):
    """A function: text -> its width in display pixels in `font` on `fig` (Agg renderer, at
    the figure's dpi; savefig at another dpi scales text and figure alike)."""
    from matplotlib.backends.backend_agg import RendererAgg

    renderer = RendererAgg(fig.bbox.width, fig.bbox.height, fig.dpi)

    def width(text: str) -> float:
        return renderer.get_text_width_height_descent(text, font, ismath=False)[0]

    return width


def wrap_to_width(text: str, measure, width: float) -> list[str]:
    """The lines of `text` (its own newlines kept), each wrapped at spaces so that
    measure(line) <= width; a word too long for a line alone is split across lines."""
    out = []
    for paragraph in text.split("\n"):
        line = ""
        for word in paragraph.split(" "):
            candidate = f"{line} {word}" if line else word
            if measure(candidate) <= width:
                line = candidate
                continue
            if line:
                out.append(line)
            while measure(word) > width and len(word) > 1:
                k = max(1, _longest_fitting(word, measure, width))
                out.append(word[:k])
                word = word[k:]
            line = word
        out.append(line)
    return out


def _longest_fitting(word: str, measure, width: float) -> int:
    lo, hi = 0, len(word)  # measure(word[:lo]) fits; word[:hi] does not
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if measure(word[:mid]) <= width else (lo, mid)
    return lo


def _cut_to_width(line: str, tail: str, measure, width: float) -> str:
    """`line` shortened until line + tail fits, then with tail."""
    while line and measure(line + tail) > width:
        line = line[:-1]
    return line.rstrip() + tail
