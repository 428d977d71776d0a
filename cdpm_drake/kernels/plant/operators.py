"""Models of the person holding the handle, for simulation and the reel-bridge emulator.

numpy and numba, no Drake. An operator is a pure function of time and the platform's true motion, so that it
keeps no hidden state: `force(t, p, v) -> (3,)`, base frame, N; t in s, p in m, v in m/s.
"""

import csv
import math
import dataclasses
import typing
from pathlib import Path

import numba
import numpy as np

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


class OperatorError(ValueError):
    """A bad operator description; the message names the field and the value."""


# The shipped models as one compiled kernel (operator_force_into), by kind: the simulated
# reels tick the person with it (operator_force_on_state), no Python model call per tick.
NO_FORCE, FORCE_PROFILE, SPRING_HAND = 0, 1, 2


class NoForce:
    """Nobody touches the handle."""

    def force(self, t: float, p, v) -> np.ndarray:
        return np.zeros(3)

    def force_into(self, t: float, p, v, out) -> None:
        out[:] = 0.0

    def compiled(self):
        """(kind, times (n,) s, rows (n, 3), params (4,)) for operator_force_into."""
        return NO_FORCE, np.zeros(1), np.zeros((1, 3)), np.zeros(4)


class ForceProfile:
    """A piecewise-linear force table (t_k, F_k); held at the end values outside the table."""

    def __init__(self, times, forces, *, field: str = "operator",
                 values: tuple[str, str] = ("forces", "[Fx, Fy, Fz] row (N)"), rows=None):
        """`values` names the rows' field and what a row is, for messages (the spring hand's
        rows are waypoints). `rows`: where each row comes from, for messages (a CSV's
        "'file' line 7"); default `<field>.times[k]`."""
        name, row = values
        t = np.asarray(times, dtype=float)
        f = np.asarray(forces, dtype=float)
        if t.ndim != 1 or t.size == 0:
            raise OperatorError(f"{field}.times must be a non-empty list of seconds, got "
                                f"{times!r}")
        if f.shape != (t.size, 3):
            raise OperatorError(f"{field}.{name} must have one {row} per time; "
                                f"got shape {f.shape} for {t.size} times")
        # Where each row is, as messages name it: "operator.path: 'f.csv' line 7", or
        # "operator.times[3], operator.forces[3]".
        self.rows = ([f"{field}: {r}" for r in rows] if rows is not None
                     else [f"{field}.times[{k}], {field}.{name}[{k}]" for k in range(t.size)])
        bad = ~(np.isfinite(t) & np.all(np.isfinite(f), axis=1))
        if bad.any():
            k = int(np.argmax(bad))
            raise OperatorError(f"{self.rows[k]}: the time and the {row} must be finite "
                                f"numbers, got t = {float(t[k])!r} s, "
                                f"{[float(x) for x in f[k]]!r}")
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0))
            raise OperatorError(f"{field}.times must increase strictly: times[{k + 1}] = "
                                f"{float(t[k + 1])!r} s follows {float(t[k])!r} s")
        self.times, self.forces = t, np.ascontiguousarray(f)

    def force(self, t: float, p, v) -> np.ndarray:
        out = np.empty(3)
        _interp_into(self.times, self.forces, float(t), out)
        return out

    def force_into(self, t: float, p, v, out) -> None:
        """`force` written into out (3,): the simulated operator's tick."""
        _interp_into(self.times, self.forces, t, out)

    def compiled(self):
        """(kind, times (n,) s, rows (n, 3), params (4,)) for operator_force_into."""
        return FORCE_PROFILE, self.times, self.forces, np.zeros(4)


@_jit
def _interp_into(times, rows, t, out):
    """Piecewise-linear interpolation of rows (n, 3) at times (n,), held at the end rows, as
    np.interp per column: slope (f_j+1 - f_j) / (t_j+1 - t_j) times (t - t_j) plus f_j."""
    n = times.shape[0]
    if t <= times[0] or n == 1:
        j = 0 if t <= times[0] else n - 1
        out[0], out[1], out[2] = rows[j, 0], rows[j, 1], rows[j, 2]
        return
    if t >= times[n - 1]:
        out[0], out[1], out[2] = rows[n - 1, 0], rows[n - 1, 1], rows[n - 1, 2]
        return
    j = np.searchsorted(times, t, side="right") - 1
    dt = times[j + 1] - times[j]
    for k in range(3):
        out[k] = (rows[j + 1, k] - rows[j, k]) / dt * (t - times[j]) + rows[j, k]


@_jit
def _spring_force_into(times, waypoints, K, D, F_max, release, t, p, v, out):
    """The SpringHand force (N) into out (3,); release = inf: never lets go."""
    if t >= release:
        out[0] = out[1] = out[2] = 0.0
        return
    _interp_into(times, waypoints, t, out)
    fx = K * (out[0] - p[0]) - D * v[0]
    fy = K * (out[1] - p[1]) - D * v[1]
    fz = K * (out[2] - p[2]) - D * v[2]
    n = math.sqrt(fx * fx + fy * fy + fz * fz)
    if n > F_max:
        k = F_max / n
        fx, fy, fz = fx * k, fy * k, fz * k
    out[0], out[1], out[2] = fx, fy, fz


def _without_trailing_blanks(cells: list) -> list:
    """A CSV row without its trailing empty cells (`1,2,3,4,` as a spreadsheet writes it)."""
    cells = list(cells)
    while cells and not cells[-1].strip():
        cells.pop()
    return cells


def load_force_csv(path, *, field: str = "operator.path") -> ForceProfile:
    """A CSV with a header row `t, fx, fy, fz` (s, N) replayed as a ForceProfile."""
    path = Path(path)
    if not path.is_file():
        raise OperatorError(f"{field}: force file {str(path)!r} does not exist")
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise OperatorError(f"{field}: force file {str(path)!r} is empty")
    header = _without_trailing_blanks([h.strip().lower() for h in rows[0]])
    want = ["t", "fx", "fy", "fz"]
    if header != want:
        # An extra column (a torque, a second sensor) would be dropped without a word.
        raise OperatorError(f"{field}: force file {str(path)!r} must have exactly the header "
                            f"{','.join(want)} (four columns), got {','.join(rows[0])!r}")
    data, lines = [], []
    for n, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue  # a blank line (a trailing newline too many)
        where = f"{field}: {str(path)!r} line {n}"
        try:
            if len(_without_trailing_blanks(row)) != 4:  # short: a shape error; long: a
                raise ValueError                            # column dropped unseen
            values = [float(x) for x in row[:4]]
        except ValueError:
            raise OperatorError(f"{where}: not four numbers (t, fx, fy, fz): {row!r}") from None
        if not all(math.isfinite(x) for x in values):
            raise OperatorError(f"{where}: t, fx, fy, fz must be finite numbers, got {row!r}")
        if data and not values[0] > data[-1][0]:
            raise OperatorError(f"{where}: times must increase strictly: t = {values[0]!r} s "
                                f"follows t = {data[-1][0]!r} s on line {lines[-1]}")
        data.append(values)
        lines.append(n)
    if not data:
        raise OperatorError(f"{field}: force file {str(path)!r} has no data rows")
    arr = np.array(data)
    return ForceProfile(arr[:, 0], arr[:, 1:], field=field,
                        rows=[f"{str(path)!r} line {n}" for n in lines])


class SpringHand:
    """A hand pulling the handle towards a moving target through a spring-damper.

    The target moves piecewise-linearly through `waypoints` (m, base frame), reaching waypoint k
    at `times[k]` (s) and holding the last one. F = K (target(t) - p) - D v, its norm capped at
    `max_force` (N): a person does not pull harder than that.
    """

    def __init__(self, waypoints, times, stiffness, damping, max_force, release_time=None, *,
                 field: str = "operator"):
        w = np.asarray(waypoints, dtype=float)
        self.profile = ForceProfile(times, w, field=field,  # same checks: rows of 3 per time
                                    values=("waypoints", "[x, y, z] row (m)"))
        for name, value in (("stiffness", stiffness), ("damping", damping),
                            ("max_force", max_force)):
            if not np.isfinite(value) or value < 0:
                raise OperatorError(f"{field}.{name} must be a finite value >= 0, got {value!r}")
        self.K, self.D, self.F_max = float(stiffness), float(damping), float(max_force)
        if release_time is not None and not np.isfinite(release_time):
            raise OperatorError(f"{field}.release_time must be a time in s or null, got "
                                f"{release_time!r}")
        self.release_time = None if release_time is None else float(release_time)

    def target(self, t: float) -> np.ndarray:
        return self.profile.force(t, None, None)

    def force(self, t: float, p, v) -> np.ndarray:
        out = np.empty(3)
        self.force_into(float(t), np.asarray(p, dtype=float), np.asarray(v, dtype=float), out)
        return out

    def force_into(self, t: float, p, v, out) -> None:
        """`force` written into out (3,): the simulated operator's tick."""
        release = math.inf if self.release_time is None else self.release_time
        _spring_force_into(self.profile.times, self.profile.forces, self.K, self.D, self.F_max,
                           release, t, p, v, out)

    def compiled(self):
        """(kind, times (n,) s, rows (n, 3) m, params [K, D, F_max, release]) for
        operator_force_into."""
        release = math.inf if self.release_time is None else self.release_time
        return (SPRING_HAND, self.profile.times, self.profile.forces,
                np.array([self.K, self.D, self.F_max, release]))


@_jit
def operator_force_on_state(kind, times, rows, params, t, state, m):
    """`operator_force_into` on the simulated world's state (systems.simulated_reels: p at
    m, v at m + 3, the force written at 2 m + 6, for m cables)."""
    operator_force_into(kind, times, rows, params, t, state[m:m + 3], state[m + 3:m + 6],
                        state[2 * m + 6:2 * m + 9])


@_jit
def operator_force_at(kind, times, rows, params, t, x, ip, iv, out, io):
    """`operator_force_into` on p = x[ip:ip + 3], v = x[iv:iv + 3], the force written to
    out[io:io + 3] (the dynamic plant's step: systems/dynamic_plant.py)."""
    operator_force_into(kind, times, rows, params, t, x[ip:ip + 3], x[iv:iv + 3],
                        out[io:io + 3])


@_jit
def operator_force_into(kind, times, rows, params, t, p, v, out):
    """The force (N) of a shipped model at time t (s) on p (m), v (m/s), into out (3,), from
    its `compiled()` form: the same kernels as the models' own force_into."""
    if kind == SPRING_HAND:
        _spring_force_into(times, rows, params[0], params[1], params[2], params[3], t, p, v,
                           out)
    elif kind == FORCE_PROFILE:
        _interp_into(times, rows, t, out)
    else:
        out[0] = out[1] = out[2] = 0.0


# --- Typed descriptions (the scenario's `operator:` entry) -----------------------------------
# Loaded with yaml_load_typed; the YAML tag is the class name, e.g. `operator: !SpringHandOperator`.

@dataclasses.dataclass
class NoOperator:
    """Nobody touches the handle (experiment 1)."""


@dataclasses.dataclass
class ScriptedOperator:
    """A piecewise-linear force table."""

    # Breakpoint times, s, strictly increasing.
    times: list[float] = dataclasses.field(default_factory=lambda: [0.0])
    # Force at each breakpoint, [Fx, Fy, Fz] in N, base frame.
    forces: list[list[float]] = dataclasses.field(default_factory=lambda: [[0.0, 0.0, 0.0]])


@dataclasses.dataclass
class CsvOperator:
    """Replay of a recorded force: CSV with header t,fx,fy,fz (s, N)."""

    # Path to the CSV file; relative paths are relative to the scenario file.
    path: str = ""


@dataclasses.dataclass
class SpringHandOperator:
    """A spring-damper hand pulling the handle through waypoints with a capped force."""

    # Hand target positions, m, base frame.
    waypoints: list[list[float]] = dataclasses.field(default_factory=list)
    # Time at which the target reaches each waypoint, s.
    times: list[float] = dataclasses.field(default_factory=list)
    # Spring stiffness, N/m.
    stiffness: float = 60.0
    # Damping, N s/m.
    damping: float = 6.0
    # Largest force the person applies, N.
    max_force: float = 5.0
    # Time at which the person lets go of the handle, s (null: never).
    release_time: typing.Optional[float] = None


OPERATOR_TYPES = (NoOperator, ScriptedOperator, CsvOperator, SpringHandOperator)


def make_operator(config, base_dir: Path | None = None):
    """The operator model for a typed description (one of OPERATOR_TYPES)."""
    if isinstance(config, NoOperator):
        return NoForce()
    if isinstance(config, ScriptedOperator):
        return ForceProfile(config.times, config.forces, field="operator")
    if isinstance(config, CsvOperator):
        path = Path(config.path)
        if base_dir is not None and not path.is_absolute():
            path = Path(base_dir) / path
        return load_force_csv(path)
    if isinstance(config, SpringHandOperator):
        return SpringHand(config.waypoints, config.times, config.stiffness, config.damping,
                          config.max_force, config.release_time, field="operator")
    raise OperatorError(f"unknown operator {type(config).__name__!r}; valid operators: "
                        f"{[t.__name__ for t in OPERATOR_TYPES]}")
