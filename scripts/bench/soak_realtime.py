"""Soak test of the real-time path: N runs x D s of `cdpm run` against cdpm-reel-emulator
through a loopback relay that timestamps every datagram both ways. Run it before trusting a
new host (or a new kernel, a new load on it, a new version of this package).

Per run it starts the emulator (a separate process, `--scenario` and `--rt-priority` as given),
the relay (a thread of this process: the controller's bridge address is the relay, which
forwards to the emulator and back), and `cdpm run` (a separate process, the same command a
user types, with a stall tracer, below). It reports, per run:

* how the run ended, and whether the watchdog stopped it (a clean run must not stop);
* the watchdog's holds: stops (zero velocity, enable off) that the bridge answered within
  `resume_within`, after which the run went on, as the relay saw them (and as the controller's
  report counts them), with the bridge's silence around each and the host's delays then;
* the controller-side latency: from the relay forwarding a status to the controller to the
  relay receiving the first command that echoes it (or a newer status), p50 / p99 / max, ms,
  over the statuses forwarded while the reels were enabled. By design it is below one period
  plus the tick's compute (and the relay's hop): the status waits in the socket for the next
  tick's update, whose command leaves in the same step;
* the tick period (the wall time between consecutive ticks' log rows, ticks.bin), p50 / max;
* the largest gap between two statuses the bridge sent (who was late: the bridge or the
  controller);
* every tick whose period exceeded `--slow` (4 ms: two ticks late, one short of the 3-tick
  watchdog) with what the controller was doing then, and whether the host was late then.

The host sentinel is a process with one thread pinned to each CPU at SCHED_FIFO 99 (ahead of
everything the soak runs), waking every 1 ms: a wake-up more than 1 ms late means the host
held that CPU (a hypervisor descheduling the virtual CPU, the kernel busy), not the
controller. A late tick the sentinel saw too is the host's.

The stall tracer is a thread in the controller process (`--no-trace` runs the plain `cdpm
run`): every 1 ms it checks that the tick log gained a row; when none came for 3 ms it records
the main thread's Python stack and the tick-log writer's, the kernel's view of the main thread
(/proc: run state R/S/D, the system call it is in, context switches it made voluntarily or
was preempted by) and whether a garbage collection is running; every garbage collection of
the run is recorded too. Clock: time.monotonic() everywhere (CLOCK_MONOTONIC, the same in all
three processes), so the relay's, the tracer's and the tick log's times line up.

Usage: python scripts/bench/soak_realtime.py [--runs 10] [--duration 15] [--rt-priority 50]
           [--scenario exp2_interaction] [--slow 0.004] [--no-trace] [--keep DIR]
           [--json FILE]

Exit code 0 when every run completed, 1 when any ended otherwise (a watchdog stop included).
--rt-priority 50 (the default) is what the README tells users on a busy host; it needs root or
CAP_SYS_NICE. --rt-priority 0 measures normal scheduling.
"""

import argparse
import json
import os
import re
import select
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

# --- the relay -------------------------------------------------------------------------------

# The header every datagram starts with (hardware/PROTOCOL.md): magic, version, cable count,
# flags, sequence, echo_sequence, time, echo_time.
_HEADER = struct.Struct("<4sBBHIIdd")
_ECHO_VALID = 0x1


class Relay:
    """Forwards datagrams between the controller and the bridge on loopback, recording for
    each the time.monotonic() it arrived, its sequence and echo (statuses: the time it was
    forwarded too). The controller's bridge address is `address`; the bridge sees the relay's
    second socket as its controller. Records go into preallocated arrays (no allocation per
    datagram) of `capacity` rows each way."""

    def __init__(self, bridge_port: int, capacity: int, rt_priority: int = 0):
        self.bridge = ("127.0.0.1", int(bridge_port))
        self.rt_priority = rt_priority
        self._front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._front.bind(("127.0.0.1", 0))
        self._back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._back.bind(("127.0.0.1", 0))
        for s in (self._front, self._back):
            s.setblocking(False)
        self.controller = None
        # commands: arrival, sequence, echo (-1: none), enable; statuses: arrival, forwarded,
        # sequence.
        self.cmd = np.zeros((capacity, 4))
        self.status = np.zeros((capacity, 3))
        self.n_cmd = self.n_status = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="relay", daemon=True)

    @property
    def address(self) -> tuple[str, int]:
        return self._front.getsockname()

    def start(self) -> "Relay":
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._front.close()
        self._back.close()

    def _run(self) -> None:
        if self.rt_priority:
            # This thread only (Linux applies the policy per thread).
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.rt_priority))
        front, back = self._front, self._back
        now = time.monotonic
        while not self._stop.is_set():
            readable, _, _ = select.select((front, back), (), (), 0.05)
            if front in readable:
                while True:
                    try:
                        data, sender = front.recvfrom(4096)
                    except BlockingIOError:
                        break
                    t = now()
                    self.controller = sender
                    if len(data) >= _HEADER.size and self.n_cmd < len(self.cmd):
                        _, _, _, flags, seq, echo, _, _ = _HEADER.unpack_from(data)
                        row = self.cmd[self.n_cmd]
                        row[0], row[1] = t, seq
                        row[2] = echo if flags & _ECHO_VALID else -1
                        row[3] = 1.0 if flags & 0x2 else 0.0
                        self.n_cmd += 1
                    try:
                        back.sendto(data, self.bridge)
                    except OSError:
                        pass  # the emulator is not there (yet): the controller will notice
            if back in readable:
                while True:
                    try:
                        data, sender = back.recvfrom(4096)
                    except BlockingIOError:
                        break
                    t = now()
                    if self.controller is None:
                        continue
                    try:
                        front.sendto(data, self.controller)
                    except OSError:
                        continue
                    if len(data) >= _HEADER.size and self.n_status < len(self.status):
                        row = self.status[self.n_status]
                        row[0], row[1] = t, now()
                        row[2] = _HEADER.unpack_from(data)[4]
                        self.n_status += 1

    def commands(self) -> np.ndarray:
        return self.cmd[:self.n_cmd].copy()

    def statuses(self) -> np.ndarray:
        return self.status[:self.n_status].copy()


def controller_latency(statuses: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """For each status forwarded while the controller ran enabled: the time from its
    forwarding to the arrival of the first command echoing it or a newer status, s.
    (Sequences start at 1 in each session and do not wrap within a soak run.)"""
    enabled = commands[commands[:, 3] > 0]
    if not len(enabled) or not len(statuses):
        return np.zeros(0)
    echo_time, echo = enabled[:, 0], enabled[:, 2]
    # The echo never decreases; the first command whose echo >= the status's sequence.
    running = np.maximum.accumulate(echo)
    first, last = enabled[0, 0], enabled[-1, 0]
    sent, seq = statuses[:, 1], statuses[:, 2]
    keep = (sent >= first) & (sent <= last)
    k = np.searchsorted(running, seq[keep], side="left")
    ok = k < len(running)
    return echo_time[k[ok]] - sent[keep][ok]


# --- the stall tracer, inside the controller process -----------------------------------------


def _proc_task(tid: int) -> dict:
    """The kernel's view of one thread: run state, the system call it is in, its context
    switches (voluntary: it blocked; nonvoluntary: it was preempted)."""
    out = {}
    base = f"/proc/self/task/{tid}"
    try:
        with open(f"{base}/stat") as f:
            out["state"] = f.read().rsplit(")", 1)[1].split()[0]
        with open(f"{base}/syscall") as f:
            call = f.read().split()
            out["syscall"] = {"202": "futex", "230": "clock_nanosleep", "35": "nanosleep",
                              "7": "poll", "23": "select", "270": "pselect6", "1": "write",
                              "45": "recvfrom", "44": "sendto", "0": "read",
                              "running": "running"}.get(call[0], call[0]) if call else "?"
        with open(f"{base}/status") as f:
            for line in f:
                if line.startswith("voluntary_ctxt_switches"):
                    out["vol"] = int(line.split()[1])
                elif line.startswith("nonvoluntary_ctxt_switches"):
                    out["nonvol"] = int(line.split()[1])
    except OSError:
        pass
    return out


def _stack(frame, depth: int = 6) -> list[str]:
    lines = []
    while frame is not None and len(lines) < depth:
        code = frame.f_code
        lines.append(f"{Path(code.co_filename).name}:{frame.f_lineno} {code.co_name}")
        frame = frame.f_back
    return lines


class StallTracer:
    """Polls the tick log's row count every `poll` s; when no row came for `threshold` s,
    records up to `per_stall` snapshots of what the process is doing (see the module doc).
    Also records every garbage collection (start, duration, generation)."""

    def __init__(self, threshold: float = 0.003, poll: float = 0.001, per_stall: int = 4):
        import gc

        self.threshold, self.poll, self.per_stall = threshold, poll, per_stall
        self.writer = None
        self.stalls = []
        self.gc = []
        self.late_wakes = 0       # polls that woke > 2 ms late (the tracer itself held off)
        self.max_wake_late = 0.0
        self._gc_start = None
        self._stop = threading.Event()
        self._main = threading.main_thread()
        gc.callbacks.append(self._on_gc)
        self._thread = threading.Thread(target=self._run, name="stall-tracer", daemon=True)

    def _on_gc(self, phase, info):
        t = time.monotonic()
        if phase == "start":
            self._gc_start = t
        elif self._gc_start is not None:
            self.gc.append({"start": self._gc_start, "seconds": t - self._gc_start,
                            "generation": info["generation"],
                            "collected": info.get("collected", 0),
                            "thread": threading.current_thread().name})
            self._gc_start = None

    def attach(self, writer) -> None:
        self.writer = writer
        if not self._thread.is_alive():
            self._thread.start()

    def _run(self) -> None:
        main_tid = self._main.native_id
        last_rows, last_change, taken = -1, time.monotonic(), 0
        stall = None
        due = time.monotonic()
        while not self._stop.is_set():
            due += self.poll
            pause = due - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            now = time.monotonic()
            late = now - due
            self.max_wake_late = max(self.max_wake_late, late)
            if late > 0.002:
                self.late_wakes += 1
                due = now
            rows = self.writer.rows
            if rows != last_rows:
                if stall is not None:
                    stall["end"], stall["end_rows"] = now, rows
                    self.stalls.append(stall)
                    stall = None
                last_rows, last_change, taken = rows, now, 0
                continue
            if now - last_change < self.threshold or taken >= self.per_stall:
                continue
            if stall is None:
                stall = {"since": last_change, "rows": rows, "snapshots": []}
            taken += 1
            stall["snapshots"].append(self._snapshot(now, main_tid))

    def _snapshot(self, now, main_tid) -> dict:
        frames = sys._current_frames()
        threads = {t.ident: t for t in threading.enumerate()}
        snap = {"t": now, "in_gc": self._gc_start is not None,
                "main": _stack(frames.get(self._main.ident)),
                "main_kernel": _proc_task(main_tid), "others": {}}
        for ident, frame in frames.items():
            t = threads.get(ident)
            if t is None or t is self._main or t.name == "stall-tracer":
                continue
            snap["others"][t.name] = {"stack": _stack(frame, 3),
                                      "kernel": _proc_task(t.native_id)}
        return snap

    def stop(self) -> dict:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        return {"stalls": self.stalls, "gc": self.gc, "late_wakes": self.late_wakes,
                "max_wake_late": self.max_wake_late}


def controller_child(trace_path: str, cli_args: list[str]) -> int:
    """`cdpm run` with the stall tracer attached to its tick log (this script re-invoked with
    --as-controller); the trace goes to `trace_path` as JSON when the run ends."""
    from cdpm_drake import cli
    from cdpm_drake.hardware import tick_log

    tracer = StallTracer()
    original = tick_log.TickLogWriter.__init__

    def init_and_attach(self, *args, **kwargs):
        original(self, *args, **kwargs)
        tracer.attach(self)

    tick_log.TickLogWriter.__init__ = init_and_attach
    try:
        return cli.main(cli_args)
    finally:
        Path(trace_path).write_text(json.dumps(tracer.stop()))


# --- the host sentinel: is the machine itself available? -------------------------------------


def sentinel_child(out_path: str, period: float = 0.001) -> int:
    """One thread pinned to each CPU, at SCHED_FIFO 99 when allowed (ahead of everything the
    soak runs at 50), waking every `period` s and recording each wake-up later than 1 ms:
    (time.monotonic() it was due, s late, cpu). Such a delay is the host's (a virtual CPU
    descheduled by the hypervisor, the kernel busy), not the controller's. Runs until SIGTERM,
    then writes `out_path` (.npy)."""
    import gc
    import signal

    gc.disable()
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(99))
    except (OSError, AttributeError):
        pass  # normal scheduling: the sentinel then also sees the host's load
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    late = np.zeros((100_000, 3))
    count = [0]

    def watch(cpu):
        try:
            os.sched_setaffinity(0, {cpu})
        except OSError:
            return
        due = time.monotonic()
        while not stop.is_set():
            due += period
            pause = due - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            lag = time.monotonic() - due
            if lag > 0.001:
                if count[0] < len(late):
                    late[count[0]] = due, lag, cpu
                    count[0] += 1
                due = time.monotonic()

    threads = [threading.Thread(target=watch, args=(cpu,), daemon=True)
               for cpu in sorted(os.sched_getaffinity(0))]
    for t in threads:
        t.start()
    print("sentinel ready", flush=True)
    while not stop.wait(0.2):
        pass
    for t in threads:
        t.join(timeout=1.0)
    np.save(out_path, late[:count[0]])
    return 0


# --- one soak run ----------------------------------------------------------------------------


def _free_port() -> int:
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    return port


def soak_run(k: int, args, folder: Path) -> dict:
    """One run: emulator, relay, traced `cdpm run`; the measurements of docs above."""
    sentinel_path = folder / f"run{k:03d}.sentinel.npy"
    sentinel = subprocess.Popen([sys.executable, __file__, "--as-sentinel", str(sentinel_path)],
                                stdout=subprocess.PIPE, text=True)
    sentinel.stdout.readline()
    emu_port = _free_port()
    emulator = subprocess.Popen(
        [sys.executable, "-m", "cdpm_drake.emulator", "--scenario", args.scenario, "--port",
         str(emu_port), "--rt-priority", str(args.rt_priority)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    banner = emulator.stdout.readline()
    if "cdpm-reel-emulator:" not in banner or "error" in banner:
        emulator.kill()
        raise RuntimeError(f"the emulator did not start: {banner!r}")
    relay = Relay(emu_port, capacity=int((args.duration + 10) / 0.002) * 2,
                  rt_priority=args.rt_priority).start()
    run_dir = folder / f"run{k:03d}"
    trace_path = folder / f"run{k:03d}.trace.json"
    cli_args = ["run", args.scenario, "--duration", f"{args.duration:g}", "--out",
                str(run_dir), "--rt-priority", str(args.rt_priority), "--scenario-text",
                f"plant: !HardwareReels {{port: {relay.address[1]}}}"]
    command = ([sys.executable, __file__, "--as-controller", str(trace_path), "--"]
               if args.trace else [sys.executable, "-m", "cdpm_drake.cli"]) + cli_args
    load = os.getloadavg()[0]
    try:
        done = subprocess.run(command, capture_output=True, text=True,
                              timeout=args.duration + 120)
    finally:
        relay.stop()
        sentinel.terminate()
        sentinel.wait(timeout=10)
        emulator.send_signal(2)
        try:
            emulator_out = emulator.communicate(timeout=10)[0]
        except subprocess.TimeoutExpired:
            emulator.kill()
            emulator_out = emulator.communicate()[0]
    result = {"run": k, "load": load, "code": done.returncode,
              "stderr": done.stderr[-2000:], "emulator": emulator_out[-1000:]}
    log_path = run_dir / "log.npz"
    if not log_path.exists():
        result.update(ending="no log", message=(done.stderr.strip().splitlines() or ["?"])[-1])
        return result
    log = np.load(log_path)
    result["ending"] = str(log["ending"])
    result["message"] = str(log["fault_message"])
    result["watchdog"] = "no valid status" in result["message"]
    wall, tick, compute = log["wall"], log["tick"], log["compute"]
    period = np.diff(wall)
    result["ticks"] = int(len(wall))
    result["period_p50"], result["period_max"] = (float(np.median(period)),
                                                  float(period.max())) if len(period) else (
        np.nan, np.nan)
    statuses, commands = relay.statuses(), relay.commands()
    host = np.load(sentinel_path) if sentinel_path.exists() else np.zeros((0, 3))
    result["holds"] = _holds(commands, statuses, host)
    reported = re.search(r"stopped the reels (\d+) time", done.stdout)
    result["holds_reported"] = int(reported.group(1)) if reported else 0
    lat = controller_latency(statuses, commands)
    result["latency"] = ((float(np.percentile(lat, 50)), float(np.percentile(lat, 99)),
                          float(lat.max())) if len(lat) else (np.nan,) * 3)
    arrival = statuses[:, 0]
    inside = arrival[(arrival >= wall[0]) & (arrival <= wall[-1])] if len(wall) else arrival
    result["bridge_gap_max"] = float(np.diff(inside).max()) if len(inside) > 1 else np.nan
    trace = json.loads(trace_path.read_text()) if trace_path.exists() else None
    inside_run = (host[:, 0] >= wall[0]) & (host[:, 0] <= wall[-1]) if len(wall) else []
    result["host_late_max"] = float(host[inside_run, 1].max()) if np.any(inside_run) else 0.0
    result["host_late_over_slow"] = int(np.count_nonzero(host[inside_run, 1] > args.slow)) \
        if np.any(inside_run) else 0
    result["slow"] = _slow_ticks(wall, tick, compute, statuses, trace, host, args.slow)
    if result["ending"] != "completed":
        result["timeline"] = _timeline(wall, tick, compute, statuses, commands, host)
    if trace is not None:
        result["gc_in_run"] = [g for g in trace["gc"]
                               if len(wall) and wall[0] <= g["start"] <= wall[-1]]
        result["tracer_late_wakes"] = trace["late_wakes"]
    if args.keep:
        np.savez(folder / f"run{k:03d}.relay.npz", statuses=statuses, commands=commands)
    else:
        for path in run_dir.iterdir():
            path.unlink()
        run_dir.rmdir()
        trace_path.unlink(missing_ok=True)
        sentinel_path.unlink(missing_ok=True)
    return result


def _holds(commands, statuses, host) -> list[dict]:
    """The watchdog's holds as the relay saw them: an enabled command stream that stops
    (zero velocity, enable off) and later enables again. For each: when the reels were
    stopped (s from the first command), how long the bridge's statuses had been silent then,
    how long until they enabled again, and the host's delays meanwhile."""
    on = commands[:, 3] > 0
    holds = []
    k = int(np.argmax(on)) if on.any() else len(on)
    while k < len(on):
        stop = k + int(np.argmax(~on[k:])) if (~on[k:]).any() else len(on)
        if stop >= len(on):
            break
        again = stop + int(np.argmax(on[stop:])) if on[stop:].any() else len(on)
        if again >= len(on):
            break  # the run's own end
        t_stop, t_again = commands[stop, 0], commands[again, 0]
        around = statuses[(statuses[:, 0] >= t_stop - 0.02) & (statuses[:, 0] <= t_again), 0]
        holds.append({"at": float(t_stop - commands[0, 0]),
                      "bridge_gap_ms": 1e3 * float(np.diff(around).max())
                      if len(around) > 1 else None,
                      "stopped_ms": 1e3 * float(t_again - t_stop),
                      "host_late": _host_late(host, t_stop - 0.02, t_again)})
        k = again
    return holds


def _host_late(host, a, b) -> list[tuple]:
    """The sentinel's late wake-ups overlapping [a, b]: (cpu, ms late)."""
    hit = (host[:, 0] < b) & (host[:, 0] + host[:, 1] > a)
    return [(int(cpu), 1e3 * lag) for _, lag, cpu in host[hit]]


def _slow_ticks(wall, tick, compute, statuses, trace, host, slow) -> list[dict]:
    """Every tick that came more than `slow` s after the one before, with the tracer's
    snapshots of that gap, the statuses the relay forwarded in it and the host's own delays."""
    out = []
    for i in np.nonzero(np.diff(wall) > slow)[0]:
        a, b = wall[i], wall[i + 1]
        entry = {"tick": int(tick[i + 1]), "period_ms": 1e3 * (b - a),
                 "compute_ms": 1e3 * float(compute[i + 1]),
                 "statuses_in_gap": int(np.count_nonzero((statuses[:, 0] > a)
                                                         & (statuses[:, 0] < b))),
                 "host_late": _host_late(host, a, b)}
        if trace is not None:
            snaps = [s for st in trace["stalls"] for s in st["snapshots"] if a <= s["t"] <= b]
            entry["snapshots"] = snaps
            entry["gc"] = [g for g in trace["gc"] if a - 0.001 <= g["start"] <= b]
        out.append(entry)
    return out


def _timeline(wall, tick, compute, statuses, commands, host, span: float = 0.03) -> list[str]:
    """The last `span` s of a run that did not complete: every datagram the relay saw, every
    tick the controller logged (with the start of its update) and the host's delays, in order;
    times in ms from the first tick."""
    end = max(wall[-1] if len(wall) else 0.0, commands[-1, 0] if len(commands) else 0.0)
    t0 = wall[0] if len(wall) else end
    events = [(a, f"relay: status {int(q)} from the bridge") for a, _, q in statuses]
    events += [(a, f"relay: command {int(q)} echoing status {int(e)}"
                   f"{'' if en else ' (enable off)'}") for a, q, e, en in commands]
    events += [(w, f"controller: tick {int(t)} logged, its update began at "
                   f"{1e3 * (w - c - t0):.3f}") for w, t, c in zip(wall, tick, compute)]
    events += [(d, f"host: cpu{int(cpu)} {1e3 * lag:.2f} ms late") for d, lag, cpu in host]
    return [f"{1e3 * (t - t0):10.3f}  {text}" for t, text in sorted(events)
            if end - span <= t <= end + 0.005]


# --- the report ------------------------------------------------------------------------------


def _describe(snap: dict) -> str:
    k = snap["main_kernel"]
    where = " <- ".join(snap["main"][:3])
    text = (f"main {k.get('state', '?')}/{k.get('syscall', '?')} "
            f"(ctx vol {k.get('vol', '?')}, preempted {k.get('nonvol', '?')})"
            f"{' IN GC' if snap['in_gc'] else ''}: {where}")
    for name, other in snap["others"].items():
        ok = other["kernel"]
        text += (f"; {name} {ok.get('state', '?')}/{ok.get('syscall', '?')}: "
                 f"{other['stack'][0] if other['stack'] else '?'}")
    return text


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--as-sentinel"]:
        return sentinel_child(argv[1])
    if argv[:1] == ["--as-controller"]:
        rest = argv[2:]
        if rest[:1] == ["--"]:
            rest = rest[1:]
        return controller_child(argv[1], rest)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=10, help="runs (default 10)")
    parser.add_argument("--duration", type=float, default=15.0, help="s per run (default 15)")
    parser.add_argument("--scenario", default="exp2_interaction",
                        help="scenario of the controller and the emulator (default "
                        "exp2_interaction)")
    parser.add_argument("--rt-priority", type=int, default=50,
                        help="SCHED_FIFO priority of the controller, the emulator and the "
                        "relay (default 50, as the README says; 0: normal scheduling)")
    parser.add_argument("--slow", type=float, default=0.004,
                        help="report every tick whose period exceeds this, s (default 0.004)")
    parser.add_argument("--no-trace", dest="trace", action="store_false",
                        help="run the plain `cdpm run`, without the stall tracer")
    parser.add_argument("--keep", type=Path, default=None,
                        help="keep the run folders and traces here (default: a temporary "
                        "folder, removed)")
    parser.add_argument("--json", type=Path, default=None,
                        help="also write every run's measurements to this JSON file")
    args = parser.parse_args(argv)
    if args.runs < 1 or not args.duration > 0:
        parser.error("--runs must be >= 1 and --duration > 0")
    if args.rt_priority:
        from cdpm_drake.hardware.priority import set_realtime_priority

        # Fail early without root; the relay thread sets its own (per thread: the children
        # start at normal priority and raise theirs with --rt-priority, as a user's do).
        set_realtime_priority(args.rt_priority)
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    import gc

    from cdpm_drake.text import format_table

    results = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        print(f"soak: {args.runs} runs x {args.duration:g} s of `cdpm run {args.scenario}` "
              f"against cdpm-reel-emulator through a relay, SCHED_FIFO "
              f"{args.rt_priority or 'off'}, tracer {'on' if args.trace else 'off'}; load "
              f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
        for k in range(1, args.runs + 1):
            gc.collect()
            gc.disable()  # the relay thread records into preallocated arrays; no pauses
            try:
                r = soak_run(k, args, folder)
            finally:
                gc.enable()
            results.append(r)
            lat = r.get("latency", (np.nan,) * 3)
            print(f"run {k}: {r['ending']}{' (WATCHDOG)' if r.get('watchdog') else ''}, "
                  f"{r.get('ticks', 0)} ticks, watchdog holds {len(r.get('holds', []))} "
                  f"(the controller says {r.get('holds_reported', 0)}), latency p50/p99/max "
                  f"{1e3 * lat[0]:.3f}/{1e3 * lat[1]:.3f}/{1e3 * lat[2]:.3f} ms, tick period "
                  f"max {1e3 * r.get('period_max', np.nan):.2f} ms, ticks over "
                  f"{1e3 * args.slow:g} ms: {len(r.get('slow', []))}, load {r['load']:.2f}",
                  flush=True)
            for s in r.get("slow", []):
                host = ", ".join(f"cpu{c} {ms:.1f} ms" for c, ms in s["host_late"])
                print(f"    tick {s['tick']}: period {s['period_ms']:.2f} ms, compute "
                      f"{s['compute_ms']:.2f} ms, statuses forwarded meanwhile "
                      f"{s['statuses_in_gap']}; host late: {host or 'no'}")
                for g in s.get("gc", []):
                    print(f"      gc gen {g['generation']} {1e3 * g['seconds']:.2f} ms in "
                          f"{g['thread']}")
                seen = {}
                for snap in s.get("snapshots", []):
                    text = _describe(snap)
                    seen[text] = seen.get(text, 0) + 1
                for text, n in seen.items():
                    print(f"      {n} x {text}")
            for h in r.get("holds", []):
                host = ", ".join(f"cpu{c} {ms:.1f} ms" for c, ms in h["host_late"])
                gap = h["bridge_gap_ms"]
                print(f"    watchdog hold at {h['at']:.3f} s: reels enabled again "
                      f"{h['stopped_ms']:.1f} ms after the stop; longest gap between the "
                      f"bridge's statuses around it "
                      f"{'?' if gap is None else f'{gap:.1f}'} ms; host late: {host or 'no'}")
            if r["ending"] != "completed":
                print(f"    {r.get('message') or r.get('stderr', '')[-500:]}")
                for line in r.get("timeline", []):
                    print(f"    {line}")
            for g in r.get("gc_in_run", []):
                print(f"    gc during the run: gen {g['generation']}, "
                      f"{1e3 * g['seconds']:.2f} ms, {g['collected']} collected")
    rows = []
    for r in results:
        lat = r.get("latency", (np.nan,) * 3)
        rows.append((r["run"], r["ending"], "yes" if r.get("watchdog") else "no",
                     len(r.get("holds", [])), r.get("ticks", 0), f"{1e3 * lat[0]:.3f}", f"{1e3 * lat[1]:.3f}",
                     f"{1e3 * lat[2]:.3f}", f"{1e3 * r.get('period_p50', np.nan):.3f}",
                     f"{1e3 * r.get('period_max', np.nan):.2f}", len(r.get("slow", [])),
                     f"{1e3 * r.get('bridge_gap_max', np.nan):.2f}",
                     f"{1e3 * r.get('host_late_max', np.nan):.2f}",
                     len(r.get("gc_in_run", [])), f"{r['load']:.2f}"))
    all_lat = [r["latency"][2] for r in results if "latency" in r]
    print()
    print(format_table(["run", "ending", "watchdog stop", "holds", "ticks", "latency p50 ms", "p99 ms",
                        "max ms", "period p50 ms", "max ms", f"ticks > {1e3 * args.slow:g} ms",
                        "bridge gap max ms", "host late max ms", "gc in run", "load"], rows))
    clean = sum(r["ending"] == "completed" for r in results)
    print(f"\n{clean} of {len(results)} runs completed, "
          f"{sum(bool(r.get('watchdog')) for r in results)} watchdog stops, "
          f"{sum(len(r.get('holds', [])) for r in results)} watchdog holds resumed, "
          f"{sum(r.get('ticks', 0) for r in results)} ticks, "
          f"{sum(len(r.get('slow', [])) for r in results)} ticks over "
          f"{1e3 * args.slow:g} ms; controller-side latency max "
          f"{1e3 * max(all_lat, default=np.nan):.3f} ms; load now "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if args.json is not None:
        args.json.write_text(json.dumps(results, default=float, indent=1))
    return 0 if clean == len(results) else 1


if __name__ == "__main__":
    sys.exit(main())
