"""The run's log, log.npz (docs/LOG_FORMAT.md), one row per tick: assembling it from the
logged signals, how the run ended, saving, loading and checking it, its summary table, and
whether a run's log fits in memory (and on disk).

`cdpm simulate` (runs/simulate.py) and `cdpm run` (runs/realtime.py) write it; `cdpm plot`,
`cdpm export` and the views read it with load_log. SI units, base frame A, as the format
says. What reads a diagram (the builder, the plant, Drake) is imported inside the functions
that need it, so that reading a log stays free of Drake.
"""

import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cdpm_drake.config import ResolvedScenario, Scenario, ScenarioError, resolve_scenario
from cdpm_drake.runs.run_scenario import write_run_scenario
from cdpm_drake.text import format_number

# Keys every log holds (load_log checks them).
LOG_KEYS = ("time", "p", "F_H", "F_int", "F_wall", "F_d", "velocity_admittance", "velocity",
            "reel_velocity", "lengths", "pair_distances", "active", "crossed", "pairs", "d_l",
            "d_u", "F_u", "eps", "F_max", "reels", "attachments", "workspace_lower",
            "workspace_upper", "robot_name", "scenario_name")
# Keys with one row per tick (check_keys checks those a reader uses).
PER_TICK_KEYS = ("time", "p", "F_H", "F_int", "F_d", "pair_distances", "active", "crossed",
                 "lengths", "reel_velocity", "wall", "tensions", "slack", "p_true", "rpy_true",
                 "lengths_commanded", "pair_distances_true", "crossed_true", "rpy",
                 "tension_estimate", "tension_target", "t_star", "F_kin", "filter_status",
                 "filter_binding", "velocity_limited", "kappa", "t_star_hand", "pair_margin")


# --- reading a log --------------------------------------------------------------------------


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
    # Every reader needs the rows to line up: a log cut or edited by hand is refused here,
    # once, with its name, not by the first figure that reads the short key.
    T = len(log["time"])
    for key in PER_TICK_KEYS:
        arr = np.asarray(log[key]) if key in log else None
        if arr is not None and (arr.ndim == 0 or arr.shape[0] != T):
            raise LogError(f"{str(path)!r}: log key {key!r} has shape {arr.shape!r}; expected "
                           f"one row per tick ({T} rows, as 'time')")
    return log


def nan_rows(log: Mapping, keys=("p", "F_H", "lengths")) -> list[str]:
    """For each key of `keys` the log holds with NaN in some rows: a sentence naming the
    key, how many rows and the first time (s). A reader that draws the log warns with them:
    the rows are gaps in its figures, not data."""
    out = []
    t = np.asarray(log["time"], dtype=float).reshape(-1)
    for key in keys:
        if key not in log:
            continue
        arr = np.asarray(log[key], dtype=float)
        bad = np.isnan(arr.reshape(arr.shape[0], -1)).any(axis=1) if arr.ndim else []
        if np.any(bad):
            first = int(np.argmax(bad))
            when = f" (first at t = {t[first]:.3f} s)" if first < len(t) else ""
            out.append(f"log key {key!r} is NaN on {int(np.sum(bad))} of {len(bad)} rows"
                       f"{when}: those rows are gaps in the figures")
    return out


def check_keys(log: Mapping, needs, may_use=(), reader: str = "this reader") -> None:
    """LogError when the log lacks a key of `needs` (the message names the `reader`, e.g.
    "the forces plot"), or, when `needs` has "time", when a per-tick key (PER_TICK_KEYS) of
    `needs` or of `may_use` that the log holds has not one row per tick."""
    needs = tuple(needs)
    missing = [k for k in needs if k not in log]
    if missing:
        raise LogError(f"{reader} needs log key(s) {missing!r} (docs/LOG_FORMAT.md); "
                       f"the log holds {sorted(log)!r}")
    if "time" in needs:
        T = len(log["time"])
        for key in needs + tuple(k for k in may_use if k in log):
            arr = np.asarray(log[key])
            if key in PER_TICK_KEYS and (arr.ndim == 0 or arr.shape[0] != T):
                raise LogError(f"log key {key!r} has shape {arr.shape!r}; expected one row per "
                               f"tick ({T} rows, as 'time')")


# --- assembling a log ---------------------------------------------------------------------


def collect_log(diagram, context, scenario: Scenario | ResolvedScenario, robot) -> dict:
    """The logger's contents as named arrays, one row per tick (docs/LOG_FORMAT.md)."""
    from cdpm_drake.diagram import logged_signals

    time_column, signals = logged_signals(diagram, context)
    # The dynamic plant's ground truth, logged inside the plant (no ports for it), one row per
    # tick like the rest: cut to the ticks every logger logged (Ctrl-C or SIGTERM can stop the
    # run between two loggers' publishes of one tick).
    from cdpm_drake.systems.plants.dynamic_plant import ground_truth_log
    truth = ground_truth_log(diagram, context)
    if truth:
        n = min([len(time_column)] + [len(rows) for rows in truth.values()])
        time_column = time_column[:n]
        signals = {key: rows[:n] for key, rows in {**signals, **truth}.items()}
    return assemble_log(time_column, signals, scenario, robot)


def log_from_tick_log(tick_path, scenario: Scenario | ResolvedScenario,
                      robot) -> tuple[dict, dict, dict]:
    """docs/LOG_FORMAT.md from a run's ticks.bin: (log without the ending keys, timing,
    {"ticks": whole rows read, "cut_bytes": bytes of a partial last row left out,
    "damaged": rows read that the file's damage garbled (tick_log.damaged_rows), kept as
    read, "damaged_ticks": their row numbers})."""
    from cdpm_drake.diagram import LOGGED
    from cdpm_drake.hardware.tick_log import (damaged_rows, read_tick_log, realtime_stats,
                                              tick_log_tail)

    resolved = resolve_scenario(scenario)
    scenario = resolved.scenario

    tick_path = Path(tick_path)
    raw = read_tick_log(tick_path) if tick_path.exists() else {}
    tail = tick_log_tail(tick_path) if tick_path.exists() else {"ticks": 0, "cut_bytes": 0}
    T = scenario.time_step
    damaged = damaged_rows(raw, T) if raw else np.zeros(0, dtype=bool)
    tail = dict(tail, damaged=int(damaged.sum()),
                damaged_ticks=np.flatnonzero(damaged).tolist())
    timing = realtime_stats(raw, T) if raw else {}
    signals = {key: raw[key] for key, _, _ in LOGGED if key in raw}
    log = assemble_log(raw.get("time", np.zeros(0)), signals, resolved, robot)
    log["tick"] = raw.get("tick", np.zeros(0, dtype=int))
    log["wall"] = raw.get("wall", np.zeros(0))
    compute = raw.get("compute", np.full((len(log["time"]), 1), np.nan))
    log["compute"] = np.asarray(compute, dtype=float).reshape(-1)
    plant = scenario.plant
    log["watchdog_limit"] = np.array(getattr(plant, "watchdog_ticks", np.nan) * T)
    return log, timing, tail


def assemble_log(time_column, signals: dict, scenario: Scenario | ResolvedScenario,
                 robot) -> dict:
    """docs/LOG_FORMAT.md from the logged signals ({LOGGED key: (T, width)}): fills the
    signals of blocks the diagram did not have, and adds the robot and parameters."""
    resolved = resolve_scenario(scenario)
    scenario = resolved.scenario
    log = dict(signals)
    T = len(time_column)
    P = robot.num_pairs
    log["time"] = np.asarray(time_column, dtype=float)
    if "pair_distances" not in log and P and "p" in log:
        # No interference block (disabled): the distances are still worth a look.
        from cdpm_drake.kernels.interference import pair_distances
        log["pair_distances"] = pair_distances(robot, log["p"]).reshape(T, P)
    for key, width in (("F_int", 3), ("F_wall", 3), ("pair_distances", P), ("active", P),
                       ("crossed", P)):
        log.setdefault(key, np.zeros((T, width)))
    for key in ("active", "crossed", "slack"):
        if key in log:
            log[key] = np.asarray(log[key]) > 0.5
    log["pairs"] = np.array(robot.pairs, dtype=int).reshape(P, 2)
    params = resolved.interference
    if "p_true" in log and "rpy_true" in log:
        # On the robot the plant plays (its true geometry where it differs from the file).
        log.update(true_pair_distances(resolved.plant_robot, log["p_true"], log["rpy_true"],
                                       None if params is None else params.d_u))
    if resolved.true_robot is not None:
        log["reels_true"] = resolved.true_robot.reels.copy()
        log["attachments_true"] = resolved.true_robot.attachments.copy()
        log["encoder_zero_error"] = np.asarray(resolved.encoder_zero_error, dtype=float)
        log["EA_true"] = np.array(float(resolved.true_robot.dynamics.EA))
        log["mass_true"] = np.array(float(resolved.true_robot.dynamics.mass))
        log["com_true"] = np.asarray(resolved.true_robot.dynamics.com, dtype=float).copy()
    if params is not None:
        for key in ("d_l", "d_u", "F_u", "eps"):
            log[key] = np.asarray(getattr(params, key), dtype=float)
        log["F_max"] = np.array(params.F_max)
    else:
        for key in ("d_l", "d_u", "F_u", "eps"):
            log[key] = np.full(P, np.nan)
        log["F_max"] = np.array(0.0)
    if "tension_target" in log:  # tension control: its target's floor and ceiling
        log["controller_min_tension"] = np.array(float(scenario.controller.min_tension))
        log["controller_max_tension"] = np.array(float(scenario.controller.max_tension))
    # The speed limit, m/s (the robot's or the scenario's): the summary tells a command held
    # at it from one slowed below it while a margin is lost.
    log["max_velocity"] = np.array(float(resolved.max_velocity))
    # The hard floor the safety filter keeps each pair at (d_min; logged whether or
    # not the filter ran, like d_l and d_u).
    if resolved.d_min is not None and len(resolved.d_min) == P:
        log["d_min"] = np.asarray(resolved.d_min, dtype=float)
        if resolved.d_min_margin is not None and np.any(resolved.d_min_margin):
            # What the robot file's stated uncertainty added to d_min (the summary says it).
            log["d_min_uncertainty"] = np.asarray(resolved.d_min_margin, dtype=float)
            log["kinetostatic_floor_uncertainty"] = np.array(resolved.kinetostatic_margin)
    # Where the platform started (the homing pose on a robot): what a calibration fixes.
    log["initial_position"] = np.asarray(scenario.initial_position, dtype=float)
    log["initial_rpy"] = np.asarray(getattr(scenario.plant, "initial_rpy", [0.0, 0.0, 0.0]),
                                    dtype=float)
    log["reels"] = robot.reels.copy()
    log["attachments"] = robot.attachments.copy()
    log["workspace_lower"] = robot.workspace.lower.copy()
    log["workspace_upper"] = robot.workspace.upper.copy()
    log["robot_name"] = np.array(robot.name)
    log["scenario_name"] = np.array(scenario.name)
    return log


# Where no d_u applies (interference off), a true crossing counts within this distance, m:
# a real one happens at d ~ 0, so any bound well above a tick's motion finds it.
TRUE_CROSSING_NEAR = 0.1


def true_pair_distances(robot, p_true, rpy_true, d_u=None) -> dict:
    """The ground truth of a plant that logs its true pose (the dynamic plant): every watched
    pair's distance along the run from the true, rotated platform, and where the pair was
    truly crossed (the controller's crossing rule on the true geometry, with each pair's d_u,
    else TRUE_CROSSING_NEAR). Computed from the log after the run, never wired to the
    controller. {"pair_distances_true": (T, P) m, "crossed_true": (T, P) bool}."""
    from cdpm_drake.kernels.interference import posed_pair_distances
    from cdpm_drake.kernels.rotation import rotations_from_rpy

    near = (np.full(robot.num_pairs, TRUE_CROSSING_NEAR) if d_u is None
            else np.asarray(d_u, dtype=float))
    dist, crossed = posed_pair_distances(robot, p_true, rotations_from_rpy(rpy_true), near)
    return {"pair_distances_true": dist, "crossed_true": crossed}


# --- how the run ended --------------------------------------------------------------------


def mark_ending(log: dict, ending: str, error: BaseException | None,
                diagnosis: str = "") -> dict:
    """Add how the run ended (docs/LOG_FORMAT.md): `ending` "completed", "interrupted" or
    "fault"; for a fault, `fault_time` (the last logged tick, s) and `fault_message` (the
    error, then the plant's `diagnosis` when there is one)."""
    if ending not in ("completed", "interrupted", "fault"):
        raise ValueError(f"ending must be 'completed', 'interrupted' or 'fault', got {ending!r}")
    t = log["time"]
    fault = ending == "fault"
    log["ending"] = np.array(ending)
    log["fault_time"] = np.array(float(t[-1]) if fault and len(t) else np.nan)
    message = "" if not fault else (f"{type(error).__name__}: {error}" if error is not None
                                    else "unknown fault")
    if fault and diagnosis:
        message += f" ({diagnosis})"
    log["fault_message"] = np.array(message)
    return log


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


# --- saving, and the summary table ---------------------------------------------------------


def save_log(log: dict, out_dir, scenario: Scenario | ResolvedScenario) -> Path:
    """Write DIR/log.npz and the resolved scenario DIR/scenario.yaml, with copies of the
    robot file and force CSV it reads (run_scenario.write_run_scenario: the folder reruns alone);
    returns the npz path. The scenario's duration is set to what the log covers, so the file
    reproduces the run."""
    changes = {"duration": float(log["time"][-1])} if len(log["time"]) else {}
    path = write_log(log, out_dir)
    write_run_scenario(Path(out_dir), scenario, **changes)
    return path


def write_log(log: dict, out_dir) -> Path:
    """Write DIR/log.npz (created if needed), compressed; returns its path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "log.npz"
    np.savez_compressed(path, **log)
    return path


def summary_rows(log: dict):
    """Per watched pair that ever came within its d_u (or, with a true pose logged, was truly
    within it or crossed): the pair; its smallest distance in mm (the controller's, and with
    a true pose the true one); its d_l and d_u in mm (the band of the force: it acts below
    d_u, and is strongest from d_l); on how many ticks it was within d_u (log `active`: the
    force on); whether it crossed (1: on some tick), and with a true pose whether it truly
    crossed. Distances as text to 0.01 mm; `summary_header` names the columns."""
    rows = []
    truth = "pair_distances_true" in log
    T = len(log["time"])

    def mm(x):
        return format_number(1000 * float(x)) if np.isfinite(x) else "-"

    for k, (i, j) in enumerate(log["pairs"]):
        active = log["active"][:, k]
        crossed = log["crossed"][:, k]
        show = active.any() or crossed.any()
        if truth and T:
            d_true = log["pair_distances_true"][:, k]
            d_u = float(log["d_u"][k]) if np.isfinite(log["d_u"][k]) else -np.inf
            show = show or bool(d_true.min() <= d_u) or bool(log["crossed_true"][:, k].any())
        if show and T:
            row = (f"({i},{j})", mm(log["pair_distances"][:, k].min()))
            if truth:
                row += (mm(d_true.min()),)
            row += (mm(log["d_l"][k]), mm(log["d_u"][k]), int(active.sum()),
                    int(crossed.any()))
            if truth:
                row += (int(log["crossed_true"][:, k].any()),)
            rows.append(row)
    return rows


def summary_header(log: dict) -> list[str]:
    """The column names of `summary_rows(log)`."""
    if "pair_distances_true" in log:
        return ["pair", "min distance, controller (mm)", "min distance, true (mm)", "d_l (mm)",
                "d_u (mm)", "ticks within d_u", "crossed", "truly crossed"]
    return ["pair", "min distance (mm)", "d_l (mm)", "d_u (mm)", "ticks within d_u",
            "crossed"]


# --- will the log fit --------------------------------------------------------------------------

# A run holds its whole log in memory: the loggers' rows, then their copy as the log's arrays
# (collect_log, or the tick log read back after `cdpm run`), so about twice the rows' bytes at
# the end of a run.
LOG_COPIES = 2


class LogTooLarge(ScenarioError):
    """A duration whose log cannot fit in memory (or on disk); the message names the sizes."""


def available_memory() -> int | None:
    """Bytes of memory a new allocation can get without swapping: Linux's MemAvailable (free
    memory plus the page cache it can drop), else the free physical pages (os.sysconf); None
    where neither is known (no check then)."""
    import os

    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def log_bytes_per_tick(diagram) -> int:
    """Bytes one tick adds to the run's in-memory log: 8 (a float64) per value of every
    VectorLogSink in the diagram and its subdiagrams (the controller's log, the dynamic
    plant's ground truth), plus its sample time."""
    from pydrake.systems.framework import Diagram
    from pydrake.systems.primitives import VectorLogSink

    total, todo = 0, [diagram]
    while todo:
        for system in todo.pop().GetSystems():
            if isinstance(system, Diagram):
                todo.append(system)
            elif isinstance(system, VectorLogSink):
                total += 8 * (system.get_input_port().size() + 1)
    return total


def _bytes(n: float) -> str:
    """A size in B, kB, MB, GB, TB (powers of 1000), three significant digits."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}"
        n /= 1000.0


def check_log_fits(duration: float, time_step: float, bytes_per_tick: int, *,
                   copies: int = LOG_COPIES, memory: int | None = None, disk_dir=None,
                   disk_bytes_per_tick: int = 0) -> None:
    """LogTooLarge when the log of a run of `duration` s (ticks 0..n of `time_step` s), of
    `bytes_per_tick`, held `copies` times, exceeds the memory available (`memory` bytes,
    default available_memory()), or when `disk_dir` is given and the ticks' rows of
    `disk_bytes_per_tick` exceed its free space (a real-time run streams them there first).
    The message names the duration, the sizes and the longest duration that fits."""
    import shutil

    ticks = int(np.floor(duration / time_step + 1e-9)) + 1
    limits = []
    memory = available_memory() if memory is None else memory
    if memory is not None and bytes_per_tick > 0:
        limits.append((memory, copies * bytes_per_tick, "memory available"))
    if disk_dir is not None and disk_bytes_per_tick > 0:
        try:
            free = shutil.disk_usage(disk_dir).free
        except OSError:
            free = None
        if free is not None:
            limits.append((free, disk_bytes_per_tick, f"free disk at {str(disk_dir)!r}"))
    for room, per_tick, what in limits:
        if ticks * per_tick > room:
            longest = max(0, room // per_tick - 1) * time_step
            held = (f", held {copies} times over" if per_tick == copies * bytes_per_tick
                    and copies > 1 else "")
            raise LogTooLarge(
                f"duration {duration:g} s is {ticks:,} ticks, whose log needs "
                f"{_bytes(ticks * per_tick)} ({per_tick:,} bytes a tick: "
                f"{bytes_per_tick // 8:,} logged values of 8 bytes{held}), more than the "
                f"{_bytes(room)} of {what}; give a duration of at most {longest:.4g} s here")
