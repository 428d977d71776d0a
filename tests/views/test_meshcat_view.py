"""The Meshcat view: what `draw` puts in the scene, read back from Meshcat's own packed
messages, and what the HTML replay's recording holds. Meshcat listens on loopback only."""

import base64
import re
from pathlib import Path

import numpy as np
import pytest
from helpers_docs import page
from helpers_meshcat import prop, transform, unpack
from helpers_synthetic_log import synthetic_log

from cdpm_drake.runs.latest_signals import latest_signals
from cdpm_drake.views import meshcat_view as mv

# A 4-cable robot small enough to reason about by hand (tests/conftest.py's valid robot).
REELS = np.array([[0.0, 0.0, 3.0], [4.0, 0.0, 3.0], [4.0, 3.0, 3.0], [2.0, 1.5, 0.0]])
ATTACH = np.array([[-0.1, -0.1, 0.1], [0.1, -0.1, 0.1], [0.1, 0.1, 0.1], [0.0, 0.0, -0.1]])
PAIRS = [(1, 2), (1, 3), (2, 3)]
P = np.array([2.0, 1.5, 1.5])


# --- helpers reading the scene ------------------------------------------------------------------


def rgb(meshcat, path) -> np.ndarray:
    color = unpack(meshcat._GetPackedObject(path))["object"]["materials"][0]["color"]
    return np.array([(color >> 16) & 0xFF, (color >> 8) & 0xFF, color & 0xFF]) / 255.0


def visible_level(meshcat, view, i) -> int:
    shown = [k for k in range(mv.LEVELS) if prop(meshcat, view.cable_level_path(i, k), "visible")]
    assert len(shown) == 1, shown
    return shown[0]


@pytest.fixture(scope="module")
def meshcat():
    return mv.make_meshcat(port=0)


@pytest.fixture
def view(meshcat):
    return mv.CdpmMeshcatView(meshcat, REELS, ATTACH, [1.0, 0.5, 0.5], [3.0, 2.5, 2.5], PAIRS,
                              force_scale=0.05, d_l=0.05, d_u=0.061)


def test_meshcat_listens_on_loopback(meshcat):
    assert meshcat.web_url().startswith("http://localhost:")


# --- colours --------------------------------------------------------------------------------------


def test_pair_levels_closed_form():
    # d_l = 50 mm, d_u = 61 mm: the band (50, 61] mm splits into LEVELS - 2 = 4 steps of 2.75 mm.
    d = [0.040, 0.050, 0.0505, 0.0535, 0.061, 0.0611, np.nan]
    assert mv.LEVELS == 6
    # 40, 50 mm <= d_l: red (0); 50.5 mm: first step (1); 53.5 mm: (3.5 / 11) * 4 = 1.27 -> 2;
    # 61 mm = d_u is still in the band, last step (4); above d_u and NaN: grey (5).
    assert mv.pair_levels(d, 0.050, 0.061).tolist() == [0, 0, 1, 2, 4, 5, 5]


def test_cable_levels_take_the_nearest_pair():
    # (1,2) at 40 mm: red; (1,3) far; (2,3) at 55 mm: (5/11) * 4 = 1.8 -> level 2.
    levels = mv.cable_levels([0.040, 0.2, 0.055], PAIRS, 4, 0.05, 0.061)
    # Cable 4 is in no pair: grey.
    assert levels.tolist() == [0, 0, 2, 5]


def test_level_colours_red_to_orange_then_grey():
    assert mv.level_rgb(0) == mv.RED
    assert mv.level_rgb(mv.LEVELS - 1) == mv.GREY
    greens = [mv.level_rgb(k)[1] for k in range(mv.LEVELS - 1)]
    assert greens == sorted(greens) and len(set(greens)) == mv.LEVELS - 1


def test_draw_colours_the_interfering_pair_red(meshcat, view):
    view.draw(P, [5.0, 0, 0], [0, 2.0, 0], [5.0, 2.0, 0], [0.040, 0.2, 0.055])
    # Same numbers as test_cable_levels_take_the_nearest_pair.
    assert [visible_level(meshcat, view, i) for i in (1, 2, 3, 4)] == [0, 0, 2, 5]
    for i in (1, 2):
        np.testing.assert_allclose(rgb(meshcat, view.cable_level_path(i, 0)), [1, 0, 0])
    # Meshcat stores 8-bit colours: grey 0.55 -> 140/255.
    np.testing.assert_allclose(rgb(meshcat, view.cable_level_path(4, 5)), mv.GREY, atol=1 / 255)
    # The pair moves apart: everything grey, and only changed flags were sent again.
    view.draw(P, [5.0, 0, 0], [0, 0, 0], [5.0, 0, 0], [0.2, 0.2, 0.2])
    assert [visible_level(meshcat, view, i) for i in (1, 2, 3, 4)] == [5, 5, 5, 5]
    # A per-call band overrides the view's: with d_l = 0.25 m every pair is "red".
    view.draw(P, [5.0, 0, 0], [0, 0, 0], [5.0, 0, 0], [0.2, 0.2, 0.2], d_l=0.25, d_u=0.3)
    assert [visible_level(meshcat, view, i) for i in (1, 2, 3, 4)] == [0, 0, 0, 5]


# --- geometry -------------------------------------------------------------------------------------


def test_cables_run_from_reel_to_attachment(meshcat, view):
    view.draw(P, [0, 0, 1.0], [0, 0, 0], [0, 0, 1.0], [0.2, 0.2, 0.2])
    for i in range(1, 5):
        X = transform(meshcat, view.cable_path(i))
        scale = prop(meshcat, f"{view.cable_path(i)}/length", "scale")
        # The unit cylinder along z, scaled to the length, spans a_i .. a_i + rho_i, with
        # rho_i = p + b_i - a_i (eq. 1).
        np.testing.assert_allclose(X[:3, 3], REELS[i - 1], atol=1e-12)
        np.testing.assert_allclose(X[:3, 3] + X[:3, 2] * scale[2], P + ATTACH[i - 1], atol=1e-12)
        assert scale[:2] == [1.0, 1.0]
        np.testing.assert_allclose(X[:3, :3] @ X[:3, :3].T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(transform(meshcat, "/cdpm/platform")[:3, 3], P)


def test_force_arrow_length_is_proportional_to_the_force(meshcat, view):
    tips = []
    for F_int in (np.array([0.3, -0.4, 1.2]), 2.5 * np.array([0.3, -0.4, 1.2])):
        view.draw(P, [1.0, 2.0, -2.0], F_int, F_int + [1.0, 2.0, -2.0], [0.2, 0.2, 0.2])
        path = view.force_path("F_int")
        X = transform(meshcat, path)
        length = prop(meshcat, f"{path}/scaled", "scale")[2]
        # |F_int| = 1.3 N (0.3^2 + 0.4^2 + 1.2^2 = 1.69), 0.05 m/N: 0.065 m, then 0.1625 m.
        assert length == pytest.approx(0.05 * np.linalg.norm(F_int), rel=1e-12)
        np.testing.assert_allclose(X[:3, 3], P)
        tips.append(X[:3, 3] + X[:3, 2] * length)
        np.testing.assert_allclose(tips[-1], P + 0.05 * F_int, atol=1e-12)
        assert prop(meshcat, path, "visible") is True
    # |F_H| = 3 N: 0.15 m.
    assert prop(meshcat, f"{view.force_path('F_H')}/scaled", "scale")[2] == pytest.approx(0.15)
    np.testing.assert_allclose(tips[1] - P, 2.5 * (tips[0] - P), atol=1e-12)


def test_default_arrows_reach_out_of_the_platform_at_the_documented_scale(meshcat):
    from cdpm_drake.robot import load_robot, robot_names

    view = mv.CdpmMeshcatView(meshcat, REELS, ATTACH, [1.0, 0.5, 0.5], [3.0, 2.5, 2.5], PAIRS)
    view.draw(P, [0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [0.2, 0.2, 0.2])
    # 1 N is drawn FORCE_SCALE m long; the guide (docs/viewing.md) and the scene state that
    # scale.
    length = prop(meshcat, f"{view.force_path('F_int')}/scaled", "scale")[2]
    assert length == mv.FORCE_SCALE == 0.25
    readme = page("viewing")
    assert "0.25 m per N" in readme
    assert meshcat.HasPath("/cdpm/clock/force_scale")
    # On every built-in robot an arrow of 1 N (less than the F_u and hand forces of the shipped
    # scenarios, 2-5 N) ends outside the platform box: its half-size is max |b_i| per axis.
    for name in robot_names():
        half = np.abs(load_robot(name).attachments).max()
        assert mv.FORCE_SCALE * 1.0 > 1.5 * half, (name, half)


def _look_at(eye, target):
    """World-to-camera rotation of a camera at eye looking at target, z up (OpenGL: the camera
    looks along its -z, y up), written out here independently of the view."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return np.stack([right, up, -forward])


def _ndc(points, eye, target, fov_deg, aspect):
    """Normalised device coordinates (x, y in [-1, 1] inside the view) of a pinhole camera."""
    camera = (np.asarray(points) - eye) @ _look_at(eye, target).T
    depth = -camera[:, 2]
    assert np.all(depth > 0)  # in front of the camera
    f = 1.0 / np.tan(np.radians(fov_deg) / 2)
    return np.stack([camera[:, 0] * f / aspect / depth, camera[:, 1] * f / depth], axis=1)


@pytest.mark.parametrize("robot_name", ["paper_7cable", "cube_8cable"])
def test_the_default_camera_frames_the_whole_robot(meshcat, robot_name):
    from cdpm_drake.robot import load_robot

    robot = load_robot(robot_name)
    view = mv.CdpmMeshcatView(meshcat, robot.reels, robot.attachments, robot.workspace.lower,
                              robot.workspace.upper, robot.pairs)
    eye, target = mv.camera_pose(robot.reels, direction=view.view_direction)
    # Meshcat's default camera, whose field of view is in the meshcat.js that pydrake ships:
    # `create_camera(){... new PerspectiveCamera(75, 1, .01, 100)`.
    import pydrake

    js = (Path(pydrake.__file__).parent / "share/drake/geometry/meshcat.js").read_text()
    fov = float(re.search(r"create_camera\(\)\{.*?\((\d+(?:\.\d+)?),1,\.01,100\)", js).group(1))
    assert fov == mv.CAMERA_FOV
    # What Meshcat got: the camera's position (three.js is y up: (x, z, -y)).
    x, y, z = prop(meshcat, "/Cameras/default/rotated/<object>", "position")
    np.testing.assert_allclose([x, -z, y], eye - [0, 0, 0], atol=1e-9)
    # The target is the centre of the reels' box: every corner of that box (so every reel,
    # the workspace and the platform inside it) is in view, in a 4:3 and a 16:9 window...
    lo, hi = robot.reels.min(axis=0), robot.reels.max(axis=0)
    np.testing.assert_allclose(target, 0.5 * (lo + hi))
    corners = np.array([[(hi if (n >> a) & 1 else lo)[a] for a in range(3)] for n in range(8)])
    for aspect in (4 / 3, 16 / 9):
        ndc = _ndc(corners, eye, target, fov, aspect)
        assert np.all(np.abs(ndc) < 0.98), (aspect, ndc)
        # ... and it fills the view: not a speck in the middle of it.
        assert np.abs(ndc).max() > 0.6, ndc


def test_cables_are_numbered_beside_their_reels_facing_the_camera(meshcat, view):
    eye, target = mv.camera_pose(REELS, direction=view.view_direction)
    height = mv._TEXT_HEIGHT * view.size
    for i in range(1, 5):
        path = view.label_path(i)
        geometry = unpack(meshcat._GetPackedObject(path))["object"]["geometries"][0]
        assert len(geometry["data"]["attributes"]["position"]["array"]) > 0
        X = transform(meshcat, path)
        # Within a text height of reel i, its face (z axis) along the camera's axis, towards
        # the camera, and upright (x horizontal).
        assert np.linalg.norm(X[:3, 3] - REELS[i - 1]) < 1.0 * height
        np.testing.assert_allclose(X[:3, 2], (eye - target) / np.linalg.norm(eye - target),
                                   atol=1e-12)
        assert abs(X[2, 0]) < 1e-12
    # Each number its own glyphs: the meshes of "1" .. "4" all differ.
    shapes = {tuple(unpack(meshcat._GetPackedObject(view.label_path(i)))["object"]["geometries"]
                    [0]["data"]["attributes"]["position"]["array"]) for i in range(1, 5)}
    assert len(shapes) == 4


def _clock(meshcat, view) -> str:
    """The clock's text, read back from which glyph of each slot is visible."""
    text = ""
    for slot in range(mv.CLOCK_SLOTS):
        shown = [g for g in mv.CLOCK_GLYPHS
                 if prop(meshcat, view.clock_glyph_path(slot, g), "visible")]
        assert len(shown) <= 1
        text += shown[0] if shown else " "
    return text


def test_the_clock_shows_the_simulated_time(meshcat, view):
    view.draw(P, [0, 0, 0], [0, 0, 0], [0, 0, 0], [0.2, 0.2, 0.2], sim_time=12.34)
    assert _clock(meshcat, view) == "12.34 s  "
    view.draw(P, [0, 0, 0], [0, 0, 0], [0, 0, 0], [0.2, 0.2, 0.2], sim_time=0.5)
    assert _clock(meshcat, view) == "0.50 s   "
    assert meshcat.HasPath("/cdpm/clock/prefix")  # "t ="


def test_the_view_direction_sees_the_forces_side_on():
    # Forces all along y: a camera beside the x axis sees them side-on, one in front (-y, the
    # default's side) nearly end-on. Of the two sides (+x, -x) the one nearer the default
    # (which looks from -x): (-cos 27 deg, 0, sin 27 deg) at the 27 deg elevation.
    forces = np.tile([0.0, 2.0, 0.0], (10, 1))
    d = mv.view_direction(forces)
    np.testing.assert_allclose(d, [-np.cos(np.radians(27)), 0.0, np.sin(np.radians(27))],
                               atol=1e-12)
    # Along x instead: from the front (-y), like the default.
    d = mv.view_direction(np.tile([3.0, 0.0, 0.0], (10, 1)))
    np.testing.assert_allclose(d, [0.0, -np.cos(np.radians(27)), np.sin(np.radians(27))],
                               atol=1e-12)
    # No force at all: the default direction.
    np.testing.assert_array_equal(mv.view_direction(np.zeros((5, 3))), mv.CAMERA_DIRECTION)


def test_a_zero_force_hides_its_arrow(meshcat, view):
    view.draw(P, [1.0, 0, 0], [0, 0, 0], [1.0, 0, 0], [0.2, 0.2, 0.2])
    assert prop(meshcat, view.force_path("F_int"), "visible") is False
    assert prop(meshcat, view.force_path("F_H"), "visible") is True


def test_arrow_colours_follow_fig_12(meshcat, view):
    for name, expected in (("F_H", mv.FORCE_RGBA["F_H"]), ("F_int", mv.FORCE_RGBA["F_int"]),
                           ("F_d", mv.FORCE_RGBA["F_d"])):
        for part in ("shaft", "head"):
            got = rgb(meshcat, f"{view.force_path(name)}/scaled/{part}")
            np.testing.assert_allclose(got, expected[:3], atol=1 / 255)


def test_static_scene(meshcat, view):
    for path in ("/cdpm/frame", "/cdpm/workspace", "/cdpm/platform/box",
                 *(f"/cdpm/reels/reel_{i}" for i in range(1, 5))):
        assert meshcat.HasPath(path), path
    np.testing.assert_allclose(transform(meshcat, "/cdpm/reels/reel_4")[:3, 3], REELS[3])
    # Workspace wireframe: 12 edges, each from a corner to a corner of the box.
    geometry = unpack(meshcat._GetPackedObject("/cdpm/workspace"))["object"]["geometries"][0]
    segments = np.array(geometry["data"]["attributes"]["position"]["array"]).reshape(-1, 2, 3)
    assert len(segments) == 12
    assert set(map(tuple, segments.reshape(-1, 3))) == {
        (x, y, z) for x in (1.0, 3.0) for y in (0.5, 2.5) for z in (0.5, 2.5)}
    # Each edge runs along one axis over the box's side: 2 m in x, y and z.
    steps = np.abs(segments[:, 1] - segments[:, 0])
    assert sorted(np.flatnonzero(row)[0] for row in steps) == [0] * 4 + [1] * 4 + [2] * 4
    np.testing.assert_allclose(steps.sum(axis=1), 2.0)


def test_bad_input_names_the_field(meshcat):
    good = dict(reels=REELS, attachments=ATTACH, workspace_lower=[1, 1, 1],
                workspace_upper=[2, 2, 2], pairs=PAIRS)
    for change, match in ((dict(attachments=ATTACH[:3]), "attachments must be an array of "
                           r"shape \(4, 3\)"),
                          (dict(pairs=[(1, 5)]), r"pairs must name two different cables in 1..4"),
                          (dict(workspace_lower=[1, 1]), "workspace_lower must be a 3-vector"),
                          (dict(force_scale=0.0), "force_scale must be a finite value > 0")):
        with pytest.raises(ValueError, match=match):
            mv.CdpmMeshcatView(meshcat, **{**good, **change})
    with pytest.raises(ValueError, match="fps must be a finite value > 0"):
        mv.save_replay_html(synthetic_log(0.1), "unused.html", meshcat=meshcat, fps=0)


# --- live view and replay -------------------------------------------------------------------------


def test_live_view_callback_draws_the_latest_logged_tick(meshcat):
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink

    log = synthetic_log(0.1)
    view = mv.CdpmMeshcatView.from_log(meshcat, log)
    builder = DiagramBuilder()
    # F_int has no logger here: the callback must draw it as zero (arrow hidden).
    values = {"p": log["p"][7], "F_H": [0.0, 4.0, 0.0], "F_d": [0.0, 4.0, 0.0],
              "pair_distances": log["pair_distances"][0]}
    for key, value in values.items():
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        sink = builder.AddNamedSystem(f"log_{key}", VectorLogSink(len(value), 0.002))
        builder.Connect(source.get_output_port(), sink.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.01)
    mv.live_view_callback(view, latest_signals)(diagram, simulator.get_context())
    np.testing.assert_allclose(transform(meshcat, "/cdpm/platform")[:3, 3], log["p"][7])
    assert prop(meshcat, view.force_path("F_int"), "visible") is False
    # |F_H| = 4 N at the default FORCE_SCALE of 0.25 m/N: 1 m.
    assert prop(meshcat, f"{view.force_path('F_H')}/scaled", "scale")[2] == pytest.approx(1.0)
    # Pair (1,3) at 45 mm < d_l = 50 mm: cables 1 and 3 red.
    assert visible_level(meshcat, view, 1) == 0 and visible_level(meshcat, view, 3) == 0
    # The clock shows the diagram's time, 0.01 s.
    assert _clock(meshcat, view) == "0.01 s   "


def test_live_view_callback_reads_the_blocks_when_there_are_no_loggers(meshcat):
    # A real-time run has no in-memory loggers (it streams to disk): the view must then read
    # the blocks' output ports, here of the full controller diagram at its first tick.
    from pydrake.systems.analysis import Simulator

    from cdpm_drake.diagram import BuildOptions, build_diagram
    from cdpm_drake.config import load_scenario, scenario_robot

    scenario = load_scenario("exp1_no_interaction")
    robot = scenario_robot(scenario)
    diagram = build_diagram(scenario, BuildOptions(loggers=False))
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.01)
    view = mv.CdpmMeshcatView(meshcat, robot.reels, robot.attachments, robot.workspace.lower,
                              robot.workspace.upper, robot.pairs, d_l=0.050, d_u=0.061)
    mv.live_view_callback(view, latest_signals)(diagram, simulator.get_context())
    fk = diagram.GetSubsystemByName("forward_kinematics")
    p = fk.GetOutputPort("p_WP").Eval(fk.GetMyContextFromRoot(simulator.get_context()))
    np.testing.assert_allclose(transform(meshcat, "/cdpm/platform")[:3, 3], p)
    # exp1 starts with cables 1 and 3 inside d_u: F_int is drawn (its arrow is visible).
    assert prop(meshcat, view.force_path("F_int"), "visible") is True


def test_replay_frames_sample_the_log_at_fps():
    time = np.arange(501) * 0.002 + 3.0  # 1 s of 2 ms ticks, not starting at 0
    frames, rows = mv.replay_frames(time, 50.0)
    # 1 s at 50 frames/s: frames 0, 0.02, ..., 1.0 s (51), each showing tick 10 k.
    assert len(frames) == 51
    np.testing.assert_allclose(frames, np.arange(51) / 50.0)
    assert rows.tolist() == list(range(0, 501, 10))
    # A log sparser than the frame rate repeats its last tick.
    _, rows = mv.replay_frames([0.0, 0.1], 50.0)
    assert rows.tolist() == [0] * 5 + [1]


def _animation(html: str) -> dict:
    """The set_animation message StaticHtml embeds (base64 msgpack in a data: URL)."""
    for blob in re.findall(r'data:application/octet-binary;base64,([A-Za-z0-9+/=]+)', html):
        message = unpack(base64.b64decode(blob))
        if message["type"] == "set_animation":
            return {a["path"]: {t["name"]: t for t in a["clip"]["tracks"]}
                    for a in message["animations"]}
    raise AssertionError("no set_animation message in the HTML")


def test_replay_html_records_the_log(meshcat, tmp_path):
    # Pair (5,7) closes from 70.5 mm to 50.5 mm (below its d_l = 57 mm) over 0.4 s.
    log = synthetic_log(0.4, d57=(0.0705, 0.0505))
    path = mv.save_replay_html(log, tmp_path / "replay" / "run.html", meshcat=meshcat, fps=25)
    html = path.read_text()
    # Self-contained: no script or stylesheet fetched from anywhere.
    assert re.search(r"<script[^>]+src=", html) is None
    assert re.search(r"<link[^>]+href=", html) is None
    assert "<title>cdpm replay: synthetic paper_7cable_swap13</title>" in html
    tracks = _animation(html)

    # 0.4 s at 25 frames/s: frames 0..10, frame k showing tick 20 k (0.04 s / 2 ms).
    position = tracks["/cdpm/platform"][".position"]["keys"]
    assert [key["time"] for key in position] == list(range(11))
    np.testing.assert_allclose([key["value"] for key in position], log["p"][::20])

    view = mv.CdpmMeshcatView.from_log(meshcat, log)
    # Frame k shows 70.5 - 2 k mm; red (level 0) once at or below d_l = 57 mm, i.e. from
    # frame 7 (56.5 mm) on. Only changes are recorded: the red cylinder of cable 5
    # gets a key at frame 0 (hidden) and one at frame 7 (shown).
    red = tracks[view.cable_level_path(5, 0)][".visible"]["keys"]
    assert [(key["time"], key["value"]) for key in red] == [(0, False), (7, True)]
    grey = tracks[view.cable_level_path(7, mv.LEVELS - 1)][".visible"]["keys"]
    # Grey while above d_u = 62 mm: frames 0..4 (70.5 .. 62.5 mm); hidden from frame 5 (60.5).
    assert [(key["time"], key["value"]) for key in grey] == [(0, True), (5, False)]
    scale = tracks[f"{view.cable_path(5)}/length"][".scale"]["keys"]
    from cdpm_drake.kernels.kinematics import cable_lengths
    from cdpm_drake.robot import load_robot
    robot = load_robot("paper_7cable").with_swapped_attachments(1, 3)
    # Cable lengths by eq. 2, independently of the view.
    np.testing.assert_allclose([key["value"][2] for key in scale],
                               cable_lengths(robot, log["p"][::20])[:, 4])
    # The clock: frame k shows 0.04 k s, so the last slot is an "8" at frames 2 and 7 only
    # ("0.08 s", "0.28 s"); the point stays in slot 1 throughout.
    eight = tracks[view.clock_glyph_path(3, "8")][".visible"]["keys"]
    assert [(key["time"], key["value"]) for key in eight] == [(0, False), (2, True), (3, False),
                                                              (7, True), (8, False)]
    point = tracks[view.clock_glyph_path(1, ".")][".visible"]["keys"]
    assert [(key["time"], key["value"]) for key in point] == [(0, True)]
