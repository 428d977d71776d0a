"""tensions.png of a tension-controlled run (issue 32): one panel per cable, numbered 1..m,
with the plant's tension, the controller's estimate and target in that cable's colour; the
target's floor as the log says it was used each tick (not controller.min_tension drawn as a
constant); t* drawn where finite and shaded where +inf; no legend entry for what is not drawn.
Expected values come from the log's arrays, worked out here by hand."""

import numpy as np
import pytest
from helpers_synthetic_log import synthetic_log

from cdpm_drake.views.figures_plant import cable_style, figure_tensions


def _tension_log(duration=0.2, truth=True):
    """A tension-controlled run's log: per cable i (1..7) the plant's tension 20 + i N, the
    estimate 20.5 + i N, the target 21 + i N, except that on ticks 30-59 the pose lets the
    weakest cable (7) have only 3.4 + 0.01 k N (the floor lowered); min_tension 10 N,
    max_tension 30 N, t* 15 N (+inf on ticks 0-9)."""
    log = synthetic_log(duration)
    T = len(log["time"])
    cables = np.arange(1, 8)
    log["tension_estimate"] = np.tile(20.5 + cables, (T, 1)).astype(float)
    target = np.tile(21.0 + cables, (T, 1)).astype(float)
    target[:, 2] = 10.0  # cable 3 sits at the floor where the floor held
    target[30:60, 6] = 3.4 + 0.01 * np.arange(30)
    log["tension_target"] = target
    log["tension_status"] = np.zeros((T, 1))
    log["tension_status"][30:60] = 1
    log["t_star"] = np.full((T, 1), 15.0)
    log["t_star"][:10] = np.inf
    log["controller_min_tension"] = np.array(10.0)
    log["controller_max_tension"] = np.array(30.0)
    if truth:
        log["tensions"] = np.tile(20.0 + cables, (T, 1)).astype(float)
        log["slack"] = np.zeros((T, 7), dtype=bool)
    return log


def _gid(ax, gid):
    return [a for a in ax.get_children() if getattr(a, "get_gid", lambda: None)() == gid]


def test_one_panel_per_cable_with_its_truth_estimate_and_target_in_its_colour():
    log = _tension_log()
    fig = figure_tensions(log)
    panels = [ax for ax in fig.axes if ax.get_title().startswith("cable ")]
    assert [ax.get_title() for ax in panels] == [f"cable {i}" for i in range(1, 8)]
    for i, ax in enumerate(panels, start=1):
        lines = [line for line in ax.get_lines() if line.get_gid() and "cable" in
                 line.get_gid()]
        assert len(lines) == 3  # truth, estimate, target: three lines a panel, not fourteen
        for what, key, style in (("true tension (plant)", "tensions", "-"),
                                 ("controller's estimate", "tension_estimate", "--"),
                                 ("target", "tension_target", ":")):
            line, = _gid(ax, f"{what} cable {i}")
            np.testing.assert_array_equal(line.get_ydata(), log[key][:, i - 1])
            assert line.get_color() == cable_style(i)["color"]
            assert line.get_linestyle() == style


def test_the_floor_is_the_one_used_each_tick_not_a_constant():
    # Where the floor held the weakest target is min_tension (10 N, cable 3); on ticks 30-59
    # the pose lowered it to cable 7's target, 3.4 N at its lowest.
    log = _tension_log()
    fig = figure_tensions(log)
    expected = np.full(len(log["time"]), 10.0)
    expected[30:60] = 3.4 + 0.01 * np.arange(30)
    floors = [line for ax in fig.axes for line in _gid(ax, "floor used")]
    assert len(floors) == 8  # every cable's panel and the panel below
    for line in floors:
        np.testing.assert_allclose(line.get_ydata(), expected, rtol=1e-12)
    below = [ax for ax in fig.axes if _gid(ax, "t_star")][0]
    labels = [text.get_text().replace("\n", " ") for text in below.get_legend().get_texts()]
    assert ("target's floor as used (its weakest cable): lowest 3.40 N, set to min_tension "
            "= 10 N") in labels
    # No horizontal line at min_tension: the old picture drew the floor as a constant 10 N.
    for ax in fig.axes:
        for line in ax.get_lines():
            y = np.asarray(line.get_ydata(), dtype=float)
            assert not (y.size == 2 and np.all(y == 10.0)), line.get_label()
    # The ceiling (30 N) is within reach of the tensions (27 N): drawn in every panel.
    assert len([1 for ax in fig.axes for _ in _gid(ax, "controller_max_tension")]) == 7


def test_t_star_shaded_where_infinite_and_no_legend_entry_for_a_line_not_drawn():
    log = _tension_log()
    t = log["time"]
    fig = figure_tensions(log)
    below = [ax for ax in fig.axes if _gid(ax, "t_star")][0]
    t_star, = _gid(below, "t_star")
    assert np.isnan(t_star.get_ydata()[:10]).all() and (t_star.get_ydata()[10:] == 15).all()
    inf, = _gid(below, "t_star +inf")
    half = 0.5 * (t[1] - t[0])
    assert inf.get_x() == pytest.approx(t[0] - half)
    assert inf.get_x() + inf.get_width() == pytest.approx(t[9] + half)
    # t* +inf on every tick: no t* line and no legend entry for one; the shade says why.
    log["t_star"][:] = np.inf
    fig = figure_tensions(log)
    texts = [text.get_text().replace("\n", " ") for ax in fig.axes if ax.get_legend()
             for text in ax.get_legend().get_texts()]
    texts += [text.get_text() for legend in fig.legends for text in legend.get_texts()]
    assert not any(text.startswith("t* at") for text in texts)
    assert any(text.startswith("t* = +inf") for text in texts)
    assert not [ax for ax in fig.axes if _gid(ax, "t_star")]


def test_on_the_robot_the_panels_hold_the_estimate_and_target_alone():
    log = _tension_log(truth=False)
    fig = figure_tensions(log)
    panels = [ax for ax in fig.axes if ax.get_title().startswith("cable ")]
    assert len(panels) == 7
    assert not [1 for ax in panels for line in ax.get_lines()
                if (line.get_gid() or "").startswith("true tension")]
    legend = [text.get_text() for text in fig.legends[0].get_texts()]
    assert "true tension (plant)" not in legend and "controller's estimate" in legend
    # No slack rows without the plant's truth: the panels and the floor's panel only.
    assert len(fig.axes) == 8
    # A ceiling far above every tension is named, not drawn.
    log["controller_max_tension"] = np.array(500.0)
    fig = figure_tensions(log)
    notes = [a for ax in fig.axes for a in _gid(ax, "controller_max_tension")]
    assert [note.get_text() for note in notes] == [
        "ceiling max_tension = 500 N: above the cables' panels"]
