"""The sweep file (docs/SWEEP_FORMAT.md): its schema, where shipped sweeps live, loading and
checking it. The scenario YAML it holds (overlay, variants) is checked per variant later."""

import copy
import dataclasses
import math
import typing
from pathlib import Path

import numpy as np

from cdpm_drake.config import ScenarioError
from cdpm_drake.data import SWEEPS_DIR
from cdpm_drake.robot import resolve_named_yaml
from cdpm_drake.runs.sweep.errors import SweepError
from cdpm_drake.runs.sweep.fields import parse_field_path
from cdpm_drake.runs.sweep.metrics import NUMERIC_METRICS


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


# Most variants a sweep may expand to: a typo in a grid (a count of 1000 on four axes) should
# be an error, not a year of runs.
MAX_VARIANTS = 100_000


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
    from cdpm_drake.config.resolve import check_name

    try:  # its results go to runs/sweeps/<name>/: a name must not leave that folder
        check_name(sweep.name, "runs/sweeps/<name>/")
    except ScenarioError as e:
        raise SweepError(f"{path}: {e}") from None
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
    if (len(spec) != 3 or not float(spec[2]).is_integer()
            or not 1 <= spec[2] <= MAX_VARIANTS):  # checked before any value is made
        raise SweepError(f"{where}.{key} must be [start, stop, count] with an integer "
                         f"count in 1..{MAX_VARIANTS:,}, got {spec!r}")
    if not all(math.isfinite(x) for x in spec[:2]):
        raise SweepError(f"{where}.{key} start and stop must be finite, got {spec!r}")
    if key == "geomspace" and not (spec[0] > 0 and spec[1] > 0):
        raise SweepError(f"{where}.geomspace start and stop must be > 0, got {spec!r}")
    if int(spec[2]) > 1 and spec[0] == spec[1]:
        raise SweepError(f"{where}.{key} repeats one value {int(spec[2])} times: {spec!r}")


def _check_random(r: RandomSamples, where: str) -> None:
    if not 1 <= r.count <= MAX_VARIANTS:  # checked before any sample is drawn
        raise SweepError(f"{where}.count must be an integer in 1..{MAX_VARIANTS:,}, got "
                         f"{r.count!r}")
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
