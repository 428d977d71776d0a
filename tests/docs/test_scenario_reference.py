"""docs/scenario_reference.md is what scripts/tools/scenario_reference.py writes from the
dataclasses today, and it has a row for every field of every scenario and robot-file class."""

import dataclasses
import re
import typing
from pathlib import Path

from helpers_scripts import load_script

REPO = Path(__file__).resolve().parents[2]
REFERENCE = REPO / "docs" / "scenario_reference.md"


def _generator():
    return load_script("tools/scenario_reference.py")


def _tables(text: str) -> dict[str, set[str]]:
    """{class name: the field names in its table} of the reference."""
    tables, current = {}, None
    for line in text.splitlines():
        if line.startswith("### "):
            current = tables.setdefault(line[4:].strip(), set())
        m = re.match(r"^\| `(\w+)` \|", line)
        if m and current is not None:
            current.add(m.group(1))
    return tables


def test_the_committed_reference_is_current():
    text = _generator().render()
    assert REFERENCE.read_text() == text, (
        "docs/scenario_reference.md is stale: run python scripts/tools/scenario_reference.py")


def test_every_field_of_every_class_has_a_row():
    from cdpm_drake.config import Scenario
    from cdpm_drake.robot import RobotSchema

    gen = _generator()
    tables = _tables(REFERENCE.read_text())
    classes = gen.walk(Scenario) + gen.walk(RobotSchema)
    names = {c.__name__ for c in classes}
    # The walk reaches every nested config and every member of the plant and operator unions.
    for expected in ("Admittance", "Logistic", "PairLogistic", "Interference", "Limits",
                     "WallForce", "Sensor", "Controller", "SafetyFilter", "KinetostaticForce",
                     "ModelMonitor", "SimulatedReels", "DynamicReels", "HardwareReels",
                     "NoOperator", "ScriptedOperator", "CsvOperator", "SpringHandOperator",
                     "WorkspaceSchema", "LimitsSchema", "PlatformSchema", "CablesSchema",
                     "ReelDrivesSchema"):
        assert expected in names, expected
    for member in typing.get_args(typing.get_type_hints(Scenario)["plant"]):
        assert member.__name__ in names, member
    for cls in classes:
        assert cls.__name__ in tables, cls.__name__
        fields = {f.name for f in dataclasses.fields(cls)}
        assert tables[cls.__name__] == fields, (cls.__name__, fields ^ tables[cls.__name__])


def test_rows_carry_the_unit_and_default_of_the_source():
    # Read from the comments above the fields: `# Virtual mass M, kg.` / `mass: float = 6.25`.
    rows = {}
    for line in REFERENCE.read_text().splitlines():
        cells = [c.strip() for c in line.strip("|").split(" | ")]
        if len(cells) == 5 and cells[0].startswith("`"):
            rows.setdefault(cells[0].strip("`"), cells)
    assert rows["mass"][2:4] == ["kg", "`6.25`"]
    assert rows["damping"][2:4] == ["N s/m", "`6.25`"]
    assert rows["max_acceleration"][2] == "m/s^2"
    assert rows["length_gain"][2:4] == ["1/s", "`40.0`"]
    assert rows["filter_window"][2] == "samples"
    assert rows["initial_rpy"][2] == "rad"
