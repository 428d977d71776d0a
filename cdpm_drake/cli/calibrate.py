"""`cdpm calibrate`: fit a robot file's reel exits, encoder offsets and (full pose) attachment
points to the encoder lengths of one or more runs, report what the data identify, and write
the calibrated file beside the original."""

import sys
from pathlib import Path

from cdpm_drake.cli.arguments import check_writable_dir
from cdpm_drake.cli.errors import CliError, InputError


def cmd_calibrate(args) -> int:
    """Exit 0: written (or --dry-run); 1: the data cannot calibrate the robot (the reason
    printed, nothing written)."""
    from cdpm_drake.robot.calibration import CalibrationError, CalibrationPrior
    from cdpm_drake.runs.calibrate import (CalibrationSettings, calibrate_runs, calibrated_path,
                                           calibrated_yaml, report)

    if args.write_motion is not None:
        return _write_motion(args)
    if not args.runs:
        raise CliError("give the runs to calibrate from (RUN ...), or --write-motion FILE "
                       "for a calibration motion of the robot")

    for name in ("encoder_std", "reels_prior", "attachments_prior", "offsets_prior",
                 "min_spacing", "max_speed"):
        value = getattr(args, name)
        if not value > 0:
            raise CliError(f"--{name.replace('_', '-')} must be > 0, got {value!r}")
    if not 8 <= args.max_poses <= 2000:
        raise CliError(f"--max-poses must be within 8..2000, got {args.max_poses!r}")
    settings = CalibrationSettings(
        encoder_std=args.encoder_std, fit_attachments=args.attachments,
        max_poses=args.max_poses, min_spacing=args.min_spacing, max_speed=args.max_speed,
        prior=CalibrationPrior(reels_std=args.reels_prior,
                               attachments_std=args.attachments_prior,
                               offsets_std=args.offsets_prior))
    try:
        cal = calibrate_runs(args.runs, args.robot, settings, args.measured_poses)
    except CalibrationError as e:
        raise InputError(str(e)) from None
    for line in report(cal, settings):
        print(line)
    if cal.problems:
        for problem in cal.problems:
            print(f"cdpm calibrate: refused: {problem}", file=sys.stderr)
        print("cdpm calibrate: nothing written", file=sys.stderr)
        return 1
    out = calibrated_path(Path(cal.robot_path), args.out)
    if args.dry_run:
        print(f"(--dry-run: would write {out})")
        return 0
    if out.resolve() == Path(cal.robot_path).resolve():
        raise CliError(f"--out {str(out)!r} is the original robot file; the calibrated file "
                       "is written beside it, never over it")
    if out.exists() and not args.force:
        raise CliError(f"{str(out)!r} exists; give --out another file, or --force to "
                       "replace it")
    check_writable_dir(out.parent if str(out.parent) else Path("."), "the calibrated file's folder")
    out.write_text(calibrated_yaml(cal, settings))
    print(f"calibrated robot: {out} (use it as `robot: {out}` in a scenario)")
    return 0


def _write_motion(args) -> int:
    """`--write-motion FILE`: a calibration motion scenario for the robot."""
    import numpy as np

    from cdpm_drake.robot import load_robot
    from cdpm_drake.runs.calibrate import calibration_motion_yaml

    robot = load_robot(args.robot)
    start = None
    if args.start is not None:
        start = np.asarray(args.start, dtype=float)
        if not robot.workspace.contains(start):
            raise CliError(f"--start {args.start!r} m is outside robot {robot.name!r}'s "
                           f"workspace box (lower {robot.workspace.lower.tolist()}, upper "
                           f"{robot.workspace.upper.tolist()})")
    out = args.write_motion
    if out.exists() and not args.force:
        raise CliError(f"{str(out)!r} exists; give another file, or --force to replace it")
    check_writable_dir(out.parent if str(out.parent) else Path("."), "--write-motion's folder")
    ref = args.robot if not Path(args.robot).suffix else str(Path(args.robot).resolve())
    out.write_text(calibration_motion_yaml(ref, robot, start=start))
    print(f"calibration motion: {out} (cdpm simulate {out}, or cdpm run it against the robot)")
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser(
        "calibrate", help="fit the robot file's geometry to runs' encoder lengths",
        description="Self-calibration from redundant cable lengths: fit the reel exits, each "
                    "run's encoder offsets and, with the full pose (--attachments), the "
                    "attachment points to the encoder lengths of one or more runs "
                    "(quasi-static poses picked from each log), by robust nonlinear least "
                    "squares with each run's first pose (its homing) fixed. Prints per cable "
                    "the correction, its standard deviation, whether the data identify it, "
                    "and the misfit before and after; writes ROBOT_calibrated.yaml beside "
                    "the robot file with the uncertainties (never over it). Refuses, "
                    "writing nothing, logs of another robot, too few poses, a misfit above "
                    "the encoders' noise, a correction beyond the prior. "
                    "docs/calibration.md gives the procedure.")
    p.add_argument("runs", nargs="*", type=Path, metavar="RUN",
                   help="a run folder, its log.npz, or runs/<name> (its latest run)")
    p.add_argument("--write-motion", type=Path, default=None, metavar="FILE",
                   help="instead of fitting: write a calibration motion scenario for --robot "
                        "(poses spread over its workspace box where its cables hold the "
                        "platform), to run first")
    p.add_argument("--start", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="--write-motion's start (the homing pose), m (default: the box's "
                        "centre)")
    p.add_argument("--robot", required=True,
                   help="the robot file the runs used (a built-in name or a YAML path)")
    p.add_argument("--out", type=Path, default=None,
                   help="the calibrated file (default: ROBOT_calibrated.yaml beside the robot "
                        "file; a built-in robot's in the current folder)")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.add_argument("--dry-run", action="store_true", help="fit and report, write nothing")
    p.add_argument("--attachments", action="store_true",
                   help="fit the attachment points too (logs of the full pose only)")
    p.add_argument("--measured-poses", type=Path, default=None, metavar="FILE",
                   help="externally measured platform positions (laser tracker, motion "
                        "capture) at a few held poses of the runs, base frame (YAML: poses: "
                        "[{time or index, position, std, run}]; docs/calibration.md): they "
                        "fix the base frame's turn a translating platform's lengths cannot "
                        "see, so the exits' absolute positions can be identified")
    p.add_argument("--encoder-std", type=float, default=1e-4, metavar="M",
                   help="one encoder reading's noise, m (default 1e-4)")
    p.add_argument("--reels-prior", type=float, default=0.05, metavar="M",
                   help="how far the file's reel exits may be off, one std per axis, m "
                        "(default 0.05)")
    p.add_argument("--attachments-prior", type=float, default=0.02, metavar="M",
                   help="the same for the attachment points, m (default 0.02)")
    p.add_argument("--offsets-prior", type=float, default=0.05, metavar="M",
                   help="the same for the encoder offsets, m (default 0.05)")
    p.add_argument("--max-poses", type=int, default=150,
                   help="at most this many poses per run (default 150)")
    p.add_argument("--min-spacing", type=float, default=0.03, metavar="M",
                   help="poses at least this far apart, m (default 0.03)")
    p.add_argument("--max-speed", type=float, default=0.3, metavar="M/S",
                   help="poses where the platform moves slower than this, m/s (default 0.3)")
