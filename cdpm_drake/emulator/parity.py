"""Parity of a lockstep rehearsal with the simulation: `cdpm run --lockstep` against the
dynamic emulator in lockstep (the UDP bridge, or CiA 402 drives on python-can's virtual bus
with a CANopen force sensor), judged on the emulator's truth against `cdpm simulate` of the
same scenario on the dynamic plant (`plant: !DynamicReels` with the same settings).

Both sides run in this process (the emulator's bridge or drives in a thread, as `cdpm
emulate` runs them) with the start-up ramp off (`ramp_time: 0`: the simulation has none).
The tolerances (TOLERANCES) are those a rehearsal promises: the same end (completed, or a
fault within 10 ms of the simulation's), the smallest true tension within 0.5 N, the largest
within 5 %, the true closest approach of a cable pair within 0.5 mm and the true path of the
platform within 1 mm. Used by scripts/bench/parity_table.py and tests/emulator/."""

import dataclasses
import itertools
import tempfile
from pathlib import Path

import numpy as np

from cdpm_drake.config import load_scenario, resolve_scenario
from cdpm_drake.emulator.bridges import DynamicBridge
from cdpm_drake.emulator.server import ReelBridgeServer
from cdpm_drake.runs.log import true_pair_distances

EXPERIMENTS = ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs")
# Controller settings compared: name -> (scenario overlay, tension sensor of both plants).
FULL = "controller: {pose: full, tension_control: true}"
SETTINGS = {
    "default": ("{}", "drive_torque"),
    "paper": ("{method: paper}", "drive_torque"),
    "full+tc, no sensor": ("{" + FULL + "}", "none"),
    "full+tc, drive torque": ("{" + FULL + "}", "drive_torque"),
    "full+tc, load cells": ("{" + FULL + "}", "load_cell"),
}
BUSES = ("udp", "canopen")
# The rehearsal's promise: fault times s, tensions N (smallest) and share (largest), m.
TOLERANCES = dict(fault_time=0.010, min_tension=0.5, max_tension=0.05, closest=0.5e-3,
                  path=1e-3)
_channels = itertools.count()


def rows() -> list[tuple[str, str, str]]:
    """Every (experiment, setting, bus) compared."""
    return [(e, s, b) for e in EXPERIMENTS for s in SETTINGS for b in BUSES]


def unsupported(setting: str, bus: str) -> str:
    """Why a combination cannot be rehearsed ('' when it can): CanopenReels.tension_sensor
    takes only TENSION_SENSORS (drive_torque, none)."""
    from cdpm_drake.hardware.canopen_config import TENSION_SENSORS

    if bus == "canopen" and SETTINGS[setting][1] not in TENSION_SENSORS:
        return "CiA 402 drives have no load cells"
    return ""


def scenario_of(experiment: str, setting: str):
    """The scenario of a row on the dynamic plant (`--plant dynamic`: !DynamicReels with its
    defaults, as the shipped experiments have no plant of their own) measuring tensions with
    the setting's sensor."""
    overlay, sensor = SETTINGS[setting]
    plant = f"plant: !DynamicReels {{tension_sensor: {sensor}}}"
    return load_scenario(experiment, "{" + plant + ("" if overlay == "{}" else ", ")
                         + overlay[1:])


def _ending(log) -> tuple[str, float, str]:
    """(ending, fault time s or NaN, fault message) of a run's or a simulation's log."""
    ending = str(log.get("ending", "completed"))
    return (ending, float(log.get("fault_time", np.nan)), str(log.get("fault_message", "")))


def _truth(rows, robot, duration) -> dict:
    """The emulator's truth rows (emulator.main.write_truth_log's columns: time, plant_time,
    tensions, drive_force, reel_speed, p_true, rpy_true, ...) up to `duration` of plant time,
    with every pair's true distance."""
    rows = [r for r in rows if r[1] <= duration + 1e-9]
    p = np.array([r[5] for r in rows]).reshape(-1, 3)
    rpy = np.array([r[6] for r in rows]).reshape(-1, 3)
    return dict(plant_time=np.array([r[1] for r in rows]),
                tensions=np.array([r[2] for r in rows]).reshape(len(rows), -1), p_true=p,
                pair_distances_true=true_pair_distances(robot, p, rpy)["pair_distances_true"])


def simulated(scenario, duration: float) -> dict:
    """`cdpm simulate` of the scenario (on its dynamic plant): its log, with the true pair
    distances."""
    from cdpm_drake.runs.simulate import simulate

    resolved = resolve_scenario(scenario)
    log = simulate(scenario=resolved, duration=duration).log
    log["pair_distances_true"] = true_pair_distances(resolved.robot, log["p_true"],
                                                     log["rpy_true"])["pair_distances_true"]
    return log


def udp_rehearsal(scenario, duration: float, out_dir, **fields) -> tuple[dict, dict]:
    """`cdpm run --lockstep` against `cdpm emulate --plant dynamic --lockstep --truth-log`
    (with `--load-cells` where the sensor is load cells); `fields`: HardwareReels' others.
    Returns (the run's log, the truth)."""
    from cdpm_drake.hardware.config import HardwareReels
    from cdpm_drake.runs.realtime import run

    resolved = resolve_scenario(scenario)
    sensor = scenario.plant.tension_sensor
    bridge = DynamicBridge(resolved, load_cells=sensor == "load_cell")
    server = ReelBridgeServer(bridge, lockstep=True, truth=int(duration / 0.002) + 100,
                              record=0).start()
    try:
        hardware = HardwareReels(port=server.address[1], ramp_time=0.0, tension_sensor=sensor,
                                 **fields)
        result = run(scenario=dataclasses.replace(scenario, plant=hardware), out_dir=out_dir,
                     duration=duration, lockstep=True)
    finally:
        server.stop()
    return _run_log(result), _truth(list(server.truth), resolved.robot, duration)


def _run_log(result) -> dict:
    log = dict(result.log)
    if "ending" not in log:  # a run that never ticked (a start-up refusal)
        log.update(ending=np.array(result.ending), fault_time=np.array(0.0),
                   fault_message=np.array(str(result.error)), time=np.zeros(0))
    return log


def canopen_rehearsal(scenario, duration: float, out_dir,
                      **fields) -> tuple[dict, dict]:
    """`cdpm run --lockstep` on `plant: !CanopenReels` against `cdpm emulate --canopen
    --plant dynamic --lockstep` on python-can's virtual bus, the hand reaching the controller
    through a CANopen force sensor (node 20); the truth is the plant's after each SYNC (what
    the UDP emulator's --truth-log keeps per status). `fields`: CanopenReels' others
    (force_per_torque_unit, ...). Returns (the run's log, the truth)."""
    from cdpm_drake.hardware.canopen_config import CanopenReels
    from cdpm_drake.hardware.force_config import CanopenForceSensor
    from cdpm_drake.runs.realtime import run

    resolved = resolve_scenario(scenario)
    bridge = DynamicBridge(resolved)
    truth = []
    step = bridge.step

    def recorded_step(dt):
        step(dt)
        truth.append((None, bridge.plant_time, bridge.true_tensions(), None, None,
                      *bridge.true_pose()))

    bridge.step = recorded_step
    config = CanopenReels(interface="virtual", channel=f"parity-{next(_channels)}",
                          ramp_time=0.0, tension_sensor=scenario.plant.tension_sensor,
                          force_sensor=CanopenForceSensor(node_id=20), **fields)
    drives = canopen_drives(bridge, config)
    try:
        result = run(scenario=dataclasses.replace(scenario, plant=config), out_dir=out_dir,
                     duration=duration, lockstep=True)
    finally:
        drives.stop()
    return _run_log(result), _truth(truth, resolved.robot, duration)


def canopen_drives(bridge, config, faults=()):
    """`cdpm emulate --canopen --lockstep`'s drives for `config` (a CanopenReels on
    python-can's virtual bus, with its force sensor) on `bridge`'s plant, with `faults`
    (EmulatedDrives'), started: .stop() them."""
    try:
        import can
    except ImportError:
        raise RuntimeError("the CANopen rows need the python-can package: pip install "
                           "'cdpm_drake[canopen]'") from None

    from cdpm_drake.emulator.canopen_drives import EmulatedDrives
    from cdpm_drake.hardware.canopen_config import (resolved_node_ids, resolved_offsets,
                                                    velocity_units)

    m = bridge.robot.num_cables
    bus = can.Bus(interface="virtual", channel=config.channel, receive_own_messages=False)
    drives = EmulatedDrives(bridge, bus, resolved_node_ids(config, m),
                            counts_per_metre=config.counts_per_metre,
                            position_offset=resolved_offsets(config, m),
                            velocity_units=velocity_units(config),
                            force_per_torque_unit=config.force_per_torque_unit,
                            faults=faults, lockstep=True)
    return drives.play_force_sensor(config.force_sensor).start()


def compare(sim: dict, log: dict, truth: dict) -> dict:
    """The five differences between a rehearsal (its log's ending, the emulator's truth) and
    the simulation, and whether each is within TOLERANCES. Over the time both ran."""
    (end_s, t_s, msg_s), (end_r, t_r, msg_r) = _ending(sim), _ending(log)
    same_end = end_s == end_r and (end_s != "fault" or abs(t_s - t_r) <= TOLERANCES["fault_time"])
    end = sim["time"][-1] if len(sim["time"]) else 0.0
    if len(truth["plant_time"]):
        end = min(end, truth["plant_time"][-1])
    ks, kt = sim["time"] <= end + 1e-9, truth["plant_time"] <= end + 1e-9
    out = dict(end_sim=end_s if end_s != "fault" else f"fault {t_s:.3f} s",
               end_run=end_r if end_r != "fault" else f"fault {t_r:.3f} s",
               fault_sim=msg_s, fault_run=msg_r, same_end=same_end)
    if not kt.any() or not ks.any():
        out.update(min_tension=np.nan, max_tension=np.nan, closest=np.nan, path=np.nan,
                   passed=False)
        return out
    Ts, Tr = sim["tensions"][ks], truth["tensions"][kt]
    out["min_tension"] = float(Tr.min() - Ts.min())
    out["max_tension"] = float(Tr.max() / Ts.max() - 1.0)
    out["closest"] = float(truth["pair_distances_true"][kt].min()
                           - sim["pair_distances_true"][ks].min())
    path = np.stack([np.interp(sim["time"][ks], truth["plant_time"][kt], truth["p_true"][kt, i])
                     for i in range(3)], axis=1)
    out["path"] = float(np.linalg.norm(path - sim["p_true"][ks], axis=1).max())
    out["moved"] = float(np.linalg.norm(sim["p_true"][ks][-1] - sim["p_true"][0]))
    out["passed"] = bool(same_end and within(out))
    return out


def within(d: dict) -> bool:
    """The four figures of `compare` within TOLERANCES."""
    return (abs(d["min_tension"]) <= TOLERANCES["min_tension"]
            and abs(d["max_tension"]) <= TOLERANCES["max_tension"]
            and abs(d["closest"]) <= TOLERANCES["closest"] and d["path"] <= TOLERANCES["path"])


def parity(experiment: str, setting: str, bus: str, duration: float, out_dir=None,
           sim: dict | None = None, **fields) -> dict:
    """One row: the rehearsal over `bus` against the simulation (`sim`, to reuse one
    simulation for both buses) over `duration` s; `fields`: the hardware plant's others.
    Returns compare's dict plus the row's
    names."""
    scenario = scenario_of(experiment, setting)
    if sim is None:
        sim = simulated(scenario, duration)
    rehearse = udp_rehearsal if bus == "udp" else canopen_rehearsal
    with tempfile.TemporaryDirectory() as tmp:
        log, truth = rehearse(scenario, duration, Path(out_dir or tmp) / f"{bus}", **fields)
    return dict(experiment=experiment, setting=setting, bus=bus, duration=duration,
                **compare(sim, log, truth))


HEADER = ("| experiment | controller | bus | end (sim / rehearsal) | smallest T, N | "
          "largest T | closest approach, mm | path, mm | |\n"
          "| --- | --- | --- | --- | ---: | ---: | ---: | ---: | --- |")


def table_row(r: dict) -> str:
    """A markdown row of `parity`'s result (or of an unsupported combination)."""
    head = f"| {r['experiment']} | {r['setting']} | {r['bus']} |"
    if r.get("unsupported"):
        return head + f" n/a: {r['unsupported']} | | | | | n/a |"
    end = r["end_sim"] if r["end_sim"] == r["end_run"] else f"{r['end_sim']} / {r['end_run']}"
    return (head + f" {end} | {r['min_tension']:+.3f} | {100 * r['max_tension']:+.2f} % | "
            f"{1e3 * r['closest']:+.3f} | {1e3 * r['path']:.3f} | "
            f"{'pass' if r['passed'] else 'FAIL'} |")
