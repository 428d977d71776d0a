"""Externally measured poses for `cdpm calibrate --measured-poses FILE`: the platform's
position measured by a laser tracker or a motion-capture system at a few moments of a
calibration run, in the robot's base frame. They fix the turn of the base frame that a
translating platform's lengths cannot see (robot/calibration.py, measured_gauge).

The file (YAML, read with yaml_load_typed into MeasuredPosesFile):

    poses:
      - {time: 12.0, position: [1.20, 2.05, 1.10], std: 0.0002}   # s in the run's log
      - {index: 14000, position: [2.41, 3.02, 0.95], std: 0.0002}  # or the log's sample
      - {time: 40.5, position: [0.98, 1.50, 1.72], std: 0.0002, run: 2}

Each pose gives either `time` (s, the run's clock: the log's `time`; the nearest sample is
taken) or `index` (the log's sample, 0-based), the measured `position` [x, y, z] (m, base
frame), its `std` (m, one standard deviation per axis) and `run` (which RUN argument, 1..R;
default 1)."""

import dataclasses
import math
import typing
from pathlib import Path

import numpy as np

from cdpm_drake.robot.calibration import CalibrationError

# A measured pose must be held this still, m/s (the platform's speed in the log there): a
# tracker's reading and the log's sample are of slightly different moments.
MAX_MEASURED_SPEED = 0.01


@dataclasses.dataclass
class MeasuredPose:
    # When the pose was measured: the run's time, s (the nearest log sample is taken) ...
    time: typing.Optional[float] = None
    # ... or the log's sample index, 0-based (give one of the two).
    index: typing.Optional[int] = None
    # The platform's measured position [x, y, z], base frame, m.
    position: list[float] = dataclasses.field(default_factory=list)
    # One standard deviation of the measurement, per axis, m.
    std: float = 0.0
    # Which run (the RUN arguments in order, 1..R) it was measured in.
    run: int = 1


@dataclasses.dataclass
class MeasuredPosesFile:
    # The measured poses (at least 2 off one line through the homing pose, or 3 off one line).
    poses: list[MeasuredPose] = dataclasses.field(default_factory=list)


def load_measured_poses(path) -> list[MeasuredPose]:
    """The file's poses, each checked (CalibrationError naming the field and value)."""
    from pydrake.common.yaml import yaml_load, yaml_load_typed

    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"--measured-poses {str(path)!r}: no such file")
    try:
        raw = yaml_load(filename=str(path))
    except Exception as e:
        raise CalibrationError(f"{path}: not valid YAML: {e}") from None
    if not isinstance(raw, dict) or not isinstance(raw.get("poses"), list):
        raise CalibrationError(f"{path}: expected a mapping with a list `poses:` (each "
                               "{time or index, position, std}), got "
                               f"{str(raw)[:80]!r}")
    fields = {f.name for f in dataclasses.fields(MeasuredPose)}
    for j, entry in enumerate(raw["poses"]):
        where = f"{path}: poses[{j}]"
        if not isinstance(entry, dict):
            raise CalibrationError(f"{where} must be a mapping {{time or index, position, "
                                   f"std}}, got {entry!r}")
        unknown = sorted(set(entry) - fields)
        if unknown:
            raise CalibrationError(f"{where}: unknown field(s) {unknown}; valid: "
                                   f"{sorted(fields)}")
        pos = entry.get("position")
        if not (isinstance(pos, list) and len(pos) == 3
                and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                        and math.isfinite(x) for x in pos)):
            raise CalibrationError(f"{where}.position must be [x, y, z] in m, finite "
                                   f"numbers, got {pos!r}")
        std = entry.get("std")
        if isinstance(std, bool) or not isinstance(std, (int, float)) \
                or not (math.isfinite(std) and std > 0):
            raise CalibrationError(f"{where}.std must be a number > 0 (m), got {std!r}")
        if ("time" in entry) == ("index" in entry):
            raise CalibrationError(f"{where}: give exactly one of time (s) and index (the "
                                   f"log's sample), got {sorted(set(entry) & {'time', 'index'})}")
        if "time" in entry and (isinstance(entry["time"], bool) or not isinstance(
                entry["time"], (int, float)) or not math.isfinite(entry["time"])):
            raise CalibrationError(f"{where}.time must be a number (s), got {entry['time']!r}")
        if "index" in entry and (isinstance(entry["index"], bool)
                                 or not isinstance(entry["index"], int) or entry["index"] < 0):
            raise CalibrationError(f"{where}.index must be an integer >= 0, got "
                                   f"{entry['index']!r}")
        run = entry.get("run", 1)
        if isinstance(run, bool) or not isinstance(run, int) or run < 1:
            raise CalibrationError(f"{where}.run must be an integer >= 1, got {run!r}")
    if not raw["poses"]:
        raise CalibrationError(f"{path}: poses is empty")
    return yaml_load_typed(schema=MeasuredPosesFile, filename=str(path)).poses


def measured_sample(pose: MeasuredPose, j: int, times, positions, source) -> int:
    """The log sample of measured pose j (0-based in its file), checked: inside the log, and
    quasi-static there (the log's estimated pose slower than MAX_MEASURED_SPEED)."""
    t = np.asarray(times, dtype=float)
    if pose.index is not None:
        k = int(pose.index)
        if k >= t.size:
            raise CalibrationError(f"measured pose {j + 1}: index {k} is outside the log of "
                                   f"run {pose.run} ({source}: samples 0..{t.size - 1})")
        what = f"index {k}"
    else:
        dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
        if not t[0] - dt / 2 <= pose.time <= t[-1] + dt / 2:
            raise CalibrationError(f"measured pose {j + 1}: time {pose.time:g} s is outside "
                                   f"the log of run {pose.run} ({source}: {t[0]:g} to "
                                   f"{t[-1]:g} s)")
        k = int(np.argmin(np.abs(t - pose.time)))
        what = f"time {pose.time:g} s"
    # The speed about the sample: the platform's net travel over +-0.1 s (a tick's difference
    # would see the encoders' quantisation).
    window = np.flatnonzero(np.abs(t - t[k]) <= 0.1)
    lo, hi = int(window[0]), int(window[-1])
    p = np.asarray(positions, dtype=float)
    speed = (float(np.linalg.norm(p[hi] - p[lo])) / (t[hi] - t[lo])) if hi > lo else 0.0
    if speed > MAX_MEASURED_SPEED:
        raise CalibrationError(f"measured pose {j + 1} ({what}, run {pose.run}): the "
                               f"platform moves at {speed * 1e3:.0f} mm/s there, not "
                               f"quasi-static (at most {MAX_MEASURED_SPEED * 1e3:.0f} mm/s): "
                               "measure where the calibration motion holds still (between a "
                               "waypoint's two times)")
    return k


def describe(pose: MeasuredPose, j: int) -> str:
    when = f"t = {pose.time:g} s" if pose.index is None else f"sample {pose.index}"
    return f"measured pose {j + 1} (run {pose.run}, {when})"
