"""Sweep pictures from hand-written results rows: the plotted numbers are read back from the
artists and compared with means, spreads and the Pareto front worked out by hand."""

import numpy as np
import pytest

from cdpm_drake.runs.sweep import METRICS, NUMERIC_METRICS
from cdpm_drake.views import sweep_plots as sp

COLUMNS = ["run", "a", "b", "random_seed", "status", "error", "min_distance",
           "operator_effort"]


def row(run, a, b, seed, d=None, effort=None):
    ok = d is not None
    return {"run": run, "a": a, "b": b, "random_seed": str(seed),
            "status": "ok" if ok else "error", "error": "" if ok else "boom",
            "min_distance": "" if d is None else repr(d),
            "operator_effort": "" if effort is None else repr(effort)}


# a in {1, 2} x b in {10, 20} x seeds {1, 2}; cell (a=2, b=20) failed for both seeds.
ROWS = [row("r1", "1", "10", 1, 0.050, 1.0), row("r2", "1", "10", 2, 0.054, 1.0),
        row("r3", "1", "20", 1, 0.060, 2.0), row("r4", "1", "20", 2, 0.062, 2.0),
        row("r5", "2", "10", 1, 0.040, 3.0), row("r6", "2", "10", 2, 0.044, 3.0),
        row("r7", "2", "20", 1), row("r8", "2", "20", 2)]


def test_heatmap_cells_are_means_over_seeds_in_mm():
    fig = sp.figure_heatmap(COLUMNS, ROWS, "min_distance")
    image = fig.axes[0].images[0].get_array()
    # rows: b = 10, 20 (y); columns: a = 1, 2 (x); means of the two seeds, in mm.
    expected = np.array([[52.0, 42.0], [61.0, np.nan]])
    np.testing.assert_allclose(image.filled(np.nan), expected, rtol=1e-12)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert texts.count("error") == 1 and "52" in texts


def test_metric_against_an_axis_has_the_spread_over_seeds():
    fig = sp.figure_metric_vs_axis(COLUMNS, ROWS, "min_distance", "a")
    ax = fig.axes[0]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    # One line per value of b: b = 10 has a = 1, 2 -> 52, 42 mm; b = 20 only a = 1 -> 61 mm.
    np.testing.assert_allclose(lines["b = 10"].get_ydata(), [52.0, 42.0])
    np.testing.assert_allclose(lines["b = 20"].get_ydata(), [61.0])
    band = ax.collections[0].get_paths()[0].vertices[:, 1]
    assert band.min() == pytest.approx(40.0) and band.max() == pytest.approx(54.0)


def test_pareto_front_keeps_the_non_dominated_runs():
    # (effort, distance): A(1, 1) B(2, 3) C(3, 2) D(4, 4) E(2, 1): C is dominated by B (less
    # effort, more distance), E by A (less effort, same distance).
    pts = {"A": (1, 1), "B": (2, 3), "C": (3, 2), "D": (4, 4), "E": (2, 1)}
    rows = [row(k, "1", "1", 0, d, e) for k, (e, d) in pts.items()]
    assert [r["run"] for r in sp.pareto_front(rows)] == ["A", "B", "D"]
    fig = sp.figure_pareto(COLUMNS, rows)
    front = [ln for ln in fig.axes[0].get_lines() if ln.get_label() == "Pareto front"][0]
    np.testing.assert_allclose(front.get_xdata(), [1, 2, 4])
    np.testing.assert_allclose(front.get_ydata(), [1000, 3000, 4000])  # m -> mm


def test_plot_sweep_writes_the_pictures(tmp_path):
    paths = sp.plot_sweep(COLUMNS, ROWS, tmp_path, metric="operator_effort")
    assert [p.name for p in paths] == ["operator_effort_heatmap.png", "operator_effort_vs_a.png",
                                       "operator_effort_vs_b.png", "pareto.png"]
    assert all(p.stat().st_size > 1000 for p in paths)


# Issue 22, point 16: one unit per quantity, written on its axis, and readable labels.
DU, FU = "interference.default.d_u", "interference.default.F_u"
UNITS_COLUMNS = ["run", DU, FU, "random_seed", "status", "error", "min_distance",
                 "operator_effort"]


def unit_row(run, d_u, F_u, d, effort):
    return {"run": run, DU: d_u, FU: F_u, "random_seed": "0", "status": "ok", "error": "",
            "min_distance": repr(d), "operator_effort": repr(effort)}


UNIT_ROWS = [unit_row("r1", "0.0605", "1.0", 0.0584, 10.0),
             unit_row("r2", "0.0605", "5.0", 0.0598, 30.0),
             unit_row("r3", "0.064", "1.0", 0.0584, 12.0),
             unit_row("r4", "0.064", "5.0", 0.0596, 40.0)]


@pytest.mark.parametrize("field, label, scale", [
    (DU, "d_u, every pair (mm)", 1000.0),
    ("interference.default.F_u", "F_u, every pair (N)", 1.0),
    ("interference.pairs[1,3].d_l", "d_l of pair 1-3 (mm)", 1000.0),
    ("admittance.mass", "admittance mass M (kg)", 1.0),
    ("limits.max_velocity", "speed limit (m/s)", 1.0),
    ("sensor.filter_window", "sensor filter window (samples)", 1.0),
    ("initial_position[2]", "start z (mm)", 1000.0),
    ("random_seed", "random seed", 1.0),
    ("some.new_field", "some.new_field", 1.0),  # unknown: its path, no unit invented
])
def test_field_axes_have_readable_labels_and_units(field, label, scale):
    assert sp.field_axis(field) == (label, scale)


def test_the_heatmap_shows_distances_in_one_unit_on_labelled_axes():
    fig = sp.figure_heatmap(UNITS_COLUMNS, UNIT_ROWS, "min_distance")
    ax, bar = fig.axes
    assert ax.get_xlabel() == "d_u, every pair (mm)" and ax.get_ylabel() == "F_u, every pair (N)"
    # d_u values 0.0605 and 0.064 m, drawn in mm like the colour bar's distances.
    assert [t.get_text() for t in ax.get_xticklabels()] == ["60.5", "64"]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["1", "5"]
    assert bar.get_ylabel() == "closest approach of any pair (mm)"
    np.testing.assert_allclose(ax.images[0].get_array(), [[58.4, 58.4], [59.8, 59.6]])


def test_the_metric_against_a_field_and_the_pareto_front_speak_in_units():
    fig = sp.figure_metric_vs_axis(UNITS_COLUMNS, UNIT_ROWS, "min_distance", DU)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "d_u, every pair (mm)"
    assert ax.get_ylabel() == "closest approach of any pair (mm)"
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    assert sorted(lines) == ["F_u = 1 N", "F_u = 5 N"]
    np.testing.assert_allclose(lines["F_u = 5 N"].get_xdata(), [60.5, 64.0])  # mm
    fig = sp.figure_pareto(UNITS_COLUMNS, UNIT_ROWS)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "operator effort, integral of |F_H| (N s), smaller is better"
    # The front: r1 (10 N s, 58.4 mm) and r2 (30 N s, 59.8 mm); r3, r4 are dominated. Its
    # points are numbered from the least effort, the key beside the plot says what each swept.
    assert sorted(t.get_text() for t in ax.texts if t.get_gid() == "front label") == ["1", "2"]
    key, = [t for t in ax.texts if t.get_gid() == "front key"]
    assert key.get_text().split("\n") == ["The front's runs", "1: d_u 60.5 mm, F_u 1 N",
                                           "2: d_u 60.5 mm, F_u 5 N"]


def test_a_cell_without_an_ok_run_says_how_its_runs_ended():
    rows = UNIT_ROWS[:3] + [dict(UNIT_ROWS[3], status="fault", error="stopped",
                                 min_distance="0.05")]
    fig = sp.figure_heatmap(UNITS_COLUMNS, rows, "min_distance")
    assert "fault" in [t.get_text() for t in fig.axes[0].texts]


@pytest.mark.parametrize("dpi", [90, 110])  # the figure's own, and plot_sweep's PNGs
def test_every_pareto_label_stays_inside_the_frame(dpi):
    # Issue 27: the label of the front's last point, the rightmost and topmost run, ran over
    # the frame. As drawn (at the figure's dpi and at the PNGs'), every label's box lies
    # inside the axes.
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    pts = {"A": (1, 1), "B": (2, 3), "C": (3, 2), "D": (4, 4), "E": (2, 1)}
    rows = [row(k, "1", "1", 0, d, e) for k, (e, d) in pts.items()]
    fig = sp.figure_pareto(COLUMNS, rows)
    fig.set_dpi(dpi)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    ax = fig.axes[0]
    frame = ax.get_window_extent(canvas.get_renderer())
    labels = [t for t in ax.texts if t.get_gid() == "front label"]
    assert [t.get_text() for t in labels] == ["1", "2", "3"]  # A, B, D: the front
    for label in labels:
        box = label.get_window_extent(canvas.get_renderer())
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1, (box, frame)
        assert frame.y0 <= box.y0 and box.y1 <= frame.y1, (box, frame)


def _boxes(fig, texts):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return [t.get_window_extent(canvas.get_renderer()) for t in texts]


def test_the_pareto_front_s_numbers_never_overlap_on_a_dense_front():
    # Issue 32: exp2_du_Fu's front starts with two runs 0.4 N s apart at 58.42 mm (d_u 60.5
    # and 61 mm at F_u 1 N), and their labels were written over each other. Here eight front
    # points, each 0.2 N s and 0.01 mm from the next, on an axis spanning 40 N s: their
    # numbers' boxes, as drawn, overlap neither each other nor the frame.
    pts = {f"F{k}": (10.0 + 0.2 * k, 0.05842 + 1e-5 * k) for k in range(8)}
    pts["far"] = (50.0, 0.0600)
    rows = [row(k, "1", "1", 0, d, e) for k, (e, d) in pts.items()]
    assert len(sp.pareto_front(rows)) == 9
    fig = sp.figure_pareto(COLUMNS, rows)
    ax = fig.axes[0]
    labels = [t for t in ax.texts if t.get_gid() == "front label"]
    assert [t.get_text() for t in labels] == [str(k) for k in range(1, 10)]
    boxes = _boxes(fig, labels)
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not a.overlaps(b), (a, b)


def test_lines_against_a_field_that_coincide_stay_distinguishable():
    # F_u = 1..4 N give the same distance at every d_u in exp2_du_Fu: their lines lay exactly
    # on top of each other. Each line its own marker and dash; drawn in order, each later
    # one above (zorder) and smaller than the one before, hollow, so those below stay seen.
    rows = [unit_row(f"r{k}{j}", d_u, f"{F_u:.1f}", 0.0584, 10.0)
            for k, F_u in enumerate((1.0, 2.0, 3.0, 4.0)) for j, d_u in
            enumerate(("0.0605", "0.061", "0.062"))]
    fig = sp.figure_metric_vs_axis(UNITS_COLUMNS, rows, "min_distance", DU)
    lines = [ln for ln in fig.axes[0].get_lines() if ln.get_label().startswith("F_u")]
    assert len(lines) == 4
    assert len({(ln.get_marker(), ln.get_linestyle()) for ln in lines}) == 4
    sizes = [ln.get_markersize() for ln in lines]
    assert sizes == sorted(sizes, reverse=True) and len(set(sizes)) == 4
    orders = [ln.get_zorder() for ln in lines]
    assert orders == sorted(orders) and len(set(orders)) == 4
    assert all(ln.get_markerfacecolor() == "none" for ln in lines)


@pytest.mark.parametrize("metric", NUMERIC_METRICS)
def test_every_metric_has_a_readable_name_and_its_unit_in_titles(metric):
    # No raw column name in a title: every metric that ranks runs is named (METRIC_NAMES),
    # with its unit from METRICS (m drawn as mm), and the field swept with its unit.
    assert metric in sp.METRIC_NAMES
    rows = [dict(r, **{metric: "0.5"}) for r in UNIT_ROWS]
    fig = sp.figure_metric_vs_axis(UNITS_COLUMNS + [metric], rows, metric, FU)
    title = fig.axes[0].get_title()
    unit = METRICS[metric][0]
    shown = {"m": "mm"}.get(unit, unit)
    name = sp.METRIC_NAMES[metric]
    assert title.startswith(f"{name} ({shown})" if shown != "-" else name), title
    assert "against F_u, every pair (N)" in title
    assert metric not in title.replace(name, "")
