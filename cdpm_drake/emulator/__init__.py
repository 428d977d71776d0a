"""The reel-bridge emulator (`cdpm-reel-emulator`, `cdpm emulate`): the reel bridge played on
loopback, to rehearse a run before the robot. The protocol is hardware/PROTOCOL.md.

    server.py   ReelBridgeServer: the bridge on a UDP socket, its sessions and record
    bridges.py  the two plants behind it: ReelBridge (kinematic), DynamicBridge (dynamic)
    faults.py   FaultPlan: what the emulator breaks, and from when
    canopen_drives.py  `cdpm emulate --canopen`: CiA 402 drives on a CAN bus, same plants
    main.py     the UDP bridge's command line: its parser, build_server, main
    netft.py    NetFTServer: the handle's Net F/T (ATI's RDT over UDP), for either emulator
    plant_setup.py  what both command lines build alike (dynamic scenario, Net F/T)
    entry.py    the console entry point: main.py's, or canopen_drives.py's with --canopen

The names below are the emulator's API, re-exported so that `cdpm_drake.emulator:main` stays
the console entry point."""

from cdpm_drake.emulator.bridges import DynamicBridge, ReelBridge
from cdpm_drake.emulator.faults import FaultPlan
from cdpm_drake.emulator.main import build_parser, build_server
from cdpm_drake.emulator.server import ReceivedCommand, ReelBridgeServer
# Last: importing the submodule emulator/main.py binds the package's `main` to it.
from cdpm_drake.emulator.entry import main  # noqa: E402

__all__ = ["DynamicBridge", "FaultPlan", "ReceivedCommand", "ReelBridge", "ReelBridgeServer",
           "build_parser", "build_server", "main"]
