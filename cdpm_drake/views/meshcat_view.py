"""A 3D view of the CDPM in Drake's Meshcat: live while a run goes, or as an HTML replay.

The scene, in the base frame A (m): the frame (the box spanned by the reels) and the reels, the
workspace box (wireframe), the platform (a box), one cylinder per cable from its reel a_i to its
attachment p + b_i coloured by the distance to its nearest cable (red at or below d_l, red to
orange inside the band (d_l, d_u], grey above d_u: the interfering pair is red, as in the paper's
Fig. 9), and the forces from the platform as arrows (blue measured F_H, black interference F_int,
red resultant F_d, as in Fig. 12; purple the safety filter's kinetostatic cue F_kin), FORCE_SCALE = 0.25 m long per N by default (1 N reaches out of
the paper's 0.3 m platform); the scale is written in the scene. Each reel carries its cable's
number (1..m) and a clock shows the simulated time (s). The text is flat geometry facing the
default camera, which frames the whole robot (camera_pose).

Everything that moves is posed by a transform, a scale or a visibility flag, never by
re-sending geometry, because those three are what a Meshcat recording can animate; the same
`draw` therefore serves the live view and the replay of `save_replay_html`. A cable is a unit
cylinder along z, posed at its reel and scaled along z to its length; each cable has one
cylinder per colour level and only the one of its current level is visible. `draw` only sends
what changed and costs a few dozen Meshcat messages.

Scene paths use 1-based cable numbers (`/cdpm/cables/cable_3`, `/cdpm/labels/cable_3`).
"""

import functools

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from pydrake.geometry import (Box, Cylinder, Meshcat, MeshcatCone, MeshcatParams, Rgba,
                              Sphere)
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

# Colour levels of a cable: 0 = red (d <= d_l), 1..LEVELS-2 = red to orange across the band
# (d_l, d_u] where the pair's force is on, LEVELS-1 = grey (d > d_u, force off).
LEVELS = 6
RED = (1.0, 0.0, 0.0)
ORANGE = (1.0, 0.6, 0.0)
GREY = (0.55, 0.55, 0.55)
# A slack cable (dynamic plant): light, translucent grey, thinner, over any distance colour.
SLACK_RGBA = (0.85, 0.85, 0.85, 0.35)
FORCE_RGBA = {"F_H": (0.0, 0.2, 1.0, 1.0), "F_int": (0.05, 0.05, 0.05, 1.0),
              "F_d": (0.9, 0.0, 0.0, 1.0),
              # The kinetostatic cue (the safety filter, beyond the paper): its own arrow.
              "F_kin": (0.55, 0.1, 0.75, 1.0)}
# Used when a log has no logistic parameters (interference disabled): the paper's experiment 1
# band, so the colours still say how close the cables came.
DEFAULT_D_L = 0.050  # m
DEFAULT_D_U = 0.061  # m
# Below this a force (N) or a cable (m) has no direction worth drawing.
_TINY = 1e-9
# An arrow is a unit-length shaft + head along z, scaled along z to its length.
_HEAD_FRACTION = 0.2
# m of arrow per N of force: 1 N is 0.25 m, longer than the paper's platform half-size (0.15 m),
# so an arrow of the forces these scenarios use (F_u 2-3 N, a hand's 1-5 N) reaches well out.
FORCE_SCALE = 0.25
# The default camera: Meshcat's own (its meshcat.js creates a perspective camera of 75 deg
# vertical field of view), and the narrowest window (width / height) it must frame the robot
# in.
CAMERA_FOV = 75.0
CAMERA_MIN_ASPECT = 4.0 / 3.0
# From the robot's centre towards the camera: in front (-y), to the left (-x), above (+z).
CAMERA_DIRECTION = np.array([-0.45, -1.0, 0.5]) / np.linalg.norm([-0.45, -1.0, 0.5])
# Text height as a share of the robot's size (the diagonal of the reels' box).
_TEXT_HEIGHT = 0.035
TEXT_RGBA = (0.08, 0.08, 0.12, 1.0)
# The clock: "t = " then CLOCK_SLOTS characters, each slot able to show any of CLOCK_GLYPHS
# (visibility flags, which a recording can animate), left-aligned: "t = 12.34 s".
CLOCK_GLYPHS = "0123456789.s"
CLOCK_SLOTS = 9  # "9999.99 s"


# --- Pure math (numpy) ------------------------------------------------------------------------


def pair_levels(pair_distances, d_l, d_u, num_levels: int = LEVELS) -> np.ndarray:
    """Colour level of each pair (0 red .. num_levels-1 grey) from its distance (m) and its
    band [d_l, d_u] (m, scalars or one per pair): 0 at d <= d_l, num_levels-1 at d > d_u, and
    1..num_levels-2 across (d_l, d_u] in equal steps. NaN distances count as far."""
    d = np.asarray(pair_distances, dtype=float).reshape(-1)
    d_l = np.broadcast_to(np.asarray(d_l, dtype=float), d.shape)
    d_u = np.broadcast_to(np.asarray(d_u, dtype=float), d.shape)
    s = (d - d_l) / (d_u - d_l)
    inner = 1 + np.minimum(np.floor(s * (num_levels - 2)), num_levels - 3)
    level = np.where(s <= 0, 0, np.where(s <= 1, inner, num_levels - 1))
    return np.where(np.isnan(d), num_levels - 1, level).astype(int)


def cable_levels(pair_distances, pairs, num_cables: int, d_l, d_u,
                 num_levels: int = LEVELS) -> np.ndarray:
    """Colour level of each cable: the lowest (closest) level of the pairs it belongs to;
    `pairs` are 1-based (P, 2); cables in no pair are grey. Returns (num_cables,) ints."""
    level = np.full(num_cables, num_levels - 1, dtype=int)
    pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
    if len(pairs):
        pl = pair_levels(pair_distances, d_l, d_u, num_levels)
        np.minimum.at(level, pairs[:, 0] - 1, pl)
        np.minimum.at(level, pairs[:, 1] - 1, pl)
    return level


def level_rgb(level: int, num_levels: int = LEVELS) -> tuple[float, float, float]:
    """RGB of a colour level: red, then from red towards orange in steps (level 1 is already
    distinct from red), then grey."""
    if level <= 0:
        return RED
    if level >= num_levels - 1:
        return GREY
    f = level / (num_levels - 2)
    return tuple(float(r + f * (o - r)) for r, o in zip(RED, ORANGE))


def _box_segments(lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """Start and end points (3, 12) of the edges of an axis-aligned box, m."""
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    corner = [np.where([(n >> a) & 1 for a in range(3)], hi, lo) for n in range(8)]
    starts, ends = [], []
    for n in range(8):
        for a in range(3):
            if not (n >> a) & 1:
                starts.append(corner[n])
                ends.append(corner[n | (1 << a)])
    return np.array(starts).T.copy(), np.array(ends).T.copy()


def view_direction(forces=None, elevation: float = 27.0, azimuths: int = 16) -> np.ndarray:
    """Unit vector from the robot towards the camera. With forces (N, (T, 3), e.g. the F_H,
    F_int, F_d of a log) the one of `azimuths` directions (every 360 / azimuths deg from +x)
    at `elevation` (deg) that sees them most side-on (largest mean projected length |F x c|),
    so that the arrows show their length; of equally good ones the nearest in azimuth to
    CAMERA_DIRECTION. Without forces, CAMERA_DIRECTION."""
    f = None if forces is None else np.asarray(forces, dtype=float).reshape(-1, 3)
    if f is not None:
        f = f[np.all(np.isfinite(f), axis=1)]
    if f is None or not np.any(f):
        return CAMERA_DIRECTION.copy()
    e = np.radians(elevation)
    usual = np.arctan2(CAMERA_DIRECTION[1], CAMERA_DIRECTION[0])
    angles = 2 * np.pi * np.arange(azimuths) / azimuths
    # Nearest to the usual view first, so that argmax keeps it among ties.
    angles = sorted(angles, key=lambda a: abs(np.angle(np.exp(1j * (a - usual)))))
    candidates = [np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
                  for a in angles]
    seen = [np.linalg.norm(np.cross(f, c), axis=1).mean() for c in candidates]
    return candidates[int(np.argmax(np.round(seen, 9)))]


def camera_pose(reels, fov: float = CAMERA_FOV, aspect: float = CAMERA_MIN_ASPECT,
                direction=CAMERA_DIRECTION) -> tuple[np.ndarray, np.ndarray]:
    """Camera position and target (m, base frame) that frame the whole robot: the target is
    the centre of the reels' box, and the camera is as far along `direction` as it takes for
    the box's bounding sphere to fit, with 5 % to spare, in a perspective view of vertical
    field of view `fov` (deg) in a window `aspect` (width / height) or wider."""
    reels = np.asarray(reels, dtype=float).reshape(-1, 3)
    lo, hi = reels.min(axis=0), reels.max(axis=0)
    target = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)
    half_v = np.radians(fov) / 2.0
    half = min(half_v, np.arctan(aspect * np.tan(half_v)))
    direction = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    return target + 1.05 * radius / np.sin(half) * direction, target


def facing_rotation(eye, target) -> RotationMatrix:
    """Orientation of flat text seen from eye looking at target: x to the viewer's right, y up
    (as close to +z as the view allows), z towards the viewer."""
    view = np.asarray(target, dtype=float) - np.asarray(eye, dtype=float)
    view /= np.linalg.norm(view)
    right = np.cross(view, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:  # looking straight down or up
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, view)
    return RotationMatrix(np.column_stack([right, up, -view]))


# Text: DejaVu Sans Mono (shipped with matplotlib) rasterised once per string, each run of lit
# pixels a rectangle, so that Meshcat draws it with a plain triangle mesh (which the HTML
# replay keeps and a recording can show or hide).
_TEXT_ROWS = 24            # pixel rows per line of text
_MONO_ADVANCE = 0.6021     # DejaVu Sans Mono's advance width, em (1233 / 2048)
_EM = 0.75 * _TEXT_ROWS    # px: the em of the cells (advance = _MONO_ADVANCE em)


@functools.lru_cache(maxsize=256)
def text_bitmap(text: str) -> np.ndarray:
    """(rows, cols) bool pixels of a line of text in the monospaced font, cell k spanning
    columns [k, k + 1) * _cell_px()."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cols = max(1, int(np.ceil(len(text) * _MONO_ADVANCE * _EM * 1.25)) + 1)
    fig = Figure(figsize=(cols / 100.0, _TEXT_ROWS / 100.0), dpi=100)
    fig.text(0.0, 0.22, text, fontsize=_EM * 0.9, family="DejaVu Sans Mono", ha="left",
             va="baseline", color="black")
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    gray = np.asarray(canvas.buffer_rgba())[..., :3].mean(axis=2)
    return gray < 128


def text_mesh(text: str, height: float) -> tuple[np.ndarray, np.ndarray]:
    """A flat triangle mesh of a line of text `height` m high in its own x-y plane (x along the
    text, y up, origin at its left end, halfway up): vertices (3, N) m and faces (3, M)."""
    lit = text_bitmap(text)
    rows, _ = lit.shape
    pixel = height / rows
    rects, open_runs = [], {}
    for r in range(rows + 1):
        runs = set()
        if r < rows:
            row = np.concatenate([[False], lit[r], [False]])
            edges = np.flatnonzero(np.diff(row.astype(int)))
            runs = set(zip(edges[::2], edges[1::2]))
        # A run that continues from the row above extends its rectangle downwards.
        for run in list(open_runs):
            if run not in runs:
                rects.append((*run, open_runs.pop(run), r))
        for run in runs:
            open_runs.setdefault(run, r)
    vertices, faces = [], []
    for c0, c1, r0, r1 in rects:
        n = len(vertices)
        x0, x1 = c0 * pixel, c1 * pixel
        y0, y1 = (rows / 2 - r1) * pixel, (rows / 2 - r0) * pixel
        vertices += [(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)]
        faces += [(n, n + 1, n + 2), (n, n + 2, n + 3)]
    if not vertices:
        return np.zeros((3, 0)), np.zeros((3, 0), dtype=np.int32)
    return (np.asarray(vertices, dtype=float).T.copy(order="F"),
            np.asarray(faces, dtype=np.int32).T.copy(order="F"))


def _cell_px() -> float:
    """Width of one character of text_bitmap, px (the font is drawn at 1.25 _EM)."""
    return _MONO_ADVANCE * _EM * 1.25


def clock_text(sim_time: float) -> str:
    """What the clock shows after "t = " for sim_time (s): e.g. "12.34 s", clipped to
    0 .. 9999.99 s."""
    return f"{min(max(float(sim_time), 0.0), 9999.99):.2f} s"


# --- The view ---------------------------------------------------------------------------------


def make_meshcat(port: int | None = None) -> Meshcat:
    """A Meshcat server on the loopback interface; port None takes the first free one from
    7000, 0 an ephemeral one. Open `meshcat.web_url()` in a browser."""
    params = MeshcatParams()
    params.host = "localhost"
    params.port = port
    return Meshcat(params)


def _points(value, name: str, rows: int | None = None) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3 or (rows is not None and arr.shape[0] != rows):
        want = f"({rows}, 3)" if rows is not None else "(m, 3)"
        raise ValueError(f"{name} must be an array of shape {want} in m, got shape "
                         f"{arr.shape!r}: {value!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has non-finite entries: {value!r}")
    return arr


def _vector(value, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (3,):
        raise ValueError(f"{name} must be a 3-vector [x, y, z], got {value!r}")
    return arr


class CdpmMeshcatView:
    """Draws one CDPM pose with its forces in a Meshcat scene under `prefix`.

    reels (m, 3) a_i and workspace corners (3,) in the base frame, m; attachments (m, 3) b_i in
    the platform frame, m; pairs (P, 2) the 1-based cable pairs of the pair_distances columns;
    force_scale in m of arrow per N (FORCE_SCALE); d_l, d_u (m, scalars or one per pair) the
    default colour band, overridden per call by draw's d_l, d_u.
    """

    def __init__(self, meshcat: Meshcat, reels, attachments, workspace_lower, workspace_upper,
                 pairs, force_scale: float = FORCE_SCALE, d_l=DEFAULT_D_L, d_u=DEFAULT_D_U,
                 prefix: str = "/cdpm", cable_radius: float = 0.01,
                 set_camera: bool = True, view_direction=CAMERA_DIRECTION):
        self.meshcat = meshcat
        self.reels = _points(reels, "reels")
        m = self.reels.shape[0]
        self.attachments = _points(attachments, "attachments", rows=m)
        self.workspace_lower = _vector(workspace_lower, "workspace_lower")
        self.workspace_upper = _vector(workspace_upper, "workspace_upper")
        pairs = np.asarray(pairs).reshape(-1, 2) if np.size(pairs) else np.zeros((0, 2), int)
        if pairs.size and (np.any(pairs < 1) or np.any(pairs > m)
                           or np.any(pairs[:, 0] == pairs[:, 1])):
            raise ValueError(f"pairs must name two different cables in 1..{m} per row, got "
                             f"{pairs.tolist()!r}")
        self.pairs = pairs.astype(int)
        if not (np.isfinite(force_scale) and force_scale > 0):
            raise ValueError(f"force_scale must be a finite value > 0 m/N, got {force_scale!r}")
        self.force_scale = float(force_scale)
        self.d_l, self.d_u = d_l, d_u
        if not prefix.startswith("/"):
            raise ValueError(f"prefix must be an absolute Meshcat path such as '/cdpm', got "
                             f"{prefix!r}")
        self.prefix = prefix.rstrip("/")
        self.cable_radius = float(cable_radius)
        direction = _vector(view_direction, "view_direction")
        if not np.linalg.norm(direction) > 0:
            raise ValueError(f"view_direction must be a non-zero 3-vector, got {view_direction!r}")
        self.view_direction = direction / np.linalg.norm(direction)
        self._visible: dict[str, bool] = {}
        self._build()
        if set_camera:
            self.set_camera()

    @classmethod
    def from_log(cls, meshcat: Meshcat, log: Mapping, **kwargs) -> "CdpmMeshcatView":
        """A view of the robot a log.npz describes (docs/LOG_FORMAT.md); the colour band is the
        log's d_l, d_u where finite, the defaults elsewhere; the camera looks from where the
        log's forces are seen most side-on (view_direction)."""
        d_l = np.asarray(log["d_l"], dtype=float)
        d_u = np.asarray(log["d_u"], dtype=float)
        ok = np.isfinite(d_l) & np.isfinite(d_u)
        kwargs.setdefault("d_l", np.where(ok, d_l, DEFAULT_D_L))
        kwargs.setdefault("d_u", np.where(ok, d_u, DEFAULT_D_U))
        forces = [np.asarray(log[k], dtype=float).reshape(-1, 3)
                  for k in ("F_H", "F_int", "F_d") if k in log]
        kwargs.setdefault("view_direction", view_direction(np.vstack(forces) if forces
                                                           else None))
        return cls(meshcat, log["reels"], log["attachments"], log["workspace_lower"],
                   log["workspace_upper"], log["pairs"], **kwargs)

    @property
    def num_cables(self) -> int:
        return self.reels.shape[0]

    def cable_path(self, i: int) -> str:
        """Scene path of cable i (1-based)."""
        return f"{self.prefix}/cables/cable_{i}"

    def cable_level_path(self, i: int, level: int) -> str:
        return f"{self.cable_path(i)}/length/level_{level}"

    def cable_slack_path(self, i: int) -> str:
        return f"{self.cable_path(i)}/length/slack"

    def force_path(self, name: str) -> str:
        """Scene path of the arrow of force `name` in F_H, F_int, F_d."""
        return f"{self.prefix}/forces/{name}"

    def label_path(self, i: int) -> str:
        """Scene path of cable i's number (1-based), beside its reel."""
        return f"{self.prefix}/labels/cable_{i}"

    def clock_glyph_path(self, slot: int, glyph: str) -> str:
        """Scene path of character `glyph` (one of CLOCK_GLYPHS) in slot 0..CLOCK_SLOTS-1."""
        name = {".": "point"}.get(glyph, glyph)
        return f"{self.prefix}/clock/slot_{slot}/{name}"

    @property
    def size(self) -> float:
        """The robot's size, m: the diagonal of the reels' box."""
        return float(np.linalg.norm(self.reels.max(axis=0) - self.reels.min(axis=0))) or 1.0

    # -- static scene --

    def _build(self) -> None:
        mc, pre = self.meshcat, self.prefix
        mc.Delete(pre)
        lo, hi = self.reels.min(axis=0), self.reels.max(axis=0)
        size = float(np.linalg.norm(hi - lo)) or 1.0
        start, end = _box_segments(lo, hi)
        mc.SetLineSegments(f"{pre}/frame", start, end, 2.0, Rgba(0.25, 0.25, 0.3, 1.0))
        start, end = _box_segments(self.workspace_lower, self.workspace_upper)
        mc.SetLineSegments(f"{pre}/workspace", start, end, 2.0, Rgba(0.1, 0.6, 0.2, 1.0))
        reel = Sphere(0.008 * size)
        for i, a in enumerate(self.reels, start=1):
            mc.SetObject(f"{pre}/reels/reel_{i}", reel, Rgba(0.15, 0.15, 0.15, 1.0))
            mc.SetTransform(f"{pre}/reels/reel_{i}", RigidTransform(a))
        extent = 2.0 * np.abs(self.attachments).max(axis=0)
        extent = np.where(extent > 0.02, extent, 0.05)
        mc.SetObject(f"{pre}/platform/box", Box(*extent), Rgba(0.55, 0.6, 0.75, 0.5))
        centre = RigidTransform([0.0, 0.0, 0.5])
        for i in range(1, self.num_cables + 1):
            for k in range(LEVELS):
                path = self.cable_level_path(i, k)
                mc.SetObject(path, Cylinder(self.cable_radius, 1.0), Rgba(*level_rgb(k), 1.0))
                mc.SetTransform(path, centre)
                mc.SetProperty(path, "visible", False)
            path = self.cable_slack_path(i)
            mc.SetObject(path, Cylinder(0.5 * self.cable_radius, 1.0), Rgba(*SLACK_RGBA))
            mc.SetTransform(path, centre)
            mc.SetProperty(path, "visible", False)
        shaft_radius = 0.003 * size
        head = MeshcatCone(_HEAD_FRACTION, 3.0 * shaft_radius, 3.0 * shaft_radius)
        for name, rgba in FORCE_RGBA.items():
            scaled = f"{self.force_path(name)}/scaled"
            mc.SetObject(f"{scaled}/shaft", Cylinder(shaft_radius, 1.0 - _HEAD_FRACTION),
                         Rgba(*rgba))
            mc.SetTransform(f"{scaled}/shaft", RigidTransform([0, 0, 0.5 - _HEAD_FRACTION / 2]))
            # The cone's apex is at its origin and it opens along +z: flip it so the apex is
            # the arrow's tip at z = 1.
            mc.SetObject(f"{scaled}/head", head, Rgba(*rgba))
            mc.SetTransform(f"{scaled}/head", RigidTransform(RollPitchYaw(np.pi, 0, 0),
                                                             [0.0, 0.0, 1.0]))
        self._build_text()
        self.forget_drawn_state()

    def _text(self, path: str, text: str, height: float) -> None:
        vertices, faces = text_mesh(text, height)
        if faces.shape[1]:
            self.meshcat.SetTriangleMesh(path, vertices, faces, Rgba(*TEXT_RGBA))

    def _build_text(self) -> None:
        """Cable numbers beside the reels, the clock and the force scale, facing the default
        camera."""
        mc, pre = self.meshcat, self.prefix
        eye, target = camera_pose(self.reels, direction=self.view_direction)
        R = facing_rotation(eye, target)
        right, up, normal = (R.matrix()[:, k] for k in range(3))
        height = _TEXT_HEIGHT * self.size
        centre = 0.5 * (self.reels.min(axis=0) + self.reels.max(axis=0))
        for i, a in enumerate(self.reels, start=1):
            # Beside the reel as seen from the camera, away from the robot's centre, so that
            # neither the reel nor its cable covers the number.
            out = a - centre
            out -= (out @ normal) * normal
            out = out / np.linalg.norm(out) if np.linalg.norm(out) > 1e-9 else right
            self._text(self.label_path(i), str(i), height)
            mc.SetTransform(self.label_path(i), RigidTransform(R, a + 0.7 * height * out))
        # The clock and the scale in the top left corner of the default view, in the plane
        # through the target.
        distance = float(np.linalg.norm(eye - target))
        half_h = distance * np.tan(np.radians(CAMERA_FOV) / 2.0)
        half_w = CAMERA_MIN_ASPECT * half_h
        corner = target - 0.92 * half_w * right + 0.85 * half_h * up
        mc.SetTransform(f"{pre}/clock", RigidTransform(R, corner))
        cell = _cell_px() * height / _TEXT_ROWS  # m per character
        self._text(f"{pre}/clock/prefix", "t =", height)
        for slot in range(CLOCK_SLOTS):
            for glyph in CLOCK_GLYPHS:
                path = self.clock_glyph_path(slot, glyph)
                self._text(path, glyph, height)
                mc.SetTransform(path, RigidTransform([(4 + slot) * cell, 0.0, 0.0]))
                mc.SetProperty(path, "visible", False)
        scale = f"{pre}/clock/force_scale"
        self._text(scale, f"arrows: 1 N = {self.force_scale:g} m", 0.7 * height)
        mc.SetTransform(scale, RigidTransform([0.0, -1.4 * height, 0.0]))

    def set_camera(self) -> None:
        """Frame the whole robot from view_direction (camera_pose) with Meshcat's default
        camera (CAMERA_FOV)."""
        eye, target = camera_pose(self.reels, direction=self.view_direction)
        self.meshcat.SetCameraPose(eye, target)
        # The origin triad would be confused with the force arrows.
        self.meshcat.SetProperty("/Axes", "visible", False)

    def forget_drawn_state(self) -> None:
        """Make the next draw send everything (e.g. at the first frame of a recording)."""
        self._visible.clear()
        self._clock = [None] * CLOCK_SLOTS

    # -- per-frame drawing --

    def _set_visible(self, path: str, visible, time) -> None:
        visible = bool(visible)
        if self._visible.get(path) != visible:
            self.meshcat.SetProperty(path, "visible", visible, time)
            self._visible[path] = visible

    def _pose_along(self, path: str, origin, vector, time) -> float:
        """Pose path at origin with its z axis along vector; returns |vector|."""
        length = float(np.linalg.norm(vector))
        R = (RotationMatrix.MakeFromOneVector(vector, 2) if length > _TINY
             else RotationMatrix())
        self.meshcat.SetTransform(path, RigidTransform(R, origin), time)
        return length

    def draw(self, p, F_H, F_int, F_d, pair_distances, *, d_l=None, d_u=None,
             sim_time: float | None = None, time: float | None = None, rpy=None,
             slack=None, F_kin=None) -> None:
        """Draw the platform at p (m), the cables, and the forces F_H, F_int, F_d (N), base
        frame; pair_distances (m) in the order of `pairs`; the clock shows sim_time (s) when
        given. d_l, d_u (m) override the colour band. With `time` (s, from the start of the
        recording) the frame goes into the current Meshcat recording. A dynamic plant's log
        adds the platform's rotation `rpy` (rad; p is then its true position) and which
        cables are `slack` (drawn light grey). F_kin (N): the kinetostatic cue of the safety
        filter, in purple (hidden when None or zero)."""
        mc = self.meshcat
        if sim_time is not None:
            text = clock_text(sim_time).ljust(CLOCK_SLOTS)
            for slot in range(CLOCK_SLOTS):
                if self._clock[slot] == text[slot]:
                    continue
                for glyph in CLOCK_GLYPHS:
                    self._set_visible(self.clock_glyph_path(slot, glyph), glyph == text[slot],
                                      time)
                self._clock[slot] = text[slot]
        p = _vector(p, "p")
        R = RotationMatrix() if rpy is None else RotationMatrix(RollPitchYaw(_vector(rpy, "rpy")))
        mc.SetTransform(f"{self.prefix}/platform", RigidTransform(R, p), time)
        levels = cable_levels(pair_distances, self.pairs, self.num_cables,
                              self.d_l if d_l is None else d_l, self.d_u if d_u is None else d_u)
        b = self.attachments @ R.matrix().T
        slack = np.zeros(self.num_cables, bool) if slack is None else np.asarray(slack) > 0.5
        for i in range(1, self.num_cables + 1):
            a = self.reels[i - 1]
            length = self._pose_along(self.cable_path(i), a, p + b[i - 1] - a, time)
            mc.SetProperty(f"{self.cable_path(i)}/length", "scale",
                           [1.0, 1.0, max(length, _TINY)], time)
            for k in range(LEVELS):
                self._set_visible(self.cable_level_path(i, k),
                                  k == levels[i - 1] and not slack[i - 1], time)
            self._set_visible(self.cable_slack_path(i), slack[i - 1], time)
        for name, force in (("F_H", F_H), ("F_int", F_int), ("F_d", F_d),
                            ("F_kin", np.zeros(3) if F_kin is None else F_kin)):
            path = self.force_path(name)
            magnitude = self._pose_along(path, p, _vector(force, name), time)
            shown = magnitude * self.force_scale > _TINY
            if shown:
                mc.SetProperty(f"{path}/scaled", "scale",
                               [1.0, 1.0, self.force_scale * magnitude], time)
            self._set_visible(path, shown, time)

    def draw_row(self, log: Mapping, k: int, time: float | None = None) -> None:
        """Draw tick k of a log.npz dictionary (docs/LOG_FORMAT.md); a dynamic plant's log
        shows the true pose (p_true, rpy_true) and the slack cables."""
        dynamic = all(key in log for key in ("p_true", "rpy_true", "slack"))
        self.draw(log["p_true"][k] if dynamic else log["p"][k], log["F_H"][k], log["F_int"][k],
                  log["F_d"][k], log["pair_distances"][k], sim_time=float(log["time"][k]),
                  time=time, rpy=log["rpy_true"][k] if dynamic else None,
                  slack=log["slack"][k] if dynamic else None,
                  F_kin=log["F_kin"][k] if "F_kin" in log else None)


# --- Live view and replay ---------------------------------------------------------------------


def live_view_callback(view: CdpmMeshcatView, read_latest):
    """`on_chunk(diagram, context)` for `simulation.simulate` and `realtime.run`: draws the
    latest tick, as `read_latest(diagram, context, keys)` gives it ({key: value} of the keys
    the diagram logs: runs/latest_signals.py's latest_signals, which the caller hands in, so
    that the view reads no block or plant itself); a dynamic plant's ground truth (p_true,
    rpy_true, slack) when there is one; signals the diagram lacks are drawn as zero."""
    widths = {"p": 3, "F_H": 3, "F_int": 3, "F_d": 3, "pair_distances": len(view.pairs),
              "p_true": 3, "rpy_true": 3, "slack": view.num_cables, "F_kin": 3}

    def on_chunk(diagram, context) -> None:
        row = read_latest(diagram, context, tuple(widths))

        def value(key):
            found = row.get(key)
            return np.zeros(widths[key]) if found is None else found

        dynamic = row.get("p_true") is not None
        view.draw(row["p_true"] if dynamic else value("p"), value("F_H"), value("F_int"),
                  value("F_d"), value("pair_distances"), sim_time=context.get_time(),
                  rpy=row.get("rpy_true"), slack=row.get("slack"), F_kin=value("F_kin"))

    return on_chunk


def replay_frames(time, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Recording times (s from the first tick, k / fps) and the log row shown at each: the
    last tick at or before that time. A log of T ticks over D s gives floor(D fps) + 1 frames."""
    t = np.asarray(time, dtype=float).reshape(-1)
    if t.size == 0:
        return np.zeros(0), np.zeros(0, dtype=int)
    frames = np.arange(int(np.floor((t[-1] - t[0]) * fps + 1e-9)) + 1) / fps
    rows = np.searchsorted(t - t[0], frames + 1e-9, side="right") - 1
    return frames, np.clip(rows, 0, t.size - 1)


def save_replay_html(log: Mapping, path, meshcat: Meshcat | None = None, fps: float = 50.0,
                     force_scale: float = FORCE_SCALE) -> Path:
    """Write a self-contained HTML replay of a log (docs/LOG_FORMAT.md): a Meshcat recording
    at `fps` frames per second of log time, saved with Meshcat's StaticHtml, which opens in a
    browser with no server. Uses (and clears under /cdpm) `meshcat`, or a private loopback
    server. Returns the path written."""
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a finite value > 0 frames/s, got {fps!r}")
    if len(log["time"]) == 0:
        raise ValueError("the log has no ticks ('time' is empty): nothing to replay")
    meshcat = make_meshcat(port=0) if meshcat is None else meshcat
    view = CdpmMeshcatView.from_log(meshcat, log, force_scale=force_scale)
    frames, rows = replay_frames(log["time"], fps)
    # The scene as the page first shows it, before the animation takes over.
    view.draw_row(log, int(rows[0]))
    meshcat.StartRecording(frames_per_second=fps, set_visualizations_while_recording=False)
    view.forget_drawn_state()
    for t, k in zip(frames, rows):
        view.draw_row(log, int(k), time=float(t))
    meshcat.StopRecording()
    meshcat.PublishRecording()
    html = meshcat.StaticHtml()
    title = " ".join(str(log[k]) for k in ("scenario_name", "robot_name") if k in log)
    html = html.replace("<title>Drake MeshCat</title>",
                        f"<title>cdpm replay: {_html_escape(title)}</title>", 1)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(html, encoding="utf-8")
    return path


def _html_escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
