"""cdpm: simulate, inspect and run the interference-aware admittance controller of a CDPM.

Run `cdpm <command> --help` for each command's options.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

from cdpm_drake.text import format_table, prefixed_log_records


class CliError(Exception):
    """A bad command-line argument (usage, exit 2); printed without a traceback."""


class InputError(Exception):
    """A file or folder named on the command line that cannot be found or read (exit 1, as
    for a scenario or robot that cannot be found); printed without a traceback."""


def _fmt(v, digits=3) -> str:
    return "[" + ", ".join(f"{x:.{digits}f}" for x in np.asarray(v, dtype=float)) + "]"


# --- info ------------------------------------------------------------------------------------


def info(*, robot: str = "paper_7cable", swaps=None, plot_dir=None, grid_step: float = 0.05,
         out=None) -> list[Path]:
    """Print a robot description: cables, Jacobian conditioning, workspace, the cable pairs'
    distances, and its statics (wrench-matrix rank, the share of the box that holds the
    platform, the hand forces it holds). `robot` is a robot or a scenario (a built-in name or
    a YAML path); a scenario shows its robot as the experiment uses it: with its swaps, its
    start and its path (simulated on the kinematic plant). `swaps` [(i, j), ...] (1-based)
    replace a scenario's swaps or swap a robot's cables. `plot_dir`: also write the workspace
    pictures there. Returns the pictures written."""
    out = sys.stdout if out is None else out
    from cdpm_drake.kernels.kinematics import cable_lengths, condition_number

    with _robot_warnings_in_report():
        r, scenario = _info_target(robot)
        base = r  # before any swap: the statics warnings compare with it
        if scenario is not None:
            import copy

            from cdpm_drake.config import scenario_robot

            unswapped = copy.copy(scenario)
            unswapped.swaps = []
            base = scenario_robot(unswapped)
        if swaps is not None:
            if scenario is not None:
                scenario.swaps = [list(s) for s in swaps]
            else:
                for i, j in swaps:
                    r = r.with_swapped_attachments(i, j)
        if scenario is not None:
            from cdpm_drake.config import resolve_scenario

            resolved = resolve_scenario(scenario)
            r = resolved.robot
    if np.array_equal(r.attachments, base.attachments):
        base = None
    _check_info_grid(r, grid_step)  # before the report
    c = r.workspace.center
    lengths = cable_lengths(r, c)
    what = (f"scenario {scenario.name!r}: " if scenario is not None else "") + f"robot {r.name!r}"
    print(f"{what} ({r.source}): {r.num_cables} cables, {r.num_pairs} watched pairs", file=out)
    if scenario is not None or swaps:
        shown = scenario.swaps if scenario is not None else swaps
        print(f"swapped cables: {', '.join(f'{i}-{j}' for i, j in shown) or 'none'}", file=out)
    rows = [(i + 1, _fmt(r.reels[i]), _fmt(r.attachments[i]), f"{lengths[i]:.4f}")
            for i in range(r.num_cables)]
    print(format_table(["cable", "reel a_i (m)", "attachment b_i (m)", "length at centre (m)"], rows),
          file=out)
    print(f"workspace box: lower {_fmt(r.workspace.lower)} m, upper {_fmt(r.workspace.upper)} m,"
          f" centre {_fmt(c)} m", file=out)
    from cdpm_drake.robot import frame_warnings
    for message in frame_warnings(r):
        print(f"warning: {message}", file=out)
    print(f"Jacobian condition number at the centre: {condition_number(r, c):.3f}", file=out)
    lim = r.limits
    print(f"limits: velocity {lim.max_velocity} m/s, acceleration {lim.max_acceleration} m/s^2,"
          f" reel speed {lim.max_reel_speed} m/s", file=out)
    for pair, why in sorted(r.excluded_reasons.items()):
        print(f"pair {pair} skipped: {why}", file=out)
    from cdpm_drake.kernels.interference import pair_distances, translation_distance_bound

    d = pair_distances(r, c)
    g = translation_distance_bound(r)
    rows = [(f"({i},{j})", f"{1000 * dk:.1f}", f"{1000 * gk:.1f}")
            for (i, j), dk, gk in zip(r.pairs, d, g)]
    print("cable-cable distances at the centre, and the largest any translation gives:",
          file=out)
    print(format_table(["pair", "distance (mm)", "largest (mm)"], rows), file=out)
    print("(the two are equal where the closest points are the attachment points; d_u must "
          "stay below 'largest' or that pair's force never switches off)", file=out)
    path, grid, t_grid, grid_text = _print_statics(r, scenario, grid_step, out, base=base)
    _print_wrench_feasibility(r, grid, t_grid, grid_text, out)
    if plot_dir is None:
        return []
    from cdpm_drake.views.workspace_plots import plot_workspace

    d_u = (resolved.interference.d_u if scenario is not None and resolved.interference
           is not None else INFO_D_U)
    written = plot_workspace(r, plot_dir, floor=INFO_FLOOR, d_u=d_u, path=path,
                             name=scenario.name if scenario is not None else r.name)
    for png in written:
        print(f"plot: {png}", file=out)
    return written


class _robot_warnings_in_report:
    """Within the block, the warnings that loading a robot logs (its statics, the pairs the
    interference block skips) are not printed: `cdpm info`'s report says each of them, on
    its own grid, once."""

    def __enter__(self):
        import logging

        self._logger = logging.getLogger("cdpm_drake.robot")
        self._filter = lambda record: record.levelno < logging.WARNING
        self._logger.addFilter(self._filter)
        return self

    def __exit__(self, *exc):
        self._logger.removeFilter(self._filter)


def _check_info_grid(r, step) -> None:
    """CliError when the --grid step gives more than INFO_MAX_GRID_POINTS on r's box."""
    size = r.workspace.upper - r.workspace.lower

    def counts_of(step):
        return [int(np.floor(s / step + 1e-9)) + 1 for s in size]

    counts = counts_of(step)
    if np.prod(counts, dtype=float) > INFO_MAX_GRID_POINTS:
        least = np.ceil(1000 * np.cbrt(np.prod(size) / INFO_MAX_GRID_POINTS)) / 1000
        while np.prod(counts_of(least), dtype=float) > INFO_MAX_GRID_POINTS:
            least += 0.001  # whole mm: the smallest step that fits
        raise CliError(f"--grid {step!r} m gives {counts[0]} x {counts[1]} x {counts[2]} points "
                       f"on the workspace box of robot {r.name!r}, more than "
                       f"{INFO_MAX_GRID_POINTS:,}; give a step of at least {least:.3f} m")


# The floor (N) of the statics summary and of the pictures, and the d_u (m) the
# interference-free picture of a robot alone uses (the paper's experiments use 61-62 mm).
INFO_FLOOR = 5.0
INFO_D_U = 0.062


def _info_target(name):
    """(robot, None) for a robot, (its robot, the Scenario) for a scenario: a built-in name of
    either, or a YAML file (a robot file has `reels`)."""
    from cdpm_drake.robot import RobotError, is_path_like, load_robot, robot_names
    from cdpm_drake.config import load_scenario, scenario_names, scenario_robot

    text = str(name)
    if text in robot_names():
        return load_robot(text), None
    if text in scenario_names():
        scenario = load_scenario(text)
        return scenario_robot(scenario), scenario
    if is_path_like(text) or Path(text).is_file():
        path = Path(text)
        if path.is_file():
            from pydrake.common.yaml import yaml_load

            try:
                raw = yaml_load(filename=str(path))
            except Exception:
                raw = None
            if isinstance(raw, dict) and "reels" not in raw and (
                    "robot" in raw or "initial_position" in raw or "operator" in raw):
                scenario = load_scenario(str(path))
                return scenario_robot(scenario), scenario
        return load_robot(text), None
    raise RobotError(f"unknown robot or scenario {text!r}; built-in robots: {robot_names()}, "
                     f"built-in scenarios: {scenario_names()} (or give a path to a .yaml file)")


def _print_statics(r, scenario, step, out, base=None):
    """The statics summary, every share on one grid (the --grid step's); returns the
    scenario's simulated path (None without one). `base`: the robot before the swaps (None
    without swaps), which the warnings compare with."""
    from cdpm_drake.robot import robot_statics, statics_warnings
    from cdpm_drake.kernels.tension import step_grid
    from cdpm_drake.robot.statics import holding_tension

    statics = robot_statics(r)
    mass = r.dynamics.mass
    grid = step_grid(r.workspace.lower, r.workspace.upper, step)
    counts = [len(np.arange(lo, hi + 1e-9, step))
              for lo, hi in zip(r.workspace.lower, r.workspace.upper)]
    grid_text = (f"{100 * step:g} cm grid from the lower corner: {counts[0]} x {counts[1]} x "
                 f"{counts[2]} points")
    print(f"statics of the level platform ({mass:g} kg at its centre, moments about the "
          f"centre); t* = the largest achievable minimum cable tension (N):", file=out)
    rank_note = ("" if statics.unreachable is None else
                 f" < 6: no tension produces a {_describe(statics.unreachable)}")
    centre = r.workspace.center
    print(f"  wrench matrix rank at the workspace centre: {statics.rank}{rank_note}; t* there "
          f"{_t_star_text(r, centre, statics.centre_t_star)}", file=out)
    t_grid = t = holding_tension(r, grid)
    share = float(np.mean(t >= INFO_FLOOR))
    print(f"  held with every cable >= {INFO_FLOOR:g} N on {100 * share:.1f} % of the workspace "
          f"box ({grid_text})", file=out)
    # The warnings of the same grid and floor (loading the robot computed them on its own
    # 11^3 grid, and `info` kept them off stderr: they are said here, once).
    label = f"the same {100 * step:g} cm grid"
    base_share = (None if base is None else
                  float(np.mean(holding_tension(base, grid) >= INFO_FLOOR)))
    import dataclasses
    for message in statics_warnings(r, dataclasses.replace(statics, share=share,
                                                           floor=INFO_FLOOR),
                                    grid=label, base=base, base_share=base_share):
        print(f"  warning: {message}", file=out)
    if scenario is None:
        return None, grid, t_grid, grid_text
    p0 = np.asarray(scenario.initial_position, dtype=float)
    print(f"  at the start {_fmt(p0, 2)} m: t* "
          f"{_t_star_text(r, p0, float(holding_tension(r, p0)))}", file=out)
    from cdpm_drake.runs.simulate import simulate

    log = simulate(scenario=_kinematic_copy(scenario)).log
    t = holding_tension(r, log["p"])
    k = int(np.argmin(t))
    print(f"  along the scenario's path (kinematic plant, {len(t)} ticks): smallest t* "
          f"{_t_star_text(r, log['p'][k], t[k])} at t = {log['time'][k]:.3f} s, p = "
          f"{_fmt(log['p'][k])} m; {100 * np.mean(t >= INFO_FLOOR):.1f} % of the ticks at "
          f">= {INFO_FLOOR:g} N", file=out)
    return log["p"], grid, t_grid, grid_text


def _t_star_text(r, p, t) -> str:
    """t* at p (m) as printed: N with two decimals, or what an infinite one means there. +inf
    needs an internal force that raises every tension: where the wrench matrix is
    rank-deficient (the cables' lines of action meet) it holds for the weight alone, at that
    exact pose, and the platform still cannot resist the wrench the rank lacks."""
    from cdpm_drake.kernels.nullspace import RANK_TOL
    from cdpm_drake.kernels.tension import wrench_matrix

    if t == -np.inf:
        return "-inf (no tensions balance the weight)"
    if t != np.inf:
        return f"{t:.2f} N"
    U, s, _ = np.linalg.svd(wrench_matrix(r, p))
    rank = int(np.sum(s > RANK_TOL * max(s[0], 1e-300)))
    if rank == 6:
        return "+inf (an internal force raises every tension: any floor holds)"
    return (f"+inf for the weight alone (the cables' lines of action meet there, so an "
            f"internal force raises every tension), but the wrench matrix has rank {rank} < 6 "
            f"there: the platform cannot resist a {_describe(U[:, rank])}, so no floor holds "
            "it against anything else")


def _kinematic_copy(scenario):
    """The scenario with the kinematic plant (the path the controller commands)."""
    import copy

    from cdpm_drake.config import SimulatedReels

    kinematic = copy.copy(scenario)
    kinematic.plant = SimulatedReels()
    return kinematic


def _describe(direction) -> str:
    from cdpm_drake.robot import describe_wrench

    return describe_wrench(direction)


# Hand forces (N, ascending from 0) and tension floors (N) of the feasibility table, and the
# points per axis of its grid for robots without a compiled t* (not 7 or 8 cables).
FEASIBILITY_FORCES = (0.0, 5.0, 10.0, 20.0)
FEASIBILITY_FLOORS = (0.0, 5.0)
FEASIBILITY_GRID = 5


def feasibility_shares(r, points, t_weight) -> list[list[float]]:
    """[force][floor]: the share of `points` (N, 3) m where the cables hold the level platform
    (the robot file's mass at its centre) plus a hand force of each FEASIBILITY_FORCES at
    the handle in each of the 26 directions, with every cable >= each FEASIBILITY_FLOORS.
    `t_weight`: t* (N) of the weight alone at the points (holding_tension: the 0 N row). A
    point that fails a force fails every larger one (t*, the minimum over a symmetric set of
    directions, is concave in the wrench, so it does not rise with the force), so each force
    is only solved where the one before held: the same shares, about half the work."""
    from cdpm_drake.robot.statics import wrench_feasibility

    d = r.dynamics
    t = np.asarray(t_weight, dtype=float)
    out = []
    for force in FEASIBILITY_FORCES:  # ascending, from 0 N
        if force > 0:
            live = np.flatnonzero(t >= min(FEASIBILITY_FLOORS))
            t = np.full(len(points), -np.inf)
            if live.size:
                t[live] = wrench_feasibility(r, mass=d.mass, hand_force=force,
                                             handle=d.handle, points=points[live]).t_star
        out.append([float(np.mean(t >= floor)) for floor in FEASIBILITY_FLOORS])
    return out


def _print_wrench_feasibility(r, points, t_weight, grid_text, out) -> None:
    from cdpm_drake.kernels.tension import grid_points
    from cdpm_drake.robot.statics import holding_tension

    d = r.dynamics
    if r.num_cables in (7, 8):  # compiled closed forms: the whole grid in about a second
        where = f"on the same grid ({grid_text})"
    else:  # a solver per point and direction: a coarser grid, said so
        n = FEASIBILITY_GRID
        points = grid_points(r.workspace.lower, r.workspace.upper, n)
        t_weight = holding_tension(r, points)
        where = (f"on a coarser {n} x {n} x {n} grid (corners included: {r.num_cables} cables "
                 "need a solver per point)")
    rows = [(f"{force:g}", *(f"{100 * share:.1f}" for share in shares))
            for force, shares in zip(FEASIBILITY_FORCES,
                                     feasibility_shares(r, points, t_weight))]
    print(f"wrench feasibility {where}: the share where the cables hold the level platform "
          f"({d.mass:g} kg, moments about its centre) plus a hand force at the handle "
          f"{_fmt(d.handle, 2)} m in each of 26 directions:", file=out)
    print(format_table(["hand force (N)"] + [f"all cables >= {floor:g} N (%)"
                                             for floor in FEASIBILITY_FLOORS], rows), file=out)


# The most points `cdpm info --grid` computes statics on (~1 us a point and hand-force
# direction for 7 and 8 cables: a few seconds at the default 5 cm, ~140 k points).
INFO_MAX_GRID_POINTS = 1_000_000


def _cmd_info(args) -> int:
    step = args.grid
    if not (step > 0 and np.isfinite(step)):
        raise CliError(f"--grid must be a step in m > 0, got {step!r}")
    if args.plot is not None:  # before the report: a folder found wanting after it is a waste
        _writable_dir(args.plot, "--plot")
    info(robot=args.robot, swaps=args.swaps, plot_dir=args.plot, grid_step=args.grid)
    return 0


def _swap_arg(text: str) -> tuple[int, int]:
    """A cable swap 'I-J' (or 'I,J'), 1-based."""
    parts = text.replace(",", "-").split("-")
    try:
        i, j = (int(x) for x in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a swap is two cable numbers I-J, e.g. 1-3; got "
                                         f"{text!r}") from None
    return i, j


# --- simulate --------------------------------------------------------------------------------


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
    from cdpm_drake.kernels.full_pose import CEILING_EXCEEDED, FLOOR_UNREACHABLE
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
    none = int(np.sum(t_star < 0))
    if none:
        text += (f"; NO tension distribution held on {none} ticks (t* < 0: outside the "
                 "wrench-feasible workspace, a cable must go slack)")
    estimate = np.asarray(log["tension_estimate"], dtype=float)
    return text + (f"; estimated tensions {estimate.min():.2f} to {estimate.max():.1f} N")


def safety_filter_summary(log) -> str:
    """One line on the safety filter of a log (safety_filter.enabled): on how many ticks it
    passed the command, changed it (and which constraints bound, safety_filter.BIND_TEXT),
    held a lost margin, braked to a hold; the smallest pair margin above d_min, by the
    controller's estimate and, with a true pose logged, the truth's; the smallest
    kinetostatic margin kappa (N)."""
    from cdpm_drake.kernels.safety_filter import (BIND_TEXT, STATUS_HOLD, STATUS_MODIFIED, STATUS_NO_RETURN,
                                STATUS_PASS)

    status = np.asarray(log["filter_status"]).reshape(-1).astype(int)
    binding = np.asarray(log["filter_binding"]).reshape(-1).astype(int)
    T = status.size
    bound = [f"{what} {int(np.sum((binding & bit) != 0))}" for bit, what in BIND_TEXT
             if np.any((binding & bit) != 0)]
    text = (f"safety filter: passed {int(np.sum(status == STATUS_PASS))} of {T} ticks, "
            f"changed {int(np.sum(status == STATUS_MODIFIED))}"
            + (f" (bound: {', '.join(bound)})" if bound else ""))
    for code, what in ((STATUS_NO_RETURN, "held a lost margin"),
                       (STATUS_HOLD, "braked to a hold")):
        n = int(np.sum(status == code))
        if n:
            text += f", {what} on {n}"
    margin = np.asarray(log["pair_margin"], dtype=float).reshape(-1)
    if np.isfinite(margin).any():
        text += f"; smallest pair margin above d_min {1000 * margin.min():.2f} mm"
        if "pair_distances_true" in log and "d_min" in log:
            true = (np.asarray(log["pair_distances_true"], dtype=float)
                    - np.asarray(log["d_min"], dtype=float)).min(axis=1)
            text += f" (true {1000 * true.min():.2f} mm)"
    kappa = np.asarray(log["kappa"], dtype=float).reshape(-1)
    if np.isfinite(kappa).any():
        text += f"; smallest kinetostatic margin {kappa[np.isfinite(kappa)].min():.2f} N"
    return text


def model_monitor_summary(log) -> str:
    """One line on the model monitor of a log (model_monitor.enabled): whether the model
    fitted on every tick, else which verdict first (model_monitor.REASONS); the largest
    length residual (mm) and its cable."""
    from cdpm_drake.kernels.model_monitor import REASONS

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
        text += (f"; largest length residual {1000 * residual.reshape(-1)[flat]:+.2f} mm "
                 f"(cable {cable})")
    return text


def _print_dynamic_summary(log, out) -> None:
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


def _print_clipped(log, scenario, out) -> None:
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
              f"{log['time'][k]:.3f} s ({_fmt(log['F_measured'][k], 1)} N)", file=out)


def _load_scenario_arg(args):
    from cdpm_drake.config import load_resolved_scenario

    # Resolved once here; the run, its view and its log all take this object.
    return load_resolved_scenario(args.scenario, overlay_text=args.scenario_text)


def simulate_main(*, scenario, duration=None, out_dir=None, progress=True, out=None,
                  on_chunk=None, html=None, plots=False, realtime_rate=None,
                  chunk=0.5, force=False, runs_root=None) -> int:
    """Simulate, write DIR/log.npz and DIR/scenario.yaml, print a summary. DIR is `out_dir`
    if given (it must be empty, or hold a run and `force` be set), else a new
    runs/<name>/<UTC timestamp>/ (run_folder.py). Returns an exit code: 0; 1 when the run
    ended on an error; 130 / 143 after Ctrl-C / SIGTERM (the log up to then is written all the
    same, and the plots and replay asked for)."""
    from cdpm_drake.runs.run_folder import RUNS_DIR, RunFolder
    from cdpm_drake.config import resolve_scenario
    from cdpm_drake.runs.log import save_log
    from cdpm_drake.runs.simulate import run_variant, simulate

    out = sys.stdout if out is None else out
    resolved = resolve_scenario(scenario)
    scenario = resolved.scenario
    variant, tag = run_variant(resolved)
    folder = RunFolder(scenario.name, out_dir, force=force,
                       root=RUNS_DIR if runs_root is None else runs_root, variant=tag)
    _run_folder_step(folder.plan)
    out_dir = _run_folder_step(folder.create)  # before the run: a long run's log needs a place
    try:
        result = simulate(scenario=resolved, duration=duration, progress=progress,
                          on_chunk=on_chunk, realtime_rate=realtime_rate, chunk=chunk)
    except BaseException:
        folder.discard()  # an early error (bad scenario, bad plant) leaves no folder
        raise
    log = result.log
    path = save_log(log, out_dir, resolved)
    folder.finish()
    T = log["time"].size
    print(f"scenario {scenario.name!r} ({', '.join(variant)}): {T} ticks, "
          f"{log['time'][-1] if T else 0:.3f} s simulated "
          f"in {result.wall_time:.2f} s wall ({result.realtime_factor:.1f}x real time)", file=out)
    print_pair_summary(log, out)
    _print_clipped(log, scenario, out)
    if T and "tension_status" in log:  # controller.tension_control
        print(tension_control_summary(log), file=out)
    if T and "filter_status" in log:  # safety_filter.enabled
        print(safety_filter_summary(log), file=out)
    if T and "model_status" in log:  # model_monitor.enabled
        print(model_monitor_summary(log), file=out)
    if T and "tensions" in log:  # the dynamic plant's ground truth
        _print_dynamic_summary(log, out)
    print(f"log: {path}", file=out)
    # A second Ctrl-C / SIGTERM while the outputs are written must not lose them: the first
    # one already decided the exit code.
    with _signals_ignored(result.error is not None):
        if plots:
            from cdpm_drake.runs.log import LogError
            from cdpm_drake.views.plots import plot_log
            try:
                for png in plot_log(log, out_dir):
                    print(f"plot: {png}", file=out)
            except LogError as e:  # the log is written; say why the figures are not
                print(f"cdpm simulate: error: plots: {e}", file=sys.stderr)
                return 1
        if html is not None:
            print(f"3D replay: {_save_replay(log, html)} (open it in a browser)", file=out)
    stopped = f"t = {log['time'][-1] if T else 0:.3f} s"
    if isinstance(result.error, KeyboardInterrupt):
        from cdpm_drake.runs.interrupt import Terminated, exit_code
        what = "SIGTERM" if isinstance(result.error, Terminated) else "Ctrl-C"
        print(f"cdpm simulate: interrupted at {stopped} ({what}); the log up to there is "
              "written", file=sys.stderr)
        return exit_code(result.error)
    if result.error is not None:
        cause = f"; {result.diagnosis}" if result.diagnosis else ""
        print(f"cdpm simulate: error: the run stopped at {stopped}: {result.error}{cause}",
              file=sys.stderr)
        return 1
    return 0


def _run_folder_step(action):
    from cdpm_drake.runs.run_folder import RunFolderError

    try:
        return action()
    except RunFolderError as e:
        raise CliError(str(e)) from None


class _signals_ignored:
    """Ignore SIGINT and SIGTERM within the block, if `active` (and in the main thread)."""

    def __init__(self, active: bool):
        self._active = active
        self._previous = {}

    def __enter__(self):
        import signal
        import threading
        if self._active and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, signal.SIG_IGN)
        return self

    def __exit__(self, *exc):
        import signal
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def _cmd_simulate(args) -> int:
    _check_duration(args.duration)
    on_chunk = None
    realtime = args.realtime
    if realtime is not None and not (realtime > 0 and np.isfinite(realtime)):
        raise CliError(f"--realtime must be a rate > 0 (1: real time), got {realtime!r}")
    scenario = _load_scenario_arg(args)
    _check_duration_tick(args.duration, scenario)
    _check_html(args.html)
    if args.meshcat:
        on_chunk = _live_meshcat(scenario)
        # Something to watch: paced at real time unless told otherwise.
        realtime = 1.0 if realtime is None else realtime
    with _duration_flag(args.duration):
        code = simulate_main(scenario=scenario, duration=args.duration, out_dir=args.out,
                             progress=not args.no_progress, on_chunk=on_chunk,
                             html=args.html, plots=args.plot, realtime_rate=realtime,
                             chunk=0.04 if args.meshcat else 0.5, force=args.force)
    if args.meshcat and not args.no_wait and sys.stdin.isatty():
        try:
            input("Meshcat is still serving the last frame; press Enter to quit. ")
        except EOFError:
            pass
    return code


def _writable_dir(path: Path, field: str, keep: bool = True) -> None:
    """CliError unless `path` is (or can be made) a writable folder; `keep=False` removes the
    folders the check made (a dry run writes nothing)."""
    from cdpm_drake.runs.run_folder import RunFolderError, writable_dir

    made = []
    q = Path(path)
    while not q.exists() and q != q.parent:
        made.append(q)
        q = q.parent
    try:
        writable_dir(path, field)
    except RunFolderError as e:
        raise CliError(str(e)) from None
    if not keep:
        for q in made:
            q.rmdir()


def _check_html(path) -> None:
    """--html FILE must be writable before a run starts, not found wanting after it."""
    if path is None:
        return
    if path.is_dir():
        raise CliError(f"--html {str(path)!r} is a folder; give a file name, e.g. "
                       f"{str(path / 'replay.html')!r}")
    _writable_dir(path.parent if str(path.parent) else Path("."), "--html's folder")


def _save_replay(log, path):
    """The self-contained HTML replay. The Meshcat server it records with is private to it, so
    Drake's "listening at http://..." line would only mislead: silenced."""
    import logging

    from cdpm_drake.views.meshcat_view import save_replay_html

    drake_log = logging.getLogger("drake")
    previous = drake_log.level
    drake_log.setLevel(logging.WARNING)
    try:
        return save_replay_html(log, path)
    finally:
        drake_log.setLevel(previous)


def _check_duration(duration):
    if duration is not None and not (duration > 0 and np.isfinite(duration)):
        raise CliError(f"--duration must be a number of seconds > 0, got {duration!r}")


class _duration_flag:
    """A log too large for the duration given by --duration is a bad option value (exit 2);
    by the scenario's duration, an invalid scenario (1, as LogTooLarge is a ScenarioError)."""

    def __init__(self, duration):
        self._flag = duration is not None

    def __enter__(self):
        return self

    def __exit__(self, kind, e, tb):
        from cdpm_drake.runs.log import LogTooLarge

        if self._flag and isinstance(e, LogTooLarge):
            raise CliError(f"--{e}") from None
        return False


def _check_duration_tick(duration, resolved) -> None:
    """--duration of at least one tick of the scenario's time_step."""
    from cdpm_drake.config import ScenarioError, check_duration

    if duration is not None:
        try:
            check_duration(duration, resolved.time_step, "--duration")
        except ScenarioError as e:
            raise CliError(str(e)) from None


def _live_meshcat(scenario):
    """A Meshcat window that follows the simulation (views hang off the CLI, not the blocks)."""
    from cdpm_drake.config import resolve_scenario
    from cdpm_drake.runs.latest_signals import latest_signals
    from cdpm_drake.views.meshcat_view import CdpmMeshcatView, live_view_callback, make_meshcat

    resolved = resolve_scenario(scenario)
    robot, params = resolved.robot, resolved.interference
    meshcat = make_meshcat()
    kwargs = {} if params is None else dict(d_l=params.d_l, d_u=params.d_u)
    view = CdpmMeshcatView(meshcat, robot.reels, robot.attachments, robot.workspace.lower,
                           robot.workspace.upper, robot.pairs, **kwargs)
    print(f"Meshcat: open {meshcat.web_url()} in a browser", file=sys.stderr)
    return live_view_callback(view, latest_signals)


# --- run -------------------------------------------------------------------------------------


def run_main(*, scenario, duration=None, out_dir=None, out=None, on_status=None,
             on_view=None, force=False, runs_root=None) -> int:
    """Run on the reels in real time; print live status and the end report. The folder
    policy is simulate_main's. Exit code 0 when the run completed, 1 on a fault or when it
    never enabled the reels, 130 / 143 when Ctrl-C / SIGTERM stopped it."""
    from cdpm_drake.runs.interrupt import exit_code
    from cdpm_drake.runs.realtime import report_lines, run
    from cdpm_drake.runs.run_folder import RUNS_DIR, RunFolder
    from cdpm_drake.config import resolve_scenario
    from cdpm_drake.runs.simulate import run_variant

    out = sys.stdout if out is None else out
    resolved = resolve_scenario(scenario)
    scenario = resolved.scenario
    variant, tag = run_variant(resolved)
    folder = RunFolder(scenario.name, out_dir, force=force,
                       root=RUNS_DIR if runs_root is None else runs_root, variant=tag)
    _run_folder_step(folder.plan)
    out_dir = _run_folder_step(folder.create)
    tty = sys.stderr.isatty()

    def status(line):
        if on_status is not None:
            on_status(line)
        print(("\r" + line) if tty else line, end="" if tty else "\n", file=sys.stderr,
              flush=True)

    try:
        result = run(scenario=resolved, out_dir=out_dir, duration=duration, status=status,
                     on_view=on_view)
    except BaseException:
        folder.discard()
        raise
    if result.log_path is None:
        folder.discard()  # it never enabled: nothing on disk, nothing in the way of the next
    else:
        folder.finish()
    if tty:
        print(file=sys.stderr)
    plant = scenario.plant
    where = (f" at {plant.address}:{plant.port}" if hasattr(plant, "address") else "")
    print(f"scenario {scenario.name!r} ({', '.join(variant)}{where})", file=out)
    for line in report_lines(result):
        print(line, file=out)
    if result.log and len(result.log["time"]):  # what the cables did, as simulate says it
        print_pair_summary(result.log, out)
        if "filter_status" in result.log:
            print(safety_filter_summary(result.log), file=out)
        if "model_status" in result.log:
            print(model_monitor_summary(result.log), file=out)
    if result.ending == "fault":
        print(f"cdpm run: error: {result.error}", file=sys.stderr)
        if not result.enabled and any(why in str(result.error) for why in (
                "do not fit robot", "outside the workspace box", "cannot hold")):
            from cdpm_drake.config import scenario_names
            which = (scenario.name if scenario.name in scenario_names()
                     else "<this run's scenario file>")
            print("cdpm run: hint: against cdpm emulate, the emulator may be playing another "
                  "scenario or robot (other start, swaps or cables); start it with this run's: "
                  f"cdpm emulate --scenario {which} ...", file=sys.stderr)
        if not result.enabled and "fault bits" in str(result.error):
            print("cdpm run: hint: fault bits stay set until the bridge is reset (power "
                  "cycle; restart cdpm emulate); COMMAND_TIMEOUT is the bridge's own watchdog "
                  "after a controller that stopped while enabled (killed)", file=sys.stderr)
        return 1
    if result.ending == "interrupted":
        return exit_code(result.signal)
    return 0


def _cmd_run(args) -> int:
    _check_duration(args.duration)
    if args.rt_priority:
        from cdpm_drake.hardware.priority import PriorityError, set_realtime_priority
        try:
            set_realtime_priority(args.rt_priority)
        except (PriorityError, ValueError) as e:
            raise CliError(f"--rt-priority {args.rt_priority!r}: {e}") from None
    scenario = _load_scenario_arg(args)
    _check_duration_tick(args.duration, scenario)
    on_view = _live_meshcat(scenario) if args.meshcat else None
    with _duration_flag(args.duration):
        return run_main(scenario=scenario, duration=args.duration, out_dir=args.out,
                        on_view=on_view, force=args.force)


# --- plot ------------------------------------------------------------------------------------


def _find_log(path: Path, command: str):
    """(the log, the run folder or .npz it came from) for a command's LOG argument: a
    log.npz, its run folder, runs/<name> (its latest run); a folder with only ticks.bin is
    recovered first."""
    from cdpm_drake.runs.run_folder import resolve_latest
    from cdpm_drake.runs.log import LogError, load_log

    target = resolve_latest(path)
    if target.is_dir() and not (target / "log.npz").exists() and (target / "ticks.bin").exists():
        print(f"cdpm {command}: {str(target)!r} has ticks.bin but no log.npz (the run was "
              "killed before converting it): recovering first", file=sys.stderr)
        _recover(target)
    try:
        return load_log(target), target
    except LogError as e:
        raise InputError(str(e)) from None


def _cmd_plot(args) -> int:
    from cdpm_drake.views.plots import plot_log

    if _is_sweep_dir(args.log):
        return _cmd_plot_sweep(args)
    log, target = _find_log(args.log, "plot")
    if args.out is not None:
        _writable_dir(args.out, "--out")
    _check_html(args.html)
    out_dir = args.out if args.out is not None else (
        target if target.is_dir() else target.parent)
    only = None
    if args.html is not None:
        # Asked for the replay: the figures already drawn from this log stay as they are;
        # only those missing (or older than the log) are drawn.
        from cdpm_drake.views.plots import FIGURE_FILES, figures_of
        log_file = target / "log.npz" if target.is_dir() else target
        only = [name for name in figures_of(log)
                if _older(Path(out_dir) / FIGURE_FILES[name], log_file)]
        kept = len(figures_of(log)) - len(only)
        if kept:
            print(f"plot: {kept} figure(s) already drawn from this log kept in {out_dir}")
    for png in plot_log(log, out_dir, only=only):
        print(f"plot: {png}")
    if args.html is not None:
        print(f"3D replay: {_save_replay(log, args.html)} (open it in a browser)")
    return 0


def _older(path: Path, than: Path) -> bool:
    """Whether `path` is missing or was written before `than` (a figure before its log)."""
    try:
        return path.stat().st_mtime < than.stat().st_mtime
    except OSError:
        return True


# --- export ----------------------------------------------------------------------------------


def _cmd_export(args) -> int:
    from cdpm_drake.views.log_csv import log_to_csv

    if _is_sweep_dir(args.log):
        raise InputError(f"{str(args.log)!r} is a sweep's folder: its results.csv is the "
                         "table already (one row per run); export a run's log.npz")
    log, target = _find_log(args.log, "export")
    text = log_to_csv(log)
    if args.out is not None and str(args.out) == "-":
        sys.stdout.write(text)
        return 0
    path = args.out if args.out is not None else (
        (target if target.is_dir() else target.parent) / "log.csv")
    if path.is_dir():
        raise CliError(f"--out {str(path)!r} is a folder; give a file name, e.g. "
                       f"{str(path / 'log.csv')!r}")
    _writable_dir(path.parent if str(path.parent) else Path("."), "--out's folder")
    path.write_text(text)
    header = text.partition("\n")[0]  # names hold no commas
    print(f"csv: {path} ({text.count(chr(10)) - 1} rows, one per tick; "
          f"{header.count(',') + 1} columns)")
    return 0


def _export_parser(sub) -> None:
    p = sub.add_parser(
        "export", help="write a log as CSV: one row per tick, named columns with units",
        description="Write a log.npz as CSV for spreadsheets and other tools: one row per "
                    "tick, one column per value, named with its unit (p_x [m], F_H_z [N], "
                    "lengths_1 [m], pair_distances_1-3 [m], active_1-3 [0/1], "
                    "rpy_true_roll [rad]), cables numbered from 1 and pairs by their cables "
                    "(docs/LOG_FORMAT.md). The per-run constants (robot, logistic parameters, "
                    "how the run ended) stay in log.npz.")
    p.add_argument("log", type=Path,
                   help="a log.npz, the run folder holding it (or only ticks.bin: recovered "
                        "first), or runs/<name> (its latest run)")
    # CSV is the only format, so the default; --csv stays accepted (scripts written for it).
    p.add_argument("--csv", action="store_true",
                   help="comma-separated values (the default and only format)")
    p.add_argument("--out", type=Path, metavar="FILE",
                   help="output file (default: log.csv beside the log; - for stdout)")
    p.set_defaults(func=_cmd_export)


# --- recover ---------------------------------------------------------------------------------


def _recover(run_dir, out=None) -> None:
    from cdpm_drake.runs.realtime import RecoverError, recover

    out = sys.stderr if out is None else out
    try:
        path, tail = recover(run_dir)
    except RecoverError as e:
        raise InputError(str(e)) from None
    cut = (f"the tail was cut: a partial last row of {tail['cut_bytes']} bytes left out"
           if tail["cut_bytes"] else "the tail was whole (no partial row)")
    print(f"recovered {tail['ticks']} ticks of {tail['expected']} ({tail['ending']}); {cut}; "
          f"log: {path}", file=out)


def _cmd_recover(args) -> int:
    from cdpm_drake.runs.run_folder import resolve_latest

    _recover(resolve_latest(args.run_dir), out=sys.stdout)
    return 0


# --- list ------------------------------------------------------------------------------------


def list_main(out=None) -> int:
    """Print the built-in robots, scenarios and sweeps, one line each."""
    from cdpm_drake import data

    out = sys.stdout if out is None else out
    ROBOTS_DIR, SCENARIOS_DIR, sweeps_dir = data.ROBOTS_DIR, data.SCENARIOS_DIR, data.SWEEPS_DIR
    for title, directory in (("robots", ROBOTS_DIR), ("scenarios", SCENARIOS_DIR),
                             ("sweeps", sweeps_dir)):
        files = sorted(directory.glob("*.yaml")) if directory.is_dir() else []
        if title == "sweeps" and not files:
            continue
        print(f"{title} ({directory}):", file=out)
        rows = [(f.stem, _one_line(f)) for f in files]
        width = max((len(n) for n, _ in rows), default=0)
        for name, line in rows:
            print(f"  {name:<{width}}  {line}", file=out)
    return 0


def _one_line(path: Path) -> str:
    """A YAML file's `description`, else its first comment line."""
    from pydrake.common.yaml import yaml_load

    try:
        raw = yaml_load(filename=str(path))
    except Exception as e:  # listed all the same: say why there is no description
        return f"(not readable: {type(e).__name__})"
    description = raw.get("description") if isinstance(raw, dict) else None
    if isinstance(description, str) and description.strip():
        return _first_sentence(" ".join(description.split()))
    comment = []  # the file's leading comment block, as one paragraph
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            if comment or line.strip():
                break
            continue
        comment.append(line.lstrip("#").strip())
    return _first_sentence(" ".join(w for w in comment if w))


def _first_sentence(text: str, limit: int = 110) -> str:
    import re

    # A sentence ends at ". " before a capital ("Fig. 7" does not end one).
    end = re.search(r"[.:;](?=\s+[A-Z])", text)
    text = text if end is None else text[:end.start() + 1]
    return text if len(text) <= limit else text[:limit - 3].rstrip() + "..."


def _cmd_list(args) -> int:
    return list_main()


# --- diagram ---------------------------------------------------------------------------------


# The diagrams `cdpm diagram` writes, each at full depth (NAME) and as an overview
# (NAME_overview), as .dot and .svg (README, "Look at it").
DIAGRAMS = ("controller_simulated", "controller_hardware", "controller_dynamic",
            "plant_dynamic", "controller_full_pose")


def diagram_main(*, scenario, out_dir, depth=None, svg=True, out=None) -> int:
    """Write the controller diagram, with the simulated, the hardware and the dynamic plant,
    the dynamic plant alone and the full-pose controller (DIAGRAMS); `depth` levels of
    sub-diagrams in the full-depth pictures (None: every level)."""
    import dataclasses

    from cdpm_drake.diagram import BuildOptions, build_diagram
    from cdpm_drake.hardware.config import HardwareReels
    from cdpm_drake.config import DynamicReels, ScenarioError, SimulatedReels
    from cdpm_drake.views.diagram_graph import write_diagrams

    out = sys.stdout if out is None else out
    options = BuildOptions(loggers=False)  # loggers only clutter the picture
    diagrams = {
        "controller_simulated": build_diagram(
            dataclasses.replace(scenario, plant=SimulatedReels()), options),
        "controller_hardware": build_diagram(
            dataclasses.replace(scenario, plant=HardwareReels()), options),
    }
    dynamic = scenario.plant if isinstance(scenario.plant, DynamicReels) else DynamicReels()
    try:
        diagrams["controller_dynamic"] = build_diagram(
            dataclasses.replace(scenario, plant=dynamic), options)
        # Inside the dynamic plant: the MultibodyPlant, drives, encoders, cables, loggers.
        diagrams["plant_dynamic"] = diagrams["controller_dynamic"].GetSubsystemByName("reels")
    except ScenarioError as e:  # a start the cables cannot hold level: say so, draw the rest
        print(f"skipped controller_dynamic: {e}", file=out)
    # The full-pose controller with its tension control (controller.pose: full), on the
    # dynamic plant: the pose forward kinematics, the tension distribution, the orientation
    # hold.
    from cdpm_drake.config import check_scenario
    full = dataclasses.replace(
        scenario, plant=dynamic, controller=dataclasses.replace(
            scenario.controller, pose="full", tension_control=True))
    try:
        check_scenario(full)
        diagrams["controller_full_pose"] = build_diagram(full, options)
    except ScenarioError as e:
        print(f"skipped controller_full_pose: {e}", file=out)
    for path in write_diagrams(diagrams, out_dir, svg=svg, max_depth=depth):
        print(f"wrote {path}", file=out)
    return 0


def _cmd_diagram(args) -> int:
    if args.depth is not None and args.depth < 1:
        raise CliError(f"--depth must be an integer >= 1, got {args.depth!r}")
    return diagram_main(scenario=_load_scenario_arg(args).scenario, out_dir=args.out, depth=args.depth,
                        svg=not args.no_svg)


# --- sweep -----------------------------------------------------------------------------------


def _is_sweep_dir(path: Path) -> bool:
    return path.is_dir() and (path / "results.csv").is_file() and not (path / "log.npz").exists()


def _cmd_plot_sweep(args) -> int:
    from cdpm_drake.runs.sweep import SweepError, plot_main
    from cdpm_drake.views.sweep_plots import plot_sweep

    if args.out is not None:
        _writable_dir(args.out, "--out")
    try:
        return plot_main(sweep_dir=args.log, plot=plot_sweep, out_dir=args.out)
    except SweepError as e:  # a bad sweep file or results: an error (1), as for scenarios
        print(f"cdpm plot: error: {e}", file=sys.stderr)
        return 1


def _cmd_sweep(args) -> int:
    from cdpm_drake.runs.sweep import SweepError, sweep_main

    if args.workers is not None and args.workers < 1:
        raise CliError(f"--workers must be an integer >= 1, got {args.workers!r}")
    if args.ray_chunk is not None and args.ray_chunk < 1:
        raise CliError(f"--ray-chunk must be an integer >= 1, got {args.ray_chunk!r}")
    if args.top < 1:
        raise CliError(f"--top must be an integer >= 1, got {args.top!r}")
    if args.out is not None:
        _writable_dir(args.out, "--out", keep=not args.dry_run)
    plot = None
    if args.plot:
        from cdpm_drake.views.sweep_plots import plot_sweep as plot
    try:
        return sweep_main(sweep=args.sweep, out_dir=args.out, workers=args.workers,
                          ray=args.ray is not None, ray_address=args.ray or None,
                          ray_chunk=args.ray_chunk, keep_logs=args.keep_logs,
                          retry_errors=args.retry_errors, plot=plot, metric=args.metric,
                          top=args.top, dry_run=args.dry_run, progress=not args.no_progress)
    except SweepError as e:  # a bad sweep file or variant: an error (1), as for scenarios
        print(f"cdpm sweep: error: {e}", file=sys.stderr)
        return 1


def _sweep_parser(sub) -> None:
    from cdpm_drake.runs.sweep import NUMERIC_METRICS, sweep_names

    p = sub.add_parser(
        "sweep", help="run many variants of a scenario (a grid, random samples, seeds)",
        description="Run every variant of a sweep file (docs/SWEEP_FORMAT.md) with the same "
                    "diagram and Simulator as cdpm simulate, on local processes (one per core) "
                    "or on Ray; write DIR/results.csv (one row per run) and each run's "
                    "resolved scenario.yaml. Rerunning the same command resumes.")
    p.add_argument("sweep", help=f"a shipped sweep ({', '.join(sweep_names())}) or a path to "
                                 "a sweep YAML")
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="output directory (default: runs/sweeps/<sweep name>)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="local worker processes (default: one per core)")
    p.add_argument("--ray", nargs="?", const="", metavar="ADDRESS",
                   help="run on Ray: a local Ray, or the cluster at ADDRESS (e.g. "
                        "ray://host:10001 or auto); needs pip install -e '.[ray]'")
    p.add_argument("--ray-chunk", type=int, metavar="K",
                   help="runs per Ray task (default: chosen so a task lasts ~2 s)")
    p.add_argument("--keep-logs", action="store_true", help="also keep each run's log.npz")
    p.add_argument("--retry-errors", action="store_true",
                   help="rerun the rows that faulted or ended in an error (a resume skips "
                        "them)")
    p.add_argument("--plot", action="store_true",
                   help="write the heatmap, metric-vs-axis and Pareto pictures")
    p.add_argument("--metric", choices=NUMERIC_METRICS, metavar="NAME",
                   help="metric of the pictures and the best-runs table (default: the sweep "
                        f"file's, else min_distance): {', '.join(NUMERIC_METRICS)}")
    p.add_argument("--top", type=int, default=5, metavar="K",
                   help="rows in the best-runs table (default 5)")
    p.add_argument("--dry-run", action="store_true",
                   help="check and list the variants, run nothing")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_sweep)


# --- main ------------------------------------------------------------------------------------


EXIT_CODES = """\
exit codes (every command):
  0    done
  1    error: a scenario, robot, sweep, log or run folder that cannot be found or is
       invalid, a run that failed or faulted, cdpm run that never enabled the reels
  2    bad usage: an unknown option, a missing or malformed argument, an option value
       out of range (--duration, --realtime, --out, ...)
  130  interrupted by Ctrl-C (SIGINT); whatever was logged is written
  143  stopped by SIGTERM (e.g. `timeout`, a batch scheduler); as for Ctrl-C
"""


class _Parser(argparse.ArgumentParser):
    """An argument error in a sub-command shows that sub-command's usage, not the top one."""

    def parse_args(self, args=None, namespace=None):
        args, extras = self.parse_known_args(args, namespace)
        if extras:
            sub = getattr(args, "_subparser", None) or self
            sub.error(f"unrecognized arguments: {' '.join(extras)}")
        return args


def _parser() -> argparse.ArgumentParser:
    from cdpm_drake import __version__

    parser = _Parser(prog="cdpm", description=__doc__, epilog=EXIT_CODES,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"cdpm {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("info", help="print a robot description: cables, Jacobian, workspace, "
                                    "statics",
                       description="Print a robot description as tables: cables, Jacobian, "
                                   "workspace, cable-cable distances and statics (where the "
                                   "cables hold the platform). Given a scenario, the robot "
                                   "as that experiment uses it: its swaps, start and path.")
    p.add_argument("robot", nargs="?", default="paper_7cable",
                   help="a built-in robot or scenario name, or a path to a robot or scenario "
                        "YAML file (default: paper_7cable)")
    p.add_argument("--swaps", nargs="+", type=_swap_arg, metavar="I-J",
                   help="swap these cables' attachment points (1-based, e.g. 1-3 5-7); with "
                        "a scenario, instead of its swaps")
    p.add_argument("--plot", type=Path, metavar="DIR",
                   help="also write the workspace pictures (wrench-feasible and "
                        "interference-free workspace slices) into DIR")
    p.add_argument("--grid", type=float, default=0.05, metavar="STEP",
                   help="grid step (m) of the statics share (default 0.05)")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("simulate", help="simulate a scenario and write its log",
                       description="Simulate a scenario's Fig. 5 diagram with Drake's Simulator "
                                   "at 500 Hz; write DIR/log.npz and DIR/scenario.yaml (with "
                                   "copies of the robot file and force CSV it reads, so DIR "
                                   "reruns alone).")
    _scenario_args(p)
    p.add_argument("--duration", type=float, help="simulated time, s (default: the scenario's)")
    p.add_argument("--out", type=Path,
                   help="output directory, used exactly; must be empty unless --force "
                        "(default: a new runs/<scenario name>/<UTC time>/, with "
                        "runs/<scenario name>/latest pointing at it)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--meshcat", action="store_true",
                   help="show the robot live in Meshcat (prints the URL to open); the "
                        "simulation then runs at real time (see --realtime)")
    p.add_argument("--realtime", type=float, metavar="RATE",
                   help="pace the simulation at RATE x real time (default: as fast as "
                        "possible; 1.0 with --meshcat)")
    p.add_argument("--no-wait", action="store_true",
                   help="with --meshcat: quit at the end instead of waiting for Enter")
    p.add_argument("--html", type=Path, metavar="FILE",
                   help="also save a self-contained 3D replay (opens in a browser, no server)")
    p.add_argument("--plot", action="store_true",
                   help="also write the paper's figures as PNGs next to the log")
    p.add_argument("--force", action="store_true",
                   help="empty a non-empty --out that holds an earlier run, then write there")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("run", help="run a scenario in real time against the reels",
                       description="Build the same diagram with the scenario's !HardwareReels "
                                   "plant and run it at 500 Hz in real time against the reel "
                                   "bridge (or cdpm-reel-emulator). Ctrl-C or SIGTERM stop it "
                                   "cleanly (zero reel velocity is sent first); every tick is "
                                   "logged to disk as it goes.")
    _scenario_args(p, default=None)
    p.add_argument("--duration", type=float, help="run time, s (default: the scenario's)")
    p.add_argument("--out", type=Path,
                   help="output directory, used exactly; must be empty unless --force "
                        "(default: a new runs/<scenario name>/<UTC time>/, with "
                        "runs/<scenario name>/latest pointing at it)")
    p.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="run under SCHED_FIFO at priority N (1..99; needs root or "
                        "CAP_SYS_NICE): keeps a busy host from delaying ticks past the "
                        "watchdog (default 0: normal scheduling)")
    p.add_argument("--meshcat", action="store_true",
                   help="show the robot live in Meshcat (prints the URL to open)")
    p.add_argument("--force", action="store_true",
                   help="empty a non-empty --out that holds an earlier run, then write there")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("emulate", help="play the reel bridge on loopback (cdpm-reel-emulator)",
                       description="Same as cdpm-reel-emulator; `cdpm emulate --help` lists "
                                   "its options.", add_help=False)
    p.add_argument("emulator_args", nargs="*",
                   help="options of cdpm-reel-emulator, e.g. --scenario exp2_interaction")

    p = sub.add_parser("plot", help="plot a log: the paper's Figs. 8-16 as PNGs",
                       description="Plot a log.npz: pair distances with d_l and d_u (Fig. 10), "
                                   "forces (Figs. 11, 13, 16), the 3D trajectory with "
                                   "interference events (Figs. 9, 15), the logistic curve "
                                   "(Fig. 8).")
    p.add_argument("log", type=Path,
                   help="a log.npz, the run folder holding it (or only ticks.bin: recovered "
                        "first), runs/<name> (its latest run), or a sweep's directory (its "
                        "pictures from results.csv)")
    p.add_argument("--out", type=Path, help="output directory (default: the log's directory)")
    p.add_argument("--html", type=Path, metavar="FILE",
                   help="save a self-contained 3D replay of the log; the PNGs already drawn "
                        "from this log are kept, only missing ones drawn")
    p.set_defaults(func=_cmd_plot)

    p = sub.add_parser("diagram", help="write the controller diagram as graphviz (.dot, .svg)",
                       description="Write the Fig. 5 diagram of a scenario as .dot and .svg "
                                   "files, each at full depth and as a readable overview: with "
                                   "the simulated, the hardware and the dynamic plant, the "
                                   "dynamic plant alone, and the full-pose controller.")
    _scenario_args(p)
    p.add_argument("--out", type=Path, default=Path("diagrams"),
                   help="output directory (default: diagrams)")
    p.add_argument("--depth", type=int, default=None,
                   help="how many levels of sub-diagrams the full-depth pictures expand "
                        "(default: every level, the plant's insides too)")
    p.add_argument("--no-svg", action="store_true", help="write only the .dot files")
    p.set_defaults(func=_cmd_diagram)

    _sweep_parser(sub)
    _export_parser(sub)

    p = sub.add_parser("recover", help="turn a killed run's ticks.bin into log.npz",
                       description="Convert the tick stream of a `cdpm run` that was killed "
                                   "before it wrote log.npz (SIGKILL, power loss) into "
                                   "DIR/log.npz, using DIR/scenario.yaml; says how many ticks "
                                   "it kept and whether the tail was cut.")
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR",
                   help="the run's folder (holding ticks.bin and scenario.yaml), or "
                        "runs/<name> for its latest run")
    p.set_defaults(func=_cmd_recover)

    p = sub.add_parser("list", help="list the built-in robots, scenarios and sweeps",
                       description="List the robots, scenarios and sweeps shipped with the "
                                   "package, one line each; use them by name from any "
                                   "directory.")
    p.set_defaults(func=_cmd_list)
    for name, choice in sub.choices.items():
        choice.set_defaults(_subparser=choice)
    return parser


def _scenario_args(p, default="exp2_interaction"):
    from cdpm_drake.config import scenario_names

    names = ", ".join(scenario_names())
    if default is None:
        p.add_argument("scenario", help=f"a built-in scenario ({names}) or a path to a "
                                        "scenario YAML")
    else:
        p.add_argument("scenario", nargs="?", default=default,
                       help=f"a built-in scenario ({names}) or a path to a scenario YAML "
                            f"(default: {default})")
    p.add_argument("--scenario-text", default=None, metavar="YAML",
                   help="YAML overlay for one-off changes, e.g. "
                        "'{duration: 5, interference: {default: {F_u: 4.0}}}'")


COMPILE_NOTICE = ("cdpm: compiling per-tick math this command needs for the first time "
                  "(numba, a few seconds, once: later runs load it from the cache)")
# Set in the environment once the notice is said: a process this command starts afterwards
# (an emulator, a worker) inherits it and does not say it again.
COMPILE_NOTICE_SAID = "CDPM_COMPILE_NOTICE_SAID"


class _compile_notice:
    """Within the block, the first compilation of a kernel (numba's "numba:compile" event:
    a cache miss, never a load from the cache) prints COMPILE_NOTICE once on `stream`, so the
    seconds of a first run are explained; a run that loads everything from numba's cache says
    nothing, and so does a process started by one that said it already (COMPILE_NOTICE_SAID
    in its environment). Each command after installing may compile what it alone needs (the
    dynamic plant's cables, the workspace statics), hence "this command ... first time"."""

    def __init__(self, stream=None):
        import os

        self._stream = stream
        self._inherited = os.environ.get(COMPILE_NOTICE_SAID)
        self.said = bool(self._inherited)
        self._installed = None

    def __enter__(self):
        try:
            from numba.core import event
        except ImportError:  # no numba event API: no notice, nothing else changes
            return self
        notice = self

        class _Listener(event.Listener):
            def on_start(self, ev):
                if not notice.said:
                    import os

                    notice.said = True
                    os.environ[COMPILE_NOTICE_SAID] = "1"
                    print(COMPILE_NOTICE, file=notice._stream or sys.stderr, flush=True)

            def on_end(self, ev):
                pass

        self._installed = event.install_listener("numba:compile", _Listener())
        self._installed.__enter__()
        return self

    def __exit__(self, *exc):
        import os

        if self._installed is not None:
            self._installed.__exit__(*exc)
            self._installed = None
        if self._inherited is None:  # the command is over: the next one may say it again
            os.environ.pop(COMPILE_NOTICE_SAID, None)


def main(argv=None) -> int:
    from cdpm_drake.hardware.tick_log import TickLogError
    from cdpm_drake.runs.interrupt import Terminated, exit_code, terminate_raises
    from cdpm_drake.kernels.kinematics import KinematicsError
    from cdpm_drake.kernels.plant.operators import OperatorError
    from cdpm_drake.robot import RobotError
    from cdpm_drake.config import ScenarioError

    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["emulate"]:
        # argparse cannot hand options through a sub-command untouched; the emulator parses
        # its own.
        from cdpm_drake.emulator import main as emulator_main
        with _compile_notice():
            return emulator_main(argv[1:])
    args = _parser().parse_args(argv)
    with prefixed_log_records(), terminate_raises(), _compile_notice():
        try:
            return int(args.func(args) or 0)
        except CliError as e:
            print(f"cdpm {args.command}: error: {e}", file=sys.stderr)
            return 2
        except (InputError, RobotError, KinematicsError, ScenarioError, OperatorError,
                TickLogError) as e:
            print(f"cdpm {args.command}: error: {e}", file=sys.stderr)
            return 1
        except KeyboardInterrupt as e:
            what = "SIGTERM" if isinstance(e, Terminated) else "Ctrl-C"
            print(f"cdpm {args.command}: interrupted ({what})", file=sys.stderr)
            return exit_code(e)
        except BrokenPipeError:
            # `cdpm info | head`: the reader left; not an error of ours.
            sys.stderr.close()
            return 0

