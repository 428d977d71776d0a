"""The bridge's two plants, without sockets, behind one interface (set_command, raise_fault,
step, lengths, speed, reel_speed, force, drive_force, load_cell, platform, reset, describe):
ReelBridge, reels following their commands with a first-order lag (`--plant kinematic`), and
DynamicBridge, the dynamic plant of `plant: !DynamicReels` stepped to the bridge's clock
(`--plant dynamic`). Lengths m, speeds m/s of cable, forces N in the base frame (drive
forces at the cable, + pays out), times s.

What the drives report (protocol version 2): the kinematic plant has no cable tensions (its
cables are rigid and its reels follow their commands), so it reports no drive force and no
load cell (NaN: "no reading"). A drive force for the reels' own motion with zero tension would
convert to 0 N at the controller, which reads as every cable slack; NaN says honestly that
this plant cannot tell. The dynamic plant's sensors are the simulated plant's, from the same
code (kernels/plant/tension_sensor.py) and the same scenario fields, sampled once a status
(in lockstep: each control tick of the plant's clock): each drive's force as its current measures it (the true drive's
inertia and friction off the model by plant.drive_torque's errors, its filter, noise and
quantum) and, with `load_cells`, the load cells of plant.load_cell (bias, noise,
bandwidth). So a rehearsal is as pessimistic as the simulation.
"""

import math

import numpy as np

from cdpm_drake.hardware.protocol import FAULT_OVERSPEED, MAX_FORCE
from cdpm_drake.kernels.drive_torque import drive_force_for_tension
from cdpm_drake.kernels.plant.tension_sensor import tension_sensor_tick
from cdpm_drake.kernels.kinematics import (KinematicsError, cable_lengths, forward_kinematics,
                                        jacobian)


def _span(layout_entry) -> tuple[int, int]:
    """(start, stop) of an (offset, size) layout entry."""
    at, size = layout_entry
    return at, at + size



class ReelBridge:
    """The bridge's physics, without sockets: reels with a first-order velocity lag and the
    operator's force.

    robot: the Robot. initial_lengths: (m,) m, as the encoders read at power-up (they need not
    fit the robot: that is what the controller's startup check is for). force: callable
    (t s, p (3,) m, v (3,) m/s) -> (3,) N in the base frame, or None for no force; t counts
    from the first enabling command. time_constant: reel lag, s (0: ideal drives).
    """

    def __init__(self, robot, initial_lengths, force=None, time_constant: float = 0.02,
                 max_reel_speed: float | None = None, encoder_offset=None):
        self.robot = robot
        self.lengths = np.array(initial_lengths, dtype=float)
        # What the encoders read beyond the reels' true lengths, m (a homing on another
        # robot's geometry: the file's, where this bridge plays the robot as built).
        self.encoder_offset = (np.zeros(robot.num_cables) if encoder_offset is None
                               else np.asarray(encoder_offset, dtype=float))
        # Commands computed on another robot's geometry (the file's, homed on) pay out
        # lengths this robot's rigid platform cannot take: its taut cables settle where they
        # agree best (the forward kinematics, then its lengths), as the in-process kinematic
        # plant does; on its own geometry the commands agree with it to round-off.
        self._settle = encoder_offset is not None
        if self.lengths.shape != (robot.num_cables,):
            raise ValueError(f"initial_lengths must have {robot.num_cables} entries (one per "
                             f"cable), got shape {self.lengths.shape!r}")
        if not (math.isfinite(time_constant) and time_constant >= 0):
            raise ValueError(f"time_constant must be >= 0 s, got {time_constant!r}")
        self.force_fn = force
        self.time_constant = float(time_constant)
        self.max_reel_speed = float(max_reel_speed if max_reel_speed is not None
                                    else robot.limits.max_reel_speed)
        self.speed = np.zeros(robot.num_cables)     # actual reel velocities, m/s
        self.command = np.zeros(robot.num_cables)   # velocities being followed, m/s
        self.enabled = False
        self.faults = 0
        self.time = 0.0                             # s stepped so far
        self.operator_start = None                  # `time` of the first enabling command, s
        self.p = self._best_fit(robot.workspace.center)
        self.v = np.zeros(3)
        self._start = (self.lengths.copy(), self.p.copy())

    def describe(self) -> str:
        """The plant it plays, for the emulator's first line."""
        return (f"plant: kinematic (reels following their commands with a "
                f"{1e3 * self.time_constant:g} ms first-order lag, speed limit "
                f"{self.max_reel_speed:g} m/s)")

    def reset(self) -> None:
        """Back to the start, at rest, the operator's clock stopped until the next enabling
        command: what a homing between two runs does. Fault bits stay (a real bridge keeps
        them until it is reset)."""
        lengths, p = self._start
        self.lengths = lengths.copy()
        self.p = p.copy()
        self.v = np.zeros(3)
        self.speed = np.zeros_like(self.speed)
        self.command = np.zeros_like(self.command)
        self.enabled = False
        self.operator_start = None

    def platform(self) -> np.ndarray:
        """The platform centre now (the best fit to the reels' lengths), base frame, m."""
        return self._best_fit(self.p)

    def encoder_lengths(self) -> np.ndarray:
        """What the encoders read now, m: the reels' lengths plus the encoders' offset."""
        return self.lengths + self.encoder_offset

    def _best_fit(self, guess):
        try:
            return forward_kinematics(self.robot, self.lengths, p_guess=guess,
                                      max_residual=np.inf)
        except KinematicsError:
            return np.asarray(guess, dtype=float)

    def set_command(self, velocity, enable: bool) -> None:
        """Follow `velocity` (m/s) from now on if `enable` and no fault is set; hold at rest
        otherwise. A command above the reel speed limit raises FAULT_OVERSPEED."""
        velocity = np.asarray(velocity, dtype=float)
        if enable and np.max(np.abs(velocity)) > self.max_reel_speed * (1 + 1e-9):
            self.raise_fault(FAULT_OVERSPEED)
        self.enabled = bool(enable) and self.faults == 0
        self.command = velocity.copy() if self.enabled else np.zeros_like(self.command)
        if self.enabled and self.operator_start is None:
            self.operator_start = self.time

    def raise_fault(self, bits: int) -> None:
        """Set fault bits; the reels stop following commands (the lag still decays)."""
        self.faults |= int(bits)
        self.enabled = False
        self.command = np.zeros_like(self.command)

    def step(self, dt: float) -> None:
        """Advance dt s under the current command. Exact for a constant command: with
        a = exp(-dt/tau), speed -> c + (s - c) a and length += c dt + (s - c) tau (1 - a)."""
        if dt <= 0:
            return
        c, s, tau = self.command, self.speed, self.time_constant
        if tau > 0:
            a = math.exp(-dt / tau)
            self.lengths += c * dt + (s - c) * tau * (1.0 - a)
            self.speed = c + (s - c) * a
        else:
            self.lengths += c * dt
            self.speed = c.copy()
        self.time += dt
        if self._settle:
            self.p = self._best_fit(self.p)
            self.lengths = cable_lengths(self.robot, self.p)
        if self.force_fn is not None:
            self.p = self._best_fit(self.p)
            self.v = np.linalg.lstsq(jacobian(self.robot, self.p), self.speed, rcond=None)[0]

    def drive_force(self) -> np.ndarray:
        """No drive force (NaN): rigid cables carry no tension this plant could load a drive
        with (see the module docstring)."""
        return np.full(self.robot.num_cables, np.nan)

    def reel_speed(self) -> np.ndarray:
        """The reels' speeds, m/s of cable."""
        return self.speed.copy()

    def load_cell(self) -> np.ndarray:
        """No load cells (NaN)."""
        return np.full(self.robot.num_cables, np.nan)

    def force(self) -> np.ndarray:
        """The force sample, N, saturated at the link's range like a real ADC."""
        if self.force_fn is None:
            return np.zeros(3)
        t = 0.0 if self.operator_start is None else self.time - self.operator_start
        f = np.asarray(self.force_fn(t, self.p.copy(), self.v.copy()), dtype=float)
        return np.clip(f, -MAX_FORCE, MAX_FORCE)


class DynamicBridge:
    """The bridge's physics as the dynamic plant (`plant: !DynamicReels`): the scenario's
    robot with mass, elastic tension-only cables, reel drives with friction and the operator,
    stepped by a Drake Simulator to the bridge's clock. Same interface as ReelBridge.

    resolved: a ResolvedScenario whose plant is a DynamicReels (its start, robot, operator and
    plant settings). The platform rests at the start until the first enabling command; the
    plant's (and the operator's) clock starts then. The encoders read each reel's payout L0
    plus its cable's stretch at the start (zeroed at the start pose, as a homing would: they
    read the rigid cable lengths there), plus `length_offset` (m, per cable). `load_cells`:
    report the true tensions as ideal load cells (else NaN: none).
    """

    def __init__(self, resolved, length_offset=None, load_cells: bool = False):
        from pydrake.systems.analysis import Simulator
        from pydrake.systems.framework import DiagramBuilder

        from cdpm_drake.config import check_dynamic_reels
        from cdpm_drake.systems.plants.dynamic_plant import (build_dynamic_plant,
                                                             plant_state_now, sensor_kernel)

        scenario = resolved.scenario
        # The robot it plays: the scenario's, or the robot as built (plant.robot,
        # plant.model_error), homed on the scenario's file as a real robot is.
        self.robot = robot = resolved.plant_robot
        m = robot.num_cables
        builder = DiagramBuilder()
        tensions0 = check_dynamic_reels(scenario, robot).tensions
        self._plant = builder.AddNamedSystem("reels", build_dynamic_plant(
            scenario, robot, resolved.operator, tensions0, log_truth=False))
        builder.ExportInput(self._plant.GetInputPort("reel_velocity_command"), "command")
        self._diagram = builder.Build()
        self._simulator = Simulator(self._diagram)
        self._context = self._simulator.get_mutable_context()
        self._command_port = self._diagram.get_input_port(0)
        self._force_port = self._plant.GetOutputPort("measured_force")
        self.load_cells = bool(load_cells)
        self._plant_context = self._plant.GetMyContextFromRoot(self._context)
        self.max_reel_speed = float(scenario.plant.max_reel_speed
                                    if scenario.plant.max_reel_speed is not None
                                    else robot.limits.max_reel_speed)
        self._h = float(scenario.plant.time_step)
        self.command = np.zeros(m)
        self._command_port.FixValue(self._context, self.command)
        self._simulator.Initialize()
        # Per tick, the plant's state and its ground truth are read from these directly.
        cables = self._plant.GetSubsystemByName("cables")
        self._state_context = self._plant.GetSubsystemByName(
            "reel_state").GetMyContextFromRoot(self._context)
        self._step_port = cables.GetOutputPort("step")
        self._cables_context = cables.GetMyContextFromRoot(self._context)
        self._L0 = slice(*_span(cables.state_layout["L0"]))
        self._speeds = slice(*_span(cables.state_layout["reel_speeds"]))
        self._tensions = slice(*_span(cables.layout["tensions"]))
        self._slack = slice(*_span(cables.layout["slack"]))
        self._rpy = slice(*_span(cables.layout["rpy_true"]))
        self._drive = slice(*_span(cables.layout["drive_force"]))
        at = cables.layout["next_reels"][0] + m  # the reels' speeds after the plant step
        self._next_speeds = slice(at, at + m)
        # The simulated plant's sensors, from its code and the scenario's fields, ticked
        # once a status (_sensed): the drives' current (filter,
        # noise, quantum, the true drives' inertia and friction errors) and the load cells
        # (bias, noise, bandwidth).
        self._T = float(scenario.time_step)
        self._sensor_setup = {kind: sensor_kernel(scenario, robot, tensions0, kind)
                              for kind in ("drive_torque", "load_cell")}
        self._p_true = slice(*_span(cables.layout["p_WP_true"]))
        p0 = np.asarray(scenario.initial_position, dtype=float)
        L0 = plant_state_now(self._diagram, self._context)["L0"]
        from cdpm_drake.kernels.rotation import rotation_from_rpy

        # The homing writes the file's rigid lengths of the start pose (the controller's
        # robot: the one played, unless the plant plays the robot as built).
        homed = resolved.robot
        rigid = np.linalg.norm(homed.reels - (p0 + homed.attachments
                                              @ rotation_from_rpy(scenario.plant.initial_rpy).T),
                               axis=1)
        self.encoder_offset = rigid - L0
        if resolved.encoder_zero_error is not None:
            self.encoder_offset = self.encoder_offset + resolved.encoder_zero_error
        if length_offset is not None:
            self.encoder_offset = self.encoder_offset + np.asarray(length_offset, dtype=float)
        self.enabled = False
        self.faults = 0
        self.time = 0.0                             # s stepped so far (the bridge's clock)
        self.operator_start = None                  # `time` of the first enabling command, s
        self._settings = scenario.plant
        # The controller's ceiling of a cable's tension, N: a true tension above it is
        # reported (a rehearsal that overloaded a cable must not read as a clean one).
        self.ceiling = float(scenario.controller.max_tension)
        self._initial = self._context.Clone()       # the start: what reset() goes back to
        self._clear_record()
        self._reset_sensors()

    def describe(self) -> str:
        """The plant it plays, for the emulator's first line."""
        c = self._settings
        return (f"plant: dynamic (!DynamicReels: time step {1e3 * c.time_step:g} ms, reel "
                f"speed limit {self.max_reel_speed:g} m/s, start tilt "
                f"{[float(a) for a in c.initial_rpy]!r} rad, rotation "
                f"{'locked' if c.lock_rotation else 'free'})")

    def _clear_record(self) -> None:
        # What the cables went through, tick by tick, since the start or the last reset (the
        # session's summary): while the controller drove the reels, and apart from that, after
        # the reels were stopped (disabled or faulted: the drives brake a moving platform and
        # the operator pulls on, which can raise tensions the run itself never saw).
        m = self.robot.num_cables
        self.driven = _Record(m, self.ceiling)
        self.stopped = _Record(m, self.ceiling)
        self.stop_time = None                       # plant time the reels were first stopped, s
        self.stops = 0                              # times the reels were stopped
        self.resumes = 0                            # times the controller enabled them again
        self._reels_stopped = False                 # now stopped (the ticks go to `stopped`)
        self._observe()

    def reset(self) -> None:
        """Back to the start pose at rest (the plant's state and clock as built), the
        operator's clock stopped until the next enabling command, the record cleared: what a
        homing between two runs does. Fault bits stay (a real bridge keeps them until it is
        reset)."""
        self._context.SetTimeStateAndParametersFrom(self._initial)
        self.command = np.zeros_like(self.command)
        self._command_port.FixValue(self._context, self.command)
        self._simulator.Initialize()
        self.enabled = False
        self.operator_start = None
        self._clear_record()
        self._reset_sensors()

    def _reset_sensors(self) -> None:
        """The sensors' start state: the start tensions as they read them, no tick yet."""
        self._sensor = {kind: start.copy() for kind, (_, _, start) in self._sensor_setup.items()}
        self._sensed_at = None                      # the plant time of the last sample, s
        m = self.robot.num_cables
        params = self._sensor_setup["drive_torque"][0]
        self._drive_reading = drive_force_for_tension(
            self._sensor["drive_torque"][:m], np.zeros(m), np.zeros(m), *params[6:10])
        self._speed_reading = np.zeros(m)

    def _sense(self) -> None:
        """One control tick of both sensors on the plant now (tension_sensor_tick, as the
        dynamic plant's sensor: its inputs the plant step's drive force, the reels' speeds
        after it and the true tensions). The drives report the measured force itself: the
        tick's tension turned back into it with the sensor's own model (the inverse of its
        last step), so the controller converts it with its model and its acceleration."""
        m = self.robot.num_cables
        step = self._step_port.Eval(self._cables_context)
        inputs = np.concatenate([step[self._drive], step[self._next_speeds],
                                 step[self._tensions]])
        for kind, (params, bias, _) in self._sensor_setup.items():
            x = np.concatenate([inputs, self._sensor[kind]])
            out = np.empty_like(self._sensor[kind])
            tension_sensor_tick(params, bias, x, out)
            if kind == "drive_torque":
                w = x[m:2 * m]
                accel = (w - x[3 * m + 2 * m:3 * m + 3 * m]) / params[1]
                self._drive_reading = drive_force_for_tension(out[:m], w, accel, *params[6:10])
                self._speed_reading = w.copy()
            self._sensor[kind] = out

    def platform(self) -> np.ndarray:
        """The platform centre now (the plant's true position), base frame, m."""
        return np.array(self._step_port.Eval(self._cables_context)[self._p_true])

    @property
    def lengths(self) -> np.ndarray:
        """The encoders, m: each reel's payout L0, zeroed at the start pose."""
        state = self._state_context.get_discrete_state_vector().value()
        return state[self._L0] + self.encoder_offset

    def encoder_lengths(self) -> np.ndarray:
        """What the encoders read now, m (`lengths`: zeroed at the start pose)."""
        return self.lengths

    @property
    def speed(self) -> np.ndarray:
        """The reels' speeds, m/s of cable."""
        return self._state_context.get_discrete_state_vector().value()[self._speeds].copy()

    def set_command(self, velocity, enable: bool) -> None:
        """As ReelBridge.set_command: follow `velocity` (m/s) if `enable` and no fault is
        set; a command above the reel speed limit raises FAULT_OVERSPEED."""
        velocity = np.asarray(velocity, dtype=float)
        if enable and np.max(np.abs(velocity)) > self.max_reel_speed * (1 + 1e-9):
            self.raise_fault(FAULT_OVERSPEED)
        was = self.enabled
        self.enabled = bool(enable) and self.faults == 0
        if was and not self.enabled:
            self._stopped()
        if self.enabled and self._reels_stopped:  # the controller resumed: driven again
            self._reels_stopped = False
            self.resumes += 1
        self._apply(velocity if self.enabled else np.zeros_like(self.command))
        if self.enabled and self.operator_start is None:
            self.operator_start = self.time

    def raise_fault(self, bits: int) -> None:
        """Set fault bits; the drives are commanded to stop (they slow down with their own
        dynamics)."""
        self.faults |= int(bits)
        if self.enabled:
            self._stopped()
        self.enabled = False
        self._apply(np.zeros_like(self.command))

    def _stopped(self) -> None:
        # Every tick from here to the next enabling command is a stopped one; the ticks the
        # controller drives after it resumed are driven ones again.
        if self.stop_time is None:
            self.stop_time = self.plant_time
        if not self._reels_stopped:
            self.stops += 1
        self._reels_stopped = True

    def _apply(self, velocity) -> None:
        if not np.array_equal(velocity, self.command):
            self.command = velocity.copy()
            self._command_port.FixValue(self._context, self.command)

    @property
    def plant_time(self) -> float:
        """The plant's (and the operator's) clock, s: 0 until the first enabling command."""
        return self._context.get_time()

    def step(self, dt: float) -> None:
        """Advance the bridge's clock by dt s; once the operator has started, the plant
        follows to the last whole plant step at or before the same time."""
        if dt <= 0:
            return
        self.time += dt
        if self.operator_start is None:
            return
        # Whole steps counted in integers: the clock's sums of wall-clock intervals would
        # otherwise land a hair either side of a step.
        steps = math.floor((self.time - self.operator_start) / self._h + 1e-6)
        self._advance(steps * self._h)

    def _sensed(self) -> None:
        """Sample the sensors when read, once per plant time (the plant runs): one sample a
        status, so that each status's drive force goes with its reel speed and the speed of
        the status before (the controller's acceleration), as the simulated sensor's sample
        a tick goes with its own. In lockstep (one period a status) these are the simulated
        plant's samples, tick for tick; on wall clock a status that comes late spans more
        plant time than the sensor's tick assumes."""
        if self.operator_start is not None and self.plant_time != self._sensed_at:
            self._sense()
            self._sensed_at = self.plant_time

    def _advance(self, until: float) -> None:
        """The plant to plant time `until` (s, a whole plant step), and its record."""
        if round(until / self._h) * self._h > self.plant_time:
            self._simulator.AdvanceTo(round(until / self._h) * self._h)
            self._observe()

    def _observe(self) -> None:
        # The plant's ground truth now (systems.dynamic_plant.ground_truth_now, read directly:
        # this runs every tick).
        step = self._step_port.Eval(self._cables_context)
        T = step[self._tensions]
        slack = step[self._slack] > 0.5
        r, p, y = (float(a) for a in step[self._rpy])
        # The angle of R = Rz(y) Ry(p) Rx(r) from level: acos((trace R - 1) / 2).
        trace = (math.cos(y) * math.cos(p) + math.sin(y) * math.sin(p) * math.sin(r)
                 + math.cos(y) * math.cos(r) + math.cos(p) * math.cos(r))
        tilt = math.acos(max(-1.0, min(1.0, (trace - 1) / 2)))
        record = self.stopped if self._reels_stopped else self.driven
        record.observe(T, slack, tilt, self.plant_time)
        self._true_tensions = np.array(T)
        self._true_pose = (np.array(step[self._p_true]), np.array(step[self._rpy]))

    def true_tensions(self) -> np.ndarray:
        """The cables' true tensions now, N (the plant's ground truth)."""
        return self._true_tensions.copy()

    def true_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The platform's true pose now: (centre (3,) m, roll-pitch-yaw (3,) rad), base
        frame (the plant's ground truth)."""
        p, rpy = self._true_pose
        return p.copy(), rpy.copy()

    def drive_force(self) -> np.ndarray:
        """Each reel drive's force at the cable as the drive measures it, N, + pays out: the
        true drive's force (its inertia and friction off the robot file's by the scenario's
        plant.drive_torque errors) through the current filter, noise and quantum of
        plant.drive_torque, sampled once a status (the dynamic plant's
        drive_torque sensor, before its conversion to a tension)."""
        self._sensed()
        return self._drive_reading.copy()

    def reel_speed(self) -> np.ndarray:
        """The reels' speeds sampled with drive_force(), m/s of cable."""
        self._sensed()
        return self._speed_reading.copy()

    def load_cell(self) -> np.ndarray:
        """The load cells, N: with `load_cells`, the dynamic plant's load_cell sensor on the
        true tensions (plant.load_cell: a bias per cell, noise, bandwidth), sampled once a
        status; else NaN (none)."""
        if self.load_cells:
            self._sensed()
            return self._sensor["load_cell"][:self.robot.num_cables].copy()
        return np.full(self.robot.num_cables, np.nan)

    def force(self) -> np.ndarray:
        """The force sample, N: the operator's force on the true platform (the plant's
        measured_force), saturated at the link's range like a real ADC."""
        f = self._force_port.Eval(self._plant_context)
        return np.clip(f, -MAX_FORCE, MAX_FORCE)

    def summary(self) -> str:
        """What the cables went through since the start or the last reset (a session): the
        tension range, each cable's slack ticks and when it first went slack, the largest
        tilt and when, while the controller drove the reels; then the same after the reels
        were stopped (disabled or faulted), if the plant ran on. Times on the plant's clock (0
        at the session's first enabling command, as the controller's log)."""
        text = f"dynamic plant over {self.driven.ticks} ticks: {self.driven.describe()}"
        if self.resumes:
            text = (f"dynamic plant over {self.driven.ticks} ticks the controller drove (it "
                    f"resumed {self.resumes} time{'s' if self.resumes > 1 else ''} after a "
                    f"stop): {self.driven.describe()}")
        if self.stopped.ticks and not self.resumes:
            text += (f"; after the reels stopped at t = {self.stop_time:.3f} s, "
                     f"{self.stopped.ticks} ticks: {self.stopped.describe()}")
        elif self.stopped.ticks:
            stops = f"{self.stops} stop{'s' if self.stops > 1 else ''}"
            text += (f"; while the reels were stopped ({stops}, the first at t = "
                     f"{self.stop_time:.3f} s), {self.stopped.ticks} ticks: "
                     f"{self.stopped.describe()}")
        return text + f" (plant time 0..{self.plant_time:.3f} s)"


class _Record:
    """What the cables went through over some ticks: tensions (N), slack ticks, tilt (rad);
    times on the plant's clock, s."""

    def __init__(self, m: int, ceiling: float = math.inf):
        self.ticks = 0
        self.ceiling = ceiling                      # N: tensions above it are reported
        self.peak = np.zeros(m)                     # each cable's largest tension, N
        self.peak_time = np.zeros(m)                # and when, s
        self.over_ticks = np.zeros(m, dtype=int)    # ticks above the ceiling per cable
        self.min_tension = math.inf
        self.max_tension = 0.0
        self.slack_ticks = np.zeros(m, dtype=int)
        self.first_slack = np.full(m, np.nan)       # plant time of each cable's first slack, s
        self.max_tilt = 0.0
        self.max_tilt_time = 0.0

    def observe(self, T, slack, tilt: float, now: float) -> None:
        self.ticks += 1
        self.min_tension = min(self.min_tension, float(T.min()))
        self.max_tension = max(self.max_tension, float(T.max()))
        self.slack_ticks += slack
        self.first_slack[slack & np.isnan(self.first_slack)] = now
        higher = T > self.peak
        self.peak[higher], self.peak_time[higher] = T[higher], now
        self.over_ticks += T > self.ceiling
        if tilt > self.max_tilt:
            self.max_tilt, self.max_tilt_time = tilt, now

    def describe(self) -> str:
        slack = ", ".join(f"{i + 1}:{int(n)} (first at t = {self.first_slack[i]:.3f} s)"
                          for i, n in enumerate(self.slack_ticks) if n)
        return (f"tensions {self.min_tension:.2f}..{self.max_tension:.2f} N, slack ticks per "
                f"cable {slack or 'none'}, largest tilt {math.degrees(self.max_tilt):.2f} deg "
                f"at t = {self.max_tilt_time:.3f} s{self.overload()}")

    def overload(self) -> str:
        """", ABOVE the ceiling ...: cable 3 up to 203.10 N at t = 4.210 s (57 ticks)", or ""
        when no cable's tension went above the ceiling."""
        over = [i for i in range(self.peak.size) if self.over_ticks[i]]
        if not over:
            return ""
        cables = ", ".join(f"cable {i + 1} up to {self.peak[i]:.2f} N at t = "
                           f"{self.peak_time[i]:.3f} s ({int(self.over_ticks[i])} tick"
                           f"{'s' if self.over_ticks[i] != 1 else ''})"
                           for i in over)
        return (f", ABOVE the ceiling controller.max_tension = {self.ceiling:g} N: {cables}")

