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

from .diagram import build_diagram, logged_signals, reserve_log
from .scenario import (DynamicReels, ResolvedScenario, Scenario, ScenarioError, SimulatedReels,
                       check_duration, resolve_scenario, write_run_scenario)


@dataclasses.dataclass
class SimulationResult:
    log: dict
    # Wall-clock seconds spent in Simulator.AdvanceTo.
    wall_time: float
    # The exception that ended the run early, or None.
    error: Exception | None = None

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
    mark_ending(log, "completed" if error is None else
                "interrupted" if isinstance(error, KeyboardInterrupt) else "fault", error)
    return SimulationResult(log=log, wall_time=wall, error=error)


def tick_targets(duration: float, time_step: float, chunk: float) -> list[float]:
    """The times to advance to, every `chunk` s (rounded to whole ticks, at least one), ending
    exactly at the last whole tick n * time_step <= duration (the log then has n + 1 rows)."""
    n = int(np.floor(duration / time_step + 1e-9))
    per = max(1, int(round(chunk / time_step)))
    ticks = list(range(per, n, per)) + [n]
    return [k * time_step for k in ticks if k > 0]


def mark_ending(log: dict, ending: str, error: BaseException | None) -> dict:
    """Add how the run ended (docs/LOG_FORMAT.md): `ending` "completed", "interrupted" or
    "fault"; for a fault, `fault_time` (the last logged tick, s) and `fault_message`."""
    if ending not in ("completed", "interrupted", "fault"):
        raise ValueError(f"ending must be 'completed', 'interrupted' or 'fault', got {ending!r}")
    t = log["time"]
    fault = ending == "fault"
    log["ending"] = np.array(ending)
    log["fault_time"] = np.array(float(t[-1]) if fault and len(t) else np.nan)
    message = "" if not fault else (f"{type(error).__name__}: {error}" if error is not None
                                    else "unknown fault")
    log["fault_message"] = np.array(message)
    return log


def collect_log(diagram, context, scenario: Scenario | ResolvedScenario, robot) -> dict:
    """The logger's contents as named arrays, one row per tick (docs/LOG_FORMAT.md)."""
    time_column, signals = logged_signals(diagram, context)
    # The dynamic plant's ground truth, logged inside the plant (no ports for it), one row per
    # tick like the rest: cut to the ticks every logger logged (Ctrl-C or SIGTERM can stop the
    # run between two loggers' publishes of one tick).
    from .systems.dynamic_plant import ground_truth_log
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
        from .interference import pair_distances
        log["pair_distances"] = pair_distances(robot, log["p"]).reshape(T, P)
    for key, width in (("F_int", 3), ("F_wall", 3), ("pair_distances", P), ("active", P),
                       ("crossed", P)):
        log.setdefault(key, np.zeros((T, width)))
    for key in ("active", "crossed", "slack"):
        if key in log:
            log[key] = np.asarray(log[key]) > 0.5
    log["pairs"] = np.array(robot.pairs, dtype=int).reshape(P, 2)
    params = resolved.interference
    if params is not None:
        for key in ("d_l", "d_u", "F_u", "eps"):
            log[key] = np.asarray(getattr(params, key), dtype=float)
        log["F_max"] = np.array(params.F_max)
    else:
        for key in ("d_l", "d_u", "F_u", "eps"):
            log[key] = np.full(P, np.nan)
        log["F_max"] = np.array(0.0)
    log["reels"] = robot.reels.copy()
    log["attachments"] = robot.attachments.copy()
    log["workspace_lower"] = robot.workspace.lower.copy()
    log["workspace_upper"] = robot.workspace.upper.copy()
    log["robot_name"] = np.array(robot.name)
    log["scenario_name"] = np.array(scenario.name)
    return log


def save_log(log: dict, out_dir, scenario: Scenario | ResolvedScenario) -> Path:
    """Write DIR/log.npz and the resolved scenario DIR/scenario.yaml, with copies of the
    robot file and force CSV it reads (scenario.write_run_scenario: the folder reruns alone);
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
    """Per watched pair that was ever active: (pair, min distance in mm to 0.01 mm as text,
    ticks active, crossed)."""
    rows = []
    for k, (i, j) in enumerate(log["pairs"]):
        active = log["active"][:, k]
        crossed = log["crossed"][:, k]
        if active.any() or crossed.any():
            d_min = 1000 * float(log["pair_distances"][:, k].min())
            rows.append((f"({i},{j})", f"{d_min:.2f}", int(active.sum()), int(crossed.any())))
    return rows
