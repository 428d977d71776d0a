"""`cdpm calibrate`'s work: read runs' logs, pick their quasi-static poses, fit the robot's
geometry to the encoder lengths (robot/calibration.py), report what the data identify, and
write the calibrated robot file beside the original (never over it)."""

import dataclasses
import datetime
from pathlib import Path

import numpy as np

from cdpm_drake.robot import load_robot, resolve_robot_path
from cdpm_drake.robot.calibration import (CalibrationError, CalibrationPrior, calibrate,
                                          parameter_names, select_poses)
from cdpm_drake.runs.log import LogError, load_log
from cdpm_drake.runs.run_folder import resolve_latest

# Two points of two files agree within this, m (a log keeps the file's numbers as floats).
SAME = 1e-9


@dataclasses.dataclass
class CalibrationSettings:
    """The fit's settings (the command's options)."""

    # One encoder reading's noise, m (a 0.1 mm encoder resolution and cable's roughness).
    encoder_std: float = 1e-4
    prior: CalibrationPrior = dataclasses.field(default_factory=CalibrationPrior)
    # Fit the attachment points too (full pose only).
    fit_attachments: bool = False
    # Poses: at most this many per run, this far apart (m), slower than this (m/s).
    max_poses: int = 150
    min_spacing: float = 0.03
    max_speed: float = 0.3
    # A parameter is identified when its standard deviation is at most this, m.
    identified_std: float = 5e-4
    # The fit is refused when a cable's RMS misfit after it exceeds this many encoder_std
    # (the model cannot explain the data: wrong robot, slack, a bad encoder).
    max_residual_sigmas: float = 5.0
    # ... or when a correction exceeds this many prior standard deviations.
    max_prior_sigmas: float = 4.0
    # ... or when a measured pose is farther than this many of its std from the fitted pose.
    max_measured_sigmas: float = 5.0


@dataclasses.dataclass
class CalibrationRun:
    """A fit and what it read."""

    robot: object                 # the file's robot (unswapped)
    robot_path: Path
    sources: list                 # the logs read
    result: object                # robot.calibration.CalibrationResult, in the file's order
    poses: int
    full_pose: bool
    stretch: bool                 # measured tensions used for the cables' stretch
    problems: list                # why the fit must not be written ([] when it may)
    # The externally measured poses: their file, and per pose (its description, its std m).
    measured_file: str = ""
    measured: list = dataclasses.field(default_factory=list)


def _attachment_order(log_b, file_b, path) -> np.ndarray:
    """order[i]: the file's cable whose attachment point the log's cable i uses (a scenario's
    swaps exchange attachment points); CalibrationError when the log's points are not the
    file's."""
    order = []
    for i, b in enumerate(log_b):
        match = np.flatnonzero(np.linalg.norm(file_b - b, axis=1) <= SAME)
        if match.size == 0:
            raise CalibrationError(f"{path}: cable {i + 1}'s attachment point {b.tolist()} m "
                                   "is none of the robot file's: the log is of another robot "
                                   "(or another version of this file)")
        order.append(int(match[0]))
    return np.array(order)


def _read(path, robot):
    """(log, attachment order) of one run, checked against the robot file."""
    target = resolve_latest(Path(path))
    try:
        log = load_log(target)
    except LogError as e:
        raise CalibrationError(str(e)) from None
    m = robot.num_cables
    reels = np.asarray(log["reels"], dtype=float)
    if reels.shape != (m, 3):
        raise CalibrationError(f"{target}: the log's robot {str(log['robot_name'])!r} has "
                               f"{reels.shape[0]} cables; {robot.name!r} has {m}: a log of "
                               "another robot")
    moved = np.max(np.linalg.norm(reels - robot.reels, axis=1))
    if moved > SAME:
        raise CalibrationError(f"{target}: the log's reel exits differ from "
                               f"{robot.name!r}'s file by up to {moved * 1e3:.2f} mm: a log "
                               "of another robot, or of the file before an edit; calibrate "
                               "with the file the run used (its run folder keeps a copy, "
                               "robot.yaml)")
    return log, _attachment_order(np.asarray(log["attachments"], dtype=float),
                                  robot.attachments, target)


def calibrate_runs(paths, robot_ref, settings: CalibrationSettings = CalibrationSettings(),
                   measured_poses=None) -> CalibrationRun:
    """Fit `robot_ref`'s geometry (a name or a file) to the encoder lengths of the runs at
    `paths` (run folders, log.npz files, runs/<name>); `measured_poses`: a file of externally
    measured poses (runs/measured_poses.py), or None."""
    from cdpm_drake.kernels.rotation import rotations_from_rpy
    from cdpm_drake.runs.measured_poses import describe, load_measured_poses, measured_sample

    robot_path = resolve_robot_path(robot_ref)
    robot = load_robot(robot_path)
    if not paths:
        raise CalibrationError("give at least one run's log to calibrate from")
    m = robot.num_cables
    measured = [] if measured_poses is None else load_measured_poses(measured_poses)
    for j, pose in enumerate(measured):
        if pose.run > len(paths):
            raise CalibrationError(f"{describe(pose, j)}: run {pose.run}, but "
                                   f"{len(paths)} run(s) given")
    m_index = [0] * len(measured)
    count = 0
    lengths, positions, rotations, tensions, runs, sources = [], [], [], [], [], []
    full = stretch = None
    order0 = None
    for r, path in enumerate(paths):
        log, order = _read(path, robot)
        if order0 is None:
            order0 = order
        elif not np.array_equal(order, order0):
            raise CalibrationError(f"{path}: its cable swaps differ from the first log's; "
                                   "calibrate runs of one swap setting together")
        has_rpy = "rpy" in log
        if full is None:
            full = has_rpy
        elif full != has_rpy:
            raise CalibrationError(f"{path}: one log has the full pose and another not; "
                                   "calibrate runs of one controller together")
        t = np.asarray(log["time"], dtype=float)
        p = np.asarray(log["p"], dtype=float).copy()
        e = np.asarray(log["lengths"], dtype=float)
        keep = select_poses(t, p, e, min_spacing=settings.min_spacing,
                            max_speed=settings.max_speed, max_poses=settings.max_poses)
        mine = [j for j, pose in enumerate(measured) if pose.run == r + 1]
        samples = [measured_sample(measured[j], j, t, p, resolve_latest(Path(path)))
                   for j in mine]
        keep = np.union1d(keep, np.asarray(samples, dtype=int)).astype(int)
        for j, k in zip(mine, samples):
            m_index[j] = count + int(np.searchsorted(keep, k))
        count += keep.size
        rpy = np.asarray(log["rpy"], dtype=float).copy() if has_rpy else None
        # The first pose is the homing pose: where the run started, known (the estimate
        # there is the file's geometry's, off by the very errors the fit is after).
        if "initial_position" in log:
            p[0] = np.asarray(log["initial_position"], dtype=float)
            if has_rpy and "initial_rpy" in log:
                rpy[0] = np.asarray(log["initial_rpy"], dtype=float)
        T = np.asarray(log.get("tension_measured", np.full_like(e, np.nan)), dtype=float)
        has_t = bool(np.all(np.isfinite(T[keep])))
        stretch = has_t if stretch is None else (stretch and has_t)
        lengths.append(e[keep])
        positions.append(p[keep])
        rotations.append(rotations_from_rpy(rpy[keep]) if has_rpy else None)
        tensions.append(T[keep])
        runs.append(np.full(keep.size, r))
        sources.append(str(resolve_latest(Path(path))))
    K = sum(len(x) for x in lengths)
    dof = 6 if full else 3
    if K < 2 or K * (m - dof) < 4 * m:
        raise CalibrationError(
            f"the logs give {K} distinct quasi-static poses (at least "
            f"{settings.min_spacing * 1e3:.0f} mm apart, slower than "
            f"{settings.max_speed:g} m/s); a fit of {4 * m} parameters from {m - dof} "
            f"redundant lengths per pose needs at least {int(np.ceil(4 * m / (m - dof))) + 1}:"
            " run the calibration scenario (cdpm_drake/data/scenarios/calibration_motion.yaml)"
            " or a longer motion through the workspace")
    # The fit runs in the log's cable order (the swapped attachment points), the file is
    # written in the file's.
    result = calibrate(
        robot.reels, robot.attachments[order0], np.vstack(lengths), np.vstack(positions),
        np.concatenate(rotations) if full else None,
        tensions=np.vstack(tensions) if stretch else None, EA=robot.dynamics.EA,
        run=np.concatenate(runs), fit_attachments=settings.fit_attachments and full,
        encoder_std=settings.encoder_std, prior=settings.prior,
        identified_std=settings.identified_std,
        measured=((np.array(m_index), np.array([x.position for x in measured], dtype=float),
                   np.array([x.std for x in measured], dtype=float)) if measured else None))
    inverse = np.argsort(order0)
    result.attachments = result.attachments[inverse]
    result.attachments_std = result.attachments_std[inverse]
    result.attachments_std_in_frame = result.attachments_std_in_frame[inverse]
    described = [(describe(x, j), float(x.std)) for j, x in enumerate(measured)]
    return CalibrationRun(robot=robot, robot_path=robot_path, sources=sources, result=result,
                          poses=K, full_pose=bool(full), stretch=bool(stretch),
                          problems=_problems(robot, result, settings, described),
                          measured_file=str(measured_poses) if measured else "",
                          measured=described)


def _problems(robot, result, settings, measured=()) -> list:
    """Why the fit must not be written: a misfit above the encoders' resolution, a correction
    beyond the prior, nothing identified, a measured pose far from the fitted one."""
    problems = []
    for (what, std), d in zip(measured, result.measured_residual):
        off = float(np.linalg.norm(d))
        if off > settings.max_measured_sigmas * std * np.sqrt(3):
            problems.append(f"{what} is {off * 1e3:.2f} mm from the fitted pose, more than "
                            f"{settings.max_measured_sigmas:g} x its std {std * 1e3:g} mm per "
                            "axis: an outlier (a mistyped coordinate, a time off the "
                            "platform's dwell, another frame); correct or remove it")
    bound = settings.max_residual_sigmas * settings.encoder_std
    for i, rms in enumerate(result.residual_after):
        if rms > bound:
            problems.append(f"cable {i + 1}'s misfit after the fit is {rms * 1e3:.3f} mm RMS, "
                            f"above {settings.max_residual_sigmas:g} x the encoders' "
                            f"{settings.encoder_std * 1e3:g} mm: the model cannot explain its "
                            "lengths (slack, a slipping encoder, another robot), or the "
                            "encoders are noisier than --encoder-std says")
    for name, fitted, file, prior in (
            ("reel", result.reels, robot.reels, settings.prior.reels_std),
            ("attachment", result.attachments, robot.attachments,
             settings.prior.attachments_std)):
        moved = np.linalg.norm(fitted - file, axis=1)
        for i in np.flatnonzero(moved > settings.max_prior_sigmas * prior * np.sqrt(3)):
            problems.append(f"{name} {i + 1} moved {moved[i] * 1e3:.1f} mm, more than "
                            f"{settings.max_prior_sigmas:g} x the prior's {prior * 1e3:g} mm "
                            "per axis allows: check the file (a wrong row or sign) or widen "
                            "the prior")
    # The data must have taught something: some parameter known, in the frame the gauge
    # holds, to better than half of what the file claimed.
    learnt = [np.min(result.reels_std_in_frame) < 0.5 * settings.prior.reels_std,
              np.min(result.offsets_std) < 0.5 * settings.prior.offsets_std]
    if not any(learnt):
        problems.append("the data tell nothing the file did not: " + _smallest(result))
    return problems


def _smallest(result) -> str:
    sv = result.singular_values
    return (f"the data's smallest singular values are {', '.join(f'{s:.3g}' for s in sv[-3:])}"
            f" (largest {sv[0]:.3g}; in units of one encoder_std per mm): more distinct "
            "poses, farther apart")


def report(cal: CalibrationRun, settings: CalibrationSettings) -> list[str]:
    """The fit as lines of text: per cable, the correction, its standard deviation, whether
    the data identify it, and the misfit before and after."""
    res, robot = cal.result, cal.robot
    m = robot.num_cables
    lines = [f"robot {robot.name!r} ({cal.robot_path}): {cal.poses} poses from "
             f"{len(cal.sources)} run(s), {'full pose' if cal.full_pose else 'translation'}"
             f", {'measured tensions for the stretch' if cal.stretch else 'no stretch'}; "
             f"encoder noise {settings.encoder_std * 1e3:g} mm; identified: standard "
             f"deviation <= {settings.identified_std * 1e3:g} mm"]
    lines.append("cable  reel exit moved (mm)       std (mm) in frame  offset (mm)  std   "
                 "misfit before/after (mm RMS)")
    unidentified = set(res.unidentified)
    runs = res.offsets.shape[0]
    for i in range(m):
        d = (res.reels[i] - robot.reels[i]) * 1e3
        reel_star = "" if all(f"reel {i + 1} {a}" not in unidentified for a in "xyz") else "*"
        offset = f"encoder offset {i + 1}" + (" (run 1)" if runs > 1 else "")
        offset_star = "*" if offset in unidentified else ""
        lines.append(
            f"{i + 1:>5}  [{d[0]:+6.2f} {d[1]:+6.2f} {d[2]:+6.2f}]  "
            f"{np.max(res.reels_std[i]) * 1e3:7.2f}{reel_star:1} "
            f"{np.max(res.reels_std_in_frame[i]) * 1e3:7.2f}  "
            f"{res.offsets[0, i] * 1e3:+10.3f}  {res.offsets_std[0, i] * 1e3:5.2f}"
            f"{offset_star:1}  {res.residual_before[i] * 1e3:7.3f} / "
            f"{res.residual_after[i] * 1e3:.3f}")
    if res.fit_attachments:
        for i in range(m):
            d = (res.attachments[i] - robot.attachments[i]) * 1e3
            lines.append(f"attachment {i + 1}: moved [{d[0]:+.2f} {d[1]:+.2f} {d[2]:+.2f}] "
                         f"mm, std {np.max(res.attachments_std[i]) * 1e3:.2f} mm")
    if unidentified:
        names = parameter_names(m, res.fit_attachments, runs)
        lines.append(f"* not identified by the data ({len(unidentified)} of {len(names)} "
                     f"parameters; "
                     f"{_smallest(res)}): their values stay near the file's, their "
                     "uncertainty is written with them")
    for (what, std), d in zip(cal.measured, res.measured_residual):
        lines.append(f"{what}: the fitted pose is {np.linalg.norm(d) * 1e3:.3f} mm from it "
                     f"(its std {std * 1e3:g} mm per axis)")
    if res.gauge == "homing+measured":
        lines.append(f"the base frame's turn is the measured poses' ({cal.measured_file}), "
                     "its position the homing pose's: the reel exits' standard deviations "
                     "are absolute")
    elif not cal.full_pose:
        lines.append("a translating platform's lengths cannot see a turn of the whole base "
                     "frame about the homing pose: it is held at the file's, so the reel "
                     "exits' standard deviations include the file's own uncertainty of it; "
                     "'in frame': relative to that frame, how well the cables are known "
                     "relative to each other (what their distances, and the margins, use);"
                     " --measured-poses fixes it")
    return lines


def calibrated_path(robot_path: Path, out=None) -> Path:
    """Where the calibrated file goes: `out`, else beside the original as
    <name>_calibrated.yaml (a built-in robot's: in the current folder)."""
    if out is not None:
        return Path(out)
    from cdpm_drake.robot import ROBOTS_DIR

    folder = Path(".") if robot_path.parent.resolve() == ROBOTS_DIR.resolve() \
        else robot_path.parent
    return folder / f"{robot_path.stem}_calibrated.yaml"


def calibrated_yaml(cal: CalibrationRun, settings: CalibrationSettings) -> str:
    """The calibrated robot file: the original's fields with the fitted geometry and a
    calibration section stating where it came from and how well it is known."""
    import yaml

    raw = yaml.safe_load(Path(cal.robot_path).read_text())
    res = cal.result

    def rows(a, digits=6):
        return [[round(float(x), digits) for x in row] for row in np.asarray(a)]

    raw["reels"] = rows(res.reels)
    if res.fit_attachments:
        raw["attachments"] = rows(res.attachments)
    raw["calibration"] = {
        "calibrated_from": list(cal.sources),
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "original": str(cal.robot_path),
        "poses": int(cal.poses),
        "encoder_std": float(settings.encoder_std),
        "reels_std": rows(res.reels_std, 7),
        "attachments_std": (rows(res.attachments_std, 7) if res.fit_attachments else
                            [[0.0, 0.0, 0.0]] * cal.robot.num_cables),
        "reels_std_in_frame": rows(res.reels_std_in_frame, 7),
        "attachments_std_in_frame": (rows(res.attachments_std_in_frame, 7)
                                     if res.fit_attachments else
                                     [[0.0, 0.0, 0.0]] * cal.robot.num_cables),
        "encoder_offsets": [round(float(x), 7) for x in res.offsets[0]],
        "encoder_offsets_std": [round(float(x), 7) for x in res.offsets_std[0]],
        "residual_before": [round(float(x), 7) for x in res.residual_before],
        "residual_after": [round(float(x), 7) for x in res.residual_after],
        "not_identified": list(res.unidentified),
    }
    if cal.measured_file:
        raw["calibration"]["measured_poses"] = cal.measured_file
    if not res.fit_attachments and cal.robot.uncertainty is not None:
        # Not fitted: the file's own stated uncertainty of them stands.
        for key in ("attachments_std", "attachments_std_in_frame"):
            raw["calibration"][key] = rows(cal.robot.uncertainty.attachments_std, 7)
    head = (f"# {cal.robot.name}, calibrated by `cdpm calibrate` from {len(cal.sources)} "
            f"run(s) ({cal.poses} poses) on {raw['calibration']['created']}; the original: "
            f"{cal.robot_path}.\n# Its comments are not kept; the calibration section says "
            "what the fit found and how well the data knew it (docs/calibration.md).\n")
    return head + yaml.safe_dump(raw, sort_keys=False, default_flow_style=None, width=100)


MOTION_HEADER = """\
# A calibration motion for robot {name!r} (written by `cdpm calibrate --write-motion`): a
# person (a spring hand) leads the platform slowly through {count} poses spread over its
# workspace box, each held {dwell:g} s, so that `cdpm calibrate` can fit the reel exits and the
# encoder offsets to the redundant cable lengths (docs/calibration.md). The poses keep
# t* >= {floor:g} N (the cables hold the platform there with margin) and the cables unswapped;
# the safety filter stays on. Run it against the robot with `cdpm run` (with the robot's
# plant), or in simulation against a robot that differs from its file (plant: model_error,
# or plant.robot).
"""


def calibration_motion_yaml(robot_ref: str, robot, *, start=None, poses: int = 16,
                            floor: float = 8.0, dwell: float = 2.0, plant: str = "") -> str:
    """A scenario YAML that tours `robot` for a calibration (calibration_tour,
    tour_schedule); `robot_ref` is how the scenario names the robot, `plant` the plant's YAML
    (default: the kinematic plant)."""
    from cdpm_drake.robot.calibration import calibration_tour, tour_schedule

    start = robot.workspace.center if start is None else np.asarray(start, dtype=float)
    points = calibration_tour(robot, start, poses=poses, floor=floor)
    waypoints, times = tour_schedule(points, dwell=dwell)
    lines = [MOTION_HEADER.format(name=robot.name, count=len(points) - 1, dwell=dwell,
                                  floor=floor).rstrip("\n"),
             f"name: calibration_motion",
             f'description: "A slow tour of {len(points) - 1} poses through the workspace, '
             f'each held {dwell:g} s, for cdpm calibrate"',
             f"robot: {robot_ref}",
             f"initial_position: {np.round(start, 4).tolist()}",
             f"duration: {round(times[-1] + 1.0, 1)}",
             "time_step: 0.002",
             "admittance: {mass: 6.25, damping: 6.25}",
             "interference:",
             "  default: {d_l: 0.05, d_u: 0.061, F_u: 2.0, eps: 0.1}",
             "operator: !SpringHandOperator",
             "  waypoints:"]
    lines += [f"    - {[float(x) for x in w]}" for w in waypoints]
    lines += [f"  times: {[float(t) for t in times]}",
              "  stiffness: 60.0",
              "  damping: 6.0",
              "  max_force: 5.0",
              "# The file's geometry is what is uncertain here: a file off by centimetres "
              "leaves lengths",
              "# millimetres to centimetres off its poses, which the model monitor would take "
              "for slack",
              "# (3 mm) or a broken model (10 mm), and the forward kinematics for an "
              "inconsistent robot",
              "# (5 mm and the stretch). These bounds are widened to what a file measured "
              "with a tape may",
              "# be off (the plant's max_length_residual: set it on your robot's plant too); "
              "the motion",
              "# is slow and the hand gentle (5 N at most).",
              "model_monitor: {slack_length: 0.02, fit_tolerance: 0.04}",
              f"plant: {plant or '!SimulatedReels {max_length_residual: 0.04}'}"]
    return "\n".join(lines) + "\n"
