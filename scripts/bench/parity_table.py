"""Parity of lockstep rehearsals with the simulation, as a table.

For exp1-3 x {the default method, the paper's, full pose with tension control under each
tension sensor (none, drive torque, load cells)} x {UDP, CANopen}: `cdpm run --lockstep`
against the dynamic emulator in lockstep (CANopen: CiA 402 drives and a CANopen force sensor
on python-can's virtual bus), `ramp_time: 0`, versus `cdpm simulate` of the same scenario on
the dynamic plant, over --duration s. Judged on the emulator's truth (cdpm_drake/emulator/
parity.py): the same end, and the differences rehearsal - simulation of the smallest true
tension (N), the largest (%), the true closest approach of a cable pair (mm) and the largest
distance between the true paths (mm); pass when within 0.5 N, 5 %, 0.5 mm, 1 mm.

  python scripts/bench/parity_table.py                 # print the table (3 s runs)
  python scripts/bench/parity_table.py --write-docs    # and put it into docs/on_the_robot.md
"""

import argparse
import re
import sys
import time
from pathlib import Path

from cdpm_drake.emulator import parity

DOC = Path(__file__).resolve().parents[2] / "docs" / "on_the_robot.md"
START, END = "<!-- parity table -->", "<!-- /parity table -->"


def table(duration: float, experiments=parity.EXPERIMENTS, say=print) -> list[dict]:
    """Every row of parity.rows() for `experiments`, one simulation per (experiment,
    setting) shared by both buses."""
    results = []
    for experiment in experiments:
        for setting in parity.SETTINGS:
            sim = parity.simulated(parity.scenario_of(experiment, setting), duration)
            for bus in parity.BUSES:
                why = parity.unsupported(setting, bus)
                start = time.perf_counter()
                r = (dict(experiment=experiment, setting=setting, bus=bus, unsupported=why)
                     if why else parity.parity(experiment, setting, bus, duration, sim=sim))
                results.append(r)
                say(parity.table_row(r) + (f"  ({time.perf_counter() - start:.1f} s)"
                                           if not why else ""))
                if not why and not r["passed"] and (r["fault_sim"] or r["fault_run"]):
                    say(f"    simulation: {r['fault_sim'] or 'completed'}\n"
                        f"    rehearsal: {r['fault_run'] or 'completed'}")
    return results


def markdown(results: list[dict], duration: float) -> str:
    passed = sum(bool(r.get("passed")) for r in results)
    runnable = sum(not r.get("unsupported") for r in results)
    return "\n".join([
        f"Rehearsal minus simulation over the first {duration:g} s ({passed} of {runnable} "
        "within the tolerances; written by `python scripts/bench/parity_table.py "
        "--write-docs`):", "", parity.HEADER, *map(parity.table_row, results)])


def write_docs(text: str, path: Path = DOC) -> None:
    page = path.read_text()
    if START not in page or END not in page:
        raise ValueError(f"{path} has no {START} ... {END} block to write the table into")
    new = re.sub(re.escape(START) + ".*?" + re.escape(END),
                 lambda _: f"{START}\n{text}\n{END}", page, count=1, flags=re.S)
    path.write_text(new)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--duration", type=float, default=3.0, help="s of each run (default 3)")
    p.add_argument("--experiments", nargs="+", default=list(parity.EXPERIMENTS),
                   choices=parity.EXPERIMENTS)
    p.add_argument("--write-docs", action="store_true",
                   help=f"put the table into {DOC.name} between {START} and {END}")
    args = p.parse_args(argv)
    if not args.duration > 0:
        p.error(f"--duration must be > 0 s, got {args.duration!r}")
    if args.write_docs and sorted(args.experiments) != sorted(parity.EXPERIMENTS):
        p.error("--write-docs writes the whole table: give every experiment (the default)")
    print(parity.HEADER, flush=True)
    results = table(args.duration, args.experiments,
                    say=lambda line: print(line, flush=True))
    text = markdown(results, args.duration)
    if args.write_docs:
        write_docs(text)
        print(f"written into {DOC}")
    return 0 if all(r.get("passed") or r.get("unsupported") for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
