"""The validated robot: reels, platform attachment points, workspace box, limits, the
dynamic plant's parameters. Plain numpy, no Drake.

All positions are in metres. The base frame is the paper's frame A (reels), the platform
frame is frame B with its origin at the platform centre; the platform only translates, so B
is parallel to A. Cables are numbered 1..m in everything a user sees (files, messages);
arrays are 0-based. The checks of single values (as_points, is_finite, ...) are shared with
the robot file's raw-field checks (file.py).
"""

import dataclasses
import math
import typing

import numpy as np

from cdpm_drake.robot.schema import CablesSchema, PlatformSchema, ReelDrivesSchema


# Two points closer than this are "the same point" (m). Far below any real cable diameter, far
# above round-off for coordinates of a few metres.
SAME_POINT_TOL = 1e-9


class RobotError(ValueError):
    """A robot description is invalid. The message names the file, field and value."""


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
class RobotLimits:
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
    # Centre of mass, platform frame, m: the centre for a robot file; a robot as built
    # (robot/perturb.py) may have it elsewhere.
    com: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
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


# The platform masses a robot file may give, kg: below 10 g no platform carries a handle
# and a force sensor (1e-12 is a unit slip), above 10 t no cable robot of this kind holds it.
MIN_MASS, MAX_MASS = 0.01, 10_000.0


def validate_dynamics(d: Dynamics, src: str) -> Dynamics:
    """The checked Dynamics (arrays as float arrays); RobotError naming field and value."""
    def positive(value, field, unit, allow_zero=False):
        if not is_finite(value) or (float(value) < 0 if allow_zero else float(value) <= 0):
            bound = ">= 0" if allow_zero else "> 0"
            raise RobotError(f"{src}: {field} must be a finite value {bound} {unit}, "
                             f"got {plain(value)!r}")

    positive(d.mass, "platform.mass", "kg")
    if not MIN_MASS <= float(d.mass) <= MAX_MASS:
        raise RobotError(f"{src}: platform.mass must lie in [{MIN_MASS:g}, {MAX_MASS:g}] kg "
                         f"(a platform carries a handle and a force sensor, and cables hold "
                         f"it), got {float(d.mass):g} kg")
    I = d.inertia
    if not (is_sequence(I) and len(I) == 3 and all(is_sequence(r) and len(r) == 3 for r in I)
            and all(is_finite(c) for r in I for c in r)):
        raise RobotError(f"{src}: platform.inertia must be a 3 x 3 matrix of finite numbers "
                         f"in kg m^2, got {plain(I)!r}")
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
    handle = as_vector(d.handle, "platform.handle", src)
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
class GeometryUncertainty:
    """How well the geometry is known (a calibrated file's calibration section): one standard
    deviation per axis of each reel exit (base frame) and attachment point (platform frame),
    (m, 3) m."""

    reels_std: np.ndarray
    attachments_std: np.ndarray

    def cable_std(self) -> np.ndarray:
        """(m,) m: each cable's end points' combined standard deviation, the larger axis of
        each point (a bound on how far the cable's line may sit from the file's)."""
        return np.hypot(np.max(self.reels_std, axis=1), np.max(self.attachments_std, axis=1))


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
    limits: RobotLimits = RobotLimits()
    cable_diameter: float = 0.0
    ignore_pairs: tuple[tuple[int, int], ...] = ()
    source: str = "<code>"
    # Mass, inertia, cable and reel-drive parameters of the dynamic plant.
    dynamics: Dynamics = Dynamics()
    # A calibrated file's stated uncertainty of the geometry; None: not stated.
    uncertainty: typing.Optional[GeometryUncertainty] = None
    # A calibrated file's calibration section as written (schema.CalibrationSchema's fields),
    # for what `cdpm info` says of it; None: a file measured by hand.
    calibration: typing.Optional[dict] = None

    def __post_init__(self):
        reels = as_points(self.reels, "reels", self.source)
        attachments = as_points(self.attachments, "attachments", self.source)
        workspace = self.workspace
        # In code a workspace may also be given as {"lower": ..., "upper": ...} or (lower, upper).
        if isinstance(workspace, dict):
            workspace = Workspace(workspace.get("lower", ()), workspace.get("upper", ()))
        elif isinstance(workspace, (tuple, list)) and len(workspace) == 2:
            workspace = Workspace(*workspace)
        elif not isinstance(workspace, Workspace):
            raise RobotError(f"{self.source}: workspace must be a Workspace, a mapping with "
                             f"lower and upper, or a pair (lower, upper); got {workspace!r}")
        lower = as_vector(workspace.lower, "workspace.lower", self.source)
        upper = as_vector(workspace.upper, "workspace.upper", self.source)
        object.__setattr__(self, "reels", reels)
        object.__setattr__(self, "attachments", attachments)
        object.__setattr__(self, "workspace", Workspace(lower, upper))
        ignore = tuple(tuple(int(k) for k in pair) for pair in self.ignore_pairs)
        object.__setattr__(self, "ignore_pairs", ignore)
        _validate(self)
        object.__setattr__(self, "dynamics", validate_dynamics(self.dynamics, self.source))
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
        uncertainty = self.uncertainty
        if uncertainty is not None:  # each point keeps its own uncertainty
            b_std = uncertainty.attachments_std.copy()
            b_std[[i - 1, j - 1]] = b_std[[j - 1, i - 1]]
            uncertainty = dataclasses.replace(uncertainty, attachments_std=b_std)
        return dataclasses.replace(self, attachments=b, uncertainty=uncertainty,
                                   name=f"{self.name}_swap{i}{j}")

    def describe_pair(self, k: int) -> str:
        i, j = self.pairs[k]
        return f"({i},{j})"


def as_points(value, field: str, source: str) -> np.ndarray:
    if not is_sequence(value):
        raise RobotError(f"{source}: {field} must be a list of [x, y, z] rows in m, one per "
                         f"cable, got {plain(value)!r}")
    rows = list(value)
    for k, row in enumerate(rows):
        if not is_sequence(row):
            raise RobotError(f"{source}: {field} of cable {k + 1} must be [x, y, z] in m, "
                             f"got {plain(row)!r}")
        n = len(row)
        if n != 3:
            raise RobotError(f"{source}: {field} of cable {k + 1} must have 3 coordinates "
                             f"[x, y, z] in m, got {n}: {plain(row)!r}")
        for c in row:
            if not is_finite(c):
                raise RobotError(f"{source}: {field} of cable {k + 1} has a coordinate "
                                 f"{plain(c)!r} that is not a finite number: {plain(row)!r}")
    arr = np.array(rows, dtype=float).reshape(len(rows), 3)
    return arr


def as_vector(value, field: str, source: str) -> np.ndarray:
    if not is_sequence(value):
        raise RobotError(f"{source}: {field} must be [x, y, z] in m, got {plain(value)!r}")
    row = list(value)
    if len(row) != 3:
        raise RobotError(f"{source}: {field} must have 3 coordinates [x, y, z] in m, "
                         f"got {len(row)}: {plain(row)!r}")
    for c in row:
        if not is_finite(c):
            raise RobotError(f"{source}: {field} has a coordinate {plain(c)!r} that is not a "
                             f"finite number: {plain(row)!r}")
    return np.array(row, dtype=float)


def is_sequence(v) -> bool:
    if isinstance(v, (str, bytes, dict)):
        return False
    try:
        len(v)  # a 0-d numpy array has __len__ but raises here
    except TypeError:
        return False
    return True


def is_finite(c) -> bool:
    # YAML 1.1 reads `1e3` as a string, so strings that parse as numbers are numbers (Drake's
    # typed loader agrees); booleans (`yes`, `true`) are not, even though float() takes them.
    if isinstance(c, (bool, np.bool_)):
        return False
    try:
        return math.isfinite(float(c))
    except (TypeError, ValueError):
        return False


def plain(v):
    """v with numpy scalars and arrays turned into plain Python, so `!r` reads like the file."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (list, tuple)):
        return [plain(c) for c in v]
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
        if not is_finite(value) or value < 0:
            raise RobotError(f"{src}: {field} must be a finite value >= 0 m, got {value!r}")
    for field in ("max_velocity", "max_acceleration", "max_reel_speed"):
        value = getattr(robot.limits, field)
        if not is_finite(value) or value <= 0:
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
