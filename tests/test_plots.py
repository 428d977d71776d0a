"""The paper's figures drawn from a log: the plotted data, read back from the figures'
artists, must equal the log (times in s, distances in mm = 1000 x the log's m, forces in N)."""

import numpy as np
import pytest
from helpers_synthetic_log import EXP1, EXP3, logistic, synthetic_log

from cdpm_drake.views import plots


@pytest.fixture(scope="module")
def log():
    return synthetic_log(duration=1.0)


def _lines(ax, prefix):
    return {line.get_label(): line for line in ax.get_lines()
            if line.get_label().startswith(prefix)}


def test_plot_log_writes_four_pngs(log, tmp_path):
    import matplotlib.pyplot as plt  # only to see that plot_log left no pyplot figure open

    before = plt.get_fignums()
    paths = plots.plot_log(log, tmp_path / "out", dpi=50)
    assert [p.name for p in paths] == ["distances.png", "forces.png", "trajectory.png",
                                       "logistic.png"]
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


def test_distances_show_the_active_pairs_in_mm_with_their_bands(log):
    fig = plots.figure_distances(log)
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
    ax = plots.figure_distances(log).axes[0]
    # Pair (1,3) starts at 45 mm, the smallest distance of the log; NaN bands draw no line.
    assert sorted(_lines(ax, "cables ")) == ["cables 1-3"]
    assert _lines(ax, "d_") == {}
    assert ax.get_title().startswith("No pair came within d_u")


def test_forces_plot_every_component_of_F_H_F_int_F_d(log):
    fig = plots.figure_forces(log)
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


def test_forces_add_F_wall_when_the_wall_pushed(log):
    pushed = dict(log, F_wall=np.tile([0.0, 0.0, 1.5], (len(log["time"]), 1)))
    ax = plots.figure_forces(pushed).axes[2]
    wall = [line for line in ax.get_lines() if line.get_label() == "F_wall,z"]
    assert len(wall) == 1 and np.all(wall[0].get_ydata() == 1.5)


def test_trajectory_marks_events_crossings_reels_and_cables(log):
    fig = plots.figure_trajectory(log)
    ax = fig.axes[0]
    lines = {line.get_label(): line for line in ax.get_lines()}

    def data(label):
        return np.array(lines[label].get_data_3d()).T

    np.testing.assert_array_equal(data("platform path p"), log["p"])
    np.testing.assert_array_equal(data("a pair within d_u"), log["p"][log["active"].any(axis=1)])
    # The synthetic log flags pair (1,3) crossed during its first 5 ticks.
    np.testing.assert_array_equal(data("a pair crossed"), log["p"][:5])
    np.testing.assert_array_equal(data("reels A_i"), log["reels"])
    texts = sorted(t.get_text().strip() for t in ax.texts)
    assert texts == [f"A{i}" for i in range(1, 8)]
    # Tick 0 is the first with interference (pair (1,3) at 45 mm < d_u): cables 1 and 3 red,
    # each from its reel a_i to p + b_i.
    cables = {line.get_gid(): line for line in ax.get_lines() if line.get_gid()}
    assert sorted(cables) == sorted(f"cable {i}" for i in range(1, 8))
    for i in range(1, 8):
        xyz = np.array(cables[f"cable {i}"].get_data_3d()).T
        np.testing.assert_allclose(xyz, [log["reels"][i - 1],
                                         log["p"][0] + log["attachments"][i - 1]])
        assert cables[f"cable {i}"].get_color() == ("red" if i in (1, 3) else "0.55")
    assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_zlabel()) == ("x (m)", "y (m)", "z (m)")


def test_logistic_curves_follow_eqs_26_28_for_each_parameter_set(log):
    fig = plots.figure_logistic(log)
    # Two sets: EXP1 for 20 pairs, EXP3 for pair (5,7).
    assert len(fig.axes) == 2
    assert [ax.get_title() for ax in fig.axes] == ["20 cable pairs", "cables 5-7"]
    for ax, (d_l, d_u, F_u, eps) in zip(fig.axes, (EXP1, EXP3)):
        curve = _lines(ax, "F_u = ")[f"F_u = {F_u:g} N, eps = {eps:g} N"]
        d = np.asarray(curve.get_xdata()) / 1000.0
        assert d.min() == pytest.approx(max(0.0, d_l - (d_u - d_l)))
        assert d.max() == pytest.approx(d_u + (d_u - d_l))
        # The helper's own transcription of eqs. 26 and 28.
        np.testing.assert_allclose(curve.get_ydata(), logistic(d, d_l, d_u, F_u, eps))
        marks = [line for line in ax.get_lines() if line.get_gid() == "conditions (27)"][0]
        # Eq. 27: F_u - eps at d_l, eps at d_u.
        np.testing.assert_allclose(marks.get_xdata(), [1000 * d_l, 1000 * d_u])
        np.testing.assert_allclose(marks.get_ydata(), [F_u - eps, eps])
        labels = set(_lines(ax, "").keys())
        assert {f"d_l = {1000 * d_l:g} mm", f"d_u = {1000 * d_u:g} mm",
                f"F_u - eps = {F_u - eps:g} N", f"eps = {eps:g} N"} <= labels
    assert "(N)" in fig.axes[0].get_ylabel() and "(mm)" in fig.axes[0].get_xlabel()


def test_logistic_without_parameters_says_so():
    fig = plots.figure_logistic(synthetic_log(duration=0.2, interference=False))
    ax = fig.axes[0]
    assert ax.get_lines() == []
    assert any("interference disabled" in t.get_text() for t in ax.texts)


def test_load_log_roundtrip_and_errors(log, tmp_path):
    np.savez_compressed(tmp_path / "log.npz", **log)
    loaded = plots.load_log(tmp_path)  # a run directory
    assert sorted(loaded) == sorted(log)
    for key in log:
        np.testing.assert_array_equal(loaded[key], log[key])
    assert str(loaded["robot_name"]) == "paper_7cable_swap13"

    partial = {k: v for k, v in log.items() if k != "F_int"}
    np.savez(tmp_path / "partial.npz", **partial)
    with pytest.raises(plots.LogError, match=r"lacks the key\(s\) \['F_int'\]"):
        plots.load_log(tmp_path / "partial.npz")
    with pytest.raises(plots.LogError, match="does not exist"):
        plots.load_log(tmp_path / "nowhere")
    (tmp_path / "junk.npz").write_text("not a zip")
    with pytest.raises(plots.LogError, match="is not a log written by cdpm simulate or cdpm run"):
        plots.load_log(tmp_path / "junk.npz")


def test_figures_name_missing_or_misshapen_keys(log):
    with pytest.raises(plots.LogError, match=r"needs log key\(s\) \['F_d'\]"):
        plots.figure_forces({k: v for k, v in log.items() if k != "F_d"})
    with pytest.raises(plots.LogError, match="'F_H' has shape"):
        plots.figure_forces(dict(log, F_H=log["F_H"][:-1]))
