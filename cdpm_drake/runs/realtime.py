"""Running the same diagram in real time against the reels (`cdpm run`).

The scenario's plant must be `!HardwareReels` (or `!CanopenReels`, hardware/CANOPEN.md); the
builder is the simulation's. Every tick is
streamed to `DIR/ticks.bin` as the run goes (nothing but the last few unflushed ticks is lost if
the process is killed); at the end it is converted to `DIR/log.npz` (docs/LOG_FORMAT.md). Any
way the run ends (its duration, Ctrl-C, SIGTERM, a reel fault, any error) zero reel velocity
with enable off is sent before anything else.

Nothing that can take milliseconds happens inside a tick. A tick is the work Drake does from
reading the bridge (the discrete updates at t_k) to sending the command (the publishes at
t_k+1), back to back; the loop below advances `step` s (10 ticks) per AdvanceTo and does its
own work between two AdvanceTo calls, which return right after a tick's command went out,
about one period minus that tick's compute (~1.8 ms) before the next tick is due:

* file I/O: the tick log's rows are copied into blocks of memory allocated before the run;
  a writer thread writes full blocks to the file (its header too), so the tick thread never
  calls the file system (hardware/tick_log.py);
* printing: the live status line is formatted between steps and handed to a thread of its
  own (`_StatusPump`), so a terminal or a pipe that blocks holds up that thread only (lines
  are dropped meanwhile, never queued);
* allocation that grows: no list, log or buffer grows during the run (the tick log's pool
  is fixed and touched when it is created); a tick's temporaries are freed by reference
  counting as it goes;
* garbage collection: the build's garbage is collected and what survives frozen before the
  reels are enabled (hardware.reels.start_realtime); the automatic collector is off for the
  whole loop (a collection would run inside whichever tick allocated past its threshold);
  the loop collects the young generations itself between steps, when the allocation count
  says the collector would have, and the collector is back on at the end
  (`_collector_between_steps`);
* the live 3D view (`on_view`, `--meshcat`) is also drawn between steps; it takes
  milliseconds, which delays the next tick (the bridge's statuses wait in the socket): a
  rehearsal feature, not for the robot.

In lockstep (`run(lockstep=True)`, `cdpm run --lockstep`: the plant's `lockstep: true`)
nothing keeps wall-clock time: Drake runs unpaced and each tick waits for the bridge's answer
to its command (hardware/reels.py, hardware/canopen_reels.py), so the same scenario gives the
same log on any host.

Measured (scripts/bench/soak_realtime.py; README, "On the robot", point 4): with this, a tick comes
late only when the host holds the process's virtual CPU (a higher-priority sentinel thread on
that CPU is late by the same amount every time); a bridge silenced that way is what the
watchdog's hold and resume (hardware/reels.py, `resume_within`) rides out.
"""

import contextlib
import dataclasses
import gc
import signal
import threading
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator

from cdpm_drake.diagram import BuildOptions, build_diagram
from cdpm_drake.config import (DynamicReels, ResolvedScenario, Scenario, ScenarioError, SimulatedReels,
                       resolve_scenario)
from cdpm_drake.runs.log import check_log_fits, log_from_tick_log, mark_ending, write_log
from cdpm_drake.runs.run_scenario import write_run_scenario
from cdpm_drake.runs.simulate import tick_targets


@dataclasses.dataclass
class RunResult:
    # The log (docs/LOG_FORMAT.md); empty ({}) when the run never enabled the reels.
    log: dict
    # Tick timing from the tick log (hardware.tick_log.realtime_stats), s.
    timing: dict
    # The link's counters and the bridge's count of commands it never received.
    link: dict
    # Why the run ended early (ReelFault, KinematicsError, ...), or None.
    error: Exception | None
    # "completed", "interrupted" (Ctrl-C / SIGTERM) or "fault".
    ending: str
    # DIR/log.npz and DIR/ticks.bin, or None when the run wrote none (it never enabled).
    log_path: Path | None
    tick_log_path: Path | None
    # The signal that interrupted the run ("SIGINT", "SIGTERM"), or None.
    signal: str | None = None
    # False when the run ended before the reels were enabled (no bridge, lengths that do not
    # fit): such a run writes nothing but its report.
    enabled: bool = True
    # True when the ticks were paced by the bridge's answers (lockstep), not the wall clock.
    lockstep: bool = False


class _StatusPump:
    """Calls `status(line)` from a thread of its own, so that printing (to a terminal or a
    pipe that may block) never holds up the control loop. One line waits at most: a newer
    line replaces it (counted in `dropped`). An exception in `status` stops the pump."""

    def __init__(self, status):
        self._status = status
        self._pending = None
        self._closed = False
        self._ready = threading.Condition()
        self.dropped = 0
        self.error = None
        self._thread = threading.Thread(target=self._run, name="status-line", daemon=True)
        self._thread.start()

    def put(self, line: str) -> None:
        with self._ready:
            if self._pending is not None:
                self.dropped += 1
            self._pending = line
            self._ready.notify()

    def _run(self) -> None:
        while True:
            with self._ready:
                while self._pending is None and not self._closed:
                    self._ready.wait()
                if self._pending is None:
                    return
                line, self._pending = self._pending, None
            try:
                self._status(line)
            except Exception as e:  # a closed pipe, a broken callback: stop showing lines
                self.error = e
                return

    def close(self, timeout: float = 1.0) -> None:
        """Show the pending line, then stop (waiting `timeout` s at most for a blocked
        `status`)."""
        with self._ready:
            self._closed = True
            self._ready.notify()
        self._thread.join(timeout)


@contextlib.contextmanager
def _collector_between_steps():
    """Automatic garbage collection off for the block; yields `collect()`, which the loop
    calls between steps: it collects the young generation(s) when the allocation counts
    reach the collector's own thresholds (what an automatic collection would have done, in
    a tick); only the objects that survived since (a tick's temporaries are freed by
    reference counting), 0.1-0.2 ms for the few hundred the soak saw. Afterwards the frozen
    objects (start_realtime) go back to the collector and it is on again if it was."""
    threshold0, threshold1, _ = gc.get_threshold()

    def collect():
        count0, count1, _ = gc.get_count()
        if count1 >= threshold1:
            gc.collect(1)
        elif count0 >= threshold0:
            gc.collect(0)

    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield collect
    finally:
        gc.unfreeze()
        if was_enabled:
            gc.enable()


class StopRequest:
    """Ctrl-C and SIGTERM set a flag that the run loop checks between short steps; raising
    inside Drake's event loop instead would skip nothing but could leave a half-done tick."""

    def __init__(self):
        self.signal = None
        self._previous = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            from cdpm_drake.runs.interrupt import honoured
            for sig in filter(honoured, (signal.SIGINT, signal.SIGTERM)):  # ignored stays so
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame):
        self.signal = signal.Signals(signum).name

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def run(*, scenario: Scenario | ResolvedScenario, out_dir, duration: float | None = None, status=None,
        status_period: float = 1.0, step: float = 0.02, on_view=None,
        view_period: float = 0.1, lockstep: bool | None = None) -> RunResult:
    """Run the scenario's diagram at real-time rate 1 against the reel bridge.

    `lockstep` (None: the plant's own `lockstep` setting): against `cdpm emulate
    --lockstep`, each tick waits for the status answering its command and nothing keeps
    time (the plant's `lockstep: true`; rate unlimited), so the run is deterministic.

    `status(text)` receives a one-line live status every `status_period` s of run time,
    from a thread of its own (the module docstring says why); `on_view(diagram, context)` (a
    live 3D view) is called every `view_period` s, between steps. The loop advances `step` s
    at a time, so Ctrl-C / SIGTERM stop it within that.
    """
    from cdpm_drake.hardware.reels import ReelFault, start_realtime

    resolved = resolve_scenario(scenario)  # once: the builder and the log take it
    scenario, robot = resolved.scenario, resolved.robot
    if isinstance(scenario.plant, (SimulatedReels, DynamicReels)):
        raise ScenarioError(
            f"scenario {scenario.name!r} has plant: !{type(scenario.plant).__name__}; `cdpm "
            "run` drives real "
            "reels and needs plant: !HardwareReels {address: ..., port: ...} or plant: "
            "!CanopenReels {interface: ..., channel: ..., force_sensor: ...} (use `cdpm "
            "simulate` for a simulation, or --scenario-text 'plant: !HardwareReels {}')")
    if lockstep is not None and lockstep != scenario.plant.lockstep:
        scenario = dataclasses.replace(
            scenario, plant=dataclasses.replace(scenario.plant, lockstep=bool(lockstep)))
        resolved = dataclasses.replace(resolved, scenario=scenario)
    duration = scenario.duration if duration is None else float(duration)
    if not (duration > 0 and np.isfinite(duration)):
        raise ScenarioError(f"duration must be a finite number > 0 s, got {duration!r}")
    from cdpm_drake.hardware.force_config import force_source_problem

    if force_source_problem(scenario.plant):  # before anything opens the bus
        raise ScenarioError(force_source_problem(scenario.plant))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for stale in ("ticks.bin", "log.npz"):
        # An earlier run's files would otherwise be reported as this run's if it fails early.
        (out / stale).unlink(missing_ok=True)
    tick_path = out / "ticks.bin"
    diagram = build_diagram(resolved, BuildOptions(loggers=False, tick_log=str(tick_path)))
    reels = diagram.GetSubsystemByName("reels")
    sink = diagram.GetSubsystemByName("tick_log")
    # The ticks stream to disk, and are read back into memory at the end (log_from_tick_log).
    row = tick_row_bytes(sink)
    check_log_fits(duration, scenario.time_step, row, disk_dir=out, disk_bytes_per_tick=row)
    simulator = Simulator(diagram)
    context = simulator.get_context()
    # Written before the run (`cdpm recover` needs it after a kill), once nothing can fail early.
    scenario_path = out / "scenario.yaml"
    write_run_scenario(out, resolved, duration=duration)  # with its robot file and CSV
    T = scenario.time_step
    error, ending, enabled = None, "completed", False
    pump = _StatusPump(status) if status is not None else None
    with StopRequest() as stop, _collector_between_steps() as collect:
        try:
            sink.open()  # before the enabling command: it maps ~20 MB (TickLogSink.open)
            # Lockstep: the bridge's answers pace the ticks, as fast as both can go.
            start_realtime(simulator, 0.0 if scenario.plant.lockstep else 1.0)
            enabled = True  # initialisation enables the reels or raises
            t, next_status, next_view = 0.0, 0.0, 0.0
            # Whole ticks counted in integers, so the last tick (D * 500 + 1 rows) is reached.
            for target in tick_targets(duration, T, step):
                if stop.signal is not None:
                    ending = "interrupted"
                    break
                simulator.AdvanceTo(target)
                # Between steps: the next tick is about a period minus its compute away.
                t = target
                if pump is not None and t >= next_status:
                    pump.put(_status_line(diagram, context, reels, t))
                    next_status += status_period
                if on_view is not None and t >= next_view:
                    on_view(diagram, context)
                    next_view += view_period
                collect()
            if stop.signal is not None:
                ending = "interrupted"  # also when it came during the last step
        except ReelFault as e:
            error, ending = e, "fault"
        except Exception as e:  # KinematicsError, a bad packet path, ...: stop the reels
            error, ending = e, "fault"
        finally:
            reels.shutdown()  # zero velocity first, whatever happened
            if pump is not None:
                pump.close()
            # Each clean-up step on its own: a failing log writer (disk full) must not skip
            # the link report, the socket's release or the conversion of what was written.
            cleanup_errors = []
            link = {}
            for step_name, action in (("tick log", sink.close),
                                      ("link report", lambda: link.update(
                                          _link_report(reels, context))),
                                      ("reel link", reels.close)):
                try:
                    action()
                except Exception as e:  # noqa: PERF203 - report them all
                    cleanup_errors.append(f"{step_name}: {type(e).__name__}: {e}")
            if cleanup_errors and error is None:
                error, ending = RuntimeError("; ".join(cleanup_errors)), "fault"
    if not enabled:
        # Nothing happened on the robot: no log to keep, nothing to block the next run.
        for path in (tick_path, scenario_path):
            path.unlink(missing_ok=True)
        return RunResult(log={}, timing={}, link=link, error=error, ending=ending,
                         log_path=None, tick_log_path=None, signal=stop.signal, enabled=False,
                         lockstep=scenario.plant.lockstep)
    log, timing, _ = log_from_tick_log(tick_path, resolved, robot)
    mark_ending(log, ending, error)
    log_path = write_log(log, out)
    return RunResult(log=log, timing=timing, link=link, error=error, ending=ending,
                     log_path=log_path, tick_log_path=tick_path, signal=stop.signal,
                     lockstep=scenario.plant.lockstep)


def tick_row_bytes(sink) -> int:
    """Bytes of one row of the tick log that `sink` (a TickLogSink) writes: 8 per value of
    each input port, plus its tick (int64), time, wall time and compute time."""
    values = sum(sink.get_input_port(k).size() for k in range(sink.num_input_ports()))
    return 8 * (values + 4)


def recover(run_dir) -> tuple[Path, dict]:
    """Turn a run folder's ticks.bin (a run killed before it converted it) into log.npz, with
    the run's scenario.yaml. Returns (the log's path, {"ticks", "cut_bytes", "ending"}).
    The ending is "completed" when every tick of the scenario's duration is there, else
    "interrupted"."""
    from cdpm_drake.config import load_scenario

    run_dir = Path(run_dir)
    tick_path = run_dir / "ticks.bin"
    scenario_path = run_dir / "scenario.yaml"
    if not run_dir.is_dir():
        raise RecoverError(f"{str(run_dir)!r} " + ("is a file" if run_dir.exists() else
                                                   "does not exist")
                           + ": give a `cdpm run` folder (it holds ticks.bin and scenario.yaml)")
    for path in (tick_path, scenario_path):
        if not path.is_file():
            raise RecoverError(f"{str(run_dir)!r} has no {path.name} (a `cdpm run` folder "
                               "holds ticks.bin and scenario.yaml)")
    if (run_dir / "log.npz").exists():
        # The run converted its stream itself, with how it ended: never replace that.
        raise RecoverError(f"{str(run_dir)!r} already has its log.npz; nothing to recover "
                           "(remove it to convert ticks.bin again)")
    resolved = resolve_scenario(load_scenario(scenario_path))
    scenario, robot = resolved.scenario, resolved.robot
    log, _, tail = log_from_tick_log(tick_path, resolved, robot)
    # Ticks 0..n of the duration the run was asked for (scenario.yaml records it).
    expected = int(np.floor(scenario.duration / scenario.time_step + 1e-9)) + 1
    ending = "completed" if len(log["time"]) >= expected else "interrupted"
    mark_ending(log, ending, None)
    log_path = write_log(log, run_dir)
    return log_path, dict(tail, ending=ending, expected=expected)


class RecoverError(ValueError):
    """A folder that cannot be recovered; the message names it and what is missing."""


def _output(diagram, context, system_name, port_name):
    from cdpm_drake.diagram import block_output_port

    port = block_output_port(diagram, system_name, port_name)
    return port.Eval(port.get_system().GetMyContextFromRoot(context))


def _status_line(diagram, context, reels, t) -> str:
    from cdpm_drake.diagram import has_block

    p = _output(diagram, context, "forward_kinematics", "p_WP")
    F_H = _output(diagram, context, "force_sensor", "F_H")
    text = (f"t {t:7.2f} s  p [{p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}] m  |F_H| "
            f"{np.linalg.norm(F_H):5.2f} N")
    if has_block(diagram, "interference_force"):
        d = _output(diagram, context, "interference_force", "pair_distances")
        F = _output(diagram, context, "interference_force", "F_int")
        text += f"  |F_int| {np.linalg.norm(F):4.2f} N  closest pair {1000 * d.min():6.1f} mm"
    link = reels.link
    if link is not None:
        k = link.counters
        text += (f"  commands sent {k.sent}, statuses accepted {k.accepted}, "
                 f"statuses lost {k.lost}")
    return text


def _link_report(reels, context) -> dict:
    link = reels.link
    report = {} if link is None else link.counters.as_dict()
    try:
        book = reels.book(reels.GetMyContextFromRoot(context))
        report["commands_lost_at_bridge"] = int(book["commands_lost"])
        # The watchdog's stops that the bridge answered in time (the run went on).
        report["watchdog_holds"] = int(book["holds"])
        report["longest_hold"] = float(book["longest_hold"])
    except Exception:  # the context may be gone after a failed initialisation
        report.setdefault("commands_lost_at_bridge", None)
    return report


def report_lines(result: RunResult) -> list[str]:
    """The end-of-run summary: tick period and compute time percentiles, overruns, lost
    packets, faults."""
    t = result.timing
    why = f" by {result.signal}" if result.ending == "interrupted" and result.signal else ""
    lines = [f"run ended: {result.ending}{why}"
             + (f" ({type(result.error).__name__}: {result.error})" if result.error else "")]
    if result.lockstep:
        lines.append("lockstep: each tick waited for the bridge's answer to its command; the "
                     "tick periods below are this host's speed, not the robot's timing")
    if t:
        ms = {k: 1e3 * t[k] for k in ("p50", "p99", "max")}
        lines.append(f"ticks logged {t['ticks']}, missing {t['missing_ticks']}, overruns "
                     f"{t['overruns']}; tick period p50 {ms['p50']:.3f} ms, p99 "
                     f"{ms['p99']:.3f} ms, max {ms['max']:.3f} ms")
        compute = np.asarray(result.log.get("compute", []), dtype=float)
        compute = compute[np.isfinite(compute)]
        if compute.size:
            c = 1e3 * np.percentile(compute, [50, 99, 100])
            period = 1e3 * float(result.log["time"][1] - result.log["time"][0]) \
                if len(result.log["time"]) > 1 else float("nan")
            lines.append(f"compute per tick p50 {c[0]:.3f} ms, p99 {c[1]:.3f} ms, max "
                         f"{c[2]:.3f} ms of the {period:g} ms tick")
    k = result.link
    if k:
        rejected = {r: n for r, n in k.get("rejected", {}).items() if n}
        lines.append(
            f"packets: commands sent {k.get('sent', 0)}, lost before the bridge "
            f"{k.get('commands_lost_at_bridge')}; statuses received {k.get('received', 0)}, "
            f"accepted {k.get('accepted', 0)}, lost {k.get('lost', 0)}, rejected "
            f"{count_by_reason(rejected)}, foreign {k.get('foreign', 0)}")
        if k.get("bus"):  # CANopen: the bus, what the drives said of themselves
            rated = k.get("rated_torque") or []
            torque = ("rated torque 0x6076 per drive " + str([round(x, 4) for x in rated])
                      + " N m" if any(np.isfinite(rated)) else
                      "rated torque 0x6076 not given by the drives")
            lines.append(f"CAN bus {k['bus']}: {torque} (force_per_torque_unit "
                         f"{k.get('force_per_torque_unit', float('nan')):g} N per per mille); "
                         f"handle force sensor tared at "
                         f"{[round(x, 3) for x in k.get('force_bias', [])]} N")
        if k.get("watchdog_holds"):
            lines.append(
                f"watchdog: stopped the reels {k['watchdog_holds']} time(s) for a silent bridge "
                f"that answered within resume_within, and resumed (longest stop "
                f"{1e3 * k['longest_hold']:.1f} ms)")
    if result.log_path is not None:
        lines.append(f"log: {result.log_path} (stream: {result.tick_log_path})")
    else:
        lines.append("no log written: the reels were never enabled")
    return lines


def count_by_reason(counts: dict) -> str:
    """{'value': 3, 'crc': 1} -> '4 (value 3, crc 1)'; {} -> '0'."""
    total = sum(counts.values())
    if not total:
        return "0"
    return f"{total} (" + ", ".join(f"{r} {n}" for r, n in counts.items() if n) + ")"
