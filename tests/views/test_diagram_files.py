"""The committed graphviz of the controller (diagrams/*.dot) must match the code.

Regenerate with `cdpm diagram` when a block or a connection changes."""

import dataclasses
import re
from pathlib import Path

import pytest

from cdpm_drake.cli.diagram import DIAGRAMS as DIAGRAM_NAMES
from cdpm_drake.cli import main
from cdpm_drake.diagram import BuildOptions, PLANT_PORTS, build_diagram
from cdpm_drake.hardware.config import HardwareReels
from cdpm_drake.config import SimulatedReels, load_scenario
from cdpm_drake.views.diagram_graph import overview_graphviz, render_svg, stable_graphviz

DIAGRAMS = Path(__file__).resolve().parents[2] / "diagrams"


def test_committed_dot_files_are_up_to_date(tmp_path):
    assert main(["diagram", "--out", str(tmp_path), "--no-svg"]) == 0
    written = sorted(p.stem for p in tmp_path.glob("*.dot"))
    assert written == sorted(list(DIAGRAM_NAMES) + [f"{n}_overview" for n in DIAGRAM_NAMES])
    for name in written:
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
    # The tension damping (on by default) is in the real reels' diagram only: the kinematic
    # plant has no tensions to measure. Without it the two are one diagram.
    scenario = load_scenario("exp2_interaction", "{controller: {tension_damping: "
                             "{enabled: false}}}")
    sim = build_diagram(dataclasses.replace(scenario, plant=SimulatedReels()))
    hw = build_diagram(dataclasses.replace(scenario, plant=HardwareReels()))
    sim_systems, sim_edges = _graph(sim)
    hw_systems, hw_edges = _graph(hw)
    assert sim_systems.keys() == hw_systems.keys()
    assert sim_edges == hw_edges
    for name in sim_systems:
        assert sim_systems[name] == hw_systems[name], name
    # The plant: same name, same ports, different implementation.
    # Every plant measures tensions (NaN without a sensor): PLANT_PORTS gains the port once
    # the real reels' plant has it on every branch.
    assert (set(sim_systems["reels"][0] + sim_systems["reels"][1])
            == set(PLANT_PORTS) | {"tension_measured"})
    assert type(sim.GetSubsystemByName("reels")) is not type(hw.GetSubsystemByName("reels"))


# The README's column is ~880 px wide on GitHub (its content width), 660 pt at 96 px/in: an
# SVG up to that width shows at its natural size, text at the 10 pt (13 px) it was set in.
README_WIDTH_PT = 660


def _svg_size(svg: str) -> tuple[float, float]:
    width, height = re.search(r'<svg width="([\d.]+)pt" height="([\d.]+)pt"', svg).groups()
    return float(width), float(height)


def _nodes(dot: str) -> dict:
    """{node id: the text of its label} of overview_graphviz's output."""
    return {m.group(1): re.sub(r"<[^>]+>", " ", m.group(2))
            for m in re.finditer(r"^  (n\d+) \[label=<(.*)>\];$", dot, flags=re.M)}


def test_committed_overview_fits_the_readme_and_is_shown_there():
    readme = (DIAGRAMS.parent / "README.md").read_text()
    for name in ("controller_simulated_overview", "controller_hardware_overview"):
        width, height = _svg_size((DIAGRAMS / f"{name}.svg").read_text())
        # Measured: 948 x 708 pt. The controller grew from the paper's seven blocks to ten
        # (safety filter, kinetostatic block, model monitor; the position read by six):
        # graphviz needs that width, and the README's column shows it at ~70 %, the SVG at
        # full size a click away. The bound keeps it from growing further unnoticed. The
        # tension damping block between the mapping and the reels (every plant with a
        # tension_measured port): 1133 x 798 pt.
        assert width <= 1.75 * README_WIDTH_PT, (name, width)
        assert height <= 900, (name, height)
    assert "](diagrams/controller_simulated_overview.svg)" in readme
    assert "diagrams/controller_simulated.svg" in readme  # the full-depth one, linked beside


@pytest.mark.parametrize("plant", [SimulatedReels(), HardwareReels()], ids=["sim", "hw"])
def test_overview_has_every_top_level_system_and_connection_with_short_names(plant):
    scenario = dataclasses.replace(load_scenario("exp3_two_pairs"), plant=plant)
    # Unfused, so that every connection is one between the systems drawn; the fused diagram
    # (the product) draws the same (tests/systems/test_fast_calls.py).
    diagram = build_diagram(scenario, BuildOptions(loggers=False, fuse_wiring=False))
    dot = overview_graphviz(diagram)
    nodes = _nodes(dot)
    systems = diagram.GetSystems()
    # One node per block of Fig. 5 (a block whose systems were added flat is one node, see
    # diagram.flat_blocks), named as in the diagram, with its class name only.
    flat = diagram.flat_blocks
    assert {"force_sensor", "forward_kinematics", "interference_force", "admittance",
            "safety_limits"} <= flat.keys()
    in_flat = {name: block for block, info in flat.items() for name in info["systems"]}
    names = [s.get_name() for s in systems if s.get_name() not in in_flat] + list(flat)
    node_names = {int(k[1:]): next(n for n in names if n in label.split())
                  for k, label in nodes.items()}
    assert sorted(node_names.values()) == sorted(names)
    assert "cdpm_drake." not in dot and "pydrake." not in dot and "drake::" not in dot
    # One edge per connection between blocks, from an output port cell to an input port cell;
    # the connections inside a flat block are not drawn.
    edges = re.findall(r"^  n(\d+):o(\d+):s -> n(\d+):i(\d+):n(?: \[constraint=false\])?;$",
                       dot, flags=re.M)
    between = [(src, dst) for (dst, _), (src, _) in diagram.connection_map().items()
               if in_flat.get(src.get_name(), src.get_name())
               != in_flat.get(dst.get_name(), dst.get_name())]
    assert len(edges) == len(between)
    assert ({(node_names[int(s)], node_names[int(d)]) for s, _, d, _ in edges}
            == {(in_flat.get(src.get_name(), src.get_name()),
                 in_flat.get(dst.get_name(), dst.get_name())) for src, dst in between})
    index = {name: k for k, name in node_names.items()}
    # The adder's inputs carry the names of the forces it sums (eq. 22), not u0, u1, ...
    assert re.search(r">u\d+<", dot) is None
    label = nodes[f"n{index['F_d_adder']}"].split()
    assert {"F_H", "F_int"} <= set(label)
    # The simulated plant is a sub-diagram: one node that names what it holds.
    text = nodes[f"n{index['reels']}"]
    if isinstance(plant, SimulatedReels):
        # The reels' step (which also samples the simulated person) and its state.
        assert "simulated_reels" in text and "state" in text
    assert {"reel_velocity_command", "cable_lengths", "measured_force"} <= set(text.split())


def test_overview_of_any_diagram_shows_exported_ports_and_collapses_subdiagrams():
    # Independent of the controller: a diagram of Drake primitives, one of them a sub-diagram,
    # with an exported input and output.
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import Adder, Gain

    inner = DiagramBuilder()
    gain = inner.AddNamedSystem("gain", Gain(2.0, 1))
    inner.ExportInput(gain.get_input_port(), "x")
    inner.ExportOutput(gain.get_output_port(), "y")
    sub = inner.Build()
    sub.set_name("doubler")
    builder = DiagramBuilder()
    doubler = builder.AddSystem(sub)
    adder = builder.AddNamedSystem("sum", Adder(2, 1))
    builder.Connect(doubler.get_output_port(), adder.get_input_port(1))
    builder.ExportInput(doubler.get_input_port(), "command")
    builder.ExportInput(adder.get_input_port(0), "offset")
    builder.ExportOutput(adder.get_output_port(), "total")
    dot = overview_graphviz(builder.Build())
    nodes = _nodes(dot)
    assert len(nodes) == 2
    assert "doubler" in nodes["n0"] and "of gain" in nodes["n0"]
    # Input 1 of the adder receives "y"; input 0 is exported, so it keeps its own name.
    assert nodes["n1"].split()[:2] == ["u0", "y"]
    assert 'in0 [shape=cds, label="command", width=' in dot and "in0 -> n0:i0:n;" in dot
    assert "in1 -> n1:i0:n;" in dot and "n1:o0:s -> out0;" in dot
    width, _ = _svg_size(render_svg(dot))
    assert 0 < width < README_WIDTH_PT


def test_the_dynamic_plant_overview_fits_the_readme_with_the_multibody_plant_collapsed():
    # Issue 21: the MultibodyPlant's ~25 ports made this picture 2773 pt wide. Only the ports
    # in use are drawn (MAX_PORTS), and the plant's Selector is drawn as the connections it
    # makes, labelled with the piece of the signal where it is one.
    from cdpm_drake.config import DynamicReels
    from cdpm_drake.views.diagram_graph import MAX_PORTS

    plant = build_diagram(dataclasses.replace(load_scenario("exp2_interaction"),
                                              plant=DynamicReels()),
                          BuildOptions(loggers=False)).GetSubsystemByName("reels")
    mbp = plant.GetSubsystemByName("platform_plant")
    assert mbp.num_input_ports() + mbp.num_output_ports() > 20
    from cdpm_drake.cli.diagram import diagram_caption
    dot = overview_graphviz(plant, caption=diagram_caption(load_scenario("exp2_interaction")))
    assert dot == (DIAGRAMS / "plant_dynamic_overview.dot").read_text()
    width, height = _svg_size((DIAGRAMS / "plant_dynamic_overview.svg").read_text())
    assert width <= README_WIDTH_PT and height <= 900, (width, height)  # measured 348 x 432
    nodes = _nodes(dot)
    ids = {m.group(2): m.group(1) for m in re.finditer(r"^  (n\d+) \[label=<.*?<B>(\w+)</B>",
                                                        dot, flags=re.M)}
    index = {name: ids[name] for name in ("platform_plant", "cables", "reel_state")}
    label = nodes[index["platform_plant"]].split()
    # Used: the force in, the state out; the rest counted, not drawn.
    assert "applied_generalized_force" in label and "state" in label
    assert "actuation" not in label and "geometry_query" not in label
    unused_in = mbp.num_input_ports() - 1
    unused_out = mbp.num_output_ports() - 1
    assert f"+{unused_in} ports" in " ".join(label) and f"+{unused_out} ports" in " ".join(label)
    assert unused_in + 1 > MAX_PORTS  # the collapse applied, not the plain port row
    # No Selector node: its connections are drawn, each edge named by the piece it carries.
    assert "wiring" not in " ".join(nodes.values()) and "Selector" not in dot
    cables, state, mbp_node = (int(index[n][1:]) for n in ("cables", "reel_state",
                                                             "platform_plant"))
    edges = re.findall(r"^  n(\d+):o\d+:s -> n(\d+):i\d+:n(?: \[label=\" (\w+)\""
                       r"(?:, constraint=false)?\]| \[constraint=false\])?;$", dot, flags=re.M)
    assert (str(mbp_node), str(cables), "") in edges  # the state into the cables' inputs
    assert (str(cables), str(mbp_node), "generalized_force") in edges
    assert (str(cables), str(state), "") in edges  # into its input named next_reels
    assert (str(state), str(cables), "") in edges  # and back into the cables' inputs
    assert "next_reels" in nodes[index["reel_state"]].split()
    assert 'in0 [shape=cds, label="reel_velocity_command", width=' in dot
    assert f"in0 -> n{cables}:i0:n;" in dot and f"n{cables}:o0:s -> out1;" in dot


def test_overview_draws_only_the_used_ports_of_a_system_with_many():
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource, Multiplexer

    from cdpm_drake.views.diagram_graph import MAX_PORTS

    builder = DiagramBuilder()
    mux = builder.AddNamedSystem("mux", Multiplexer([1] * (MAX_PORTS + 2)))
    few = builder.AddNamedSystem("few", Multiplexer([1] * MAX_PORTS))
    one = builder.AddNamedSystem("one", ConstantVectorSource([1.0]))
    builder.Connect(one.get_output_port(), mux.get_input_port(3))
    builder.Connect(one.get_output_port(), few.get_input_port(2))
    builder.ExportInput(mux.get_input_port(5), "x5")
    builder.ExportOutput(mux.get_output_port(), "y")
    dot = overview_graphviz(builder.Build())
    nodes = _nodes(dot)
    mux_label = next(label for label in nodes.values() if " mux " in f" {label} ")
    # Inputs 3 (connected) and 5 (exported) drawn; the other MAX_PORTS of 8 counted.
    assert 'PORT="i3"' in dot and 'PORT="i5"' in dot
    assert f"+{MAX_PORTS} ports" in mux_label
    # At MAX_PORTS ports, every port is drawn, used or not.
    few_label = next(label for label in nodes.values() if " few " in f" {label} ")
    assert "ports" not in few_label and len(few_label.split()) >= MAX_PORTS + 2


# --- issue 27, part B ------------------------------------------------------------------------


def test_the_readme_counts_and_names_the_diagrams_cdpm_diagram_writes():
    # Issue 27: the README said "all eight diagrams" where ten are written. The sentence (now
    # in docs/viewing.md) names the full-depth ones and counts both kinds; both against
    # DIAGRAM_NAMES, which the test above holds to what `cdpm diagram` writes.
    flat = " ".join((DIAGRAMS.parent / "docs" / "viewing.md").read_text().split())
    m = re.search(r"`cdpm diagram` regenerates the (\w+) diagrams, (\w+) at full depth "
                  r"\(([^)]*)\) and the overview of each", flat)
    assert m, "the README's sentence on `cdpm diagram` changed"
    words = {2 * len(DIAGRAM_NAMES): m.group(1), len(DIAGRAM_NAMES): m.group(2)}
    numbers = {"four": 4, "five": 5, "six": 6, "eight": 8, "ten": 10, "twelve": 12}
    assert {n: numbers[w] for n, w in words.items()} == {n: n for n in words}
    assert re.findall(r"`(\w+)`", m.group(3)) == list(DIAGRAM_NAMES)


def test_the_full_depth_files_are_drawn_at_full_depth():
    # Issue 27: "full-depth" while the default depth collapsed the plant, so that
    # controller_dynamic.dot equalled controller_simulated.dot. Now every sub-diagram is
    # expanded: each controller's plant shows its own systems (scenario.py's plants: the
    # simulated reels and their state; the dynamic one's MultibodyPlant, cables, drives,
    # encoders); --depth 1 still collapses them.
    dynamic = (DIAGRAMS / "controller_dynamic.dot").read_text()
    simulated = (DIAGRAMS / "controller_simulated.dot").read_text()
    assert dynamic != simulated
    for part in ("platform_plant", "cables", "reel_state", "encoders"):
        assert f"name={part}" in dynamic, part
        assert f"name={part}" not in simulated, part
    assert "name=simulated_reels" in simulated
    assert "name=platform_plant" in (DIAGRAMS / "controller_full_pose.dot").read_text()
    scenario = dataclasses.replace(load_scenario("exp2_interaction"), plant=SimulatedReels())
    diagram = build_diagram(scenario, BuildOptions(loggers=False))
    assert "name=simulated_reels" not in stable_graphviz(diagram, max_depth=1)
    assert stable_graphviz(diagram) == simulated


def _overflowing_text(svg: str) -> list:
    """The texts of the SVG's nodes that do not fit their cell with 1 pt to spare on either
    side when drawn in DejaVu Sans (a browser's usual fallback for Helvetica, about a sixth
    wider; widths from matplotlib's copy of the font, independent of graphviz's estimate):
    a table cell is the polygon drawn before the text, an arrow-shaped port node's body ends
    where its point begins."""
    from cdpm_drake.views.diagram_graph import text_width

    bad = []
    for node in re.findall(r'<g id="node\d+" class="node">(.*?)</g>', svg, flags=re.S):
        cell = None
        for m in re.finditer(r'<polygon [^>]*points="([^"]+)"|<text ([^>]*)>([^<]*)</text>',
                             node):
            if m.group(1):
                xs = sorted({float(p.split(",")[0]) for p in m.group(1).split()})
                # Five distinct x: the cds arrow (its point the last); four: a rectangle.
                cell = (xs[0], xs[-2] if len(xs) == 3 else xs[-1])
                continue
            attrs, text = m.group(2), m.group(3).replace("&amp;", "&")
            x = float(re.search(r' x="([-\d.]+)"', attrs).group(1))
            size = float(re.search(r'font-size="([\d.]+)"', attrs).group(1))
            width = text_width(text, size, 'font-weight="bold"' in attrs)
            anchor = re.search(r'text-anchor="(\w+)"', attrs).group(1)
            lo = {"start": x, "middle": x - width / 2, "end": x - width}[anchor]
            if lo < cell[0] + 1.0 or lo + width > cell[1] - 1.0:
                bad.append((text, round(lo - cell[0], 1), round(cell[1] - lo - width, 1)))
    return bad


@pytest.mark.parametrize("name", [f"{n}_overview" for n in DIAGRAM_NAMES])
def test_every_name_fits_its_cell_in_a_wider_font(name):
    # Issue 27: port names ran over their cells in plant_dynamic_overview (graphviz sized the
    # cells by Helvetica's widths: applied_generalized_force left 0.6 pt, the arrow-shaped
    # ports' names reached into their points).
    assert _overflowing_text((DIAGRAMS / f"{name}.svg").read_text()) == []


def test_the_full_pose_overview_ranks_the_blocks_in_signal_order():
    # Issue 27: a tangle of crossing edges: graphviz broke the loops itself and ranked the
    # tension distribution (whose memory feeds the forward kinematics) above the forward
    # kinematics. The edges that close loops between blocks are drawn without a rank
    # constraint (the reel command's loop back to the plant is graphviz's): the three memory
    # outputs (`*_previous`: the tension estimate back to the forward kinematics, the
    # filter's last command to the kinetostatic block, the damping's ringing back to the
    # tension distribution's floor) and the command back to the
    # admittance (its anti-windup), so the blocks come top to bottom as the signals flow.
    dot = (DIAGRAMS / "controller_full_pose_overview.dot").read_text()
    nodes = _nodes(dot)
    ids = {name: k for k, label in nodes.items()
           for name in ("reels", "forward_kinematics", "tension_distribution", "admittance",
                        "safety_limits", "safety_filter", "kinetostatic_force",
                        "jacobian_mapping", "tension_damping", "model_monitor")
           if name in label.split()}
    free = re.findall(r"^  (n\d+):o\d+:s -> (n\d+):i\d+:n \[constraint=false\];$", dot,
                      flags=re.M)
    assert sorted(free) == sorted([(ids["tension_distribution"], ids["forward_kinematics"]),
                                   (ids["safety_filter"], ids["kinetostatic_force"]),
                                   (ids["tension_damping"], ids["tension_distribution"]),
                                   (ids["safety_filter"], ids["admittance"])])
    # Laid out: the blocks' heights in that order (graphviz's y grows upwards).
    import pygraphviz

    graph = pygraphviz.AGraph(string=dot)
    graph.layout(prog="dot")
    y = {name: float(graph.get_node(k).attr["pos"].split(",")[1]) for name, k in ids.items()}
    order = ["reels", "forward_kinematics", "kinetostatic_force", "admittance",
             "safety_limits", "safety_filter", "tension_distribution", "jacobian_mapping",
             "tension_damping"]
    # The monitor, which no block reads, at the bottom (beside the last block).
    assert y["model_monitor"] == pytest.approx(y["tension_damping"], abs=60)
    assert sorted(order, key=lambda name: -y[name]) == order


def test_diagram_of_a_robot_or_another_scenario_says_which_it_was_built_for(tmp_path, capsys):
    # Issue 32: `cdpm diagram exp3_two_pairs` wrote files identical to the default's (the
    # blocks are the same; the parameters are not drawn) and a robot's name was refused.
    assert main(["diagram", "exp3_two_pairs", "--out", str(tmp_path / "exp3"), "--no-svg"]) == 0
    assert main(["diagram", "cube_8cable", "--out", str(tmp_path / "cube"), "--no-svg"]) == 0
    exp3 = (tmp_path / "exp3" / "controller_simulated_overview.dot").read_text()
    cube = (tmp_path / "cube" / "controller_simulated_overview.dot").read_text()
    assert ('label="scenario exp3_two_pairs: robot paper_7cable_swap13_swap57, 7 cables, '
            'swapped 1-3, 5-7, method promise"') in exp3
    assert 'label="scenario cube_8cable: robot cube_8cable, 8 cables, method promise"' in cube
