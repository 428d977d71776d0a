"""Sweeps: many variants of one scenario, run on every core or on a Ray cluster, tabulated.

A sweep file (docs/SWEEP_FORMAT.md) names a base scenario, an optional overlay, and axes
(a grid), random samples, explicit overlays and seeds. Each variant is a full scenario: the base
with YAML overlays applied through the scenario's own schema check, `yaml_load_typed` and
`check_scenario`, and run by `simulation.simulate` (the same `build_diagram` and Drake
Simulator as `cdpm simulate`). Every variant is resolved before the first run, so a bad field
or value stops the sweep before it starts, naming the variant.

Results go to DIR/results.csv (one row per run, rewritten atomically as runs finish) and
DIR/runs/<run>/ (the resolved scenario.yaml, row.json, and log.npz with keep_logs). A rerun
skips the rows whose run id and resolved-scenario hash are already there.
"""

import copy
import csv
import dataclasses
import hashlib
import io
import itertools
import json
import logging
import math
import os
import re
import signal
import sys
import time
import typing
from pathlib import Path

import numpy as np

from cdpm_drake.robot import resolve_named_yaml
from cdpm_drake.config import (INTERNAL_FIELDS, Scenario, ScenarioError, interference_params, load_resolved_scenario, resolve_scenario,
                       resolve_scenario_path, scenario_robot, scenario_to_yaml)

from cdpm_drake.data import SWEEPS_DIR  # noqa: E402

# Most variants a sweep may expand to: a typo in a grid (a count of 1000 on four axes) should
# be an error, not a year of runs.
MAX_VARIANTS = 100_000


class SweepError(ValueError):
    """A bad sweep file or variant; the message names the field (or variant) and the value."""


# --- The sweep file --------------------------------------------------------------------------


@dataclasses.dataclass
class Axis:
    """One grid axis: a scenario field and its values (exactly one of the three ways)."""

    # Scenario field path as in the YAML, e.g. interference.default.d_u, admittance.mass,
    # interference.pairs[1,3].d_u (pair override, cables from 1), initial_position[2] (from 0).
    field: str = ""
    # The values as written (any YAML value the field takes).
    values: list = dataclasses.field(default_factory=list)
    # [start, stop, count]: count evenly spaced values, both ends included.
    linspace: typing.Optional[list[float]] = None
    # [start, stop, count]: count values evenly spaced on a log scale, both ends included.
    geomspace: typing.Optional[list[float]] = None


@dataclasses.dataclass
class RandomSamples:
    """`count` variants with each field drawn uniformly from its [low, high] range."""

    count: int = 0
    # Seed of the sampler (not of the scenario: see `seeds`).
    seed: int = 0
    # Field path -> [low, high]; an integer field draws integers, both ends included.
    ranges: dict[str, list[float]] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class SweepFile:
    # A short identifier (default: the file's stem), used in the output directory's name.
    name: str = ""
    description: str = ""
    # A shipped scenario's name or a path to a scenario YAML, relative to the sweep file.
    base: str = "exp2_interaction"
    # A YAML overlay applied to the base first, like --scenario-text (e.g. {duration: 5.0}).
    overlay: dict = dataclasses.field(default_factory=dict)
    # Grid: the product of all axes.
    axes: list[Axis] = dataclasses.field(default_factory=list)
    # Random samples, crossed with the grid.
    random: typing.Optional[RandomSamples] = None
    # Explicit overlays (YAML mappings), crossed with the grid and the samples.
    variants: list = dataclasses.field(default_factory=list)
    # Repeat every variant with each of these random_seed values.
    seeds: list[int] = dataclasses.field(default_factory=list)
    # The metric the pictures and the closing table use unless told otherwise.
    metric: str = "min_distance"


# Fields whose contents are scenario YAML (or a field's values): kept as written and checked
# per variant by the scenario's own checks, since their schema is the scenario's.
_RAW_FIELDS = ("overlay", "variants")


def sweep_names() -> list[str]:
    return sorted(p.stem for p in SWEEPS_DIR.glob("*.yaml"))


def resolve_sweep_path(name_or_path) -> Path:
    return resolve_named_yaml(name_or_path, SWEEPS_DIR, "sweep", SweepError)


def load_sweep_file(name_or_path) -> tuple[SweepFile, Path]:
    """The typed sweep file (a shipped sweep's name or a path) and its path."""
    from pydrake.common.yaml import yaml_dump, yaml_load, yaml_load_typed

    # The scenario's checker: same wording for both files.
    from cdpm_drake.config import check_yaml, with_line

    path = resolve_sweep_path(name_or_path)
    try:
        raw = yaml_load(filename=str(path))
    except Exception as e:
        raise SweepError(f"{path}: not valid YAML: {e}") from None
    if not isinstance(raw, dict):
        raise SweepError(f"{path}: a sweep file is a mapping with the fields "
                         f"{[f.name for f in dataclasses.fields(SweepFile)]}, got {raw!r}")
    try:
        check_yaml(raw, SweepFile, "")
    except ScenarioError as e:
        raise SweepError(f"{path}: {with_line(e, str(path))}") from None
    typed = copy.deepcopy(raw)
    for key in _RAW_FIELDS:
        typed.pop(key, None)
    for axis in typed.get("axes") or []:
        if isinstance(axis, dict):
            axis.pop("values", None)
    try:
        sweep = yaml_load_typed(schema=SweepFile, data=yaml_dump(typed))
    except Exception as e:
        raise SweepError(f"{path}: {e}") from None
    if not isinstance(raw.get("overlay", {}) or {}, dict):
        raise SweepError(f"{path}: overlay must be a mapping of scenario fields, got "
                         f"{raw['overlay']!r}")
    sweep.overlay = raw.get("overlay") or {}
    variants = raw.get("variants") or []
    for k, v in enumerate(variants):
        if not isinstance(v, dict) or not v:
            raise SweepError(f"{path}: variants[{k}] must be a non-empty mapping of scenario "
                             f"fields (an overlay), got {v!r}")
    sweep.variants = variants
    for k, (axis, raw_axis) in enumerate(zip(sweep.axes, raw.get("axes") or [])):
        axis.values = raw_axis.get("values") or []
        _check_axis(axis, f"{path}: axes[{k}]",
                    given=[key for key in ("values", "linspace", "geomspace")
                           if raw_axis.get(key) is not None])
    if sweep.random is not None:
        _check_random(sweep.random, f"{path}: random")
    for k, s in enumerate(sweep.seeds):
        if s < 0:
            raise SweepError(f"{path}: seeds[{k}] must be an integer >= 0, got {s!r}")
    if len(set(sweep.seeds)) != len(sweep.seeds):
        raise SweepError(f"{path}: seeds lists a seed twice: {sweep.seeds!r}")
    if sweep.metric not in NUMERIC_METRICS:
        raise SweepError(f"{path}: metric {sweep.metric!r} is not a metric that ranks runs; "
                         f"valid metrics: {NUMERIC_METRICS}")
    if not sweep.name:
        sweep.name = path.stem
    return sweep, path


def _check_axis(axis: Axis, where: str, given=None) -> None:
    """`given`: the keys of values, linspace, geomspace the file wrote (default: those set)."""
    if not axis.field:
        raise SweepError(f"{where}.field must name a scenario field, e.g. "
                         "interference.default.d_u")
    parse_field_path(axis.field, where=f"{where}.field")
    if given is None:
        given = [k for k in ("values", "linspace", "geomspace") if getattr(axis, k)]
    if len(given) != 1:
        raise SweepError(f"{where} ({axis.field}) needs exactly one of values, linspace, "
                         f"geomspace; got {given or 'none'}")
    if given == ["values"] and not axis.values:
        raise SweepError(f"{where}.values ({axis.field}) is empty: list at least one value")
    if axis.values:
        if not isinstance(axis.values, list):
            raise SweepError(f"{where}.values must be a list, got {axis.values!r}")
        seen = []
        for v in axis.values:
            if v in seen:
                raise SweepError(f"{where}.values lists {v!r} twice: {axis.values!r}")
            seen.append(v)
        return
    key = given[0]
    spec = getattr(axis, key)
    if len(spec) != 3 or not float(spec[2]).is_integer() or spec[2] < 1:
        raise SweepError(f"{where}.{key} must be [start, stop, count] with an integer "
                         f"count >= 1, got {spec!r}")
    if not all(math.isfinite(x) for x in spec[:2]):
        raise SweepError(f"{where}.{key} start and stop must be finite, got {spec!r}")
    if key == "geomspace" and not (spec[0] > 0 and spec[1] > 0):
        raise SweepError(f"{where}.geomspace start and stop must be > 0, got {spec!r}")
    if int(spec[2]) > 1 and spec[0] == spec[1]:
        raise SweepError(f"{where}.{key} repeats one value {int(spec[2])} times: {spec!r}")


def _check_random(r: RandomSamples, where: str) -> None:
    if r.count < 1:
        raise SweepError(f"{where}.count must be an integer >= 1, got {r.count!r}")
    if r.seed < 0:
        raise SweepError(f"{where}.seed must be an integer >= 0, got {r.seed!r}")
    if not r.ranges:
        raise SweepError(f"{where}.ranges must map at least one field path to [low, high]")
    for field, lo_hi in r.ranges.items():
        parse_field_path(field, where=f"{where}.ranges")
        if len(lo_hi) != 2 or not all(math.isfinite(x) for x in lo_hi) or lo_hi[0] > lo_hi[1]:
            raise SweepError(f"{where}.ranges[{field!r}] must be [low, high] with "
                             f"low <= high, got {lo_hi!r}")


def axis_values(axis: Axis) -> list:
    if axis.values:
        return list(axis.values)
    start, stop, count = axis.linspace or axis.geomspace
    f = np.linspace if axis.linspace else np.geomspace
    # Rounded to 12 significant digits: 0.0625 rather than 0.062500000000000001 in the columns.
    return [float(f"{x:.12g}") for x in f(float(start), float(stop), int(count))]


# --- Field paths -----------------------------------------------------------------------------

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


def _put(node: dict, obj, segs: list[_Seg], value, path: str) -> None:
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
        _put(sub, child, rest, value, path)
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
    _put(raws[k], objs[k], rest, value, path)


def _leaf_type(obj, segs: list[_Seg]):
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
    return _apply(scenario, overlay)[0]


def _apply(scenario: Scenario, overlay: dict):
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


# --- Variants --------------------------------------------------------------------------------


@dataclasses.dataclass
class Variant:
    """One run of a sweep: the resolved scenario and where it sits in the sweep."""

    # Position in the expansion (the row order of results.csv).
    index: int
    # Stable id: a hash of the variant's own values (its field values, overlay and seed), so
    # adding a value to an axis keeps the ids of the runs already done.
    run: str
    # Field path -> value, for the swept fields (axes, then random ranges).
    values: dict
    # The explicit overlay (from `variants:`), or None.
    overlay: typing.Optional[dict]
    random_seed: int
    scenario: Scenario
    scenario_yaml: str
    # Hash of scenario_yaml: a changed sweep file (base, overlay) reruns what it changed.
    scenario_hash: str

    def label(self) -> str:
        parts = [f"{k}={_shown(v)}" for k, v in self.values.items()]
        if self.overlay is not None:
            parts.append(f"variant={_flow(self.overlay)}")
        parts.append(f"random_seed={self.random_seed}")
        return ", ".join(parts)


@dataclasses.dataclass
class Sweep:
    file: SweepFile
    path: Path
    # The base scenario with the sweep's overlay applied.
    base: Scenario
    variants: list[Variant]
    # Swept field paths, in column order.
    fields: list[str]

    @property
    def has_overlays(self) -> bool:
        return bool(self.file.variants)


def load_sweep(name_or_path, *, on_warning=None) -> Sweep:
    """Load a sweep file and resolve every variant (SweepError naming the variant when one is
    rejected). Scenario warnings are collected and reported once each through `on_warning`
    (message, number of variants), not once per variant."""
    sweep_file, path = load_sweep_file(name_or_path)
    base_ref = sweep_file.base
    local = path.parent / base_ref
    base_path = local if (local.suffix in (".yaml", ".yml") or local.is_file()) else base_ref
    if isinstance(base_path, Path) and not base_path.is_file():
        raise SweepError(f"{path}: base {base_ref!r}: no file {str(base_path)!r} (a path is "
                         "relative to the sweep file)")
    try:
        resolve_scenario_path(base_path)
        resolved = load_resolved_scenario(base_path)
    except ScenarioError as e:
        raise SweepError(f"{path}: base: {e}") from None
    base = resolved.scenario
    if "initial_position" in resolved.defaulted:
        # Left out: each variant starts at its own robot's centre (an axis may change robots).
        base = dataclasses.replace(base, initial_position=None)
    try:
        base = apply_overlay(base, sweep_file.overlay)
    except ScenarioError as e:
        raise SweepError(f"{path}: overlay {_flow(sweep_file.overlay)}: {e}") from None

    grid = []
    for axis in sweep_file.axes:
        values = axis_values(axis)
        if not axis.values and _leaf_type(base, parse_field_path(axis.field)) is int:
            # A spaced axis of an integer field (sensor.filter_window): whole numbers.
            if not all(float(v).is_integer() for v in values):
                raise SweepError(f"{path}: axis {axis.field} is an integer field, but its "
                                 f"values {values} are not whole numbers")
            values = [int(v) for v in values]
        grid.append((axis.field, values))
    samples = _random_samples(sweep_file.random, base) if sweep_file.random else [{}]
    overlays = list(sweep_file.variants) or [None]
    seeds = list(sweep_file.seeds) or [None]
    fields = [f for f, _ in grid] + (list(sweep_file.random.ranges) if sweep_file.random
                                    else [])
    if len(set(fields)) != len(fields):
        dup = sorted({f for f in fields if fields.count(f) > 1})
        raise SweepError(f"{path}: field(s) {dup} are swept twice (axes and random ranges "
                         "must name different fields)")
    count = math.prod(len(v) for _, v in grid) * len(samples) * len(overlays) * len(seeds)
    if count > MAX_VARIANTS:
        raise SweepError(f"{path}: the sweep expands to {count} variants, more than "
                         f"{MAX_VARIANTS}; use fewer axis values or random samples")

    drake_warnings = _WarningCollector()
    scenario_log = logging.getLogger("cdpm_drake.config")
    scenario_log.addHandler(drake_warnings)
    previous_propagate = scenario_log.propagate
    scenario_log.propagate = False
    variants, ids = [], {}
    try:
        combos = itertools.product(itertools.product(*[v for _, v in grid]), samples,
                                   overlays, seeds)
        for index, (point, sample, overlay, seed) in enumerate(combos):
            values = dict(zip([f for f, _ in grid], point))
            values.update(sample)
            variant = _resolve_variant(index, base, values, overlay, seed, path)
            drake_warnings.count_variant()
            if variant.run in ids:
                raise SweepError(f"{path}: variants {ids[variant.run]} and {index} are the "
                                 f"same run ({variant.label()})")
            ids[variant.run] = index
            variants.append(variant)
    finally:
        scenario_log.removeHandler(drake_warnings)
        scenario_log.propagate = previous_propagate
    if on_warning is not None:
        for message, n in drake_warnings.counts.items():
            on_warning(message, n)
    if not variants:
        raise SweepError(f"{path}: the sweep has no variants")
    return Sweep(file=sweep_file, path=path, base=base, variants=variants, fields=fields)


class _WarningCollector(logging.Handler):
    """Counts distinct scenario warnings over the variants (each once per variant)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.counts = {}
        self._this_variant = set()

    def emit(self, record):
        msg = record.getMessage()
        if msg not in self._this_variant:
            self._this_variant.add(msg)
            self.counts[msg] = self.counts.get(msg, 0) + 1

    def count_variant(self):
        self._this_variant = set()


def _resolve_variant(index, base, values, overlay, seed, path) -> Variant:
    from cdpm_drake.config import warn_reel_saturation, warn_unreachable_d_u

    coords = {"values": values, "overlay": overlay, "random_seed": seed}
    run = "r" + hashlib.sha1(json.dumps(coords, sort_keys=True, default=repr).encode()
                             ).hexdigest()[:10]
    shown = ", ".join([f"{k}={_shown(v)}" for k, v in values.items()]
                      + ([f"variant={_flow(overlay)}"] if overlay is not None else [])
                      + ([f"random_seed={seed}"] if seed is not None else []))
    where = f"{path}: variant {index + 1} (run {run}: {shown or 'the base'})"
    scenario = base
    try:
        if overlay is not None:
            scenario = apply_overlay(scenario, overlay)
        assign = {}
        if scenario.initial_position is None and any(
                f.startswith("initial_position") for f in values):
            # One coordinate of a left-out start edits the robot's centre.
            scenario = resolve_scenario(scenario).scenario
        for field, value in values.items():
            _put(assign, scenario, parse_field_path(field), value, field)
        if seed is not None:
            assign["random_seed"] = seed
        scenario, resolved = _apply(scenario, assign)
        resolved = resolved or resolve_scenario(scenario)
        robot = resolved.robot
        if scenario.interference.enabled and robot.num_pairs:
            warn_unreachable_d_u(robot, interference_params(scenario, robot))
        warn_reel_saturation(scenario, robot)
    except (ScenarioError, SweepError) as e:
        raise SweepError(f"{where}: {e}") from None
    if _is_hardware(scenario.plant):
        raise SweepError(f"{where}: plant is !{type(scenario.plant).__name__}; a sweep "
                         "simulates, so it needs a simulated plant (plant: !SimulatedReels {})")
    scenario = resolved.scenario  # as run: a left-out start is its robot's centre
    text = scenario_to_yaml(scenario)
    return Variant(index=index, run=run, values=values, overlay=overlay,
                   random_seed=scenario.random_seed, scenario=scenario, scenario_yaml=text,
                   scenario_hash=hashlib.sha256(text.encode()).hexdigest()[:16])


def _is_hardware(plant) -> bool:
    try:
        from cdpm_drake.hardware.config import HardwareReels
    except ImportError:
        return False
    return isinstance(plant, HardwareReels)


def _random_samples(r: RandomSamples, base: Scenario) -> list[dict]:
    rng = np.random.default_rng(r.seed)
    kinds = {f: _leaf_type(base, parse_field_path(f)) for f in r.ranges}
    samples = []
    for _ in range(r.count):
        sample = {}
        for field, (lo, hi) in r.ranges.items():
            if kinds[field] is int:
                sample[field] = int(rng.integers(math.ceil(lo), math.floor(hi) + 1))
            else:
                sample[field] = float(f"{rng.uniform(lo, hi):.12g}")
        samples.append(sample)
    return samples


def _flow(value) -> str:
    """Compact one-line YAML of raw data (for messages and the `variant` column)."""
    if isinstance(value, dict):
        tag = value.get("_tag")
        inner = "{" + ", ".join(f"{k}: {_flow(v)}" for k, v in value.items()
                                if k != "_tag") + "}"
        return f"{tag} {inner}" if tag else inner
    if isinstance(value, list):
        return "[" + ", ".join(_flow(v) for v in value) + "]"
    return _shown(value)


def _shown(value) -> str:
    """A value in a message: as a CSV cell, but a NaN or infinite float spelled out (an
    empty cell would read as no value at all)."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return _cell(value)


def _cell(value) -> str:
    """One CSV cell: floats in full precision (repr), booleans as YAML writes them."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    if isinstance(value, (int, str)):
        return str(value)
    return _flow(value)


# --- Metrics ---------------------------------------------------------------------------------

# Quantities in m are shown in mm (tables, pictures) (the paper's distances are in mm).
UNIT_SCALE = {"m": (1000.0, "mm")}

# A swept field's last name -> (what it is, unit in SI), by the section it is in
# (scenario.py's comments). "" for the section: a top-level field.
FIELDS = {
    ("interference", "d_l"): ("d_l", "m"), ("interference", "d_u"): ("d_u", "m"),
    ("interference", "F_u"): ("F_u", "N"), ("interference", "eps"): ("eps", "N"),
    ("interference", "F_max"): ("F_max, the clip of |F_int|", "N"),
    ("interference", "gradient_floor"): ("gradient floor", "-"),
    ("admittance", "mass"): ("admittance mass M", "kg"),
    ("admittance", "damping"): ("admittance damping C", "N s/m"),
    ("limits", "max_velocity"): ("speed limit", "m/s"),
    ("limits", "max_acceleration"): ("acceleration limit", "m/s^2"),
    ("wall_force", "margin"): ("wall force margin", "m"),
    ("wall_force", "max_force"): ("wall force at the face", "N"),
    ("sensor", "filter_window"): ("sensor filter window", "samples"),
    ("sensor", "noise_std"): ("sensor noise std", "N"),
    ("sensor", "axial_range"): ("sensor axial range", "N"),
    ("sensor", "transverse_range"): ("sensor transverse range", "N"),
    ("operator", "max_force"): ("hand's largest force", "N"),
    ("operator", "stiffness"): ("hand stiffness", "N/m"),
    ("operator", "damping"): ("hand damping", "N s/m"),
    ("operator", "release_time"): ("hand lets go at", "s"),
    ("plant", "time_constant"): ("reel time constant", "s"),
    ("plant", "max_reel_speed"): ("reel speed limit", "m/s"),
    ("plant", "time_step"): ("plant time step", "s"),
    ("plant", "min_tension"): ("start tension floor", "N"),
    ("plant", "max_length_residual"): ("largest length residual", "m"),
    ("", "duration"): ("duration", "s"),
    ("", "time_step"): ("control period", "s"),
    ("", "random_seed"): ("random seed", "-"),
}


def field_axis(field: str) -> tuple[str, float]:
    """(label with its unit, scale from the field's SI value to the drawn one) of a swept
    field path: `interference.default.d_u` -> ("d_u, every pair (mm)", 1000);
    `interference.pairs[1,3].F_u` -> ("F_u of pair 1-3 (N)", 1); `initial_position[2]` ->
    ("start z (mm)", 1000). A field not in FIELDS keeps its path, without a unit."""
    parts = field.split(".")
    last = parts[-1]
    pair = re.search(r"pairs\[(\d+)\s*[,-]\s*(\d+)\]", field)
    start = re.fullmatch(r"initial_position\[(\d)\]", field)
    if start and int(start.group(1)) < 3:
        what, unit = f"start {'xyz'[int(start.group(1))]}", "m"
    elif (parts[0] if len(parts) > 1 else "", last) in FIELDS:
        what, unit = FIELDS[(parts[0] if len(parts) > 1 else "", last)]
        if parts[0] == "interference" and len(parts) == 3 and parts[1] == "default":
            what += ", every pair"
        elif pair:
            what += f" of pair {pair.group(1)}-{pair.group(2)}"
    else:
        return field, 1.0
    scale, shown = UNIT_SCALE.get(unit, (1.0, unit))
    return (f"{what} ({shown})" if shown != "-" else what), scale



# name -> (unit, which way is better, what). docs/SWEEP_FORMAT.md says the same in prose.
METRICS = {
    "min_distance": ("m", "max", "smallest distance of any watched cable pair over the run"),
    "min_distance_pair": ("-", None, "the pair where min_distance occurred, e.g. 1-3"),
    "time_below_d_l": ("s", "min", "time during which any pair was below its d_l"),
    "crossings": ("-", "min", "number of pairs that crossed at least once"),
    "peak_F_int": ("N", "min", "largest |F_int| (interference force)"),
    "peak_F_d": ("N", "min", "largest |F_d| (desired force F_H + F_int + F_wall)"),
    "peak_speed": ("m/s", None, "largest |velocity| commanded after the limits"),
    "operator_effort": ("N s", "min", "integral of |F_H| dt (what the operator pushed)"),
    "limit_time": ("s", "min", "time during which the limits changed the admittance velocity"),
    # The plant's ground truth (the dynamic plant, which logs its true pose); empty for the
    # kinematic plant, whose pose is the controller's estimate.
    "min_distance_true": ("m", "max", "smallest TRUE distance of any watched cable pair, from "
                                      "the plant's true (rotated) pose (dynamic plant)"),
    "min_distance_true_pair": ("-", None, "the pair where min_distance_true occurred"),
    "crossings_true": ("-", "min", "number of pairs that truly crossed (dynamic plant)"),
    "slack_ticks": ("-", "min", "ticks with at least one slack cable (dynamic plant)"),
    "min_tension": ("N", "max", "smallest cable tension over the run (dynamic plant)"),
    "max_rotation": ("deg", "min", "largest platform rotation from level (dynamic plant)"),
    "sim_s": ("s", None, "simulated time the run covered"),
    "wall_s": ("s", "min", "wall-clock time of the run (build and simulate)"),
    "rtf": ("-", "max", "real-time factor: sim_s / wall_s"),
}
NUMERIC_METRICS = [m for m in METRICS if not m.endswith("_pair")]
# A row's status: "ok"; "fault": the run stopped part-way, its metrics cover the ticks it
# logged; "error": it did not run (or its worker died), no metrics.
FAILED = ("fault", "error")

# A limit "acts" when the commanded velocity differs from the admittance's by more than this,
# m/s: the limits pass an unlimited velocity through exactly, so this only absorbs round-off.
LIMIT_TOLERANCE = 1e-9


def run_metrics(log: dict, scenario: Scenario) -> dict:
    """The sweep's metrics of one log (docs/LOG_FORMAT.md). Durations and the effort are left
    Riemann sums over the ticks: the value at a tick holds until the next (zero-order hold)."""
    t = np.asarray(log["time"], dtype=float)
    T = t.size
    dt = np.diff(t) if T > 1 else np.zeros(0)

    def held(mask_or_values):  # sum over ticks 0..T-2 of value * (t[k+1] - t[k])
        v = np.asarray(mask_or_values, dtype=float)[:-1] if T > 1 else np.zeros(0)
        return float(np.sum(v * dt))

    def peak(key):
        x = np.asarray(log.get(key, np.zeros((0, 3))), dtype=float)
        return float(np.linalg.norm(x, axis=1).max()) if x.size else 0.0

    out = {}
    d = np.asarray(log["pair_distances"], dtype=float).reshape(T, -1)
    pairs = np.asarray(log["pairs"]).reshape(-1, 2)
    if d.size:
        flat = int(np.argmin(d))
        k = flat % d.shape[1]
        out["min_distance"] = float(d.reshape(-1)[flat])
        out["min_distance_pair"] = f"{int(pairs[k][0])}-{int(pairs[k][1])}"
        d_l = np.asarray(log["d_l"], dtype=float)
        if not np.all(np.isfinite(d_l)):  # interference off: the log has no d_l, the config does
            d_l = np.asarray(interference_params(scenario, scenario_robot(scenario)).d_l)
        out["time_below_d_l"] = held(np.any(d < d_l[None, :], axis=1))
    else:
        out.update(min_distance=math.nan, min_distance_pair="", time_below_d_l=0.0)
    # The crossing flags come from the interference block; without it (the log's logistic
    # parameters are NaN then, docs/LOG_FORMAT.md) the log has none.
    has_block = d.shape[1] > 0 and bool(np.all(np.isfinite(np.asarray(log["d_l"], float))))
    out["crossings"] = (int(np.any(np.asarray(log["crossed"]), axis=0).sum()) if has_block
                        and T else math.nan)
    out["peak_F_int"] = peak("F_int")
    out["peak_F_d"] = peak("F_d")
    out["peak_speed"] = peak("velocity")
    F_H = np.asarray(log["F_H"], dtype=float).reshape(T, 3)
    out["operator_effort"] = held(np.linalg.norm(F_H, axis=1))
    v = np.asarray(log["velocity"], dtype=float).reshape(T, 3)
    v_adm = np.asarray(log["velocity_admittance"], dtype=float).reshape(T, 3)
    out["limit_time"] = held(np.any(np.abs(v - v_adm) > LIMIT_TOLERANCE, axis=1))
    out.update(_truth_metrics(log, T, pairs))
    out["sim_s"] = float(t[-1] - t[0]) if T > 1 else 0.0
    return out


def _truth_metrics(log: dict, T: int, pairs) -> dict:
    """The dynamic plant's ground-truth metrics (METRICS), NaN / "" for a log without them."""
    out = dict(min_distance_true=math.nan, min_distance_true_pair="", crossings_true=math.nan,
               slack_ticks=math.nan, min_tension=math.nan, max_rotation=math.nan)
    if not T:
        return out
    if "pair_distances_true" in log:
        d = np.asarray(log["pair_distances_true"], dtype=float).reshape(T, -1)
        if d.size:
            flat = int(np.argmin(d))
            k = flat % d.shape[1]
            out["min_distance_true"] = float(d.reshape(-1)[flat])
            out["min_distance_true_pair"] = f"{int(pairs[k][0])}-{int(pairs[k][1])}"
        out["crossings_true"] = int(np.any(np.asarray(log["crossed_true"]), axis=0).sum())
    if "tensions" in log:
        out["slack_ticks"] = int(np.any(np.asarray(log["slack"], dtype=bool), axis=1).sum())
        out["min_tension"] = float(np.min(log["tensions"]))
    if "rpy_true" in log:
        from cdpm_drake.kernels.rotation import rotation_angle, rotations_from_rpy
        out["max_rotation"] = float(np.degrees(
            rotation_angle(rotations_from_rpy(log["rpy_true"])).max()))
    return out


# --- One run (in a worker) -------------------------------------------------------------------


@dataclasses.dataclass
class RunTask:
    """What a worker needs for one run (picklable; a Ray task carries a list of them)."""

    run: str
    index: int
    values: dict
    scenario_yaml: str
    scenario_hash: str
    keep_log: bool = False


def tasks_for(variants, keep_logs: bool = False) -> list[RunTask]:
    return [RunTask(run=v.run, index=v.index, values=v.values, scenario_yaml=v.scenario_yaml,
                    scenario_hash=v.scenario_hash, keep_log=keep_logs) for v in variants]


def execute_run(task: RunTask, before_run=None) -> dict:
    """Run one variant: load its resolved scenario from its YAML (the file written beside the
    row), simulate it, and return its row (and the compressed log bytes with keep_log).
    Never raises for a failing run: the row says `error` (it did not run, or its worker
    died), or `fault` (it stopped part-way: the metrics are those of the ticks it logged)."""
    from pydrake.common.yaml import yaml_load_typed

    from cdpm_drake.runs.simulate import simulate

    row = {"run": task.run, "scenario_hash": task.scenario_hash, "status": "ok", "error": ""}
    start = time.perf_counter()
    cpu = time.process_time()
    log = None
    try:
        if before_run is not None:
            before_run(task)
        scenario = yaml_load_typed(schema=Scenario, data=task.scenario_yaml)
        result = simulate(scenario=scenario)
        wall = time.perf_counter() - start
        log = result.log
        metrics = run_metrics(log, scenario)
        row.update(metrics)  # a faulted run's too: what it logged up to the fault
        if result.error is not None:
            row.update(status="fault", error=f"the run stopped at t = {metrics['sim_s']:.3f} s: "
                                             f"{type(result.error).__name__}: {result.error}")
        row["wall_s"] = wall
        row["rtf"] = metrics["sim_s"] / wall if wall > 0 else math.nan
    except Exception as e:
        row.update(status="error", error=f"{type(e).__name__}: {e}",
                   wall_s=time.perf_counter() - start)
    # Internal (not a column): CPU seconds of the run, which bench_sweep.py sets against wall
    # time to tell a busy machine from overhead of ours.
    row["_cpu_s"] = time.process_time() - cpu
    if task.keep_log and log is not None:
        buf = io.BytesIO()
        np.savez_compressed(buf, **log)
        row["_log_npz"] = buf.getvalue()
    return row


def _worker_main(conn, before_run):
    """A local worker: imported once (warm start), then runs tasks until told to stop."""
    # Ctrl-C reaches the whole process group; the parent decides what stops and when.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    from cdpm_drake.runs import simulate as simulation  # noqa: F401  (the warm start: pydrake and the blocks, once)
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        conn.send(execute_run(task, before_run))


# --- Runners ---------------------------------------------------------------------------------


def _describe_exit(code) -> str:
    if code is None:
        return "still running"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


class LocalRunner:
    """One spawned process per worker, each fed one run at a time over its own pipe, so a
    worker that dies is known to have died on that run (its error row), and is replaced.
    The pool lives from the first `run` to `close` (a benchmark warms it up once)."""

    def __init__(self, workers: int, before_run=None):
        import multiprocessing
        self.workers = int(workers)
        self._ctx = multiprocessing.get_context("spawn")
        self._before_run = before_run
        self._pool = []

    def describe(self) -> str:
        return f"{self.workers} local worker process{'es' if self.workers != 1 else ''}"

    def _start(self):
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_worker_main, args=(child, self._before_run),
                                 daemon=True, name="cdpm-sweep-worker")
        proc.start()
        child.close()
        return {"conn": parent, "proc": proc, "task": None}

    def run(self, tasks: list[RunTask], on_row, should_stop) -> None:
        """Run the tasks; returns when all are done, or as soon as should_stop() is true (the
        runs under way are then abandoned: close() stops their workers)."""
        from multiprocessing.connection import wait

        pending = list(reversed(tasks))
        pool = self._pool
        while len(pool) < min(self.workers, len(tasks)):
            pool.append(self._start())
        while pending or any(w["task"] is not None for w in pool):
            if should_stop():
                return
            for w in pool:
                if w["task"] is None and pending:
                    w["task"] = pending.pop()
                    w["conn"].send(w["task"])
            busy = [w for w in pool if w["task"] is not None]
            wait([w["conn"] for w in busy] + [w["proc"].sentinel for w in busy], timeout=0.25)
            for k, w in enumerate(pool):
                if w["task"] is None:
                    continue
                row = None
                try:
                    if w["conn"].poll():
                        row = w["conn"].recv()
                except (EOFError, OSError):
                    row = None
                if row is not None:
                    w["task"] = None
                    on_row(row)
                elif not w["proc"].is_alive():
                    w["proc"].join()
                    on_row(_died_row(w["task"], "the worker process died "
                                                f"({_describe_exit(w['proc'].exitcode)}) "
                                                "while running this variant"))
                    w["conn"].close()
                    pool[k] = self._start()

    def close(self) -> None:
        """Stop every worker: idle ones are told to quit, busy ones are terminated."""
        pool, self._pool = self._pool, []
        for w in pool:
            try:
                if w["task"] is None and w["proc"].is_alive():
                    w["conn"].send(None)
            except OSError:
                pass
        deadline = time.monotonic() + 2.0
        for w in pool:
            if w["task"] is not None:
                w["proc"].terminate()
            w["proc"].join(timeout=max(0.0, deadline - time.monotonic()))
            if w["proc"].is_alive():
                w["proc"].kill()
                w["proc"].join()
            w["conn"].close()


def _died_row(task: RunTask, why: str) -> dict:
    return {"run": task.run, "scenario_hash": task.scenario_hash, "status": "error",
            "error": why}


def _ray_chunk(tasks, before_run):
    """A Ray task: several runs in one go, so Ray's per-task cost is spread over them."""
    from cdpm_drake.runs import simulate as simulation  # noqa: F401
    rows = []
    for task in tasks:
        start = time.perf_counter()
        row = execute_run(task, before_run)
        row["_task_s"] = time.perf_counter() - start
        rows.append(row)
    return rows


class RayRunner:
    """Runs grouped into Ray tasks. `address` None starts a local Ray (unless one is already
    initialised, as in the tests); a cluster's nodes need cdpm_drake installed."""

    def __init__(self, address=None, chunk=None, before_run=None, init_kwargs=None):
        self.address = address
        self.chunk = chunk
        self._before_run = before_run
        self._init_kwargs = dict(init_kwargs or {})
        self._started = False
        self.cpus = None
        self.chunks = 0
        self.task_stats = []

    def describe(self) -> str:
        where = self.address or "a local Ray"
        return f"Ray ({where}, {self.cpus:g} CPUs, {self.chunks} tasks)"

    def connect(self):
        try:
            import ray
        except ImportError:
            raise SweepError("--ray needs Ray: pip install -e '.[ray]' (or pip install "
                             "'ray>=2.9')") from None
        if not ray.is_initialized():
            kwargs = {"include_dashboard": False, "log_to_driver": False, **self._init_kwargs}
            if self.address:
                kwargs["address"] = self.address
            try:
                ray.init(**kwargs)
            except Exception as e:
                raise SweepError(f"--ray {self.address or ''}: cannot start or reach Ray: "
                                 f"{e}") from None
            self._started = True
        self.cpus = float(ray.cluster_resources().get("CPU", 1.0))
        return ray

    def chunk_size(self, tasks: list[RunTask], durations: list[float]) -> int:
        """Runs per task: enough that a task lasts >= 2 s of estimated compute (Ray's
        per-task cost is a few ms, so < 1 % then), yet >= 3 tasks per CPU for balance."""
        if self.chunk:
            return max(1, int(self.chunk))
        n = len(tasks)
        # 5x real time is what one run of the shipped experiments does here (bench_sweep.py).
        est = max(1e-3, float(np.mean(durations)) / 5.0) if durations else 1.0
        by_time = math.ceil(2.0 / est)
        by_balance = max(1, n // max(1, int(3 * self.cpus)))
        return max(1, min(by_time, by_balance))

    def run(self, tasks: list[RunTask], on_row, should_stop, durations=()) -> None:
        ray = self.connect()
        import ray.exceptions as rex

        remote = ray.remote(max_retries=0)(_ray_chunk)
        size = self.chunk_size(tasks, list(durations))
        refs = {}

        def submit(group):
            refs[remote.remote(group, self._before_run)] = group

        for k in range(0, len(tasks), size):
            submit(tasks[k:k + size])
        self.chunks = len(refs)
        while refs:
            if should_stop():
                for ref in refs:
                    ray.cancel(ref, force=True)
                return
            done, _ = ray.wait(list(refs), num_returns=1, timeout=0.25)
            for ref in done:
                group = refs.pop(ref)
                try:
                    rows = ray.get(ref)
                except (rex.WorkerCrashedError, rex.RayTaskError, rex.TaskCancelledError,
                        rex.NodeDiedError, rex.ObjectLostError) as e:
                    if len(group) > 1:  # find the run that kills: one task each
                        for task in group:
                            submit([task])
                        self.chunks += len(group)
                        continue
                    rows = [_died_row(group[0], "the Ray worker died while running this "
                                                f"variant ({type(e).__name__})")]
                # (runs in the task, seconds of compute inside it): for bench_sweep.py.
                self.task_stats.append((len(rows), sum(r.get("_task_s", 0.0) for r in rows)))
                for row in rows:
                    on_row(row)

    def close(self) -> None:
        """Shut Ray down if this runner started it (a Ray the caller started stays up)."""
        if self._started:
            import ray
            ray.shutdown()
            self._started = False


# --- The sweep -------------------------------------------------------------------------------


def columns_for(sweep: Sweep) -> list[str]:
    cols = ["run"] + list(sweep.fields)
    if sweep.has_overlays:
        cols.append("variant")
    cols += ["random_seed", "status", "error"]
    cols += list(METRICS) + ["scenario_hash"]
    return cols


def _atomic_write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


class ResultStore:
    """DIR/results.csv and DIR/runs/<run>/: rows kept as they finish (row.json at once,
    results.csv rewritten atomically at most every `csv_period` s and at the end)."""

    def __init__(self, sweep: Sweep, out_dir: Path, csv_period: float = 1.0):
        self.sweep = sweep
        self.out = Path(out_dir)
        self.columns = columns_for(sweep)
        self.rows = {}  # run id -> row (as written)
        self._csv_period = csv_period
        self._last_csv = 0.0
        self._dirty = False

    def run_dir(self, run: str) -> Path:
        return self.out / "runs" / run

    def previous(self) -> dict:
        """Rows of earlier invocations found under DIR/runs/ (run id -> row)."""
        found = {}
        for v in self.sweep.variants:
            p = self.run_dir(v.run) / "row.json"
            if p.is_file():
                try:
                    found[v.run] = json.loads(p.read_text())
                except (OSError, ValueError):
                    continue  # half-written by a killed process: rerun
        return found

    def prepare(self, variant: Variant) -> None:
        d = self.run_dir(variant.run)
        d.mkdir(parents=True, exist_ok=True)
        _atomic_write(d / "scenario.yaml", variant.scenario_yaml.encode())
        stale = d / "row.json"
        if stale.exists():
            stale.unlink()

    def keep(self, variant: Variant, row: dict) -> None:
        log = row.pop("_log_npz", None)
        row.pop("_task_s", None)
        row.pop("_cpu_s", None)
        full = self._full_row(variant, row)
        d = self.run_dir(variant.run)
        d.mkdir(parents=True, exist_ok=True)
        if log is not None:
            _atomic_write(d / "log.npz", log)
        _atomic_write(d / "row.json", json.dumps(full, indent=1).encode())
        self.rows[variant.run] = full
        self._dirty = True
        if time.monotonic() - self._last_csv >= self._csv_period:
            self.flush()

    def adopt(self, variant: Variant, row: dict) -> None:
        self.rows[variant.run] = self._full_row(variant, row)
        self._dirty = True

    def _full_row(self, variant: Variant, row: dict) -> dict:
        full = {c: "" for c in self.columns}
        for k, v in variant.values.items():
            full[k] = _cell(v)
        if self.sweep.has_overlays:
            full["variant"] = _flow(variant.overlay) if variant.overlay is not None else ""
        full["random_seed"] = str(variant.random_seed)
        for k, v in row.items():
            if k in full and k not in variant.values:
                full[k] = v if isinstance(v, str) else _cell(v)
        full["run"] = variant.run
        full["scenario_hash"] = variant.scenario_hash
        return full

    def flush(self) -> Path:
        self.out.mkdir(parents=True, exist_ok=True)
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=self.columns, lineterminator="\n")
        w.writeheader()
        for v in self.sweep.variants:
            if v.run in self.rows:
                w.writerow(self.rows[v.run])
        path = self.out / "results.csv"
        _atomic_write(path, buf.getvalue().encode())
        self._last_csv = time.monotonic()
        self._dirty = False
        return path


@dataclasses.dataclass
class SweepOutcome:
    # "done", "interrupted" (SIGINT) or "terminated" (SIGTERM).
    ending: str
    rows: list[dict]
    skipped: int
    ran: int
    failed: int
    wall_s: float
    results: Path
    runner: str = ""


def default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


def run_sweep(sweep: Sweep, out_dir, *, workers: int | None = None, ray: bool = False,
              ray_address: str | None = None, ray_chunk: int | None = None,
              ray_init: dict | None = None, keep_logs: bool = False,
              retry_errors: bool = False, progress: bool = True,
              before_run=None) -> SweepOutcome:
    """Run every variant not already done in `out_dir`; return the rows in sweep order.

    `before_run(task)` is called in the worker before each run (an extension point; the
    tests use it to make a variant kill its worker). Ctrl-C and SIGTERM stop the sweep: the
    runs under way are abandoned (rerun next time), every finished row is kept."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    lock = _lock(out_dir)
    try:
        return _run_sweep(sweep, out_dir, workers=workers, ray=ray, ray_address=ray_address,
                          ray_chunk=ray_chunk, ray_init=ray_init, keep_logs=keep_logs,
                          retry_errors=retry_errors, progress=progress, before_run=before_run)
    finally:
        _unlock(lock, out_dir)


LOCK_FILE = ".sweep.lock"


def _lock(out_dir: Path):
    """An exclusive lock on DIR/.sweep.lock, which says who holds it (pid, start time): two
    sweeps writing one directory would run the same variants twice and race on results.csv.
    The file exists only while a sweep runs (`_unlock` removes it)."""
    path = out_dir / LOCK_FILE
    while True:
        f = open(path, "a+")
        try:
            import fcntl
        except ImportError:  # not POSIX: no lock
            return f
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.seek(0)
            holder = f.read().strip()
            f.close()
            raise SweepError(f"--out {str(out_dir)!r} is in use by another cdpm sweep"
                             + (f" ({holder})" if holder else "")
                             + "; wait for it or give another --out") from None
        # A sweep that finished between our open and our lock removed the file we hold:
        # lock the one at the path now, or a third sweep could take that one alongside.
        try:
            current = os.stat(path).st_ino == os.fstat(f.fileno()).st_ino
        except FileNotFoundError:
            current = False
        if current:
            f.seek(0)
            f.truncate()
            f.write(f"pid {os.getpid()}, since {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
            f.flush()
            return f
        f.close()


def _unlock(f, out_dir: Path) -> None:
    """Remove DIR/.sweep.lock while still holding it (a sweep waiting for it then finds it
    gone and takes a new one), then release it."""
    try:
        (out_dir / LOCK_FILE).unlink(missing_ok=True)
    finally:
        f.close()


def _run_sweep(sweep, out_dir, *, workers, ray, ray_address, ray_chunk, ray_init, keep_logs,
               retry_errors, progress, before_run) -> SweepOutcome:
    store = ResultStore(sweep, out_dir)
    _atomic_write(out_dir / "sweep.yaml", sweep.path.read_bytes())
    previous = store.previous()
    todo = []
    for v in sweep.variants:
        row = previous.get(v.run)
        if row is not None and row.get("scenario_hash") == v.scenario_hash and (
                row.get("status") == "ok" or (row.get("status") in FAILED
                                              and not retry_errors)):
            store.adopt(v, row)
        else:
            todo.append(v)
    skipped = len(sweep.variants) - len(todo)
    store.flush()
    by_run = {v.run: v for v in sweep.variants}
    if ray:
        runner = RayRunner(address=ray_address, chunk=ray_chunk, before_run=before_run,
                           init_kwargs=ray_init)
    else:
        n = default_workers() if workers is None else int(workers)
        if n < 1:
            raise SweepError(f"--workers must be an integer >= 1, got {workers!r}")
        runner = LocalRunner(n, before_run=before_run)

    stop = {"signal": None}

    def on_signal(signum, frame):
        stop["signal"] = signum

    installed = {}
    import threading

    from cdpm_drake.runs.interrupt import honoured
    if threading.current_thread() is threading.main_thread():
        for s in (signal.SIGINT, signal.SIGTERM):
            if honoured(s):  # one ignored when the sweep started stays ignored
                installed[s] = signal.signal(s, on_signal)
    bar = None
    failed = [0]
    start = time.perf_counter()
    try:
        for v in todo:
            store.prepare(v)
        tasks = tasks_for(todo, keep_logs=keep_logs)
        if tasks and progress:
            from tqdm import tqdm
            bar = tqdm(total=len(tasks), desc=f"sweep {sweep.file.name}", unit="run",
                       file=sys.stderr, dynamic_ncols=True)
            bar.set_postfix(failed=0)

        def on_row(row):
            v = by_run[row["run"]]
            store.keep(v, row)
            if row.get("status") != "ok":
                failed[0] += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(failed=failed[0])

        if tasks:
            try:
                if ray:
                    runner.run(tasks, on_row, lambda: stop["signal"] is not None,
                               durations=[v.scenario.duration for v in todo])
                else:
                    runner.run(tasks, on_row, lambda: stop["signal"] is not None)
            finally:
                runner.close()
    finally:
        if bar is not None:
            bar.close()
        results = store.flush()
        for s, handler in installed.items():
            signal.signal(s, handler)
    ending = {None: "done", signal.SIGINT: "interrupted",
              signal.SIGTERM: "terminated"}[stop["signal"]]
    rows = [store.rows[v.run] for v in sweep.variants if v.run in store.rows]
    describe = runner.describe() if (tasks and (not ray or runner.cpus is not None)) else ""
    return SweepOutcome(ending=ending, rows=rows, skipped=skipped, ran=len(rows) - skipped,
                        failed=failed[0], wall_s=time.perf_counter() - start,
                        results=results, runner=describe)


# --- Reading results back --------------------------------------------------------------------


def read_results(path) -> tuple[list[str], list[dict]]:
    """(columns, rows) of DIR/results.csv (or the file itself); SweepError when missing."""
    path = Path(path)
    if path.is_dir():
        path = path / "results.csv"
    if not path.is_file():
        raise SweepError(f"no sweep results at {str(path)!r} (cdpm sweep writes "
                         "DIR/results.csv)")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
        cols = list(reader.fieldnames or [])
    if "run" not in cols or "random_seed" not in cols or "status" not in cols:
        raise SweepError(f"{str(path)!r} is not a results.csv written by cdpm sweep (it has "
                         f"the columns {cols})")
    return cols, rows


def swept_fields(columns: list[str]) -> list[str]:
    """The swept field columns: between `run` and `random_seed` (docs/SWEEP_FORMAT.md)."""
    return columns[columns.index("run") + 1:columns.index("random_seed")]


def metric_value(row: dict, metric: str) -> float:
    try:
        return float(row.get(metric, ""))
    except ValueError:
        return math.nan


def best_rows(rows: list[dict], metric: str, top: int = 5) -> list[dict]:
    """The `top` ok rows, best first by the metric's better direction (min_distance: largest)."""
    if metric not in NUMERIC_METRICS:
        raise SweepError(f"metric {metric!r} cannot rank runs; valid metrics: "
                         f"{NUMERIC_METRICS}")
    better = _better(metric)
    ok = [r for r in rows if r.get("status") == "ok" and math.isfinite(metric_value(r, metric))]
    sign = -1.0 if better == "max" else 1.0
    return sorted(ok, key=lambda r: sign * metric_value(r, metric))[:max(0, int(top))]


def _better(metric: str) -> str:
    """"max" or "min": which way ranks first (metrics without a better side: largest)."""
    return METRICS[metric][1] or "max"


def best_table(columns: list[str], rows: list[dict], metric: str, top: int = 5) -> str:
    from cdpm_drake.text import format_table

    best = best_rows(rows, metric, top)
    fields = swept_fields(columns)
    shown = [metric] + [m for m in ("min_distance", "operator_effort", "crossings")
                        if m != metric]
    table = ([("run", [r["run"] for r in best])]
             + [field_column(f, [r[f] for r in best]) for f in fields]
             + [("random_seed", [r["random_seed"] for r in best])]
             + [metric_column(m, [r.get(m, "") for r in best]) for m in shown])
    return format_table([h for h, _ in table], list(zip(*[c for _, c in table])))


# Decimals of a metric in the tables, by the unit it is shown in: distances to 0.01 mm (as
# the summaries), forces and effort to 0.01 N (N s), times and speeds to 0.001, degrees to
# 0.01; a count ("-") whole, another unitless number to 0.01.
TABLE_DECIMALS = {"mm": 2, "N": 2, "N s": 2, "s": 3, "m/s": 3, "deg": 2}


def _unit_of(label: str) -> str:
    """The unit in a label's last parentheses ("d_u, every pair (mm)" -> "mm"), or ""."""
    return label.rsplit("(", 1)[1].rstrip(")") if label.endswith(")") else ""


def _numbers(cells) -> list:
    out = []
    for c in cells:
        try:
            x = float(c)
        except (TypeError, ValueError):
            x = None
        out.append(x if x is not None and math.isfinite(x) else None)
    return out


def _column(cells, scale: float, decimals: int | None) -> list[str]:
    """Cells as numbers in the shown unit, all with the same decimals (`decimals`, or the
    fewest, at most 6, that show every value exactly); a cell that is no number as it is."""
    nums = _numbers(cells)
    values = [None if x is None else scale * x for x in nums]
    if decimals is None:
        decimals = next((d for d in range(7) if all(
            v is None or abs(v - round(v, d)) <= 1e-9 * max(1.0, abs(v)) for v in values)), 6)
    return [str(c) if v is None else f"{v:.{decimals}f}" for c, v in zip(cells, values)]


def field_column(field: str, cells) -> tuple[str, list[str]]:
    """(header, cells) of a swept field in a table: its path with the unit it is shown in
    (m as mm, as the summaries and pictures), every value with the same decimals."""
    label, scale = field_axis(field)
    unit = _unit_of(label) if label != field else ""
    return (f"{field} ({unit})" if unit else field), _column(cells, scale, None)


def metric_column(metric: str, cells) -> tuple[str, list[str]]:
    """(header, cells) of a metric in a table: its name with the unit it is shown in (m as
    mm), decimals by that unit (TABLE_DECIMALS)."""
    unit = METRICS[metric][0]
    scale, shown = UNIT_SCALE.get(unit, (1.0, unit))
    nums = [x for x in _numbers(cells) if x is not None]
    decimals = TABLE_DECIMALS.get(shown, 0 if all(x == int(x) for x in nums) else 2)
    return f"{metric} ({shown})", _column(cells, scale, decimals)


# --- The command -----------------------------------------------------------------------------


def sweep_main(*, sweep, out_dir=None, workers=None, ray=False, ray_address=None,
               ray_chunk=None, keep_logs=False, retry_errors=False, plot=None, metric=None,
               top=5, dry_run=False, progress=True, out=None, before_run=None,
               ray_init=None) -> int:
    """`cdpm sweep`: load and check every variant, run what is not done, write the results,
    print the best runs. Exit code 0 (all ok), 1 (some runs failed), 130/143 (SIGINT/SIGTERM:
    every finished row is kept)."""
    out = sys.stdout if out is None else out

    def warn(message, n):
        print(f"cdpm sweep: warning ({n} variant{'s' if n != 1 else ''}): {message}",
              file=sys.stderr)

    s = load_sweep(sweep, on_warning=warn)
    metric = metric or s.file.metric
    if metric not in NUMERIC_METRICS:
        raise SweepError(f"--metric {metric!r} is not a metric that ranks runs; valid "
                         f"metrics: {NUMERIC_METRICS}")
    out_dir = Path(out_dir) if out_dir is not None else Path("runs") / "sweeps" / s.file.name
    total_sim = sum(v.scenario.duration for v in s.variants)
    print(f"sweep {s.file.name!r} ({s.path}): {len(s.variants)} runs of {s.base.name!r}, "
          f"{total_sim:g} s simulated in all; fields: {', '.join(s.fields) or '-'}", file=out)
    if dry_run:
        from cdpm_drake.text import format_table
        table = ([("run", [v.run for v in s.variants])]
                 + [field_column(f, [_cell(v.values[f]) for v in s.variants])
                    for f in s.fields]
                 + [("random_seed", [v.random_seed for v in s.variants])])
        print(format_table([h for h, _ in table], list(zip(*[c for _, c in table]))),
              file=out)
        print(f"dry run: nothing ran; the results would go to {out_dir / 'results.csv'} "
              f"(each run's scenario.yaml under {out_dir / 'runs'}/)", file=out)
        return 0
    outcome = run_sweep(s, out_dir, workers=workers, ray=ray, ray_address=ray_address,
                        ray_chunk=ray_chunk, ray_init=ray_init, keep_logs=keep_logs,
                        retry_errors=retry_errors, progress=progress, before_run=before_run)
    ok = sum(r["status"] == "ok" for r in outcome.rows)
    errors = [r for r in outcome.rows if r["status"] != "ok"]
    faults = sum(r["status"] == "fault" for r in errors)
    print(f"{outcome.ran} run(s) done now"
          + (f" on {outcome.runner}" if outcome.runner else "")
          + f", {outcome.skipped} already done (resumed), in {outcome.wall_s:.1f} s wall; "
          f"{ok} ok, {faults} faulted, {len(errors) - faults} error(s); results: "
          f"{outcome.results}", file=out)
    for r in errors[:10]:
        print(f"  {r['status']} {r['run']}: {r['error']}", file=out)
    if len(errors) > 10:
        print(f"  ... and {len(errors) - 10} more (see the error column)", file=out)
    columns = columns_for(s)
    if ok:
        shown = UNIT_SCALE.get(METRICS[metric][0], (1.0, METRICS[metric][0]))[1]
        print(f"best runs by {metric} ({shown}, "
              f"{'largest' if _better(metric) == 'max' else 'smallest'} first):", file=out)
        print(best_table(columns, outcome.rows, metric, top), file=out)
    if plot is not None:  # the views hang off the CLI, which passes them in
        why = nothing_to_draw(outcome.rows, metric)
        if why:
            print(f"cdpm sweep: error: no pictures: {why}", file=sys.stderr)
            errors = errors or [why]
        else:
            for png in plot(columns, outcome.rows, out_dir, metric=metric):
                print(f"plot: {png}", file=out)
    if outcome.ending == "interrupted":
        print(f"cdpm sweep: interrupted; {len(outcome.rows)} finished row(s) kept in "
              f"{outcome.results}; rerun the same command to resume", file=sys.stderr)
        return 130
    if outcome.ending == "terminated":
        print(f"cdpm sweep: terminated; {len(outcome.rows)} finished row(s) kept in "
              f"{outcome.results}; rerun the same command to resume", file=sys.stderr)
        return 143
    return 1 if errors else 0


def plot_main(*, sweep_dir, plot, out_dir=None, metric=None, out=None) -> int:
    """`cdpm plot SWEEP_DIR`: the sweep's pictures (`plot`, views.sweep_plots.plot_sweep) and
    its best runs, from results.csv."""
    out = sys.stdout if out is None else out
    sweep_dir = Path(sweep_dir)
    columns, rows = read_results(sweep_dir)
    if metric is None:
        metric = "min_distance"
        try:
            metric = load_sweep_file(sweep_dir / "sweep.yaml")[0].metric
        except (SweepError, ScenarioError):
            pass
    why = nothing_to_draw(rows, metric)
    if why:  # no empty axes: say why there is no picture
        raise SweepError(f"{str(sweep_dir)!r}: no pictures: {why}")
    for png in plot(columns, rows, out_dir or sweep_dir, metric=metric):
        print(f"plot: {png}", file=out)
    if any(r["status"] == "ok" for r in rows):
        print(f"best runs by {metric}:", file=out)
        print(best_table(columns, rows, metric), file=out)
    return 0


def nothing_to_draw(rows: list[dict], metric: str) -> str:
    """Why a sweep's pictures of `metric` would have nothing to draw ("" when they would
    not): they show the rows that finished ok with a value of the metric."""
    if not rows:
        return "results.csv has no rows yet"
    ok = [r for r in rows if r.get("status") == "ok"]
    if not ok:
        faults = sum(r.get("status") == "fault" for r in rows)
        return (f"none of the {len(rows)} runs finished ok ({faults} faulted, "
                f"{len(rows) - faults} error(s): see the status and error columns of "
                "results.csv)")
    if not any(math.isfinite(metric_value(r, metric)) for r in ok):
        return (f"none of the {len(ok)} ok runs has a value of {metric} (see docs/"
                "SWEEP_FORMAT.md; e.g. crossings needs the interference block)")
    return ""
