"""The controller diagram as graphviz, .svg via pygraphviz: the full-depth picture from Drake's
GetGraphvizString (NAME.dot) and a readable overview of the top level (NAME_overview.dot)."""

import math
import re
from pathlib import Path

# Drake names graphviz nodes and clusters after system ids, which depend on how many systems
# the process built before (a sub-diagram drawn alone also names its port clusters
# `clusters<id>in`); renumbering them in order of appearance makes the text stable.
_ID = re.compile(r"\b(s|clusters|cluster|_)(\d+)")


def stable_graphviz(diagram, max_depth: int | None = None) -> str:
    """Drake's graphviz of `diagram`, `max_depth` levels of sub-diagrams expanded (None:
    every level, the full depth), with stable node names and edge order."""
    text = diagram.GetGraphvizString(max_depth=max_depth)
    ids: dict[str, str] = {}

    def renumber(match):
        key = match.group(2)
        if key not in ids:
            ids[key] = str(len(ids))
        return match.group(1) + ids[key]

    lines = _ID.sub(renumber, text).split("\n")
    # Drake lists connections in pointer order, which differs between processes: sort each
    # run of edge lines.
    out, run = [], []
    for line in lines + [""]:
        if " -> " in line:
            run.append(line)
            continue
        out.extend(sorted(run))
        run = []
        out.append(line)
    return "\n".join(out[:-1])


def render_svg(dot_text: str) -> str:
    try:
        import pygraphviz
    except ImportError as e:
        raise RuntimeError(f"rendering SVG needs pygraphviz ({e}); `pip install pygraphviz`, "
                           "or write only the .dot files with --no-svg") from None

    return pygraphviz.AGraph(string=dot_text).draw(format="svg", prog="dot").decode()


def write_diagrams(diagrams: dict, out_dir, *, svg: bool = True,
                   max_depth: int | None = None, caption: str | None = None) -> list[Path]:
    """Write NAME.dot and NAME_overview.dot (and their .svg) for each {NAME: diagram}: Drake's
    graphviz at full depth (every sub-diagram expanded, the plant's too; `max_depth` levels
    when given) and the readable top level (overview_graphviz); returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, diagram in diagrams.items():
        for stem, dot in ((name, stable_graphviz(diagram, max_depth=max_depth)),
                          (f"{name}_overview", overview_graphviz(diagram, caption=caption))):
            path = out / f"{stem}.dot"
            path.write_text(dot)
            paths.append(path)
            if svg:
                svg_path = out / f"{stem}.svg"
                svg_path.write_text(render_svg(dot))
                paths.append(svg_path)
    return paths


# --- The readable overview -------------------------------------------------------------------

# Drake's primitives name their inputs u0, u1, ... (Adder, Multiplexer): the overview labels
# such an input with the signal it receives instead.
_NUMBERED_INPUT = re.compile(r"^u\d+$")


def _html(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _short_type(system) -> str:
    """The class name without its module, e.g. `Adder` for pydrake's Adder_[float]."""
    name = type(system).__name__
    return re.sub(r"_\[.*\]$", "", name)


# A system with more ports than this (a MultibodyPlant has ~25) shows only the ones wired or
# exported, and says how many it leaves out.
MAX_PORTS = 6


# Graphviz sizes a cell by its own estimate of the text (Helvetica's widths); a viewer
# without Helvetica draws it in its sans-serif fallback, often DejaVu Sans, up to a sixth
# wider, and long port names ran over their cells. Each cell gets at least the width of its
# text in DejaVu Sans (matplotlib's copy) plus its padding and border, points.
WIDTH_FONT = "DejaVu Sans"


def text_width(text: str, size: float, bold: bool = False) -> float:
    """The width (pt) of `text` at `size` pt in WIDTH_FONT, unhinted (as a browser draws it
    at any zoom)."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import text_to_path

    font = FontProperties(family=WIDTH_FONT, size=size, weight="bold" if bold else "normal")
    return text_to_path.get_text_width_height_descent(text, font, ismath=False)[0]


def _cell_width(text: str, size: float, padding: float, bold: bool = False) -> int:
    """A TD's WIDTH (pt): the text's, its padding and border on both sides, a point of air."""
    return math.ceil(text_width(text, size, bold) + 2 * padding + 2 + 2)


def _port_row(names, prefix: str, used=None) -> str:
    """A row of port cells `prefix<k>`; with more than MAX_PORTS names, only the indices in
    `used` and a last cell `+n ports`."""
    shown = list(enumerate(names))
    if used is not None and len(names) > MAX_PORTS:
        shown = [(k, n) for k, n in shown if k in used]
    cells = "".join(f'<TD PORT="{prefix}{k}" WIDTH="{_cell_width(n, 10, 2)}">{_html(n)}</TD>'
                    for k, n in shown)
    if len(shown) < len(names):
        more = f"+{len(names) - len(shown)} ports"
        cells += f'<TD WIDTH="{_cell_width(more, 10, 2)}"><I>{more}</I></TD>'
    return ('<TR><TD BORDER="0" CELLPADDING="0"><TABLE BORDER="0" CELLBORDER="1" '
            f'CELLSPACING="0" CELLPADDING="2"><TR>{cells}</TR></TABLE></TD></TR>')


def overview_graphviz(diagram, title: str | None = None, caption: str | None = None) -> str:
    """A readable graphviz of a diagram's top level, derived from the built diagram: one node
    per top-level system (its name, its class without the module; a sub-diagram such as the
    simulated plant collapsed into one node, and so is a block whose systems were added flat,
    see `diagram.flat_blocks`), its input ports on top and output ports below, one edge per
    connection between nodes, numbered inputs (u0, u1 of an Adder) labelled with the signal
    they receive; a system with more than MAX_PORTS ports (a MultibodyPlant) shows only the
    ones in use. A diagram's fused wiring (`diagram.fused_wiring`: one Selector that routes
    pieces of signals) is drawn as the connections it makes (with `label_edges`, an edge
    carrying a piece of one signal is labelled with the piece's name). Laid out top to
    bottom so that it fits a page's width. `caption`: a line drawn under the graph (which
    scenario and robot it was built for: the blocks do not show the parameters)."""
    systems = list(diagram.GetSystems())
    by_name = {s.get_name(): k for k, s in enumerate(systems)}
    flat = getattr(diagram, "flat_blocks", {})
    in_block = {by_name[name]: block for block, info in flat.items() for name in info["systems"]}
    # The blocks' fused wiring (diagram.fused_wiring) is not drawn: edges go through it.
    fused = getattr(diagram, "fused_wiring", None)
    wiring_k = by_name[fused["system"]] if fused else None
    # Nor the fused memory: the blocks' delays, drawn inside the blocks as unfused.
    memory_k = by_name.get(fused.get("memory")) if fused else None
    # The safety blocks' fused callback (`diagram.fused_kernels`) is not drawn either: its
    # blocks are, each with its ports, and edges into it go to the blocks that read them.
    kernels = getattr(diagram, "fused_kernels", None)
    kernels_k = by_name[kernels["system"]] if kernels else None
    # Nodes: [name, kind, inputs, outputs, shaded]; where each system's ports land on them
    # (in_at: a list, as one input of the fused wiring can be several blocks' inputs).
    nodes, node_of, in_at, out_at = [], {}, {}, {}
    merged = []  # (source (system, output), target (node, input)) of fused-away inputs

    def add_block(block):
        info = flat[block]
        j = len(nodes)
        # Its parts by their own names (the block's main system: by its class).
        kinds = info.get("kinds", {})
        parts = [name[len(block) + 1:] if name != block else
                 kinds.get(name) or _short_type(systems[by_name[name]])
                 for name in info.get("parts", info["systems"])]
        nodes.append([block, _inside(parts), list(info["inputs"]),
                      list(info["outputs"]), True])
        for i, (port_name, ports) in enumerate(info["inputs"].items()):
            for name, p in ports:
                if name in by_name:
                    in_at.setdefault((by_name[name], p), []).append((j, i))
                elif port_name in info.get("sources", {}):
                    # Its wiring fed straight from another block's: fused into that one,
                    # so the edge comes from where the source is now.
                    source, sp = info["sources"][port_name]
                    merged.append(((by_name[source], sp), (j, i)))
        for i, (name, p) in enumerate(info["outputs"].values()):
            out_at[(by_name[name], p)] = (j, i)
        for name in info["systems"]:
            node_of[by_name[name]] = j

    # In the order the blocks and systems were added (`diagram.block_order`, where the
    # diagram has it: a block whose systems were all fused away has its place there).
    order = [by_name.get(name, name) for name in getattr(diagram, "block_order", ())
             if name in by_name or name in flat]
    order += [k for k in range(len(systems)) if k not in order]
    for k in order:
        if isinstance(k, str):
            if k not in (n[0] for n in nodes):
                add_block(k)
            continue
        system, block = systems[k], in_block.get(k)
        if k in (wiring_k, memory_k, kernels_k):
            continue
        if block is None:
            kind = _short_type(system)
            if hasattr(system, "GetSystems"):  # a sub-diagram, collapsed: say what is inside
                kind = _inside([s.get_name() for s in system.GetSystems()])
            node_of[k] = len(nodes)
            nodes.append([system.get_name(), kind,
                          [None] * system.num_input_ports(),
                          [system.get_output_port(p).get_name()
                           for p in range(system.num_output_ports())],
                          hasattr(system, "GetSystems")])
            for p in range(system.num_input_ports()):
                in_at.setdefault((k, p), []).append((node_of[k], p))
            for p in range(system.num_output_ports()):
                out_at[(k, p)] = (node_of[k], p)
        elif block not in (n[0] for n in nodes):
            add_block(block)
    if kernels:  # what the fused callback reads, it reads for its blocks
        node_of[kernels_k] = {j for j, n in enumerate(nodes) if n[0] in kernels["blocks"]}
    index = {id(s): k for k, s in enumerate(systems)}
    edges = set()
    connections = [((index[id(src)], int(src_k)), (index[id(dst)], int(dst_k)))
                   for (dst, dst_k), (src, src_k) in diagram.connection_map().items()]
    # Through the fused wiring: each of its outputs is an edge from every source it reads.
    wired = {d[1]: s for s, d in connections if d[0] == wiring_k}
    direct, direct_from_wiring, labels = [], {}, {}
    for s, d in connections:
        if d[0] == wiring_k:
            continue
        if s[0] != wiring_k:
            direct.append((s, in_at.get(d, [])))
            continue
        if s in out_at:  # a block's output, where the block exported it
            direct.append((s, in_at.get(d, [])))
            continue
        reads = fused["reads"][s[1]]
        for i in reads:
            # The input of d's block that this wiring input is, else d's own input.
            reader = node_of.get(d[0])
            readers = reader if isinstance(reader, set) else {reader}
            targets = [t for t in in_at.get((wiring_k, i), []) if t[0] in readers]
            direct.append((wired.get(i), targets or in_at.get(d, [])))
            if fused.get("label_edges") and len(reads) == 1:
                # A piece of one signal: the edge says which (the wiring output's name).
                for t in targets or in_at.get(d, []):
                    labels[t] = systems[wiring_k].get_output_port(s[1]).get_name()
        direct_from_wiring.setdefault(s[1], []).append((None, in_at.get(d, [])))
    direct += [(source, [target]) for source, target in merged]
    for s, targets in direct:
        for t in targets:
            if s in out_at and out_at[s][0] != t[0]:  # not inside one flat block
                edges.add(out_at[s] + t)
    connections = sorted(edges)
    source_of = {(d, dk): (s, sk) for s, sk, d, dk in connections}
    for j, node in enumerate(nodes):
        for i, name in enumerate(node[2]):
            if name is None:
                k = next(k for k in node_of if node_of[k] == j)
                name = systems[k].get_input_port(i).get_name()
            if _NUMBERED_INPUT.match(name) and (j, i) in labels:
                name = labels[(j, i)]
            elif _NUMBERED_INPUT.match(name) and (j, i) in source_of:
                s, sk = source_of[(j, i)]
                name = nodes[s][3][sk]
            node[2][i] = name

    # The diagram's own (exported) ports, when it has any: (port name, [node inputs]) and
    # (port name, node output); through the fused wiring, to what its outputs feed or from
    # what they read.
    exported_in, exported_out = [], []
    for p in range(diagram.num_input_ports()):
        targets = []
        for system, port in diagram.GetInputPortLocators(diagram.get_input_port(p).get_index()):
            k = index[id(system)]
            if k == wiring_k:
                for out_k, reads in fused["reads"].items():
                    if int(port) in reads:
                        targets += [t for s_, ts in direct_from_wiring.get(out_k, [])
                                    for t in ts]
            else:
                targets += in_at[(k, int(port))]
        exported_in.append((diagram.get_input_port(p).get_name(), targets))
    for p in range(diagram.num_output_ports()):
        system, port = diagram.get_output_port_locator(diagram.get_output_port(p).get_index())
        k = index[id(system)]
        sources = ([out_at[wired[i]] for i in fused["reads"][int(port)] if wired.get(i) in out_at]
                   if k == wiring_k else [out_at[(k, int(port))]])
        exported_out.append((diagram.get_output_port(p).get_name(), sources))
    used_in = {(j, i) for _, _, j, i in connections} | {t for _, ts in exported_in for t in ts}
    used_out = {(j, i) for j, i, _, _ in connections} | {s_ for _, ss in exported_out
                                                         for s_ in ss}

    lines = [f'digraph "{_html(title or diagram.get_name())}" {{',
             '  graph [rankdir=TB, nodesep=0.25, ranksep=0.35, fontname="Helvetica", '
             'fontsize=11' + (f', label="{_html(caption)}", labelloc=b' if caption else "")
             + '];',
             '  node [shape=plaintext, fontname="Helvetica", fontsize=10, margin=0];',
             '  edge [fontname="Helvetica", fontsize=9, arrowsize=0.6, color="#444444"];']
    for j, (name, kind, inputs, outputs, shaded) in enumerate(nodes):
        rows = []
        if inputs:
            rows.append(_port_row(inputs, "i", {i for n, i in used_in if n == j}))
        fill = ' BGCOLOR="#e8eef8"' if shaded else ""
        width = max(_cell_width(name, 10, 3, bold=True), _cell_width(kind, 8, 3))
        rows.append(f'<TR><TD{fill} WIDTH="{width}"><B>{_html(name)}</B><BR/>'
                    f'<FONT POINT-SIZE="8" COLOR="#555555">{_html(kind)}</FONT></TD></TR>')
        if outputs:
            rows.append(_port_row(outputs, "o", {i for n, i in used_out if n == j}))
        lines.append(f'  n{j} [label=<<TABLE BORDER="0" CELLBORDER="1" CELLSPACING="0" '
                     f'CELLPADDING="3">{"".join(rows)}</TABLE>>];')
    for p, (name, targets) in enumerate(exported_in):
        lines.append(f'  in{p} [shape=cds, label="{_html(name)}", '
                     f'width={_port_node_width(name)}];')
        for j, i in targets:
            lines.append(f'  in{p} -> n{j}:i{i}:n;')
    for p, (name, sources) in enumerate(exported_out):
        lines.append(f'  out{p} [shape=cds, label="{_html(name)}", '
                     f'width={_port_node_width(name)}];')
        for j, i in sources:
            lines.append(f'  n{j}:o{i}:s -> out{p};')
    # A block's memory output (`<signal>_previous`: last tick's value) feeds back by
    # construction, whichever order the walk meets the blocks in.
    memory = {e for e in connections if nodes[e[0]][3][e[1]].endswith("_previous")}
    feedback = feedback_edges(len(nodes), connections,
                              [j for _, targets in exported_in for j, _ in targets], memory)
    for s, sk, d, dk in connections:
        label = labels.get((d, dk))
        attributes = [] if label is None or label == nodes[d][2][dk] else [
            f'label=" {_html(label)}"']
        if (s, sk, d, dk) in feedback:
            attributes.append("constraint=false")
        attributes = f" [{', '.join(attributes)}]" if attributes else ""
        lines.append(f"  n{s}:o{sk}:s -> n{d}:i{dk}:n{attributes};")
    # A block no other block reads (a monitor: its outputs go to the log alone) at the
    # bottom, beside the last blocks, not widening the rank of the blocks it watches.
    feeds = {s for s, _, _, _ in connections}
    sinks = [j for j in range(len(nodes)) if j not in feeds and nodes[j][2]]
    if sinks:
        lines.append("  {rank=max; " + " ".join(f"n{j};" for j in sinks) + "}")
    lines.append("}")
    return "\n".join(lines) + "\n"


def feedback_edges(num_nodes: int, connections, roots=(), memory=()) -> set:
    """The connections (s, sk, d, dk) that carry a block's memory back to a block before it,
    to draw without a rank constraint. Found by a depth-first walk from the roots (the nodes
    the diagram's own inputs feed), then from node 0 on (the plant, added first), each
    node's edges taken in order of its output ports: the signals flow from the plant's
    first output (cable_lengths) through the blocks, and an edge to a node still on the walk
    closes a loop. The loop through a walk's root (the reel command back to the plant) is
    left out: graphviz turns that one round itself and keeps it short. Without these hints
    graphviz breaks the loops in the order of its node ids and may rank a block's memory
    above the block that feeds it (the full-pose overview: 24 edge crossings, 13 with).
    `memory`: connections known to carry memory; feedback whatever the walk, and not walked
    (else the walk may reach a block first through another's memory and rank it below)."""
    out = {}
    memory = set(memory)
    for edge in sorted(connections, key=lambda e: (e[0], e[1], e[2], e[3])):
        if edge not in memory:
            out.setdefault(edge[0], []).append(edge)
    state = [0] * num_nodes  # 0 unseen, 1 on the walk, 2 done
    back = set()
    for root in list(dict.fromkeys(roots)) + list(range(num_nodes)):
        if state[root]:
            continue
        state[root] = 1
        stack = [(root, iter(out.get(root, [])))]
        while stack:
            node, edges = stack[-1]
            edge = next(edges, None)
            if edge is None:
                state[node] = 2
                stack.pop()
                continue
            target = edge[2]
            if state[target] == 1 and target != root:
                back.add(edge)
            elif state[target] == 0:
                state[target] = 1
                stack.append((target, iter(out.get(target, []))))
    return back | memory


def _port_node_width(name: str) -> str:
    """The width (in) of a diagram port's arrow-shaped node: its name in WIDTH_FONT at the
    graph's 10 pt, centred, clear of the arrow's 12 pt point on both sides (graphviz centres
    the name on the whole shape), as graphviz writes inches."""
    return f"{(text_width(name, 10) + 36) / 72:.2f}"


def _inside(names) -> str:
    """`of a, b, c +n`: what a collapsed node is made of."""
    return "of " + ", ".join(names[:3]) + (f" +{len(names) - 3}" if len(names) > 3 else "")
