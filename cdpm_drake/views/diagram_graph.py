"""The controller diagram as graphviz: .dot from Drake's GetGraphvizString, .svg via pygraphviz."""

import re
from pathlib import Path

# Drake names graphviz nodes and clusters after system ids, which depend on how many systems
# the process built before (a sub-diagram drawn alone also names its port clusters
# `clusters<id>in`); renumbering them in order of appearance makes the text stable.
_ID = re.compile(r"\b(s|clusters|cluster|_)(\d+)")


def stable_graphviz(diagram, max_depth: int = 1) -> str:
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


def write_diagrams(diagrams: dict, out_dir, *, svg: bool = True, max_depth: int = 1) -> list[Path]:
    """Write NAME.dot (and NAME.svg) for each {NAME: diagram}; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, diagram in diagrams.items():
        dot = stable_graphviz(diagram, max_depth=max_depth)
        path = out / f"{name}.dot"
        path.write_text(dot)
        paths.append(path)
        if svg:
            svg_path = out / f"{name}.svg"
            svg_path.write_text(render_svg(dot))
            paths.append(svg_path)
    return paths
