"""The run summaries `cdpm simulate` and `cdpm run` print after a run, read from its log: the
cable pairs (the table of `runs.simulate.summary_rows`, the peak forces, the crossings), the
hand force the sensor clipped, the tension control, the safety filter, the model monitor and
the dynamic plant's ground truth. Distances in mm, forces in N, times in s."""

import numpy as np

from cdpm_drake.text import format_number, format_table, format_vector


def _named_cables(cable, ticks) -> str:
    """'7 (120 ticks), 6 (3 ticks)': the 1-based cables `cable` names on the `ticks` (bool
    mask), most often named first."""
    named = cable[ticks]
    numbers, counts = np.unique(named[named > 0], return_counts=True)
    order = np.argsort(-counts, kind="stable")
    return ", ".join(f"{numbers[k]} ({counts[k]} tick{'s' if counts[k] != 1 else ''})"
                     for k in order) or "none named"


def tension_control_summary(log) -> str:
    """One line on the tension control of a log (controller.tension_control): per status
    (pose_control.tension_tick) how many ticks and which cables: the floor held; lowered to
    what the pose and the ceiling allow (the weakest cable); the ceiling exceeded to keep
    the hard floor (the cable above it); the hard floor unreachable (t* < tension_floor:
    the cables raised to it); W rank-deficient; and on how many no distribution held at all
    (t* < 0: outside the wrench-feasible workspace)."""
    from cdpm_drake.kernels.full_pose import CEILING_EXCEEDED, FLOOR_UNREACHABLE, HAND_TOO_FAST
    from cdpm_drake.kernels.tension import BELOW_FLOOR, FEASIBLE, GENERAL

    status = np.asarray(log["tension_status"]).reshape(-1)
    t_star = np.asarray(log["t_star"], dtype=float).reshape(-1)
    # Logs written before the cable was logged name none.
    cable = np.asarray(log["tension_cable"] if "tension_cable" in log
                       else np.zeros(status.size)).reshape(-1).astype(int)
    T = status.size
    parts = [f"the floor held on {int(np.sum(status == FEASIBLE))} of {T} ticks"]
    for code, what, role in (
            (BELOW_FLOOR, "lowered to what the pose and the ceiling allow", "weakest cable"),
            (CEILING_EXCEEDED, "above controller.max_tension to keep every cable at "
             "controller.tension_floor", "cable above the ceiling"),
            (FLOOR_UNREACHABLE, "the pose cannot hold every cable at controller.tension_floor"
             " (t* below it), weak cables raised to it", "cable raised most"),
            (GENERAL, "the wrench matrix rank-deficient (minimum-norm target)",
             "cable raised most")):
        ticks = status == code
        if ticks.any():
            smallest = t_star[ticks].min()
            t_text = f"smallest t* {smallest:.2f} N; " if np.isfinite(smallest) else ""
            parts.append(f"{what} on {int(ticks.sum())} ({t_text}{role}: "
                         f"{_named_cables(cable, ticks)})")
    text = "tension control: " + "; ".join(parts)
    fast = np.flatnonzero(status == HAND_TOO_FAST)
    if fast.size:
        first = int(fast[0])
        when = (f" first at {float(np.asarray(log['time']).reshape(-1)[first]):.3f} s"
                if "time" in log else "")
        text += (f"; WARNING: hand faster than the tension path can follow on {fast.size} "
                 f"ticks ({_named_cables(cable, status == HAND_TOO_FAST)};{when}, cable "
                 f"{int(cable[first])}: the internal force that keeps it at "
                 "controller.tension_floor rises slower than the hand takes it down)")
    text += unseen_ringing_warning(log)
    none = int(np.sum(t_star < 0))
    if none:
        text += (f"; NO tension distribution held on {none} ticks (t* < 0: outside the "
                 "wrench-feasible workspace, a cable must go slack)")
    estimate = np.asarray(log["tension_estimate"], dtype=float)
    return text + (f"; estimated tensions {estimate.min():.2f} to {estimate.max():.1f} N")


def unseen_ringing_warning(log) -> str:
    """'; WARNING: ...' where the unseen-ringing block (no tension sensor) warned of a cable
    whose predicted ringing may take it below controller.tension_floor while its estimate
    says it is taut: each such cable (1-based) with its first time, its ticks and its
    predicted swing then; '' where it warned of none (or the log has no such block)."""
    if "ringing_warned" not in log:
        return ""
    warned = np.asarray(log["ringing_warned"], dtype=float) > 0.5
    if not warned.any():
        return ""
    time = np.asarray(log["time"], dtype=float).reshape(-1)
    swing = np.asarray(log["ringing_swing"], dtype=float)
    firsts = sorted((int(np.argmax(warned[:, i])), i) for i in range(warned.shape[1])
                    if warned[:, i].any())
    cables = ", ".join(f"cable {i + 1} from {time[k]:.3f} s ({int(warned[:, i].sum())} ticks, "
                       f"swing {swing[k, i]:.1f} N)" for k, i in firsts)
    return ("; WARNING: ringing the encoders cannot see may take a cable below "
            f"controller.tension_floor, or slack (no tension sensor): {cables}")


def overload_summary(log, ceiling: float, overload: float = 0.0) -> str:
    """A WARNING line when a cable's measured tension (log `tension_measured`, N; NaN where
    there is no reading) went above the controller's ceiling `ceiling` (N,
    controller.max_tension): on how many ticks, and per cable (1-based) its peak, when, and
    its ticks above; "" when none did, or nothing was measured. `overload` (N, 0: off): the
    model monitor's fault tension, said beside it. The dynamic plant's true tensions
    (`tensions`) where nothing was measured."""
    key = "tension_measured"
    if key not in log or not np.isfinite(np.asarray(log[key], dtype=float)).any():
        key = "tensions"
    if key not in log:
        return ""
    T = np.asarray(log[key], dtype=float)
    T = T.reshape(T.shape[0], -1)
    if not T.size:
        return ""
    with np.errstate(invalid="ignore"):
        above = np.where(np.isfinite(T), T, -np.inf) > ceiling
    if not above.any():
        return ""
    time = np.asarray(log["time"], dtype=float).reshape(-1)
    cables = []
    for i in np.flatnonzero(above.any(axis=0)):
        k = int(np.nanargmax(T[:, i]))
        n = int(above[:, i].sum())
        cables.append(f"cable {i + 1} up to {T[k, i]:.1f} N at t = {time[k]:.3f} s "
                      f"({n} tick{'s' if n != 1 else ''})")
    what = "measured" if key == "tension_measured" else "true (the dynamic plant's)"
    stop = (f"; the model monitor stops a run at {overload:g} N (model_monitor.overload)"
            if overload > 0 else "")
    return (f"WARNING: a cable's {what} tension went ABOVE the ceiling "
            f"controller.max_tension = {ceiling:g} N on {int(above.any(axis=1).sum())} of "
            f"{T.shape[0]} ticks: {', '.join(cables)}{stop}")


def print_overload(log, scenario, out) -> None:
    """overload_summary of a run of `scenario` (its ceiling, and its monitor's overload
    tension where the monitor runs), if a cable went above the ceiling."""
    mon = scenario.model_monitor
    ceiling = float(scenario.controller.max_tension)
    line = overload_summary(log, ceiling, float(mon.overload) * ceiling if mon.enabled else 0.0)
    if line:
        print(line, file=out)


def _spans(mask, time) -> list[tuple[float, float]]:
    """The (start, end) times (s) of each run of True ticks in `mask`."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(int)))
    return [(float(time[a]), float(time[b - 1])) for a, b in zip(edges[::2], edges[1::2])]


def lost_margin_text(mask, time, depth, what, unit, scale=1.0) -> str:
    """`what lost (below 0) on N ticks (x s in k spans, first from a to b s), down to -d unit`,
    or "" when no tick of `mask` is True."""
    n = int(np.sum(mask))
    if not n:
        return ""
    spans = _spans(mask, time)
    dt = float(np.median(np.diff(time))) if len(time) > 1 else 0.0
    first = f"from {spans[0][0]:.3f} to {spans[0][1]:.3f} s"
    where = (first if len(spans) == 1
             else f"{n * dt:.3f} s in {len(spans)} spans, the first {first}")
    return (f"{what} LOST on {n} tick{'s' if n != 1 else ''} ({where}), down to "
            f"{format_number(scale * float(np.min(depth[mask])))} {unit}")


def safety_filter_summary(log) -> str:
    """The safety filter of a log (safety_filter.enabled): on how many ticks it passed the
    command, changed it (and which constraints bound, safety_filter.BIND_TEXT, the speed
    limit told apart from the lost-margin cap below it), held a lost margin, braked to a hold;
    when and how long a margin was lost (the pair margin or kinetostatic kappa below 0); the
    smallest pair margin above d_min, by the controller's estimate and, with a true pose
    logged, the truth's; the smallest kinetostatic margin kappa (N)."""
    from cdpm_drake.kernels.safety_filter import (BIND_SPEED, BIND_TEXT, LOST_SPEED,
                                                  STATUS_HOLD, STATUS_MODIFIED,
                                                  STATUS_NO_RETURN, STATUS_PASS)

    status = np.asarray(log["filter_status"]).reshape(-1).astype(int)
    binding = np.asarray(log["filter_binding"]).reshape(-1).astype(int)
    time = np.asarray(log["time"], dtype=float).reshape(-1)
    T = status.size
    # The speed ball binds at max_velocity, or below it at the cap that slows the platform
    # while a margin is lost: two different causes, two labels.
    speed = np.linalg.norm(np.asarray(log["velocity"], dtype=float).reshape(T, -1), axis=1)
    v_max = float(log["max_velocity"]) if "max_velocity" in log else float(speed.max(initial=0))
    at_speed = (binding & BIND_SPEED) != 0
    capped = at_speed & (speed < v_max * (1.0 - 1e-6))
    # (label, ticks) of each way the command was bound; the speed ball told apart by where.
    masks = [(what, (binding & bit) != 0) for bit, what in BIND_TEXT if bit != BIND_SPEED]
    speed_at = [i for i, (bit, _) in enumerate(BIND_TEXT) if bit == BIND_SPEED][0]
    masks[speed_at:speed_at] = [
        (BIND_TEXT[speed_at][1], at_speed & ~capped),
        (f"lost-margin speed cap (towards {LOST_SPEED:g} m/s)", capped)]
    bound = [(what, int(np.sum(mask))) for what, mask in masks if np.any(mask)]
    changed = int(np.sum(status == STATUS_MODIFIED))
    several = ("; a tick can bind several ways, so these add up to more than the ticks "
               "changed" if sum(n for _, n in bound)
               > changed + int(np.sum(status >= STATUS_NO_RETURN)) else "")
    listed = ", ".join(f"{what} {n}" for what, n in bound)
    text = (f"safety filter: passed {int(np.sum(status == STATUS_PASS))} of {T} ticks, "
            f"changed {changed}"
            + (f" (bound: {listed}{several})" if bound else ""))
    for code, what in ((STATUS_NO_RETURN, "held a lost margin (not restored)"),
                       (STATUS_HOLD, "braked to a hold")):
        n = int(np.sum(status == code))
        if n:
            text += f", {what} on {n}"
    margin = np.asarray(log["pair_margin"], dtype=float).reshape(-1)
    kappa = np.asarray(log["kappa"], dtype=float).reshape(-1)
    # Round-off at a barrier is not a loss (runs.sweep.metrics.D_L_TOLERANCE: 1 um).
    for mask, depth, what, unit, scale in (
            (margin < -1e-6, margin, "pair margin", "mm", 1000.0),
            (kappa < -1e-6, kappa, "kinetostatic margin", "N", 1.0)):
        lost = lost_margin_text(mask, time, depth, what, unit, scale)
        if lost:
            text += "; " + lost
    if np.isfinite(margin).any():
        text += f"; smallest pair margin above d_min {format_number(1000 * margin.min())} mm"
        if "pair_distances_true" in log and "d_min" in log:
            true = (np.asarray(log["pair_distances_true"], dtype=float)
                    - np.asarray(log["d_min"], dtype=float)).min(axis=1)
            text += f" (true {format_number(1000 * true.min())} mm)"
        text += _closest_to_d_min(log)
    if np.isfinite(kappa).any():
        text += f"; smallest kinetostatic margin {kappa[np.isfinite(kappa)].min():.2f} N"
    if "d_min_uncertainty" in log:
        extra = 1000 * np.asarray(log["d_min_uncertainty"], dtype=float)
        text += (f"; the robot file's stated geometry uncertainty raised d_min by "
                 f"{format_number(extra.min())}-{format_number(extra.max())} mm"
                 + (f" and the kinetostatic floor by "
                    f"{float(log['kinetostatic_floor_uncertainty']):.2f} N"
                    if "kinetostatic_floor_uncertainty" in log else "") + " (2 sigma)")
    return text


def _closest_to_d_min(log) -> str:
    """The pair behind the smallest pair margin, in the pair table's terms: a margin is a
    distance less the pair's d_min (the safety filter's hard floor, not d_l or d_u), at the
    filter's smoothed position; the table's distances are the distances themselves at the
    estimated pose. "" without the pairs' distances and d_min in the log."""
    if not all(k in log for k in ("pair_distances", "d_min", "pairs")):
        return ""
    d = np.asarray(log["pair_distances"], dtype=float)
    d_min = np.asarray(log["d_min"], dtype=float).reshape(-1)
    if d.ndim != 2 or not d.size or d.shape[1] != d_min.size:
        return ""
    over = d - d_min
    if not np.isfinite(over).any():
        return ""
    k, q = np.unravel_index(np.nanargmin(over), over.shape)
    i, j = (int(c) for c in np.asarray(log["pairs"])[q])
    return (f" (a distance less its pair's d_min, at the filter's smoothed position; the "
            f"pair table's distances are the distances themselves: the closest to its d_min "
            f"was ({i},{j}), {format_number(1000 * d[k, q])} mm at t = "
            f"{float(log['time'][k]):.3f} s against d_min {format_number(1000 * d_min[q])} "
            f"mm)")


def model_monitor_summary(log, monitor=None) -> str:
    """One line on the model monitor of a log (model_monitor.enabled): whether the model
    fitted on every tick (and then by what it watches), else which verdict first
    (model_monitor.REASONS); the largest length residual (mm) and its cable. With the
    plant's truth logged (`slack`, the dynamic plant), the slack the monitor did not see: on
    how many ticks, and why (`monitor_blindness`). `monitor`: the scenario's
    config.ModelMonitor, for its thresholds (its defaults otherwise)."""
    from cdpm_drake.config import ModelMonitor
    from cdpm_drake.kernels.model_monitor import REASONS

    monitor = ModelMonitor() if monitor is None else monitor
    status = np.asarray(log["model_status"]).reshape(-1).astype(int)
    residual = np.asarray(log["model_residual"], dtype=float)
    bad = np.flatnonzero(status)
    if bad.size:
        k = int(bad[0])
        text = (f"model monitor: {REASONS[status[k]]} at t = {log['time'][k]:.3f} s "
                f"({bad.size} of {status.size} ticks)")
    else:
        text = f"model monitor: the model fitted on all {status.size} ticks"
    if residual.size and np.isfinite(residual).any():
        flat = np.nanargmax(np.abs(np.where(np.isfinite(residual), residual, 0.0)))
        cable = int(flat % residual.shape[1]) + 1
        worst = format_number(1000 * residual.reshape(-1)[flat], sign=True)
        text += f"; largest length residual {worst} mm (cable {cable})"
    if not bad.size:  # "fitted" says only as much as what it watches
        slack_by = (f"a tension estimate below -{monitor.slack_tension:g} N" if
                    "tension_estimate" in log else f"a cable over "
                    f"{1000 * monitor.slack_length:g} mm longer than the estimated pose's "
                    "geometry")
        text += (f"; what it watches: slack as {slack_by}, lengths within "
                 f"{1000 * monitor.fit_tolerance:g} mm of the pose, t* of the measured hand "
                 f">= {0.0 - float(monitor.unholdable):g} N (from the encoder lengths, the "
                 "estimated pose and the hand force)")
    blind = monitor_blindness(log, monitor)
    return text + (f"; {blind}" if blind else "")


def _longest_run(mask) -> int:
    """The most consecutive True entries of a bool vector."""
    best = run = 0
    for x in np.asarray(mask, dtype=bool):
        run = run + 1 if x else 0
        best = max(best, run)
    return best


def monitor_blindness(log, monitor) -> str:
    """The dynamic plant's truly slack ticks (log `slack`) the model monitor passed as fitted
    (model_status ok), in words with the reason: what the monitor reads for a slack cable (its
    length residual, or its tension estimate) at its most telling on those ticks against the
    threshold, the platform's true turn where the pose estimate is a translation, and the
    longest slack spell against the ticks a fault needs. "" when there are none."""
    from cdpm_drake.kernels.model_monitor import OK, SLACK
    from cdpm_drake.kernels.rotation import rotation_angle, rotations_from_rpy

    if "slack" not in log:
        return ""
    slack = np.asarray(log["slack"], dtype=bool)
    status = np.asarray(log["model_status"]).reshape(-1).astype(int)
    unseen = slack & (status == OK)[:, None]
    ticks = np.any(unseen, axis=1)
    if not ticks.any():
        return ""
    T = status.size
    cables = ", ".join(f"{i + 1} ({int(n)})" for i, n in enumerate(unseen.sum(axis=0)) if n)
    first = float(log["time"][int(np.argmax(np.any(slack, axis=1)))])
    text = (f"NOT SEEN by it: the plant's truth has a cable slack on {int(ticks.sum())} of {T} "
            f"ticks the monitor passed (cable (ticks): {cables}; first truly slack at t = "
            f"{first:.3f} s")
    seen = np.flatnonzero(status == SLACK)
    late = 1000 * (float(log["time"][seen[0]]) - first) if seen.size else None
    text += f", the monitor's first slack verdict {late:.0f} ms later)" if seen.size else ")"
    why = []
    if "tension_estimate" in log:
        est = np.asarray(log["tension_estimate"], dtype=float)[unseen]
        why.append(f"the slack cables' tension estimates stayed >= {est.min():.2f} N on those "
                   f"ticks (slack needs < -{monitor.slack_tension:g} N; the estimate comes from "
                   "the encoder lengths and the pose fit)")
    else:
        r = np.asarray(log["model_residual"], dtype=float)[unseen]
        why.append(f"the slack cables were at most {max(0.0, -1000 * r.min()):.2f} mm longer "
                   f"than the estimated pose's geometry on those ticks (slack needs > "
                   f"{1000 * monitor.slack_length:g} mm)")
    if "rpy_true" in log and "rpy" not in log:
        turn = float(np.degrees(rotation_angle(rotations_from_rpy(
            np.asarray(log["rpy_true"], dtype=float))).max()))
        if turn >= 1.0:
            why.append(f"the platform truly turned up to {turn:.1f} deg, which the translating "
                       "pose estimate cannot represent: a turned platform's lengths fit a "
                       "shifted, level one")
    longest = _longest_run(ticks)
    if longest < monitor.ticks:
        why.append(f"each slack spell lasted at most {longest} ticks (a verdict needs "
                   f"model_monitor.ticks = {monitor.ticks})")
    return text + ": " + "; ".join(why)


def print_dynamic_summary(log, out) -> None:
    from cdpm_drake.kernels.rotation import rotation_angle, rotations_from_rpy

    T = len(log["time"])
    slack = [f"{i + 1} ({int(n)} ticks)" for i, n in enumerate(log["slack"].sum(axis=0)) if n]
    slack_ticks = int(np.any(log["slack"], axis=1).sum())
    error = 1000 * np.linalg.norm(log["p"] - log["p_true"], axis=1).max()
    rotation = np.degrees(rotation_angle(rotations_from_rpy(log["rpy_true"])).max())
    print(f"dynamic plant (true): tensions {log['tensions'].min():.2f} to "
          f"{log['tensions'].max():.1f} N; a cable slack on {slack_ticks} of {T} ticks "
          f"({100 * slack_ticks / T:.2f} %), cables: {', '.join(slack) or 'none'}; largest "
          f"rotation {rotation:.2f} deg; largest FK error {error:.2f} mm", file=out)
    if "lengths_commanded" in log:
        drift = 1000 * np.abs(log["lengths_commanded"] - log["lengths"]).max()
        print(f"length loop: largest |l_d - l| {drift:.2f} mm (commanded vs encoder lengths)",
              file=out)


def print_pair_summary(log, out) -> None:
    """The cable pairs of a log (`cdpm simulate`'s and `cdpm run`'s): each pair's closest
    approach beside its d_l and d_u, the ticks it was within d_u and whether it crossed; the
    peak forces; how many pairs crossed."""
    from cdpm_drake.runs.log import summary_header, summary_rows

    T = len(log["time"])
    rows = summary_rows(log)
    if rows:
        print(format_table(summary_header(log), rows), file=out)
    else:
        print("no cable pair came within its d_u", file=out)
    norms = {k: np.linalg.norm(log[k], axis=1).max() if T else 0.0
             for k in ("F_H", "F_int", "F_d")}
    print("peak |F_H| {F_H:.2f} N, |F_int| {F_int:.2f} N, |F_d| {F_d:.2f} N".format(**norms),
          file=out)
    crossings = int(np.any(log["crossed"], axis=0).sum()) if T else 0
    if "crossed_true" in log:  # the controller's estimate beside the plant's truth
        truly = int(np.any(log["crossed_true"], axis=0).sum()) if T else 0
        print(f"pairs that crossed: {truly} truly (from the true pose), {crossings} by the "
              "controller's estimate", file=out)
    else:
        print(f"pairs that crossed: {crossings}", file=out)


def print_clipped(log, scenario, out) -> None:
    """The ticks whose raw hand force (F_measured) the sensor model clipped, if any."""
    from cdpm_drake.config import sensor_range_text
    from cdpm_drake.kernels.force_sensor import beyond_range

    if "F_measured" not in log or not len(log["time"]):
        return
    s = scenario.sensor
    clipped = beyond_range(log["F_measured"], s.axial_axis, s.axial_range, s.transverse_range)
    if clipped.any():
        k = int(np.argmax(clipped))
        print(f"hand force beyond the sensor's range ({sensor_range_text(s)}), clipped: "
              f"{int(clipped.sum())} of {len(clipped)} ticks, the first at t = "
              f"{log['time'][k]:.3f} s ({format_vector(log['F_measured'][k], 1)} N)", file=out)
