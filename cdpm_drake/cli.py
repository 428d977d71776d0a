"""cdpm: simulate, inspect and run the interference-aware admittance controller of a CDPM.

Run `cdpm <command> --help` for each command's options.
"""

import argparse
import sys

import numpy as np


class CliError(Exception):
    """A bad command-line argument; printed without a traceback."""


def _table(headers, rows) -> str:
    cells = [[str(h) for h in headers]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[k]) for r in cells) for k in range(len(headers))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _fmt(v, digits=3) -> str:
    return "[" + ", ".join(f"{x:.{digits}f}" for x in np.asarray(v, dtype=float)) + "]"


# --- info ------------------------------------------------------------------------------------


def info(*, robot: str, out=sys.stdout) -> None:
    """Print a robot description: cables, Jacobian conditioning, workspace."""
    from .kinematics import cable_lengths, condition_number
    from .robot import load_robot

    r = load_robot(robot)
    c = r.workspace.center
    lengths = cable_lengths(r, c)
    print(f"robot {r.name!r} ({r.source}): {r.num_cables} cables, {r.num_pairs} watched pairs",
          file=out)
    rows = [(i + 1, _fmt(r.reels[i]), _fmt(r.attachments[i]), f"{lengths[i]:.4f}")
            for i in range(r.num_cables)]
    print(_table(["cable", "reel a_i (m)", "attachment b_i (m)", "length at centre (m)"], rows),
          file=out)
    print(f"workspace box: lower {_fmt(r.workspace.lower)} m, upper {_fmt(r.workspace.upper)} m,"
          f" centre {_fmt(c)} m", file=out)
    print(f"Jacobian condition number at the centre: {condition_number(r, c):.3f}", file=out)
    lim = r.limits
    print(f"limits: velocity {lim.max_velocity} m/s, acceleration {lim.max_acceleration} m/s^2,"
          f" reel speed {lim.max_reel_speed} m/s", file=out)
    for pair, why in sorted(r.excluded_reasons.items()):
        print(f"pair {pair} skipped: {why}", file=out)
    try:
        from .interference import pair_distances
    except ImportError:
        return
    d = pair_distances(r, c)
    rows = [(f"({i},{j})", f"{1000 * dk:.1f}") for (i, j), dk in zip(r.pairs, d)]
    print("cable-cable distances at the centre:", file=out)
    print(_table(["pair", "distance (mm)"], rows), file=out)


def _cmd_info(args) -> None:
    info(robot=args.robot)


# --- main ------------------------------------------------------------------------------------


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cdpm", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("info", help="print a robot description: cables, Jacobian, workspace",
                       description="Print a robot description as a table.")
    p.add_argument("robot", nargs="?", default="paper_7cable",
                   help="a built-in robot's name or a path to a robot YAML file "
                        "(default: paper_7cable)")
    p.set_defaults(func=_cmd_info)
    return parser


def main(argv=None) -> int:
    from .kinematics import KinematicsError
    from .robot import RobotError

    args = _parser().parse_args(argv)
    try:
        args.func(args)
    except (CliError, RobotError, KinematicsError) as e:
        print(f"cdpm {args.command}: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
