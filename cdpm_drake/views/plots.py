"""The paper's result figures (Figs. 8-16), and the run's other figures, drawn from a log.npz
(docs/LOG_FORMAT.md, read with runs/log.py's load_log).

Each `figure_*` function returns a `matplotlib.figure.Figure` built without pyplot, so no global
figure state leaks between calls and tests can read the plotted data back from the artists;
`plot_log` writes them all as PNGs. Distances are shown in mm (as in the paper), forces in N,
positions in m, time in s; cables are numbered 1..m. The figures live by subject:
figures_interference.py (distances, logistic), figures_motion.py (forces, trajectory),
figures_plant.py (cables, tensions, pose_error), figures_timing.py, figures_safety.py; what
each reads from the log is figure_keys.py, what they all share figure_layout.py.
"""

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cdpm_drake.views.figure_keys import OPTIONAL, has_keys
from cdpm_drake.views.figures_interference import figure_distances, figure_logistic
from cdpm_drake.views.figures_motion import figure_forces, figure_trajectory
from cdpm_drake.views.figures_plant import figure_cables, figure_pose_error, figure_tensions
from cdpm_drake.views.figures_safety import figure_safety
from cdpm_drake.views.figures_timing import figure_timing

# The file each figure is written to, in the output folder.
FIGURE_FILES = {"distances": "distances.png", "forces": "forces.png",
                "trajectory": "trajectory.png", "logistic": "logistic.png",
                "cables": "cables.png", "timing": "timing.png", "tensions": "tensions.png",
                "pose_error": "pose_error.png", "safety": "safety.png"}
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
