"""cdpm-reel-emulator: play the reel bridge on loopback, to rehearse a run before the robot.

Two plants behind the bridge. `--plant kinematic` (the default): the reels follow the
commanded velocities with a first-order lag, the encoders report what each reel paid out, the
force sensor the operator's force at the best-fit platform pose. `--plant dynamic`: the
scenario's robot with mass, elastic cables, drive friction and the operator, the dynamic plant
of `plant: !DynamicReels` (systems/dynamic_plant.py) stepped in real time; the encoders report
each reel's payout, zeroed at the start pose as a homing would (they read the rigid cable
lengths there), the force sensor the operator's force on the true platform; the closing
summary adds the cables' tensions, their slack ticks and the platform's tilt.
Fault-injection flags impair the link (drop, delay, duplicate, reorder, corrupt) or break the
bridge (freeze, NaN, stop, fault bits) from `--fault-after` seconds after the controller first
enables the reels. The protocol is hardware/PROTOCOL.md.

Each controller session (a `cdpm run`) after the first starts where the first did: the plant is
reset to the start, as a homing between two runs would (its fault bits stay), and the operator's
clock starts again at the session's first enabling command; the session's line says where the
last one left the platform. With the dynamic plant, each session's close reports what the
cables went through in it (tensions, when each went slack, the largest tilt and when, on the
plant's clock), while the controller drove the reels and, apart, after they were stopped.

Examples:
  cdpm-reel-emulator --robot paper_7cable --start 1.77 3.65 1.22
  cdpm-reel-emulator --scenario exp2_interaction --drop 0.01 --seed 3
  cdpm-reel-emulator --scenario exp2_interaction --plant dynamic
  cdpm-reel-emulator --stop --fault-after 2.0
"""

import argparse
import collections
import dataclasses
import errno
import gc
import math
import socket
import sys
import threading
import time

import numpy as np

from cdpm_drake.kernels.kinematics import KinematicsError, cable_lengths, forward_kinematics, jacobian
from cdpm_drake.hardware.config import DEFAULT_BRIDGE_PORT
from cdpm_drake.hardware.link import resolve_ipv4
from cdpm_drake.hardware.priority import set_realtime_priority
from cdpm_drake.hardware.protocol import (FAULT_COMMAND_TIMEOUT, FAULT_OVERSPEED, MAX_FORCE, REASONS,
                       ProtocolError, SequenceTracker, Status, decode_command, encode_status,
                       next_sequence)


def _span(layout_entry) -> tuple[int, int]:
    """(start, stop) of an (offset, size) layout entry."""
    at, size = layout_entry
    return at, at + size


# Ticks whose compute time the server keeps for its summary (8.7 min at 500 Hz).
COMPUTE_WINDOW = 1 << 18


@dataclasses.dataclass(frozen=True)
class FaultPlan:
    """What the emulator breaks, from `after` seconds after the first enabling command."""

    # Share of datagrams dropped, in each direction, 0..1.
    drop: float = 0.0
    # Extra latency of every status, s.
    delay: float = 0.0
    # Share of statuses sent twice, 0..1.
    duplicate: float = 0.0
    # Share of statuses held back and sent after the next one, 0..1.
    reorder: float = 0.0
    # Share of statuses with one byte flipped after the CRC was computed, 0..1.
    corrupt: float = 0.0
    # Resend the last status unchanged, forever (a hung bridge task).
    freeze: bool = False
    # Report cable 1's length as NaN, in otherwise valid datagrams.
    nan: bool = False
    # Send nothing more (a crashed bridge); commands are still read and recorded.
    stop: bool = False
    # Fault bits to raise (protocol.FAULT_*); the reels stop.
    fault_bits: int = 0
    # Delay from the first command with enable set to the start of the faults above, s.
    after: float = 0.0

    def __post_init__(self):
        for name in ("drop", "duplicate", "reorder", "corrupt"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value <= 1.0):
                raise ValueError(f"{name} must be a share in [0, 1], got {value!r}")
        for name in ("delay", "after"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0 s, got {value!r}")
        if not (isinstance(self.fault_bits, int) and 0 <= self.fault_bits < 1 << 32):
            raise ValueError(f"fault_bits must be a 32-bit unsigned integer, got "
                             f"{self.fault_bits!r}")

    @property
    def any(self) -> bool:
        return self != FaultPlan(after=self.after)


class ReelBridge:
    """The bridge's physics, without sockets: reels with a first-order velocity lag and the
    operator's force.

    robot: the Robot. initial_lengths: (m,) m, as the encoders read at power-up (they need not
    fit the robot: that is what the controller's startup check is for). force: callable
    (t s, p (3,) m, v (3,) m/s) -> (3,) N in the base frame, or None for no force; t counts
    from the first enabling command. time_constant: reel lag, s (0: ideal drives).
    """

    def __init__(self, robot, initial_lengths, force=None, time_constant: float = 0.02,
                 max_reel_speed: float | None = None):
        self.robot = robot
        self.lengths = np.array(initial_lengths, dtype=float)
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
        if self.force_fn is not None:
            self.p = self._best_fit(self.p)
            self.v = np.linalg.lstsq(jacobian(self.robot, self.p), self.speed, rcond=None)[0]

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
    read the rigid cable lengths there), plus `length_offset` (m, per cable).
    """

    def __init__(self, resolved, length_offset=None):
        from pydrake.systems.analysis import Simulator
        from pydrake.systems.framework import DiagramBuilder

        from cdpm_drake.config import check_dynamic_reels
        from cdpm_drake.systems.plants.dynamic_plant import build_dynamic_plant, plant_state_now

        scenario = resolved.scenario
        self.robot = robot = resolved.robot
        m = robot.num_cables
        builder = DiagramBuilder()
        self._plant = builder.AddNamedSystem("reels", build_dynamic_plant(
            scenario, robot, resolved.operator, check_dynamic_reels(scenario, robot).tensions,
            log_truth=False))
        builder.ExportInput(self._plant.GetInputPort("reel_velocity_command"), "command")
        self._diagram = builder.Build()
        self._simulator = Simulator(self._diagram)
        self._context = self._simulator.get_mutable_context()
        self._command_port = self._diagram.get_input_port(0)
        self._force_port = self._plant.GetOutputPort("measured_force")
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
        self._p_true = slice(*_span(cables.layout["p_WP_true"]))
        p0 = np.asarray(scenario.initial_position, dtype=float)
        L0 = plant_state_now(self._diagram, self._context)["L0"]
        from cdpm_drake.kernels.rotation import rotation_from_rpy

        rigid = np.linalg.norm(robot.reels - (p0 + robot.attachments
                                              @ rotation_from_rpy(scenario.plant.initial_rpy).T),
                               axis=1)
        self.encoder_offset = rigid - L0
        if length_offset is not None:
            self.encoder_offset = self.encoder_offset + np.asarray(length_offset, dtype=float)
        self.enabled = False
        self.faults = 0
        self.time = 0.0                             # s stepped so far (the bridge's clock)
        self.operator_start = None                  # `time` of the first enabling command, s
        self._settings = scenario.plant
        self._initial = self._context.Clone()       # the start: what reset() goes back to
        self._clear_record()

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
        self.driven = _Record(m)
        self.stopped = _Record(m)
        self.stop_time = None                       # plant time the reels were stopped, s
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

    def platform(self) -> np.ndarray:
        """The platform centre now (the plant's true position), base frame, m."""
        return np.array(self._step_port.Eval(self._cables_context)[self._p_true])

    @property
    def lengths(self) -> np.ndarray:
        """The encoders, m: each reel's payout L0, zeroed at the start pose."""
        state = self._state_context.get_discrete_state_vector().value()
        return state[self._L0] + self.encoder_offset

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
        if self.stop_time is None:  # the first stop ends what the controller drove
            self.stop_time = self.plant_time

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
        if steps * self._h > self.plant_time:
            self._simulator.AdvanceTo(steps * self._h)
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
        record = self.driven if self.stop_time is None else self.stopped
        record.observe(T, slack, tilt, self.plant_time)

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
        if self.stopped.ticks:
            text += (f"; after the reels stopped at t = {self.stop_time:.3f} s, "
                     f"{self.stopped.ticks} ticks: {self.stopped.describe()}")
        return text + f" (plant time 0..{self.plant_time:.3f} s)"


class _Record:
    """What the cables went through over some ticks: tensions (N), slack ticks, tilt (rad);
    times on the plant's clock, s."""

    def __init__(self, m: int):
        self.ticks = 0
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
        if tilt > self.max_tilt:
            self.max_tilt, self.max_tilt_time = tilt, now

    def describe(self) -> str:
        slack = ", ".join(f"{i + 1}:{int(n)} (first at t = {self.first_slack[i]:.3f} s)"
                          for i, n in enumerate(self.slack_ticks) if n)
        return (f"tensions {self.min_tension:.2f}..{self.max_tension:.2f} N, slack ticks per "
                f"cable {slack or 'none'}, largest tilt {math.degrees(self.max_tilt):.2f} deg "
                f"at t = {self.max_tilt_time:.3f} s")


@dataclasses.dataclass(frozen=True)
class ReceivedCommand:
    """A command as the emulator read it: `time` is the bridge clock when it was read, s;
    `command_time` the controller's `time` field, s."""

    time: float
    tick: int
    sequence: int
    command_time: float
    enable: bool
    velocity: np.ndarray
    fault_active: bool


class ReelBridgeServer:
    """The bridge on a UDP socket, run in this thread (`run`) or a background one (`start`).

    Every `period` s it reads the waiting commands (the newest valid one takes effect),
    advances the reels, and sends one status to the sender of the latest valid command (or to
    `controller` if given; then commands from anyone else are ignored). If the reels are
    enabled and no valid command came for `command_timeout` s, it raises FAULT_COMMAND_TIMEOUT.
    """

    def __init__(self, bridge: ReelBridge, address: tuple[str, int] = ("127.0.0.1", 0),
                 faults: FaultPlan = FaultPlan(), period: float = 0.002, seed: int = 0,
                 controller: tuple[str, int] | None = None, command_timeout: float = 0.05,
                 record: int = 100_000, log=None, session_timeout: float = 1.0):
        """`record`: how many received commands to keep in `commands` (tests read them; the
        command-line emulator keeps none). `log(text)` is told what the bridge sees: each
        controller session opened and closed, the first rejected datagram of each reason per
        session (None: silent). A session closes when a new one starts or after
        `session_timeout` s without a valid command. The fault plan applies to one session:
        the first in which it takes effect; later sessions run without faults."""
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period must be a finite number > 0 s, got {period!r}")
        if not (math.isfinite(session_timeout) and session_timeout > 0):
            raise ValueError(f"session_timeout must be a finite number > 0 s, got "
                             f"{session_timeout!r}")
        self.bridge = bridge
        self.period = float(period)
        self.command_timeout = float(command_timeout)
        self._faults = faults
        self._rng = np.random.default_rng(seed)
        self._m = bridge.robot.num_cables
        self._fixed_controller = (None if controller is None
                                  else (resolve_ipv4(controller[0], "controller"),
                                        int(controller[1])))
        self._controller = self._fixed_controller
        self._log = log
        self.session_timeout = float(session_timeout)
        host, port = resolve_ipv4(address[0], "address"), int(address[1])
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.setblocking(False)
        try:
            self._sock.bind((host, port))
        except OSError as e:
            self._sock.close()
            hint = (" (another cdpm emulate or bridge is listening there? choose another "
                    "--port)" if e.errno == errno.EADDRINUSE else
                    " (not an address of this machine? see --address)"
                    if e.errno == errno.EADDRNOTAVAIL else "")
            raise OSError(e.errno, f"cannot listen on UDP {host}:{port}: "
                                   f"{e.strerror or e}{hint}") from None
        self._tracker = SequenceTracker()
        self._last_command = None
        self._last_command_wall = None
        self._sequence = 0
        self._frozen = None              # the datagram a frozen bridge repeats
        self._held = None                # a status held back for reordering
        self._delayed = collections.deque()  # (due time, datagram)
        self._stop = threading.Event()
        self._thread = None
        self._lock = threading.Lock()
        self.start_wall = None
        self.first_enable_time = None    # bridge time of the first enabling command, s
        self.fault_onset = None          # bridge time the FaultPlan took effect, s
        self.fault_onset_tick = None
        self.tick = 0
        self.commands = collections.deque(maxlen=record)
        # Controller sessions, numbered from 1 (0: none yet); `session_open` while one runs.
        self.session = 0
        self.session_open = False
        self._session_start = 0.0
        self._session_commands = 0
        self._session_rejected = {}
        self._fault_session = None   # the session in which the fault plan took effect
        # Compute time of each tick (reading commands, stepping the plant, sending the
        # status), s: the last COMPUTE_WINDOW ticks.
        self.compute = collections.deque(maxlen=COMPUTE_WINDOW)
        self.counters = {"statuses_sent": 0, "statuses_dropped": 0, "commands_received": 0,
                         "commands_dropped": 0, "commands_foreign": 0, "late_ticks": 0,
                         "sessions": 0,
                         "rejected": {r: 0 for r in REASONS}}

    @property
    def address(self) -> tuple[str, int]:
        """(address, port) the bridge listens on."""
        return self._sock.getsockname()

    @property
    def faults(self) -> FaultPlan:
        return self._faults

    def compute_summary(self) -> str:
        """Compute per tick over the last COMPUTE_WINDOW ticks: p50, p99 and max, ms."""
        if not self.compute:
            return "compute per tick: no ticks"
        c = 1e3 * np.asarray(self.compute)
        return (f"compute per tick p50 {np.percentile(c, 50):.3f} / p99 "
                f"{np.percentile(c, 99):.3f} / max {c.max():.3f} ms over {c.size} ticks "
                f"(period {self.period * 1e3:g} ms)")

    @property
    def commands_lost(self) -> int:
        """Command sequence numbers skipped by the commands read (the status's
        commands_lost)."""
        return self._tracker.lost

    def inject(self, faults: FaultPlan) -> None:
        """Replace the fault plan while running; its `after` counts from now."""
        with self._lock:
            self._faults = faults
            self._fault_session = None
            self.fault_onset = None
            self.fault_onset_tick = None
            if self.start_wall is not None:
                self.first_enable_time = time.monotonic() - self.start_wall

    # --- the loop ----------------------------------------------------------------------------

    def run(self, duration: float | None = None) -> None:
        """Serve until `duration` s have passed, stop() is called, or forever."""
        self.start_wall = time.monotonic()
        last = 0.0
        deadline = self.start_wall
        while not self._stop.is_set():
            tick_start = time.monotonic()
            now = tick_start - self.start_wall
            if duration is not None and now >= duration:
                break
            with self._lock:
                command = self._drain(now)
                if (self.session_open and self._last_command_wall is not None
                        and now - self._last_command_wall > self.session_timeout):
                    self._close_session(now, f"no command for {self.session_timeout:g} s")
                self.bridge.step(now - last)
                last = now
                if command is not None:
                    self.bridge.set_command(command.velocity, command.enable)
                    if command.enable and self.first_enable_time is None:
                        self.first_enable_time = now
                if (self.bridge.enabled and self._last_command_wall is not None
                        and now - self._last_command_wall > self.command_timeout):
                    self.bridge.raise_fault(FAULT_COMMAND_TIMEOUT)
                active = self._fault_active(now)
                self._send_status(now, active)
            self.compute.append(time.monotonic() - tick_start)
            self.tick += 1
            deadline += self.period
            pause = deadline - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            elif pause < -10 * self.period:
                # Far behind (the host stalled): restart the schedule rather than burst.
                self.counters["late_ticks"] += 1
                deadline = time.monotonic()

    def _fault_active(self, now: float) -> bool:
        plan = self._faults
        if not plan.any or self.first_enable_time is None:
            return False
        if self.fault_onset is None:
            if now < self.first_enable_time + plan.after:
                return False
            self.fault_onset, self.fault_onset_tick = now, self.tick
            # Before any command (inject() at start-up), the faults belong to the first session.
            self._fault_session = max(self.session, 1)
            self._say(f"session {self.session}: injecting faults now ({now:.3f} s): "
                      f"{_plan_text(plan)}")
            if plan.fault_bits:
                self.bridge.raise_fault(plan.fault_bits)
        return True

    def _drain(self, now: float):
        newest = None
        active = self.fault_onset is not None
        for _ in range(256):
            try:
                data, sender = self._sock.recvfrom(4096)
            except (BlockingIOError, ConnectionRefusedError):
                break
            if self._fixed_controller is not None and sender != self._fixed_controller:
                self.counters["commands_foreign"] += 1
                continue
            if active and self._faults.drop and self._rng.random() < self._faults.drop:
                self.counters["commands_dropped"] += 1
                continue
            try:
                command = decode_command(data, self._m)
                self._accept_sequence(command, now, sender)
            except ProtocolError as e:
                self.counters["rejected"][e.reason] += 1
                self._note_rejection(e, sender)
                continue
            if not self.session_open:
                self._open_session(now, sender)
            self.counters["commands_received"] += 1
            self._session_commands += 1
            self._controller = sender
            self._last_command = command
            self._last_command_wall = now
            newest = command
            self.commands.append(ReceivedCommand(now, self.tick, command.sequence, command.time,
                                                 command.enable, command.velocity, active))
        return newest

    def _accept_sequence(self, command, now: float = 0.0, sender=None) -> None:
        """Order the command stream. A controller that starts again (a new `cdpm run`) greets
        with enable-clear commands from sequence 1; while the reels are at rest, such a
        command opens a new session instead of being dropped as old (hardware/PROTOCOL.md)."""
        try:
            self._tracker.accept(command.sequence)
        except ProtocolError as e:
            if e.reason != "sequence" or command.enable or self.bridge.enabled:
                raise
            self._tracker = SequenceTracker()
            self._tracker.accept(command.sequence)
            self.counters["sessions"] += 1
            if self.session_open:
                self._close_session(now, "a new controller session began")
            self._open_session(now, sender)

    # --- sessions ----------------------------------------------------------------------------

    def _say(self, text: str) -> None:
        if self._log is not None:
            self._log(text)

    def _open_session(self, now: float, sender) -> None:
        self.session += 1
        self.session_open = True
        self._session_start = now
        self._session_commands = 0
        self._session_rejected = {}
        where = f" by {sender[0]}:{sender[1]}" if sender else ""
        self._say(f"session {self.session} opened{where} at {now:.3f} s")
        if (self._fault_session is not None and self._fault_session < self.session
                and self._faults.any):
            # The plan was spent on an earlier session: this one runs clean. The bits the plan
            # raised are cleared (the operator reset the e-stop between runs); the bits the
            # bridge raised itself (COMMAND_TIMEOUT, OVERSPEED) stay, as on a real bridge.
            injected = self.bridge.faults & self._faults.fault_bits
            self._say(f"session {self.session}: no faults injected (the fault plan applied "
                      f"to session {self._fault_session})"
                      + (f"; injected fault bits {injected:#06x} cleared" if injected else ""))
            self.bridge.faults &= ~self._faults.fault_bits
            self._faults = FaultPlan()
        if self.session > 1:
            # The fault plan's clock restarts with each session (`after` counts from its first
            # enabling command); the first session keeps what inject() set.
            self.first_enable_time = None
            self.fault_onset = self.fault_onset_tick = None
            self._frozen, self._held = None, None
            self._delayed.clear()
            # Each rehearsal starts where the scenario does, as after a homing: the last run
            # left the platform wherever the hand took it.
            left = self.bridge.platform()
            self.bridge.reset()
            start = self.bridge.platform()
            self._say(f"session {self.session}: the platform is back at its start "
                      f"{_vector(start)} m (reset, as a homing would; the last session left it "
                      f"at {_vector(left)} m, {np.linalg.norm(left - start):.3f} m away), the "
                      f"operator's clock at 0")

    def _close_session(self, now: float, why: str) -> None:
        self.session_open = False
        rejected = _count_by_reason(self._session_rejected)
        self._say(f"session {self.session} closed at {now:.3f} s ({why}): "
                  f"{self._session_commands} commands accepted, rejected {rejected}, reels "
                  f"{'enabled' if self.bridge.enabled else 'at rest'}, faults "
                  f"{self.bridge.faults:#06x}")
        if hasattr(self.bridge, "summary"):  # what the plant went through in the session
            self._say(f"session {self.session}: {self.bridge.summary()}")

    def _note_rejection(self, e: ProtocolError, sender) -> None:
        n = self._session_rejected.get(e.reason, 0)
        self._session_rejected[e.reason] = n + 1
        if n == 0:  # the first of each reason per session; the rest are counted
            self._say(f"rejected a command from {sender[0]}:{sender[1]} ({e.reason}): {e}; "
                      f"further '{e.reason}' rejections are counted, not shown")

    def _send_status(self, now: float, active: bool) -> None:
        plan = self._faults if active else FaultPlan()
        if plan.stop:
            return
        if plan.freeze and self._frozen is not None:
            self._emit(self._frozen)
            return
        b = self.bridge
        self._sequence = next_sequence(self._sequence)
        c = self._last_command
        lengths = b.lengths.copy()
        if plan.nan:
            lengths[0] = np.nan
        data = encode_status(Status(
            sequence=self._sequence, time=now, lengths=lengths, force=b.force(),
            faults=b.faults, enabled=b.enabled,
            echo_sequence=None if c is None else c.sequence,
            echo_time=0.0 if c is None else c.time,
            commands_lost=self._tracker.lost % (1 << 32)), check=not plan.nan)
        self._frozen = data  # what a hung bridge task would keep resending
        rng = self._rng
        if plan.drop and rng.random() < plan.drop:
            self.counters["statuses_dropped"] += 1
            return
        if plan.corrupt and rng.random() < plan.corrupt:
            buf = bytearray(data)
            buf[int(rng.integers(len(buf)))] ^= int(rng.integers(1, 256))
            data = bytes(buf)
        copies = [data, data] if plan.duplicate and rng.random() < plan.duplicate else [data]
        if plan.reorder and self._held is None and rng.random() < plan.reorder:
            self._held = copies
            return
        if self._held is not None:
            copies, self._held = copies + self._held, None
        for d in copies:
            if plan.delay > 0:
                self._delayed.append((now + plan.delay, d))
            else:
                self._emit(d)
        while self._delayed and self._delayed[0][0] <= now:
            self._emit(self._delayed.popleft()[1])

    def _emit(self, data: bytes) -> None:
        if self._controller is None:
            return
        try:
            self._sock.sendto(data, self._controller)
            self.counters["statuses_sent"] += 1
        except OSError:
            pass  # the controller is gone; it is the one that must notice

    # --- in-process mode ---------------------------------------------------------------------

    def start(self) -> "ReelBridgeServer":
        """Serve from a daemon thread (tests, benchmarks)."""
        self._thread = threading.Thread(target=self.run, name="reel-bridge-emulator",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and release the socket. Commands that arrived since the last tick
        (a controller's shutdown burst, sent just before stop() is called) are read into
        `commands` and the counters first, not lost with the socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._sock.fileno() < 0:
            return  # stopped before
        if self._thread is None or not self._thread.is_alive():
            with self._lock:
                now = (time.monotonic() - self.start_wall if self.start_wall is not None
                       else 0.0)
                self._drain(now)
        self._sock.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


def _vector(v) -> str:
    return "[" + ", ".join(f"{x:.3f}" for x in np.asarray(v, dtype=float)) + "]"


def _count_by_reason(counts: dict) -> str:
    """{'value': 3, 'crc': 1} -> '4 (value 3, crc 1)'; {} -> '0'."""
    total = sum(counts.values())
    if not total:
        return "0"
    return f"{total} (" + ", ".join(f"{r} {n}" for r, n in counts.items() if n) + ")"


def _plan_text(plan: FaultPlan) -> str:
    """The fault plan's active settings, e.g. 'stop, drop 0.01'."""
    parts = []
    for f in dataclasses.fields(plan):
        value = getattr(plan, f.name)
        if f.name == "after" or value == f.default:
            continue
        parts.append(f.name if value is True else
                     f"{f.name} {value:#06x}" if f.name == "fault_bits" else f"{f.name} {value:g}")
    return ", ".join(parts) or "none"


# --- command line ----------------------------------------------------------------------------


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cdpm-reel-emulator", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="exit codes: 0 done (--duration), 1 error (robot, "
                                       "scenario, cannot listen), 2 bad usage, 130 after "
                                       "Ctrl-C, 143 after SIGTERM (the summary is printed "
                                       "first)")
    g = p.add_argument_group("robot and operator")
    g.add_argument("--scenario", help="take robot, cable swaps, start position, operator and "
                   "bridge address/port from this scenario (name or path)")
    g.add_argument("--scenario-text", help="YAML overlay applied to --scenario")
    g.add_argument("--robot", help="built-in robot name or robot YAML path "
                   "(default: paper_7cable, or the scenario's)")
    g.add_argument("--start", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="platform start position, base frame, m (default: workspace centre, "
                   "or the scenario's); the reels' initial lengths follow by inverse kinematics")
    g.add_argument("--length-offset", nargs=2, action="append", default=[],
                   metavar=("CABLE", "METRES"),
                   help="add METRES to cable CABLE's (1-based) initial length, to rehearse the "
                   "controller's refusal to enable on lengths that do not fit the robot")
    g.add_argument("--force", nargs=3, type=float, metavar=("FX", "FY", "FZ"),
                   help="constant operator force, base frame, N (overrides the scenario's)")
    g.add_argument("--plant", choices=("kinematic", "dynamic"), default="kinematic",
                   help="kinematic: reels with a first-order lag (default); dynamic: the "
                   "scenario's robot with mass, elastic cables, drive friction and the "
                   "operator (plant: !DynamicReels; its settings from the scenario's plant "
                   "when that is one)")
    g.add_argument("--time-constant", type=float, default=None,
                   help="reel velocity lag, s (default: 0.02; kinematic plant only)")
    n = p.add_argument_group("network")
    n.add_argument("--address", default=None,
                   help="address to listen on (default: 127.0.0.1, or the scenario's)")
    n.add_argument("--port", type=int, default=None,
                   help=f"UDP port to listen on (default: {DEFAULT_BRIDGE_PORT}, or the "
                   "scenario's)")
    n.add_argument("--controller", metavar="ADDRESS:PORT",
                   help="send statuses only there and ignore commands from anyone else "
                   "(default: answer the sender of the latest valid command)")
    n.add_argument("--period", type=float, default=0.002, help="status period, s (default 0.002)")
    n.add_argument("--command-timeout", type=float, default=0.05,
                   help="raise COMMAND_TIMEOUT when enabled and no command came for this "
                   "long, s (default 0.05)")
    n.add_argument("--duration", type=float, default=None, help="stop after this long, s")
    n.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="run under SCHED_FIFO at priority N (1..99; needs root or "
                   "CAP_SYS_NICE), as a real bridge's firmware would; default 0: normal")
    f = p.add_argument_group("fault injection (from --fault-after s after the first enable)")
    f.add_argument("--seed", type=int, default=0, help="random seed of the impairments")
    f.add_argument("--drop", type=float, default=0.0, help="share of datagrams dropped")
    f.add_argument("--delay", type=float, default=0.0, help="extra status latency, s")
    f.add_argument("--duplicate", type=float, default=0.0, help="share of statuses sent twice")
    f.add_argument("--reorder", type=float, default=0.0, help="share of statuses reordered")
    f.add_argument("--corrupt", type=float, default=0.0, help="share of statuses corrupted")
    f.add_argument("--freeze", action="store_true", help="repeat the last status forever")
    f.add_argument("--nan", action="store_true", help="report cable 1's length as NaN")
    f.add_argument("--stop", action="store_true", help="stop sending statuses")
    f.add_argument("--fault-bits", type=lambda s: int(s, 0), default=0,
                   help="raise these fault bits, e.g. 0x1 for ESTOP (see PROTOCOL.md)")
    f.add_argument("--fault-after", type=float, default=0.0,
                   help="seconds after the first enabling command before faults start")
    return p


def build_server(args, log=None) -> ReelBridgeServer:
    """The server described by parsed command-line arguments; `log` as ReelBridgeServer's."""
    from cdpm_drake.robot import load_robot

    force = None
    address, port = "127.0.0.1", DEFAULT_BRIDGE_PORT
    if args.scenario:
        from cdpm_drake.config import load_scenario, scenario_operator, scenario_robot

        scenario = load_scenario(args.scenario, args.scenario_text)
        robot = scenario_robot(scenario)
        start = scenario.initial_position
        force = scenario_operator(scenario).force
        address = getattr(scenario.plant, "address", address)
        port = getattr(scenario.plant, "port", port)
    else:
        robot = load_robot(args.robot or "paper_7cable")
        start = robot.workspace.center
    if args.scenario and args.robot:
        raise ValueError("give either --scenario or --robot, not both (the scenario names "
                         "its robot)")
    if args.start is not None:
        start = args.start
        box = robot.workspace
        if not box.contains(start):
            # The controller refuses to enable there (hardware.reels.start_pose_problem): a
            # rehearsal from such a start rehearses nothing else.
            raise ValueError(f"--start {[float(x) for x in start]!r} m is outside the workspace "
                             f"box of robot {robot.name!r} (lower {box.lower.tolist()!r}, "
                             f"upper {box.upper.tolist()!r} m); give a start inside it")
    lengths = cable_lengths(robot, np.asarray(start, dtype=float))
    for cable, metres in args.length_offset:
        k = int(cable)
        if not 1 <= k <= robot.num_cables:
            raise ValueError(f"--length-offset cable {cable!r}: cables are numbered "
                             f"1..{robot.num_cables}")
        lengths[k - 1] += float(metres)
    if args.force is not None:
        constant = np.asarray(args.force, dtype=float)
        force = lambda t, p, v: constant  # noqa: E731
    controller = None
    if args.controller:
        host, _, cport = args.controller.rpartition(":")
        if not host or not cport.isdigit():
            raise ValueError(f"--controller must be ADDRESS:PORT, got {args.controller!r}")
        controller = (host, int(cport))
    faults = FaultPlan(drop=args.drop, delay=args.delay, duplicate=args.duplicate,
                       reorder=args.reorder, corrupt=args.corrupt, freeze=args.freeze,
                       nan=args.nan, stop=args.stop, fault_bits=args.fault_bits,
                       after=args.fault_after)
    if args.plant == "dynamic":
        if args.time_constant is not None:
            raise ValueError("--time-constant sets the kinematic plant's lag; the dynamic "
                             "plant's drives come from the robot file's reel_drives section")
        bridge = DynamicBridge(_dynamic_scenario(args, robot, start),
                               length_offset=lengths - cable_lengths(robot, np.asarray(
                                   start, dtype=float)))
    else:
        bridge = ReelBridge(robot, lengths, force=force, time_constant=0.02
                            if args.time_constant is None else args.time_constant)
    return ReelBridgeServer(bridge, address=(args.address or address,
                                             args.port if args.port is not None else port),
                            faults=faults, period=args.period, seed=args.seed,
                            controller=controller, command_timeout=args.command_timeout,
                            record=0, log=log)


def _dynamic_scenario(args, robot, start):
    """The resolved scenario of `--plant dynamic`: the scenario's (or, with --robot, a
    scenario of that robot), at `start`, with --force as its operator, and a !DynamicReels
    plant (the scenario's own when it has one)."""
    import dataclasses as dc

    from cdpm_drake.kernels.plant.operators import NoOperator, ScriptedOperator
    from cdpm_drake.config import DynamicReels, Scenario, load_scenario, resolve_scenario

    if args.scenario:
        scenario = load_scenario(args.scenario, args.scenario_text)
    else:
        scenario = Scenario(robot=args.robot or "paper_7cable", swaps=[],
                            operator=NoOperator())
    plant = scenario.plant if isinstance(scenario.plant, DynamicReels) else DynamicReels()
    operator = scenario.operator
    if args.force is not None:
        operator = ScriptedOperator(times=[0.0], forces=[[float(f) for f in args.force]])
    scenario = dc.replace(scenario, plant=plant, operator=operator,
                          initial_position=[float(x) for x in start])
    resolved = resolve_scenario(scenario)
    if resolved.robot.num_cables != robot.num_cables:  # pragma: no cover - same robot
        raise ValueError("the scenario's robot changed under --plant dynamic")
    return resolved


def main(argv=None) -> int:
    """Exit codes as `cdpm`'s: 0 done (--duration), 1 error (robot, scenario, cannot bind),
    2 bad usage, 130 / 143 after Ctrl-C / SIGTERM (the summary is printed first)."""
    from cdpm_drake.text import prefixed_log_records

    with prefixed_log_records():
        return _main(argv)


def _main(argv) -> int:
    from cdpm_drake.runs.interrupt import exit_code, terminate_raises
    from cdpm_drake.robot import RobotError
    from cdpm_drake.config import ScenarioError

    parser = _parser()
    args = parser.parse_args(argv)
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        parser.error(f"--duration must be a number of seconds > 0, got {args.duration!r}")

    def say(text):
        print(f"cdpm-reel-emulator: {text}", flush=True)

    try:
        set_realtime_priority(args.rt_priority)
        server = build_server(args, log=say)
    except (RobotError, ScenarioError, OSError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else e
        print(f"cdpm-reel-emulator: error: {why}", file=sys.stderr)
        return 1
    except ValueError as e:  # a flag's value
        print(f"cdpm-reel-emulator: error: {e}", file=sys.stderr)
        return 2
    # A full garbage collection scans every object alive, modules included (19 ms measured
    # with pydrake loaded), long enough to trip the controller's watchdog; what exists now
    # lives for the whole run, so take it out of the collector's sight.
    gc.freeze()
    host, port = server.address
    robot = server.bridge.robot
    say(f"robot {robot.name!r} ({robot.num_cables} cables) on {host}:{port}, period "
        f"{server.period * 1e3:g} ms, {server.bridge.describe()}, start "
        f"{_vector(server.bridge.platform())} m"
        + (f", faults {_plan_text(server.faults)} from {server.faults.after:g} s after the "
           "first enable (one session)" if server.faults.any else ""))
    code = 0
    with terminate_raises():
        try:
            server.run(duration=args.duration)
        except KeyboardInterrupt as e:
            code = exit_code(e)
        finally:
            server.stop()
            now = time.monotonic() - server.start_wall if server.start_wall else 0.0
            if server.session_open:
                server._close_session(now, "the emulator stopped")
            c = server.counters
            rejected = {r: n for r, n in c["rejected"].items() if n}
            say(f"{c['commands_received']} commands received ({server.session} controller "
                f"session(s)), rejected {_count_by_reason(rejected)}, {c['statuses_sent']} "
                f"statuses sent, commands lost {server.commands_lost}, faults "
                f"{server.bridge.faults:#06x}")
            say(server.compute_summary())
    return code

