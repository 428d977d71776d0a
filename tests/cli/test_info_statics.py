"""`cdpm info`'s statics (issue 18): the wrench-matrix rank, the share of the box that holds
the level platform against an LP on the same grid, a scenario's robot with its swaps, start
and path, --swaps, and the workspace pictures (--plot) with their data read back.

References: scipy's linprog (HiGHS) for t*; the scenario's own simulation for the path;
interference.pair_distances for the interference-free picture."""

import re

import numpy as np
import pytest
from conftest import highs_t_star

from cdpm_drake import cli
from cdpm_drake.kernels.interference import pair_distances
from cdpm_drake.robot import load_robot
from cdpm_drake.config import load_scenario, scenario_robot
from cdpm_drake.kernels.tension import gravity_wrench, step_grid, wrench_matrix
from cdpm_drake.robot.statics import holding_tension
from cdpm_drake.views import workspace_plots as wp


def newtons(text):
    """A t* as cdpm info prints it: '12.34' (N), '+inf' or '-inf' (with words after)."""
    return {"+inf": np.inf, "-inf": -np.inf}.get(text, None) or float(text)


T_STAR = r"([-+]?inf|-?[0-9.]+)"


def run_info(capsys, *args):
    code = cli.main(["info", *args])
    out, err = capsys.readouterr()
    return code, out, err


def share_line(out):
    m = re.search(r"held with every cable >= 5 N on ([0-9.]+) % of the workspace box "
                  r"\(([0-9.]+) cm grid from the lower corner: (\d+) x (\d+) x (\d+) points\)",
                  out)
    assert m, out
    return float(m[1]), float(m[2]), tuple(int(m[k]) for k in (3, 4, 5))


@pytest.mark.parametrize("name", ["paper_7cable", "cube_8cable"])
def test_info_prints_rank_and_the_share_an_lp_finds_on_the_same_grid(capsys, name):
    # A 25 cm grid keeps HiGHS's 1000-odd LPs quick; the grid is the one the line describes.
    code, out, err = run_info(capsys, name, "--grid", "0.25")
    assert code == 0, err
    robot = load_robot(name)
    share, step, counts = share_line(out)
    pts = step_grid(robot.workspace.lower, robot.workspace.upper, step / 100)
    assert len(pts) == np.prod(counts)
    w = gravity_wrench(robot.dynamics.mass)
    t = np.array([highs_t_star(wrench_matrix(robot, p), w) for p in pts])
    assert share == pytest.approx(100 * np.mean(t >= 5.0), abs=0.05)
    s = np.linalg.svd(wrench_matrix(robot, robot.workspace.center), compute_uv=False)
    rank = int(np.sum(s > 1e-9 * s[0]))
    centre = highs_t_star(wrench_matrix(robot, robot.workspace.center), w)
    m = re.search(r"wrench matrix rank at the workspace centre: (\d+)(.*); t\* there " + T_STAR,
                  out)
    assert int(m[1]) == rank == 6
    assert newtons(m[3]) == pytest.approx(centre, abs=0.006)


def test_info_of_a_scenario_shows_its_swapped_robot_start_and_path(capsys):
    code, out, err = run_info(capsys, "exp3_two_pairs", "--grid", "0.5")
    assert code == 0, err
    assert "scenario 'exp3_two_pairs': robot 'paper_7cable_swap13_swap57'" in out
    assert "swapped cables: 1-3, 5-7" in out
    robot = scenario_robot(load_scenario("exp3_two_pairs"))
    w = gravity_wrench(robot.dynamics.mass)
    start = highs_t_star(wrench_matrix(robot, [2.22, 3.22, 1.03]), w)
    m = re.search(r"at the start \[2\.22, 3\.22, 1\.03\] m: t\* " + T_STAR, out)
    assert newtons(m[1]) == pytest.approx(start, abs=0.006)
    m = re.search(r"along the scenario's path \(kinematic plant, (\d+) ticks\): smallest t\* "
                  + T_STAR + r".* at t = (\S+) s, p = \[([^\]]*)\] m", out)
    assert int(m[1]) == 15001  # 30 s at 500 Hz, both ends
    p = np.array([float(x) for x in m[4].split(",")])
    assert newtons(m[2]) == pytest.approx(highs_t_star(wrench_matrix(robot, p), w), abs=0.01)
    assert newtons(m[2]) <= start + 0.005  # the start is on the path (2 decimals printed)


def test_info_swaps_a_robots_cables(capsys):
    code, out, err = run_info(capsys, "paper_7cable", "--swaps", "1-3", "--grid", "0.5")
    assert code == 0, err
    assert "swapped cables: 1-3" in out
    b = load_robot("paper_7cable").attachments
    rows = re.findall(r"^\s*(\d+)\s+\[[^\]]*\]\s+\[([^\]]*)\]", out, re.MULTILINE)
    shown = {int(k): [float(x) for x in v.split(",")] for k, v in rows}
    np.testing.assert_allclose(shown[1], b[2], atol=5e-4)
    np.testing.assert_allclose(shown[3], b[0], atol=5e-4)


def test_info_swaps_replace_a_scenarios_swaps(capsys):
    code, out, err = run_info(capsys, "exp2_interaction", "--swaps", "5-7", "--grid", "0.5")
    assert code == 0, err
    assert "robot 'paper_7cable_swap57'" in out and "swapped cables: 5-7" in out


@pytest.mark.parametrize("swaps, message", [("1-x", "a swap is two cable numbers I-J"),
                                            ("1", "a swap is two cable numbers I-J")])
def test_info_rejects_a_malformed_swap(capsys, swaps, message):
    with pytest.raises(SystemExit) as e:
        cli.main(["info", "paper_7cable", "--swaps", swaps])
    assert e.value.code == 2 and message in capsys.readouterr().err


def test_info_rejects_a_cable_the_robot_does_not_have(capsys):
    # An option value out of range is bad usage, exit 2 (docs/running.md's exit codes; issue
    # 32: it was 1, as for a bad file).
    code, out, err = run_info(capsys, "paper_7cable", "--swaps", "1-9")
    assert code == 2 and "cannot swap cable 9" in err and "1..7" in err


def test_info_of_an_unknown_name_lists_robots_and_scenarios(capsys):
    code, out, err = run_info(capsys, "nothing_like_it")
    assert code == 1
    assert "paper_7cable" in err and "exp2_interaction" in err


def test_info_plot_writes_both_workspace_pictures(capsys, tmp_path):
    code, out, err = run_info(capsys, "exp2_interaction", "--grid", "0.5", "--plot",
                              str(tmp_path))
    assert code == 0, err
    for name in ("workspace_wrench.png", "workspace_interference.png"):
        assert f"plot: {tmp_path / name}" in out
        assert (tmp_path / name).stat().st_size > 20_000


# --- the pictures' data --------------------------------------------------------------------


def _meshes(fig):
    return [c for ax in fig.axes[:3] for c in ax.collections if hasattr(c, "get_array")
            and c.get_array() is not None and c.get_array().ndim == 2]


def test_the_wrench_picture_colours_each_slice_by_t_star():
    robot = load_robot("paper_7cable").with_swapped_attachments(1, 3)
    path = np.array([[1.56, 3.24, 1.22], [1.87, 3.68, 0.53], [1.80, 3.60, 0.60]])
    fig = wp.figure_wrench_workspace(robot, path=path, step=0.1)
    centre = wp.slice_centre(robot, path)
    np.testing.assert_allclose(centre, [1.715, 3.46, 0.875])  # its bounding box's middle
    meshes = _meshes(fig)
    assert len(meshes) == 3
    for mesh, (fixed, drawn) in zip(meshes, wp.SLICES):
        u, v, pts = wp.slice_points(robot, fixed, centre[fixed], 0.1)
        assert np.all(pts[..., fixed] == centre[fixed])
        t = np.clip(holding_tension(robot, pts), 5.0 - wp.T_BELOW, 5.0 + wp.T_ABOVE)
        np.testing.assert_allclose(np.asarray(mesh.get_array()), t, atol=1e-9)
    # The path is drawn on each slice, projected onto its two axes.
    ax = fig.axes[0]
    line = [ln for ln in ax.get_lines() if ln.get_label() == "path (projected)"][0]
    np.testing.assert_allclose(line.get_xdata(), path[:, 0])
    np.testing.assert_allclose(line.get_ydata(), path[:, 1])
    held = float(ax.get_title().split(": ")[1].split(" %")[0])
    u, v, pts = wp.slice_points(robot, 2, centre[2], 0.1)
    assert held == pytest.approx(100 * np.mean(holding_tension(robot, pts) >= 5.0), abs=0.5)


def test_the_interference_picture_colours_each_slice_by_the_closest_pairs_margin():
    robot = load_robot("paper_7cable").with_swapped_attachments(1, 3)
    d_u = 0.062
    fig = wp.figure_interference_workspace(robot, d_u=d_u, step=0.1)
    centre = robot.workspace.center
    for mesh, (fixed, drawn) in zip(_meshes(fig), wp.SLICES):
        u, v, pts = wp.slice_points(robot, fixed, centre[fixed], 0.1)
        d = pair_distances(robot, pts.reshape(-1, 3)).reshape(len(v), len(u), -1)
        np.testing.assert_allclose(np.asarray(mesh.get_array()), 1000 * (d.min(-1) - d_u),
                                   atol=1e-9)
    # Cables 1 and 3 swapped: that pair is the one within d_u (listed under the slices).
    assert "pairs within d_u: 1-3" in fig.axes[0].get_xlabel()


# --- issue 27: one grid, one warning, a cause that is true ------------------------------------


def test_info_says_each_robot_warning_once_and_on_the_grid_it_prints(capsys, tmp_path):
    # paper_7cable's attachment points before issue 18 (held on a quarter of the box), with
    # one pair ignored: loading logs both warnings; `info` says each once, in its report, and
    # the share in the statics warning is the one of the grid the report prints.
    from helpers_robots import PRE_18

    from conftest import to_yaml

    base = load_robot("paper_7cable")
    spec = {"name": "pre18", "reels": base.reels.tolist(), "attachments": PRE_18,
            "workspace": {"lower": base.workspace.lower.tolist(),
                          "upper": base.workspace.upper.tolist()},
            "ignore_pairs": [[1, 2]]}
    path = tmp_path / "pre18.yaml"
    path.write_text(to_yaml(spec) + "\n")
    code, out, err = run_info(capsys, str(path), "--grid", "0.25")
    assert code == 0, err
    assert "workspace box" not in err and "skips" not in err, err
    assert out.count("warning: pre18: the cables hold the level platform") == 1, out
    assert out.count("pair (1, 2) skipped: listed in ignore_pairs") == 1, out
    share, step, _ = share_line(out)
    robot = load_robot(path)
    pts = step_grid(robot.workspace.lower, robot.workspace.upper, 0.25)
    w = gravity_wrench(robot.dynamics.mass)
    lp = 100 * np.mean([highs_t_star(wrench_matrix(robot, p), w) >= 5.0 for p in pts])
    assert share == pytest.approx(lp, abs=0.05)
    assert (f"with every cable >= 5 N on only {lp:.0f} % of the workspace box (the same 25 cm "
            "grid); the moment balance fails") in out, out


def test_info_of_exp2_blames_its_swap_not_the_robot_file(capsys):
    # Experiment 2 swaps cables 1 and 3 (to make them interfere); the robot file's attachment
    # points hold the platform on most of the box without that swap. Shares by HiGHS on the
    # report's grid.
    code, out, err = run_info(capsys, "exp2_interaction", "--grid", "0.25")
    assert code == 0, err
    base = load_robot("paper_7cable")
    swapped = scenario_robot(load_scenario("exp2_interaction"))
    pts = step_grid(base.workspace.lower, base.workspace.upper, 0.25)
    w = gravity_wrench(base.dynamics.mass)

    def lp(robot):
        return 100 * np.mean([highs_t_star(wrench_matrix(robot, p), w) >= 5.0 for p in pts])

    held, held_unswapped = lp(swapped), lp(base)
    assert held < 50.0 <= held_unswapped
    (warning,) = [line for line in out.splitlines() if "warning:" in line]
    assert warning.endswith(
        f"with every cable >= 5 N on only {held:.0f} % of the workspace box (the same 25 cm "
        f"grid); the swapped cables (1-3) are the cause: robot 'paper_7cable' without the "
        f"swaps is held on {held_unswapped:.0f} % of it"), warning
    assert "attachment points" not in warning


def test_an_infinite_t_star_where_the_rank_is_low_says_what_it_holds(capsys, tmp_path):
    # The README's four-cable robot: at its box centre the four cables' lines of action meet
    # (numpy: rank 3), the weight is in W's range and a positive nullspace vector raises every
    # tension (HiGHS: unbounded, +inf), yet the platform turns under any moment about y.
    from conftest import to_yaml

    spec = {"name": "four", "reels": [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [2.0, 3.0, 0.0],
                                      [2.0, 1.5, 3.0]],
            "attachments": [[-0.1, -0.1, 0.0], [0.1, -0.1, 0.0], [0.0, 0.1, 0.0],
                            [0.0, 0.0, 0.1]],
            "workspace": {"lower": [1.5, 1.0, 0.5], "upper": [2.5, 2.0, 2.0]}}
    path = tmp_path / "four.yaml"
    path.write_text(to_yaml(spec) + "\n")
    robot = load_robot(path)
    c = robot.workspace.center
    W = wrench_matrix(robot, c)
    s = np.linalg.svd(W, compute_uv=False)
    assert int(np.sum(s > 1e-9 * s[0])) == 3
    assert highs_t_star(W, gravity_wrench(robot.dynamics.mass)) == np.inf
    code, out, err = run_info(capsys, str(path), "--grid", "0.25")
    assert code == 0, err
    line = next(x for x in out.splitlines() if "rank at the workspace centre" in x)
    assert "t* there +inf for the weight alone" in line and "rank 3 < 6 there" in line, line
    assert "any floor holds" not in out


def test_info_says_a_box_beyond_the_reels_frame_once(capsys, tmp_path, valid_spec,
                                                     write_robot):
    valid_spec["workspace"] = {"lower": [1.0, 0.5, 0.5], "upper": [4.5, 2.5, 2.5]}
    path = write_robot(valid_spec)
    code, out, err = run_info(capsys, str(path), "--grid", "0.5")
    assert code == 0, err
    assert "reels' frame" not in err
    assert out.count("warning: tetra_4cable: the workspace box's upper x face, "
                     "workspace.upper[0] = 4.5 m, lies beyond the reels' frame") == 1, out

# --- issue 27, part B: the pictures' layout and scales ---------------------------------------


def test_the_interference_scale_comes_from_the_slices_margins():
    # Issue 27: a +-20 mm scale hid exp2's 2.5 mm of margin (a pale green). Now red is the
    # slices' most negative margin and green their largest, 0 (d_u) the yellow middle; the
    # margins computed here from interference.pair_distances on the same slices.
    robot = load_robot("paper_7cable").with_swapped_attachments(1, 3)
    path = np.array([[1.56, 3.24, 1.22], [1.87, 3.68, 0.53], [1.28, 3.60, 1.04]])
    d_u = 0.062
    fig = wp.figure_interference_workspace(robot, d_u=d_u, path=path, step=0.1)
    centre = wp.slice_centre(robot, path)
    margins = []
    for fixed, _ in wp.SLICES:
        u, v, pts = wp.slice_points(robot, fixed, centre[fixed], 0.1)
        margins.append(1000 * (pair_distances(robot, pts.reshape(-1, 3)).min(-1) - d_u))
    lo, hi = min(m.min() for m in margins), max(m.max() for m in margins)
    assert 0.5 < hi < 5.0 and lo < -10.0  # a few mm of margin, tens within d_u
    for mesh in _meshes(fig):
        norm = mesh.norm
        assert (norm.vmin, norm.vcenter, norm.vmax) == pytest.approx((lo, 0.0, hi))
    # The largest margin gets the scale's full green, the deepest the full red.
    assert float(norm(hi)) == pytest.approx(1.0) and float(norm(lo)) == pytest.approx(0.0)
    assert float(norm(0.5 * hi)) == pytest.approx(0.75)
    # Ticks on both sides of 0, within the scale.
    ticks = fig.axes[-1].get_yticks()
    assert (ticks > 0).sum() >= 2 and (ticks < 0).sum() >= 2
    assert lo <= ticks.min() and ticks.max() <= hi


@pytest.mark.parametrize("which", ["wrench", "interference"])
def test_the_colour_bar_stands_beside_the_slices_and_the_legend_below_them(which):
    # Issue 27: the wrench map's legend covered the 5 N line, its colour bar stood far off
    # (equal-aspect slices shrunk inside wide axes: measured 4.8 % of the figure's width from
    # the last slice). As drawn: the colour bar starts within 2 % of the figure's width after
    # the last slice, the slices as close to each other, and the path's legend is the
    # figure's, below every slice.
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    robot = load_robot("paper_7cable").with_swapped_attachments(1, 3)
    path = np.array([[1.56, 3.24, 1.22], [1.87, 3.68, 0.53]])
    fig = (wp.figure_wrench_workspace(robot, path=path, step=0.1) if which == "wrench" else
           wp.figure_interference_workspace(robot, d_u=0.062, path=path, step=0.1))
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    slices, bar = fig.axes[:3], fig.axes[3]
    drawn = [ax.get_position(original=False) for ax in slices]  # after the equal aspect
    assert 0 < bar.get_position().x0 - drawn[-1].x1 < 0.02
    for left, right in zip(drawn, drawn[1:]):
        assert 0 < right.x0 - left.x1 < 0.06  # the gap holds the right one's tick labels
    assert all(ax.get_legend() is None for ax in slices)
    legend = fig.legends[0].get_window_extent(renderer)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["path (projected)", "start"]
    assert all(legend.y1 <= ax.get_tightbbox(renderer).y0 for ax in slices)


def test_info_of_a_robot_whose_statics_need_a_solver_everywhere_uses_a_coarse_grid(
        capsys, tmp_path):
    # Every attachment at the platform's centre: the wrench matrix has rank 3, a nullspace of
    # 4 dimensions, so t* needs Clarabel at every point (robot.statics.solver_points), ~4 ms
    # each: the 5 cm grid's 51 x 65 x 43 = 142,545 points took minutes with no word (757 s
    # before it was stopped). Now the statics and the feasibility table use the coarse grids
    # (11^3 and 5^3), said so, and the share is the one HiGHS finds on the same 11^3 points.
    from cdpm_drake.data import ROBOTS_DIR
    from cdpm_drake.kernels.tension import grid_points
    from cdpm_drake.robot.statics import solver_points

    text = (ROBOTS_DIR / "paper_7cable.yaml").read_text()
    start, end = text.index("attachments:"), text.index("# The virtual wall")
    path = tmp_path / "point.yaml"
    path.write_text(text[:start] + "attachments:\n" + "  - [0.0, 0.0, 0.0]\n" * 7 + text[end:])
    r = load_robot(path)
    grid = step_grid(r.workspace.lower, r.workspace.upper, 0.05)
    assert len(grid) == 51 * 65 * 43 and solver_points(r, grid).all()
    assert not solver_points(load_robot("paper_7cable"), grid).any()
    assert cli.main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    m = re.search(r"held with every cable >= 5 N on ([0-9.]+) % of the workspace box \(a "
                  r"coarser 11 x 11 x 11 grid, corners included: at 142,545 of the 5 cm grid's "
                  r"142,545 points t\* needs a solver, ~570 s\)", out)
    assert m, out
    coarse = grid_points(r.workspace.lower, r.workspace.upper, 11)
    t = np.array([highs_t_star(wrench_matrix(r, p), gravity_wrench(r.dynamics.mass))
                  for p in coarse])
    assert float(m.group(1)) == pytest.approx(100 * np.mean(t >= 5.0), abs=0.05)
    assert ("wrench feasibility on a coarser 5 x 5 x 5 grid (corners included: this robot's "
            "statics need a solver per point)") in out
