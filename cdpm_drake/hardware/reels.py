"""HardwareReelsSystem: the real reels (through the reel bridge) as a Drake plant.

It has the simulated plant's ports, so the controller diagram does not change. Events at the
control rate (period `time_step`):

* initialisation (inside Simulator.Initialize): waits up to `startup_timeout` for the bridge's
  first status, checks the measured lengths against the robot file, then enables with the
  velocity ramp at 0. The state starts from those lengths, so the controller's forward
  kinematics starts from the measured pose, not from the scenario's start.
* publish at t_k: sends ramp x reel_velocity_command(t_k) (zero while disabled).
* discrete update at t_k: drains the link, keeps the newest valid status, runs the
  watchdog and advances the ramp. A discrete update, like the simulated reels', so every
  block's update at t_k sees the same sample: an unrestricted update would run before the
  other blocks' discrete updates and feed them tick k+1's lengths and force (the sensor filter
  would count a sample twice). (Drake handles a step's publishes before the next step's
  updates, so the command sent at t_k uses the lengths read at t_{k-1}.)

A fault (a bridge fault bit, a non-finite command) sends zero velocity with enable off at
once, latches in the state, and the next publish raises ReelFault, which ends
Simulator.AdvanceTo. (pydrake 1.51 crashes the process when a Python LeafSystem's event returns
EventStatus.Failed(self, ...); a raised exception propagates out of AdvanceTo unchanged.)

The watchdog (no valid status for `watchdog_ticks` ticks and (watchdog_ticks - 1) periods of
wall time) also sends zero velocity with enable off at once, then holds: it sends nothing more
and waits up to `resume_within` s (wall clock) for the bridge to answer. A valid status that
echoes the stop, with no status lost since the silence began, proves the link whole again: the
reels are re-enabled, ramping from rest, and the run goes on. Anything else (the time runs out,
a status lost, a fault bit) latches the fault as above. Why: a bridge that is paused, not
broken, e.g. an emulator on a virtual machine whose host holds a virtual CPU for 5-15 ms
(measured on the shared VM this was developed on: scripts/bench/soak_realtime.py), would otherwise
end a person's interaction; the reels stop within the same `watchdog_ticks` either way.

Lockstep (`config.lockstep`, against `cdpm emulate --lockstep`, which steps its plant one
period per command): each update waits (up to startup_timeout s of wall clock) for the status
that echoes the last command sent, and the watchdog and resume_within count ticks of the
context's clock instead of wall-clock seconds; the run is then the same on any host.

Protocol version (hardware/PROTOCOL.md "Versions"): the start-up greetings alternate version 2
and version 1; the first status that settles it fixes the version for the run (book
PROTOCOL). With version 2, each status's drive forces, reel speeds and load cells give the
`tension_measured` output by `config.tension_sensor` (drive_torque: the reel's equation of
motion, kernels/drive_torque.py, with the robot file's reel_drives; load_cell; none: NaN);
NaN where a reading is missing, and always with a version-1 bridge. It is computed in the same
discrete update as the lengths, with numpy and one compiled kernel (compiled in the
constructor, never on the real-time path), and nothing in it raises.

The socket is a resource, not state: it is held as an attribute because it cannot be copied
into or restored from a Context. Everything that changes what the system outputs or sends
(lengths, force, sequence numbers, watchdog counter, fault latch, enable flag, ramp) lives in
the Context.
"""

import dataclasses
import gc
import time

import numpy as np
from pydrake.systems.framework import LeafSystem

from cdpm_drake.kernels.drive_torque import drive_model, tension_from_drive
from cdpm_drake.kernels.kinematics import KinematicsError, cable_lengths, forward_kinematics
from cdpm_drake.hardware.config import (HardwareReels, check_hardware_reels, check_homing,
                                        resolved_position_offset)
from cdpm_drake.hardware.link import ReelLink
from cdpm_drake.robot.stretch import derived_length_residual
from cdpm_drake.hardware.protocol import (VERSION, VERSIONS, fault_names, next_sequence,
                                          sequence_delta)
from cdpm_drake.hardware.force_config import NetFT
from cdpm_drake.hardware.force_sources import (RDT_STATUS_ERROR, ForceSensorError,
                                               NetFTSource)

# Book-keeping state vector (float64; 32-bit sequence numbers are exact in a double).
STATUS_SEQ = 0        # sequence of the last accepted status
HAVE_STATUS = 1       # 1 once a status was accepted
COMMAND_ECHO = 2      # last command sequence the bridge echoed (-1: none)
MISSED = 3            # consecutive ticks without a valid status
ENABLED = 4           # 1: commands carry enable and the ramped velocity
RAMP = 5              # velocity scale, 0..1
LAST_STATUS_WALL = 6  # time.monotonic() when the last valid status was read, s
FAULT = 7             # fault latch: one of the FAULT_* reasons below (0: none)
FAULT_BITS = 8        # the bridge's fault bits when FAULT == FAULT_BRIDGE
FAULT_TIME = 9        # context time at which the fault latched, s
STATUS_TIME = 10      # the last status's `time` field (echoed in commands), s
COMMANDS_LOST = 11    # the bridge's count of commands it never received
HOLD = 12             # 1 while the watchdog holds the reels stopped and waits for the bridge
HOLD_WALL = 13        # time.monotonic() when the hold began, s
HOLD_TIME = 14        # context time when the hold began (zero velocity sent), s
HOLD_SEQUENCE = 15    # sequence of the hold's first stop command: the bridge must echo it
HOLD_LOST = 16        # the link's count of lost statuses when the hold began
HOLD_MISSED = 17      # silent ticks when the watchdog stopped the reels
HOLDS = 18            # holds that ended with the bridge answering (the run went on)
LONGEST_HOLD = 19     # the longest of those, s (wall clock)
PROTOCOL = 20         # the protocol version agreed with the bridge at start-up (1 or 2)
SPEED_TIME = 21       # the `time` of the status whose reel speeds the state holds, s (NaN: none)
BOOK_SIZE = 22

# Lockstep: how long a start-up greeting waits for its answer before the next, s (a
# version-1 bridge never answers the version-2 one).
LOCKSTEP_GREETING = 0.5

# A reel acceleration is taken from two statuses at most this far apart on the bridge's
# clock, s; further apart (a long silence, a bridge restart) it is unknown (NaN).
MAX_ACCEL_INTERVAL = 0.1

# Why the run stops: a silent bridge (no answer within resume_within), a bridge fault bit, a
# bridge that answered the watchdog's stop after losing statuses on the way, the handle's Net
# F/T silent or reporting an error (its status in FAULT_BITS).
FAULT_NONE, FAULT_WATCHDOG, FAULT_BRIDGE, FAULT_WATCHDOG_LOSS, FAULT_FORCE = 0, 1, 2, 3, 4


class ReelFault(RuntimeError):
    """The hardware plant ended the run. Zero reel velocity with enable off was sent first.
    `time` is the context time of the fault, s."""

    def __init__(self, message: str, time: float | None = None):
        super().__init__(message)
        self.time = time


class HardwareReelsSystem(LeafSystem):
    """The reels and force sensor behind a reel bridge, over UDP (hardware/PROTOCOL.md).

    .. pydrake_system::

        name: reels
        input_ports:
        - reel_velocity_command (m/s of cable, one per cable, + pays out)
        output_ports:
        - cable_lengths (m, one per cable, as measured)
        - measured_force (N, base frame, raw sensor sample)
        - tension_measured (N, one per cable; NaN where there is no reading)

    `robot`: the robot (after cable swaps); its reel speed limit scales down any command
    above it (the direction of motion is kept). `config`: a HardwareReels. `time_step`: the
    control period, s.
    """

    def __init__(self, robot, config: HardwareReels, time_step: float = 0.002):
        super().__init__()
        check_hardware_reels(config)
        if not (isinstance(time_step, (int, float)) and np.isfinite(time_step)
                and time_step > 0):
            raise ValueError(f"time_step must be a finite number > 0 s, got {time_step!r}")
        self._robot = robot
        if config.max_length_residual is None:  # derived from the robot's cables
            config = dataclasses.replace(
                config, max_length_residual=derived_length_residual(robot))
        self._config = config
        self._T = float(time_step)
        self._m = m = robot.num_cables
        check_homing(config, m)
        # The homing's offsets, added to every status's lengths (docs/on_the_robot.md).
        self._offset = np.array(resolved_position_offset(config, m))
        self._vmax = float(robot.limits.max_reel_speed)
        # The controller's model of its reel drives (robot file reel_drives), at the cable,
        # its kernel compiled now (not on the real-time path).
        self._drive_model = drive_model(robot.dynamics, m)
        self._sensor = config.tension_sensor
        self._ramp_step = 1.0 if config.ramp_time == 0 else self._T / config.ramp_time
        # A catch-up burst of ticks after a stall of this process runs faster than the bridge
        # sends; the watchdog also waits this much wall-clock time so such a burst cannot
        # trip it, while a silent bridge still trips it on the N-th tick.
        self._silence = (config.watchdog_ticks - 1) * self._T
        # Lockstep (config.lockstep): ticks are the clock; no catch-up burst to allow for.
        self._lockstep = bool(config.lockstep)
        if self._lockstep:
            self._silence = 0.0
        self._link: ReelLink | None = None
        # link.counters.sent right after the last shutdown's copies (None: not stopped yet):
        # like the socket, a fact about the link, not about the controller's state.
        self._stopped_at: int | None = None
        # The handle's force from a Net F/T instead of the bridge's status (a resource, as
        # the socket); its records counted, ticks without one, time.monotonic() of the last.
        sensor = config.force_sensor
        self.force_source = NetFTSource(sensor) if isinstance(sensor, NetFT) else None
        self._hand = self.DeclareDiscreteState(np.zeros(3))

        self._command = self.DeclareVectorInputPort("reel_velocity_command", m)
        # Placeholders until the initialisation event reads the bridge.
        self._lengths = self.DeclareDiscreteState(cable_lengths(robot, robot.workspace.center))
        self._force = self.DeclareDiscreteState(3)
        book = np.zeros(BOOK_SIZE)
        book[COMMAND_ECHO] = -1.0
        self._book = self.DeclareDiscreteState(book)
        # The last reel speeds received (m/s; for the acceleration) and the tensions, N.
        self._speed = self.DeclareDiscreteState(np.full(m, np.nan))
        self._tension = self.DeclareDiscreteState(np.full(m, np.nan))
        self.DeclareStateOutputPort("cable_lengths", self._lengths)
        self.DeclareStateOutputPort("measured_force", self._force)
        self.DeclareStateOutputPort("tension_measured", self._tension)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._initialize_from_bridge)
        self.DeclarePeriodicDiscreteUpdateEvent(self._T, 0.0, self._update_from_bridge)
        self.DeclarePeriodicPublishEvent(self._T, 0.0, self._publish_command)

    # --- resources ---------------------------------------------------------------------------

    @property
    def link(self) -> ReelLink | None:
        """The open link (None before initialisation); its `counters` are the run's packet
        statistics."""
        return self._link

    def _open_link(self) -> ReelLink:
        if self._link is None or self._link.closed:
            c = self._config
            self._link = ReelLink(self._m, bridge=(c.address, c.port),
                                  local=(c.local_address, c.local_port))
        return self._link

    def shutdown(self) -> None:
        """Send zero velocity with enable off (`shutdown_repeats` copies). Safe to call at any
        time and more than once, e.g. from the CLI's Ctrl-C / SIGTERM handling: the copies go
        out once per stop (a fault stops from the update, the publish and the run's clean-up),
        and again only after another command was sent (hardware/PROTOCOL.md)."""
        link = self._link
        if link is None or link.closed or self._stopped_at == link.counters.sent:
            return
        # Version 1, whatever was agreed: every bridge reads it.
        for _ in range(self._config.shutdown_repeats):
            link.send_command(np.zeros(self._m), enable=False, echo_sequence=None)
        self._stopped_at = link.counters.sent

    def close(self) -> None:
        """shutdown(), then release the socket (and the Net F/T's)."""
        self.shutdown()
        if self._link is not None:
            self._link.close()
        if self.force_source is not None:
            self.force_source.close()

    def book(self, context) -> dict:
        """The book-keeping state as a dict (diagnostics: sequence numbers, watchdog, ramp)."""
        b = context.get_discrete_state(self._book).get_value()
        names = ("status_sequence", "have_status", "command_echo", "missed_ticks", "enabled",
                 "ramp", "last_status_wall", "fault", "fault_bits", "fault_time",
                 "status_time", "commands_lost", "hold", "hold_wall", "hold_time",
                 "hold_sequence", "hold_lost", "hold_missed", "holds", "longest_hold",
                 "protocol_version", "speed_time")
        return {k: float(b[i]) for i, k in enumerate(names)}

    # --- events ------------------------------------------------------------------------------

    def _initialize_from_bridge(self, context, state):
        c = self._config
        link = self._open_link()
        zero = np.zeros(self._m)
        deadline = time.monotonic() + c.startup_timeout
        status, version = None, None
        first_v2 = None  # the sequence of the first version-2 greeting
        greeting = VERSION
        while version is None:
            # Zero-velocity, enable-off greetings tell the bridge where to send its statuses;
            # they alternate versions 2 and 1 until a status settles which one it speaks.
            sent = link.send_command(zero, enable=False, echo_sequence=None,
                                     time=context.get_time(), version=greeting)
            if greeting == 2 and first_v2 is None:
                first_v2 = sent
            greeting = 1 if greeting == 2 else VERSION
            # In lockstep each greeting is answered (by a bridge of its version) only when
            # the bridge got to it: wait longer than a period, so one greeting makes one tick.
            link.wait(min(LOCKSTEP_GREETING if self._lockstep else self._T,
                          max(0.0, deadline - time.monotonic())))
            status = link.receive(None, VERSIONS)
            version = agreed_version(status, first_v2)
            if version is None and time.monotonic() >= deadline:
                raise ReelFault(
                    f"no valid status from the reel bridge at {c.address}:{c.port} within "
                    f"startup_timeout = {c.startup_timeout:g} s; is the bridge (or "
                    f"cdpm-reel-emulator) running and configured with this robot's "
                    f"{self._m} cables? {self._link_summary()}", context.get_time())
        if status.faults:
            self.shutdown()
            raise ReelFault(
                f"refusing to enable the reels: the reel bridge reports fault bits "
                f"{status.faults:#06x} ({', '.join(fault_names(status.faults))}) at startup",
                context.get_time())
        lengths = status.lengths + self._offset
        try:
            p = forward_kinematics(self._robot, lengths, max_residual=c.max_length_residual)
        except KinematicsError as e:
            self.shutdown()
            raise ReelFault(
                f"refusing to enable the reels: the measured cable lengths "
                f"{np.round(lengths, 4).tolist()} m (the bridge's plus position_offset) do "
                f"not fit robot {self._robot.name!r} ({self._robot.source}) within "
                f"max_length_residual = {c.max_length_residual:g} m: {e}. Check the robot "
                f"file, the cable numbering and the homing (position_offset).",
                context.get_time()) from None
        problem = start_pose_problem(self._robot, p)
        if problem:
            self.shutdown()
            raise ReelFault(f"refusing to enable the reels: {problem}", context.get_time())
        state.get_mutable_discrete_state(self._lengths).SetFromVector(lengths)
        state.get_mutable_discrete_state(self._force).SetFromVector(status.force)
        speed = state.get_mutable_discrete_state(self._speed).get_mutable_value()
        tension = state.get_mutable_discrete_state(self._tension).get_mutable_value()
        speed[:] = np.nan
        tension[:] = np.nan
        book = np.zeros(BOOK_SIZE)
        book[PROTOCOL] = version
        book[SPEED_TIME] = np.nan
        self._measure_tension(book, status, speed, tension)
        book[STATUS_SEQ] = status.sequence
        book[HAVE_STATUS] = 1.0
        book[COMMAND_ECHO] = -1.0 if status.echo_sequence is None else status.echo_sequence
        book[ENABLED] = 1.0
        book[RAMP] = 0.0
        book[LAST_STATUS_WALL] = context.get_time() if self._lockstep else time.monotonic()
        book[STATUS_TIME] = status.time
        book[COMMANDS_LOST] = status.commands_lost
        state.get_mutable_discrete_state(self._book).SetFromVector(book)
        if self.force_source is not None:
            self._start_netft(context, state)

    def _start_netft(self, context, state) -> None:
        """Open the Net F/T's stream and tare it (the handle left alone), before the first
        enabling command; the force state from its newest record."""
        try:
            self.force_source.open()
            self.force_source.tare()
        except (OSError, ForceSensorError) as e:
            self.shutdown()
            raise ReelFault(f"refusing to enable the reels: {e}", context.get_time()) from None
        state.get_mutable_discrete_state(self._force).SetFromVector(self.force_source.force())
        state.get_mutable_discrete_state(self._hand).SetFromVector(
            [self.force_source.records, -1.0, time.monotonic()])

    def _read_netft(self, context, state, book, now) -> None:
        """The Net F/T's newest record into the force state; a silence of
        force_sensor.missed_ticks ticks (and as many periods less one of wall time) or an
        error status latches FAULT_FORCE."""
        src = self.force_source
        src.poll()
        count0, missed, heard = context.get_discrete_state(self._hand).get_value()
        missed, heard = (0.0, now) if src.records != count0 else (missed + 1.0, heard)
        state.get_mutable_vector(self._hand).SetFromVector([src.records, missed, heard])
        state.get_mutable_vector(self._force).SetFromVector(src.force())
        limit = src.config.missed_ticks
        if src.status & RDT_STATUS_ERROR:
            book[FAULT], book[FAULT_BITS] = FAULT_FORCE, float(src.status)
        elif missed >= limit and now - heard >= (limit - 1) * self._T:
            book[FAULT], book[FAULT_BITS] = FAULT_FORCE, -missed

    def _update_from_bridge(self, context, state):
        book = context.get_discrete_state(self._book).get_value().copy()
        if book[FAULT] != FAULT_NONE:
            return  # latched; the next publish ends the run
        link = self._open_link()
        last = int(book[STATUS_SEQ]) if book[HAVE_STATUS] else None
        versions = (int(book[PROTOCOL]),) if book[PROTOCOL] else VERSIONS
        if self._lockstep:
            status = self._receive_answer(link, last, versions, book)
            now = context.get_time()  # the watchdog's clock: ticks x period
        else:
            status = link.receive(last, versions)
            now = time.monotonic()
        if status is not None:
            state.get_mutable_vector(self._lengths).SetFromVector(status.lengths + self._offset)
            state.get_mutable_vector(self._force).SetFromVector(status.force)
            self._measure_tension(
                book, status, state.get_mutable_vector(self._speed).get_mutable_value(),
                state.get_mutable_vector(self._tension).get_mutable_value())
            book[STATUS_SEQ] = status.sequence
            book[HAVE_STATUS] = 1.0
            if status.echo_sequence is not None:
                book[COMMAND_ECHO] = status.echo_sequence
            book[MISSED] = 0.0
            book[LAST_STATUS_WALL] = now
            book[STATUS_TIME] = status.time
            book[COMMANDS_LOST] = status.commands_lost
            if status.faults:
                book[FAULT], book[FAULT_BITS] = FAULT_BRIDGE, status.faults
        else:
            book[MISSED] += 1.0
        if self.force_source is not None and book[FAULT] == FAULT_NONE:
            self._read_netft(context, state, book, now)
        if book[FAULT] == FAULT_NONE:
            if book[HOLD]:
                self._judge_hold(book, status, now, link)
            elif (status is None and book[MISSED] >= self._config.watchdog_ticks
                    and now - book[LAST_STATUS_WALL] >= self._silence):
                self._start_hold(book, context.get_time(), now, link)
        if book[FAULT] != FAULT_NONE:
            # A fault that ends a hold happened when the reels were stopped.
            book[FAULT_TIME] = book[HOLD_TIME] if book[HOLD] else context.get_time()
            book[HOLD] = 0.0
            book[ENABLED] = 0.0
            book[RAMP] = 0.0
            # Stop now rather than at the next publish, one tick later.
            self.shutdown()
        elif book[ENABLED]:
            book[RAMP] = min(1.0, book[RAMP] + self._ramp_step)
        state.get_mutable_vector(self._book).SetFromVector(book)

    def _receive_answer(self, link, last, versions, book):
        """Lockstep: the newest valid status once one answers the last command sent (echoes
        its sequence), waiting up to startup_timeout s of wall clock for it; whatever came
        (maybe None) when the time is up. No wait when the last command was answered
        already (a hold sends nothing)."""
        target = link.last_sent_sequence
        echo = int(book[COMMAND_ECHO])
        newest = None
        if echo >= 0 and sequence_delta(echo, target) >= 0:
            return link.receive(last, versions)
        deadline = time.monotonic() + self._config.startup_timeout
        while True:
            status = link.receive(last, versions)
            if status is not None:
                newest, last = status, status.sequence
                if (status.echo_sequence is not None
                        and sequence_delta(status.echo_sequence, target) >= 0):
                    return newest
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return newest
            link.wait(remaining)

    def _measure_tension(self, book, status, speed, tension) -> None:
        """The cables' tensions (N) into `tension` from a new status, by the tension sensor;
        `speed` holds the previous status's reel speeds (m/s) and takes this one's. NaN where a
        reading is missing; never raises (numpy and a compiled kernel with numpy's error
        model: NaN and inf propagate)."""
        if status.version < 2 or self._sensor == "none":
            tension[:] = np.nan
            return
        if self._sensor == "load_cell":
            tension[:] = status.load_cell
            return
        w = status.reel_speed
        dt = status.time - book[SPEED_TIME]  # NaN without an earlier speed
        if 0.0 < dt <= MAX_ACCEL_INTERVAL:
            accel = (w - speed) / dt
        elif np.isnan(book[SPEED_TIME]):
            # The first status (start-up, drives disabled): a reel at rest (within the
            # drives' dead band) is not accelerating, so its tension is known from the first
            # tick, as the simulated sensor's is; a moving one waits for a second speed.
            accel = np.where(np.abs(w) <= self._drive_model[3], 0.0, np.nan)
        else:
            accel = np.full(self._m, np.nan)
        tension_from_drive(status.drive_force, w, accel, *self._drive_model, tension)
        speed[:] = w
        book[SPEED_TIME] = status.time

    def _start_hold(self, book, t, now, link) -> None:
        """The watchdog: stop the reels now (zero velocity, enable off), then hold for the
        bridge's answer, or latch at once when resume_within is 0."""
        book[HOLD_MISSED] = book[MISSED]
        if self._config.resume_within <= 0:
            book[FAULT] = FAULT_WATCHDOG
            return
        book[HOLD], book[HOLD_WALL], book[HOLD_TIME] = 1.0, now, t
        book[HOLD_SEQUENCE] = next_sequence(link.last_sent_sequence)
        book[HOLD_LOST] = link.counters.lost
        book[ENABLED] = 0.0
        book[RAMP] = 0.0
        self.shutdown()  # the stop commands: sequences HOLD_SEQUENCE onwards

    def _judge_hold(self, book, status, now, link) -> None:
        """While holding: resume when a status answers the stop in time with nothing lost on
        the way; latch when the time is up or statuses were lost."""
        # (In lockstep `now` is the context time: resume_within counts ticks.)
        if now - book[HOLD_WALL] > self._config.resume_within:
            book[FAULT] = FAULT_WATCHDOG
        elif link.counters.lost != book[HOLD_LOST]:
            # Statuses went missing, not just late: a lossy link, not a paused bridge.
            book[FAULT] = FAULT_WATCHDOG_LOSS
        elif (status is not None and status.echo_sequence is not None
              and sequence_delta(status.echo_sequence, int(book[HOLD_SEQUENCE])) >= 0):
            # The bridge read the stop and answered: the round trip is whole again.
            book[HOLD] = 0.0
            book[ENABLED] = 1.0  # the ramp starts again from 0
            book[HOLDS] += 1.0
            book[LONGEST_HOLD] = max(book[LONGEST_HOLD], now - book[HOLD_WALL])

    def _publish_command(self, context):
        book = context.get_discrete_state(self._book).get_value()
        link = self._open_link()
        if book[FAULT] != FAULT_NONE:
            self.shutdown()
            raise ReelFault(self._fault_message(book), float(book[FAULT_TIME]))
        if book[HOLD]:
            return  # the stop went out; nothing more until the bridge answers it
        u = self._command.Eval(context)
        bad = ~np.isfinite(u)
        if bad.any():
            self.shutdown()
            k = int(np.argmax(bad))
            raise ReelFault(
                f"reel fault at t = {context.get_time():.3f} s: reel_velocity_command of cable "
                f"{k + 1} is {float(u[k])!r} m/s; zero reel velocity sent", context.get_time())
        if book[ENABLED]:
            v = book[RAMP] * u
            peak = float(np.max(np.abs(v)))
            if peak > self._vmax:
                v = v * (self._vmax / peak)
        else:
            v = np.zeros(self._m)
        echo = int(book[STATUS_SEQ]) if book[HAVE_STATUS] else None
        link.send_command(v, enable=bool(book[ENABLED]), echo_sequence=echo,
                          echo_time=float(book[STATUS_TIME]), time=context.get_time(),
                          version=int(book[PROTOCOL]) or 1)

    # --- messages ----------------------------------------------------------------------------

    def _link_summary(self) -> str:
        if self._link is None:
            return "link: not open"
        k = self._link.counters
        rejected = {r: n for r, n in k.rejected.items() if n}
        text = (f"link: sent {k.sent}, received {k.received}, accepted {k.accepted}, "
                f"rejected {rejected or 0}, foreign {k.foreign}")
        if self._link.last_error:
            text += f"; last rejected datagram: {self._link.last_error}"
        return text

    def _fault_message(self, book) -> str:
        c = self._config
        t = float(book[FAULT_TIME])
        if book[FAULT] == FAULT_FORCE:
            detail, src = float(book[FAULT_BITS]), self.force_source
            why = (f"no record from the handle's force sensor ({src.describe()}) for "
                   f"{int(-detail)} ticks (force_sensor.missed_ticks = "
                   f"{src.config.missed_ticks})" if detail < 0 else src.status_problem())
        elif book[FAULT] == FAULT_BRIDGE:
            bits = int(book[FAULT_BITS])
            why = (f"the reel bridge reports fault bits {bits:#06x} "
                   f"({', '.join(fault_names(bits))})")
        else:
            n = int(book[HOLD_MISSED])
            why = (f"no valid status from the reel bridge at {c.address}:{c.port} for {n} ticks "
                   f"({n * self._T * 1e3:.0f} ms; watchdog_ticks = {c.watchdog_ticks})")
            if book[FAULT] == FAULT_WATCHDOG_LOSS:
                lost = self._link.counters.lost - int(book[HOLD_LOST]) if self._link else 0
                why += (f", and the statuses that came back had skipped {lost} (lost or "
                        f"rejected on the way: a faulty link, not a paused bridge)")
            elif c.resume_within > 0:
                why += (f", and none answered the stop within resume_within = "
                        f"{c.resume_within * 1e3:g} ms")
        return (f"reel fault at t = {t:.3f} s: {why}; zero reel velocity sent. "
                f"{self._link_summary()}")


def agreed_version(status, first_v2) -> int | None:
    """The protocol version a start-up status settles (hardware/PROTOCOL.md "Versions"), or
    None while it is open: 2 for a version-2 status; 1 for a version-1 status that echoes a
    command sent after the first version-2 greeting (sequence `first_v2`), which the bridge
    would have answered in version 2 had it read it."""
    if status is None:
        return None
    if status.version >= 2:
        return 2
    if (first_v2 is not None and status.echo_sequence is not None
            and sequence_delta(status.echo_sequence, first_v2) >= 1):
        return 1
    return None


# Where the reels may be enabled: the platform centre that the measured lengths give inside
# the robot's workspace box, give or take START_BOX_TOLERANCE (m: an encoder offset well below
# a millimetre must not refuse a platform resting on a face, which the virtual wall keeps
# inside from the first tick; a platform centimetres out is outside), and held by its
# cables: t* of the level platform there (statics.holding_tension) >= START_MIN_T_STAR (N).
# Zero is where holding stops being possible at all: below it no set of tensions >= 0
# balances the platform's weight (a cable would have to push), so the platform is not at rest
# where the lengths put it (it hangs tilted, a cable is slack, or the lengths are wrong), and
# the controller's model of it fails from the first tick. A higher floor (the 5 N of `cdpm
# info`) would refuse poses the cables do hold: 21 % of the built-in robot's box (27 % with
# exp2's swapped cables; 11 x 11 x 11 grid), where a run may start and move on from.
START_BOX_TOLERANCE = 0.001
START_MIN_T_STAR = 0.0


def start_pose_problem(robot, p) -> str:
    """Why the reels must not be enabled with the platform centre at p (base frame, m), in
    words naming the pose and the box; "" when they may. A robot whose cables cannot balance
    moments (wrench-matrix rank < 6 at the workspace centre: it is modelled as translating)
    is judged by the forces alone (the platform as a point)."""
    from cdpm_drake.robot import robot_statics
    from cdpm_drake.kernels.tension import gravity_wrench
    from cdpm_drake.robot.statics import holding_tension
    from cdpm_drake.robot.tension_program import max_min_tension

    p = np.asarray(p, dtype=float)
    box = robot.workspace
    where = (f"the platform centre p = {_vector(p)} m (from the measured cable lengths)")
    if not box.contains(p, START_BOX_TOLERANCE):
        out = np.maximum(box.lower - p, p - box.upper)
        k = int(np.argmax(out))
        return (f"{where} is outside the workspace box of robot {robot.name!r} "
                f"({robot.source}): lower {_vector(box.lower)} m, upper {_vector(box.upper)} m "
                f"({1000 * out[k]:.1f} mm beyond its {'xyz'[k]} "
                f"{'lower' if p[k] < box.lower[k] else 'upper'} face). Bring the platform "
                "into the box (by hand with the drives off, or by a homing) first")
    mass = robot.dynamics.mass
    if robot_statics(robot).rank < 6:
        rho = robot.reels - p  # the cables' directions from a point platform
        t_star = max_min_tension((rho / np.linalg.norm(rho, axis=1, keepdims=True)).T,
                                 gravity_wrench(mass)[:3])
        model = "the platform as a point (forces only: the robot's cables cannot balance moments)"
    else:
        t_star = float(holding_tension(robot, p))
        model = "the level platform"
    if not t_star >= START_MIN_T_STAR:
        return (f"the cables cannot hold {model} ({mass:g} kg) at {where}: its largest "
                f"achievable minimum tension t* is {t_star:.2f} N < {START_MIN_T_STAR:g} N, "
                "so no cable tensions >= 0 balance its weight there (a cable would have to "
                "push); the platform is not at rest where the lengths put it (tilted, a cable "
                "slack, or the encoders are off). `cdpm info` shows where in the box the "
                "cables hold it")
    return ""


def _vector(v) -> str:
    return "[" + ", ".join(f"{x:.3f}" for x in np.asarray(v, dtype=float)) + "]"


def start_realtime(simulator, rate: float = 1.0) -> None:
    """Initialise a simulator holding a HardwareReelsSystem for a real-time run.

    Initialize() blocks while the reels wait for the bridge; Drake starts its real-time clock
    before that, so without ResetStatistics() the first ticks would race to catch up. The
    build's garbage is collected before the reels are enabled (a full collection takes
    20-60 ms with pydrake loaded, more than the watchdog allows; the bridge's own command
    timeout starts with the first enabling command). The objects alive by then (modules, the
    diagram) live for the whole run: gc.freeze() takes them out of every later collection.
    (realtime.run also keeps the collector out of the ticks: see its docstring.)"""
    simulator.set_target_realtime_rate(rate)
    gc.collect()
    simulator.Initialize()
    gc.freeze()
    simulator.ResetStatistics()
