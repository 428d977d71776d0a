"""Running a scenario's diagram with Drake's Simulator.

`simulate(scenario=...)` is what `cdpm simulate` calls; it returns the log as a dict of arrays
(runs/log.py, docs/LOG_FORMAT.md). A run that fails part-way still returns (and the CLI still
writes) everything logged up to the failure.
"""

import dataclasses
import time

import numpy as np
from pydrake.systems.analysis import Simulator

from cdpm_drake.diagram import build_diagram, reserve_log
from cdpm_drake.config import (DynamicReels, ResolvedScenario, Scenario, ScenarioError, SimulatedReels,
                       check_duration, resolve_scenario)
from cdpm_drake.runs.log import check_log_fits, collect_log, log_bytes_per_tick, mark_ending


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
    # First: which controller, the paper's method or the hard promise (Scenario.method).
    if scenario.method == "paper":
        words, tags = ["the paper's method: no safety filter"], ["paper"]
    elif scenario.safety_filter.enabled:
        words, tags = ["the hard promise: safety filter on"], []
    else:
        words, tags = ["safety filter off"], ["no-filter"]
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
