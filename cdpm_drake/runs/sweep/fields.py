"""Scenario field paths (`interference.pairs[1,3].d_u`, `initial_position[2]`) and the
YAML overlay that sets them on a scenario, through the scenario's own checks."""

import copy
import dataclasses
import re
import typing

from cdpm_drake.config import INTERNAL_FIELDS, Scenario, ScenarioError, resolve_scenario
from cdpm_drake.runs.sweep.errors import SweepError


_SEGMENT = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[[^\]]*\])*)$")
_SELECTOR = re.compile(r"\[([^\]]*)\]")


@dataclasses.dataclass(frozen=True)
class _Seg:
    name: str
    # List selectors after the name: ("index", k) (0-based) or ("pair", (i, j)) (1-based).
    selectors: tuple = ()


def parse_field_path(text: str, where: str = "field") -> list[_Seg]:
    """`interference.pairs[1,3].d_u` -> segments; SweepError naming `where` when malformed."""
    if not isinstance(text, str) or not text.strip():
        raise SweepError(f"{where}: a field path must be a non-empty string, got {text!r}")
    segs = []
    for part in text.strip().split("."):
        m = _SEGMENT.match(part.strip())
        if not m:
            raise SweepError(f"{where}: {text!r} is not a field path (names separated by dots, "
                             "e.g. interference.default.d_u or interference.pairs[1,3].d_u)")
        selectors = []
        for sel in _SELECTOR.findall(m.group(2)):
            items = [s.strip() for s in re.split(r"[,\-]", sel)]
            if not all(re.fullmatch(r"\d+", s) for s in items) or len(items) not in (1, 2):
                raise SweepError(f"{where}: {text!r}: [{sel}] must be a list index [k] "
                                 "(from 0) or a cable pair [i,j] (cables from 1)")
            if len(items) == 1:
                selectors.append(("index", int(items[0])))
            else:
                selectors.append(("pair", (int(items[0]), int(items[1]))))
        segs.append(_Seg(m.group(1), tuple(selectors)))
    return segs


def _union_members(schema):
    origin = typing.get_origin(schema)
    if origin is typing.Union:
        return [a for a in typing.get_args(schema) if a is not type(None)]
    return None


def _raw(value):
    """The YAML data of a scenario value (dataclasses as mappings, with tags for unions)."""
    from pydrake.common.yaml import yaml_load

    if dataclasses.is_dataclass(value):
        from pydrake.common.yaml import yaml_dump_typed
        return yaml_load(data=yaml_dump_typed(value))
    if isinstance(value, list):
        return [_raw(v) for v in value]
    return copy.deepcopy(value)


def put_field(node: dict, obj, segs: list[_Seg], value, path: str) -> None:
    """Write `value` at `segs` into the overlay mapping `node`, which overlays the dataclass
    `obj`. Mappings merge in an overlay, lists replace: a selected list is copied whole from
    `obj` (or taken from `node` if an earlier field already copied it) and edited there; a
    union field (operator, plant) carries the tag of its current type, so that the overlay
    edits the operator the scenario has rather than replacing it by the first type."""
    seg, rest = segs[0], segs[1:]
    if not dataclasses.is_dataclass(obj):
        raise SweepError(f"field {path!r}: {seg.name!r} is below a value that is not a "
                         f"mapping ({obj!r})")
    names = [f.name for f in dataclasses.fields(obj) if f.name not in INTERNAL_FIELDS]
    if seg.name not in names:
        from cdpm_drake.text import did_you_mean
        raise SweepError(f"field {path!r}: unknown field {seg.name!r}"
                         f"{did_you_mean(seg.name, names)} (valid fields there: {names})")
    schema = typing.get_type_hints(type(obj))[seg.name]
    child = getattr(obj, seg.name)
    if not seg.selectors:
        if not rest:
            node[seg.name] = value
            return
        members = _union_members(schema)
        if child is None and members is not None and len(members) == 1:
            child = members[0]()  # Optional[dataclass] not set yet: start from its defaults
        sub = node.get(seg.name)
        if not isinstance(sub, dict):
            sub = node[seg.name] = {}
        if members is not None and len(members) > 1 and "_tag" not in sub:
            sub["_tag"] = "!" + type(child).__name__
        put_field(sub, child, rest, value, path)
        return
    # A list: edit a whole copy.
    if not isinstance(child, list):
        raise SweepError(f"field {path!r}: {seg.name} is not a list (it is {child!r}), so it "
                         "takes no [..] selector")
    current = node.get(seg.name)
    if not isinstance(current, list):
        current = node[seg.name] = _raw(child)
    objs, raws = child, current
    for n, (kind, key) in enumerate(seg.selectors):
        last = n == len(seg.selectors) - 1 and not rest
        if kind == "pair":
            from cdpm_drake.config import PairLogistic
            if n > 0 or typing.get_args(schema)[:1] != (PairLogistic,):
                raise SweepError(f"field {path!r}: a cable pair selector [i,j] only applies "
                                 "to interference.pairs")
            k = next((m for m, o in enumerate(objs) if sorted(o.pair) == sorted(key)), None)
            if k is None:  # no override for this pair yet: create it
                objs = list(objs) + [PairLogistic(pair=list(key))]
                raws.append({"pair": list(key)})
                k = len(raws) - 1
        else:
            k = key
            if not 0 <= k < len(raws):
                raise SweepError(f"field {path!r}: index [{k}] is out of range; {seg.name} "
                                 f"has {len(raws)} entries (indices from 0)")
        if last:
            raws[k] = value
            return
        if n < len(seg.selectors) - 1:
            if not isinstance(raws[k], list):
                raise SweepError(f"field {path!r}: entry [{k}] is not a list")
            objs, raws = objs[k], raws[k]
    if not isinstance(raws[k], dict):
        raise SweepError(f"field {path!r}: entry [{k}] of {seg.name} is not a mapping")
    put_field(raws[k], objs[k], rest, value, path)


def field_type(obj, segs: list[_Seg]):
    """The schema type of the field at `segs` (for random draws: int fields draw integers)."""
    for n, seg in enumerate(segs):
        if not dataclasses.is_dataclass(obj):
            return None
        hints = typing.get_type_hints(type(obj))
        if seg.name not in hints:
            return None
        schema = hints[seg.name]
        child = getattr(obj, seg.name)
        for kind, _ in seg.selectors:
            args = typing.get_args(schema)
            schema = args[0] if args else None
            child = child[0] if isinstance(child, list) and child else None
        members = _union_members(schema)
        if members is not None and len(members) == 1:
            schema = members[0]
        if n == len(segs) - 1:
            return schema
        obj = child if child is not None else (schema() if dataclasses.is_dataclass(schema)
                                               else None)
    return None


def apply_overlay(scenario: Scenario, overlay: dict) -> Scenario:
    """The scenario with a YAML overlay (raw mapping) applied, as `--scenario-text` applies
    one: the scenario's schema check, yaml_load_typed with the scenario as defaults, then
    check_scenario. ScenarioError with the scenario's own message."""
    return apply_overlay_resolved(scenario, overlay)[0]


def apply_overlay_resolved(scenario: Scenario, overlay: dict):
    """apply_overlay, also returning the result's resolve_scenario (None for an empty
    overlay)."""
    from pydrake.common.yaml import yaml_dump, yaml_load_typed

    from cdpm_drake.config import check_yaml, explain_load_error

    if not overlay:
        return scenario, None
    check_yaml(overlay, Scenario, "")
    try:
        result = yaml_load_typed(schema=Scenario, data=yaml_dump(overlay), defaults=scenario)
    except Exception as e:
        raise ScenarioError(explain_load_error(e)) from None
    return result, resolve_scenario(result)
