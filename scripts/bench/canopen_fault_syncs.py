"""SYNCs from a CANopen fault's onset to the stop, against the independent CiA 402 drive set
(tests/hardware/independent_cia402.py): per fault, in one process on the virtual bus
(lockstep) and end to end (`cdpm run` and the drive set in two processes over udp_multicast in
`unshare -n`, both under SCHED_FIFO), the SYNCs after the onset (the SYNC whose TPDO first
shows the fault) on which every live drive had target velocity 0, was quick stopped, and was
disabled. hardware/CANOPEN.md quotes its table.

    python scripts/bench/canopen_fault_syncs.py [--repeats 3] [--no-e2e]
"""

import argparse
import collections
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(REPO / "tests"), str(REPO / "tests" / "hardware")]

FAULTS = {"fault (EMCY)": [("fault", 2, 100)], "fault bit": [("fault_bit", 2, 100)],
          "fault bit, TPDO late": [("fault_bit", 2, 100), ("late", 2, 100)],
          "silent node": [("silent", 2, 100)], "frozen position": [("frozen", 5, 100)],
          "frozen, TPDO late": [("frozen", 5, 100), ("late", 5, 100)]}


def main() -> int:
    import test_canopen_independent as t

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--no-e2e", action="store_true")
    args = p.parse_args()
    rows = collections.defaultdict(list)
    with tempfile.TemporaryDirectory() as tmp:
        for name, faults in FAULTS.items():
            for r in range(args.repeats):
                summary = t._in_process(faults)[0]
                rows[(name, "one process")].append(t.stop_syncs(summary))
                if args.no_e2e:
                    continue
                # End to end the fault comes 1 s into exp2 (cable 5 at ~14 mm/s then).
                e2e = [(k, n, 500) for k, n, _ in faults]
                for attempt in range(3):
                    _, _, _, summary = t._run(Path(tmp), f"{name}{r}{attempt}".replace(" ", "_")
                                              .replace(",", "").replace("(", "")
                                              .replace(")", ""), e2e, duration=3.0)
                    if summary["onsets"]:
                        break
                if summary["onsets"]:
                    rows[(name, "end to end")].append(t.stop_syncs(summary))
    print("| fault | where | runs | target 0 | quick stop | disabled |")
    print("|---|---|---|---|---|---|")
    for (name, where), results in rows.items():
        def span(i):
            values = sorted({x[i] - x[0] for x in results if x[i] is not None})
            return "/".join(map(str, values)) + (" (never in some)" if any(
                x[i] is None for x in results) else "")
        print(f"| {name} | {where} | {len(results)} | {span(1)} | {span(2)} | {span(3)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
