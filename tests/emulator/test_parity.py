"""A lockstep rehearsal reproduces the simulation: one test per row of the parity table of
docs/on_the_robot.md (scripts/bench/parity_table.py, cdpm_drake/emulator/parity.py), over a
shorter run. exp1-3 x {the default method, the paper's, full pose with tension control under
each tension sensor} x {UDP, CANopen}: `cdpm run --lockstep` against the dynamic emulator in
lockstep (`ramp_time: 0`) versus `cdpm simulate` of the same scenario on the dynamic plant,
judged on the emulator's truth: the same end (a fault within 10 ms), the smallest true
tension within 0.5 N, the largest within 5 %, the true closest approach within 0.5 mm, the
true path within 1 mm (the tolerances the rehearsal promises; the reference is the
simulation's ground truth, computed here, never a stored number).

DURATION below: the docs' table's 3 s, which keeps this file under 1.5 minutes on 2 cores
(measured: see DURATION's comment)."""

import numpy as np
import pytest

from cdpm_drake.emulator import parity

# s of each run: the docs' table's own, so that each test is one of its rows. Measured on
# this 2-core host (shared with another test run, load average 3): the whole file in 79 s
# (1 s runs: 44 s); a UDP row rehearses about 2 simulated seconds a second, a CANopen row
# (python-can's virtual bus, 7 drives and a force node a SYNC) about one; one simulation
# per (experiment, setting) is shared by both buses.
DURATION = 3.0
ROWS = [pytest.param(e, s, b, id=f"{e}-{s}-{b}".replace(" ", "").replace(",", "_"))
        for e, s, b in parity.rows() if not parity.unsupported(s, b)]
_simulations = {}


def _simulation(experiment, setting):
    """`cdpm simulate` of the row's scenario, once for both buses."""
    key = (experiment, setting)
    if key not in _simulations:
        _simulations[key] = parity.simulated(parity.scenario_of(experiment, setting), DURATION)
    return _simulations[key]


@pytest.mark.parametrize("experiment, setting, bus", ROWS)
def test_the_lockstep_rehearsal_matches_the_simulation(experiment, setting, bus):
    if bus == "canopen":
        pytest.importorskip("can")
    r = parity.parity(experiment, setting, bus, DURATION,
                      sim=_simulation(experiment, setting))
    assert r["same_end"], (r["end_sim"], r["fault_sim"], r["end_run"], r["fault_run"])
    tol = parity.TOLERANCES
    assert abs(r["min_tension"]) <= tol["min_tension"], r
    assert abs(r["max_tension"]) <= tol["max_tension"], r
    assert abs(r["closest"]) <= tol["closest"], r
    assert r["path"] <= tol["path"], r
    # A path within 1 mm of a platform at rest says nothing: each experiment moves it more
    # than 1 cm (the hand, or exp1's scripted target).
    assert r["moved"] > 0.01, r


def test_the_comparison_catches_a_rehearsal_off_the_simulation():
    """compare() on a made-up truth 2 mm off the simulation's path, 1 N lower in tension and
    ending on a fault 20 ms after the simulation's: each figure is the offset put in, and
    nothing passes (the tolerances are 1 mm, 0.5 N, 10 ms)."""
    t = np.arange(0.0, 0.1001, 0.002)
    p = np.stack([t, 0 * t, 0 * t], 1)
    d = np.full((len(t), 2), 0.05)
    sim = dict(time=t, p_true=p, tensions=np.full((len(t), 7), 10.0), pair_distances_true=d,
               ending=np.array("fault"), fault_time=np.array(0.08))
    truth = dict(plant_time=t, p_true=p + [0.0, 0.002, 0.0], tensions=np.full((len(t), 7), 9.0),
                 pair_distances_true=d)
    log = dict(ending=np.array("fault"), fault_time=np.array(0.1))
    r = parity.compare(sim, log, truth)
    assert not r["same_end"] and not r["passed"]
    assert r["min_tension"] == pytest.approx(-1.0)
    assert r["max_tension"] == pytest.approx(-0.1)  # 9 / 10 - 1
    assert r["path"] == pytest.approx(0.002)
    assert r["closest"] == pytest.approx(0.0)
    log["fault_time"] = np.array(0.085)  # 5 ms: the same end; the path still 2 mm off
    r = parity.compare(sim, log, truth)
    assert r["same_end"] and not r["passed"]


def test_canopen_rows_with_load_cells_are_refused_by_the_plant():
    """The table's n/a rows: CiA 402 drives measure no cable tension but their torque, so
    `plant: !CanopenReels {tension_sensor: load_cell}` is refused, naming the field."""
    from cdpm_drake.hardware.canopen_config import CanopenReels, check_canopen_reels

    assert parity.unsupported("full+tc, load cells", "canopen")
    with pytest.raises(ValueError, match=r"tension_sensor must be one of .*'load_cell'"):
        check_canopen_reels(CanopenReels(tension_sensor="load_cell"), 7, 0.002)


def test_the_docs_table_has_every_row_and_the_script_writes_only_its_block(tmp_path):
    """docs/on_the_robot.md's parity table (scripts/bench/parity_table.py --write-docs) has
    one row per (experiment, setting, bus) of parity.rows(), its n/a rows exactly the
    unsupported ones; the script replaces its marked block and nothing else, and refuses a
    page without the markers."""
    from helpers_scripts import load_script

    script = load_script("bench/parity_table.py")
    page = script.DOC.read_text()
    block = page.split(script.START)[1].split(script.END)[0]
    table = [line.split("|")[1:4] for line in block.splitlines()
             if line.startswith("| exp") and not line.startswith("| experiment")]
    assert [tuple(c.strip() for c in cells) for cells in table] == parity.rows()
    assert sum("n/a" in line for line in block.splitlines()) == sum(
        bool(parity.unsupported(s, b)) for _, s, b in parity.rows())
    doc = tmp_path / "page.md"
    doc.write_text(f"before\n{script.START}\nold\n{script.END}\nafter\n")
    script.write_docs("new table", doc)
    assert doc.read_text() == f"before\n{script.START}\nnew table\n{script.END}\nafter\n"
    doc.write_text("no markers\n")
    with pytest.raises(ValueError, match="no <!-- parity table -->"):
        script.write_docs("x", doc)
