"""Loading a scenario: by name (the shipped ones in `cdpm_drake/data/scenarios/`) or path,
with a `--scenario-text` YAML overlay; its paths made absolute, then checked and resolved."""

from pathlib import Path

from cdpm_drake.config.load_warnings import (warn_reel_saturation, warn_sensor_range,
                                             warn_unreachable_d_u)
from cdpm_drake.config.resolve import ResolvedScenario, resolve_scenario
from cdpm_drake.config.scenario import Scenario, ScenarioError
from cdpm_drake.config.yaml_io import check_yaml_text, explain_load_error
from cdpm_drake.data import SCENARIOS_DIR
from cdpm_drake.kernels.plant.operators import CsvOperator
from cdpm_drake.robot import resolve_named_yaml


def scenario_names() -> list[str]:
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.yaml"))


def resolve_scenario_path(name_or_path) -> Path:
    return resolve_named_yaml(name_or_path, SCENARIOS_DIR, "scenario", ScenarioError)


def load_scenario(name_or_path="exp2_interaction", overlay_text: str | None = None) -> Scenario:
    """Load a scenario by name or path, apply a YAML overlay, and check it."""
    return load_resolved_scenario(name_or_path, overlay_text).scenario


def load_resolved_scenario(name_or_path="exp2_interaction",
                           overlay_text: str | None = None,
                           method: str | None = None) -> "ResolvedScenario":
    """`load_scenario`, returning the check's `resolve_scenario` result, so that a caller that
    goes on to build and run it resolves it only once. `method` (the command line's
    --method) replaces the scenario's Scenario.method after the overlay."""
    from pydrake.common.yaml import yaml_load, yaml_load_typed

    path = resolve_scenario_path(name_or_path)
    check_yaml_text(f"{path}", filename=str(path))
    try:
        scenario = yaml_load_typed(schema=Scenario, filename=str(path))
    except Exception as e:
        raise ScenarioError(f"{path}: {explain_load_error(e)}") from None
    # Every path resolves against the file it appears in, so a scenario means the same from
    # every directory; an overlay's, typed on the command line, against the current one.
    source = f"--scenario-text {overlay_text!r}"
    raw = {}
    if overlay_text:
        check_yaml_text(source, data=overlay_text)
        raw = yaml_load(data=overlay_text) or {}
    _resolve_paths(scenario, path.parent.resolve(), f"scenario {str(path)!r}",
                   "the scenario file's folder", robot="robot" not in raw,
                   operator="operator" not in raw)
    if overlay_text:
        try:
            scenario = yaml_load_typed(schema=Scenario, data=overlay_text, defaults=scenario)
        except Exception as e:
            raise ScenarioError(f"{source}: {explain_load_error(e)}") from None
        _resolve_paths(scenario, Path.cwd(), source, "the current directory for an overlay",
                       robot="robot" in raw, operator="operator" in raw)
    # Absolute, so the resolved scenario written beside a log (which records base_dir) finds
    # the same robot and CSV files when loaded back from elsewhere.
    scenario.base_dir = str((path.parent / scenario.base_dir).resolve())
    if method is not None:
        scenario.method = method
    try:
        resolved = resolve_scenario(scenario, source=str(path))
    except ScenarioError as e:
        # The same error (a refusal's own class kept), its message with where it is written.
        e.args = (_where_written(str(e), path, overlay_text, raw),) + e.args[1:]
        raise
    if resolved.interference is not None:
        warn_unreachable_d_u(resolved.robot, resolved.interference)
    warn_reel_saturation(scenario, resolved.robot)
    warn_sensor_range(resolved)
    return resolved


def _where_written(message: str, path: Path, overlay_text, raw: dict) -> str:
    """A value error of the resolution (`admittance.mass must be ... > 0, got -1.0`) prefixed,
    as a typo's is, with where that field is written: the overlay's line when the overlay
    sets it, else the file's line; the message unchanged when it names no field written."""
    import re

    from cdpm_drake.config.yaml_io import field_keys
    from cdpm_drake.text import yaml_line

    m = re.match(r"([A-Za-z_][\w.\[\]]*) must ", message)
    if not m:
        return message
    keys = field_keys(m.group(1))
    if overlay_text and keys and keys[0] in raw:
        line = yaml_line(keys, data=overlay_text)
        if line is not None:
            return f"--scenario-text {overlay_text!r}: line {line}: {message}"
    line = yaml_line(keys, filename=str(path))
    return f"{path}: line {line}: {message}" if line is not None else message


def _resolve_paths(scenario: Scenario, base: Path, source: str, base_what: str, *,
                   robot: bool, operator: bool) -> None:
    """Make the scenario's robot file and CSV operator path absolute, relative to `base`
    (the folder of the file they appear in), with no fallback; a robot name must be a
    built-in one. ScenarioError names the `source` and the full path tried."""
    from cdpm_drake.robot import ROBOTS_DIR, is_path_like, robot_names

    if robot:
        ref = scenario.robot
        if is_path_like(ref):
            full = Path(ref) if Path(ref).is_absolute() else base / ref
            if full.is_dir():
                inside = sorted(q.name for q in full.glob("*.yaml"))[:5]
                raise ScenarioError(
                    f"{source}: robot {ref!r} is a folder, not a robot file: give the .yaml "
                    f"file itself" + (f" (it holds {inside})" if inside else
                                      " (it holds no .yaml file)"))
            if not full.is_file():
                raise ScenarioError(
                    f"{source}: robot file {ref!r} does not exist: tried {str(full)!r}"
                    + ("" if Path(ref).is_absolute() else
                       f" (relative paths are relative to {base_what})"))
            scenario.robot = str(full)
        elif not (ROBOTS_DIR / f"{ref}.yaml").is_file():
            raise ScenarioError(f"{source}: unknown robot {ref!r}; built-in robots: "
                                f"{robot_names()} (or give a path to a .yaml file)")
    if operator and isinstance(scenario.operator, CsvOperator) and scenario.operator.path:
        ref = scenario.operator.path
        full = Path(ref) if Path(ref).is_absolute() else base / ref
        if not full.is_file():
            raise ScenarioError(
                f"{source}: operator.path {ref!r} does not exist: tried {str(full)!r}"
                + ("" if Path(ref).is_absolute() else
                   f" (relative paths are relative to {base_what})"))
        scenario.operator.path = str(full)
