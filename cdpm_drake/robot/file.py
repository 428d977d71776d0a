"""Robot files: a shipped robot by name (`cdpm_drake/data/robots/`) or a YAML file by path,
read with yaml_load_typed after checks of the raw fields that name the field, the line and
the value (Drake's own messages do not), then validated into a Robot."""

import dataclasses
import logging
import os
from pathlib import Path

# Shipped robot descriptions are package data, so a wheel (not only an editable install) has
# them; the repository's hardware/robots, next to the reel link protocol, links here.
from cdpm_drake.data import ROBOTS_DIR
import numpy as np

from cdpm_drake.robot.model import (Dynamics, GeometryUncertainty, Robot, RobotError,
                                    RobotLimits, Workspace,
                                    as_points, as_vector, is_finite, is_sequence, plain,
                                    validate_dynamics)
from cdpm_drake.robot.schema import (REQUIRED_FIELDS, CablesSchema, CalibrationSchema,
                                     LimitsSchema,
                                     PlatformSchema, ReelDrivesSchema, RobotSchema,
                                     WorkspaceSchema)
from cdpm_drake.robot.statics_checks import frame_warnings, report_statics

# The package's logger, not this module's: `cdpm info` filters it (a filter on a logger
# does not see its children's records) and tests capture it by that name.
_log = logging.getLogger("cdpm_drake.robot")


def robot_names() -> list[str]:
    """Names of the robots shipped with the package."""
    return sorted(p.stem for p in ROBOTS_DIR.glob("*.yaml"))


def is_path_like(name_or_path) -> bool:
    """A .yaml/.yml name or one with a folder in it is a path; anything else is a name."""
    text = str(name_or_path)
    return Path(text).suffix in (".yaml", ".yml") or "/" in text or os.sep in text


def resolve_named_yaml(name_or_path, directory: Path, what: str, error=ValueError) -> Path:
    """A YAML file given by path, or by the name of one shipped in `directory` ("paper_7cable"
    for directory/paper_7cable.yaml). A name resolves to a file (given as a path, or an
    existing file) or to the shipped one, never to a folder: a folder `exp2_interaction/` in
    the current directory does not hide the shipped scenario. `error` is raised naming the
    `what`, the full path tried and the choices."""
    path = Path(name_or_path)
    if is_path_like(name_or_path) or path.is_file():
        if not path.is_file():
            where = "a folder" if path.is_dir() else "does not exist"
            raise error(f"{what} file {str(path)!r} {'is ' if path.is_dir() else ''}{where}"
                        + (f" (tried {str(path.absolute())!r})" if not path.is_absolute()
                           else ""))
        return path
    candidate = directory / f"{name_or_path}.yaml"
    if candidate.is_file():
        return candidate
    shipped = sorted(p.stem for p in directory.glob("*.yaml"))
    raise error(f"unknown {what} {str(name_or_path)!r}; built-in {what}s: {shipped} (or give a "
                f"path to a .yaml file)")


def resolve_robot_path(name_or_path: str | Path) -> Path:
    """A shipped robot's name (e.g. 'paper_7cable') or a path to a YAML file."""
    return resolve_named_yaml(name_or_path, ROBOTS_DIR, "robot", RobotError)


def load_robot(path: str | Path) -> Robot:
    """Load and validate a robot description (a path, or a shipped robot's name)."""
    from pydrake.common.yaml import yaml_load, yaml_load_typed

    path = resolve_robot_path(path)
    src = str(path)
    try:
        raw = yaml_load(filename=src)
    except Exception as e:
        raise RobotError(f"{src}: not valid YAML: {e}") from None
    if not isinstance(raw, dict):
        raise RobotError(f"{src}: expected a mapping with fields {list(REQUIRED_FIELDS)}, "
                         f"got {type(raw).__name__}")
    from cdpm_drake.text import duplicate_yaml_keys, quoted_numbers

    twice = duplicate_yaml_keys(filename=src)
    if twice:  # as a scenario file's: YAML keeps the last and drops the first silently
        raise RobotError(f"{src}: the key {twice[0]}: write each key once (YAML would keep "
                         "the last one and drop the first without a word)")
    # Every number of a robot file is a float or an int: a quoted one ("3.0") is a string
    # Drake's loader would convert without a word; only the name is text.
    quoted = [q for q in quoted_numbers(filename=src) if q[0] != "name"]
    if quoted:
        where, line, text = quoted[0]
        raise RobotError(f"{src}: line {line}: {where} must be a number, got the string "
                         f"{text!r} (quoted); write it without quotes: {text}")
    missing = [k for k in REQUIRED_FIELDS if k not in raw]
    if missing:
        valid = [f.name for f in dataclasses.fields(RobotSchema)]
        unknown = [k for k in raw if k not in valid]
        # A misspelt required field shows up as both: say both, so the typo is obvious.
        from cdpm_drake.text import did_you_mean
        hints = "".join(did_you_mean(k, missing) for k in unknown)
        raise RobotError(f"{src}: missing required field(s) {missing}; a robot file needs "
                         f"{list(REQUIRED_FIELDS)}"
                         + (f" (unknown field(s) {unknown!r} given{hints})" if unknown else ""))
    _check_keys(raw, RobotSchema, "", src)
    if not isinstance(raw["workspace"], dict):
        raise RobotError(f"{src}: workspace must be a mapping with fields lower and upper, "
                         f"got {raw['workspace']!r}")
    for k in ("lower", "upper"):
        if k not in raw["workspace"]:
            raise RobotError(f"{src}: missing required field workspace.{k}")
    _check_keys(raw["workspace"], WorkspaceSchema, "workspace.", src)
    for key, section in (("limits", LimitsSchema), ("platform", PlatformSchema),
                         ("cables", CablesSchema), ("reel_drives", ReelDrivesSchema),
                         ("calibration", CalibrationSchema)):
        if key in raw and not isinstance(raw[key], dict):
            raise RobotError(f"{src}: {key} must be a mapping with fields "
                             f"{[f.name for f in dataclasses.fields(section)]}, got "
                             f"{raw[key]!r}")
        if isinstance(raw.get(key), dict):
            _check_keys(raw[key], section, f"{key}.", src)
    # The dynamic-plant sections likewise (a scalar inertia, a string mass).
    validate_dynamics(_raw_dynamics(raw), src)
    _check_raw_fields(raw, src)
    # Check the geometry on the raw data first: Drake's messages for a non-number or a scalar
    # row do not say which field or cable is wrong.
    as_points(raw["reels"], "reels", src)
    as_points(raw["attachments"], "attachments", src)
    as_vector(raw["workspace"]["lower"], "workspace.lower", src)
    as_vector(raw["workspace"]["upper"], "workspace.upper", src)
    try:
        schema = yaml_load_typed(schema=RobotSchema, filename=src)
    except Exception as e:  # Drake's messages name the field; add the file.
        raise RobotError(f"{src}: {e}") from None
    robot = robot_from_schema(schema, source=src)
    for message in frame_warnings(robot):
        _log.warning("%s", message)
    report_statics(robot)
    if robot.excluded_reasons:
        # Once per load, not per copy: said where the user can see it, since these pairs get
        # no protection from the interference force.
        by_reason: dict[str, list] = {}
        for (i, j), why in sorted(robot.excluded_reasons.items()):
            by_reason.setdefault(why, []).append(f"({i},{j})")
        _log.warning("%s: the interference block skips %d cable pair(s): %s", robot.name,
                     len(robot.excluded_reasons),
                     "; ".join(f"{', '.join(pairs)}: {why}" for why, pairs in by_reason.items()))
    return robot


def _check_raw_fields(raw: dict, src: str) -> None:
    """The scalar and list fields of a robot file's raw YAML, named with their value: Drake's
    typed loader says only "could not convert string to float: 'thin'"."""
    name = raw.get("name")
    if not isinstance(name, str) or not name:
        raise RobotError(f"{src}: name must be a non-empty string, got {plain(name)!r}")
    if "cable_diameter" in raw and (not is_finite(raw["cable_diameter"])
                                    or float(raw["cable_diameter"]) < 0):
        raise RobotError(f"{src}: cable_diameter must be a finite value >= 0 m, got "
                         f"{plain(raw['cable_diameter'])!r}")
    for field, unit in (("max_velocity", "m/s"), ("max_acceleration", "m/s^2"),
                        ("max_reel_speed", "m/s")):
        value = (raw.get("limits") or {}).get(field, 1.0)
        if not is_finite(value) or float(value) <= 0:
            raise RobotError(f"{src}: limits.{field} must be a finite value > 0 {unit}, got "
                             f"{plain(value)!r}")
    pairs = raw.get("ignore_pairs", [])
    if not is_sequence(pairs):
        raise RobotError(f"{src}: ignore_pairs must be a list of cable pairs [i, j], got "
                         f"{plain(pairs)!r}")
    for k, pair in enumerate(pairs):
        if not (is_sequence(pair) and len(pair) == 2
                and all(isinstance(c, int) and not isinstance(c, bool) for c in pair)):
            raise RobotError(f"{src}: ignore_pairs[{k}] must be two cable numbers [i, j], got "
                             f"{plain(pair)!r}")


def _raw_dynamics(raw: dict) -> Dynamics:
    """Dynamics from a robot file's raw YAML (defaults where a field is absent), to check."""
    platform, cables, drives = (raw.get(k) or {} for k in ("platform", "cables", "reel_drives"))
    d = Dynamics()
    return dataclasses.replace(
        d, mass=platform.get("mass", d.mass), inertia=platform.get("inertia", d.inertia),
        handle=platform.get("handle", d.handle), EA=cables.get("EA", d.EA),
        damping=cables.get("damping", d.damping),
        bandwidth=drives.get("bandwidth", d.bandwidth),
        reel_inertia=drives.get("inertia", d.reel_inertia),
        viscous_friction=drives.get("viscous_friction", d.viscous_friction),
        coulomb_friction=drives.get("coulomb_friction", d.coulomb_friction))


def _check_keys(raw: dict, schema, prefix: str, src: str) -> None:
    from cdpm_drake.text import did_you_mean, yaml_line

    valid = [f.name for f in dataclasses.fields(schema)]
    unknown = [k for k in raw if k not in valid]
    if unknown:
        # The first one's line, and the closest valid name of each.
        line = yaml_line(prefix.split(".")[:-1] + [str(unknown[0])], filename=src)
        hints = "".join(did_you_mean(k, valid).replace("'", f"'{prefix}", 1)
                        for k in unknown)
        raise RobotError(f"{src}: {f'line {line}: ' if line else ''}unknown field(s) "
                         f"{[prefix + str(k) for k in unknown]!r}{hints} (valid fields: "
                         f"{[prefix + k for k in valid]})")


def robot_from_schema(schema: RobotSchema, source: str = "<code>") -> Robot:
    lim = schema.limits
    return Robot(
        name=schema.name,
        reels=schema.reels,
        attachments=schema.attachments,
        workspace=Workspace(schema.workspace.lower, schema.workspace.upper),
        limits=RobotLimits(lim.max_velocity, lim.max_acceleration, lim.max_reel_speed),
        cable_diameter=schema.cable_diameter,
        ignore_pairs=tuple(tuple(p) for p in schema.ignore_pairs),
        source=source,
        uncertainty=geometry_uncertainty(schema.calibration, len(schema.reels), source),
        calibration=(dataclasses.asdict(schema.calibration)
                     if schema.calibration.calibrated_from else None),
        dynamics=Dynamics(
            mass=schema.platform.mass, inertia=schema.platform.inertia,
            handle=schema.platform.handle, EA=schema.cables.EA, damping=schema.cables.damping,
            bandwidth=schema.reel_drives.bandwidth, reel_inertia=schema.reel_drives.inertia,
            viscous_friction=schema.reel_drives.viscous_friction,
            coulomb_friction=schema.reel_drives.coulomb_friction),
    )


def geometry_uncertainty(cal, m: int, src: str):
    """A calibrated file's stated uncertainty as a GeometryUncertainty, None where the file
    states none. RobotError naming the field for a bad shape or value."""
    if not any((cal.reels_std, cal.attachments_std, cal.reels_std_in_frame,
                cal.attachments_std_in_frame)):
        return None
    arrays = {}
    for field in ("reels_std", "attachments_std", "reels_std_in_frame",
                  "attachments_std_in_frame"):
        value = getattr(cal, field)
        if not value:
            arrays[field] = np.zeros((m, 3))
            continue
        arr = np.asarray(value, dtype=float)
        if arr.shape != (m, 3) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise RobotError(f"{src}: calibration.{field} must be {m} rows of 3 finite "
                             f"standard deviations >= 0 m (row i: cable i+1), got {value!r}")
        arrays[field] = arr
    # The margins need the cables' uncertainty relative to each other: the in-frame one
    # where the file states it.
    relative = any((cal.reels_std_in_frame, cal.attachments_std_in_frame))
    suffix = "_in_frame" if relative else ""
    return GeometryUncertainty(reels_std=arrays["reels_std" + suffix],
                               attachments_std=arrays["attachments_std" + suffix])
