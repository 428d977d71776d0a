"""A CanopenReelsSystem against EmulatedDrives on python-can's `virtual` bus, in one process
(tests/hardware/test_canopen.py, tests/config/test_wiring_canopen.py), and whether a private
network namespace can be made for the end-to-end runs over udp_multicast."""

import itertools
import shutil
import subprocess
import time

import numpy as np

T = 0.002
_channels = itertools.count()


def bus_sensor(**fields):
    """A CanopenForceSensor for the tests' rigs (node 20, a short tare)."""
    from cdpm_drake.hardware.force_config import CanopenForceSensor

    return CanopenForceSensor(**dict(dict(node_id=20, tare_samples=5), **fields))


def fresh_channel() -> str:
    return f"canopen-test-{next(_channels)}"


def rig(robot, config, u, *, bridge=None, faults=(), drive_ids=None, time_step=T,
        **drive_args):
    """(simulator, reels system, drives, bridge, start lengths): `config` a CanopenReels on a
    virtual channel, a constant command `u` (m/s per cable), the drives (node ids
    `drive_ids`, default config's) in front of `bridge` (default: ideal ReelBridge at the
    workspace centre), running in a thread: stop them with close(reels, drives). The
    control period and the drives' plant step: `time_step` s."""
    import can
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from cdpm_drake.emulator.bridges import ReelBridge
    from cdpm_drake.emulator.canopen_drives import EmulatedDrives
    from cdpm_drake.hardware.canopen_config import resolved_node_ids
    from cdpm_drake.hardware.canopen_reels import CanopenReelsSystem
    from cdpm_drake.kernels.kinematics import cable_lengths

    L0 = cable_lengths(robot, robot.workspace.center)
    if bridge is None:
        bridge = ReelBridge(robot, L0, time_constant=0.0)
    bus = can.Bus(interface="virtual", channel=config.channel, receive_own_messages=False)
    ids = drive_ids or resolved_node_ids(config, robot.num_cables)
    # The handle's force sensor node, played with the drives when the config has one (with
    # `force_bias`, N in its axes, a zero offset of its own).
    from cdpm_drake.hardware.force_config import CanopenForceSensor
    bias = drive_args.pop("force_bias", (0.0, 0.0, 0.0))
    drives = EmulatedDrives(bridge, bus, ids, faults=faults, period=time_step, **drive_args)
    if isinstance(config.force_sensor, CanopenForceSensor):
        drives.play_force_sensor(config.force_sensor, bias)
    b = DiagramBuilder()
    reels = b.AddSystem(CanopenReelsSystem(robot, config, time_step=time_step))
    source = b.AddSystem(ConstantVectorSource(np.asarray(u, dtype=float)))
    b.Connect(source.get_output_port(), reels.get_input_port())
    return Simulator(b.Build()), reels, drives.start(), bridge, L0


def lockstep(sim, reels, drives, until, T=T):
    """Advance tick by tick to `until` s, each tick taking at least T of wall time, and
    before the next tick wait (0.1 s at most) until the drives acted on every SYNC sent (and
    so sent their TPDOs): the ticks of a host that answers in time, whatever the load of this
    shared 2-core machine (the silence a fault makes stays one). The order is real time's:
    Drake runs a tick's update right after its publish, then this waits."""
    t = sim.get_context().get_time()
    while t < until - 1e-9:
        start = time.monotonic()
        t += T
        sim.AdvanceTo(t)
        deadline = start + 0.1
        # The virtual bus delivers a frame into the receivers' queues as it is sent.
        while drives.syncs != reels.master.syncs and time.monotonic() < deadline:
            time.sleep(0.0002)
        time.sleep(max(0.0, T - (time.monotonic() - start)))


def close(reels, drives):
    """Close the controller's end, wait (1 s at most) for the drives to act on the last SYNC
    it sent, then stop them."""
    reels.close()
    deadline = time.monotonic() + 1.0
    while drives.syncs != reels.master.syncs and time.monotonic() < deadline:
        time.sleep(0.001)
    drives.stop()


def namespace_problem() -> str:
    """Why no private network namespace (`unshare -n`) can be made here, or ''."""
    for tool in ("unshare", "ip"):
        if shutil.which(tool) is None:
            return f"no `{tool}` on this machine"
    try:
        done = subprocess.run(["unshare", "-n", "true"], capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"unshare -n failed: {e}"
    if done.returncode != 0:
        return f"unshare -n refused (needs root): {done.stderr.decode().strip()}"
    return ""
