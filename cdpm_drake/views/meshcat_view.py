"""A 3D view of the CDPM in Drake's Meshcat: live while a run goes, or as an HTML replay.

The scene, in the base frame A (m): the frame (the box spanned by the reels) and the reels, the
workspace box (wireframe), the platform (a box), one cylinder per cable from its reel a_i to its
attachment p + b_i coloured by the distance to its nearest cable (red at or below d_l, red to
orange inside the band (d_l, d_u], grey above d_u: the interfering pair is red, as in the paper's
Fig. 9), and the forces from the platform as arrows (blue measured F_H, black interference F_int,
red resultant F_d, as in Fig. 12), `force_scale` m long per N.

Everything that moves is posed by a transform, a scale or a visibility flag, never by
re-sending geometry, because those three are what a Meshcat recording can animate; the same
`draw` therefore serves the live view and the replay of `save_replay_html`. A cable is a unit
cylinder along z, posed at its reel and scaled along z to its length; each cable has one
cylinder per colour level and only the one of its current level is visible. `draw` only sends
what changed and costs a few dozen Meshcat messages.

Scene paths use 1-based cable numbers (`/cdpm/cables/cable_3`).
"""

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
              "F_d": (0.9, 0.0, 0.0, 1.0)}
# Used when a log has no logistic parameters (interference disabled): the paper's experiment 1
# band, so the colours still say how close the cables came.
DEFAULT_D_L = 0.050  # m
DEFAULT_D_U = 0.061  # m
# Below this a force (N) or a cable (m) has no direction worth drawing.
_TINY = 1e-9
# An arrow is a unit-length shaft + head along z, scaled along z to its length.
_HEAD_FRACTION = 0.2


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
    force_scale in m of arrow per N; d_l, d_u (m, scalars or one per pair) the default colour
    band, overridden per call by draw's d_l, d_u.
    """

    def __init__(self, meshcat: Meshcat, reels, attachments, workspace_lower, workspace_upper,
                 pairs, force_scale: float = 0.05, d_l=DEFAULT_D_L, d_u=DEFAULT_D_U,
                 prefix: str = "/cdpm", cable_radius: float = 0.01,
                 set_camera: bool = True):
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
        self._visible: dict[str, bool] = {}
        self._build()
        if set_camera:
            self.set_camera()

    @classmethod
    def from_log(cls, meshcat: Meshcat, log: Mapping, **kwargs) -> "CdpmMeshcatView":
        """A view of the robot a log.npz describes (docs/LOG_FORMAT.md); the colour band is the
        log's d_l, d_u where finite, the defaults elsewhere."""
        d_l = np.asarray(log["d_l"], dtype=float)
        d_u = np.asarray(log["d_u"], dtype=float)
        ok = np.isfinite(d_l) & np.isfinite(d_u)
        kwargs.setdefault("d_l", np.where(ok, d_l, DEFAULT_D_L))
        kwargs.setdefault("d_u", np.where(ok, d_u, DEFAULT_D_U))
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
        self._visible.clear()

    def set_camera(self) -> None:
        """Look at the workspace centre from the front, left and above."""
        lo, hi = self.reels.min(axis=0), self.reels.max(axis=0)
        target = 0.5 * (self.workspace_lower + self.workspace_upper)
        span = float(np.linalg.norm(hi - lo)) or 1.0
        eye = target + span * np.array([-0.3, -0.65, 0.3])
        self.meshcat.SetCameraPose(eye, target)
        # The origin triad would be confused with the force arrows.
        self.meshcat.SetProperty("/Axes", "visible", False)

    def forget_drawn_state(self) -> None:
        """Make the next draw send everything (e.g. at the first frame of a recording)."""
        self._visible.clear()

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
             time: float | None = None, rpy=None, slack=None) -> None:
        """Draw the platform at p (m), the cables, and the forces F_H, F_int, F_d (N), base
        frame; pair_distances (m) in the order of `pairs`. d_l, d_u (m) override the colour
        band. With `time` (s, from the start of the recording) the frame goes into the
        current Meshcat recording. A dynamic plant's log adds the platform's rotation `rpy`
        (rad; p is then its true position) and which cables are `slack` (drawn light grey)."""
        mc = self.meshcat
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
        for name, force in (("F_H", F_H), ("F_int", F_int), ("F_d", F_d)):
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
                  log["F_d"][k], log["pair_distances"][k], time=time,
                  rpy=log["rpy_true"][k] if dynamic else None,
                  slack=log["slack"][k] if dynamic else None)


# --- Live view and replay ---------------------------------------------------------------------


def live_view_callback(view: CdpmMeshcatView):
    """`on_chunk(diagram, context)` for `simulation.simulate` and `realtime.run`: draws the
    latest tick, from the loggers (log_<key>, diagram.LOGGED) where the diagram has them and
    from the blocks' output ports otherwise (a real-time run streams to disk instead);
    signals the diagram lacks are drawn as zero."""
    from ..diagram import LOGGED

    sources = {key: (system, port) for key, system, port in LOGGED}

    def latest(diagram, context, key, width):
        name = f"log_{key}"
        if diagram.HasSubsystemNamed(name):
            data = diagram.GetSubsystemByName(name).FindLog(context).data()
            return data[:, -1] if data.shape[1] else np.zeros(width)
        if key in ("p_true", "rpy_true", "slack"):  # the dynamic plant's, logged inside it
            plant = (diagram.GetSubsystemByName("reels")
                     if diagram.HasSubsystemNamed("reels") else None)
            if plant is not None and hasattr(plant, "HasSubsystemNamed") and (
                    plant.HasSubsystemNamed(name)):
                data = plant.GetSubsystemByName(name).FindLog(context).data()
                return data[:, -1] if data.shape[1] else None
            return None
        system_name, port_name = sources[key]
        if diagram.HasSubsystemNamed(system_name):
            system = diagram.GetSubsystemByName(system_name)
            return system.GetOutputPort(port_name).Eval(system.GetMyContextFromRoot(context))
        return np.zeros(width)

    def on_chunk(diagram, context) -> None:
        row = {key: latest(diagram, context, key, width)
               for key, width in (("p", 3), ("F_H", 3), ("F_int", 3), ("F_d", 3),
                                  ("pair_distances", len(view.pairs)), ("p_true", 3),
                                  ("rpy_true", 3), ("slack", view.num_cables))}
        dynamic = row["p_true"] is not None
        view.draw(row["p_true"] if dynamic else row["p"], row["F_H"], row["F_int"], row["F_d"],
                  row["pair_distances"], rpy=row["rpy_true"], slack=row["slack"])

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
                     force_scale: float = 0.05) -> Path:
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
