"""The committed graphviz of the controller (diagrams/*.dot) must match the code.

Regenerate with `cdpm diagram` when a block or a connection changes."""

import dataclasses
from pathlib import Path


from cdpm_drake.cli import main
from cdpm_drake.diagram import BuildOptions, PLANT_PORTS, build_diagram
from cdpm_drake.hardware.config import HardwareReels
from cdpm_drake.scenario import SimulatedReels, load_scenario
from cdpm_drake.views.diagram_graph import stable_graphviz

DIAGRAMS = Path(__file__).resolve().parent.parent / "diagrams"


def test_committed_dot_files_are_up_to_date(tmp_path):
    assert main(["diagram", "--out", str(tmp_path), "--no-svg"]) == 0
    for name in ("controller_simulated", "controller_hardware", "controller_dynamic",
                 "plant_dynamic"):
        fresh = (tmp_path / f"{name}.dot").read_text()
        committed = (DIAGRAMS / f"{name}.dot").read_text()
        assert fresh == committed, (f"diagrams/{name}.dot is out of date: run `cdpm diagram` "
                                    "and commit the result")
        assert (DIAGRAMS / f"{name}.svg").stat().st_size > 1000


def test_graphviz_text_is_stable_across_builds():
    # Drake numbers nodes after system ids, which grow with every system the process builds;
    # the committed files must not depend on that.
    scenario = load_scenario("exp2_interaction")
    first = stable_graphviz(build_diagram(scenario, BuildOptions(loggers=False)))
    build_diagram(scenario)  # more systems created in between
    second = stable_graphviz(build_diagram(scenario, BuildOptions(loggers=False)))
    assert first == second


def _graph(diagram):
    """{system name: (input port names, output port names)} and the set of connections."""
    systems = {s.get_name(): (
        tuple(s.get_input_port(k).get_name() for k in range(s.num_input_ports())),
        tuple(s.get_output_port(k).get_name() for k in range(s.num_output_ports())))
        for s in diagram.GetSystems()}
    edges = {(src_sys.get_name(), src_sys.get_output_port(src_k).get_name(),
              dst_sys.get_name(), dst_sys.get_input_port(dst_k).get_name())
             for (dst_sys, dst_k), (src_sys, src_k) in diagram.connection_map().items()}
    return systems, edges


def test_simulated_and_hardware_diagrams_differ_only_in_the_plant():
    scenario = load_scenario("exp2_interaction")
    sim = build_diagram(dataclasses.replace(scenario, plant=SimulatedReels()))
    hw = build_diagram(dataclasses.replace(scenario, plant=HardwareReels()))
    sim_systems, sim_edges = _graph(sim)
    hw_systems, hw_edges = _graph(hw)
    assert sim_systems.keys() == hw_systems.keys()
    assert sim_edges == hw_edges
    for name in sim_systems:
        assert sim_systems[name] == hw_systems[name], name
    # The plant: same name, same ports, different implementation.
    assert set(sim_systems["reels"][0] + sim_systems["reels"][1]) == set(PLANT_PORTS)
    assert type(sim.GetSubsystemByName("reels")) is not type(hw.GetSubsystemByName("reels"))
