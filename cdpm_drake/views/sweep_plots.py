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

# What each metric is, for its axis (METRICS has the unit).
METRIC_NAMES = {
    "min_distance": "closest approach of any pair",
    "time_below_d_l": "time any pair was below d_l",
    "crossings": "pairs that crossed",
    "peak_F_int": "peak |F_int|",
    "peak_F_d": "peak |F_d|",
    "peak_speed": "peak platform speed",
    "operator_effort": "operator effort, integral of |F_H|",
    "limit_time": "time the limits acted",
    "sim_s": "simulated time",
    "wall_s": "wall time",
    "rtf": "real-time factor",
}

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
        line, = ax.plot(px, mean, marker="o",
                        label=f"{_short(group)} = {_value_text(group, g)}" if group else "mean")
        if any(h > low for h, low in zip(hi, lo)):
            ax.fill_between(px, lo, hi, alpha=0.2, color=line.get_color(), linewidth=0)
    if not numeric:
        ax.set_xticks(range(len(xs)), xs)
    ax.set_xlabel(x_label)
    ax.set_ylabel(label)
    seeds = len({r["random_seed"] for r in rows})
    ax.set_title(f"{label.split(' (')[0]} against {_short(field)}"
                 + (f" (band: min to max over {seeds} seeds)" if seeds > 1 else ""))
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
    """min_distance (larger is better) against operator_effort (smaller is better)."""
    x, y = "operator_effort", "min_distance"
    sx, lx = _scaled(x)
    sy, ly = _scaled(y)
    fields = swept_fields(columns)
    fig = Figure(figsize=(7.5, 5.0), layout="constrained")
    ax = fig.add_subplot()
    pts = _ok(_ok(rows, x), y)
    ax.scatter([sx * metric_value(r, x) for r in pts], [sy * metric_value(r, y) for r in pts],
               color="0.6", s=20, label="runs")
    front = pareto_front(rows, x, y)
    fx = [sx * metric_value(r, x) for r in front]
    fy = [sy * metric_value(r, y) for r in front]
    ax.plot(fx, fy, color="tab:red", marker="o", label="Pareto front")
    labels = []
    for k, (r, px, py) in enumerate(zip(front, fx, fy)):
        text = ", ".join(f"{_short(f)} {_value_text(f, r[f])}" for f in fields) or r["run"]
        # Alternate above and below: neighbours on the front often sit close together.
        labels.append(ax.annotate(text, (px, py), textcoords="offset points", fontsize=7,
                                  xytext=(6, 6) if k % 2 == 0 else (6, -12),
                                  annotation_clip=False))
    ax.set_xlabel(f"{lx}, smaller is better")
    ax.set_ylabel(f"{ly}, larger is better")
    ax.set_title("Keeping the cables apart against fighting the operator")
    ax.legend(loc="lower right")
    ax.grid(True, alpha=0.3)
    _keep_inside(fig, ax, labels)
    return fig


def _keep_inside(fig, ax, labels) -> None:
    """Move each point's label to the other side of its point where it would run over the
    axes' frame (the front's last point is often the rightmost run, its best the topmost)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()  # the layout: where the frame and the labels are
    renderer = canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    for label in labels:
        box = label.get_window_extent(renderer)
        dx, dy = label.xyann
        if box.x1 > frame.x1:
            label.set_horizontalalignment("right")
            dx = -abs(dx)
        if box.y1 > frame.y1:
            dy = -12
        elif box.y0 < frame.y0:
            dy = 6
        label.xyann = (dx, dy)


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
