"""A log as a MATLAB .mat file (`cdpm export LOG --mat`), version 5, written with scipy.

Every key of the log becomes a variable of the same name with the log's shape: per-tick keys
one row per tick (`time` a T x 1 column, `p` T x 3, `lengths` T x m with column i cable i),
per-run constants as they are (`pairs` P x 2, already 1-based cable numbers; `reels` m x 3).
Strings are char arrays, flags logical, NaN and inf kept. Beside them: `cables`, the column
vector 1..m (so `lengths(:, cables == 3)` is cable 3), and `units`, a struct with the unit
of every key (log_csv.unit_of: SI, "0/1" a flag, "-" none, a status code its meaning).
No Drake.
"""

import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cdpm_drake.views.log_csv import unit_of

# MATLAB's rule for a variable or field name (namelengthmax is 63).
_MATLAB_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")
# Names the export adds beside the log's keys.
ADDED = ("cables", "units")


class MatExportError(ValueError):
    """A log that cannot be written as a .mat file (a key MATLAB cannot name)."""


def log_to_mat_dict(log: Mapping) -> dict:
    """{variable name: value} for scipy.io.savemat: the log's keys, `cables` and `units`."""
    out = {}
    for key in log:
        if not _MATLAB_NAME.fullmatch(key) or key in ADDED:
            raise MatExportError(f"log key {key!r} cannot be a MATLAB variable (a letter, then "
                                 "letters, digits or _, at most 63; not 'cables' or 'units')")
        value = np.asarray(log[key])
        if value.dtype.kind == "U":
            value = str(value) if value.ndim == 0 else value  # a char array
        out[key] = value
    m = np.shape(log["reels"])[0] if "reels" in log else np.shape(log["lengths"])[1]
    out["cables"] = np.arange(1, m + 1, dtype=float)
    # A key the format does not list (a newer log's) gets no unit rather than a guessed one.
    out["units"] = {key: unit_of(key) or "" for key in log}
    out["units"]["cables"] = "-"
    return out


def write_log_mat(log: Mapping, path) -> Path:
    """Write the log to `path` as a version-5 .mat file (1-D arrays as columns); returns it.
    Needs scipy (ImportError without it)."""
    from scipy.io import savemat

    path = Path(path)
    # Written beside, then renamed: an export stopped part-way leaves no half file.
    part = path.with_name(f".{path.name}.part")
    try:
        savemat(part, log_to_mat_dict(log), format="5", oned_as="column",
                long_field_names=True, do_compression=True)
        part.replace(path)
    finally:
        part.unlink(missing_ok=True)
    return path
