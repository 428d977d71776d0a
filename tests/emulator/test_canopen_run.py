"""`cdpm run` against `cdpm emulate --canopen` in two processes over python-can's
udp_multicast bus, inside a private network namespace (`unshare -n`: its own loopback, so the
multicast frames stay in this test). Skipped, with the reason, where the namespace cannot be
made (not root, no unshare or ip). Both processes run under SCHED_FIFO (`--rt-priority`, root
here as for the namespace), as the docs advise on a busy host: this one is shared.

Checked: the run completes and its logged lengths are the integral of its logged commands
(the emulated drives are ideal: lag 0, one plant step per SYNC); a drive fault, a dead node
and a frozen encoder each end the run with the log kept up to the fault, every live drive
stopped (target velocity 0, quick stop) and disabled (switch on disabled) within 3 SYNCs of
the drive's onset (the first SYNC whose TPDO shows the fault)."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers_canopen import namespace_problem

REPO = Path(__file__).resolve().parents[2]
T = 0.002
ATTEMPTS = 3
# The handle's force sensor, a node on the bus that the emulator plays with the drives.
SENSOR = "force_sensor: !CanopenForceSensor {node_id: 20}"
# missed_tpdo_ticks 6 (default 3), as the UDP run tests widen their watchdog: two Python
# processes on this shared 2-core host are held up for several ms at times, and these runs
# are about the run, not the silence (whose tests are in tests/hardware).
PLANT = ("plant: !CanopenReels {interface: udp_multicast, channel: 239.74.163.2, "
         "ramp_time: 0.0, missed_tpdo_ticks: 6, " + SENSOR + "}")
# The fault runs keep the default missed_tpdo_ticks (2): both processes run under SCHED_FIFO
# (`--rt-priority`, as on the robot; under normal scheduling, with other jobs on this host,
# both were held up past 5 ticks: p99 tick 5 ms, 17 overruns in 0.4 s measured).
FAULT_PLANT = ("plant: !CanopenReels {interface: udp_multicast, channel: 239.74.163.2, "
               "ramp_time: 0.0, " + SENSOR + "}")


def _script(out: Path, emulate_flags: str, duration: float, plant: str) -> str:
    py = f"PYTHONPATH={REPO} {sys.executable} -m cdpm_drake.cli"
    return f"""
set -u
ip link set lo up
ip route add 224.0.0.0/4 dev lo
cd {out}
{py} emulate --canopen --scenario exp2_interaction --scenario-text '{plant}' \\
    --time-constant 0 --duration 120 --rt-priority 40 {emulate_flags} > emulator.txt 2>&1 &
EMU=$!
for i in $(seq 600); do grep -q "CiA 402 drives" emulator.txt && break; sleep 0.1; done
{py} run exp2_interaction --duration {duration} --out {out}/run --rt-priority 50 \\
    --scenario-text '{plant}' > run.txt 2>&1
echo $? > run_code.txt
kill -TERM $EMU
wait $EMU || true
"""


def _run(tmp_path, name, emulate_flags="", duration=2.0, plant=None):
    problem = namespace_problem()
    if problem:
        pytest.skip(f"no private network namespace for udp_multicast: {problem}")
    out = tmp_path / name
    out.mkdir()
    done = subprocess.run(["unshare", "-n", "bash", "-c", _script(out, emulate_flags,
                                                                   duration, plant or PLANT)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    texts = {f: (out / f).read_text() for f in ("run.txt", "emulator.txt")}
    return int((out / "run_code.txt").read_text()), out / "run", texts


def test_cdpm_run_against_emulated_canopen_drives(tmp_path):
    # Two processes on this shared 2-core host: one may be held up for a few ms, which the
    # controller rightly ends as a silent drive (missed_tpdo_ticks = 2); such a run is
    # repeated, up to ATTEMPTS in all (the silence's own test is in tests/hardware).
    for attempt in range(ATTEMPTS):
        code, run_dir, texts = _run(tmp_path, f"completed{attempt}")
        if code == 0 or "no TPDO from" not in texts["run.txt"]:
            break
    assert code == 0, texts
    assert "run ended: completed" in texts["run.txt"], texts
    log = np.load(run_dir / "log.npz")
    assert str(log["ending"]) == "completed"
    n = len(log["time"])
    assert n == 1001  # ticks 0..1000 of 2 s at 500 Hz
    # The hand reached the diagram through the force sensor node: the emulator's hand is
    # exp2's spring hand on its platform (the best fit to the lengths the controller reads
    # too), so the logged measured_force is that hand at the logged pose and velocity, to
    # the node's counts (0.01 N) and the tare's rounding, of a tick within a few (the
    # sample read is the newest; a frame late on a busy host is a tick older). Measured on a
    # quiet host: 0.015 N at most at the same tick, with the hand up to 1.4 N.
    from cdpm_drake.config import load_scenario, scenario_operator
    hand = scenario_operator(load_scenario("exp2_interaction")).force
    # The hand's damping acts on the platform's own velocity, which lags the commanded one
    # by the emulated reels' 20 ms (the commanded velocity put up to 0.09 N of the hand's
    # 6 N s/m damping between the two): its velocity from the logged positions.
    T = float(log["time"][1] - log["time"][0])
    moving = np.gradient(np.asarray(log["p"], dtype=float), T, axis=0)
    expected = np.array([hand(t, p, v) for t, p, v in zip(log["time"], log["p"], moving)])
    assert np.linalg.norm(expected, axis=1).max() > 1.0
    # A frame is late by as many ticks as the host stalled the run (its longest tick gap on
    # the wall clock; under CI's load a 20 ms stall made a sample 9 ticks old): the lags
    # looked at cover that, never fewer than 3.
    stalled = int(np.ceil(np.max(np.diff(np.asarray(log["wall"], dtype=float))) / T))
    late = max(3, stalled)
    off = np.min([np.abs(log["F_measured"][late:-1] - expected[late + lag:n - 1 + lag])
                  .max(axis=1) for lag in range(-late, 2)], axis=0)
    # A tick next to a stall of the host (a wall-clock gap over 1.5 periods) reads a sample
    # and a pose of different ages, and its velocity from the positions spans the stall
    # (CI met 0.045 N on one such tick, every other within 0.011 N): those are left out,
    # and they may be at most a tenth of the run.
    gaps = np.diff(np.asarray(log["wall"], dtype=float)) > 1.5 * T
    near = np.zeros(n, dtype=bool)
    for k in np.flatnonzero(gaps):
        near[max(0, k - 2):k + 3] = True
    steady = ~near[late:-1]
    assert steady.mean() > 0.9, steady.mean()
    # The emulator's own stalls are not in the controller's wall clock (its frame is late, the
    # controller's tick is on time): CI met one such tick at 0.038 N among 0.015 N. So 98 % of
    # the steady ticks are held to 0.03 N and every one to 0.1 N, a tenth of the hand's peak:
    # a hand that did not arrive, or came scaled, turned or without its tare, is off by more
    # (the exact comparison runs in lockstep: tests/hardware/test_force_sensors.py and the
    # CANopen rows of tests/emulator/test_parity.py).
    assert np.quantile(off[steady], 0.98) <= 0.03, np.sort(off[steady])[-10:]
    assert off[steady].max() <= 0.1, np.sort(off[steady])[-10:]
    # The drives integrate their target velocities one plant step per SYNC (lag 0); the
    # command logged at tick k goes out with SYNC k, and the drives' answer to it is read
    # on tick k + 1 (Drake runs the update right after the publish). So from tick k to
    # k + 1 the logged lengths move by the command of tick k times T, to the quantisation
    # (1 um position counts: 1 um on a difference; 1 um/s velocity units): 99.6 % of the
    # ticks on a quiet host. A TPDO late by a period (a busy host: down to 82 % of the ticks
    # measured) moves two ticks' worth at once on the next tick, and a SYNC the multicast
    # socket dropped makes the drives skip a step. Over the run the lengths moved by the
    # commands' integral, to a few such steps (0.6 um measured on a quiet host): a wrong
    # unit or scale would miss it by millimetres.
    lengths, command = log["lengths"], log["reel_velocity"]
    step = np.abs(np.diff(lengths, axis=0)[1:] - command[1:-1] * T).max(axis=1)
    moved = lengths[-1] - lengths[0]
    assert np.abs(moved).max() > 0.005  # exp2's operator moved it cm
    assert (step <= 1.5e-6).mean() > 0.5, np.sort(step)[-20:]
    assert np.abs(moved - command[:-1].sum(axis=0) * T).max() <= 3 * np.abs(command).max() * T
    assert "drive states 1: switch on disabled" in texts["emulator.txt"]


@pytest.mark.parametrize("fault, cable, message, within", [
    # EMCY: read on the tick of the SYNC the fault precedes or the next, quick stop with it.
    ("drive_fault", 3, r"the drive of cable 3 \(node 3\) sent EMCY error code 0x2310", 2),
    # Silent: no TPDO for missed_tpdo_ticks = 2 ticks, quick stop with the next SYNC.
    ("dead_node", 2, r"no TPDO from the drive of cable 2 \(node 2\) for 2 ticks", 3),
    # Frozen: cable 5 runs at ~14 mm/s there; its first TPDO with the position of the one
    # before is read on the next tick (2), or the one after if it came a tick late (3).
    ("frozen_position", 5, r"cable 5 \(node 5\)'s position actual has not changed for [12] "
                           r"TPDOs", 3),
])
def test_a_fault_ends_the_run_with_the_log_kept_and_the_drives_disabled(tmp_path, fault, cable,
                                                                       message, within):
    """The fault runs of the UDP link, on the bus: the run ends by the fault, its log kept up
    to it, and by the `within`-th SYNC after the fault (the first after it is 1, the drive's
    onset) every live drive has target velocity 0 (quick stop), on the next it is disabled:
    at most 3 SYNCs after the onset (the emulator's own record says which SYNC)."""
    for attempt in range(ATTEMPTS):
        code, run_dir, texts = _run(tmp_path, f"{fault}{attempt}", f"--fault {fault} "
                                    f"--fault-cable {cable} --fault-after 1.0", duration=3.0,
                                    plant=FAULT_PLANT)
        if "injected" in texts["emulator.txt"] and re.search(message, texts["run.txt"]):
            break  # else a host stall ended the run before the fault was read: again
    assert code != 0
    assert re.search(message, texts["run.txt"]), texts
    log = np.load(run_dir / "log.npz")
    assert str(log["ending"]) == "fault"
    # The log runs up to the fault (about 1 s after the drives were enabled), not past it.
    fault_time = float(log["fault_time"])
    assert 0.8 < fault_time < 2.0 and log["time"][-1] <= fault_time + T
    assert len(log["time"]) >= int(0.8 / T)
    emu = texts["emulator.txt"]
    line = next(x for x in emu.splitlines() if f"{fault} after SYNC" in x)
    zero = int(line.split("live drive ")[1].split(" SYNC")[0])
    off = int(line.split("operation enabled ")[1].split(" SYNC")[0])
    disabled = int(line.split("all disabled ")[1].split(" SYNC")[0])
    assert zero <= within and off == zero and disabled == zero + 1 <= 4, line
    states = emu.split("drive states ")[-1].split("; lengths")[0]
    expected = {"drive_fault": "fault", "dead_node": "switch on disabled"}.get(
        fault, "switch on disabled")
    assert f"{cable}: {expected}" in states and all(
        f"{k}: switch on disabled" in states for k in range(1, 8) if k != cable), states
