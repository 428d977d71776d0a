"""A log as CSV (`cdpm export LOG`): one row per tick, one named column per value.

Every per-tick key of docs/LOG_FORMAT.md that the log holds becomes columns named
`<key>_<component> [<unit>]`: the x, y, z of a vector (`p_x [m]`, `F_H_z [N]`,
`omega_z [rad/s]`), cables numbered from 1 (`lengths_1 [m]`, `tensions_7 [N]`), cable pairs
by their cable numbers `i-j` (`pair_distances_1-3 [m]`, `crossed_true_1-3 [0/1]`), roll,
pitch and yaw of an orientation (`rpy_true_roll [rad]`); a key with one value per tick is
one column (`t_star [N]`). Flags are 0 or 1 (`[0/1]`), status codes integers labelled with
their meaning, NaN an empty cell, floats in the shortest form that reads back exactly. The
per-run constants (robot geometry, logistic parameters, how the run ended) stay in log.npz.
COLUMNS and RUN_CONSTANTS are the one table of every key's unit (unit_of), which the MATLAB
and MCAP exports read too. No Drake.
"""

import csv
import io
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

# The status codes (docs/LOG_FORMAT.md), as their columns' "unit".
TENSION_STATUS = ("code: 0 floor held/1 floor lowered/2 rank-deficient/3 ceiling exceeded/"
                  "4 floor unreachable/5 hand too fast")
CABLE_NUMBER = "cable: 1..m; 0 none"
FILTER_STATUS = "code: 0 passed/1 modified/2 lost margins held/3 braking to a hold"
FILTER_BINDING = ("bits: 1 pairs/2 box/4 kinetostatic/8 speed/16 acceleration")
MODEL_STATUS = "code: 0 ok/1 slack cable/2 lengths misfit/3 hand unholdable"
# Per-tick keys in docs/LOG_FORMAT.md's order: (unit, what the columns are).
# "xyz": three components; "rpy": roll, pitch, yaw; "cables": one per cable; "pairs": one per
# watched pair; None: one value per tick. The units "0/1" (flags) and TENSION_STATUS (codes)
# are written as integers.
COLUMNS = {
    "time": ("s", None),
    "tick": ("-", None),
    "p": ("m", "xyz"),
    "F_H": ("N", "xyz"),
    "F_measured": ("N", "xyz"),
    "tension_measured": ("N", "cables"),
    "F_int": ("N", "xyz"),
    "F_wall": ("N", "xyz"),
    "F_d": ("N", "xyz"),
    "velocity_admittance": ("m/s", "xyz"),
    "velocity": ("m/s", "xyz"),
    "reel_velocity": ("m/s", "cables"),
    "reel_velocity_damping": ("m/s", "cables"),
    "lengths": ("m", "cables"),
    "lengths_commanded": ("m", "cables"),
    "pair_distances": ("m", "pairs"),
    "active": ("0/1", "pairs"),
    "crossed": ("0/1", "pairs"),
    "wall": ("s", None),
    "compute": ("s", None),
    # The full-pose controller (controller.pose: full) and its tension control.
    "rpy": ("rad", "rpy"),
    "omega": ("rad/s", "xyz"),
    "tension_estimate": ("N", "cables"),
    "tension_target": ("N", "cables"),
    "tension_command": ("N", "cables"),
    "t_star": ("N", None),
    "tension_status": (TENSION_STATUS, None),
    "tension_cable": (CABLE_NUMBER, None),
    # Without a tension sensor: the ringing the encoders cannot see, predicted.
    "ringing_swing": ("N", "cables"),
    "ringing_warned": ("0/1", "cables"),
    # The safety filter, its kinetostatic limit, the model monitor (beyond the paper).
    "velocity_limited": ("m/s", "xyz"),
    "filter_status": (FILTER_STATUS, None),
    "filter_binding": (FILTER_BINDING, None),
    "pair_margin": ("m", None),
    "F_kin": ("N", "xyz"),
    "kappa": ("N", None),
    "t_c": ("N", None),
    "t_star_hand": ("N", None),
    "model_status": (MODEL_STATUS, None),
    "model_residual": ("m", "cables"),
    # The dynamic plant's ground truth.
    "tensions": ("N", "cables"),
    "slack": ("0/1", "cables"),
    "p_true": ("m", "xyz"),
    "rpy_true": ("rad", "rpy"),
    "pair_distances_true": ("m", "pairs"),
    "crossed_true": ("0/1", "pairs"),
    # Issue 31: the sensed tensions (NaN where the plant has no sensor) and the tension
    # damping's part of reel_velocity.
    "tension_measured": ("N", "cables"),
    "reel_velocity_damping": ("m/s", "cables"),
}
# The per-run constants (docs/LOG_FORMAT.md), their units: "-" a number without one (cable
# numbers) or text.
RUN_CONSTANTS = {
    "pairs": "-", "d_l": "m", "d_u": "m", "F_u": "N", "eps": "N", "d_min": "m",
    "F_max": "N", "max_velocity": "m/s", "reels": "m", "attachments": "m",
    "workspace_lower": "m", "workspace_upper": "m", "robot_name": "-", "scenario_name": "-",
    "ending": "-", "fault_time": "s", "fault_message": "-", "watchdog_limit": "s",
    "controller_min_tension": "N", "controller_max_tension": "N",
    # The homing pose; a plant that plays the robot as built (docs/calibration.md).
    "initial_position": "m", "initial_rpy": "rad", "reels_true": "m",
    "attachments_true": "m", "encoder_zero_error": "m", "EA_true": "N", "mass_true": "kg",
    "com_true": "m",
    "d_min_uncertainty": "m", "kinetostatic_floor_uncertainty": "N",
}
_PARTS = {"xyz": ("x", "y", "z"), "rpy": ("roll", "pitch", "yaw")}
_INTEGERS = ("0/1", TENSION_STATUS, CABLE_NUMBER, FILTER_STATUS, FILTER_BINDING,
             MODEL_STATUS)


def unit_of(key: str) -> str | None:
    """The unit of a log key as the exports write it (a status code's meaning, 0/1 for a
    flag); None for a key docs/LOG_FORMAT.md does not list."""
    if key in COLUMNS:
        return COLUMNS[key][0]
    return RUN_CONSTANTS.get(key)


def csv_columns(log: Mapping) -> list[tuple[str, np.ndarray]]:
    """(header, values (T,)) of every column, in COLUMNS order; keys not in COLUMNS with one
    row per tick follow, numbered from 1 without a unit."""
    T = len(np.asarray(log["time"]).reshape(-1))
    pairs = np.asarray(log.get("pairs", np.zeros((0, 2))), dtype=int).reshape(-1, 2)
    columns = []
    keys = [k for k in COLUMNS if k in log] + sorted(
        k for k in log if k not in COLUMNS and np.ndim(log[k]) in (1, 2)
        and np.shape(log[k])[0] == T and np.asarray(log[k]).dtype.kind in "biuf")
    for key in keys:
        values = np.asarray(log[key])
        if values.ndim == 0 or values.shape[0] != T:
            continue  # not one row per tick (a malformed log): left out, not misaligned
        unit, kind = COLUMNS.get(key, ("", None))
        if unit in _INTEGERS and np.all(np.isfinite(values)):
            values = values.astype(int)
        suffix = f" [{unit}]" if unit else ""
        if values.ndim == 1 or (kind is None and values.shape[1] == 1):
            columns.append((f"{key}{suffix}", values.reshape(T)))
            continue
        width = values.shape[1]
        if kind in _PARTS and width == len(_PARTS[kind]):
            names = _PARTS[kind]
        elif kind == "pairs" and width == len(pairs):
            names = [f"{i}-{j}" for i, j in pairs]
        else:
            names = [str(c + 1) for c in range(width)]  # cables (and anything else) from 1
        columns += [(f"{key}_{name}{suffix}", values[:, c]) for c, name in enumerate(names)]
    return columns


def _cell(value) -> str:
    """A Python bool, int or float as a cell: 1/0, the integer, the shortest exact float
    ("" for NaN)."""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(value)
    return "" if math.isnan(value) else repr(value)


def log_to_csv(log: Mapping) -> str:
    """The CSV text: a header row, then one row per tick."""
    columns = csv_columns(log)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([name for name, _ in columns])
    data = [values.tolist() for _, values in columns]  # Python scalars: fast to format
    for row in zip(*data):
        writer.writerow([_cell(v) for v in row])
    return buffer.getvalue()


def write_log_csv(log: Mapping, path) -> Path:
    """Write log_to_csv(log) to `path`; returns it."""
    path = Path(path)
    path.write_text(log_to_csv(log))
    return path
