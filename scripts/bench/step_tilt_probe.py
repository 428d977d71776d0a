"""Where a 40 N step across paper_7cable's swapped pair 1-3 takes the pair, tick by tick, on
the dynamic plant (full pose, tension control, drive-torque sensor), and what idealised
counters give: the true pair distance against d_l (from the plant's true pose) at fixed
times after the step, its minimum and when, the true tilt there, which cables are slack, and
how the run ends.

Variants (each a change of the shipped controller, not a proposal):
- shipped;
- monitor off: the model monitor's slack fault (50 ms) ends the shipped runs; without it the
  run shows where the platform goes on;
- slew unlimited: the internal force at its target at once (the tension command's rise and
  fall limits lifted, monitor off): the hand's wrench fed forward into the tension command
  with nothing slewed (its statics already are: full_pose.tension_tick);
- internal force held: the internal force frozen at the step (monitor off);
- orientation x4: the orientation hold's gain 4 times the shipped 10 1/s (monitor off);
- tilted open 0.5, 1.0: the platform started (and so held, the orientation hold keeps the
  first tick's) tilted against that fraction of the static tilt the 40 N hand gives it on
  its elastic cables at the start (K^-1 of the hand's wrench at the handle), which opens the
  pair ahead of the hand (shipped controller, monitor on).

    python scripts/bench/step_tilt_probe.py                  # exp2 and exp3, steps at 0.3 and 1.0 s
    python scripts/bench/step_tilt_probe.py --ticks          # and exp3's step at 1.0 s tick by tick
    python scripts/bench/step_tilt_probe.py --variants shipped --cases exp3_two_pairs@1.0
"""

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import adversarial_benchmark as ab  # noqa: E402

OFF = "model_monitor: {enabled: false}, "
# name: (overlay text, diagram module constants patched for the run)
VARIANTS = {
    "shipped": ("", {}),
    "monitor off": (OFF, {}),
    "slew unlimited": (OFF, {"TENSION_SLEW_RATE": 1e9, "TENSION_FALL_RATE": 1e9}),
    "internal force held": (OFF, {"TENSION_SLEW_RATE": 1e-6, "TENSION_FALL_RATE": 1e-6}),
    "orientation x4": (OFF + "controller: {pose: full, tension_control: true, "
                       "orientation_gain: 40.0}, ", {}),
    "tilted open 0.5": ("", {}),
    "tilted open 1.0": ("", {}),
}
CASES = ("exp2_interaction@0.3", "exp2_interaction@1.0", "exp3_two_pairs@0.3",
         "exp3_two_pairs@1.0")
AFTER_MS = (10, 20, 30, 40, 60, 100, 200)


def run(scenario, t0, variant, force=40.0, after=0.4):
    """The log (dict of arrays) of a `force` N step across 1-3 at t0 s under `variant`."""
    logging.disable(logging.WARNING)
    import cdpm_drake.diagram as diagram
    from cdpm_drake.config import load_resolved_scenario
    from cdpm_drake.runs.simulate import simulate

    text, patch = VARIANTS[variant]
    base = load_resolved_scenario(scenario)
    f = [round(float(x), 6) for x in force * ab._direction(base, (1, 3))]
    op = ("operator: !ScriptedOperator {times: [0, %g, %g, %g], forces: [[0,0,0],[0,0,0], "
          "%s, %s]}, " % (t0, t0 + 0.002, t0 + after + 1, f, f))
    # The variant's controller overlay (if any) replaces the sensor overlay's.
    sensor = ab.FULL_SENSOR % "drive_torque"
    if "controller:" in text:
        sensor = sensor.replace("controller: {pose: full, tension_control: true}, ", "")
    if variant.startswith("tilted open"):
        rpy = -float(variant.split()[-1]) * hand_tilt(base, force)
        sensor = sensor.replace("{tension_sensor: drive_torque}", "{tension_sensor: drive_torque, "
                                "initial_rpy: [%.6f, %.6f, %.6f]}" % tuple(rpy))
    overlay = "{duration: %g, %s%s%s}" % (t0 + after, sensor, op, text)
    saved = {k: getattr(diagram, k) for k in patch}
    try:
        for k, v in patch.items():
            setattr(diagram, k, v)
        result = simulate(scenario=load_resolved_scenario(scenario, overlay))
    finally:
        for k, v in saved.items():
            setattr(diagram, k, v)
    log = {k: np.asarray(v) for k, v in result.log.items()}
    log["fault"] = None if result.error is None else str(result.error)
    return log


def hand_tilt(resolved, force):
    """The platform's static tilt (rad, rpy to first order) under `force` N across 1-3 at the
    handle, every cable taut and the reels held, at the start: K^-1 dw's rotation part."""
    from cdpm_drake.kernels.tension import wrench_matrix

    robot, d = resolved.robot, resolved.robot.dynamics
    p0 = np.asarray(resolved.scenario.initial_position, dtype=float)
    F = force * ab._direction(resolved, (1, 3))
    W = wrench_matrix(robot, p0)
    L = np.linalg.norm(robot.reels - (p0 + robot.attachments), axis=1)
    x = np.linalg.solve(W @ np.diag(d.EA / L) @ W.T,
                        np.concatenate([F, np.cross(np.asarray(d.handle, float), F)]))
    return x[3:]


def summary(log, t0):
    """(margins mm at AFTER_MS, min mm, its ms after the step, true tilt deg there, estimated
    tilt deg there, slack cables there, first slack ms and cables, end)."""
    t = log["time"]
    k = [i for i, p in enumerate(log["pairs"]) if tuple(p) == (1, 3)][0]
    d = 1000 * (log["pair_distances_true"][:, k] - log["d_l"][k])
    i0 = int(np.searchsorted(t, t0))
    step = t[1] - t[0]
    at = [d[i0 + int(round(ms / 1000 / step))] if i0 + int(round(ms / 1000 / step)) < t.size
          else np.nan for ms in AFTER_MS]
    j = i0 + int(np.argmin(d[i0:]))
    slack = log["slack"] > 0.5
    first = np.flatnonzero(slack[i0:].any(axis=1))
    first_txt = ("%.0f ms (%s)" % (1000 * (t[i0 + first[0]] - t0), ",".join(
        str(c + 1) for c in np.flatnonzero(slack[i0 + first[0]]))) if first.size else "none")
    end = ("fault at +%.0f ms" % (1000 * (t[-1] - t0)) if log["fault"] else "ran")
    return (at, d[j], 1000 * (t[j] - t0), np.degrees(log["rpy_true"][j]),
            np.degrees(log["rpy"][j]), np.flatnonzero(slack[j]) + 1, first_txt, end)


def elastic(scenario, p, force=40.0, horizon=0.2):
    """The pair 1-3's distance change (mm) the step alone makes with the reels held and every
    cable taut, undamped (the platform's modes at p, level: K = W diag(EA/L) W^T, M =
    diag(m I, I_c), K phi = w^2 M phi): sum_k g . phi_k (phi_k . dw) / w_k^2 (1 - cos w_k t),
    g the pair distance's gradient in the pose (finite differences), dw the hand's wrench at
    the handle. Returns (static mm, its tilt's part mm, min over `horizon` mm, at ms, the
    modes' frequencies Hz)."""
    from cdpm_drake.config import load_resolved_scenario
    from cdpm_drake.kernels.interference import posed_pair_distances
    from cdpm_drake.kernels.rotation import rotations_from_rpy
    from cdpm_drake.kernels.tension_damping import modal_problem

    resolved = load_resolved_scenario(scenario)
    robot, d = resolved.robot, resolved.robot.dynamics
    F = force * ab._direction(resolved, (1, 3))
    dw = np.concatenate([F, np.cross(np.asarray(d.handle, float), F)])
    A, C = modal_problem(robot.reels, robot.attachments, p, d.EA, d.mass, d.inertia)
    lam, Y = np.linalg.eigh(A)
    phi = np.linalg.solve(C.T, Y)  # mass-normalised: phi^T M phi = I
    k = robot.pair_position(1, 3)

    def distance(q):
        dd, _ = posed_pair_distances(robot, q[None, :3], rotations_from_rpy(q[None, 3:]),
                                     np.zeros(len(robot.pairs)))
        return dd[0, k]

    q0 = np.concatenate([p, np.zeros(3)])
    g = np.array([(distance(q0 + 1e-6 * e) - distance(q0 - 1e-6 * e)) / 2e-6
                  for e in np.eye(6)])
    share = (g @ phi) * (phi.T @ dw) / lam  # m per mode, statics
    tilt = g[3:] @ (phi[3:] * ((phi.T @ dw) / lam)).sum(axis=1)
    t = np.arange(0.0, horizon, 1e-4)
    curve = 1000 * (share[None, :] * (1.0 - np.cos(np.sqrt(lam)[None, :] * t[:, None]))).sum(1)
    j = int(np.argmin(curve))
    return (1000 * share.sum(), 1000 * tilt, curve[j], 1000 * t[j],
            np.sqrt(lam) / (2 * np.pi))


def ticks(log, t0, count=40):
    """Rows: ms after the step, true and estimated tilt (deg), the pair vs d_l (true and
    estimated, mm), true and measured tensions, slack cables."""
    t = log["time"]
    k = [i for i, p in enumerate(log["pairs"]) if tuple(p) == (1, 3)][0]
    i0 = int(np.searchsorted(t, t0))
    print("| ms | true tilt (deg) | estimated tilt (deg) | pair - d_l true / est. (mm) "
          "| true tensions (N) | commanded (N) | slack |")
    print("|---|---|---|---|---|---|---|")
    for i in range(i0, min(t.size, i0 + count), 2):
        print("| %+.0f | %s | %s | %.2f / %.2f | %s | %s | %s |" % (
            1000 * (t[i] - t0), np.round(np.degrees(log["rpy_true"][i]), 2),
            np.round(np.degrees(log["rpy"][i]), 2),
            1000 * (log["pair_distances_true"][i, k] - log["d_l"][k]),
            1000 * (log["pair_distances"][i, k] - log["d_l"][k]),
            np.round(log["tensions"][i], 0), np.round(log["tension_command"][i], 0),
            ",".join(str(c + 1) for c in np.flatnonzero(log["slack"][i] > 0.5)) or "-"))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", default=",".join(CASES),
                        help="scenario@step time s, comma-separated")
    parser.add_argument("--variants", default=",".join(VARIANTS),
                        help="comma-separated, of: " + ", ".join(VARIANTS))
    parser.add_argument("--after", type=float, default=0.4, help="s simulated after the step")
    parser.add_argument("--ticks", action="store_true",
                        help="also exp3's step at 1.0 s (shipped) tick by tick")
    args = parser.parse_args(argv)
    cases = [(c.split("@")[0], float(c.split("@")[1])) for c in args.cases.split(",")]
    variants = args.variants.split(",")
    for v in variants:
        if v not in VARIANTS:
            parser.error("--variants: unknown %r (known: %s)" % (v, ", ".join(VARIANTS)))
    print("| case | variant | " + " | ".join("+%d ms" % ms for ms in AFTER_MS)
          + " | min (mm) | at (ms) | true tilt there (deg) | estimated (deg) | slack there "
          "| first slack | end |")
    print("|---" * (len(AFTER_MS) + 9) + "|")
    for scenario, t0 in cases:
        for v in variants:
            log = run(scenario, t0, v, after=args.after)
            at, low, when, tilt, est, slack, first, end = summary(log, t0)
            print("| %s @ %g s | %s | %s | %.2f | %.0f | %s | %s | %s | %s | %s |" % (
                scenario, t0, v, " | ".join("%.2f" % a for a in at), low, when,
                np.round(tilt, 2), np.round(est, 2), ",".join(map(str, slack)) or "-",
                first, end), flush=True)
    print()
    print("| case | margin at the step (mm) | statics: pair change, all / tilt's (mm) "
          "| elastic step, reels held: min change (mm) at (ms) | modes (Hz) |")
    print("|---|---|---|---|---|")
    for scenario, t0 in cases:
        log = run(scenario, t0, "shipped", after=0.004)
        k = [i for i, p in enumerate(log["pairs"]) if tuple(p) == (1, 3)][0]
        i0 = int(np.searchsorted(log["time"], t0))
        static, tilt, low, when, hz = elastic(scenario, log["p_true"][i0])
        print("| %s @ %g s | %.2f | %.2f / %.2f | %.2f at %.1f | %s |" % (
            scenario, t0, 1000 * (log["pair_distances_true"][i0, k] - log["d_l"][k]),
            static, tilt, low, when, " ".join("%.1f" % h for h in hz)), flush=True)
    if args.ticks:
        ticks(run("exp3_two_pairs", 1.0, "shipped"), 1.0, count=34)
    return 0


if __name__ == "__main__":
    sys.exit(main())
