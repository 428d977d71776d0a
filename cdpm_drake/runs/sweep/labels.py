"""How swept fields and metrics are labelled and in what unit they are shown (m as mm), in
the tables and the pictures."""

import re


# Quantities in m are shown in mm (tables, pictures) (the paper's distances are in mm).
UNIT_SCALE = {"m": (1000.0, "mm")}

# A swept field's last name -> (what it is, unit in SI), by the section it is in (the
# comments of the Scenario's fields, cdpm_drake.config). "" for the section: a top-level field.
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
