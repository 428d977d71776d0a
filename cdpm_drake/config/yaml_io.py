"""Scenario YAML: the check of raw YAML against the schema (before yaml_load_typed, whose
messages name neither the nested field nor the valid choices), the errors it raises with
the line of the field, and the writer of a resolved scenario."""

import dataclasses
import typing

from cdpm_drake.config.plants import PLANT_TYPES
from cdpm_drake.config.scenario import Scenario, ScenarioError
from cdpm_drake.kernels.plant.operators import OPERATOR_TYPES


def check_yaml_text(source: str, **where) -> None:
    """Check raw YAML against the Scenario schema before yaml_load_typed, whose messages do not
    say which nested field is wrong (`The fields ['mas'] were unknown to the schema`,
    `could not convert string to float: 'a'`) nor list the valid fields. A file's message
    gives the line of the field."""
    from pydrake.common.yaml import yaml_load

    try:
        raw = yaml_load(**where)
    except Exception as e:
        raise ScenarioError(f"{source}: not valid YAML: {e}") from None
    if raw is None and "filename" in where:
        raise ScenarioError(f"{source}: the file is empty (or only comments); a scenario is a "
                            "mapping of fields, e.g. `robot: paper_7cable` "
                            "(docs/scenario_reference.md lists them)")
    if raw is None:  # `null`, `~` or only comments: Drake's loader says "YAML root was a
        # <class 'NoneType'>"
        raise ScenarioError(f"{source}: the overlay is empty (YAML {where['data'].strip()!r} "
                            "is no field); an overlay is a mapping of fields, e.g. "
                            "--scenario-text 'duration: 2'")
    if not isinstance(raw, dict):
        raise ScenarioError(f"{source}: a scenario is a mapping of fields (`field: value` "
                            f"lines), got a YAML {type(raw).__name__}: {raw!r:.80}")
    from cdpm_drake.text import duplicate_yaml_keys

    twice = duplicate_yaml_keys(filename=where.get("filename"), data=where.get("data"))
    if twice:
        raise ScenarioError(f"{source}: the key {twice[0]}: write each key once (YAML would "
                            "keep the last one and drop the first without a word)")
    from cdpm_drake.text import quoted_numbers

    quoted = frozenset(path for path, _, _ in quoted_numbers(filename=where.get("filename"),
                                                              data=where.get("data")))
    try:
        check_yaml(raw, Scenario, "", quoted)
    except ScenarioError as e:
        raise ScenarioError(f"{source}: {with_line(e, where.get('filename'))}") from None


# Fields the loader fills in, not for users to write: accepted, never listed as choices.
INTERNAL_FIELDS = ("base_dir",)


def _field_error(field: str, message: str) -> ScenarioError:
    """A ScenarioError about the YAML field at `field` (e.g. interference.pairs[0].du)."""
    error = ScenarioError(message)
    error.field = field
    return error


def field_keys(field: str) -> list:
    """`interference.pairs[0].du` -> ["interference", "pairs", 0, "du"] (text.yaml_line's
    key path)."""
    import re

    return [int(index) if index else name
            for name, index in re.findall(r"([^.\[\]]+)|\[(\d+)\]", field)]


def with_line(error: Exception, filename=None) -> str:
    """The message of a check_yaml error, prefixed with `line N: ` where the file `filename`
    writes the field it names."""
    from cdpm_drake.text import yaml_line

    field = getattr(error, "field", None)
    line = (yaml_line(field_keys(field), filename=filename)
            if filename is not None and field else None)
    return f"line {line}: {error}" if line is not None else str(error)


def is_number(v) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, (int, float)):
        return True
    try:  # YAML 1.1 reads `1e3` as a string; Drake's loader takes it as a number
        float(v)
        return isinstance(v, str)
    except (TypeError, ValueError):
        return False


def check_yaml(value, schema, field: str, quoted=frozenset()) -> None:
    """Raise ScenarioError naming the field, the value and the valid choices where raw YAML
    data `value` does not fit the type `schema`. `quoted`: the fields written as quoted
    strings (text.quoted_numbers), which a number field refuses."""
    from cdpm_drake.text import did_you_mean

    name = field or "the scenario"
    if dataclasses.is_dataclass(schema):
        if not isinstance(value, dict):
            raise _field_error(field, f"{name} must be a mapping, got {value!r}")
        fields = [f.name for f in dataclasses.fields(schema)]
        valid = [f for f in fields if f not in INTERNAL_FIELDS]
        for key, item in value.items():
            if key == "_tag":
                continue
            if key not in fields:
                where = f"{field}.{key}" if field else str(key)
                raise _field_error(where, f"unknown field {where!r}{did_you_mean(key, valid)} "
                                          f"(valid fields{' of ' + field if field else ''}: "
                                          f"{valid})")
        types = typing.get_type_hints(schema)
        for key, item in value.items():
            if key != "_tag":
                check_yaml(item, types[key], f"{field}.{key}" if field else key, quoted)
        return
    origin, args = typing.get_origin(schema), typing.get_args(schema)
    if origin is typing.Union:
        if type(None) in args:
            if value is None:
                return
            rest = [a for a in args if a is not type(None)]
            return check_yaml(value, rest[0] if len(rest) == 1 else typing.Union[tuple(rest)],
                              field, quoted)
        tags = ["!" + a.__name__ for a in args]
        tag = value.get("_tag") if isinstance(value, dict) else None
        if tag is None:
            try:  # an untagged entry is the first member, as yaml_load_typed reads it
                return check_yaml(value, args[0], field, quoted)
            except ScenarioError as e:
                raise _field_error(getattr(e, "field", field),
                                   _untagged_hint(e, value, args, tags, field)) from None
        if tag not in tags:
            raise _field_error(field, f"{field}: unknown type {tag!r}{did_you_mean(tag, tags)} "
                                      f"(valid {field} types: {tags})")
        return check_yaml(value, args[tags.index(tag)], field, quoted)
    if origin is list:
        if not isinstance(value, list):
            raise _field_error(field, f"{name} must be a list, got {value!r}")
        for k, item in enumerate(value):
            check_yaml(item, args[0], f"{field}[{k}]", quoted)
        return
    if schema is float and isinstance(value, str) and field in quoted:
        raise _field_error(field, f"{name} must be a number, got the string {value!r} "
                                  f"(quoted); write it without quotes: {value}")
    if schema is float and not is_number(value):
        raise _field_error(field, f"{name} must be a number, got {value!r}")
    if schema is int and not (isinstance(value, int) and not isinstance(value, bool)):
        raise _field_error(field, f"{name} must be an integer, got {value!r}")
    if schema is bool and not isinstance(value, bool):
        raise _field_error(field, f"{name} must be true or false, got {value!r}")
    if schema is str and not isinstance(value, str):
        raise _field_error(field, f"{name} must be a string, got {value!r}")


def _untagged_hint(e: ScenarioError, value, args, tags, field: str) -> str:
    """The message for an untagged mapping that does not fit the union's first member: name
    the tag it needs, with the members that have its fields (a scenario whose operator is a
    !SpringHandOperator still needs the tag in an overlay: untagged means the first member)."""
    text = f"{e} (an untagged {field} is {tags[0]}; valid {field} types: {tags})"
    if not isinstance(value, dict) or not value:
        return text
    keys = [k for k in value if k != "_tag"]
    fits = [tag for tag, member in zip(tags, args) if dataclasses.is_dataclass(member)
            and set(keys) <= {f.name for f in dataclasses.fields(member)}]
    if not fits:
        return text
    flow = ", ".join(f"{k}: {_flow_yaml(value[k])}" for k in keys)
    article = "an" if field[:1] in "aeiou" else "a"
    return (f"{e}; a mapping without a tag is read as {tags[0]}, so {article} {field} needs "
            f"its tag, e.g. `{field}: {fits[0]} {{{flow}}}` (types with these fields: "
            f"{fits}; valid {field} types: {tags})")


def _flow_yaml(v) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(_flow_yaml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k}: {_flow_yaml(x)}" for k, x in v.items()) + "}"
    return str(v)


def explain_load_error(e: Exception) -> str:
    msg = str(e)
    if "did not match any of the allowed type options" in msg:
        if "'operator'" in msg:
            msg += f"; valid operators: {['!' + t.__name__ for t in OPERATOR_TYPES]}"
        if "'plant'" in msg:
            msg += f"; valid plants: {['!' + t.__name__ for t in PLANT_TYPES]}"
    return msg


def scenario_to_yaml(scenario: Scenario) -> str:
    """The resolved scenario as YAML (written beside every log), without the loader's
    internal base_dir (a loaded file's paths are resolved already)."""
    from pydrake.common.yaml import yaml_dump_typed

    text = yaml_dump_typed(dataclasses.replace(scenario, base_dir=""))
    return text.replace("\nbase_dir: ''\n", "\n")
