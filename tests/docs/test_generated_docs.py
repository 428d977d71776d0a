"""The simulation-derived numbers and pictures of README.md and docs/ are what the code gives
today. scripts/tools/regenerate_docs.py writes them: numbers into the pages' marked blocks
(`<!-- generated: NAME -->...<!-- /generated -->`), pictures with the numbers they show as PNG
metadata. Here the cheap blocks are recomputed whole, the costly tables row by row for a
sample, each picture's numbers for a sample of what it shows; a run, a retune or a fix that
moves a number fails this test until the script is rerun and its output committed.

Machine-dependent text (real-time factors, written as measured with date and machine) is not
compared. The reference for every number is a fresh simulation of the current code (the same
runs the script makes), never the numbers the pages hold."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from helpers_docs import guide_text, page
from helpers_scripts import load_script

REPO = Path(__file__).resolve().parents[2]


def _generator():
    return load_script("tools/regenerate_docs.py")


gen = _generator()
RUNS = gen.Runs()  # every test of this file shares the simulations
BLOCKS = {b.name: b for b in gen.BLOCKS}
# Recomputed whole: a few 30 s runs of the kinematic plant and three of the dynamic plant.
WHOLE = ("readme_exp2_promise", "readme_exp2_paper", "readme_exp2_tension",
         "readme_exp2_tension_none", "robots_shipped_holding", "robots_paper_share",
         "dynamic_kinematic_closest", "dynamic_braking_tension", "dynamic_exp2_smallest")
# Recomputed for a sample of rows (the whole tables take ~1 min): experiment 2's three
# controllers on the dynamic plant and exp3's open loop (its slack and fault), one hand of the
# damping benchmark under every sensor.
SAMPLED = {"dynamic_experiments": [("exp2_interaction", "full pose"),
                                   ("exp2_interaction", "length loop"),
                                   ("exp2_interaction", "open loop"),
                                   ("exp3_two_pairs", "open loop")],
           "dynamic_damping_table": ["exp2 corner 20 N"]}
# Rendered from their picture's numbers (checked against runs in test_sweep_pictures_...).
FROM_PICTURES = ("sweep_exp2_numbers", "sweep_exp2_dynamic_numbers")


def _block(name):
    return gen.blocks_of(page(BLOCKS[name].page))[name]


def test_every_block_of_the_pages_is_the_scripts_and_each_is_checked_here():
    found = {}
    for path in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        for name in gen.blocks_of(path.read_text()):
            assert name not in found, f"{name} in {found.get(name)} and {path.name}"
            found[name] = path
    assert set(found) == set(BLOCKS), set(found) ^ set(BLOCKS)
    for name, block in BLOCKS.items():
        assert found[name] == gen.page_path(block.page), name
    assert set(WHOLE) | set(SAMPLED) | set(FROM_PICTURES) == set(BLOCKS)


def test_measured_text_is_free_and_the_rest_is_literal():
    rendered = f"| exp2 | 2.75 | {gen.measured('13x')} |"
    assert gen.pattern(rendered).fullmatch("| exp2 | 2.75 | 21x |")
    assert not gen.pattern(rendered).fullmatch("| exp2 | 2.76 | 13x |")
    assert gen.written(rendered) == "| exp2 | 2.75 | 13x |"


@pytest.mark.parametrize("name", WHOLE)
def test_a_cheap_block_is_what_the_code_gives(name):
    rendered = BLOCKS[name].render(RUNS)
    assert gen.pattern(rendered).fullmatch(_block(name)), (
        f"{name} is stale: the code gives {gen.written(rendered)!r}; run python "
        f"scripts/tools/regenerate_docs.py --only {name}")


@pytest.mark.parametrize("name, key", [(n, k) for n, keys in SAMPLED.items() for k in keys])
def test_a_sampled_row_of_a_table_is_what_the_code_gives(name, key):
    block = BLOCKS[name]
    assert key in block.rows
    line = block.row(RUNS, key)
    assert any(gen.pattern(line).fullmatch(shown) for shown in _block(name).splitlines()), (
        f"{name}: no row {gen.written(line)!r}; run python scripts/tools/regenerate_docs.py "
        f"--only {name}")


@pytest.mark.parametrize("name", FROM_PICTURES)
def test_a_sweeps_prose_is_rendered_from_its_pictures_numbers(name):
    rendered = BLOCKS[name].render(RUNS)
    assert gen.written(rendered) == _block(name), name


def _linked_pictures():
    """(page, picture path) of every PNG a page of the guide shows."""
    out = []
    for path in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        for target in re.findall(r"!\[[^\]]*\]\(([^)\s]+\.png)\)", path.read_text()):
            out.append((path.name, (path.parent / target).resolve()))
    return out


def test_every_picture_the_guide_shows_was_written_by_the_script():
    # The diagrams (diagrams/*.svg) are drawn by `cdpm diagram` from the code, not from a run.
    shown = _linked_pictures()
    assert len({p for _, p in shown}) == len(gen.PICTURES), shown
    for where, picture in shown:
        assert picture.exists(), (where, picture)
        meta = gen.read_picture(picture)
        assert meta.get("script") == gen.SCRIPT, (where, picture.name, "not the script's")
        assert meta["name"] == picture.name and picture.name in gen.PICTURES, picture.name


@pytest.mark.parametrize("file, scenario, kind", [
    ("exp1_distances.png", "exp1_no_interaction", "distances"),
    ("exp2_trajectory.png", "exp2_interaction", "trajectory")])
def test_a_run_pictures_numbers_are_the_runs(file, scenario, kind):
    numbers = gen.read_picture(gen.DOCS / file)["numbers"]
    log = RUNS(scenario).log
    if kind == "distances":  # from the log directly: each active pair's smallest distance
        near = np.asarray(log["active"]).any(axis=0)
        if not near.any():  # none came within d_u: the figure draws the closest pair
            near = np.arange(near.size) == np.argmin(log["pair_distances"].min(axis=0))
        expected = {f"{i}-{j}": round(1000 * float(log["pair_distances"][:, k].min()), 2)
                    for k, (i, j) in enumerate(log["pairs"]) if near[k]}
        assert expected and numbers == expected
    else:
        assert numbers["lower_mm"] == [round(float(v), 1) for v in 1000 * log["p"].min(axis=0)]
        assert numbers["upper_mm"] == [round(float(v), 1) for v in 1000 * log["p"].max(axis=0)]


def test_the_workspace_pictures_numbers_are_the_robots():
    from cdpm_drake.config import load_resolved_scenario

    resolved = load_resolved_scenario("exp2_interaction")
    expected = gen.workspace_numbers(resolved, RUNS("exp2_interaction").log["p"])
    for file in ("workspace_wrench_exp2.png", "workspace_interference_exp2.png"):
        assert gen.read_picture(gen.DOCS / file)["numbers"] == expected, file


@pytest.mark.parametrize("file, cells", [
    ("sweep_exp2_du_Fu_heatmap.png", [(0.0605, 1.0), (0.064, 5.0)]),
    ("sweep_exp2_dynamic_du_Fu_heatmap.png", [(0.0605, 5.0)])])
def test_sweep_pictures_numbers_are_the_runs_of_their_cells(file, cells):
    from cdpm_drake.runs.sweep.run_task import execute_run, tasks_for
    from cdpm_drake.runs.sweep.variants import load_sweep

    numbers = gen.read_picture(gen.DOCS / file)["numbers"]
    sweep = load_sweep(numbers["sweep"])
    du, fu = "interference.default.d_u", "interference.default.F_u"
    assert len(numbers["runs"]) == len(sweep.variants)
    for d_u, F_u in cells:
        shown = next(r for r in numbers["runs"] if r[du] == d_u and r[fu] == F_u)
        variant = next(v for v in sweep.variants if v.run == shown["run"])
        row = execute_run(tasks_for([variant])[0])
        assert row["status"] == shown["status"] == "ok", row["error"]
        for metric in gen.SWEEP_METRICS:
            if metric in shown:
                assert math.isclose(float(row[metric]), shown[metric], rel_tol=1e-6,
                                    abs_tol=1e-9), (file, d_u, F_u, metric)


def test_the_dynamic_sweeps_two_pictures_show_the_same_runs():
    tension = gen.read_picture(gen.DOCS / "sweep_exp2_dynamic_du_Fu_min_tension.png")["numbers"]
    distance = gen.read_picture(gen.DOCS / "sweep_exp2_dynamic_du_Fu_heatmap.png")["numbers"]
    assert tension["metric"] == "min_tension" and distance["metric"] == "min_distance_true"
    assert tension["runs"] == distance["runs"]


def test_the_guide_holds_no_stale_marker():
    # A block left half-written (an opening marker without its end) would hide from blocks_of.
    text = guide_text()
    assert text.count("<!-- generated:") == text.count("<!-- /generated -->")
