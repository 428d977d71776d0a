"""The paper's figures drawn from a log: the plotted data, read back from the figures'
artists, must equal the log (times in s, distances in mm = 1000 x the log's m, forces in N)."""

import numpy as np
import pytest
from helpers_synthetic_log import EXP1, EXP3, logistic, synthetic_log

from cdpm_drake.runs.log import LogError, load_log
from cdpm_drake.views.figure_keys import OPTIONAL, has_keys
from cdpm_drake.views.figure_layout import INTERRUPT_COLOR, mark_fault_time, wrap_to_width
from cdpm_drake.views.figures_interference import figure_distances, figure_logistic
from cdpm_drake.views.figures_motion import (EVENT_ALPHA, MIN_FORCE_SPAN, figure_forces,
                                             figure_trajectory)
from cdpm_drake.views.figures_plant import figure_cables, figure_pose_error, figure_tensions
from cdpm_drake.views.figures_timing import figure_timing
from cdpm_drake.views.plots import FIGURES, plot_log


@pytest.fixture(scope="module")
def log():
    return synthetic_log(duration=1.0)


def _lines(ax, prefix):
    return {line.get_label(): line for line in ax.get_lines()
            if line.get_label().startswith(prefix)}


def test_plot_log_writes_the_pngs(log, tmp_path):
    import matplotlib.pyplot as plt  # only to see that plot_log left no pyplot figure open

    before = plt.get_fignums()
    paths = plot_log(log, tmp_path / "out", dpi=50)
    # A simulation's log has no tick clock: no timing figure.
    assert [p.name for p in paths] == ["distances.png", "forces.png", "trajectory.png",
                                       "logistic.png", "cables.png"]
    for path in paths:
        head = path.read_bytes()[:24]
        assert head[:8] == b"\x89PNG\r\n\x1a\n", path
        # PNG IHDR: width and height follow the 8-byte signature and the 8-byte chunk header.
        width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
        assert width > 100 and height > 100
    # figsize (8, 4.5) in at 50 dpi: 400 x 225 pixels.
    head = paths[0].read_bytes()[:24]
    assert (int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")) == (400, 225)
    assert plt.get_fignums() == before
    realtime = plot_log(synthetic_log(0.1, realtime=True), tmp_path / "rt", dpi=20)
    assert realtime[-1].name == "timing.png" and len(realtime) == 6


def test_distances_show_the_active_pairs_in_mm_with_their_bands(log):
    fig = figure_distances(log)
    ax = fig.axes[0]
    curves = _lines(ax, "cables ")
    # The synthetic log brings pairs (1,3) and (5,7) within d_u, no other.
    assert sorted(curves) == ["cables 1-3", "cables 5-7"]
    for (i, j), label in (((1, 3), "cables 1-3"), ((5, 7), "cables 5-7")):
        k = [tuple(p) for p in log["pairs"]].index((i, j))
        np.testing.assert_array_equal(curves[label].get_xdata(), log["time"])
        np.testing.assert_allclose(curves[label].get_ydata(), 1000 * log["pair_distances"][:, k])
    # One line per distinct d_l and d_u of the shown pairs: 50, 57 mm and 61, 62 mm (EXP1, EXP3).
    bands = {label: line.get_ydata()[0] for label, line in _lines(ax, "d_").items()}
    assert bands == pytest.approx({"d_l = 50 mm": 1000 * EXP1[0], "d_l = 57 mm": 1000 * EXP3[0],
                                   "d_u = 61 mm": 1000 * EXP1[1], "d_u = 62 mm": 1000 * EXP3[1]})
    assert "(mm)" in ax.get_ylabel() and "(s)" in ax.get_xlabel()
    assert "Fig. 10" in ax.get_title()


def test_distances_without_interference_show_the_closest_pair():
    log = synthetic_log(duration=0.2, interference=False)
    ax = figure_distances(log).axes[0]
    # Pair (1,3) starts at 45 mm, the smallest distance of the log; NaN bands draw no line.
    assert sorted(_lines(ax, "cables ")) == ["cables 1-3"]
    assert _lines(ax, "d_") == {}
    assert ax.get_title().startswith("No pair came within d_u")


def test_forces_plot_every_component_of_F_H_F_int_F_d(log):
    fig = figure_forces(log)
    assert len(fig.axes) == 3
    for c, (ax, axis) in enumerate(zip(fig.axes, "xyz")):
        lines = {line.get_label(): line for line in ax.get_lines()}
        # F_wall is zero in this log, so it is not drawn.
        assert sorted(lines) == sorted(f"{n},{axis}" for n in ("F_H", "F_int", "F_d"))
        for name in ("F_H", "F_int", "F_d"):
            line = lines[f"{name},{axis}"]
            np.testing.assert_array_equal(line.get_xdata(), log["time"])
            np.testing.assert_array_equal(line.get_ydata(), log[name][:, c])
        assert ax.get_ylabel() == f"F_{axis} (N)"
    # Fig. 12's colours: blue measured, black interference, red resultant.
    colors = {line.get_label(): line.get_color() for line in fig.axes[0].get_lines()}
    assert colors == {"F_H,x": "tab:blue", "F_int,x": "black", "F_d,x": "tab:red"}


def test_force_axes_share_one_span_so_noise_reads_as_zero(log):
    # F_y is numerical noise (1e-6 N) in every series; F_x of F_H swings +-8 N.
    rng = np.random.default_rng(0)
    noisy = dict(log)
    for name in ("F_H", "F_int", "F_d"):
        noisy[name] = log[name].copy()
        noisy[name][:, 1] = 1e-6 * rng.standard_normal(len(log["time"]))
    fig = figure_forces(noisy)
    spans = [np.diff(ax.get_ylim())[0] for ax in fig.axes]
    # The largest component range over the series, from the data: F_x spans ~16 N (+-8 N sine
    # plus F_int); each axis is 1.1 times that high (5 % margin on each side).
    widest = max(np.ptp(np.concatenate([noisy[n][:, c] for n in ("F_H", "F_int", "F_d")]))
                 for c in range(3))
    assert widest > 15.0
    np.testing.assert_allclose(spans, 1.1 * widest, rtol=1e-12)
    # On that axis the noise fills less than 1e-6 of the height: drawn as the zero it is.
    y = fig.axes[1].get_lines()[0].get_ydata()
    assert np.ptp(y) / spans[1] < 1e-6
    # A log where nothing pushes at all still gets the minimum span, not a zoom on zero.
    still = dict(log, **{n: np.zeros_like(log[n]) for n in ("F_H", "F_int", "F_d")})
    for ax in figure_forces(still).axes:
        assert np.diff(ax.get_ylim())[0] == pytest.approx(1.1 * MIN_FORCE_SPAN)


def _pixels(fig, ax, inset=4):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())[..., :3].astype(int)
    x0, y0, x1, y1 = ax.get_window_extent(canvas.get_renderer()).extents
    height = rgba.shape[0]
    # Inside the spines only (the legends are outside the axes).
    return rgba[int(height - y1) + inset:int(height - y0) - inset, int(x0) + inset:int(x1) - inset]


def test_coinciding_force_lines_all_stay_visible(log):
    # Nobody pushes: F_H = 0 and F_d = F_int, the case where the red line hid the black one.
    alone = dict(log, F_H=np.zeros_like(log["F_H"]), F_d=log["F_int"].copy())
    fig = figure_forces(alone)
    styles = {(line.get_linestyle(), line.get_linewidth())
              for line in fig.axes[0].get_lines()}
    assert len(styles) == 3  # every series its own style or width
    # Wider lines lie below narrower ones, so a narrower one never covers a wider one.
    lines = sorted(fig.axes[0].get_lines(), key=lambda line: line.get_zorder())
    widths = [line.get_linewidth() for line in lines]
    assert widths == sorted(widths, reverse=True)
    # Rendered: black (F_int) and red (F_d) pixels along the same curve, and the blue F_H
    # along zero. Colours from matplotlib's tab palette: tab:red (214, 39, 40), tab:blue
    # (31, 119, 180).
    rgb = _pixels(fig, fig.axes[2])  # F_z: 0.8 * alpha of pair (1,3), clearly off zero
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    black = int(((r < 80) & (g < 80) & (b < 80)).sum())
    red = int(((r > 180) & (g < 90) & (b < 90)).sum())
    blue = int(((b > 150) & (r < 80) & (g > 90) & (g < 150)).sum())
    # Measured: ~460 black, ~620 red, ~3400 blue pixels; on a red line drawn over the black one
    # of the same width, no black pixel is left.
    assert black > 150 and red > 300 and blue > 300, (black, red, blue)


def test_forces_add_F_wall_when_the_wall_pushed(log):
    pushed = dict(log, F_wall=np.tile([0.0, 0.0, 1.5], (len(log["time"]), 1)))
    ax = figure_forces(pushed).axes[2]
    wall = [line for line in ax.get_lines() if line.get_label() == "F_wall,z"]
    assert len(wall) == 1 and np.all(wall[0].get_ydata() == 1.5)


def test_trajectory_marks_events_crossings_reels_and_cables(log):
    fig = figure_trajectory(log)
    zoom, robot = fig.axes[:2]
    lines = {line.get_label(): line for line in zoom.get_lines()}

    def data(label):
        return np.array(lines[label].get_data_3d()).T

    np.testing.assert_array_equal(data("platform path p"), log["p"])
    np.testing.assert_array_equal(data("a pair within d_u"), log["p"][log["active"].any(axis=1)])
    # The synthetic log flags pair (1,3) crossed during its first 5 ticks.
    np.testing.assert_array_equal(data("a pair crossed"), log["p"][:5])
    reels = [line for line in robot.get_lines() if line.get_label() == "reels A_i"]
    np.testing.assert_array_equal(np.array(reels[0].get_data_3d()).T, log["reels"])
    texts = sorted(t.get_text().strip() for t in robot.texts)
    assert texts == [f"A{i}" for i in range(1, 8)]
    # Tick 0 is the first with interference (pair (1,3) at 45 mm < d_u): cables 1 and 3 red,
    # each from its reel a_i to p + b_i.
    cables = {line.get_gid(): line for line in robot.get_lines()
              if (line.get_gid() or "").startswith("cable ")}
    assert sorted(cables) == sorted(f"cable {i}" for i in range(1, 8))
    for i in range(1, 8):
        xyz = np.array(cables[f"cable {i}"].get_data_3d()).T
        np.testing.assert_allclose(xyz, [log["reels"][i - 1],
                                         log["p"][0] + log["attachments"][i - 1]])
        assert cables[f"cable {i}"].get_color() == ("red" if i in (1, 3) else "0.55")
    for ax in (zoom, robot):
        assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_zlabel()) == ("x (m)", "y (m)", "z (m)")


def test_trajectory_zooms_to_the_motion_with_the_robot_as_context(log):
    fig = figure_trajectory(log)
    zoom, robot = fig.axes[:2]
    p = log["p"]
    # The synthetic path spans 0.13, 0.10, 0.17 m (p0 -> p1 of the helper): the zoomed axes are
    # one cube of 0.17 m x (1 + 2 x 15 %) = 0.221 m around it; the robot spans ~4.7 m.
    extent = p.max(axis=0) - p.min(axis=0)
    np.testing.assert_allclose(extent, [0.13, 0.10, 0.17], atol=1e-12)
    for (lo, hi), a, b in zip((zoom.get_xlim(), zoom.get_ylim(), zoom.get_zlim()),
                              p.min(axis=0), p.max(axis=0)):
        assert lo <= a and b <= hi
        assert hi - lo == pytest.approx(0.17 * 1.3)
    # The context panel holds the whole robot and the workspace box, and outlines the zoom.
    lines = {line.get_label(): line for line in robot.get_lines()}
    box = np.array(lines["workspace (virtual wall)"].get_data_3d()).T
    np.testing.assert_allclose(np.nanmin(box, axis=0), log["workspace_lower"])
    np.testing.assert_allclose(np.nanmax(box, axis=0), log["workspace_upper"])
    region = [line for line in robot.get_lines() if line.get_gid() == "zoomed region"][0]
    np.testing.assert_allclose(np.nanmax(np.array(region.get_data_3d()).T, axis=0),
                               [zoom.get_xlim()[1], zoom.get_ylim()[1], zoom.get_zlim()[1]])
    for get, k in ((robot.get_xlim, 0), (robot.get_ylim, 1), (robot.get_zlim, 2)):
        lo, hi = get()
        assert lo <= log["reels"][:, k].min() and log["reels"][:, k].max() <= hi


def test_trajectory_path_above_the_event_dots_and_legend_off_the_data(log):
    fig = figure_trajectory(log)
    zoom = fig.axes[0]
    lines = {line.get_label(): line for line in zoom.get_lines()}
    # Depth sorting off in the zoomed panel, so zorder decides: the path above the dots.
    assert zoom.computed_zorder is False
    assert lines["platform path p"].get_zorder() > lines["a pair within d_u"].get_zorder()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    legend = fig.legends[0].get_window_extent(renderer)
    for ax in fig.axes:
        assert not legend.overlaps(ax.get_window_extent(renderer)), ax.get_title()
    # Only what is present: this log has crossings; one without lists none.
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "a pair crossed" in labels and len(labels) == len(set(labels))
    quiet = figure_trajectory(synthetic_log(0.2, crossed_ticks=0, interference=False))
    labels = [t.get_text() for t in quiet.legends[0].get_texts()]
    assert "a pair crossed" not in labels and "a pair within d_u" not in labels
    assert "cables of the active pairs" not in labels and "platform path p" in labels
    assert not any(line.get_label() == "a pair crossed" for line in quiet.axes[0].get_lines())


def test_logistic_curves_follow_eqs_26_28_for_each_parameter_set(log):
    fig = figure_logistic(log)
    # Two sets: EXP1 for 20 pairs, EXP3 for pair (5,7).
    assert len(fig.axes) == 2
    assert [ax.get_title() for ax in fig.axes] == ["20 cable pairs", "cables 5-7"]
    for ax, (d_l, d_u, F_u, eps) in zip(fig.axes, (EXP1, EXP3)):
        curve = _lines(ax, "applied: ")[f"applied: F_u = {F_u:g} N, eps = {eps:g} N"]
        d = np.asarray(curve.get_xdata()) / 1000.0
        alpha = np.asarray(curve.get_ydata())
        assert d.min() == pytest.approx(max(0.0, d_l - (d_u - d_l)))
        assert d.max() == pytest.approx(d_u + (d_u - d_l))
        # Issue 27: what the controller applies. Within d_u the helper's own transcription of
        # eqs. 26 and 28; beyond it zero (the pair is not active: interference.py's
        # `near = dist <= d_u`); at d_u the step from eps to 0, drawn as a vertical.
        within = d < d_u - 1e-12
        np.testing.assert_allclose(alpha[within], logistic(d[within], d_l, d_u, F_u, eps))
        assert np.all(alpha[d > d_u + 1e-12] == 0.0)
        step = np.flatnonzero(np.isclose(d, d_u, rtol=0, atol=1e-12))
        assert step.tolist() == [step[0], step[0] + 1]
        np.testing.assert_allclose(alpha[step], [eps, 0.0], rtol=1e-9)
        # The logistic's tail beyond d_u, faint, for reference: never zero there.
        tail = [line for line in ax.get_lines() if line.get_gid() == "beyond d_u"][0]
        assert tail.get_alpha() < 1 and np.all(np.asarray(tail.get_ydata()) > 0)
        marks = [line for line in ax.get_lines() if line.get_gid() == "conditions (27)"][0]
        # Eq. 27: F_u - eps at d_l, eps at d_u.
        np.testing.assert_allclose(marks.get_xdata(), [1000 * d_l, 1000 * d_u])
        np.testing.assert_allclose(marks.get_ydata(), [F_u - eps, eps])
        labels = set(_lines(ax, "").keys())
        assert {f"d_l = {1000 * d_l:g} mm", f"d_u = {1000 * d_u:g} mm",
                f"F_u - eps = {F_u - eps:g} N", f"eps = {eps:g} N"} <= labels
    assert "(N)" in fig.axes[0].get_ylabel() and "(mm)" in fig.axes[0].get_xlabel()


def test_logistic_without_parameters_says_so():
    fig = figure_logistic(synthetic_log(duration=0.2, interference=False))
    ax = fig.axes[0]
    assert ax.get_lines() == []
    assert any("interference disabled" in t.get_text() for t in ax.texts)


def test_load_log_roundtrip_and_errors(log, tmp_path):
    np.savez_compressed(tmp_path / "log.npz", **log)
    loaded = load_log(tmp_path)  # a run directory
    assert sorted(loaded) == sorted(log)
    for key in log:
        np.testing.assert_array_equal(loaded[key], log[key])
    assert str(loaded["robot_name"]) == "paper_7cable_swap13"

    partial = {k: v for k, v in log.items() if k != "F_int"}
    np.savez(tmp_path / "partial.npz", **partial)
    with pytest.raises(LogError, match=r"lacks the key\(s\) \['F_int'\]"):
        load_log(tmp_path / "partial.npz")
    with pytest.raises(LogError, match="does not exist"):
        load_log(tmp_path / "nowhere")
    (tmp_path / "junk.npz").write_text("not a zip")
    with pytest.raises(LogError, match="is not a log written by cdpm simulate or cdpm run"):
        load_log(tmp_path / "junk.npz")


def test_figures_name_missing_or_misshapen_keys(log):
    with pytest.raises(LogError, match=r"needs log key\(s\) \['F_d'\]"):
        figure_forces({k: v for k, v in log.items() if k != "F_d"})
    with pytest.raises(LogError, match="'F_H' has shape"):
        figure_forces(dict(log, F_H=log["F_H"][:-1]))


def test_a_fault_is_marked_in_every_figure(tmp_path):
    # The synthetic run ends on a fault at 0.3 s (helper: "bridge silent for 3 ticks").
    log = synthetic_log(0.5, fault_time=0.3, realtime=True)
    note = "fault at t = 0.300 s: bridge silent for 3 ticks"
    time_axes = 0
    for name, make in FIGURES.items():
        if name in OPTIONAL and not has_keys(log, name):
            continue  # the dynamic plant's figures: tests/systems/test_dynamic_plant.py
        fig = make(log)
        assert note in fig.get_suptitle().replace("\n", " "), name
        for ax in fig.axes:
            if ax.name == "3d":
                continue
            marks = [line for line in ax.get_lines() if line.get_gid() == "fault"]
            if name == "logistic":
                assert marks == []  # distance on x, no time axis
                continue
            assert len(marks) == 1, (name, ax.get_ylabel())
            assert list(marks[0].get_xdata()) == [0.3, 0.3]
            time_axes += 1
        if name == "trajectory":
            for ax in fig.axes[:2]:
                star = [line for line in ax.get_lines() if line.get_gid() == "fault"][0]
                # The pose logged at the fault's tick (0.3 s / 2 ms = tick 150).
                np.testing.assert_allclose(np.array(star.get_data_3d()).ravel(), log["p"][150])
    # distances 1 + forces 3 + cables 2 + timing 2.
    assert time_axes == 8
    # Older logs and completed runs: nothing marked.
    for quiet in (synthetic_log(0.2), dict(synthetic_log(0.2), ending=np.array("completed"),
                                            fault_time=np.array(np.nan),
                                            fault_message=np.array(""))):
        fig = figure_forces(quiet)
        assert "fault" not in fig.get_suptitle()
        assert not any(line.get_gid() == "fault" for ax in fig.axes for line in ax.get_lines())
    # A long message (a ReelFault's names the bridge, the watchdog and the link counts) is
    # wrapped, not cut before its reason.
    long = dict(log, fault_message=np.array(
        "ReelFault: reel fault at t = 0.300 s: no valid status from the reel bridge at "
        "127.0.0.1:47100 for 3 ticks (6 ms; watchdog_ticks = 3); zero reel velocity sent."))
    title = figure_cables(long).get_suptitle()
    assert "zero reel velocity sent." in title
    assert len(title.split("\n")) >= 4  # wrapped to the figure's width (issue 22, below)


def test_timing_figure_shows_tick_period_compute_and_the_limits():
    log = synthetic_log(0.5, realtime=True)
    fig = figure_timing(log)
    period_ax, compute_ax = fig.axes
    period = _lines(period_ax, "tick period")["tick period"]
    # diff(wall) in ms against the time of the later tick: 2 ms, 5 ms at the late tick (0.2 s,
    # tick 100, helper).
    np.testing.assert_allclose(period.get_xdata(), log["time"][1:])
    np.testing.assert_allclose(period.get_ydata(), 1000 * np.diff(log["wall"]))
    assert period.get_ydata()[99] == pytest.approx(5.0)
    compute = _lines(compute_ax, "compute")["compute time per tick"]
    np.testing.assert_allclose(compute.get_ydata(), 1000 * log["compute"])
    for ax in (period_ax, compute_ax):
        marks = {line.get_gid(): line.get_ydata()[0] for line in ax.get_lines()
                 if line.get_gid() in ("period", "watchdog")}
        # The 2 ms period of the log's time column, the 3-tick (6 ms) watchdog limit.
        assert marks == pytest.approx({"period": 2.0, "watchdog": 6.0})
    assert "p50 2.00 ms" in fig.get_suptitle() and "max 5.00 ms" in fig.get_suptitle()
    with pytest.raises(LogError, match=r"needs log key\(s\) \['wall'\]"):
        figure_timing(synthetic_log(0.1))
    # A log of an older cdpm run (tick and wall only): the period, and a note for compute.
    older = {k: v for k, v in log.items() if k not in ("compute", "watchdog_limit")}
    fig = figure_timing(older)
    assert _lines(fig.axes[0], "tick period")
    assert not _lines(fig.axes[1], "compute")
    assert any("not recorded" in t.get_text() for t in fig.axes[1].texts)
    assert not any(line.get_gid() == "watchdog" for ax in fig.axes for line in ax.get_lines())


def test_cables_figure_shows_lengths_and_reel_speeds_numbered_from_1(log):
    fig = figure_cables(log)
    top, bottom = fig.axes
    for ax, key in ((top, "lengths"), (bottom, "reel_velocity")):
        lines = _lines(ax, "cable ")
        assert sorted(lines) == sorted(f"cable {i}" for i in range(1, 8))
        for i in range(1, 8):
            np.testing.assert_array_equal(lines[f"cable {i}"].get_xdata(), log["time"])
            np.testing.assert_array_equal(lines[f"cable {i}"].get_ydata(), log[key][:, i - 1])
        styles = {(line.get_color(), line.get_linestyle()) for line in lines.values()}
        assert len(styles) == 7
    assert "(m)" in top.get_ylabel() and "(m/s)" in bottom.get_ylabel()


def test_views_benchmark_prints_its_table():
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[2] / "scripts" / "bench" / "bench_views.py"
    done = subprocess.run([sys.executable, str(script), "--duration", "0.2", "--fps", "10"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    # 0.2 s of 2 ms ticks: 101 ticks; at 10 frames/s, 3 frames (0, 0.1, 0.2 s).
    assert "101 ticks" in done.stdout and "3 frames" in done.stdout
    for row in ("simulation (reference)", "figure forces", "figure cables", "HTML replay",
                "live view: one frame"):
        assert row in done.stdout, done.stdout


# --- issue 22: titles inside the figure, interrupted runs, slack rows, the legend's dots ---


def _dynamic(log):
    """`log` with a dynamic plant's ground truth (tensions, slack, p_true, rpy_true) and the
    safety filter's signals (passing everything, margins of 3 N and 2 mm)."""
    T = len(log["time"])
    return dict(log, tensions=np.full((T, 7), 10.0), slack=np.zeros((T, 7), dtype=bool),
                p_true=log["p"].copy(), rpy_true=np.zeros((T, 3)),
                filter_status=np.zeros((T, 1)), filter_binding=np.zeros((T, 1)),
                velocity_limited=log["velocity"].copy(), kappa=np.full((T, 1), 3.0),
                pair_margin=np.full((T, 1), 0.002))


def _titles(fig):
    return [t for t in [fig._suptitle] + [a.title for a in fig.axes] if t and t.get_text()]


@pytest.mark.parametrize("dpi", [100, 120])  # the figures' own, and plot_log's PNGs
def test_every_title_lies_inside_the_figure_for_a_long_message(dpi):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    # A long fault message (about 330 characters, a 60-character word in it) on a run with a
    # long scenario name: every figure, the dynamic plant's and the timing one included.
    word = "/home/operator/robots/calibrations/2026-12-01/paper_7cable.yaml"
    message = ("KinematicsError: cable lengths are inconsistent with robot 'paper_7cable_swap13'"
               f" loaded from {word}: the best-fit platform position [1.562326, 3.242415, "
               "1.21489] m leaves a residual of 0.0012 m on cable 5 (allowed 0.0012 m); zero "
               "reel velocity was sent and the run stopped there.")
    log = _dynamic(dict(synthetic_log(0.4, fault_time=0.3, realtime=True),
                        fault_message=np.array(message),
                        scenario_name=np.array("an_operator_s_very_long_scenario_name_for_"
                                               "the_calibration_day_of_december_2026")))
    for name, make in FIGURES.items():
        fig = make(log)
        fig.set_dpi(dpi)
        FigureCanvasAgg(fig).draw()
        renderer = fig.canvas.get_renderer()
        for text in _titles(fig):
            box = text.get_window_extent(renderer)
            assert box.x0 >= 0 and box.x1 <= fig.bbox.width, (name, text.get_text())
            assert box.y0 >= 0 and box.y1 <= fig.bbox.height, (name, text.get_text())
        title = fig.get_suptitle()
        # Wrapped, not cut: the message's first and last words, and the long word whole or
        # split across lines.
        assert "fault at t = 0.300 s: KinematicsError:" in title, name
        assert title.replace("\n", " ").endswith("the run stopped there."), name
        assert word in title.replace("\n", ""), name


def test_wrapping_keeps_every_word_and_fits_each_line():
    def measure(text):  # one unit per character
        return float(len(text))

    lines = wrap_to_width("a bb ccc dddd\nx " + "y" * 25, measure, 10)
    assert lines == ["a bb ccc", "dddd", "x", "yyyyyyyyyy", "yyyyyyyyyy", "yyyyy"]
    assert all(len(line) <= 10 for line in lines)


def test_an_interrupted_run_is_marked_like_a_fault():
    # Issue 22, point 13: `ending` "interrupted" (Ctrl-C, SIGTERM): the last logged tick is
    # where the run stopped (the synthetic log's 0.5 s run ends at t = 0.5 s, tick 250).
    log = _dynamic(dict(synthetic_log(0.5, realtime=True), ending=np.array("interrupted"),
                        fault_time=np.array(np.nan), fault_message=np.array("")))
    time_axes = 0
    for name, make in FIGURES.items():
        fig = make(log)
        assert "interrupted at t = 0.500 s (Ctrl-C or SIGTERM)" in \
            fig.get_suptitle().replace("\n", " "), name
        assert "fault" not in fig.get_suptitle()
        for ax in fig.axes:
            if ax.name == "3d":
                continue
            marks = [line for line in ax.get_lines() if line.get_gid() == "interrupted"]
            if name == "logistic":
                assert marks == []
                continue
            assert len(marks) == 1 and list(marks[0].get_xdata()) == [0.5, 0.5], name
            assert marks[0].get_color() == INTERRUPT_COLOR
            time_axes += 1
        if name == "trajectory":
            star = [line for line in fig.axes[0].get_lines()
                    if line.get_gid() == "interrupted"][0]
            np.testing.assert_allclose(np.array(star.get_data_3d()).ravel(), log["p"][-1])
    # distances 1, forces 3, cables 2, timing 2, tensions 2, pose error 2, safety 5 (the
    # bands, the speeds, what the filter changed, the tensions, the pair margin).
    assert time_axes == 17


def test_cables_slack_at_the_same_time_each_have_their_row():
    # Issue 22, point 2: cables 4, 6 and 7 slack on the same ticks (10 to 19): three rows,
    # at heights 4, 6 and 7 of an axis labelled 1..7; none hides another.
    log = _dynamic(synthetic_log(0.1))
    log["slack"][10:20, [3, 5, 6]] = True
    fig = figure_tensions(log)
    rows = fig.axes[1]
    assert [t.get_text() for t in rows.get_yticklabels()] == [str(i) for i in range(1, 8)]
    marks = {line.get_gid(): line for line in rows.get_lines()
             if (line.get_gid() or "").startswith("slack cable")}
    assert sorted(marks) == ["slack cable 4", "slack cable 6", "slack cable 7"]
    for i in (4, 6, 7):
        np.testing.assert_array_equal(marks[f"slack cable {i}"].get_ydata(), np.full(10, i))
        np.testing.assert_array_equal(marks[f"slack cable {i}"].get_xdata(),
                                      log["time"][10:20])
        assert marks[f"slack cable {i}"].get_label() == f"cable {i} slack (10 ticks)"
    quiet = figure_tensions(_dynamic(synthetic_log(0.1)))
    assert "no cable went slack" in [t.get_text() for t in quiet.axes[1].texts]


def test_the_legend_shows_the_within_d_u_dots_as_they_look(log):
    # Issue 22, point 17: the dots are drawn translucent but overlap into solid orange; the
    # legend's marker is that orange, not one pale dot.
    from matplotlib.colors import to_rgba

    fig = figure_trajectory(log)
    dots = [line for line in fig.axes[0].get_lines() if line.get_gid() == "within d_u"][0]
    assert dots.get_alpha() == EVENT_ALPHA < 1
    legend = fig.legends[0]
    handle = legend.legend_handles[[t.get_text() for t in legend.get_texts()].index(
        "a pair within d_u")]
    assert to_rgba(handle.get_color(), handle.get_alpha()) == to_rgba("tab:orange", 1.0)


# --- issue 27, part B ---------------------------------------------------------------------


def _full_pose(log, tension_control=True):
    """A full-pose run's log (docs/LOG_FORMAT.md): the dynamic plant's truth, the controller's
    orientation estimate `rpy` (each component its own ramp, none equal to the truth's) and,
    with tension control, its tensions."""
    log = _dynamic(log)
    T = len(log["time"])
    s = np.linspace(0.0, 1.0, T)[:, None]
    log["rpy_true"] = s * np.array([0.010, -0.020, 0.030])  # rad
    log["rpy"] = s * np.array([0.012, -0.018, 0.025])
    if tension_control:
        log["tension_estimate"] = np.full((T, 7), 11.0)
        log["tension_target"] = np.full((T, 7), 10.5)
        log["t_star"] = np.full((T, 1), 30.0)
    return log


def test_pose_error_is_titled_by_the_run_s_controller_and_draws_its_orientation_estimate():
    # Issue 27, bug 6: a full-pose run's figure said "translating platform, rigid cables" and
    # drew the true rotation only. The log says which controller ran: `rpy` only for
    # controller.pose: full, `tension_estimate` only with its tension control.
    base = synthetic_log(0.1)
    cases = {"translating platform, rigid cables": _dynamic(base),
             "full pose, rigid cables": _full_pose(base, tension_control=False),
             "full pose, cables stretched under the estimated tensions": _full_pose(base)}
    for model, log in cases.items():
        title = figure_pose_error(log).get_suptitle().replace("\n", " ")
        assert f"pose estimate ({model})" in title
        assert sum(m in title for m in cases) == 1
    log = cases["full pose, cables stretched under the estimated tensions"]
    rotation = figure_pose_error(log).axes[1]
    lines = {line.get_label(): line for line in rotation.get_lines()}
    # Each component, true and estimated, is the log's in degrees (180 / pi per rad), in
    # the order roll, pitch, yaw of docs/LOG_FORMAT.md.
    for c, name in enumerate(("roll", "pitch", "yaw")):
        np.testing.assert_allclose(lines[f"{name} (true)"].get_ydata(),
                                   log["rpy_true"][:, c] * 180.0 / np.pi, rtol=1e-12)
        np.testing.assert_allclose(lines[f"{name} (controller's estimate)"].get_ydata(),
                                   log["rpy"][:, c] * 180.0 / np.pi, rtol=1e-12)
        assert lines[f"{name} (true)"].get_color() == lines[
            f"{name} (controller's estimate)"].get_color()
    # The translating controller has no estimate of its own: the truth alone.
    labels = [line.get_label() for line in figure_pose_error(
        cases["translating platform, rigid cables"]).axes[1].get_lines()]
    assert not any("estimate" in label for label in labels)
    # A misshapen estimate is named, as the figure's other keys are.
    with pytest.raises(LogError, match="'rpy' has shape"):
        figure_pose_error(dict(log, rpy=log["rpy"][:5]))


def test_a_tension_controlled_log_holds_the_target_s_floor_and_ceiling(tmp_path, capsys):
    from cdpm_drake.cli import main

    run = tmp_path / "run"
    assert main(["simulate", "exp2_interaction", "--duration", "0.01", "--out", str(run),
                 "--no-progress", "--scenario-text",
                 "{controller: {pose: full, tension_control: true, min_tension: 7.5, "
                 "max_tension: 80.0}, plant: !DynamicReels {}}"]) == 0
    log = load_log(run)
    assert float(log["controller_min_tension"]) == 7.5
    assert float(log["controller_max_tension"]) == 80.0
    # Without tension control there is no target, so no floor or ceiling either.
    assert main(["simulate", "exp2_interaction", "--duration", "0.01", "--out",
                 str(tmp_path / "plain"), "--no-progress"]) == 0
    assert "controller_min_tension" not in load_log(tmp_path / "plain")


def _crossing_lines(fig, ax, label):
    """The labels of the lines of `ax` that pass through the box of the text `label`, in the
    figure as drawn (display pixels, after the layout): each line sampled at its points and
    interpolated across the box's width; vertical lines (the mark itself) skipped."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    box = label.get_window_extent()
    xs = np.linspace(box.x0, box.x1, 50)
    hits = []
    for line in ax.get_lines():
        xy = line.get_transform().transform(
            np.column_stack([line.get_xdata(), line.get_ydata()]).astype(float))
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        if len(xy) == 0 or np.ptp(xy[:, 0]) == 0:
            continue
        xy = xy[np.argsort(xy[:, 0])]
        inside = (xs >= xy[0, 0]) & (xs <= xy[-1, 0])
        ys = np.concatenate([np.interp(xs[inside], xy[:, 0], xy[:, 1]),
                             xy[(xy[:, 0] >= box.x0) & (xy[:, 0] <= box.x1), 1]])
        if np.any((ys >= box.y0) & (ys <= box.y1)):
            hits.append(line.get_label())
    return hits


@pytest.mark.parametrize("d13, d57", [((0.045, 0.070), (0.066, 0.058)),
                                      ((0.0615, 0.0615), (0.058, 0.058))])
def test_the_interrupted_label_is_not_written_over_a_line(d13, d57):
    # Issue 27: "interrupted" was written at the top of the axis, over the d_u line (a pair
    # that stays near d_u has it at the top) or over a curve ending high (pair 1-3 at 70 mm).
    # Its box, as drawn, crosses no curve and no level line of its axis.
    log = dict(synthetic_log(0.5, d13=d13, d57=d57), ending=np.array("interrupted"),
               fault_time=np.array(np.nan), fault_message=np.array(""))
    for make in (figure_distances, figure_forces):
        fig = make(log)
        for ax in fig.axes:
            label = [t for t in ax.texts if t.get_gid() == "interrupted label"][0]
            assert _crossing_lines(fig, ax, label) == [], make.__name__
    # Where nothing is in the way it stays at the top: a curve along the bottom only.
    from matplotlib.figure import Figure

    fig = Figure()
    ax = fig.add_subplot()
    ax.plot(log["time"], np.zeros(len(log["time"])))
    ax.set_ylim(-0.1, 1.0)
    mark_fault_time(ax, log)
    assert ax.texts[0].get_position()[1] == pytest.approx(0.97)
