"""A sweep's variants: the grid, random samples, explicit overlays and seeds expanded, each
resolved to a full scenario before the first run."""

import dataclasses
import hashlib
import itertools
import json
import logging
import math
import typing
from pathlib import Path

import numpy as np

from cdpm_drake.config import (Scenario, ScenarioError, interference_params,
                               load_resolved_scenario, resolve_scenario, resolve_scenario_path,
                               scenario_to_yaml)
from cdpm_drake.runs.sweep.cells import flow_yaml, shown_value
from cdpm_drake.runs.sweep.errors import SweepError
from cdpm_drake.runs.sweep.fields import (apply_overlay, apply_overlay_resolved, field_type,
                                          parse_field_path, put_field)
from cdpm_drake.runs.sweep.file import (MAX_VARIANTS, RandomSamples, SweepFile, axis_values,
                                        load_sweep_file)




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
        parts = [f"{k}={shown_value(v)}" for k, v in self.values.items()]
        if self.overlay is not None:
            parts.append(f"variant={flow_yaml(self.overlay)}")
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
        raise SweepError(f"{path}: overlay {flow_yaml(sweep_file.overlay)}: {e}") from None

    grid = []
    for axis in sweep_file.axes:
        values = axis_values(axis)
        if not axis.values and field_type(base, parse_field_path(axis.field)) is int:
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
    shown = ", ".join([f"{k}={shown_value(v)}" for k, v in values.items()]
                      + ([f"variant={flow_yaml(overlay)}"] if overlay is not None else [])
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
            put_field(assign, scenario, parse_field_path(field), value, field)
        if seed is not None:
            assign["random_seed"] = seed
        scenario, resolved = apply_overlay_resolved(scenario, assign)
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
        from cdpm_drake.hardware.canopen_config import CanopenReels
        from cdpm_drake.hardware.config import HardwareReels
    except ImportError:
        return False
    return isinstance(plant, (HardwareReels, CanopenReels))


def _random_samples(r: RandomSamples, base: Scenario) -> list[dict]:
    rng = np.random.default_rng(r.seed)
    kinds = {f: field_type(base, parse_field_path(f)) for f in r.ranges}
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
