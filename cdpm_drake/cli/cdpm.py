"""The `cdpm` command: its argument parser (every command's options and help), the exit codes,
and `main`, which imports only the module of the command it runs."""

import argparse
import sys
from pathlib import Path

from cdpm_drake.cli.compile_notice import compile_notice
from cdpm_drake.cli.errors import CliError, InputError
from cdpm_drake.text import prefixed_log_records

# The top of `cdpm --help`.
DESCRIPTION = ("cdpm: simulate, inspect and run the interference-aware admittance controller "
               "of a CDPM.\n\nRun `cdpm <command> --help` for each command's options.\n")

EXIT_CODES = """\
exit codes (every command):
  0    done
  1    error: a scenario, robot, sweep, log or run folder that cannot be found or is
       invalid, a run that failed or faulted, cdpm run that never enabled the reels
  2    bad usage: an unknown option, a missing or malformed argument, an option value
       out of range (--duration, --realtime, --out, ...)
  130  interrupted by Ctrl-C (SIGINT); whatever was logged is written
  143  stopped by SIGTERM (e.g. `timeout`, a batch scheduler); as for Ctrl-C
"""


class _Parser(argparse.ArgumentParser):
    """An argument error in a sub-command shows that sub-command's usage, not the top one."""

    def parse_args(self, args=None, namespace=None):
        args, extras = self.parse_known_args(args, namespace)
        if extras:
            sub = getattr(args, "_subparser", None) or self
            sub.error(f"unrecognized arguments: {' '.join(extras)}")
        return args


def build_parser() -> argparse.ArgumentParser:
    """The parser of `cdpm`: every command's options and help."""
    from cdpm_drake import __version__

    parser = _Parser(prog="cdpm", description=DESCRIPTION, epilog=EXIT_CODES,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"cdpm {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("info", help="print a robot description: cables, Jacobian, workspace, "
                                    "statics",
                       description="Print a robot description as tables: cables, Jacobian, "
                                   "workspace, cable-cable distances and statics (where the "
                                   "cables hold the platform). Given a scenario, the robot "
                                   "as that experiment uses it: its swaps, start and path.")
    p.add_argument("robot", nargs="?", default="paper_7cable",
                   help="a built-in robot or scenario name, or a path to a robot or scenario "
                        "YAML file (default: paper_7cable)")
    p.add_argument("--swaps", nargs="+", type=_swap_arg, metavar="I-J",
                   help="swap these cables' attachment points (1-based, e.g. 1-3 5-7); with "
                        "a scenario, instead of its swaps")
    p.add_argument("--plot", type=Path, metavar="DIR",
                   help="also write the workspace pictures (wrench-feasible and "
                        "interference-free workspace slices) into DIR")
    p.add_argument("--grid", type=float, default=0.05, metavar="STEP",
                   help="grid step (m) of the statics share (default 0.05)")

    p = sub.add_parser("simulate", help="simulate a scenario and write its log",
                       description="Simulate a scenario's Fig. 5 diagram with Drake's Simulator "
                                   "at 500 Hz; write DIR/log.npz and DIR/scenario.yaml (with "
                                   "copies of the robot file and force CSV it reads, so DIR "
                                   "reruns alone).")
    _scenario_args(p)
    p.add_argument("--duration", type=float, help="simulated time, s (default: the scenario's)")
    p.add_argument("--out", type=Path,
                   help="output directory, used exactly; must be empty unless --force "
                        "(default: a new runs/<scenario name>/<UTC time>/, with "
                        "runs/<scenario name>/latest pointing at it)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--meshcat", action="store_true",
                   help="show the robot live in Meshcat (prints the URL to open); the "
                        "simulation then runs at real time (see --realtime)")
    p.add_argument("--realtime", type=float, metavar="RATE",
                   help="pace the simulation at RATE x real time (default: as fast as "
                        "possible; 1.0 with --meshcat)")
    p.add_argument("--no-wait", action="store_true",
                   help="with --meshcat: quit at the end instead of waiting for Enter")
    p.add_argument("--html", type=Path, metavar="FILE",
                   help="also save a self-contained 3D replay (opens in a browser, no server)")
    p.add_argument("--plot", action="store_true",
                   help="also write the paper's figures as PNGs next to the log")
    p.add_argument("--force", action="store_true",
                   help="empty a non-empty --out that holds an earlier run, then write there")

    p = sub.add_parser("run", help="run a scenario in real time against the reels",
                       description="Build the same diagram with the scenario's !HardwareReels "
                                   "plant and run it at 500 Hz in real time against the reel "
                                   "bridge (or cdpm-reel-emulator), or with !CanopenReels "
                                   "against CiA 402 drives on a CAN bus (or cdpm emulate "
                                   "--canopen; hardware/CANOPEN.md). Ctrl-C or SIGTERM stop it "
                                   "cleanly (zero reel velocity is sent first); every tick is "
                                   "logged to disk as it goes.")
    _scenario_args(p, default=None)
    p.add_argument("--duration", type=float, help="run time, s (default: the scenario's)")
    p.add_argument("--out", type=Path,
                   help="output directory, used exactly; must be empty unless --force "
                        "(default: a new runs/<scenario name>/<UTC time>/, with "
                        "runs/<scenario name>/latest pointing at it)")
    p.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="run under SCHED_FIFO at priority N (1..99; needs root or "
                        "CAP_SYS_NICE): keeps a busy host from delaying ticks past the "
                        "watchdog (default 0: normal scheduling)")
    p.add_argument("--meshcat", action="store_true",
                   help="show the robot live in Meshcat (prints the URL to open)")
    p.add_argument("--force", action="store_true",
                   help="empty a non-empty --out that holds an earlier run, then write there")
    p.add_argument("--lockstep", action="store_true",
                   help="rehearsal against cdpm emulate --lockstep: each tick waits for the "
                        "status answering its command, the watchdogs count ticks, nothing "
                        "keeps wall-clock time; the run is deterministic on any host (the "
                        "plant's lockstep: true)")
    p.add_argument("--plot", action="store_true",
                   help="after the run, write the paper's figures (PNG) into its folder, as "
                        "cdpm simulate --plot")

    p = sub.add_parser("emulate", help="play the reel bridge on loopback (cdpm-reel-emulator)",
                       description="Same as cdpm-reel-emulator; `cdpm emulate --help` lists "
                                   "its options; `cdpm emulate --canopen` plays CiA 402 drives "
                                   "on a CAN bus instead.", add_help=False)
    p.add_argument("emulator_args", nargs="*",
                   help="options of cdpm-reel-emulator, e.g. --scenario exp2_interaction")

    p = sub.add_parser("plot", help="plot a log: the paper's Figs. 8-16 as PNGs",
                       description="Plot a log.npz: pair distances with d_l and d_u (Fig. 10), "
                                   "forces (Figs. 11, 13, 16), the 3D trajectory with "
                                   "interference events (Figs. 9, 15), the logistic curve "
                                   "(Fig. 8).")
    p.add_argument("log", type=Path,
                   help="a log.npz, the run folder holding it (or only ticks.bin: recovered "
                        "first), runs/<name> (its latest run), or a sweep's directory (its "
                        "pictures from results.csv)")
    p.add_argument("--out", type=Path, help="output directory (default: the log's directory)")
    p.add_argument("--html", type=Path, metavar="FILE",
                   help="save a self-contained 3D replay of the log; the PNGs already drawn "
                        "from this log are kept, only missing ones drawn")

    p = sub.add_parser("diagram", help="write the controller diagram as graphviz (.dot, .svg)",
                       description="Write the Fig. 5 diagram of a scenario as .dot and .svg "
                                   "files, each at full depth and as a readable overview: with "
                                   "the simulated, the hardware and the dynamic plant, the "
                                   "dynamic plant alone, and the full-pose controller.")
    _scenario_args(p)
    p.add_argument("--out", type=Path, default=Path("diagrams"),
                   help="output directory (default: diagrams)")
    p.add_argument("--depth", type=int, default=None,
                   help="how many levels of sub-diagrams the full-depth pictures expand "
                        "(default: every level, the plant's insides too)")
    p.add_argument("--no-svg", action="store_true", help="write only the .dot files")

    _sweep_parser(sub)
    _export_parser(sub)

    p = sub.add_parser("recover", help="turn a killed run's ticks.bin into log.npz",
                       description="Convert the tick stream of a `cdpm run` that was killed "
                                   "before it wrote log.npz (SIGKILL, power loss) into "
                                   "DIR/log.npz, using DIR/scenario.yaml; says how many ticks "
                                   "it kept and whether the tail was cut.")
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR",
                   help="the run's folder (holding ticks.bin and scenario.yaml), or "
                        "runs/<name> for its latest run")

    from cdpm_drake.cli.calibrate import add_parser as calibrate_parser
    calibrate_parser(sub)

    sub.add_parser("warm", help="compile every kernel the commands need, once (numba)",
                   description="Compile the per-tick math (numba kernels) of every command "
                               "in one step, a line per group with its time, so that no "
                               "later run pauses to compile: 40 s to 3 min after installing "
                               "or updating, a few seconds when already cached.")
    sub.add_parser("list", help="list the built-in robots, scenarios and sweeps",
                   description="List the robots, scenarios and sweeps shipped with the "
                               "package, one line each; use them by name from any "
                               "directory.")
    for name, choice in sub.choices.items():
        choice.set_defaults(_subparser=choice)
    return parser


def _swap_arg(text: str) -> tuple[int, int]:
    """A cable swap 'I-J' (or 'I,J'), 1-based."""
    parts = text.replace(",", "-").split("-")
    try:
        i, j = (int(x) for x in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a swap is two cable numbers I-J, e.g. 1-3; got "
                                         f"{text!r}") from None
    return i, j


def _scenario_args(p, default="exp2_interaction"):
    from cdpm_drake.config import scenario_names

    names = ", ".join(scenario_names())
    if default is None:
        p.add_argument("scenario", help=f"a built-in scenario ({names}) or a path to a "
                                        "scenario YAML")
    else:
        p.add_argument("scenario", nargs="?", default=default,
                       help=f"a built-in scenario ({names}) or a path to a scenario YAML "
                            f"(default: {default})")
    p.add_argument("--scenario-text", default=None, metavar="YAML",
                   help="YAML overlay for one-off changes, e.g. "
                        "'{duration: 5, interference: {default: {F_u: 4.0}}}'")
    p.add_argument("--method", choices=("promise", "paper"), default=None,
                   help="which controller: promise, the paper's Fig. 5 with the safety filter "
                        "that keeps every cable pair at or above d_min (the default); paper, "
                        "the paper's method exactly (no safety filter). Overrides the "
                        "scenario's `method:`")


def _export_parser(sub) -> None:
    p = sub.add_parser(
        "export", help="write a log as CSV, a MATLAB .mat file or a ROS 2 bag (.mcap)",
        description="Write a log.npz for other tools, in one of three formats: --csv (the "
                    "default) one row per tick, one column per value, named with its unit "
                    "(p_x [m], lengths_1 [m], pair_distances_1-3 [m], active_1-3 [0/1]); "
                    "--mat a MATLAB .mat file (v5) with every key of the log, a struct "
                    "`units` and a vector `cables` 1..m; --mcap a ROS 2 bag in MCAP storage "
                    "for Foxglove and ros2 bag (joint states of the reels, the platform pose "
                    "estimated and true, the forces as wrenches, the cables as line markers; "
                    "frame 'base', stamps from 0 s). Cables are numbered from 1 and pairs by "
                    "their cables (docs/LOG_FORMAT.md). --mcap needs rosbags: "
                    "pip install 'cdpm_drake[export]'.")
    p.add_argument("log", type=Path,
                   help="a log.npz, the run folder holding it (or only ticks.bin: recovered "
                        "first), or runs/<name> (its latest run)")
    formats = p.add_mutually_exclusive_group()
    formats.add_argument("--csv", action="store_true",
                         help="comma-separated values, log.csv (the default)")
    formats.add_argument("--mat", action="store_true",
                         help="MATLAB .mat (v5), log.mat: every log key, its unit in `units`")
    formats.add_argument("--mcap", action="store_true",
                         help="a ROS 2 bag in MCAP storage, log.mcap (Foxglove, ros2 bag)")
    p.add_argument("--out", type=Path, metavar="FILE",
                   help="output file (default: log.csv, log.mat or log.mcap beside the log; "
                        "- for stdout, CSV only)")


def _sweep_parser(sub) -> None:
    from cdpm_drake.runs.sweep import NUMERIC_METRICS, sweep_names

    p = sub.add_parser(
        "sweep", help="run many variants of a scenario (a grid, random samples, seeds)",
        description="Run every variant of a sweep file (docs/SWEEP_FORMAT.md) with the same "
                    "diagram and Simulator as cdpm simulate, on local processes (one per core) "
                    "or on Ray; write DIR/results.csv (one row per run) and each run's "
                    "resolved scenario.yaml. Rerunning the same command resumes.")
    p.add_argument("sweep", help=f"a shipped sweep ({', '.join(sweep_names())}) or a path to "
                                 "a sweep YAML")
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="output directory (default: runs/sweeps/<sweep name>)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="local worker processes (default: one per core)")
    p.add_argument("--ray", nargs="?", const="", metavar="ADDRESS",
                   help="run on Ray: a local Ray, or the cluster at ADDRESS (e.g. "
                        "ray://host:10001 or auto); needs pip install -e '.[ray]'")
    p.add_argument("--ray-chunk", type=int, metavar="K",
                   help="runs per Ray task (default: chosen so a task lasts ~2 s)")
    p.add_argument("--keep-logs", action="store_true", help="also keep each run's log.npz")
    p.add_argument("--retry-errors", action="store_true",
                   help="rerun the rows that faulted or ended in an error (a resume skips "
                        "them)")
    p.add_argument("--plot", action="store_true",
                   help="write the heatmap, metric-vs-axis and Pareto pictures")
    p.add_argument("--metric", choices=NUMERIC_METRICS, metavar="NAME",
                   help="metric of the pictures and the best-runs table (default: the sweep "
                        f"file's, else min_distance): {', '.join(NUMERIC_METRICS)}")
    p.add_argument("--top", type=int, default=5, metavar="K",
                   help="rows in the best-runs table (default 5)")
    p.add_argument("--dry-run", action="store_true",
                   help="check and list the variants, run nothing")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _command(name: str):
    """The function that runs the command `name` on its parsed arguments. Its module is
    imported here, for the one command that runs: `cdpm --help` and a usage error import
    none of them."""
    if name == "info":
        from cdpm_drake.cli.info import cmd_info as command
    elif name == "simulate":
        from cdpm_drake.cli.simulate import cmd_simulate as command
    elif name == "run":
        from cdpm_drake.cli.run import cmd_run as command
    elif name == "plot":
        from cdpm_drake.cli.plot import cmd_plot as command
    elif name == "diagram":
        from cdpm_drake.cli.diagram import cmd_diagram as command
    elif name == "sweep":
        from cdpm_drake.cli.sweep import cmd_sweep as command
    elif name == "export":
        from cdpm_drake.cli.export import cmd_export as command
    elif name == "recover":
        from cdpm_drake.cli.recover import cmd_recover as command
    elif name == "list":
        from cdpm_drake.cli.listing import cmd_list as command
    elif name == "calibrate":
        from cdpm_drake.cli.calibrate import cmd_calibrate as command
    elif name == "warm":
        from cdpm_drake.cli.warm import cmd_warm as command
    else:  # `emulate` is handed to the emulator before parsing
        raise AssertionError(f"no module for the command {name!r}")
    return command


def main(argv=None) -> int:
    """Run `cdpm` on argv (default: sys.argv[1:]); the exit code (EXIT_CODES)."""
    try:
        return _main(argv)
    except KeyboardInterrupt:
        # Ctrl-C before a command's own handler is in place (while pydrake and the kernels
        # import, about a second): no traceback, the code of an interrupt.
        print("cdpm: interrupted (Ctrl-C)", file=sys.stderr)
        return 130


def _main(argv) -> int:
    from cdpm_drake.hardware.tick_log import TickLogError
    from cdpm_drake.runs.interrupt import Terminated, exit_code, terminate_raises
    from cdpm_drake.kernels.kinematics import KinematicsError
    from cdpm_drake.kernels.plant.operators import OperatorError
    from cdpm_drake.robot import RobotError
    from cdpm_drake.config import ScenarioError

    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["emulate"]:
        # argparse cannot hand options through a sub-command untouched; the emulator parses
        # its own.
        from cdpm_drake.emulator import main as emulator_main
        with compile_notice():
            return emulator_main(argv[1:])
    args = build_parser().parse_args(argv)
    # `cdpm warm` says what it compiles itself, a line per group.
    with prefixed_log_records(), terminate_raises(), compile_notice(quiet=args.command == "warm"):
        try:
            return int(_command(args.command)(args) or 0)
        except CliError as e:
            print(f"cdpm {args.command}: error: {e}", file=sys.stderr)
            return 2
        except (InputError, RobotError, KinematicsError, ScenarioError, OperatorError,
                TickLogError) as e:
            print(f"cdpm {args.command}: error: {e}", file=sys.stderr)
            return 1
        except KeyboardInterrupt as e:
            what = "SIGTERM" if isinstance(e, Terminated) else "Ctrl-C"
            print(f"cdpm {args.command}: interrupted ({what})", file=sys.stderr)
            return exit_code(e)
        except BrokenPipeError:
            # `cdpm info | head`: the reader left; not an error of ours.
            sys.stderr.close()
            return 0
