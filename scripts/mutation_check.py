"""Mutation check: does the test suite catch plausible one-line bugs?

Each mutant below is (name, file, exact original snippet, replacement, reason, test files most
likely to kill it). For each, the tree is copied to a temporary directory (never the working
tree: every worker owns its own copy, and a mutant is undone there in a `finally`), the
snippet is replaced, and `pytest -x -q` runs first on the mutant's own test files, then, if
they all pass, on the rest of the suite. A failing run means the mutant is KILLED; a green
suite means it SURVIVED. A mutant whose original snippet is not found exactly once is STALE:
the code moved and the list must be updated (a STALE mutant counts as a failure).

    python scripts/mutation_check.py            # all mutants, one worker
    python scripts/mutation_check.py --jobs 2   # two workers (two tree copies)
    python scripts/mutation_check.py --list     # the list, and which are stale
    python scripts/mutation_check.py --only admittance_mass_damping_swapped

Prints a table (mutant, result, where it was killed, seconds) and the score killed / total.
Exit code 0 when every mutant is killed, 1 otherwise. Refresh a stale mutant when its code
moves: keep the snippets short and on lines likely to stay.
"""

import argparse
import concurrent.futures
import dataclasses
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# What a copy of the tree needs to run the suite (the package, the robot files, the tests and
# the files tests read); not the virtual environment, git, caches or run outputs.
COPY = ("cdpm_drake", "hardware", "sweeps", "tests", "scripts", "docs", "diagrams",
        "README.md", "pyproject.toml")
IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", ".pytest_cache", "runs", "*.egg-info")
# One pytest run may not take longer than this (a mutant that hangs the suite is killed).
TIMEOUT = 900.0


@dataclasses.dataclass(frozen=True)
class Mutant:
    name: str
    file: str
    original: str
    replacement: str
    reason: str
    tests: tuple = ()


M = Mutant
MUTANTS = [
    # --- math: kinematics, interference, limits, operators, robot ---------------------------
    M("jacobian_sign", "cdpm_drake/kinematics.py",
      'out[k, i, 0], out[k, i, 1], out[k, i, 2] = x / n, y / n, z / n',
      'out[k, i, 0], out[k, i, 1], out[k, i, 2] = -x / n, -y / n, -z / n',
      "J's rows point from the platform to the reel instead of along rho",
      ("tests/test_kinematics.py", "tests/test_wiring_scenario.py")),
    M("near_uses_d_l", "cdpm_drake/interference.py",
      'near = dist <= par[j, 0]',
      'near = dist <= par[j, 0] - 0.011',
      "a pair is active only within d_u minus 11 mm (about d_l), not within d_u",
      ("tests/test_rules_in_callers.py", "tests/test_interference.py")),
    M("straddle_includes_ends", "cdpm_drake/interference.py",
      'straddle = min(s, t) > 0.0 and max(s, t) < 1.0',
      'straddle = min(s, t) >= 0.0 and max(s, t) <= 1.0',
      "lines that meet beyond a cable's end count as a crossing",
      ("tests/test_rules_in_callers.py", "tests/test_interference.py")),
    M("gradient_floor_ignored", "cdpm_drake/interference.py",
      'k = ts / max(abs(ts), floor)',
      'k = _sign(ts)',
      "the force keeps full intensity at the ridge (no fade within the floor)",
      ("tests/test_rules_in_callers.py", "tests/test_interference.py")),
    M("clip_at_largest_F_u", "cdpm_drake/interference.py",
      '    if fn > F_max:\n        k = F_max / fn',
      '    if fn > F_u:\n        k = F_u / fn',
      "|F_int| is clipped at the last pair's F_u, ignoring the configured F_max",
      ("tests/test_rules_in_callers.py", "tests/test_wiring_scenario.py")),
    M("logistic_exponent_sign", "cdpm_drake/interference.py",
      'return F_u / (1.0 + math.exp(min(b * (mid - d), 700.0)))',
      'return F_u / (1.0 + math.exp(min(b * (d - mid), 700.0)))',
      "eq. 26 with the sign of the exponent flipped: the force grows with distance",
      ("tests/test_interference.py",)),
    M("crossed_at_eps", "cdpm_drake/interference.py",
      '            if crossed:\n                intensity = F_u',
      '            if crossed:\n                intensity = 0.5 * F_u',
      "a crossed pair pushes back at eps instead of F_u",
      ("tests/test_rules_in_callers.py", "tests/test_interference.py")),
    M("cross_without_straddle", "cdpm_drake/interference.py",
      "return 2 * o if can_cross else line_side",
      "return 2 * o",
      "every flip of the line side counts as a crossing, even far away or beyond an end",
      ("tests/test_rules_in_callers.py", "tests/test_interference.py")),
    M("crossed_never_released", "cdpm_drake/interference.py",
      "return o if line_side == o else q",
      "return q",
      "a crossed pair stays crossed after it returns to its side",
      ("tests/test_interference.py", "tests/test_rules_in_callers.py")),
    M("acceleration_limit_per_second", "cdpm_drake/limits.py",
      "max_step = max_acceleration * time_step",
      "max_step = max_acceleration",
      "the per-tick velocity change is capped at a (m/s^2) instead of a T (m/s)",
      ("tests/test_limits.py",)),
    M("wall_gap_copy_paste", "cdpm_drake/limits.py",
      '_face_cap(p[0] - bounds[0, 0], a, T)',
      '_face_cap(bounds[1, 0] - p[0], a, T)',
      "the gap to the lower x face is measured to the upper face",
      ("tests/test_limits.py",)),
    M("wall_force_sign", "cdpm_drake/limits.py",
      'out[k] = max_force * (push_lo * push_lo - push_up * push_up)',
      'out[k] = max_force * (push_up * push_up - push_lo * push_lo)',
      "the wall force pulls towards the faces",
      ("tests/test_limits.py", "tests/test_wiring_scenario.py")),
    M("spring_hand_damping_sign", "cdpm_drake/operators.py",
      'fx = K * (out[0] - p[0]) - D * v[0]',
      'fx = K * (out[0] - p[0]) + D * v[0]',
      "the hand's damping pushes along the velocity",
      ("tests/test_operators.py",)),
    M("release_time_inverted", "cdpm_drake/operators.py",
      '    if t >= release:\n        out[0] = out[1] = out[2] = 0.0',
      '    if t <= release:\n        out[0] = out[1] = out[2] = 0.0',
      "the hand lets go before release_time instead of after it",
      ("tests/test_operators.py", "tests/test_wiring_scenario.py")),
    M("spring_stiffness_damping_swapped", "cdpm_drake/operators.py",
      "return SpringHand(config.waypoints, config.times, config.stiffness, config.damping,",
      "return SpringHand(config.waypoints, config.times, config.damping, config.stiffness,",
      "the scenario's stiffness and damping reach the hand in the wrong order",
      ("tests/test_wiring_scenario.py", "tests/test_operators.py")),
    M("robot_limits_swapped", "cdpm_drake/robot.py",
      "limits=Limits(lim.max_velocity, lim.max_acceleration, lim.max_reel_speed),",
      "limits=Limits(lim.max_acceleration, lim.max_velocity, lim.max_reel_speed),",
      "a robot file's speed and acceleration limits land in each other's place",
      ("tests/test_wiring_scenario.py", "tests/test_robot.py")),
    M("robot_ignore_pairs_dropped", "cdpm_drake/robot.py",
      "ignore_pairs=tuple(tuple(p) for p in schema.ignore_pairs),",
      "ignore_pairs=(),",
      "a robot file's ignore_pairs never reach the robot",
      ("tests/test_wiring_scenario.py", "tests/test_robot.py")),
    M("swap_off_by_one", "cdpm_drake/robot.py",
      "b[[i - 1, j - 1]] = b[[j - 1, i - 1]]",
      "b[[i, j]] = b[[j, i]]",
      "1-based cable numbers used as 0-based indices in a swap",
      ("tests/test_robot.py", "tests/test_wiring_scenario.py")),
    M("workspace_allows_flat_box", "cdpm_drake/robot.py",
      "if not lo[axis] < hi[axis]:",
      "if not lo[axis] <= hi[axis]:",
      "a workspace box of zero width is accepted",
      ("tests/test_robot.py",)),
    # --- the builder: scenario.py, diagram.py, simulation.py ---------------------------------
    M("admittance_mass_damping_swapped", "cdpm_drake/diagram.py",
      "scenario.admittance.mass, scenario.admittance.damping, T))",
      "scenario.admittance.damping, scenario.admittance.mass, T))",
      "the builder passes M and C in the wrong order",
      ("tests/test_wiring_scenario.py", "tests/test_diagram.py")),
    M("scenario_max_velocity_ignored", "cdpm_drake/scenario.py",
      'max_velocity=float(_or(limits.max_velocity, robot.limits.max_velocity)),',
      'max_velocity=float(robot.limits.max_velocity),',
      "the scenario's speed limit never overrides the robot file's",
      ("tests/test_wiring_scenario.py", "tests/test_diagram.py")),
    M("virtual_wall_always_on", "cdpm_drake/diagram.py",
      'virtual_wall=scenario.limits.virtual_wall, time_step=T))',
      'virtual_wall=True, time_step=T))',
      "limits.virtual_wall: false is ignored",
      ("tests/test_wiring_scenario.py",)),
    M("wall_force_gets_margin", "cdpm_drake/diagram.py",
      "max_force=wall.max_force))",
      "max_force=wall.margin))",
      "the wall block's force is set from the margin",
      ("tests/test_wiring_scenario.py",)),
    M("sensor_ranges_swapped", "cdpm_drake/diagram.py",
      "transverse_range=sensor_cfg.transverse_range, window=sensor_cfg.filter_window,",
      "transverse_range=sensor_cfg.axial_range, window=sensor_cfg.filter_window,",
      "the transverse sensing range is set from the axial one",
      ("tests/test_wiring_scenario.py",)),
    M("noise_seed_ignored", "cdpm_drake/systems/simulated_reels.py",
      "std=scenario.sensor.noise_std, seed=scenario.random_seed, time_step=time_step))",
      "std=scenario.sensor.noise_std, seed=0, time_step=time_step))",
      "random_seed never reaches the sensor noise",
      ("tests/test_wiring_scenario.py",)),
    M("plant_reel_speed_ignored", "cdpm_drake/scenario.py",
      'max_reel_speed=float(_or(getattr(plant, "max_reel_speed", None),',
      'max_reel_speed=float(_or(None,',
      "plant.max_reel_speed never reaches the simulated reels",
      ("tests/test_wiring_scenario.py",)),
    M("pair_override_on_previous_pair", "cdpm_drake/scenario.py",
      "arrays[key][k] = float(value)",
      "arrays[key][k - 1] = float(value)",
      "a per-pair interference override lands on the pair before it",
      ("tests/test_wiring_scenario.py", "tests/test_scenario.py")),
    M("gradient_floor_not_passed", "cdpm_drake/scenario.py",
      'extra = {} if cfg.gradient_floor is None else {"gradient_floor": cfg.gradient_floor}',
      "extra = {}",
      "interference.gradient_floor is checked but never reaches the block",
      ("tests/test_wiring_scenario.py", "tests/test_rules_in_callers.py")),
    M("F_max_ignored", "cdpm_drake/scenario.py",
      "F_max = float(cfg.F_max) if cfg.F_max is not None else (",
      "F_max = (",
      "interference.F_max never reaches the clip",
      ("tests/test_wiring_scenario.py",)),
    M("damping_checked_as_mass", "cdpm_drake/scenario.py",
      '_positive(scenario.admittance.damping, "admittance.damping")',
      '_positive(scenario.admittance.mass, "admittance.damping")',
      "a damping of 0 or below is not refused",
      ("tests/test_scenario.py", "tests/test_wiring_scenario.py")),
    M("swap_second_cable_lost", "cdpm_drake/scenario.py",
      "robot = robot.with_swapped_attachments(int(swap[0]), int(swap[1]))",
      "robot = robot.with_swapped_attachments(int(swap[0]), int(swap[0]))",
      "a scenario's swap never moves the second cable",
      ("tests/test_wiring_scenario.py", "tests/test_scenario.py")),
    M("simulate_duration_argument_ignored", "cdpm_drake/simulation.py",
      "for target in tick_targets(duration, scenario.time_step, chunk):",
      "for target in tick_targets(scenario.duration, scenario.time_step, chunk):",
      "simulate(duration=...) runs the scenario's duration",
      ("tests/test_wiring_cli.py", "tests/test_wiring_scenario.py")),
    # --- the blocks: systems/, hardware/reels.py --------------------------------------------
    M("filter_window_off_by_one", "cdpm_drake/systems/force_sensor.py",
      'C = np.tile(np.eye(3), W - 1) / W',
      'C = np.tile(np.eye(3), W - 1) / (W - 1)',
      "the sliding average divides by one sample less than it sums",
      ("tests/test_systems.py", "tests/test_wiring_scenario.py")),
    M("axial_clip_uses_transverse", "cdpm_drake/sensor.py",
      'axial = min(max(axial, -axial_range), axial_range)',
      'axial = min(max(axial, -transverse_range), transverse_range)',
      "the axial component saturates at the transverse range",
      ("tests/test_systems.py", "tests/test_wiring_scenario.py")),
    M("reel_lag_inverted", "cdpm_drake/systems/simulated_reels.py",
      "lag = 1.0 - np.exp(-self._T / time_constant) if time_constant > 0 else 1.0",
      "lag = 1.0 - np.exp(-time_constant / self._T) if time_constant > 0 else 1.0",
      "the first-order lag uses tau / T instead of T / tau",
      ("tests/test_systems.py", "tests/test_wiring_scenario.py")),
    M("reel_speed_clipped_per_reel", "cdpm_drake/kinematics.py",
      'c = command[i] * scale if peak > max_reel_speed else command[i]',
      'c = min(max(command[i], -max_reel_speed), max_reel_speed)',
      "each reel clips its own command, which steers the platform",
      ("tests/test_systems.py", "tests/test_wiring_scenario.py")),
    M("hardware_no_ramp", "cdpm_drake/hardware/reels.py",
      "v = book[RAMP] * u",
      "v = u",
      "the reels get full velocity the tick they are enabled",
      ("tests/test_hardware_reels.py",)),
    M("watchdog_one_tick_late", "cdpm_drake/hardware/reels.py",
      "elif (status is None and book[MISSED] >= self._config.watchdog_ticks",
      "elif (status is None and book[MISSED] > self._config.watchdog_ticks",
      "the watchdog waits one tick more than watchdog_ticks",
      ("tests/test_wiring_scenario.py", "tests/test_hardware_reels.py")),
    M("hold_resumes_on_a_stale_answer", "cdpm_drake/hardware/reels.py",
      "sequence_delta(status.echo_sequence, int(book[HOLD_SEQUENCE])) >= 0",
      "sequence_delta(status.echo_sequence, int(book[HOLD_SEQUENCE])) >= -1",
      "the watchdog resumes on a status echoing the command before the stop",
      ("tests/test_hardware_reels.py",)),
    M("hold_ignores_lost_statuses", "cdpm_drake/hardware/reels.py",
      "elif link.counters.lost != book[HOLD_LOST]:",
      "elif link.counters.lost < book[HOLD_LOST]:",
      "statuses lost during the silence do not end the run (a lossy link resumes)",
      ("tests/test_hardware_reels.py",)),
    M("hold_wait_in_ms", "cdpm_drake/hardware/reels.py",
      "if now - book[HOLD_WALL] > self._config.resume_within:",
      "if now - book[HOLD_WALL] > self._config.resume_within * 1e3:",
      "resume_within read as ms: a silent bridge is waited for 1000 times too long",
      ("tests/test_hardware_reels.py", "tests/test_wiring_scenario.py")),
    M("hold_without_stop", "cdpm_drake/hardware/reels.py",
      "self.shutdown()  # the stop commands: sequences HOLD_SEQUENCE onwards",
      "pass",
      "the watchdog holds without sending the stop: the reels keep the last velocity",
      ("tests/test_hardware_reels.py",)),
    M("hold_keeps_sending", "cdpm_drake/hardware/reels.py",
      "return  # the stop went out; nothing more until the bridge answers it",
      "pass",
      "the reels send commands while the watchdog holds (more than one stop burst)",
      ("tests/test_hardware_reels.py",)),
    # --- the CLI -----------------------------------------------------------------------------
    M("simulate_out_ignored", "cdpm_drake/cli.py",
      "code = simulate_main(scenario=scenario, duration=args.duration, out_dir=args.out,",
      "code = simulate_main(scenario=scenario, duration=args.duration, out_dir=None,",
      "cdpm simulate --out writes to runs/<name> anyway",
      ("tests/test_wiring_cli.py",)),
    M("run_duration_dropped", "cdpm_drake/cli.py",
      "return run_main(scenario=scenario, duration=args.duration, out_dir=args.out,",
      "return run_main(scenario=scenario, duration=None, out_dir=args.out,",
      "cdpm run --duration is parsed but the scenario's duration runs",
      ("tests/test_wiring_cli.py",)),
    M("simulate_realtime_dropped", "cdpm_drake/cli.py",
      "html=args.html, plots=args.plot, realtime_rate=realtime,",
      "html=args.html, plots=args.plot, realtime_rate=None,",
      "cdpm simulate --realtime does not pace the run",
      ("tests/test_wiring_cli.py",)),
    M("diagram_depth_dropped", "cdpm_drake/cli.py",
      "return diagram_main(scenario=_load_scenario_arg(args).scenario, out_dir=args.out, depth=args.depth,",
      "return diagram_main(scenario=_load_scenario_arg(args).scenario, out_dir=args.out, depth=1,",
      "cdpm diagram --depth is ignored",
      ("tests/test_wiring_cli.py",)),
    M("info_robot_ignored", "cdpm_drake/cli.py",
      "        return load_robot(text), None\n    raise RobotError(",
      '        return load_robot("paper_7cable"), None\n    raise RobotError(',
      "cdpm info describes the default robot whatever it is given",
      ("tests/test_wiring_cli.py", "tests/test_cli.py")),
    M("plot_dir_writes_to_parent", "cdpm_drake/cli.py",
      "out_dir = args.out if args.out is not None else (\n        target if target.is_dir() "
      "else target.parent)",
      "out_dir = args.out if args.out is not None else (\n        target.parent)",
      "cdpm plot DIR writes its figures beside DIR instead of into it",
      ("tests/test_wiring_cli.py",)),
    M("emulator_time_constant_dropped", "cdpm_drake/emulator.py",
      "if args.time_constant is None else args.time_constant)",
      "if args.time_constant is None else 0.02)",
      "cdpm emulate --time-constant is ignored",
      ("tests/test_wiring_cli.py",)),
    # --- second batch: the same kinds, written after the tests above -------------------------
    M("speed_cap_per_axis", "cdpm_drake/limits.py",
      '        k = max_velocity / speed\n        vx, vy, vz = vx * k, vy * k, vz * k',
      '        vx, vy, vz = (min(max(vx, -max_velocity), max_velocity), '
      'min(max(vy, -max_velocity), max_velocity), min(max(vz, -max_velocity), max_velocity))',
      "the speed limit clips each axis instead of the norm (diagonal motion runs faster)",
      ("tests/test_limits.py", "tests/test_wiring_scenario.py")),
    M("wall_force_linear", "cdpm_drake/limits.py",
      'out[k] = max_force * (push_lo * push_lo - push_up * push_up)',
      'out[k] = max_force * (push_lo - push_up * push_up)',
      "the wall force rises linearly from the lower faces (not C1 at the margin)",
      ("tests/test_wiring_scenario.py", "tests/test_limits.py")),
    M("hand_cap_per_axis", "cdpm_drake/operators.py",
      '    if n > F_max:\n        k = F_max / n\n        fx, fy, fz = fx * k, fy * k, fz * k',
      '    if n > F_max:\n        fx, fy, fz = (min(max(fx, -F_max), F_max), '
      'min(max(fy, -F_max), F_max), min(max(fz, -F_max), F_max))',
      "the hand's force cap clips each axis instead of the norm",
      ("tests/test_wiring_scenario.py", "tests/test_operators.py")),
    M("scripted_force_x_only", "cdpm_drake/operators.py",
      'out[k] = (rows[j + 1, k] - rows[j, k]) / dt * (t - times[j]) + rows[j, k]',
      'out[k] = (rows[j + 1, 0] - rows[j, 0]) / dt * (t - times[j]) + rows[j, 0]',
      "every axis of a scripted force replays the x column",
      ("tests/test_wiring_scenario.py", "tests/test_operators.py")),
    M("overlay_resets_the_file", "cdpm_drake/scenario.py",
      "scenario = yaml_load_typed(schema=Scenario, data=overlay_text, defaults=scenario)",
      "scenario = yaml_load_typed(schema=Scenario, data=overlay_text, defaults=Scenario())",
      "--scenario-text starts from the defaults instead of the scenario file",
      ("tests/test_scenario.py", "tests/test_wiring_cli.py")),
    M("F_max_default_smallest_F_u", "cdpm_drake/scenario.py",
      'else (float(arrays["F_u"].max()) if P else 0.0)',
      'else (float(arrays["F_u"].min()) if P else 0.0)',
      "the default clip is the smallest F_u instead of the largest",
      ("tests/test_wiring_scenario.py",)),
    M("scenario_max_acceleration_ignored", "cdpm_drake/scenario.py",
      'max_acceleration=float(_or(limits.max_acceleration, robot.limits.max_acceleration)),',
      'max_acceleration=float(robot.limits.max_acceleration),',
      "the scenario's acceleration limit never overrides the robot file's",
      ("tests/test_wiring_scenario.py",)),
    M("sensor_axis_fixed", "cdpm_drake/diagram.py",
      "axial_axis=sensor_cfg.axial_axis, axial_range=sensor_cfg.axial_range,",
      "axial_axis=[0.0, 0.0, 1.0], axial_range=sensor_cfg.axial_range,",
      "sensor.axial_axis never reaches the sensor",
      ("tests/test_wiring_scenario.py",)),
    M("sensor_axis_not_normalised", "cdpm_drake/systems/force_sensor.py",
      "self._axis = owned(axis / np.linalg.norm(axis))",
      "self._axis = owned(axis)",
      "a handle axis that is not a unit vector scales the axial force",
      ("tests/test_wiring_scenario.py", "tests/test_systems.py")),
    M("hardware_reel_speed_unlimited", "cdpm_drake/hardware/reels.py",
      "self._vmax = float(robot.limits.max_reel_speed)",
      "self._vmax = float('inf')",
      "the real reels get commands above their speed limit",
      ("tests/test_wiring_scenario.py", "tests/test_hardware_reels.py")),
    M("gc_left_on_in_the_loop", "cdpm_drake/realtime.py",
      "    was_enabled = gc.isenabled()\n    gc.disable()",
      "    was_enabled = gc.isenabled()\n    gc.enable()",
      "the automatic garbage collector runs inside the ticks of a real-time run",
      ("tests/test_realtime_run.py",)),
    M("gc_never_between_steps", "cdpm_drake/realtime.py",
      "                collect()\n",
      "",
      "the loop never collects: cyclic garbage piles up for the whole run",
      ("tests/test_realtime_run.py",)),
    M("status_printed_in_the_loop", "cdpm_drake/realtime.py",
      "pump.put(_status_line(diagram, context, reels, t))",
      "status(_status_line(diagram, context, reels, t))",
      "the status line is printed by the control loop: a blocked terminal stops the ticks",
      ("tests/test_realtime_run.py",)),
    M("tick_log_header_in_the_loop", "cdpm_drake/hardware/tick_log.py",
      "self._full.put(MAGIC + _LEN.pack(len(header)) + header)",
      "self._write_all(MAGIC + _LEN.pack(len(header)) + header)",
      "the tick log's header is written by the thread that appends (the control loop)",
      ("tests/test_realtime_run.py", "tests/test_tick_log.py")),
    M("tick_log_pool_not_mapped", "cdpm_drake/hardware/tick_log.py",
      "memory.view(np.uint8).fill(0)",
      "memory.view(np.uint8)",
      "the tick log's pool is left unwritten: its pages are mapped by the ticks' first writes",
      ("tests/test_tick_log.py",)),
    M("run_duration_ignored", "cdpm_drake/realtime.py",
      "for target in tick_targets(duration, T, step):",
      "for target in tick_targets(scenario.duration, T, step):",
      "run(duration=...) runs the scenario's duration on the robot",
      ("tests/test_wiring_cli.py", "tests/test_realtime_run.py")),
    M("run_force_always", "cdpm_drake/run_folder.py",
      "if not self.force:",
      "if False:",
      "an --out holding an earlier run is emptied without --force",
      ("tests/test_wiring_cli.py",)),
    M("live_view_chunk_fixed", "cdpm_drake/cli.py",
      "chunk=0.04 if args.meshcat else 0.5, force=args.force)",
      "chunk=0.5, force=args.force)",
      "the live view is drawn every 0.5 s of simulated time",
      ("tests/test_wiring_cli.py",)),
    M("run_meshcat_dropped", "cdpm_drake/cli.py",
      "on_view = _live_meshcat(scenario) if args.meshcat else None",
      "on_view = None",
      "cdpm run --meshcat shows nothing",
      ("tests/test_wiring_cli.py",)),
    M("emulator_length_offset_off_by_one", "cdpm_drake/emulator.py",
      "lengths[k - 1] += float(metres)",
      "lengths[k % len(lengths)] += float(metres)",
      "--length-offset CABLE uses the 1-based cable number as an index",
      ("tests/test_wiring_cli.py", "tests/test_emulator.py")),
    M("logistic_grid_below_zero", "cdpm_drake/views/plots.py",
      "return np.linspace(max(0.0, d_l - w), d_u + w, num)",
      "return np.linspace(d_l - w, d_u + w, num)",
      "Fig. 8 is drawn over negative distances",
      ("tests/test_wiring_cli.py", "tests/test_plots.py")),
    M("noise_same_every_tick", "cdpm_drake/systems/simulated_reels.py",
      "rng = np.random.default_rng([self._seed, k])",
      "rng = np.random.default_rng(self._seed)",
      "the sensor noise is one constant offset instead of a new sample every tick",
      ("tests/test_wiring_scenario.py", "tests/test_diagram.py")),
    M("braking_curve_continuous", "cdpm_drake/limits.py",
      'return max(min(math.sqrt(2.0 * a * gap) - 0.5 * a * T, gap / T), 0.0)',
      'return max(min(math.sqrt(2.0 * a * gap), gap / T), 0.0)',
      "the braking cap at the faces is the continuous curve, not the discrete one",
      ("tests/test_limits.py",)),
    M("hand_force_a_tick_early", "cdpm_drake/systems/simulated_reels.py",
      "t_next = context.get_time() + T",
      "t_next = context.get_time()",
      "the world's kernel samples the person at this tick, not at the next one",
      ("tests/test_reference_logs.py", "tests/test_systems.py")),
    M("spring_release_ignored", "cdpm_drake/operators.py",
      "_spring_force_into(times, rows, params[0], params[1], params[2], params[3], t, p, v,",
      "_spring_force_into(times, rows, params[0], params[1], params[2], math.inf, t, p, v,",
      "the compiled spring hand never lets go",
      ("tests/test_fast_calls.py",)),
    M("fused_wiring_off_by_one", "cdpm_drake/systems/_wiring.py",
      "out += [(key, offset + j) for j in range(int(count))]",
      "out += [(key, offset + j + (count > 3)) for j in range(int(count - (count > 3)))]",
      "the fused wiring drops the first element of every piece longer than 3",
      ("tests/test_fast_calls.py",)),
    M("fused_memory_starts_at_zero", "cdpm_drake/systems/_wiring.py",
      "start = np.concatenate([spec[1] for spec in delays.values()])",
      "start = np.zeros(sum(spec[1].size for spec in delays.values()))",
      "the fused memory forgets the FK warm start's initial position",
      ("tests/test_fast_calls.py",)),
    M("no_anti_windup", "cdpm_drake/diagram.py",
      'admittance.connect_input(limits.GetOutputPort("velocity_command"), "velocity_command")',
      'admittance.connect_input(admittance.GetOutputPort("velocity"), "velocity_command")',
      "the admittance integrates from its own velocity, not the limited command (windup)",
      ("tests/test_diagram.py", "tests/test_wiring_scenario.py")),
    M("wall_force_not_in_F_d", "cdpm_drake/diagram.py",
      'forces.append(wall_system.GetOutputPort("F_wall"))',
      "pass",
      "the wall force is computed and logged but never added to F_d",
      ("tests/test_wiring_scenario.py",)),
    M("ramp_jumps_to_full", "cdpm_drake/hardware/reels.py",
      "book[RAMP] = min(1.0, book[RAMP] + self._ramp_step)",
      "book[RAMP] = 1.0",
      "the reels are enabled at full velocity (no ramp)",
      ("tests/test_wiring_scenario.py", "tests/test_hardware_reels.py")),
    M("force_table_allows_equal_times", "cdpm_drake/operators.py",
      "if np.any(np.diff(t) <= 0):",
      "if np.any(np.diff(t) < 0):",
      "a force table with two equal times is accepted (a jump with no defined value)",
      ("tests/test_operators.py",)),
    M("emulator_ignores_scenario_port", "cdpm_drake/emulator.py",
      'port = getattr(scenario.plant, "port", port)',
      "port = port",
      "cdpm emulate --scenario listens on the default port, not the scenario's",
      ("tests/test_wiring_cli.py",)),
    M("run_yaml_keeps_scenario_duration", "cdpm_drake/realtime.py",
      "write_run_scenario(out, resolved, duration=duration)",
      "write_run_scenario(out, resolved)",
      "a run's scenario.yaml records the scenario's duration, not the one that ran",
      ("tests/test_wiring_cli.py", "tests/test_realtime_run.py")),
    M("logged_velocity_is_the_admittance", "cdpm_drake/diagram.py",
      '("velocity", "safety_limits", "velocity_command"),',
      '("velocity", "admittance", "velocity"),',
      "the log's velocity column shows the admittance output, not the limited command",
      ("tests/test_wiring_scenario.py", "tests/test_diagram.py")),
    M("reels_start_at_the_centre", "cdpm_drake/diagram.py",
      'builder, robot, resolved.operator, initial_position=scenario.initial_position,',
      'builder, robot, resolved.operator, initial_position=robot.workspace.center,',
      "the simulated reels start at the workspace centre, not initial_position",
      ("tests/test_wiring_scenario.py",)),
    # --- the dynamic plant ------------------------------------------------------------------
    M("dynamic_EA_ignored", "cdpm_drake/cables.py",
      "return np.array([d.EA, d.damping, time_step, d.bandwidth, d.reel_inertia,",
      "return np.array([70000.0, d.damping, time_step, d.bandwidth, d.reel_inertia,",
      "the cables' elastic law keeps the default EA whatever the robot file says",
      ("tests/test_wiring_scenario.py", "tests/test_dynamic_plant.py")),
    M("dynamic_handle_ignored", "cdpm_drake/systems/dynamic_plant.py",
      "handle = owned(d.handle)",
      "handle = owned(np.array([0.0, 0.0, -0.15]))",
      "the hand force acts at the default handle point, not the robot file's",
      ("tests/test_wiring_scenario.py", "tests/test_dynamic_plant.py")),
    M("reel_coulomb_sign", "cdpm_drake/cables.py",
      "return free - np.sign(free) * grip",
      "return free + np.sign(free) * grip",
      "Coulomb friction drives a moving reel along instead of opposing it",
      ("tests/test_wiring_scenario.py", "tests/test_dynamic_plant.py")),
    # --- statics: tension.py -----------------------------------------------------------------
    M("t_star_pair_weights_swapped", "cdpm_drake/tension.py",
      "v = (T_p[i] * (-n[j]) + T_p[j] * n[i]) / (n[i] - n[j])",
      "v = (T_p[i] * n[i] + T_p[j] * (-n[j])) / (n[i] - n[j])",
      "the dual vertex weighs each cable's tension by its own slope, not the other's",
      ("tests/test_tension.py",)),
    M("t_star_rank_check_skipped", "cdpm_drake/tension.py",
      "if _pivoted_qr(W, A, V, beta, perm) < RANK_TOL:\n        return GENERAL, math.nan",
      "if _pivoted_qr(W, A, V, beta, perm) < 0.0:\n        return GENERAL, math.nan",
      "a rank-deficient wrench matrix goes through the one-dimensional closed form",
      ("tests/test_tension.py",)),
    M("t_star_wrench_sign", "cdpm_drake/tension.py",
      "s = -w[perm[j]]",
      "s = w[perm[j]]",
      "the tensions balance the wrench's opposite (W T = w instead of W T + w = 0)",
      ("tests/test_tension.py",)),
    M("t_star_2d_triangle_open", "cdpm_drake/tension.py",
      "if mi >= 0.0 and mj >= 0.0 and mk >= 0.0:",
      "if mi >= 0.0 and mj >= 0.0:",
      "8 cables: a cable triple counts as a dual vertex with one negative weight",
      ("tests/test_tension.py",)),
    M("least_norm_not_least", "cdpm_drake/tension.py",
      "lam = lam_star if lo > hi else min(max(0.0, lo), hi)",
      "lam = lam_star if lo > hi else lo",
      "a feasible distribution puts a cable on the floor instead of taking the least norm",
      ("tests/test_tension.py",)),
    M("grid_moment_sign", "cdpm_drake/tension.py",
      "W[3, i], W[4, i], W[5, i] = by * z - bz * y, bz * x - bx * z, bx * y - by * x",
      "W[3, i], W[4, i], W[5, i] = by * z - bz * y, bx * z - bz * x, bx * y - by * x",
      "the grid's wrench matrix takes one moment component with the wrong sign",
      ("tests/test_tension.py",)),
    M("clarabel_loose", "cdpm_drake/tension.py",
      "options.SetOption(ClarabelSolver.id(), name, 1e-10)",
      "options.SetOption(ClarabelSolver.id(), name, 1e-4)",
      "Clarabel stops early: t* of a 2-D nullspace is off by more than 1e-6 N",
      ("tests/test_tension.py",)),
    M("feasibility_best_direction", "cdpm_drake/tension.py",
      "t = max_min_tensions(robot, pts, wrenches).min(axis=1)",
      "t = max_min_tensions(robot, pts, wrenches).max(axis=1)",
      "a grid point counts as held when one hand-force direction is held, not all",
      ("tests/test_tension.py",)),
    M("length_correction_unbounded", "cdpm_drake/kinematics.py",
      "return 1.0 if largest <= MAX_CORRECTION else MAX_CORRECTION / largest",
      "return 1.0",
      "a stall's piled-up length error comes back at K_l e, however large",
      ("tests/test_length_loop.py",)),
    M("length_correction_clipped_per_cable", "cdpm_drake/kinematics.py",
      "        out[i] = base[i] + scale * out[i]",
      "        out[i] = base[i] + min(MAX_CORRECTION, max(-MAX_CORRECTION, out[i]))",
      "each cable's correction clipped alone: the corrections lose the error's direction",
      ("tests/test_length_loop.py",)),
    M("bridge_stop_drops_waiting_commands", "cdpm_drake/emulator.py",
      "                self._drain(now)\n        self._sock.close()",
      "                pass\n        self._sock.close()",
      "commands that arrived after the bridge's last tick (a shutdown burst) are lost",
      ("tests/test_emulator.py",)),
    M("numba_cache_keyed_by_one_file", "cdpm_drake/__init__.py",
      'if b"numba.njit" in source:  # kernels, and the constants they compile in',
      'if path.name == "kinematics.py":',
      "the compiled kernels' cache ignores edits of the files their callees live in",
      ("tests/test_numba_cache.py",)),
    M("statics_warning_inverted", "cdpm_drake/robot.py",
      "if statics.share < STATICS_WARN_SHARE:",
      "if statics.share > STATICS_WARN_SHARE:",
      "robots that hold their platform get the warning, the ones that cannot do not",
      ("tests/test_robot_statics.py",)),
    M("statics_cache_ignores_mass", "cdpm_drake/robot.py",
      "robot.workspace.upper.tobytes(), robot.dynamics.mass, robot.name)",
      "robot.workspace.upper.tobytes(), robot.name)",
      "a robot file's platform mass does not reach the statics of a robot already seen",
      ("tests/test_robot_statics.py",)),
    M("statics_rank_always_full", "cdpm_drake/tension.py",
      "rank = int(np.sum(s > RANK_TOL * max(s[0], 1e-300)))",
      "rank = W.shape[0]",
      "a rank-deficient wrench matrix is reported as full rank",
      ("tests/test_robot_statics.py",)),
    M("info_share_without_floor", "cdpm_drake/cli.py",
      "share = float(np.mean(holding_tension(r, grid) >= INFO_FLOOR))",
      "share = float(np.mean(holding_tension(r, grid) >= 0.0))",
      "cdpm info counts the box held at any positive tension, not at the floor",
      ("tests/test_info_statics.py",)),
    M("info_scenario_swaps_ignored", "cdpm_drake/cli.py",
      "            scenario.swaps = [list(s) for s in swaps]",
      "            pass",
      "cdpm info SCENARIO --swaps keeps the scenario's own swaps",
      ("tests/test_info_statics.py",)),
    M("workspace_slice_at_path_mean", "cdpm_drake/views/workspace_plots.py",
      "return np.clip(0.5 * (p.min(axis=0) + p.max(axis=0)), robot.workspace.lower,",
      "return np.clip(p.mean(axis=0), robot.workspace.lower,",
      "the slices pass through the path's mean, not the middle of its extent",
      ("tests/test_info_statics.py",)),
    M("workspace_margin_sign", "cdpm_drake/views/workspace_plots.py",
      "out.append((fixed, drawn, u, v, d.min(axis=-1), (d - d_u).min(axis=-1),",
      "out.append((fixed, drawn, u, v, d.min(axis=-1), (d_u - d).min(axis=-1),",
      "the interference picture colours d_u - d: green where the cables are within d_u",
      ("tests/test_info_statics.py",)),
    M("stretch_rate_adds_reel_speed", "cdpm_drake/cables.py",
      "T = _tension(L, L_dot - x[iw + i], x[iL0 + i], EA, damping)",
      "T = _tension(L, L_dot + x[iw + i], x[iL0 + i], EA, damping)",
      "the cable damping sees the reel paying out as stretching, not as slackening",
      ("tests/test_dynamic_plant.py", "tests/test_reference_logs.py")),
    M("hand_moment_sign", "cdpm_drake/cables.py",
      "out[o] = nx_ + (hy * Fz - hz * Fy)",
      "out[o] = nx_ - (hy * Fz - hz * Fy)",
      "the hand's moment about x has the wrong sign",
      ("tests/test_wiring_scenario.py", "tests/test_dynamic_plant_integration.py")),
    M("slack_never_flagged", "cdpm_drake/cables.py",
      "out[o_slack + i] = 1.0 if T <= 0.0 else 0.0",
      "out[o_slack + i] = 1.0 if T < 0.0 else 0.0",
      "a slack cable (tension exactly 0) is never flagged slack",
      ("tests/test_dynamic_plant.py", "tests/test_reference_logs.py")),
    M("reel_limit_ignored", "cdpm_drake/cables.py",
      "scale = params[7] / peak if peak > params[7] else 1.0",
      "scale = 1.0",
      "the dynamic plant's drives follow commands above the reel speed limit",
      ("tests/test_wiring_scenario.py",)),
    M("person_a_plant_step_late", "cdpm_drake/systems/dynamic_plant.py",
      "force_at(kind, times, rows, params_op, context.get_time(), x, ip, iv, out, io)",
      "force_at(kind, times, rows, params_op, context.get_time() - 0.001, x, ip, iv, out, io)",
      "the person's force lags the plant's clock by one plant step",
      ("tests/test_reference_logs.py",)),
    M("plant_ports_sampled", "cdpm_drake/systems/dynamic_plant.py",
      "    mbp.SetUseSampledOutputPorts(False)\n",
      "",
      "the MultibodyPlant steps before the controller's update: the sensor measures the hand "
      "on a platform one plant step ahead of the logged F_d",
      ("tests/test_dynamic_plant.py", "tests/test_reference_logs.py")),
    M("encoders_at_the_plant_rate", "cdpm_drake/systems/dynamic_plant.py",
      'encoders = builder.AddNamedSystem("encoders", unit_delay(m, T, L0))',
      'encoders = builder.AddNamedSystem("encoders", unit_delay(m, h, L0))',
      "the encoders are sampled at every plant step, not once per control tick",
      ("tests/test_reference_logs.py",)),
    M("emulator_encoders_not_homed", "cdpm_drake/emulator.py",
      "self.encoder_offset = rigid - L0",
      "self.encoder_offset = np.zeros(m)",
      "the dynamic emulator's encoders read the unstretched lengths, not zeroed at the start",
      ("tests/test_emulator.py", "tests/test_wiring_cli.py")),
    M("emulator_plant_runs_before_enable", "cdpm_drake/emulator.py",
      "        if self.operator_start is None:\n            return\n        # Whole steps",
      "        if self.operator_start is None:\n            self.operator_start = 0.0\n"
      "        # Whole steps",
      "the dynamic emulator's plant and operator start with the emulator, not the first enable",
      ("tests/test_emulator.py",)),
    M("dynamic_bridge_counts_taut_as_slack", "cdpm_drake/emulator.py",
      "self.slack_ticks += step[self._slack] > 0.5",
      "self.slack_ticks += step[self._slack] < 0.5",
      "the dynamic emulator's summary counts the taut cables' ticks as slack",
      ("tests/test_emulator.py",)),
    M("overview_never_collapses_ports", "cdpm_drake/views/diagram_graph.py",
      "    if used is not None and len(names) > MAX_PORTS:",
      "    if used is not None and len(names) > 10 * MAX_PORTS:",
      "the overview draws every port of a MultibodyPlant: 2773 pt wide again",
      ("tests/test_diagram_files.py",)),
    # --- the cable-length loop and the dynamic plant's truth -----------------------------------
    M("length_loop_sign", "cdpm_drake/kinematics.py",
      "out[i] = gain * error + dead_band_compensation(dead_band, error)",
      "out[i] = -gain * error + dead_band_compensation(dead_band, error)",
      "the length loop pushes the error further instead of closing it",
      ("tests/test_length_loop.py",)),
    M("length_loop_no_latch", "cdpm_drake/kinematics.py",
      "delta = x[9 + m + i] if started else x[6 + i] - rigid",
      "delta = x[9 + m + i] if started else 0.0",
      "the first tick does not latch the measured lengths: the loop pulls the encoders' "
      "offsets (the start's stretch) out of the cables",
      ("tests/test_length_loop.py",)),
    M("length_loop_step_without_dt", "cdpm_drake/kinematics.py",
      "target[i] = rigid + time_step * feedforward",
      "target[i] = rigid + feedforward",
      "the commanded position advances by J v per tick instead of J v T",
      ("tests/test_length_loop.py", "tests/test_reference_logs.py")),
    M("length_gain_not_wired", "cdpm_drake/diagram.py",
      "lambda b: build_jacobian_mapping(b, robot, length_gain=controller.length_gain,",
      "lambda b: build_jacobian_mapping(b, robot, length_gain=20.0,",
      "the scenario's controller.length_gain never reaches the Jacobian block",
      ("tests/test_wiring_scenario.py", "tests/test_length_loop.py")),
    M("dead_band_compensation_sign", "cdpm_drake/kinematics.py",
      "return FRICTION_SHARE * dead_band * math.tanh(error / FRICTION_ERROR)",
      "return -FRICTION_SHARE * dead_band * math.tanh(error / FRICTION_ERROR)",
      "the length loop pushes the drives' dead band the wrong way, widening it",
      ("tests/test_length_loop.py", "tests/test_wiring_scenario.py")),
    M("dead_band_on_kinematic_plant", "cdpm_drake/scenario.py",
      "and float(scenario.controller.length_gain) > 0 and not simulated",
      "and float(scenario.controller.length_gain) > 0",
      "the frictionless kinematic reels get the dynamic drives' dead band made up",
      ("tests/test_length_loop.py",)),
    M("length_gain_bound_inclusive", "cdpm_drake/scenario.py",
      "and float(gain) * scenario.time_step < 1.0):",
      "and float(gain) * scenario.time_step <= 1.0):",
      "K_l T = 1 (the loop's error jumps to zero in one tick and beyond) is accepted",
      ("tests/test_length_loop.py",)),
    M("true_distances_unrotated", "cdpm_drake/interference.py",
      "B[i, r] = p[k, r] + (R[k, r, 0] * attachments[i, 0]",
      "B[i, r] = p[k, r] + (R[k, 0, r] * attachments[i, 0]",
      "the true geometry rotates the attachment points by R^T instead of R",
      ("tests/test_true_distances.py",)),
    M("true_crossing_ungated", "cdpm_drake/interference.py",
      "side[q] = _side_rule(side[q], line, straddle and dist <= near[q])",
      "side[q] = _side_rule(side[q], line, straddle)",
      "a side flip far from the other cable counts as a true crossing",
      ("tests/test_true_distances.py",)),
    M("fault_slack_since_off_by_one", "cdpm_drake/simulation.py",
      "first = taut[-1] + 1 if taut.size else 0",
      "first = taut[-1] if taut.size else 0",
      "a fault names the last taut tick as when a cable went slack",
      ("tests/test_true_distances.py",)),
    M("summary_true_is_estimate", "cdpm_drake/simulation.py",
      "d_true = log[\"pair_distances_true\"][:, k]",
      "d_true = log[\"pair_distances\"][:, k]",
      "the summary prints the controller's distances in the true column",
      ("tests/test_true_distances.py",)),
    M("plot_true_is_estimate", "cdpm_drake/views/plots.py",
      "ax.plot(t, 1000.0 * truth[:, k], color=color, linewidth=2.2,",
      "ax.plot(t, 1000.0 * d[:, k], color=color, linewidth=2.2,",
      "the distances figure draws the controller's estimate as the truth",
      ("tests/test_true_distances.py", "tests/test_plots.py")),
    # --- the full-pose controller: pose.py, pose_control.py --------------------------------
    M("pose_jacobian_moment_sign", "cdpm_drake/pose.py",
      "J[3] = -(Rb[i, 1] * u[i, 2] - Rb[i, 2] * u[i, 1])",
      "J[3] = (Rb[i, 1] * u[i, 2] - Rb[i, 2] * u[i, 1])",
      "the pose fit's Jacobian turns one rotation the wrong way",
      ("tests/test_pose.py",)),
    M("pose_fk_no_stretch_correction", "cdpm_drake/pose_control.py",
      "lengths[i] = L0[i] * (1.0 + T[i] / EA) if EA > 0.0 else L0[i]",
      "lengths[i] = L0[i]",
      "the pose is fitted to the unstretched lengths, off by the cables' stretch",
      ("tests/test_pose.py",)),
    M("internal_tension_residual_sign", "cdpm_drake/pose_control.py",
      "num += n[i] * (d * (T_assumed[i] - T_p[i]) + r[i])",
      "num += n[i] * (d * (T_assumed[i] - T_p[i]) - r[i])",
      "the redundant length's residual is read as the opposite internal tension",
      ("tests/test_pose.py",)),
    M("tension_wrench_handle_unrotated", "cdpm_drake/pose_control.py",
      "hx = R[0, 0] * params[1] + R[0, 1] * params[2] + R[0, 2] * params[3]",
      "hx = params[1]",
      "the hand's moment is taken about the handle of an unrotated platform",
      ("tests/test_pose.py",)),
    M("tension_inertia_sign", "cdpm_drake/pose_control.py",
      "w[k] = F[k] - mass * a[k]",
      "w[k] = F[k] + mass * a[k]",
      "the target tensions push the platform's acceleration instead of carrying it",
      ("tests/test_pose.py",)),
    M("first_tick_not_iterated", "cdpm_drake/pose_control.py",
      "if x[2 * m + 12] == 0.0 and EA > 0.0:",
      "if x[2 * m + 12] == 2.0 and EA > 0.0:",
      "the first tick fits the pose to a guessed pretension, degrees off",
      ("tests/test_pose.py",)),
    M("warmup_skipped", "cdpm_drake/pose_control.py",
      "started = x[18] >= warmup",
      "started = x[18] >= 0.0",
      "the orientation held is latched before the estimate has settled",
      ("tests/test_wiring_scenario.py", "tests/test_pose.py")),
    M("ceiling_ignored", "cdpm_drake/pose_control.py",
      "b = min(b, (ceiling - T_p[i]) / n[i])",
      "b = min(b, math.inf)",
      "the target's ceiling is not kept for cables whose share of the internal force is "
      "positive",
      ("tests/test_pose.py", "tests/test_wiring_scenario.py")),
    M("slew_from_target", "cdpm_drake/pose_control.py",
      "before = T_before[i] if started else T_est[i]",
      "before = T_before[i] if started else T_target[i]",
      "the command starts at the target, not at the tensions the robot has",
      ("tests/test_pose.py",)),
    M("orientation_hold_sign", "cdpm_drake/pose_control.py",
      "out[0], out[1], out[2] = gain * ex, gain * ey, gain * ez",
      "out[0], out[1], out[2] = -gain * ex, -gain * ey, -gain * ez",
      "the orientation hold turns the platform further away from the orientation held",
      ("tests/test_pose.py", "tests/test_wiring_scenario.py")),
    M("tension_target_exact_max_min", "cdpm_drake/pose_control.py",
      "used = min(floor, best - FLOOR_MARGIN)",
      "used = min(floor, best)",
      "below the floor the target is the exact max-min one, which jumps along a flat maximum",
      ("tests/test_pose.py",)),
    M("pose_rates_unstretched_wrong_way", "cdpm_drake/pose_control.py",
      "target = Ld[i] * EA / (EA + T[i])",
      "target = Ld[i] * (EA + T[i]) / EA",
      "tension control commands the cables longer than rigid instead of shorter",
      ("tests/test_pose.py", "tests/test_wiring_scenario.py")),
    M("posed_interference_unrotated", "cdpm_drake/pose_control.py",
      "posed_geometry(reels, attachments, pi, pj, x[3:12].reshape((3, 3)), geo)",
      "posed_geometry(reels, attachments, pi, pj, np.eye(3), geo)",
      "the interference distances ignore the estimated orientation",
      ("tests/test_pose.py",)),
    # --- the views: plots, Meshcat ------------------------------------------------------------
    M("plot_distance_in_metres", "cdpm_drake/views/plots.py",
      "ax.plot(t, 1000.0 * d[:, k], color=color, label=label)",
      "ax.plot(t, d[:, k], color=color, label=label)",
      "Fig. 10 plots metres on an axis labelled mm",
      ("tests/test_plots.py",)),
    M("plot_forces_only_x", "cdpm_drake/views/plots.py",
      "ax.plot(t, np.asarray(log[name], dtype=float)[:, c], color=FORCE_COLORS[name],",
      "ax.plot(t, np.asarray(log[name], dtype=float)[:, 0], color=FORCE_COLORS[name],",
      "every axis of the forces figure shows the x component",
      ("tests/test_plots.py",)),
    M("cable_level_off_by_one", "cdpm_drake/views/meshcat_view.py",
      "np.minimum.at(level, pairs[:, 1] - 1, pl)",
      "np.minimum.at(level, pairs[:, 1], pl)",
      "the second cable of a pair is coloured one cable further on",
      ("tests/test_meshcat_view.py",)),
    M("pair_level_band_from_zero", "cdpm_drake/views/meshcat_view.py",
      "s = (d - d_l) / (d_u - d_l)",
      "s = (d - d_l) / d_u",
      "the colour steps span [d_l, d_l + d_u] instead of [d_l, d_u]",
      ("tests/test_meshcat_view.py",)),
    # --- everyday use: exit codes, messages, run folders, export, plots ---------------------
    M("sigint_ignored_is_overridden", "cdpm_drake/interrupt.py",
      "return signal.getsignal(sig) is not signal.SIG_IGN",
      "return True",
      "a command started with SIGINT ignored installs its handler anyway",
      ("tests/test_signals.py",)),
    M("missing_log_is_usage", "cdpm_drake/cli.py",
      "return load_log(target), target\n    except LogError as e:\n        raise InputError(",
      "return load_log(target), target\n    except LogError as e:\n        raise CliError(",
      "cdpm plot/export of a missing log exits 2 (bad usage) instead of 1",
      ("tests/test_exit_codes.py",)),
    M("html_not_checked_before_the_run", "cdpm_drake/cli.py",
      "    _check_duration_tick(args.duration, scenario)\n    _check_html(args.html)",
      "    _check_duration_tick(args.duration, scenario)",
      "an unwritable --html is found only after the run, with a traceback",
      ("tests/test_exit_codes.py",)),
    M("csv_lines_from_zero", "cdpm_drake/operators.py",
      "for n, row in enumerate(rows[1:], start=2):",
      "for n, row in enumerate(rows[1:], start=1):",
      "a force CSV's errors name the line before the bad one",
      ("tests/test_operators.py",)),
    M("csv_nan_time_only", "cdpm_drake/operators.py",
      "if not all(math.isfinite(x) for x in values):",
      "if not all(math.isfinite(x) for x in values[:1]):",
      "a NaN force in a CSV is reported without its file line",
      ("tests/test_operators.py",)),
    M("logistic_default_unchecked", "cdpm_drake/scenario.py",
      '_check_logistic_set({k: getattr(cfg.default, k) for k in arrays}, default, "")',
      'None',
      "a bad interference.default is reported as the first pair's",
      ("tests/test_scenario.py",)),
    M("duration_below_a_tick", "cdpm_drake/scenario.py",
      "if duration < time_step * (1 - 1e-9):",
      "if duration < 0:",
      "a duration shorter than one tick runs one tick",
      ("tests/test_scenario.py", "tests/test_exit_codes.py")),
    M("default_start_is_the_paper_s", "cdpm_drake/scenario.py",
      "scenario = dataclasses.replace(scenario, initial_position=default_start(robot))",
      "scenario = dataclasses.replace(scenario, initial_position=[1.77, 3.65, 1.22])",
      "a scenario without initial_position starts at the paper robot's start",
      ("tests/test_scenario.py", "tests/test_sweep.py")),
    M("default_start_unrounded", "cdpm_drake/scenario.py",
      'return [float(f"{x:.12g}") for x in robot.workspace.center]',
      "return robot.workspace.center.tolist()",
      "the default start reads 1.3499999999999999 in messages and scenario.yaml",
      ("tests/test_scenario.py",)),
    M("run_folder_keeps_robot_path", "cdpm_drake/scenario.py",
      "recorded = dataclasses.replace(recorded, robot=RUN_ROBOT_FILE)",
      "recorded = recorded",
      "a run folder's scenario.yaml points at the original robot file, not its copy",
      ("tests/test_simulate_cli.py",)),
    M("export_pairs_from_zero", "cdpm_drake/views/log_csv.py",
      'names = [f"{i}-{j}" for i, j in pairs]',
      'names = [f"{i - 1}-{j - 1}" for i, j in pairs]',
      "the CSV's pair columns count cables from 0",
      ("tests/test_export.py",)),
    M("export_cables_from_zero", "cdpm_drake/views/log_csv.py",
      "names = [str(c + 1) for c in range(width)]",
      "names = [str(c) for c in range(width)]",
      "the CSV's cable columns count from 0",
      ("tests/test_export.py",)),
    M("export_nan_as_text", "cdpm_drake/views/log_csv.py",
      'return "" if math.isnan(value) else repr(value)',
      "return repr(value)",
      "a NaN is written as the text nan, not an empty cell",
      ("tests/test_export.py",)),
    M("fault_row_drops_metrics", "cdpm_drake/sweep.py",
      "row.update(metrics)  # a faulted run's too: what it logged up to the fault",
      "row.update(metrics if result.error is None else {})",
      "a sweep's faulted run loses the metrics of the ticks it logged",
      ("tests/test_sweep.py",)),
    M("sweep_draws_nothing_silently", "cdpm_drake/sweep.py",
      "why = nothing_to_draw(outcome.rows, metric)",
      'why = ""',
      "cdpm sweep --plot with no ok run draws empty axes and says nothing",
      ("tests/test_sweep.py",)),
    M("nothing_to_draw_counts_failed_rows", "cdpm_drake/sweep.py",
      '    ok = [r for r in rows if r.get("status") == "ok"]\n    if not ok:',
      "    ok = rows\n    if not ok:",
      "a sweep whose every run failed is drawn as if they were ok",
      ("tests/test_sweep.py",)),
    M("compile_notice_every_kernel", "cdpm_drake/cli.py",
      "if not notice.said:",
      "if True:",
      "the compile notice is printed once per kernel, not once",
      ("tests/test_cli.py",)),
    M("sensor_range_axial_only", "cdpm_drake/sensor.py",
      "return (np.abs(axial) > axial_range) | (transverse > transverse_range)",
      "return np.abs(axial) > axial_range",
      "a hand force beyond the transverse range is not counted as clipped",
      ("tests/test_simulate_cli.py",)),
    M("title_wider_than_the_figure", "cdpm_drake/views/plots.py",
      "width = 0.96 * fig.bbox.width",
      "width = 1.5 * fig.bbox.width",
      "a long fault title runs off both sides of the figure",
      ("tests/test_plots.py",)),
    M("interrupted_run_unmarked", "cdpm_drake/views/plots.py",
      "    when = run_interrupted(log)\n",
      "    when = None\n",
      "plots of an interrupted run carry no mark",
      ("tests/test_plots.py",)),
    M("slack_rows_at_one_height", "cdpm_drake/views/plots.py",
      'ticks, = rows.plot(t[slack[:, i - 1]], np.full(n, i), "|"',
      'ticks, = rows.plot(t[slack[:, i - 1]], np.full(n, 1), "|"',
      "every cable's slack ticks on one row: one hides the others",
      ("tests/test_plots.py",)),
    M("legend_dot_pale", "cdpm_drake/views/plots.py",
      "markeredgewidth=0, label=dots.get_label())",
      "markeredgewidth=0, alpha=EVENT_ALPHA, label=dots.get_label())",
      "the legend's within-d_u dot is pale while the plotted dots read bright",
      ("tests/test_plots.py",)),
    M("sweep_ticks_in_m", "cdpm_drake/views/sweep_plots.py",
      'return cell if number is None else f"{scale * number:.4g}"',
      'return cell if number is None else f"{number:.4g}"',
      "a heatmap's d_u ticks in m beside an axis label and colour bar in mm",
      ("tests/test_sweep_plots.py",)),
    M("no_did_you_mean", "cdpm_drake/scenario.py",
      'f"unknown field {where!r}{did_you_mean(key, valid)} "',
      'f"unknown field {where!r} "',
      "a misspelt scenario field gets no suggestion",
      ("tests/test_scenario.py",)),
    M("yaml_line_from_zero", "cdpm_drake/text.py",
      "line, node = found[-1][0].start_mark.line + 1, found[-1][1]",
      "line, node = found[-1][0].start_mark.line, found[-1][1]",
      "the line of a bad field is one too early",
      ("tests/test_scenario.py", "tests/test_robot.py")),
    M("base_dir_offered", "cdpm_drake/scenario.py",
      "valid = [f for f in fields if f not in INTERNAL_FIELDS]",
      "valid = fields",
      "the loader's internal base_dir is listed as a valid field",
      ("tests/test_scenario.py",)),
    M("empty_values_as_none", "cdpm_drake/sweep.py",
      'if given == ["values"] and not axis.values:',
      'if given == ["values"] and axis.values is None:',
      "values: [] is reported as no values given",
      ("tests/test_sweep.py",)),
    M("nan_label_empty", "cdpm_drake/sweep.py",
      "    if isinstance(value, float) and not math.isfinite(value):\n        return repr(value)",
      "    if isinstance(value, float) and not math.isfinite(value):\n        return \"\"",
      "a NaN axis value is shown as nothing in a variant's label",
      ("tests/test_sweep.py",)),
]


def _check_unique_names():
    names = [m.name for m in MUTANTS]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise SystemExit(f"duplicate mutant names: {dupes}")


def stale_reason(mutant: Mutant, root: Path = ROOT) -> str | None:
    """None when the mutant applies (its snippet occurs exactly once), else why not."""
    path = root / mutant.file
    if not path.is_file():
        return f"{mutant.file} does not exist"
    n = path.read_text().count(mutant.original)
    if n != 1:
        return f"snippet found {n} times in {mutant.file}"
    return None


def copy_tree(dest: Path) -> Path:
    for name in COPY:
        src = ROOT / name
        if src.is_symlink():  # sweeps -> cdpm_drake/sweeps: a link in the copy too
            os.symlink(os.readlink(src), dest / name)
        elif src.is_dir():
            shutil.copytree(src, dest / name, ignore=IGNORE)
        elif src.is_file():
            shutil.copy2(src, dest / name)
    return dest


def _pytest(copy: Path, args: list[str], python: str) -> tuple[int, str]:
    env = dict(os.environ, PYTHONPATH=str(copy), PYTHONDONTWRITEBYTECODE="1",
               MPLBACKEND="Agg")
    cmd = [python, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
           "--rootdir", str(copy), *args]
    try:
        proc = subprocess.run(cmd, cwd=copy, env=env, capture_output=True, text=True,
                              timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return -1, "timeout"
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    failed = next((ln for ln in lines if ln.startswith(("FAILED", "ERROR"))), "")
    return proc.returncode, failed or (lines[-1] if lines else proc.stderr[-200:])


def run_mutant(mutant: Mutant, copy: Path, python: str) -> dict:
    """Apply the mutant in `copy`, run the tests, undo it; returns a result row."""
    start = time.perf_counter()
    why = stale_reason(mutant, copy)
    if why is not None:
        return dict(name=mutant.name, result="STALE", where=why, seconds=0.0)
    path = copy / mutant.file
    text = path.read_text()
    try:
        path.write_text(text.replace(mutant.original, mutant.replacement, 1))
        first = [t for t in mutant.tests if (copy / t).is_file()]
        stages = []
        if first:
            stages.append(("own tests", first))
        stages.append(("rest of suite",
                       ["tests"] + [f"--ignore={t}" for t in first]))
        for label, args in stages:
            code, line = _pytest(copy, args, python)
            if code != 0:
                where = f"{label}: {line}" if code != -1 else f"{label}: timeout"
                result = "killed"
                node = _failed_test(line)
                if node is not None:
                    # A kill counts only if that test passes without the mutant: on a busy
                    # host a timing test may fail by itself, which says nothing of the mutant.
                    path.write_text(text)
                    if _pytest(copy, [node], python)[0] != 0:
                        result, where = "FLAKY", f"{node} fails without the mutant too"
                return dict(name=mutant.name, result=result, where=where[:110],
                            seconds=time.perf_counter() - start)
        return dict(name=mutant.name, result="SURVIVED", where="the whole suite passed",
                    seconds=time.perf_counter() - start)
    finally:
        path.write_text(text)


def _failed_test(line: str) -> str | None:
    """The test node id of a pytest `FAILED path::name - message` line."""
    if not line.startswith(("FAILED ", "ERROR ")):
        return None
    node = line.split(" ", 1)[1].split(" - ", 1)[0].strip()
    return node if "::" in node else None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    parser.add_argument("--only", action="append", metavar="NAME",
                        help="run only this mutant (repeatable)")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="workers, each on its own copy of the tree (default 1)")
    parser.add_argument("--python", default=sys.executable,
                        help="the interpreter with the test dependencies (default: this one)")
    args = parser.parse_args(argv)
    _check_unique_names()
    if args.jobs < 1:
        parser.error(f"--jobs must be >= 1, got {args.jobs}")
    mutants = MUTANTS
    if args.only:
        known = {m.name for m in MUTANTS}
        unknown = [n for n in args.only if n not in known]
        if unknown:
            parser.error(f"unknown mutant(s) {unknown}; valid names: {sorted(known)}")
        mutants = [m for m in MUTANTS if m.name in args.only]
    if args.list:
        for m in mutants:
            why = stale_reason(m)
            print(f"{m.name:36s} {m.file:40s} {'STALE: ' + why if why else m.reason}")
        return 0

    rows = []
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="cdpm_mutants_") as tmp:
        copies = queue.Queue()
        for k in range(min(args.jobs, len(mutants))):
            copies.put(copy_tree(Path(tmp) / f"copy{k}"))

        def work(m):
            copy = copies.get()
            try:
                row = run_mutant(m, copy, args.python)
            finally:
                copies.put(copy)
            print(f"  {row['result']:8s} {m.name} ({row['seconds']:.0f} s)", flush=True)
            return row

        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, copies.qsize())) as ex:
            rows = list(ex.map(work, mutants))
    total = time.perf_counter() - started

    print()
    print(f"{'mutant':36s} {'result':8s} {'s':>5s}  where")
    for r in rows:
        print(f"{r['name']:36s} {r['result']:8s} {r['seconds']:5.0f}  {r['where']}")
    killed = sum(r["result"] == "killed" for r in rows)
    survived = [r["name"] for r in rows if r["result"] == "SURVIVED"]
    stale = [r["name"] for r in rows if r["result"] == "STALE"]
    flaky = [r["name"] for r in rows if r["result"] == "FLAKY"]
    print()
    print(f"score: {killed}/{len(rows)} killed ({100.0 * killed / max(1, len(rows)):.0f} %), "
          f"{len(survived)} survived, {len(stale)} stale, {len(flaky)} flaky; "
          f"{total / 60:.1f} min with {args.jobs} job(s)")
    if survived:
        print(f"survived: {survived}")
    if stale:
        print(f"stale (update the list): {stale}")
    if flaky:
        print(f"flaky (run them again with --only): {flaky}")
    return 0 if killed == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
