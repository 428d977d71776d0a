"""The table of a sweep's best runs: rows ranked by a metric, columns in the units shown."""

import math

from cdpm_drake.runs.sweep.errors import SweepError
from cdpm_drake.runs.sweep.labels import UNIT_SCALE, field_axis
from cdpm_drake.runs.sweep.metrics import METRICS, NUMERIC_METRICS, better_direction
from cdpm_drake.runs.sweep.results import swept_fields


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
    better = better_direction(metric)
    ok = [r for r in rows if r.get("status") == "ok" and math.isfinite(metric_value(r, metric))]
    sign = -1.0 if better == "max" else 1.0
    return sorted(ok, key=lambda r: sign * metric_value(r, metric))[:max(0, int(top))]


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
