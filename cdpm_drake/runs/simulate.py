"""Running a scenario's diagram with Drake's Simulator, and its log.

`simulate(scenario=...)` is what `cdpm simulate` calls; it returns the log as a dict of arrays
(see docs/LOG_FORMAT.md). A run that fails part-way still returns (and the CLI still writes)
everything logged up to the failure.
"""

import dataclasses
import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator

from cdpm_drake.diagram import build_diagram, logged_signals, reserve_log
from cdpm_drake.config import (DynamicReels, ResolvedScenario, Scenario, ScenarioError, SimulatedReels,
                       check_duration, resolve_scenario)
from cdpm_drake.runs.run_scenario import write_run_scenario


@dataclasses.dataclass
class SimulationResult:
    log: dict
    # Wall-clock seconds spent in Simulator.AdvanceTo.
    wall_time: float
    # The exception that ended the run early, or None.
    error: Exception | None = None
    # What the plant's ground truth says about a fault (`plant_fault_causes`; "" when the
    # plant logs none or the run did not fault).
    diagnosis: str = ""

    @property
    def realtime_factor(self) -> float:
        t = self.log["time"]
        return float(t[-1] - t[0]) / self.wall_time if t.size > 1 and self.wall_time > 0 else 0.0


def simulate(*, scenario: Scenario | ResolvedScenario, duration: float | None = None, progress: bool = False,
             on_chunk=None, chunk: float = 0.5, diagram=None,
             realtime_rate: float | None = None) -> SimulationResult:
    """Simulate the scenario's diagram for `duration` s (default: the scenario's).

    `on_chunk(diagram, context)` is called every `chunk` s of simulated time (views hang off
    it). `realtime_rate` paces the simulation (1.0: real time, for a live view); None runs
    as fast as it can. Exceptions raised by the diagram end the run; the result carries them
    in `error` with the log up to that point.
    """
    resolved = resolve_scenario(scenario)  # once: the builder and the log take it
    scenario, robot = resolved.scenario, resolved.robot
    if diagram is None and not isinstance(scenario.plant, (SimulatedReels, DynamicReels)):
        raise ScenarioError(
            f"scenario {scenario.name!r} has plant: !{type(scenario.plant).__name__}; a "
            "simulation needs plant: !SimulatedReels {} or !DynamicReels {} (use `cdpm run` "
            "to drive real reels)")
    duration = scenario.duration if duration is None else float(duration)
    if not (duration > 0 and np.isfinite(duration)):
        raise ValueError(f"duration must be a finite number > 0 s, got {duration!r}")
    check_duration(duration, scenario.time_step, "duration")
    diagram = build_diagram(resolved) if diagram is None else diagram
    check_log_fits(duration, scenario.time_step, log_bytes_per_tick(diagram))
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    if realtime_rate is not None:
        simulator.set_target_realtime_rate(float(realtime_rate))
    simulator.Initialize()
    reserve_log(diagram, context, int(duration / scenario.time_step) + 2)  # rows 0..n, + slack
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=round(duration, 6), unit="s sim", desc=scenario.name,
                   bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s [{elapsed}<{remaining}]")
    error = None
    start = time.perf_counter()
    t = 0.0
    try:
        # Step to the last whole tick inside the duration: one log row per tick, ticks 0..n.
        # Targets are whole ticks counted in integers: summing a chunk such as 0.04 s in
        # floating point ends a hair short of the last tick, which then is never logged.
        for target in tick_targets(duration, scenario.time_step, chunk):
            simulator.AdvanceTo(target)
            if bar is not None:
                bar.update(round(target - t, 6))
            t = target
            if on_chunk is not None:
                on_chunk(diagram, context)
    except (Exception, KeyboardInterrupt) as e:  # keep what was logged; the caller reports
        error = e
    finally:
        wall = time.perf_counter() - start
        if bar is not None:
            bar.close()
    log = collect_log(diagram, context, resolved, robot)
    diagnosis = ""
    if error is not None and not isinstance(error, KeyboardInterrupt):
        diagnosis = plant_fault_causes(log, resolved)
    mark_ending(log, "completed" if error is None else
                "interrupted" if isinstance(error, KeyboardInterrupt) else "fault", error,
                diagnosis)
    return SimulationResult(log=log, wall_time=wall, error=error, diagnosis=diagnosis)


def run_variant(scenario: Scenario | ResolvedScenario) -> tuple[list[str], str]:
    """What kind of run a scenario makes, for a person listing runs: (words for a summary's
    first line, e.g. ["dynamic plant", "full pose", "tension control"]; a tag for the run
    folder's name, e.g. "dynamic-full-pose-tension-control", "" for the default: the
    kinematic plant and the paper's translating controller)."""
    scenario = scenario.scenario if isinstance(scenario, ResolvedScenario) else scenario
    plant = scenario.plant
    words, tags = [], []
    if isinstance(plant, DynamicReels):
        words.append("dynamic plant")
        tags.append("dynamic")
    elif isinstance(plant, SimulatedReels):
        words.append("kinematic plant")
    else:
        words.append("hardware reels")
        tags.append("hardware")
    c = scenario.controller
    if c.pose == "full":
        words.append("full pose")
        tags.append("full-pose")
        if c.tension_control:
            words.append("tension control")
            tags.append("tension-control")
    else:
        words.append("translation only")
    return words, "-".join(tags)


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


# What plant_fault_causes counts as worth naming: a tilt above this, deg; an FK error above
# this, m.
NOTABLE_TILT = 1.0
NOTABLE_FK_ERROR = 0.002


def plant_fault_causes(log: dict, resolved: ResolvedScenario) -> str:
    """Why a run on a plant that logs its ground truth (the dynamic plant) faulted, from the
    truth at its last tick: slack cables (since when), the platform's tilt (the controller's
    model assumes a translating platform), how far the controller's position estimate was
    from the true one, the most stretched cable, and reel commands at the drives' speed
    limit. "" for a plant without ground truth or an empty log."""
    if "tensions" not in log or not len(log["time"]):
        return ""
    from cdpm_drake.kernels.rotation import rotation_angle, rotations_from_rpy

    t = log["time"]
    k = len(t) - 1
    causes = []
    slack = np.asarray(log["slack"], dtype=bool)
    cables = np.flatnonzero(slack[k])
    if cables.size:
        since = []
        for i in cables:
            taut = np.flatnonzero(~slack[:, i])
            first = taut[-1] + 1 if taut.size else 0
            since.append(f"{i + 1} since t = {t[first]:.3f} s")
        causes.append(f"cable{'s' if cables.size > 1 else ''} "
                      f"{', '.join(str(i + 1) for i in cables)} slack ({'; '.join(since)})")
    tilt = float(np.degrees(rotation_angle(rotations_from_rpy(log["rpy_true"][k]))[0]))
    if tilt > NOTABLE_TILT:
        causes.append(f"the platform tilted {tilt:.1f} deg (the controller's model keeps it "
                      "level)")
    fk_error = float(np.linalg.norm(log["p"][k] - log["p_true"][k]))
    if fk_error > NOTABLE_FK_ERROR:
        causes.append(f"the controller's position estimate {1000 * fk_error:.1f} mm from the "
                      "true position")
    dyn = resolved.robot.dynamics
    tensions = np.asarray(log["tensions"][k], dtype=float)
    if "lengths" in log and dyn is not None and tensions.size:
        stretch = tensions * np.asarray(log["lengths"][k]) / float(dyn.EA)
        i = int(np.argmax(stretch))
        causes.append(f"the most stretched cable {i + 1}: {1000 * stretch[i]:.2f} mm at "
                      f"{tensions[i]:.1f} N")
    if "reel_velocity" in log:
        peak = np.max(np.abs(log["reel_velocity"]), axis=1)
        limit = resolved.max_reel_speed
        if peak[k] >= limit:
            below = np.flatnonzero(peak < limit)
            first = below[-1] + 1 if below.size else 0
            causes.append(f"reel commands at the drives' speed limit {limit:g} m/s since "
                          f"t = {t[first]:.3f} s (scaled down: the platform lags)")
    return f"the dynamic plant at t = {t[k]:.3f} s: " + "; ".join(causes) if causes else ""


def tick_targets(duration: float, time_step: float, chunk: float) -> list[float]:
    """The times to advance to, every `chunk` s (rounded to whole ticks, at least one), ending
    exactly at the last whole tick n * time_step <= duration (the log then has n + 1 rows)."""
    n = int(np.floor(duration / time_step + 1e-9))
    per = max(1, int(round(chunk / time_step)))
    ticks = list(range(per, n, per)) + [n]
    return [k * time_step for k in ticks if k > 0]


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


def collect_log(diagram, context, scenario: Scenario | ResolvedScenario, robot) -> dict:
    """The logger's contents as named arrays, one row per tick (docs/LOG_FORMAT.md)."""
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
        log.update(true_pair_distances(robot, log["p_true"], log["rpy_true"],
                                       None if params is None else params.d_u))
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
    # The hard floor the safety filter keeps each pair at (d_min; logged whether or
    # not the filter ran, like d_l and d_u).
    if resolved.d_min is not None and len(resolved.d_min) == P:
        log["d_min"] = np.asarray(resolved.d_min, dtype=float)
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


def save_log(log: dict, out_dir, scenario: Scenario | ResolvedScenario) -> Path:
    """Write DIR/log.npz and the resolved scenario DIR/scenario.yaml, with copies of the
    robot file and force CSV it reads (run_scenario.write_run_scenario: the folder reruns alone);
    returns the npz path. The scenario's duration is set to what the log covers, so the file
    reproduces the run."""
    changes = {"duration": float(log["time"][-1])} if len(log["time"]) else {}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "log.npz"
    np.savez_compressed(path, **log)
    write_run_scenario(out, scenario, **changes)
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
        return f"{1000 * float(x):.2f}" if np.isfinite(x) else "-"

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
