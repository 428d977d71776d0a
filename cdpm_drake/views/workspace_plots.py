"""Workspace pictures of a robot, after CASPR's workspace plots: where the cables can hold the
platform (the wrench-feasible workspace) and where the cables keep clear of each other (the
interference-free workspace), as three orthogonal slices of the workspace box.

- `figure_wrench_workspace`: each slice coloured by t*, the largest achievable minimum cable
  tension of the level platform (statics.holding_tension: the robot file's platform mass at
  its centre, moments about the centre), the floor drawn as a contour; where an internal force
  raises every tension (t* = +inf) the colour is the scale's top.
- `figure_interference_workspace`: each slice coloured by how far the closest watched pair
  is beyond its d_u (red within, green beyond, each side scaled to the slices' extremes),
  the boundary drawn as a contour, and the pairs that come within d_u listed.
Both draw a path (a scenario's logged positions) projected onto every slice, with its start.
The slices pass through the path's middle (or the box centre). Figures are built without
pyplot (no global state); `plot_workspace` writes both as PNGs. Positions in m, tensions in N,
distances in mm; cables numbered 1..m.
"""

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cdpm_drake.kernels.interference import pair_distances
from cdpm_drake.robot.statics import holding_tension

AXES = "xyz"
# Each slice: (the axis held fixed, the two axes drawn).
SLICES = ((2, (0, 1)), (1, (0, 2)), (0, (1, 2)))
FILES = {"wrench": "workspace_wrench.png", "interference": "workspace_interference.png"}
# The t* colour scale: floor - T_BELOW .. floor + T_ABOVE N (beyond: the ends' colours).
T_BELOW, T_ABOVE = 10.0, 25.0
# The interference picture's colour scale spans the slices' own margins d - d_u (red: the
# most negative, green: the largest), each side at least MIN_MARGIN_SPAN mm.
MIN_MARGIN_SPAN = 0.5


def slice_centre(robot, path=None) -> np.ndarray:
    """Where the three slices cross: the middle of the path's bounding box (inside the
    workspace box), or the box centre without a path."""
    if path is None or len(path) == 0:
        return robot.workspace.center.copy()
    p = np.asarray(path, dtype=float)
    return np.clip(0.5 * (p.min(axis=0) + p.max(axis=0)), robot.workspace.lower,
                   robot.workspace.upper)


def slice_points(robot, fixed: int, value: float, step: float):
    """(u, v, points): the grid axes (m) of the slice `fixed` = value through the box, with
    step (m), and its points (len(v), len(u), 3)."""
    lo, hi = robot.workspace.lower, robot.workspace.upper
    a, b = [k for k in range(3) if k != fixed]
    u = np.arange(lo[a], hi[a] + 1e-9, step)
    v = np.arange(lo[b], hi[b] + 1e-9, step)
    pts = np.empty((len(v), len(u), 3))
    pts[..., a], pts[..., b] = u[None, :], v[:, None]
    pts[..., fixed] = value
    return u, v, pts


def _draw_path(ax, path, drawn):
    if path is None or len(path) == 0:
        return
    p = np.asarray(path, dtype=float)
    a, b = drawn
    ax.plot(p[:, a], p[:, b], color="white", linewidth=3.0, zorder=3)
    ax.plot(p[:, a], p[:, b], color="tab:blue", linewidth=1.4, zorder=4,
            label="path (projected)")
    ax.plot(p[0, a], p[0, b], "o", color="tab:blue", markeredgecolor="white", zorder=5,
            label="start")


def _panel_title(fixed, value):
    return f"{AXES[fixed]} = {value:.2f} m"


# Height of each slice's drawing area, in; the figure's width follows from the slices' shapes.
PANEL_HEIGHT = 3.6


def _slice_figure(robot, extra_height: float = 0.0):
    """(figure, its three axes) for three slices drawn to scale (equal aspect): the axes'
    widths in proportion to the slices' widths over their heights, the figure about as wide
    as they are, and the "compressed" layout, which packs fixed-aspect axes and their colour
    bar together (the constrained one shrinks each slice inside a wide axes and leaves the
    colour bar far off to the right)."""
    span = robot.workspace.upper - robot.workspace.lower
    ratios = [span[drawn[0]] / span[drawn[1]] for _, drawn in SLICES]
    width = PANEL_HEIGHT * sum(ratios) + 3.2  # the axes' labels, the gaps, the colour bar
    fig = Figure(figsize=(max(width, 9.0), PANEL_HEIGHT + 1.7 + extra_height),
                 layout="compressed")
    return fig, fig.subplots(1, 3, width_ratios=ratios)


def _path_legend(fig, path):
    """The path's legend below the slices (in a slice it would cover the contours)."""
    if path is not None and len(path):
        fig.legend(*fig.axes[0].get_legend_handles_labels(), loc="outside lower center",
                   ncol=2, fontsize=9)


def wrench_slices(robot, centre, step: float, mass=None):
    """[(fixed axis, drawn axes, u, v, t* (len(v), len(u)))] of the three slices."""
    out = []
    for fixed, drawn in SLICES:
        u, v, pts = slice_points(robot, fixed, centre[fixed], step)
        out.append((fixed, drawn, u, v, holding_tension(robot, pts, mass)))
    return out


def figure_wrench_workspace(robot, *, floor: float = 5.0, path=None, step: float = 0.05,
                            title: str | None = None, mass=None) -> Figure:
    """Three slices of the box coloured by t* (N) of the level platform, the floor contour,
    the path. The share of each slice held at >= floor is in its title."""
    centre = slice_centre(robot, path)
    mass = robot.dynamics.mass if mass is None else mass
    fig, axes = _slice_figure(robot)
    vmin, vmax = floor - T_BELOW, floor + T_ABOVE
    image = None
    for ax, (fixed, drawn, u, v, t) in zip(axes, wrench_slices(robot, centre, step, mass)):
        shown = np.clip(np.where(np.isinf(t), np.sign(t) * np.inf, t), vmin, vmax)
        image = ax.pcolormesh(u, v, shown, cmap="viridis", vmin=vmin, vmax=vmax,
                              shading="nearest")
        if np.nanmin(shown) < floor < np.nanmax(shown):
            ax.contour(u, v, shown, levels=[floor], colors="black", linewidths=1.6)
        _draw_path(ax, path, drawn)
        ax.set_xlabel(f"{AXES[drawn[0]]} (m)")
        ax.set_ylabel(f"{AXES[drawn[1]]} (m)")
        ax.set_aspect("equal")
        ax.set_title(f"{_panel_title(fixed, centre[fixed])}: {100 * np.mean(t >= floor):.0f} % "
                     f"held at >= {floor:g} N")
    bar = fig.colorbar(image, ax=list(axes), shrink=0.9, pad=0.01)
    bar.set_label("t* (N)")
    _path_legend(fig, path)
    fig.suptitle((title or f"{robot.name}: wrench-feasible workspace of the level platform "
                           f"({mass:g} kg at its centre, moments about the centre)")
                 + f"\nt* = largest achievable minimum cable tension; black line: t* = "
                   f"{floor:g} N; top colour: >= {vmax:g} N or unbounded (an internal force "
                   "raises every tension)")
    return fig


def interference_slices(robot, centre, step: float, d_u):
    """[(fixed, drawn, u, v, smallest distance (m), margin (m) = min over pairs of d - d_u,
    closest pair index)] of the three slices."""
    d_u = np.broadcast_to(np.asarray(d_u, dtype=float), (robot.num_pairs,))
    out = []
    for fixed, drawn in SLICES:
        u, v, pts = slice_points(robot, fixed, centre[fixed], step)
        d = pair_distances(robot, pts.reshape(-1, 3)).reshape(len(v), len(u), -1)
        out.append((fixed, drawn, u, v, d.min(axis=-1), (d - d_u).min(axis=-1),
                    d.argmin(axis=-1), d))
    return out


def margin_norm(margins):
    """The colour scale of margins (m, arrays) in mm: 0 at the middle (yellow), the most
    negative margin red and the largest green, each side scaled on its own, so that a few mm
    of margin on one side is not washed out by tens on the other."""
    from matplotlib.colors import TwoSlopeNorm

    lo = min(float(np.min(m)) for m in margins) * 1000.0
    hi = max(float(np.max(m)) for m in margins) * 1000.0
    return TwoSlopeNorm(0.0, vmin=min(lo, -MIN_MARGIN_SPAN), vmax=max(hi, MIN_MARGIN_SPAN))


def margin_ticks(norm) -> np.ndarray:
    """Colour bar ticks (mm) for margin_norm's scale: a few round values on each side of 0,
    each side by its own step (one locator over both would leave a short side bare)."""
    from matplotlib.ticker import MaxNLocator

    ticks = np.concatenate([MaxNLocator(4).tick_values(norm.vmin, 0.0),
                            MaxNLocator(4).tick_values(0.0, norm.vmax)])
    return np.unique(ticks[(ticks >= norm.vmin) & (ticks <= norm.vmax)])


def figure_interference_workspace(robot, *, d_u, path=None, step: float = 0.05,
                                  title: str | None = None) -> Figure:
    """Three slices of the box coloured by the smallest margin d - d_u (mm) over the watched
    pairs (d_u m, one value or one per pair); the black contour bounds where some pair comes
    within its d_u; the pairs that do are listed under each slice with their least distance."""
    centre = slice_centre(robot, path)
    d_u = np.broadcast_to(np.asarray(d_u, dtype=float), (robot.num_pairs,))
    fig, axes = _slice_figure(robot, extra_height=0.4)
    slices = interference_slices(robot, centre, step, d_u)
    norm = margin_norm([s[5] for s in slices])
    image = None
    for ax, (fixed, drawn, u, v, dmin, margin, _, d) in zip(axes, slices):
        # The margin d - d_u of the closest pair (per pair's own d_u): red within, green
        # beyond, each side scaled to the slices' own extremes (margin_norm).
        image = ax.pcolormesh(u, v, 1000 * margin, cmap="RdYlGn", norm=norm,
                              shading="nearest")
        if margin.min() < 0 < margin.max():
            ax.contour(u, v, margin, levels=[0.0], colors="black", linewidths=1.6)
        _draw_path(ax, path, drawn)
        close = [(robot.pairs[k], float(d[..., k].min())) for k in range(robot.num_pairs)
                 if (d[..., k] < d_u[k]).any()]
        note = ("pairs within d_u: " + ", ".join(f"{i}-{j} (min {1000 * m:.0f} mm)"
                                                  for (i, j), m in close[:6])
                + (" ..." if len(close) > 6 else "")) if close else "every pair above d_u"
        ax.set_xlabel(f"{AXES[drawn[0]]} (m)\n{note}")
        ax.set_ylabel(f"{AXES[drawn[1]]} (m)")
        ax.set_aspect("equal")
        ax.set_title(f"{_panel_title(fixed, centre[fixed])}: {100 * np.mean(margin >= 0):.0f} % "
                     "interference-free")
    bar = fig.colorbar(image, ax=list(axes), shrink=0.9, pad=0.01)
    du_text = (f"{1000 * d_u[0]:.0f} mm" if np.all(d_u == d_u[0])
               else f"{1000 * d_u.min():.0f}-{1000 * d_u.max():.0f} mm per pair")
    bar.set_label("smallest margin d - d_u over the pairs (mm)")
    ticks = margin_ticks(norm)
    bar.set_ticks(ticks, labels=[f"{t:g}" for t in ticks])
    _path_legend(fig, path)
    fig.suptitle((title or f"{robot.name}: interference-free workspace (watched pairs)")
                 + f"\nblack line: some pair reaches its d_u ({du_text}); red side: within "
                   "it (the interference force acts there)")
    return fig


def plot_workspace(robot, out_dir, *, floor: float = 5.0, d_u=0.062, path=None,
                   step: float = 0.05, name: str | None = None, dpi: int = 110) -> list[Path]:
    """Write workspace_wrench.png and workspace_interference.png into out_dir; their paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    label = name or robot.name
    figures = {
        "wrench": figure_wrench_workspace(
            robot, floor=floor, path=path, step=step,
            title=f"{label}: wrench-feasible workspace of the level platform "
                  f"({robot.dynamics.mass:g} kg at its centre, moments about the centre)"),
        "interference": figure_interference_workspace(
            robot, d_u=d_u, path=path, step=step,
            title=f"{label}: interference-free workspace (watched pairs)"),
    }
    written = []
    for key, fig in figures.items():
        path_out = out_dir / FILES[key]
        fig.savefig(path_out, dpi=dpi)
        written.append(path_out)
    return written
