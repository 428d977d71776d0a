"""What every hardware plant implements (hardware/INTERFACE.md): the Drake ports the diagram
wires and the resources `cdpm run` (runs/realtime.py) drives. HardwareReelsSystem (the UDP
reel bridge) and CanopenReelsSystem (CiA 402 drives) both do; an EtherCAT plant would too.
No Drake here: a typing.Protocol checked by the tests.
"""

import typing

# The plant's ports, as the simulated plants': reel_velocity_command (m/s of cable, + pays
# out) in; cable_lengths (m), measured_force (N, base frame, the handle's sensor, tared) and
# tension_measured (N per cable, NaN where unknown) out.
INPUT_PORTS = ("reel_velocity_command",)
OUTPUT_PORTS = ("cable_lengths", "measured_force", "tension_measured")


@typing.runtime_checkable
class HardwarePlant(typing.Protocol):
    """A Drake LeafSystem driving real reels, named `reels` in the diagram.

    Its initialisation event opens the link, checks the start (the measured lengths fit the
    robot, the pose is in the workspace and held, the force sensor tared) and enables, or
    raises ReelFault before anything moves. Its periodic discrete update (the control period)
    reads the link into the output state and judges it; its periodic publish sends the ramped
    command, or, after a fault, the stop, and raises ReelFault (hardware/reels.py) to end the
    run with its log."""

    @property
    def link(self):
        """The link's counters (`link.counters`: sent, received, accepted, lost, rejected,
        foreign; as_dict() for the report), None before it is open."""

    def shutdown(self) -> None:
        """Zero reel velocity with the drives disabled; safe at any time, more than once."""

    def close(self) -> None:
        """shutdown(), then release the link and the force sensor."""

    def book(self, context) -> dict:
        """Diagnostics for the report: enabled, ramp, fault, fault_time, ticks,
        commands_lost, holds, longest_hold."""
