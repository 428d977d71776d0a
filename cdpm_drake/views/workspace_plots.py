"""Workspace pictures of a robot, after CASPR's workspace plots: where the cables can hold the
platform (the wrench-feasible workspace) and where the cables keep clear of each other (the
interference-free workspace), as three orthogonal slices of the workspace box.

- `figure_wrench_workspace`: each slice coloured by t*, the largest achievable minimum cable
  tension of the level platform (tension.holding_tension: the robot file's platform mass at
  its centre, moments about the centre), the floor drawn as a contour; where an internal force
  raises every tension (t* = +inf) the colour is the scale's top.
- `figure_interference_workspace`: each slice coloured by how far the closest watched pair
  is beyond its d_u (red within, green beyond), the boundary drawn as a contour, and the pairs
  that come within d_u listed.
Both draw a path (a scenario's logged positions) projected onto every slice, with its start.
The slices pass through the path's middle (or the box centre). Figures are built without
pyplot (no global state); `plot_workspace` writes both as PNGs. Positions in m, tensions in N,
distances in mm; cables numbered 1..m.
"""

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..interference import pair_distances
from ..tension import holding_tension

AXES = "xyz"
# Each slice: (the axis held fixed, the two axes drawn).
SLICES = ((2, (0, 1)), (1, (0, 2)), (0, (1, 2)))
FILES = {"wrench": "workspace_wrench.png", "interference": "workspace_interference.png"}
# The t* colour scale: floor - T_BELOW .. floor + T_ABOVE N (beyond: the ends' colours).
T_BELOW, T_ABOVE = 10.0, 25.0
# The interference picture's colour scale: margins d - d_u of -MARGIN_SPAN .. MARGIN_SPAN mm.
MARGIN_SPAN = 20.0


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
    fig = Figure(figsize=(15, 5.2), layout="constrained")
    axes = fig.subplots(1, 3)
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
    bar = fig.colorbar(image, ax=list(axes), shrink=0.9)
    bar.set_label("t* (N)")
    if path is not None and len(path):
        axes[0].legend(loc="upper right", fontsize=8)
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


def figure_interference_workspace(robot, *, d_u, path=None, step: float = 0.05,
                                  title: str | None = None) -> Figure:
    """Three slices of the box coloured by the smallest margin d - d_u (mm) over the watched
    pairs (d_u m, one value or one per pair); the black contour bounds where some pair comes
    within its d_u; the pairs that do are listed under each slice with their least distance."""
    centre = slice_centre(robot, path)
    d_u = np.broadcast_to(np.asarray(d_u, dtype=float), (robot.num_pairs,))
    fig = Figure(figsize=(15, 5.6), layout="constrained")
    axes = fig.subplots(1, 3)
    image = None
    for ax, (fixed, drawn, u, v, dmin, margin, _, d) in zip(
            axes, interference_slices(robot, centre, step, d_u)):
        # The margin d - d_u of the closest pair (per pair's own d_u): red within, green
        # beyond, saturated at MARGIN_SPAN so the boundary stands out.
        image = ax.pcolormesh(u, v, 1000 * margin, cmap="RdYlGn", vmin=-MARGIN_SPAN,
                              vmax=MARGIN_SPAN, shading="nearest")
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
    bar = fig.colorbar(image, ax=list(axes), shrink=0.9)
    du_text = (f"{1000 * d_u[0]:.0f} mm" if np.all(d_u == d_u[0])
               else f"{1000 * d_u.min():.0f}-{1000 * d_u.max():.0f} mm per pair")
    bar.set_label(f"smallest margin d - d_u over the pairs (mm; +-{MARGIN_SPAN:g} and beyond)")
    if path is not None and len(path):
        axes[0].legend(loc="upper right", fontsize=8)
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
