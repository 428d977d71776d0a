"""The paper's result figures (Figs. 8-16) drawn from a log.npz (docs/LOG_FORMAT.md).

Each `figure_*` function returns a `matplotlib.figure.Figure` built without pyplot, so no global
figure state leaks between calls and tests can read the plotted data back from the artists;
`plot_log` writes them all as PNGs. Distances are shown in mm (as in the paper), forces in N,
positions in m, time in s; cables are numbered 1..m.

A run that ended on a fault (log keys `ending`, `fault_time`, `fault_message`) has the fault
marked in every figure: a vertical line with its label on every time axis, a marker on the
trajectory, a note under the figure. Logs without those keys (older logs) read as completed.
Figures that need keys only some logs have (`timing`: the tick clock of `cdpm run`; `tensions`,
`pose_error`: the dynamic plant's ground truth) are listed in OPTIONAL and skipped by `plot_log`
when a log lacks them.
"""

import warnings
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from cdpm_drake.kernels.interference import logistic_intensity

# What each figure reads from the log (docs/LOG_FORMAT.md).
_NEEDS = {
    "distances": ("time", "pair_distances", "active", "pairs", "d_l", "d_u"),
    "forces": ("time", "F_H", "F_int", "F_d"),
    "trajectory": ("time", "p", "active", "crossed", "reels", "attachments", "pairs"),
    "logistic": ("pairs", "d_l", "d_u", "F_u", "eps"),
    "cables": ("time", "lengths", "reel_velocity"),
    "timing": ("time", "wall"),
    # The dynamic plant's ground truth (plant: !DynamicReels).
    "tensions": ("time", "tensions", "slack"),
    "pose_error": ("time", "p", "p_true", "rpy_true"),
    # The safety filter's work (safety_filter.enabled; beyond the paper).
    "safety": ("time", "filter_status", "filter_binding", "velocity", "velocity_limited"),
}
# A figure drawn from other keys when the log lacks its _NEEDS: the tensions of a
# tension-controlled run on the robot (no plant's truth there) are the controller's estimate.
_OR_NEEDS = {"tensions": ("time", "tension_estimate")}
# Keys a figure draws when the log holds them (a full-pose or tension-controlled run's).
_MAY_USE = {"pose_error": ("rpy",), "tensions": ("tensions", "slack", "tension_estimate", "t_star"),
            "safety": ("kappa", "t_star_hand", "pair_margin")}
# Figures drawn only for logs that hold their keys.
OPTIONAL = ("timing", "tensions", "pose_error", "safety")
# Keys with one row per tick.
_PER_TICK = ("time", "p", "F_H", "F_int", "F_d", "pair_distances", "active", "crossed",
             "lengths", "reel_velocity", "wall", "tensions", "slack", "p_true", "rpy_true",
             "lengths_commanded", "pair_distances_true", "crossed_true", "rpy",
             "tension_estimate", "tension_target", "t_star", "F_kin", "filter_status",
             "filter_binding", "velocity_limited", "kappa", "t_star_hand", "pair_margin")
LOG_KEYS = ("time", "p", "F_H", "F_int", "F_wall", "F_d", "velocity_admittance", "velocity",
            "reel_velocity", "lengths", "pair_distances", "active", "crossed", "pairs", "d_l",
            "d_u", "F_u", "eps", "F_max", "reels", "attachments", "workspace_lower",
            "workspace_upper", "robot_name", "scenario_name")

# Fig. 12's colour code, used for the force plots too.
FORCE_COLORS = {"F_H": "tab:blue", "F_int": "black", "F_d": "tab:red", "F_wall": "tab:green",
                "F_kin": "tab:purple"}
FIGURE_FILES = {"distances": "distances.png", "forces": "forces.png",
                "trajectory": "trajectory.png", "logistic": "logistic.png",
                "cables": "cables.png", "timing": "timing.png", "tensions": "tensions.png",
                "pose_error": "pose_error.png", "safety": "safety.png"}
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
FAULT_COLOR = "crimson"
# Transparency of the dots where a pair was within d_u: one dot per tick, many on top of each
# other, so the path shows through where they are sparse.
EVENT_ALPHA = 0.35
# An interrupted run (Ctrl-C, SIGTERM) is marked as a fault is, in a neutral dark grey: it is
# where the log ends, not an error (and orange is the trajectory's "within d_u").
INTERRUPT_COLOR = "0.2"
# The tension target's floor and ceiling: neither a cable's colour nor the estimate's grey.
LIMIT_COLOR = "darkgoldenrod"
# Most lines of a fault message in a title; the rest is cut with "...".
TITLE_FAULT_LINES = 6


class LogError(ValueError):
    """A log file or dictionary does not follow docs/LOG_FORMAT.md."""


def load_log(path) -> dict:
    """Read DIR/log.npz (or the .npz file itself) into a dict of arrays; LogError when a key of
    docs/LOG_FORMAT.md is missing."""
    path = Path(path)
    if path.is_dir():
        path = path / "log.npz"
    if not path.is_file():
        raise LogError(f"log file {str(path)!r} does not exist (give a run directory holding "
                       "log.npz, or the .npz file)")
    try:
        with np.load(path, allow_pickle=False) as data:
            if not hasattr(data, "files"):  # a bare .npy array, not an archive
                raise ValueError("a single array, not an .npz archive")
            log = {k: data[k] for k in data.files}
    except (zipfile.BadZipFile, zlib.error, EOFError) as e:
        # A cut copy (a full disk, a transfer stopped part-way) or flipped bytes: the archive's
        # directory, at its end, or a member's checksum does not hold.
        raise LogError(f"{str(path)!r} is damaged or truncated ({path.stat().st_size} bytes): "
                       f"not a whole .npz archive ({e}); rerun it (cdpm simulate "
                       "RUN_DIR/scenario.yaml), or for a cdpm run convert its ticks.bin "
                       "again (remove log.npz, then cdpm recover RUN_DIR)") from None
    except (OSError, ValueError) as e:
        why = ("not a NumPy .npz archive" if "pickle" in str(e) or "allow_pickle" in str(e)
               else str(e))
        raise LogError(f"{str(path)!r} is not a log written by cdpm simulate or cdpm run "
                       f"(docs/LOG_FORMAT.md): {why}") from None
    missing = [k for k in LOG_KEYS if k not in log]
    if missing:
        raise LogError(f"{str(path)!r} lacks the key(s) {missing!r} of docs/LOG_FORMAT.md; "
                       f"it holds {sorted(log)!r}")
    return log


def _needs(log: Mapping, figure: str) -> tuple:
    """The keys the figure reads from this log: _NEEDS, or its _OR_NEEDS when the log holds
    those and not all of _NEEDS."""
    if figure in _OR_NEEDS and not all(k in log for k in _NEEDS[figure]) and all(
            k in log for k in _OR_NEEDS[figure]):
        return _OR_NEEDS[figure]
    return _NEEDS[figure]


def has_keys(log: Mapping, figure: str) -> bool:
    """Whether the log holds every key the figure needs."""
    return all(k in log for k in _needs(log, figure))


def _check(log: Mapping, figure: str) -> None:
    needs = _needs(log, figure)
    missing = [k for k in needs if k not in log]
    if missing:
        raise LogError(f"the {figure} plot needs log key(s) {missing!r} (docs/LOG_FORMAT.md); "
                       f"the log holds {sorted(log)!r}")
    if "time" in needs:
        T = len(log["time"])
        for key in needs + tuple(k for k in _MAY_USE.get(figure, ()) if k in log):
            arr = np.asarray(log[key])
            if key in _PER_TICK and (arr.ndim == 0 or arr.shape[0] != T):
                raise LogError(f"log key {key!r} has shape {arr.shape!r}; expected one row per "
                               f"tick ({T} rows, as 'time')")


def _title(log: Mapping) -> str:
    scen = str(log["scenario_name"]) if "scenario_name" in log else ""
    robot = str(log["robot_name"]) if "robot_name" in log else ""
    return f"{scen} ({robot})" if scen and robot else scen or robot


def _pair_label(pair) -> str:
    return f"cables {int(pair[0])}-{int(pair[1])}"


# --- how the run ended ----------------------------------------------------------------------------


def run_fault(log: Mapping) -> tuple[float, str] | None:
    """(fault time in s, NaN when unknown; message) when the log's run ended on a fault, else
    None; logs without the `ending` key ended normally."""
    if "ending" not in log or str(log["ending"]) != "fault":
        return None
    when = float(log["fault_time"]) if "fault_time" in log else float("nan")
    message = str(log["fault_message"]) if "fault_message" in log else ""
    return when, message or "fault"


def run_interrupted(log: Mapping) -> float | None:
    """The time (s) of the last logged tick when the log's run was interrupted (Ctrl-C,
    SIGTERM: `ending` "interrupted"), else None."""
    if "ending" not in log or str(log["ending"]) != "interrupted":
        return None
    t = np.asarray(log["time"], dtype=float).reshape(-1)
    return float(t[-1]) if t.size else float("nan")


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


def _mark_fault_time(ax, log: Mapping) -> None:
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


def _suptitle(fig: Figure, log: Mapping, text: str) -> None:
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


# --- Fig. 10: distances -------------------------------------------------------------------------


def figure_distances(log: Mapping) -> Figure:
    """Distance (mm) vs time (s) of each pair that was active at some tick, with the d_l and d_u
    lines of those pairs (Fig. 10). When no pair was ever active, the closest pair is shown."""
    _check(log, "distances")
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
    _mark_fault_time(ax, log)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    _suptitle(fig, log, _title(log))
    return fig


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
    _check(log, "forces")
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
        _mark_fault_time(ax, log)
        # Beside the axes, so it never hides the end of a curve.
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    axes[-1].set_xlabel("time (s)")
    _suptitle(fig, log, f"{_title(log)}\nForces on the platform (Figs. 11, 13, 16), "
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
    with the ticks where a pair was within d_u (dots, under the path) or crossed (crosses); and
    the robot as context: reels A_i, workspace box, the path, the zoomed region and the cables
    at the first interference tick, those of the active pairs in red. One legend below the
    panels lists only what was drawn."""
    _check(log, "trajectory")
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
    path, = zoom.plot(*p.T, color="tab:blue", linewidth=1.8, zorder=3, label="platform path p")
    keep(path.get_label(), path)
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
    limits = motion_limits(p)
    zoom.set(xlim=limits[0], ylim=limits[1], zlim=limits[2])
    zoom.set_box_aspect((1, 1, 1))
    zoom.set_title(f"The motion ({1000 * (limits[0, 1] - limits[0, 0]):.0f} mm cube)",
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
    _suptitle(fig, log, f"{_title(log)}\nPlatform trajectory, interference events and reels "
              "(Figs. 9, 15)")
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
    _check(log, "logistic")
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
    _suptitle(fig, log, f"{_title(log)}\nInterference force intensity as applied: the "
              "logistic function (eqs. 26-28, Fig. 8) within d_u, zero beyond")
    return fig


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
    _check(log, "cables")
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
        _mark_fault_time(ax, log)
    if lengths.shape[1]:
        top.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small",
                   ncol=1 if lengths.shape[1] <= 10 else 2)
    _suptitle(fig, log, f"{_title(log)}\nCable lengths and reel speeds")
    return fig


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
    _check(log, "timing")
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
        _mark_fault_time(ax, log)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    top.set_ylabel("tick period (ms)")
    bottom.set_ylabel("compute per tick (ms)")
    bottom.set_xlabel("time (s)")
    stats = ""
    if period.size:
        p50, p99 = np.percentile(1000.0 * period, [50, 99])
        stats = (f": period p50 {p50:.2f} ms, p99 {p99:.2f} ms, "
                 f"max {1000.0 * period.max():.2f} ms")
    _suptitle(fig, log, f"{_title(log)}\nTick timing of the real-time run{stats}")
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
    _check(log, "tensions")
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
            _mark_fault_time(a, log)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    what = ("Cable tensions (dynamic plant)" if estimate is None else
            "Cable tensions: the plant's (solid) and the controller's estimate (dashed), the "
            "target's floor and ceiling, t*" if truth else
            "Cable tensions as the controller estimates them, the target's floor and ceiling, t*")
    _suptitle(fig, log, f"{_title(log)}\n{what}")
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
    _check(log, "pose_error")
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
        _mark_fault_time(ax, log)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    _suptitle(fig, log, f"{_title(log)}\nThe controller's pose estimate ({pose_model(log)}) "
              "against the true platform")
    return fig


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
    _check(log, "safety")
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
        _mark_fault_time(ax, log)
        if ax is not ax_b and ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    _suptitle(fig, log, f"{_title(log)}\nThe safety filter: what it changed and the margins "
              "it kept")
    return fig


FIGURES = {"distances": figure_distances, "forces": figure_forces,
           "trajectory": figure_trajectory, "logistic": figure_logistic,
           "cables": figure_cables, "timing": figure_timing, "tensions": figure_tensions,
           "pose_error": figure_pose_error, "safety": figure_safety}


def figures_of(log: Mapping) -> list[str]:
    """The names (FIGURES' keys) of the figures `plot_log` draws for this log: every one but
    the OPTIONAL ones whose keys the log lacks."""
    return [name for name in FIGURES if name not in OPTIONAL or has_keys(log, name)]


def plot_log(log: Mapping[str, np.ndarray], out_dir, dpi: int = 120,
             only=None) -> list[Path]:
    """Write the figures as PNGs in out_dir (created if needed); returns their paths in the
    order of FIGURES, leaving out the OPTIONAL ones whose keys the log lacks (tensions and
    pose_error need a dynamic plant's log) and, with `only` (names), the others."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in figures_of(log):
        if only is not None and name not in only:
            continue
        path = out / FIGURE_FILES[name]
        FIGURES[name](log).savefig(path, dpi=dpi)
        paths.append(path)
    return paths
