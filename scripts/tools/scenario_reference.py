"""Write docs/scenario_reference.md: every field of the scenario and of the robot file, with its
type, unit, default and meaning, read from the dataclasses and the comments above their fields.

    python scripts/tools/scenario_reference.py            # rewrite docs/scenario_reference.md
    python scripts/tools/scenario_reference.py --check    # exit 1 when the committed file is stale

The classes are found by walking `Scenario` (every nested config, every member of the plant and
operator unions) and `RobotSchema` from the packages' public names; each class's source is
found with `inspect`, so the reference follows the code wherever a class lives. A field's
meaning is the comment block above it (a field without one shares the block of the field before
it, as `d_u, F_u, ...` under one comment); its unit is the one the comment names after a comma
(`# Virtual mass M, kg.`), in field order when the comment lists several.
"""

import argparse
import ast
import dataclasses
import inspect
import re
import sys
import textwrap
import typing
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "docs" / "scenario_reference.md"

# Units as the comments write them, longest first so that "m/s^2" is not read as "m".
UNITS = ("m/s of cable", "m/s^2", "m/s", "N s/m", "N/m", "kg m^2", "kg", "rad/s", "rad",
         "1/s", "Hz", "samples", "ticks", "N", "m", "s")
_UNIT_RE = re.compile(r"(?:,|\bin)\s+(" + "|".join(re.escape(u) for u in UNITS)
                      + r")(?=[\s.,;:()]|$)")


@dataclasses.dataclass
class Field:
    name: str
    type: str
    unit: str
    default: str
    meaning: str


def _comment_blocks(cls) -> dict[str, list[str]]:
    """{field name: the comment lines directly above it} from the class's source."""
    source = textwrap.dedent(inspect.getsource(cls))
    lines = source.splitlines()
    tree = ast.parse(source)
    body = next(n for n in tree.body if isinstance(n, ast.ClassDef)).body
    blocks = {}
    for node in body:
        if not isinstance(node, ast.AnnAssign) or not isinstance(node.target, ast.Name):
            continue
        comment = []
        i = node.lineno - 2
        while i >= 0 and lines[i].strip().startswith("#"):
            comment.insert(0, lines[i].strip().lstrip("#").strip())
            i -= 1
        blocks[node.target.id] = comment
    return blocks


def _doc(cls) -> str:
    """The class's own docstring, or "" (a dataclass without one gets its signature)."""
    doc = inspect.getdoc(cls) or ""
    return "" if doc.startswith(cls.__name__ + "(") else _sentence(doc.split("\n\n")[0])


def _sentence(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def _units(comment: str) -> list[str]:
    """The units a comment names, in order (`, kg.`, `, m/s of cable;`, `in N`)."""
    if "dimensionless" in comment.lower():
        return ["1"]
    return _UNIT_RE.findall(comment)


def _is_config(tp) -> bool:
    return dataclasses.is_dataclass(tp) and isinstance(tp, type)


def _members(tp) -> tuple:
    """The members of a Union (Optional included), else ()."""
    return typing.get_args(tp) if typing.get_origin(tp) is typing.Union else ()


def _anchor(cls) -> str:
    return "#" + cls.__name__.lower()


def _type_name(tp) -> str:
    members = _members(tp)
    if members:
        rest = [m for m in members if m is not type(None)]
        if len(rest) == 1:
            return f"{_type_name(rest[0])} or null"
        return " \\| ".join(f"[`!{m.__name__}`]({_anchor(m)})" for m in rest)
    if _is_config(tp):
        return f"[`{tp.__name__}`]({_anchor(tp)})"
    origin = typing.get_origin(tp)
    if origin is list:
        return f"list[{', '.join(_type_name(a) for a in typing.get_args(tp))}]"
    return getattr(tp, "__name__", str(tp))


def _yaml(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_yaml(v) for v in value) + "]"
    if _is_config(type(value)):
        tag = type(value).__name__
        return f"!{tag} {{}}" if not dataclasses.fields(value) else f"see [`{tag}`](#{tag.lower()})"
    return repr(value)


def _default(field, tp) -> str:
    if field.default is not dataclasses.MISSING:
        value = field.default
    elif field.default_factory is not dataclasses.MISSING:
        value = field.default_factory()
    else:
        return "required"
    if _is_config(type(value)) and _members(tp):
        return f"`!{type(value).__name__} {{}}`"
    if _is_config(type(value)):
        return f"see [`{type(value).__name__}`]({_anchor(type(value))})"
    return f"`{_yaml(value)}`"


def describe(cls, units_by_name: dict[str, str]) -> list[Field]:
    """The rows of one class's table. units_by_name: units already read for a field name (an
    override such as PairLogistic.d_u takes Logistic.d_u's when its comment lists fewer)."""
    hints = typing.get_type_hints(cls)
    comments = _comment_blocks(cls)
    fields = dataclasses.fields(cls)
    rows = []
    # A comment block covers its field and the uncommented fields after it.
    groups, current = [], None
    for f in fields:
        own_doc = _is_config(hints[f.name]) and _doc(hints[f.name])
        if comments.get(f.name) or current is None or own_doc:
            current = [f]
            groups.append(current)
        else:
            current.append(f)
    for group in groups:
        comment = _sentence(" ".join(comments.get(group[0].name, [])))
        units = _units(comment)
        for k, f in enumerate(group):
            tp = hints[f.name]
            if _is_config(tp) or _members(tp) and all(_is_config(m) for m in _members(tp)):
                unit = "-"
            elif len(units) >= len(group):
                unit = units[k]
            elif f.name in units_by_name:
                unit = units_by_name[f.name]
            elif units:
                unit = units[0]
            elif f.name.endswith("ticks"):
                unit = "ticks"
            else:
                unit = "-"
            meaning = comment
            if not comments.get(f.name) and _is_config(tp) and _doc(tp):
                meaning = _doc(tp)
            elif meaning and k > 0:
                meaning = f"(with `{group[0].name}`) {meaning}"
            if not meaning and f.name == "enabled":
                meaning = "False switches the block off."
            meaning = meaning or "-"
            if unit not in ("-", "1"):
                units_by_name.setdefault(f.name, unit)
            rows.append(Field(f.name, _type_name(tp), unit, _default(f, tp), meaning))
    return rows


def walk(root) -> list[type]:
    """root and every config class under it, depth first in field order (union members and
    list items too)."""
    seen = []

    def configs(tp):
        """The config classes a type names: itself, a union's members, a list's items."""
        if _is_config(tp):
            return [tp]
        return [c for arg in typing.get_args(tp) for c in configs(arg)]

    def visit(cls):
        if cls in seen:
            return
        seen.append(cls)
        for tp in typing.get_type_hints(cls).values():
            for member in configs(tp):
                visit(member)

    visit(root)
    return seen


def _table(cls, units_by_name) -> list[str]:
    doc = _doc(cls)
    out = [f"### {cls.__name__}", ""]
    out.append(f"`{cls.__module__}.{cls.__name__}`" + (f": {doc}" if doc else ""))
    out.append("")
    rows = describe(cls, units_by_name)
    if not rows:
        out += ["No fields: write it as `!" + cls.__name__ + " {}`.", ""]
        return out
    out += ["| field | type | unit | default | meaning |", "| --- | --- | --- | --- | --- |"]
    out += [f"| `{r.name}` | {r.type} | {r.unit} | {r.default} | {r.meaning} |" for r in rows]
    out.append("")
    return out


def render() -> str:
    from cdpm_drake.config import Scenario
    from cdpm_drake.robot import RobotSchema

    lines = [
        "# Scenario reference",
        "",
        "<!-- Generated by scripts/tools/scenario_reference.py from the dataclasses and the",
        "     comments above their fields; tests/docs/test_scenario_reference.py fails when it",
        "     is stale. Do not edit by hand: edit the comment in the source and rerun. -->",
        "",
        "Every field of a scenario file and of a robot file: its type, unit, default and",
        "meaning. A field left out takes its default. A tagged field (`plant: !DynamicReels",
        "{...}`, `operator: !SpringHandOperator {...}`) names its class in the tag; an untagged",
        "map takes the first member. How to write a scenario and change a field for one run:",
        "[scenarios.md](scenarios.md); a robot file: [robots.md](robots.md).",
        "",
        "Units: m, s, N, kg, rad; `-` where none applies (a flag, a name, a nested section);",
        "`1` dimensionless. `null` in YAML is Python's `None`.",
        "",
        "## The scenario file",
        "",
    ]
    units_by_name: dict[str, str] = {}
    for cls in walk(Scenario):
        lines += _table(cls, units_by_name)
    lines += ["## The robot file", ""]
    for cls in walk(RobotSchema):
        lines += _table(cls, units_by_name)
    return "\n".join(lines).rstrip() + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 when the committed docs/scenario_reference.md is stale")
    parser.add_argument("--out", type=Path, default=OUT, help="where to write it")
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        current = args.out.read_text() if args.out.exists() else ""
        if current != text:
            print(f"{args.out} is stale: run python scripts/tools/scenario_reference.py",
                  file=sys.stderr)
            return 1
        return 0
    args.out.write_text(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
