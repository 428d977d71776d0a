"""Robot descriptions: reels, platform attachment points, workspace box, limits.

Plain numpy; no Drake import here except for the YAML loader, which is imported lazily so the
math stays testable alone. All positions are in metres. The base frame is the paper's frame A
(reels), the platform frame is frame B with its origin at the platform centre; the platform
only translates, so B is parallel to A.

Cables are numbered 1..m in everything a user sees (files, messages); arrays are 0-based.

Beside it: statics.py, a robot's statics over its workspace (t*, the holding tension, wrench
feasibility), and tension_program.py, t* and tension distributions of any nullspace (Drake's
Clarabel beyond the compiled kernels).
"""


import dataclasses
import logging
import os
import math
from pathlib import Path

import numpy as np

_log = logging.getLogger(__name__)

# Two points closer than this are "the same point" (m). Far below any real cable diameter, far
# above round-off for coordinates of a few metres.
SAME_POINT_TOL = 1e-9

# Shipped robot descriptions are package data, so a wheel (not only an editable install) has
# them; the repository's hardware/robots, next to the reel link protocol, links here.
from cdpm_drake.data import ROBOTS_DIR  # noqa: E402  (re-exported: robot files by name)


class RobotError(ValueError):
    """A robot description is invalid. The message names the file, field and value."""


# --- YAML schema (mutable dataclasses, as yaml_load_typed requires) -------------------------


@dataclasses.dataclass
class WorkspaceSchema:
    # Lower corner of the axis-aligned virtual-wall box, base frame, m.
    lower: list[float] = dataclasses.field(default_factory=list)
    # Upper corner of the box, base frame, m.
    upper: list[float] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class LimitsSchema:
    # Largest platform speed the controller commands, m/s.
    max_velocity: float = 0.5
    # Largest platform acceleration the controller commands, m/s^2.
    max_acceleration: float = 2.0
    # Largest reel (cable) speed the drives accept, m/s of cable.
    max_reel_speed: float = 1.0


# Dynamic-plant sections (optional; only `plant: !DynamicReels` reads them). The defaults are
# for the paper's robot, whose paper gives none of these numbers: each is an estimate for a
# robot of its class, with where it comes from.
_CUBE = 0.30  # m: the attachment points span a 0.3 m cube (hardware/robots/paper_7cable.yaml)


@dataclasses.dataclass
class PlatformSchema:
    # Platform mass, kg. Estimate: a 0.3 m cube frame of 20 mm aluminium profile (12 edges x
    # 0.3 m x ~0.4 kg/m = 1.5 kg) plus the FSE103 sensor, handle and seven tension limiters
    # (~1 kg) near the centre.
    mass: float = 2.5
    # Rotational inertia about the platform centre, platform frame, kg m^2 (3 x 3, symmetric).
    # Estimate: the 1.5 kg frame as 12 thin edges of a 0.3 m cube, 7/18 m_f s^2 per axis
    # (0.0525); the 1 kg at the centre adds nothing.
    inertia: list[list[float]] = dataclasses.field(default_factory=lambda: [
        [0.0525, 0.0, 0.0], [0.0, 0.0525, 0.0], [0.0, 0.0, 0.0525]])
    # The handle point, where the operator's force acts, platform frame, m. Assumed: under
    # the sensor, at the centre of the cube's bottom face.
    handle: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, -0.15])


@dataclasses.dataclass
class CablesSchema:
    # Axial stiffness E A of every cable, N (k_i = EA / L0_i). The robot file's 1.5 mm
    # polyethylene (UHMWPE) braid: area 1.77e-6 m^2 times an effective braid modulus of
    # ~40 GPa (fibre 100 GPa; a braid's is 30-50 GPa) = 70 kN.
    EA: float = 70000.0
    # Viscous damping of each cable's stretch rate, N s/m. Chosen for ~5% of critical damping
    # of the platform's translation on 7 cables of k ~ 28 kN/m (2.5 m long) with 2.5 kg:
    # 0.05 * 2 sqrt(7/3 * 28e3 * 2.5) / (7/3) = 17 N s/m, rounded to 20.
    damping: float = 20.0


@dataclasses.dataclass
class ReelDrivesSchema:
    # Closed-loop bandwidth of each reel's velocity loop, rad/s (first order: time constant
    # 1/bandwidth). 100 rad/s (10 ms) is a typical servo drive's velocity loop (500 Hz command
    # rate); the emulator's default lag is of the same order.
    bandwidth: float = 100.0
    # Reel, gearbox and motor inertia seen at the cable, kg (J / r^2: ~1e-4 kg m^2 reflected
    # through the drum of r = 0.02 m); it turns the loop's bandwidth into a gain K = bandwidth
    # * inertia (N per m/s) that friction acts against.
    inertia: float = 0.25
    # Viscous friction at the cable, N s/m: 1% of the loop gain.
    viscous_friction: float = 0.25
    # Coulomb friction at the cable, N (drum bearings, cable guide). The paper calls the reels'
    # friction considerable; 0.125 N against K = 25 N s/m is a dead band of 5 mm/s.
    coulomb_friction: float = 0.125


@dataclasses.dataclass
class RobotSchema:
    # A short identifier, e.g. paper_7cable.
    name: str = ""
    # a_i: cable exit points at the reels, base frame, m; row i is cable i+1.
    reels: list[list[float]] = dataclasses.field(default_factory=list)
    # b_i: attachment points on the platform, platform frame (origin at its centre), m.
    attachments: list[list[float]] = dataclasses.field(default_factory=list)
    # The virtual wall: an axis-aligned box for the platform centre p, base frame, m.
    workspace: WorkspaceSchema = dataclasses.field(default_factory=WorkspaceSchema)
    # Cable diameter, m (informative: documents the margin that d_l must cover).
    cable_diameter: float = 0.0
    # Controller limits; defaults documented in LimitsSchema.
    limits: LimitsSchema = dataclasses.field(default_factory=LimitsSchema)
    # Cable pairs [i, j] (1-based) that the interference block must skip, e.g. cables that
    # leave one reel exit point and so can never separate.
    ignore_pairs: list[list[int]] = dataclasses.field(default_factory=list)
    # Dynamic-plant sections (plant: !DynamicReels); defaults documented in each schema.
    platform: PlatformSchema = dataclasses.field(default_factory=PlatformSchema)
    cables: CablesSchema = dataclasses.field(default_factory=CablesSchema)
    reel_drives: ReelDrivesSchema = dataclasses.field(default_factory=ReelDrivesSchema)


_REQUIRED = ("name", "reels", "attachments", "workspace")


# --- The validated robot ---------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Workspace:
    """Axis-aligned box for the platform centre, base frame, m."""

    lower: np.ndarray
    upper: np.ndarray

    @property
    def center(self) -> np.ndarray:
        return 0.5 * (self.lower + self.upper)

    def contains(self, p, tol: float = 0.0) -> np.ndarray | bool:
        p = np.asarray(p, dtype=float)
        inside = np.all((p >= self.lower - tol) & (p <= self.upper + tol), axis=-1)
        return bool(inside) if inside.ndim == 0 else inside


@dataclasses.dataclass(frozen=True)
class Limits:
    """Controller limits: platform speed (m/s), acceleration (m/s^2), reel speed (m/s)."""

    max_velocity: float = 0.5
    max_acceleration: float = 2.0
    max_reel_speed: float = 1.0


@dataclasses.dataclass(frozen=True, eq=False)
class Dynamics:
    """What only the dynamic plant needs (defaults and sources: PlatformSchema, CablesSchema,
    ReelDrivesSchema). Platform: mass kg, inertia (3, 3) kg m^2 about the centre and handle
    (3,) m, platform frame. Cables: EA N, damping N s/m. Reel drives: bandwidth rad/s,
    inertia kg, viscous_friction N s/m, coulomb_friction N (all at the cable)."""

    mass: float = PlatformSchema.mass
    inertia: np.ndarray = dataclasses.field(
        default_factory=lambda: np.array(PlatformSchema().inertia))
    handle: np.ndarray = dataclasses.field(
        default_factory=lambda: np.array(PlatformSchema().handle))
    EA: float = CablesSchema.EA
    damping: float = CablesSchema.damping
    bandwidth: float = ReelDrivesSchema.bandwidth
    reel_inertia: float = ReelDrivesSchema.inertia
    viscous_friction: float = ReelDrivesSchema.viscous_friction
    coulomb_friction: float = ReelDrivesSchema.coulomb_friction

    @property
    def dead_band(self) -> float:
        """The reel speed command (m/s of cable) below which a drive at rest does not move:
        its Coulomb friction against its velocity loop's gain, coulomb_friction / (bandwidth
        x inertia) (the drive law of systems/dynamic_plant.py)."""
        return float(self.coulomb_friction) / (float(self.bandwidth) * float(self.reel_inertia))


def _validate_dynamics(d: Dynamics, src: str) -> Dynamics:
    """The checked Dynamics (arrays as float arrays); RobotError naming field and value."""
    def positive(value, field, unit, allow_zero=False):
        if not _finite(value) or (float(value) < 0 if allow_zero else float(value) <= 0):
            bound = ">= 0" if allow_zero else "> 0"
            raise RobotError(f"{src}: {field} must be a finite value {bound} {unit}, "
                             f"got {_show(value)!r}")

    positive(d.mass, "platform.mass", "kg")
    I = d.inertia
    if not (_is_sequence(I) and len(I) == 3 and all(_is_sequence(r) and len(r) == 3 for r in I)
            and all(_finite(c) for r in I for c in r)):
        raise RobotError(f"{src}: platform.inertia must be a 3 x 3 matrix of finite numbers "
                         f"in kg m^2, got {_show(I)!r}")
    I = np.array(I, dtype=float)
    if np.max(np.abs(I - I.T)) > 1e-9 * max(1.0, np.max(np.abs(I))):
        raise RobotError(f"{src}: platform.inertia must be symmetric, got {I.tolist()!r}")
    moments = np.linalg.eigvalsh(I)
    if not moments[0] > 1e-12 * max(1.0, moments[-1]):
        raise RobotError(f"{src}: platform.inertia {I.tolist()!r} kg m^2 is singular or not "
                         f"positive definite (principal moments {moments.tolist()!r}); a rigid "
                         "platform's are all > 0")
    if moments[0] + moments[1] < moments[2] * (1 - 1e-9):
        raise RobotError(f"{src}: platform.inertia {I.tolist()!r} kg m^2 is not a rigid "
                         f"body's: its principal moments {moments.tolist()!r} break the "
                         "triangle inequality I1 + I2 >= I3")
    handle = _as_vector(d.handle, "platform.handle", src)
    positive(d.EA, "cables.EA", "N")
    positive(d.damping, "cables.damping", "N s/m", allow_zero=True)
    positive(d.bandwidth, "reel_drives.bandwidth", "rad/s")
    positive(d.reel_inertia, "reel_drives.inertia", "kg")
    positive(d.viscous_friction, "reel_drives.viscous_friction", "N s/m", allow_zero=True)
    positive(d.coulomb_friction, "reel_drives.coulomb_friction", "N", allow_zero=True)
    I.flags.writeable = False
    handle.flags.writeable = False
    return dataclasses.replace(d, inertia=I, handle=handle)


@dataclasses.dataclass(frozen=True, eq=False)
class Robot:
    """A translational cable robot.

    reels: (m, 3) a_i in the base frame, m. attachments: (m, 3) b_i in the platform frame, m.
    `source` only serves error messages (the file the robot came from).
    """

    name: str
    reels: np.ndarray
    attachments: np.ndarray
    workspace: Workspace
    limits: Limits = Limits()
    cable_diameter: float = 0.0
    ignore_pairs: tuple[tuple[int, int], ...] = ()
    source: str = "<code>"
    # Mass, inertia, cable and reel-drive parameters of the dynamic plant.
    dynamics: Dynamics = Dynamics()

    def __post_init__(self):
        reels = _as_points(self.reels, "reels", self.source)
        attachments = _as_points(self.attachments, "attachments", self.source)
        workspace = self.workspace
        # In code a workspace may also be given as {"lower": ..., "upper": ...} or (lower, upper).
        if isinstance(workspace, dict):
            workspace = Workspace(workspace.get("lower", ()), workspace.get("upper", ()))
        elif isinstance(workspace, (tuple, list)) and len(workspace) == 2:
            workspace = Workspace(*workspace)
        elif not isinstance(workspace, Workspace):
            raise RobotError(f"{self.source}: workspace must be a Workspace, a mapping with "
                             f"lower and upper, or a pair (lower, upper); got {workspace!r}")
        lower = _as_vector(workspace.lower, "workspace.lower", self.source)
        upper = _as_vector(workspace.upper, "workspace.upper", self.source)
        object.__setattr__(self, "reels", reels)
        object.__setattr__(self, "attachments", attachments)
        object.__setattr__(self, "workspace", Workspace(lower, upper))
        ignore = tuple(tuple(int(k) for k in pair) for pair in self.ignore_pairs)
        object.__setattr__(self, "ignore_pairs", ignore)
        _validate(self)
        object.__setattr__(self, "dynamics", _validate_dynamics(self.dynamics, self.source))
        for arr in (reels, attachments, lower, upper):
            arr.flags.writeable = False
        excluded, reasons = _never_separating(self)
        object.__setattr__(self, "excluded_pairs", excluded)
        object.__setattr__(self, "excluded_reasons", reasons)
        i, j = np.triu_indices(self.num_cables, k=1)
        keep = np.array([(a + 1, b + 1) not in excluded for a, b in zip(i, j)], dtype=bool)
        object.__setattr__(self, "_pair_i", i[keep])
        object.__setattr__(self, "_pair_j", j[keep])

    @property
    def num_cables(self) -> int:
        return int(self.reels.shape[0])

    @property
    def pair_index(self) -> tuple[np.ndarray, np.ndarray]:
        """0-based (i, j), i < j, of the pairs the interference block watches, in the order
        (1,2), (1,3), ..., (m-1,m) with excluded pairs left out."""
        return self._pair_i, self._pair_j

    @property
    def pairs(self) -> list[tuple[int, int]]:
        """1-based cable pairs watched by the interference block, in output order."""
        return [(int(a) + 1, int(b) + 1) for a, b in zip(self._pair_i, self._pair_j)]

    @property
    def num_pairs(self) -> int:
        return int(self._pair_i.size)

    def pair_position(self, i: int, j: int) -> int:
        """0-based position of the 1-based pair (i, j) in `pairs`; RobotError if not watched."""
        key = (min(i, j), max(i, j))
        try:
            return self.pairs.index(key)
        except ValueError:
            raise RobotError(
                f"{self.source}: cable pair {key!r} is not a watched pair of robot "
                f"{self.name!r} (cables are numbered 1..{self.num_cables}"
                + (f"; excluded: {sorted(self.excluded_pairs)}" if self.excluded_pairs else "")
                + ")") from None

    def with_swapped_attachments(self, i: int, j: int) -> "Robot":
        """A copy where cables i and j (1-based) trade platform attachment points, as the paper
        does (cables 1 and 3, 5 and 7) to provoke interference."""
        for k in (i, j):
            if not (isinstance(k, (int, np.integer)) and 1 <= k <= self.num_cables):
                raise RobotError(f"{self.source}: cannot swap cable {k!r}: cables are numbered "
                                 f"1..{self.num_cables}")
        b = self.attachments.copy()
        b[[i - 1, j - 1]] = b[[j - 1, i - 1]]
        return dataclasses.replace(self, attachments=b,
                                   name=f"{self.name}_swap{i}{j}")

    def describe_pair(self, k: int) -> str:
        i, j = self.pairs[k]
        return f"({i},{j})"


def _as_points(value, field: str, source: str) -> np.ndarray:
    if not _is_sequence(value):
        raise RobotError(f"{source}: {field} must be a list of [x, y, z] rows in m, one per "
                         f"cable, got {_show(value)!r}")
    rows = list(value)
    for k, row in enumerate(rows):
        if not _is_sequence(row):
            raise RobotError(f"{source}: {field} of cable {k + 1} must be [x, y, z] in m, "
                             f"got {_show(row)!r}")
        n = len(row)
        if n != 3:
            raise RobotError(f"{source}: {field} of cable {k + 1} must have 3 coordinates "
                             f"[x, y, z] in m, got {n}: {_show(row)!r}")
        for c in row:
            if not _finite(c):
                raise RobotError(f"{source}: {field} of cable {k + 1} has a coordinate "
                                 f"{_show(c)!r} that is not a finite number: {_show(row)!r}")
    arr = np.array(rows, dtype=float).reshape(len(rows), 3)
    return arr


def _as_vector(value, field: str, source: str) -> np.ndarray:
    if not _is_sequence(value):
        raise RobotError(f"{source}: {field} must be [x, y, z] in m, got {_show(value)!r}")
    row = list(value)
    if len(row) != 3:
        raise RobotError(f"{source}: {field} must have 3 coordinates [x, y, z] in m, "
                         f"got {len(row)}: {_show(row)!r}")
    for c in row:
        if not _finite(c):
            raise RobotError(f"{source}: {field} has a coordinate {_show(c)!r} that is not a "
                             f"finite number: {_show(row)!r}")
    return np.array(row, dtype=float)


def _is_sequence(v) -> bool:
    if isinstance(v, (str, bytes, dict)):
        return False
    try:
        len(v)  # a 0-d numpy array has __len__ but raises here
    except TypeError:
        return False
    return True


def _finite(c) -> bool:
    # YAML 1.1 reads `1e3` as a string, so strings that parse as numbers are numbers (Drake's
    # typed loader agrees); booleans (`yes`, `true`) are not, even though float() takes them.
    if isinstance(c, (bool, np.bool_)):
        return False
    try:
        return math.isfinite(float(c))
    except (TypeError, ValueError):
        return False


def _show(v):
    """v with numpy scalars and arrays turned into plain Python, so `!r` reads like the file."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (list, tuple)):
        return [_show(c) for c in v]
    return v


def _validate(robot: Robot) -> None:
    src = robot.source
    m = robot.reels.shape[0]
    if robot.attachments.shape[0] != m:
        raise RobotError(f"{src}: reels has {m} rows but attachments has "
                         f"{robot.attachments.shape[0]}: each cable needs one reel and one "
                         "attachment point")
    if m < 3:
        raise RobotError(f"{src}: reels has {m} cables; a translating platform needs at "
                         "least 3")
    if not robot.name or not isinstance(robot.name, str):
        raise RobotError(f"{src}: name must be a non-empty string, got {robot.name!r}")
    lo, hi = robot.workspace.lower, robot.workspace.upper
    for axis, name in enumerate("xyz"):
        if not lo[axis] < hi[axis]:
            raise RobotError(
                f"{src}: workspace is empty or inverted along {name}: lower[{axis}] = "
                f"{float(lo[axis])!r} m is not below upper[{axis}] = {float(hi[axis])!r} m")
    for field, value in (("cable_diameter", robot.cable_diameter),):
        if not _finite(value) or value < 0:
            raise RobotError(f"{src}: {field} must be a finite value >= 0 m, got {value!r}")
    for field in ("max_velocity", "max_acceleration", "max_reel_speed"):
        value = getattr(robot.limits, field)
        if not _finite(value) or value <= 0:
            raise RobotError(f"{src}: limits.{field} must be a finite value > 0, got {value!r}")
    for pair in robot.ignore_pairs:
        if len(pair) != 2 or pair[0] == pair[1] or not all(1 <= k <= m for k in pair):
            raise RobotError(f"{src}: ignore_pairs entry {list(pair)!r} must name two "
                             f"different cables in 1..{m}")
    ignored = {(min(p), max(p)) for p in robot.ignore_pairs}
    for i in range(m):
        for j in range(i + 1, m):
            if (np.linalg.norm(robot.reels[i] - robot.reels[j]) <= SAME_POINT_TOL
                    and (i + 1, j + 1) not in ignored):
                raise RobotError(
                    f"{src}: reels of cables {i + 1} and {j + 1} are at the same point "
                    f"{robot.reels[i].tolist()!r}; if the robot really leads both cables "
                    f"through one exit point, add [{i + 1}, {j + 1}] to ignore_pairs")


def _never_separating(robot: Robot) -> tuple[frozenset, dict]:
    """Pairs skipped by the interference block: listed in ignore_pairs, or sharing a platform
    attachment point (their distance is 0 at the platform whatever the pose)."""
    reasons = {}
    for pair in robot.ignore_pairs:
        reasons[(min(pair), max(pair))] = "listed in ignore_pairs"
    m = robot.num_cables
    for i in range(m):
        for j in range(i + 1, m):
            key = (i + 1, j + 1)
            if key in reasons:
                continue
            if np.linalg.norm(robot.attachments[i] - robot.attachments[j]) <= SAME_POINT_TOL:
                reasons[key] = "both cables end at the same platform point, so they always meet"
    return frozenset(reasons), reasons


# --- Loading ---------------------------------------------------------------------------------


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
        raise RobotError(f"{src}: expected a mapping with fields {list(_REQUIRED)}, "
                         f"got {type(raw).__name__}")
    missing = [k for k in _REQUIRED if k not in raw]
    if missing:
        valid = [f.name for f in dataclasses.fields(RobotSchema)]
        unknown = [k for k in raw if k not in valid]
        # A misspelt required field shows up as both: say both, so the typo is obvious.
        from cdpm_drake.text import did_you_mean
        hints = "".join(did_you_mean(k, missing) for k in unknown)
        raise RobotError(f"{src}: missing required field(s) {missing}; a robot file needs "
                         f"{list(_REQUIRED)}"
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
                         ("cables", CablesSchema), ("reel_drives", ReelDrivesSchema)):
        if key in raw and not isinstance(raw[key], dict):
            raise RobotError(f"{src}: {key} must be a mapping with fields "
                             f"{[f.name for f in dataclasses.fields(section)]}, got "
                             f"{raw[key]!r}")
        if isinstance(raw.get(key), dict):
            _check_keys(raw[key], section, f"{key}.", src)
    # The dynamic-plant sections likewise (a scalar inertia, a string mass).
    _validate_dynamics(_raw_dynamics(raw), src)
    _check_raw_fields(raw, src)
    # Check the geometry on the raw data first: Drake's messages for a non-number or a scalar
    # row do not say which field or cable is wrong.
    _as_points(raw["reels"], "reels", src)
    _as_points(raw["attachments"], "attachments", src)
    _as_vector(raw["workspace"]["lower"], "workspace.lower", src)
    _as_vector(raw["workspace"]["upper"], "workspace.upper", src)
    try:
        schema = yaml_load_typed(schema=RobotSchema, filename=src)
    except Exception as e:  # Drake's messages name the field; add the file.
        raise RobotError(f"{src}: {e}") from None
    robot = robot_from_schema(schema, source=src)
    for message in frame_warnings(robot):
        _log.warning("%s", message)
    _report_statics(robot)
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


def frame_warnings(robot: "Robot") -> list[str]:
    """The faces of the workspace box that reach beyond the reels' frame, in words: past the
    last reel exit along x or y, or above the highest one, every cable pulls the platform
    back (or down), so nothing holds it there. Below the lowest exit is where a suspended
    robot's platform hangs (gravity pulls it down, the cables up): not a warning."""
    lo, hi = robot.workspace.lower, robot.workspace.upper
    a_lo, a_hi = robot.reels.min(axis=0), robot.reels.max(axis=0)
    out = []
    for axis, name in enumerate("xyz"):
        if axis < 2 and lo[axis] < a_lo[axis] - SAME_POINT_TOL:
            out.append(f"{robot.name}: the workspace box's lower {name} face, workspace.lower"
                       f"[{axis}] = {_show(lo[axis])!r} m, lies beyond the reels' frame: no "
                       f"reel exit is at {name} <= {_show(lo[axis])!r} m (the lowest at "
                       f"{_show(a_lo[axis])!r} m), so there every cable pulls the platform "
                       f"back along +{name} and nothing holds it")
        if hi[axis] > a_hi[axis] + SAME_POINT_TOL:
            pull = "down (with its weight)" if axis == 2 else f"back along -{name}"
            out.append(f"{robot.name}: the workspace box's upper {name} face, workspace.upper"
                       f"[{axis}] = {_show(hi[axis])!r} m, lies beyond the reels' frame: no "
                       f"reel exit is at {name} >= {_show(hi[axis])!r} m (the highest at "
                       f"{_show(a_hi[axis])!r} m), so there every cable pulls the platform "
                       f"{pull} and nothing holds it")
    return out


# Statics checked on load: the level platform (platform.mass at its centre) held with every
# cable >= STATICS_FLOOR N on an STATICS_GRID^3 grid of the workspace box. A robot whose box is
# held on less than STATICS_WARN_SHARE of it gets a warning naming the share and its likely
# cause. About 5 ms for 7 or 8 cables (kernels/tension.py's compiled closed forms), once per robot
# geometry and process.
STATICS_FLOOR = 5.0
STATICS_GRID = 11
STATICS_WARN_SHARE = 0.5
# A point platform held on this much more of the box than the real one: the moment balance
# (the attachment points) is what fails.
_MOMENT_BLAME = 0.25
# Points per axis of the point platform's grid (Clarabel per point, ~0.5 ms: only computed
# for a robot that gets the warning).
_POINT_GRID = 5
_STATICS: dict = {}
_AXES = ("force along x", "force along y", "force along z", "moment about x",
         "moment about y", "moment about z")


def _statics_entry(robot: "Robot"):
    """(statics.Statics, warnings) of a robot, computed once per geometry and mass."""
    from cdpm_drake.robot.statics import workspace_statics

    key = (robot.reels.tobytes(), robot.attachments.tobytes(), robot.workspace.lower.tobytes(),
           robot.workspace.upper.tobytes(), robot.dynamics.mass, robot.name)
    if key not in _STATICS:
        statics = workspace_statics(robot, STATICS_FLOOR, STATICS_GRID)
        _STATICS[key] = (statics, tuple(statics_warnings(robot, statics)))
    return _STATICS[key]


def robot_statics(robot: "Robot"):
    """statics.Statics of the robot's level platform (cached per geometry and mass)."""
    return _statics_entry(robot)[0]


def describe_wrench(direction) -> str:
    """The largest components of a unit wrench direction [force; moment], in words."""
    d = np.asarray(direction, dtype=float)
    order = np.argsort(-np.abs(d))
    parts = [_AXES[k] for k in order if abs(d[k]) >= 0.3 * abs(d[order[0]])]
    return " and ".join(parts[:2])


def statics_warnings(robot: "Robot", statics, *, grid: str | None = None, base=None,
                     base_share: float | None = None) -> list[str]:
    """What is wrong with a robot's statics, in words (empty when its box is mostly held).
    `grid` names the grid of `statics.share` (default: its n x n x n grid). `base` is the
    robot before its cable swaps (a scenario's, or `cdpm info --swaps`) and `base_share` its
    share on the same grid: when it alone is held on most of the box, the swaps are the
    cause, not the robot file."""
    out = []
    n = statics.n
    grid = f"{n}x{n}x{n} grid" if grid is None else grid
    m = robot.num_cables
    if m < 6:
        # Too few cables for six equations: the rank and the share only restate that.
        return [f"{robot.name}: {m} cables cannot hold the platform against all six force and "
                f"moment components (wrench matrix rank {statics.rank} at the workspace "
                "centre): a free platform would turn; the kinematic plant, and plant: "
                "!DynamicReels {lock_rotation: true}, model one that only translates"]
    if statics.unreachable is not None:
        more = 6 - statics.rank - 1
        out.append(f"{robot.name}: the wrench matrix has rank {statics.rank} < 6 at the "
                   f"workspace centre {robot.workspace.center.tolist()!r} m: no cable tensions "
                   f"produce a {describe_wrench(statics.unreachable)} there"
                   + (f" (nor {more} more wrench direction(s))" if more else "")
                   + ", so the platform cannot resist one: the cables' lines of action leave "
                   "it free to turn or slide")
    if statics.share < STATICS_WARN_SHARE:
        from cdpm_drake.robot.statics import point_platform_share

        if base is not None and base_share is not None and base_share >= STATICS_WARN_SHARE:
            # The paper swaps cables to provoke interference; the swapped attachment points
            # balance the moments worse. The robot file is not at fault.
            swapped = [f"{i + 1}-{j + 1}" for i, j in _swapped_cables(base, robot)]
            cause = (f"the swapped cables ({', '.join(swapped)}) are the cause: robot "
                     f"{base.name!r} without the swaps is held on {100 * base_share:.0f} % of "
                     "it")
        else:
            point = point_platform_share(robot, statics.floor, n=_POINT_GRID,
                                         mass=statics.mass)
            where = (f"{100 * point:.0f} % of the box (a coarser {_POINT_GRID}x{_POINT_GRID}"
                     f"x{_POINT_GRID} grid)")
            cause = ("the moment balance fails: a point platform (forces only) would be "
                     f"held on {where}, so the attachment points are the likely cause"
                     if point - statics.share >= _MOMENT_BLAME else
                     f"a point platform (forces only) would be held on {where} too, so the "
                     "reels cannot hold the platform there: the box reaches beyond "
                     "what the reels' layout supports")
        out.append(f"{robot.name}: the cables hold the level platform ({statics.mass:g} kg at "
                   f"its centre) with every cable >= {statics.floor:g} N on only "
                   f"{100 * statics.share:.0f} % of the workspace box ({grid}); {cause}")
    return out


def _swapped_cables(base: "Robot", robot: "Robot") -> list[tuple[int, int]]:
    """The 0-based cable pairs whose attachment points trade places from `base` to `robot`
    (each cable once, in order); a cable that moved otherwise is left out."""
    moved = [i for i in range(base.num_cables)
             if not np.array_equal(base.attachments[i], robot.attachments[i])]
    pairs = []
    for i in moved:
        for j in moved:
            if i < j and np.array_equal(base.attachments[i], robot.attachments[j]) \
                    and np.array_equal(base.attachments[j], robot.attachments[i]):
                pairs.append((i, j))
    return pairs


def _report_statics(robot: "Robot") -> None:
    """Loading a robot says its statics: at INFO level always, as warnings when bad."""
    statics, warnings = _statics_entry(robot)
    n = statics.n
    _log.info("%s: wrench matrix rank %d at the workspace centre; level platform (%g kg) held "
              "with every cable >= %g N on %.1f %% of the workspace box (%dx%dx%d grid)",
              robot.name, statics.rank, statics.mass, statics.floor, 100 * statics.share,
              n, n, n)
    for message in warnings:
        _log.warning("%s", message)


def _check_raw_fields(raw: dict, src: str) -> None:
    """The scalar and list fields of a robot file's raw YAML, named with their value: Drake's
    typed loader says only "could not convert string to float: 'thin'"."""
    name = raw.get("name")
    if not isinstance(name, str) or not name:
        raise RobotError(f"{src}: name must be a non-empty string, got {_show(name)!r}")
    if "cable_diameter" in raw and (not _finite(raw["cable_diameter"])
                                    or float(raw["cable_diameter"]) < 0):
        raise RobotError(f"{src}: cable_diameter must be a finite value >= 0 m, got "
                         f"{_show(raw['cable_diameter'])!r}")
    for field, unit in (("max_velocity", "m/s"), ("max_acceleration", "m/s^2"),
                        ("max_reel_speed", "m/s")):
        value = (raw.get("limits") or {}).get(field, 1.0)
        if not _finite(value) or float(value) <= 0:
            raise RobotError(f"{src}: limits.{field} must be a finite value > 0 {unit}, got "
                             f"{_show(value)!r}")
    pairs = raw.get("ignore_pairs", [])
    if not _is_sequence(pairs):
        raise RobotError(f"{src}: ignore_pairs must be a list of cable pairs [i, j], got "
                         f"{_show(pairs)!r}")
    for k, pair in enumerate(pairs):
        if not (_is_sequence(pair) and len(pair) == 2
                and all(isinstance(c, int) and not isinstance(c, bool) for c in pair)):
            raise RobotError(f"{src}: ignore_pairs[{k}] must be two cable numbers [i, j], got "
                             f"{_show(pair)!r}")


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
        limits=Limits(lim.max_velocity, lim.max_acceleration, lim.max_reel_speed),
        cable_diameter=schema.cable_diameter,
        ignore_pairs=tuple(tuple(p) for p in schema.ignore_pairs),
        source=source,
        dynamics=Dynamics(
            mass=schema.platform.mass, inertia=schema.platform.inertia,
            handle=schema.platform.handle, EA=schema.cables.EA, damping=schema.cables.damping,
            bandwidth=schema.reel_drives.bandwidth, reel_inertia=schema.reel_drives.inertia,
            viscous_friction=schema.reel_drives.viscous_friction,
            coulomb_friction=schema.reel_drives.coulomb_friction),
    )
