"""Values as text: a CSV cell of results.csv, a value in a message, compact one-line YAML."""

import math


def flow_yaml(value) -> str:
    """Compact one-line YAML of raw data (for messages and the `variant` column)."""
    if isinstance(value, dict):
        tag = value.get("_tag")
        inner = "{" + ", ".join(f"{k}: {flow_yaml(v)}" for k, v in value.items()
                                if k != "_tag") + "}"
        return f"{tag} {inner}" if tag else inner
    if isinstance(value, list):
        return "[" + ", ".join(flow_yaml(v) for v in value) + "]"
    return shown_value(value)


def shown_value(value) -> str:
    """A value in a message: as a CSV cell, but a NaN or infinite float spelled out (an
    empty cell would read as no value at all)."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return csv_cell(value)


def csv_cell(value) -> str:
    """One CSV cell: floats in full precision (repr), booleans as YAML writes them."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    if isinstance(value, (int, str)):
        return str(value)
    return flow_yaml(value)
