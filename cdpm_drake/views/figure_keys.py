"""What each of the figures (views/plots.py) reads from a log (docs/LOG_FORMAT.md), and the
check each figure makes before it draws.

Figures that need keys only some logs have (`timing`: the tick clock of `cdpm run`; `tensions`,
`pose_error`: the dynamic plant's ground truth; `safety`: the safety filter's) are OPTIONAL:
`plot_log` skips them for a log that lacks their keys.
"""

from collections.abc import Mapping

from cdpm_drake.runs.log import check_keys

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
_MAY_USE = {"pose_error": ("rpy",), "trajectory": ("p_true",),
            "tensions": ("tensions", "slack", "tension_estimate", "tension_target", "t_star"),
            "safety": ("kappa", "t_star_hand", "pair_margin", "pair_distances_true",
                       "crossed_true")}
# Figures drawn only for logs that hold their keys.
OPTIONAL = ("timing", "tensions", "pose_error", "safety")


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


def check_figure(log: Mapping, figure: str) -> None:
    """LogError (runs/log.py) when the log lacks a key the figure needs, or a per-tick key
    the figure reads has not one row per tick."""
    check_keys(log, _needs(log, figure), _MAY_USE.get(figure, ()), f"the {figure} plot")
