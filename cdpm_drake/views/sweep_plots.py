"""Pictures of a sweep, drawn from its results.csv rows (docs/SWEEP_FORMAT.md).

A heatmap of a metric over two swept fields, the metric against each field with its spread
over seeds, and the Pareto front of min_distance (larger is better) against operator_effort
(smaller is better). Built without pyplot, like views/plots.py, so tests can read the plotted
data back from the artists. One unit per quantity, written on its axis: distances (d_l, d_u,
min_distance, a start coordinate's are m) in mm, as in the paper, forces in N, times in s;
swept fields are labelled by what they are (`d_u, every pair (mm)`), not by their path.
Cables count from 1.
"""

import math
import re
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cdpm_drake.runs.sweep import METRICS, UNIT_SCALE, field_axis, metric_value, swept_fields

# What each metric is, for its axis and title (METRICS has the unit); every numeric metric
# has one, so no title shows a raw column name.
METRIC_NAMES = {
    "min_distance": "closest approach of any pair",
    "time_below_d_l": "time any pair was below d_l",
    "crossings": "pairs that crossed",
    "peak_F_int": "peak |F_int|",
    "peak_F_d": "peak |F_d|",
    "peak_speed": "peak platform speed",
    "operator_effort": "operator effort, integral of |F_H|",
    "limit_time": "time the limits acted",
    "min_distance_true": "true closest approach of any pair",
    "crossings_true": "pairs that truly crossed",
    "slack_ticks": "ticks with a slack cable",
    "min_tension": "smallest cable tension",
    "max_rotation": "largest platform rotation",
    "sim_s": "simulated time",
    "wall_s": "wall time",
    "rtf": "real-time factor",
}
# The lines of the metric against a field, one per value of the other field, often lie on
# top of each other (F_u = 1..4 N give the same distance at every d_u): each its own marker
# and dash, hollow, the first drawn widest and largest so that the later ones on top leave it
# seen (coinciding points read as rings inside each other).
GROUP_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
GROUP_STYLES = ("-", "--", "-.", ":")
# The largest marker (pt) and the step down per line.
GROUP_MARKER_SIZE, GROUP_MARKER_STEP = 10.0, 1.0
# At most this many Pareto points are listed in the key beside the plot.
KEY_LINES = 25

def _short(field: str) -> str:
    """A field's label without its unit or "every pair", for legends and annotations."""
    return field_axis(field)[0].split(" (")[0].replace(", every pair", "")


def _value_text(field: str, cell: str) -> str:
    """A swept value as shown, in the axis's unit: d_u 0.0605 -> "60.5 mm"."""
    label, scale = field_axis(field)
    number = _number(cell)
    unit = label.rsplit("(", 1)[1].rstrip(")") if label.endswith(")") else ""
    if number is None:
        return cell
    return f"{scale * number:.4g}" + (f" {unit}" if unit else "")


def _scaled(metric: str):
    unit = METRICS[metric][0]
    scale, shown = UNIT_SCALE.get(unit, (1.0, unit))
    what = METRIC_NAMES.get(metric, metric)
    return scale, f"{what} ({shown})" if shown != "-" else what


def _number(cell):
    try:
        return float(cell)
    except (TypeError, ValueError):
        return None


def _levels(rows, field):
    """The distinct values of a field column, numerically sorted when they are numbers."""
    cells = sorted({r[field] for r in rows})
    nums = [_number(c) for c in cells]
    if all(n is not None for n in nums):
        return [c for _, c in sorted(zip(nums, cells))], True
    return cells, False


def _ok(rows, metric):
    return [r for r in rows if r.get("status") == "ok"
            and math.isfinite(metric_value(r, metric))]


def heatmap_grid(rows, metric, x, y):
    """(x levels, y levels, mean metric per cell (len(y), len(x)), runs per cell): the mean
    over everything else (seeds, other fields); NaN where no run of the cell finished ok."""
    xs, _ = _levels(rows, x)
    ys, _ = _levels(rows, y)
    total = np.zeros((len(ys), len(xs)))
    count = np.zeros((len(ys), len(xs)), dtype=int)
    for r in _ok(rows, metric):
        i, j = ys.index(r[y]), xs.index(r[x])
        total[i, j] += metric_value(r, metric)
        count[i, j] += 1
    with np.errstate(invalid="ignore"):
        grid = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return xs, ys, grid, count


def figure_heatmap(columns, rows, metric="min_distance", x=None, y=None) -> Figure:
    fields = swept_fields(columns)
    if x is None or y is None:
        if len(fields) < 2:
            raise ValueError(f"a heatmap needs two swept fields; this sweep has {fields}")
        x, y = fields[0], fields[1]
    scale, label = _scaled(metric)
    (x_label, x_scale), (y_label, y_scale) = field_axis(x), field_axis(y)
    fig = Figure(figsize=(7.0, 5.5), layout="constrained")
    ax = fig.add_subplot()
    xs, ys, grid, count = heatmap_grid(rows, metric, x, y)
    dense = len(xs) <= 30 and len(ys) <= 30
    if dense:
        image = ax.imshow(scale * grid, origin="lower", aspect="auto", cmap="viridis")
        ax.set_xticks(range(len(xs)), [_tick(c, x_scale) for c in xs],
                      rotation=45 if len(xs) > 8 else 0)
        ax.set_yticks(range(len(ys)), [_tick(c, y_scale) for c in ys])
        finite = grid[np.isfinite(grid)]
        mid = scale * float(np.mean([finite.min(), finite.max()])) if finite.size else 0.0
        for i in range(len(ys)):
            for j in range(len(xs)):
                if np.isfinite(grid[i, j]):
                    v = scale * grid[i, j]
                    ax.text(j, i, f"{v:.4g}", ha="center", va="center", fontsize=8,
                            color="black" if v > mid else "white")
                else:  # no run of the cell finished ok: say how they ended
                    statuses = {r.get("status") for r in rows
                                if r[x] == xs[j] and r[y] == ys[i]}
                    ax.text(j, i, "fault" if "fault" in statuses else
                            "error" if "error" in statuses else "-", ha="center",
                            va="center", fontsize=8, color="tab:red")
        spread = " (mean over seeds)" if count.max() > 1 else ""
    else:  # random samples: every run is a point
        ok = _ok(rows, metric)
        image = ax.scatter([x_scale * _number(r[x]) for r in ok],
                           [y_scale * _number(r[y]) for r in ok],
                           c=[scale * metric_value(r, metric) for r in ok], cmap="viridis",
                           s=30)
        spread = ""
    fig.colorbar(image, ax=ax, label=label)
    ax.set_xlabel(x_label)
    ax.set_ylabel(y_label)
    better = {"max": "larger is better", "min": "smaller is better"}.get(METRICS[metric][1], "")
    ax.set_title(f"{label}{spread}" + (f", {better}" if better else ""))
    return fig


def _tick(cell: str, scale: float) -> str:
    """A field value as a tick label in the axis's unit (0.0605 m -> 60.5 for mm)."""
    number = _number(cell)
    return cell if number is None else f"{scale * number:.4g}"


def figure_metric_vs_axis(columns, rows, metric, field) -> Figure:
    """The metric against one swept field: the mean over seeds as a line, the spread (min to
    max over seeds) as a band; one line per value of a second field when there are two."""
    fields = swept_fields(columns)
    others = [f for f in fields if f != field]
    group = others[0] if len(others) == 1 and len(_levels(rows, others[0])[0]) <= 8 else None
    scale, label = _scaled(metric)
    x_label, x_scale = field_axis(field)
    fig = Figure(figsize=(7.5, 4.5), layout="constrained")
    ax = fig.add_subplot()
    xs, numeric = _levels(rows, field)
    groups = _levels(rows, group)[0] if group else [None]
    ok = _ok(rows, metric)
    for g in groups:
        sel = [r for r in ok if g is None or r[group] == g]
        px, mean, lo, hi = [], [], [], []
        for k, xv in enumerate(xs):
            vals = [scale * metric_value(r, metric) for r in sel if r[field] == xv]
            if vals:
                px.append(x_scale * _number(xv) if numeric else k)
                mean.append(float(np.mean(vals)))
                lo.append(float(np.min(vals)))
                hi.append(float(np.max(vals)))
        if not px:
            continue
        k = groups.index(g)
        line, = ax.plot(px, mean, marker=GROUP_MARKERS[k % len(GROUP_MARKERS)],
                        linestyle=GROUP_STYLES[k % len(GROUP_STYLES)],
                        markersize=max(GROUP_MARKER_SIZE - GROUP_MARKER_STEP * k, 3.0),
                        linewidth=max(2.4 - 0.3 * k, 1.0), zorder=2.0 + 0.01 * k,
                        markerfacecolor="none", markeredgewidth=1.5,
                        label=f"{_short(group)} = {_value_text(group, g)}" if group else "mean")
        if any(h > low for h, low in zip(hi, lo)):
            ax.fill_between(px, lo, hi, alpha=0.2, color=line.get_color(), linewidth=0)
    if not numeric:
        ax.set_xticks(range(len(xs)), xs)
    ax.set_xlabel(x_label)
    ax.set_ylabel(label)
    seeds = len({r["random_seed"] for r in rows})
    ax.set_title(f"{label} against {x_label}"
                 + (f"\n(band: min to max over {seeds} seeds)" if seeds > 1 else ""))
    if group:
        ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8)
    ax.grid(True, alpha=0.3)
    return fig


def pareto_front(rows, x="operator_effort", y="min_distance"):
    """The ok rows not dominated in (x smaller, y larger), sorted by x."""
    pts = [r for r in _ok(_ok(rows, x), y)]
    front = []
    for r in pts:
        rx, ry = metric_value(r, x), metric_value(r, y)
        dominated = any(metric_value(o, x) <= rx and metric_value(o, y) >= ry
                        and (metric_value(o, x) < rx or metric_value(o, y) > ry) for o in pts)
        if not dominated:
            front.append(r)
    return sorted(front, key=lambda r: metric_value(r, x))


def figure_pareto(columns, rows) -> Figure:
    """min_distance (larger is better) against operator_effort (smaller is better): every run
    a grey dot, the Pareto front a red line whose points are numbered 1.. from the least
    effort, each number placed where it overlaps no other number, point or the frame
    (place_labels), and what each number's run swept listed beside the plot."""
    x, y = "operator_effort", "min_distance"
    sx, lx = _scaled(x)
    sy, ly = _scaled(y)
    fields = swept_fields(columns)
    fig = Figure(figsize=(9.5, 5.0), layout="constrained")
    ax = fig.add_subplot()
    pts = _ok(_ok(rows, x), y)
    ax.scatter([sx * metric_value(r, x) for r in pts], [sy * metric_value(r, y) for r in pts],
               color="0.6", s=20, label="runs")
    front = pareto_front(rows, x, y)
    fx = [sx * metric_value(r, x) for r in front]
    fy = [sy * metric_value(r, y) for r in front]
    ax.plot(fx, fy, color="tab:red", marker="o", label="Pareto front")
    labels = [ax.annotate(str(k), (px, py), textcoords="offset points", fontsize=8,
                          xytext=(5, 5), annotation_clip=False, gid="front label")
              for k, (px, py) in enumerate(zip(fx, fy), start=1)]
    key = [f"{k}: " + (", ".join(f"{_short(f)} {_value_text(f, r[f])}" for f in fields)
                       or r["run"]) for k, r in enumerate(front, start=1)]
    if len(key) > KEY_LINES:
        key = key[:KEY_LINES - 1] + [f"... and {len(key) - KEY_LINES + 1} more"]
    if key:
        ax.text(1.02, 1.0, "The front's runs\n" + "\n".join(key), transform=ax.transAxes,
                va="top", ha="left", fontsize=7, gid="front key")
    ax.set_xlabel(f"{lx}, smaller is better")
    ax.set_ylabel(f"{ly}, larger is better")
    ax.set_title("Keeping the cables apart against fighting the operator")
    ax.legend(loc="lower right")
    ax.grid(True, alpha=0.3)
    place_labels(fig, ax, labels)
    return fig


# Where a point's number may go, in points from the point: the nearest first.
LABEL_OFFSETS = [(dx, dy) for r in (5, 10, 16) for dx, dy in
                 ((r, r), (r, -r - 7), (-r - 5, r), (-r - 5, -r - 7), (r + 2, -3),
                  (-r - 7, -3), (-3, r + 2), (-3, -r - 9))]


def place_labels(fig, ax, labels) -> None:
    """Move each label (an annotation of a point) to the first of LABEL_OFFSETS where its box
    lies inside the axes' frame and overlaps neither a label placed before it nor a marker
    of the front (the neighbours of a dense front sit a few points apart); where none is
    free, the nearest inside the frame."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.transforms import Bbox

    canvas = FigureCanvasAgg(fig)
    canvas.draw()  # the layout: where the frame and the points are
    renderer = canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    radius = 4.0 * fig.dpi / 72.0  # a marker's half width, px
    marks = [Bbox.from_extents(*(c - radius), *(c + radius))
             for c in ax.transData.transform([label.xy for label in labels])] \
        if labels else []
    placed = []
    for label in labels:
        fallback = None
        for offset in LABEL_OFFSETS:
            label.xyann = offset
            box = label.get_window_extent(renderer)
            inside = (frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0
                      and box.y1 <= frame.y1)
            if not inside:
                continue
            fallback = fallback or offset
            if not any(box.overlaps(other) for other in placed + marks):
                break
        else:
            label.xyann = fallback or LABEL_OFFSETS[0]
        placed.append(label.get_window_extent(renderer))


def _file_part(field: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]+", "_", field).strip("_")


def plot_sweep(columns, rows, out_dir, metric="min_distance", dpi: int = 110) -> list[Path]:
    """Write <metric>_heatmap.png (two or more swept fields), <metric>_vs_<field>.png per field
    and pareto.png (min_distance against operator_effort, whatever the metric) into out_dir;
    returns the paths. Each metric's pictures carry its name: plotting a second metric into
    the same folder keeps the first one's."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fields = swept_fields(columns)
    figures = []
    if len(fields) >= 2:
        figures.append((f"{metric}_heatmap.png", figure_heatmap(columns, rows, metric)))
    for f in fields:
        figures.append((f"{metric}_vs_{_file_part(f)}.png",
                        figure_metric_vs_axis(columns, rows, metric, f)))
    figures.append(("pareto.png", figure_pareto(columns, rows)))
    paths = []
    for name, fig in figures:
        path = out / name
        fig.savefig(path, dpi=dpi)
        paths.append(path)
    return paths
