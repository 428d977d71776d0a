"""Benchmark of real-time runs: tick-period distribution (p50, p99, p99.9,
max), overruns and lost samples of the scenario's Fig. 5 diagram at real-time rate 1 with the
hardware plant against cdpm-reel-emulator (a separate process on loopback), in one table.

The reference, measured in the same run, is the same diagram with the simulated plant, paced
at real-time rate 1 as well: what Drake's pacing and the diagram cost on this host without the
link. Ratios are against it. Timing comes from the streamed tick log (time.monotonic() at each
tick's publish): overruns are ticks that started more than one period behind the schedule set
by the first tick; missing ticks are gaps in the log's tick column (samples lost to the log).

Usage: python scripts/bench/bench_realtime.py [--duration 60] [--scenario exp2_interaction]
                                        [--watchdog-ticks 3] [--rt-priority 0]
"""

import argparse
import re
import signal
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

from pydrake.systems.analysis import Simulator

from cdpm_drake.diagram import BuildOptions, build_diagram
from cdpm_drake.hardware.config import HardwareReels
from cdpm_drake.hardware.priority import set_realtime_priority
from cdpm_drake.hardware.reels import ReelFault, start_realtime
from cdpm_drake.hardware.tick_log import read_tick_log, realtime_stats
from cdpm_drake.config import SimulatedReels, load_scenario
from cdpm_drake.text import format_table


def _free_port() -> int:
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    return port


def run_case(scenario, duration, tick_path):
    """Run `scenario` for `duration` s at real-time rate 1; (timing stats, link report,
    error text or '')."""
    diagram = build_diagram(scenario, BuildOptions(loggers=False, tick_log=str(tick_path)))
    sink = diagram.GetSubsystemByName("tick_log")
    reels = diagram.GetSubsystemByName("reels")
    hardware = hasattr(reels, "shutdown")
    simulator = Simulator(diagram)
    error = ""
    link = {}
    try:
        start_realtime(simulator, 1.0)
        simulator.AdvanceTo(duration)
    except ReelFault as e:
        error = str(e).split(";")[0]
    finally:
        if hardware:
            reels.shutdown()
            if reels.link is not None:
                link = reels.link.counters.as_dict()
                link["commands_lost"] = int(reels.book(
                    reels.GetMyContextFromRoot(simulator.get_context()))["commands_lost"])
            reels.close()
        sink.close()
    return realtime_stats(read_tick_log(tick_path), scenario.time_step), link, error


def start_emulator(scenario_name, port):
    process = subprocess.Popen(
        [sys.executable, "-m", "cdpm_drake.emulator", "--scenario", scenario_name,
         "--port", str(port)], stdout=subprocess.PIPE, text=True)
    banner = process.stdout.readline()
    if "cdpm-reel-emulator:" not in banner:
        process.kill()
        raise RuntimeError(f"the emulator did not start: {banner!r}")
    return process


def stop_emulator(process) -> int | None:
    """SIGINT the emulator; its own count of commands it never received."""
    process.send_signal(signal.SIGINT)
    out, _ = process.communicate(timeout=10)
    found = re.search(r"commands lost (\d+)", out)
    return int(found.group(1)) if found else None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=60.0, help="s per case (default 60)")
    parser.add_argument("--scenario", default="exp2_interaction")
    parser.add_argument("--watchdog-ticks", type=int, default=HardwareReels.watchdog_ticks,
                        help="the hardware plant's watchdog (default: HardwareReels' %(default)s)")
    parser.add_argument("--rt-priority", type=int, default=0,
                        help="run both cases and the emulator under SCHED_FIFO at this priority "
                        "(needs root or CAP_SYS_NICE; default 0: normal scheduling)")
    args = parser.parse_args(argv)
    set_realtime_priority(args.rt_priority)  # the emulator, started later, inherits it

    results = []
    with tempfile.TemporaryDirectory() as tmp:
        reference = load_scenario(args.scenario, "plant: !SimulatedReels {}")
        assert isinstance(reference.plant, SimulatedReels)
        print(f"reference: {args.scenario} with the simulated plant, {args.duration:g} s ...",
              flush=True)
        results.append(("simulated plant (reference)",
                        *run_case(reference, args.duration, Path(tmp) / "sim.ticks")))

        port = _free_port()
        hardware = load_scenario(args.scenario)
        hardware.plant = HardwareReels(port=port, watchdog_ticks=args.watchdog_ticks)
        emulator = start_emulator(args.scenario, port)
        print(f"hardware plant against cdpm-reel-emulator on 127.0.0.1:{port}, "
              f"{args.duration:g} s ...", flush=True)
        try:
            stats, link, error = run_case(hardware, args.duration, Path(tmp) / "hw.ticks")
        finally:
            bridge_lost = stop_emulator(emulator)
        if bridge_lost is not None:
            link["commands_lost"] = bridge_lost
        results.append(("hardware plant + emulator", stats, link, error))

    ref = results[0][1]
    ms = lambda v: f"{1e3 * v:.3f}"  # noqa: E731
    rows = []
    for name, s, link, error in results:
        rejected = sum(link.get("rejected", {}).values()) if link else "-"
        rows.append((name, s["ticks"], ms(s["p50"]), ms(s["p99"]), ms(s["p99.9"]), ms(s["max"]),
                     f"{s['p99'] / ref['p99']:.2f}", f"{s['max'] / ref['max']:.2f}",
                     s["overruns"], s["missing_ticks"],
                     link.get("lost", "-") if link else "-", rejected,
                     link.get("commands_lost", "-") if link else "-", error or "none"))
    print()
    print(f"scenario {args.scenario!r}, {args.duration:g} s per case, period "
          f"{1e3 * load_scenario(args.scenario).time_step:g} ms, watchdog "
          f"{args.watchdog_ticks} ticks, SCHED_FIFO priority {args.rt_priority or 'off'}; "
          f"ratios against the reference")
    print(format_table(["case", "ticks", "p50 ms", "p99 ms", "p99.9 ms", "max ms", "p99 ratio",
                  "max ratio", "overruns", "missing ticks", "statuses lost",
                  "statuses rejected", "commands lost", "fault"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
