"""`cdpm info`: a robot (or a scenario's robot, as the experiment uses it) as text: its
cables, Jacobian conditioning, workspace box, the cable pairs' distances, and its statics:
where the cables hold the level platform, alone and against a hand force. Metres, newtons,
the world frame."""

import sys
from pathlib import Path

import numpy as np

from cdpm_drake.cli.arguments import check_writable_dir
from cdpm_drake.cli.errors import CliError
from cdpm_drake.text import format_table, format_vector


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
        r, scenario, refused = _info_target(robot)
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
            resolved, refusal = _resolve_reporting_refusal(scenario)
            refused = refused or refusal
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
    if r.calibration is not None:
        for line in calibration_lines(r):
            print(line, file=out)
    if refused is not None:
        print(f"refused: `cdpm simulate` would refuse this scenario's run (and `cdpm "
              f"emulate` its dynamic plant): {refused}", file=out)
    rows = [(i + 1, format_vector(r.reels[i]), format_vector(r.attachments[i]), f"{lengths[i]:.4f}")
            for i in range(r.num_cables)]
    print(format_table(["cable", "reel a_i (m)", "attachment b_i (m)", "length at centre (m)"],
                       rows), file=out)
    print(f"workspace box: lower {format_vector(r.workspace.lower)} m, upper "
          f"{format_vector(r.workspace.upper)} m, centre {format_vector(c)} m", file=out)
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
    path, grid, t_grid, grid_text, solved = _print_statics(r, scenario, grid_step, out,
                                                           base=base)
    _print_wrench_feasibility(r, grid, t_grid, grid_text, out, solved)
    start = (np.asarray(resolved.scenario.initial_position, dtype=float)
             if scenario is not None and refused is None else c)
    print_fastest_hand(r, start, out)
    if scenario is not None and refused is None:
        _print_homing(r, resolved.scenario, out)
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


def _load_reporting_refusal(name: str):
    """(Scenario, None), or for a scenario whose run would be refused because its robot
    cannot hold the free-rotating platform (config.UnholdableRobot): the scenario with the
    platform's rotation locked, so the report goes on, and the refusal's message."""
    from cdpm_drake.config import UnholdableRobot, load_scenario

    try:
        return load_scenario(name), None
    except UnholdableRobot as e:
        return _locked(e.scenario), str(e)


def _resolve_reporting_refusal(scenario):
    """(ResolvedScenario, None), or as `_load_reporting_refusal` (after --swaps): the
    scenario resolved with the platform's rotation locked, and the refusal's message."""
    from cdpm_drake.config import UnholdableRobot, resolve_scenario

    try:
        return resolve_scenario(scenario), None
    except UnholdableRobot as e:
        return resolve_scenario(_locked(e.scenario)), str(e)


def _locked(scenario):
    import dataclasses

    return dataclasses.replace(scenario, plant=dataclasses.replace(scenario.plant,
                                                                    lock_rotation=True))


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


def _robot_only_fields() -> set:
    """The top-level fields of a robot file that no scenario has (reels, attachments, ...)."""
    import dataclasses

    from cdpm_drake.config import Scenario
    from cdpm_drake.robot.schema import RobotSchema

    return ({f.name for f in dataclasses.fields(RobotSchema)}
            - {f.name for f in dataclasses.fields(Scenario)})


def _info_target(name):
    """(robot, None, None) for a robot, (its robot, the Scenario, the refusal of its run or
    None) for a scenario: a built-in name of either, or a YAML file (a robot file is one with
    a field no scenario has, e.g. `reels`; any other mapping is a scenario, as `cdpm
    simulate` reads it)."""
    from cdpm_drake.robot import RobotError, is_path_like, load_robot, robot_names
    from cdpm_drake.config import scenario_names, scenario_robot

    text = str(name)
    if text in robot_names():
        return load_robot(text), None, None
    if text in scenario_names():
        scenario, refused = _load_reporting_refusal(text)
        return scenario_robot(scenario), scenario, refused
    if is_path_like(text) or Path(text).is_file():
        path = Path(text)
        if path.is_file():
            from pydrake.common.yaml import yaml_load

            try:
                raw = yaml_load(filename=str(path))
            except Exception:
                raw = None
            if isinstance(raw, dict) and not set(raw) & _robot_only_fields():
                # As `cdpm simulate` reads it: a scenario, its robot paper_7cable unless named.
                scenario, refused = _load_reporting_refusal(str(path))
                return scenario_robot(scenario), scenario, refused
        return load_robot(text), None, None
    raise RobotError(f"unknown robot or scenario {text!r}; built-in robots: {robot_names()}, "
                     f"built-in scenarios: {scenario_names()} (or give a path to a .yaml file)")


def _print_homing(r, scenario, out) -> None:
    """The homing at the scenario's start (docs/on_the_robot.md): each encoder's reading
    there, the rigid length of its cable; the tensions the controller takes the homing to
    leave (the least-norm distribution holding the level platform with every cable at least
    the plant's homing_min_tension, 5 N by default) and the stretch they give."""
    from cdpm_drake.kernels.kinematics import cable_lengths
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix
    from cdpm_drake.robot.tension_program import tension_distribution

    p0 = np.asarray(scenario.initial_position, dtype=float)
    floor = float(getattr(scenario.plant, "homing_min_tension", 5.0))
    dist = tension_distribution(wrench_matrix(r, p0), gravity_wrench(r.dynamics.mass), floor)
    if not dist.feasible:
        return
    rigid = cable_lengths(r, p0)
    T = dist.tensions
    stretch = rigid * T / (r.dynamics.EA + T)
    print(f"homing at the start {format_vector(p0)} m, level (docs/on_the_robot.md): set each "
          f"encoder to read the rigid length there, the cables taut at the tensions below "
          f"(every cable >= homing_min_tension = {floor:g} N; the controller takes them where "
          f"it measures none):", file=out)
    print(format_table(["cable", "encoder reads (m)", "tension (N)", "stretch (mm)"],
                       [(i + 1, f"{rigid[i]:.5f}", f"{T[i]:.2f}", f"{1000 * stretch[i]:.3f}")
                        for i in range(r.num_cables)]), file=out)


def _print_statics(r, scenario, step, out, base=None):
    """The statics summary, every share on one grid (the --grid step's); returns the
    scenario's simulated path (None without one). `base`: the robot before the swaps (None
    without swaps), which the warnings compare with."""
    from cdpm_drake.robot import robot_statics, statics_warnings
    from cdpm_drake.kernels.tension import step_grid
    from cdpm_drake.robot.statics import holding_tension

    from cdpm_drake.kernels.tension import grid_points
    from cdpm_drake.robot.statics import solver_points

    statics = robot_statics(r)
    mass = r.dynamics.mass
    grid = step_grid(r.workspace.lower, r.workspace.upper, step)
    counts = [len(np.arange(lo, hi + 1e-9, step))
              for lo, hi in zip(r.workspace.lower, r.workspace.upper)]
    grid_text = (f"{100 * step:g} cm grid from the lower corner: {counts[0]} x {counts[1]} x "
                 f"{counts[2]} points")
    slow = int(np.sum(solver_points(r, grid)))
    solved = slow > INFO_MAX_SOLVER_POINTS
    if solved:
        # Milliseconds a point: a robot of every attachment at one point took 757 s here
        # with no word. The coarse grid the load's check uses, said so.
        n = INFO_SOLVER_GRID
        grid = grid_points(r.workspace.lower, r.workspace.upper, n)
        grid_text = (f"a coarser {n} x {n} x {n} grid, corners included: at {slow:,} of the "
                     f"{100 * step:g} cm grid's {int(np.prod(counts)):,} points t* needs a "
                     f"solver, ~{slow * SOLVER_SECONDS:.0f} s")
    print(f"statics of the level platform ({mass:g} kg at its centre, moments about the "
          f"centre); t* = the largest achievable minimum cable tension (N):", file=out)
    rank_note = ("" if statics.unreachable is None else
                 f" < 6: no tensions resist {_describe(r, r.workspace.center)}")
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
        return None, grid, t_grid, grid_text, solved
    p0 = np.asarray(scenario.initial_position, dtype=float)
    print(f"  at the start {format_vector(p0, 2)} m: t* "
          f"{_t_star_text(r, p0, float(holding_tension(r, p0)))}", file=out)
    from cdpm_drake.runs.simulate import simulate

    with _robot_warnings_in_report():  # said above, once (loading it again would repeat them)
        log = simulate(scenario=_kinematic_copy(scenario)).log
    t = holding_tension(r, log["p"])
    k = int(np.argmin(t))
    print(f"  along the scenario's path (kinematic plant, {len(t)} ticks): smallest t* "
          f"{_t_star_text(r, log['p'][k], t[k])} at t = {log['time'][k]:.3f} s, p = "
          f"{format_vector(log['p'][k])} m; {100 * np.mean(t >= INFO_FLOOR):.1f} % of the ticks at "
          f">= {INFO_FLOOR:g} N", file=out)
    return log["p"], grid, t_grid, grid_text, solved


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
            f"there: the platform cannot resist {_describe(r, p)}, so no floor holds "
            "it against anything else")


def _kinematic_copy(scenario):
    """The scenario with the kinematic plant (the path the controller commands)."""
    import copy

    from cdpm_drake.config import SimulatedReels

    kinematic = copy.copy(scenario)
    kinematic.plant = SimulatedReels()
    return kinematic


def _describe(r, p) -> str:
    """Every wrench direction r's level platform at p (m) cannot resist, in words."""
    from cdpm_drake.kernels.tension import wrench_matrix
    from cdpm_drake.robot.unresisted import unresisted_text

    return unresisted_text(wrench_matrix(r, p))


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


def _print_wrench_feasibility(r, points, t_weight, grid_text, out, solved=False) -> None:
    from cdpm_drake.kernels.tension import grid_points
    from cdpm_drake.robot.statics import holding_tension

    d = r.dynamics
    if r.num_cables in (7, 8) and not solved:  # compiled closed forms: about a second
        where = f"on the same grid ({grid_text})"
    else:  # a solver per point and direction: a coarser grid, said so
        n = FEASIBILITY_GRID
        points = grid_points(r.workspace.lower, r.workspace.upper, n)
        t_weight = holding_tension(r, points)
        why = (f"{r.num_cables} cables need" if r.num_cables not in (7, 8) else
               "this robot's statics need")
        where = (f"on a coarser {n} x {n} x {n} grid (corners included: {why} a solver per "
                 "point)")
    rows = [(f"{force:g}", *(f"{100 * share:.1f}" for share in shares))
            for force, shares in zip(FEASIBILITY_FORCES,
                                     feasibility_shares(r, points, t_weight))]
    print(f"wrench feasibility {where}: the share where the cables hold the level platform "
          f"({d.mass:g} kg, moments about its centre) plus a hand force at the handle "
          f"{format_vector(d.handle, 2)} m in each of 26 directions:", file=out)
    print(format_table(["hand force (N)"] + [f"all cables >= {floor:g} N (%)"
                                             for floor in FEASIBILITY_FLOORS], rows), file=out)


# The most points of the --grid at which `cdpm info` solves t* with Clarabel (milliseconds
# each, robot.statics.solver_points; SOLVER_SECONDS measured on a degenerate 7-cable
# robot, its 11^3 grid in 5 s): beyond, its statics use a coarse grid of INFO_SOLVER_GRID
# points per axis (11^3, the load check's), a few seconds.
INFO_MAX_SOLVER_POINTS = 2000
INFO_SOLVER_GRID = 11
SOLVER_SECONDS = 0.004

# The most points `cdpm info --grid` computes statics on (~1 us a point and hand-force
# direction for 7 and 8 cables: a few seconds at the default 5 cm, ~140 k points).
INFO_MAX_GRID_POINTS = 1_000_000


def cmd_info(args) -> int:
    """`cdpm info`: --grid and --plot checked before the report."""
    step = args.grid
    if not (step > 0 and np.isfinite(step)):
        raise CliError(f"--grid must be a step in m > 0, got {step!r}")
    if args.plot is not None:  # before the report: a folder found wanting after it is a waste
        check_writable_dir(args.plot, "--plot")
    if args.swaps is not None:
        _check_swaps_option(args.robot, args.swaps)
    info(robot=args.robot, swaps=args.swaps, plot_dir=args.plot, grid_step=args.grid)
    return 0


def _check_swaps_option(name, swaps) -> None:
    """--swaps is an option value: one that swaps nothing, undoes itself or names a cable the
    robot lacks is bad usage (exit 2), found before the report."""
    from cdpm_drake.config import ScenarioError
    from cdpm_drake.config.resolve import check_swaps
    from cdpm_drake.robot import RobotError

    try:
        check_swaps([list(s) for s in swaps])
        r = _info_target(name)[0]
        for i, j in swaps:
            r = r.with_swapped_attachments(i, j)
    except (ScenarioError, RobotError) as e:
        text = str(e).replace("swaps[", "--swaps[")
        raise CliError(text) from None


def calibration_lines(robot) -> list[str]:
    """What a calibrated robot file says of its calibration (its `calibration:` section)."""
    cal = robot.calibration
    after = max(cal["residual_after"], default=float("nan"))
    before = max(cal["residual_before"], default=float("nan"))
    lines = [f"calibrated by cdpm calibrate on {cal['created'] or '?'} from "
             f"{len(cal['calibrated_from'])} run(s), {cal['poses']} poses (the original: "
             f"{cal['original'] or '?'}); encoder noise taken as "
             f"{1000 * cal['encoder_std']:g} mm; misfit {1000 * before:.3f} -> "
             f"{1000 * after:.3f} mm RMS (largest cable)"]
    if robot.uncertainty is not None:
        lines.append(f"geometry uncertainty (1 sigma, as the margins use it): reel exits up "
                     f"to {1000 * robot.uncertainty.reels_std.max():.2f} mm, attachment "
                     f"points up to {1000 * robot.uncertainty.attachments_std.max():.2f} mm; "
                     f"the reel exits absolute: up to "
                     f"{1000 * max((max(r) for r in cal['reels_std']), default=0.0):.1f} mm")
    offsets = [f"{1000 * c:+.2f}" for c in cal["encoder_offsets"]]
    spread = max(cal["encoder_offsets_std"], default=0.0)
    lines.append(f"encoder offsets found (mm, cable 1..{len(offsets)}): {', '.join(offsets)} "
                 f"(+-{1000 * spread:.2f} mm); not identified by the data: "
                 f"{len(cal['not_identified'])} parameter(s)"
                 + (f" ({', '.join(cal['not_identified'][:3])}"
                    f"{', ...' if len(cal['not_identified']) > 3 else ''})"
                    if cal["not_identified"] else ""))
    if cal.get("measured_poses"):
        lines.append(f"base frame's turn from externally measured poses: "
                     f"{cal['measured_poses']}")
    return lines


def print_fastest_hand(r, p, out) -> None:
    """The fastest hand (N/s) the tension path follows at p along +-x, +-y, +-z, with the
    controller's default floors and ceiling (kernels/tension_path.py); nothing for fewer
    than 7 cables or a rank-deficient wrench matrix."""
    from cdpm_drake.config.scenario import Controller
    from cdpm_drake.kernels import tension_path
    from cdpm_drake.kernels.kinematics import cable_lengths
    from cdpm_drake.kernels.tension import gravity_wrench, wrench_matrix

    W = wrench_matrix(r, p)
    if r.num_cables < 7 or np.linalg.matrix_rank(W) < 6:
        return
    c, d = Controller(), r.dynamics
    lengths = cable_lengths(r, p)
    speed = tension_path.stretch_speed(r.limits.max_reel_speed, r.limits.max_velocity)
    cells = []
    for k, axis in enumerate("xyz"):
        for sign in (1.0, -1.0):
            rate = tension_path.fastest_hand(
                W, lengths, d.EA, lambda F: gravity_wrench(d.mass, F, d.handle),
                sign * np.eye(3)[k], floor=float(c.min_tension),
                hard_floor=float(c.tension_floor), ceiling=float(c.max_tension),
                speed=speed)
            cells.append(f"{'+' if sign > 0 else '-'}{axis} "
                         + ("any" if not np.isfinite(rate) else f"{rate:.0f}"))
    print(f"fastest hand the tension path follows at {format_vector(p)} m (N/s, hands up to "
          f"40 N, each cable's internal force rising at most EA/L x {speed:g} m/s; full pose "
          f"with tension control): " + ", ".join(cells), file=out)
