"""The sweep's metrics of one run, computed from its log (docs/LOG_FORMAT.md): SI units (m,
N, s), the dynamic plant's ground truth beside the controller's view."""

import math

import numpy as np

from cdpm_drake.config import Scenario, interference_params, scenario_robot


# name -> (unit, which way is better, what). docs/SWEEP_FORMAT.md says the same in prose.
METRICS = {
    "min_distance": ("m", "max", "smallest distance of any watched cable pair over the run"),
    "min_distance_pair": ("-", None, "the pair where min_distance occurred, e.g. 1-3"),
    "time_below_d_l": ("s", "min", "time during which any pair was below its d_l (by more "
                                      "than 1 um: round-off at the barrier is not below)"),
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

# A limit "acts" when the commanded velocity differs from the admittance's by more than this,
# m/s: the limits pass an unlimited velocity through exactly, so this only absorbs round-off.
LIMIT_TOLERANCE = 1e-9
# A pair is "below d_l" when it is closer than d_l by more than this, m: the safety filter
# holds a pair at d_l exactly, and its solve lands within round-off (nm) on either side of
# it; 1 um is a thousandth of a cable's diameter, far below anything physical.
D_L_TOLERANCE = 1e-6


def better_direction(metric: str) -> str:
    """"max" or "min": which way ranks first (metrics without a better side: largest)."""
    return METRICS[metric][1] or "max"


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
        out["time_below_d_l"] = held(np.any(d < d_l[None, :] - D_L_TOLERANCE, axis=1))
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
