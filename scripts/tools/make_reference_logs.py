"""Store the logs of the three shipped experiments, and of the dynamic plant's reference runs,
as reference data for tests.

Runs exp1_no_interaction, exp2_interaction and exp3_two_pairs for their full durations, as
the paper's Fig. 5 (the safety filter off), and writes tests/data/reference_logs/<name>.npz with the signals p, F_int, F_d, lengths,
pair_distances and velocity (m, N, m/s), plus the git commit the code came from.

With --promise: the same three experiments as shipped (the hard promise: the safety filter,
the kinetostatic force and the model monitor on: a speed-up of those blocks is pinned by them) into
tests/data/reference_logs/promise/, with every logged signal of those blocks too
(PROMISE_SIGNALS); non-finite values (t* = +inf) are stored apart, where they are.

With --dynamic: runs the scenarios of tests/data/dynamic_reference/ (`!DynamicReels` on a frozen
robot file, see the README there) and writes <name>.npz beside each, with the plant's ground
truth (tensions, slack, p_true, rpy_true) and, for the runs through the controller, the
signals above. `run_dynamic_reference` is what tests/runs/test_reference_logs.py re-runs.

Each signal is stored losslessly enough for a 1e-9 (m, N) comparison and small enough to
commit: quantised to QUANTUM (1e-11, so the stored value is within 5e-12 of the simulated
one), first-differenced along time (the signals are smooth, so the differences are small
integers) and zip-compressed. `load_reference_log` undoes that.

Usage: python scripts/tools/make_reference_logs.py [--out tests/data/reference_logs] [names...]
       python scripts/tools/make_reference_logs.py --dynamic [names...]
"""

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from cdpm_drake.config import load_scenario  # noqa: E402
from cdpm_drake.runs.simulate import simulate  # noqa: E402

EXPERIMENTS = ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs")
SIGNALS = ("p", "F_int", "F_d", "lengths", "pair_distances", "velocity")
# The paper's Fig. 5 exactly: the safety filter (on by default) off.
FIG_5 = "{safety_filter: {enabled: false}}"
QUANTUM = 1e-11  # m, N, m/s per integer step
# The default diagram's signals: Fig. 5's and the safety blocks' outputs.
PROMISE_SIGNALS = SIGNALS + ("velocity_admittance", "velocity_limited", "F_kin", "kappa", "t_c",
                             "t_star_hand", "filter_status", "filter_binding", "pair_margin",
                             "model_status", "model_residual", "reel_velocity",
                             "lengths_commanded")
PROMISE_DIR = ROOT / "tests" / "data" / "reference_logs" / "promise"

DYNAMIC_DIR = ROOT / "tests" / "data" / "dynamic_reference"
# The plant's ground truth (m, rad, N; slack as 0/1), in every dynamic reference log.
TRUTH = ("p_true", "rpy_true", "tensions", "slack")
# Reference runs of the plant alone, its reel command held at zero (no controller).
PLANT_ALONE = ("free_oscillation",)


def dynamic_names() -> list[str]:
    """The dynamic reference runs: one scenario file each in DYNAMIC_DIR."""
    return sorted(path.stem for path in DYNAMIC_DIR.glob("*.yaml"))


def run_dynamic_reference(name: str, overlay: str | None = None) -> dict:
    """The signals of the dynamic reference run `name` ({signal: (T, width)}, 'time' (T,)):
    TRUTH, plus SIGNALS for a run through the controller. Raises if the run fails.
    `overlay`: a YAML overlay on the scenario (e.g. another plant time step)."""
    scenario = load_scenario(str(DYNAMIC_DIR / f"{name}.yaml"), overlay)
    if name not in PLANT_ALONE:
        result = simulate(scenario=scenario)
        if result.error is not None:
            raise RuntimeError(f"{name}: the run failed: {result.error}")
        log = result.log
        return {key: np.asarray(log[key], dtype=float) for key in SIGNALS + TRUTH} | {
            "time": log["time"]}
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from cdpm_drake.diagram import make_plant
    from cdpm_drake.config import scenario_robot
    from cdpm_drake.systems.plants.dynamic_plant import ground_truth_log

    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("reels", make_plant(scenario))
    hold = builder.AddSystem(ConstantVectorSource(np.zeros(scenario_robot(scenario).num_cables)))
    builder.Connect(hold.get_output_port(), plant.GetInputPort("reel_velocity_command"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(scenario.duration)
    truth = ground_truth_log(diagram, simulator.get_context())
    out = {key: np.asarray(truth[key], dtype=float) for key in TRUTH}
    return out | {"time": scenario.time_step * np.arange(len(out["tensions"]))}


def encode(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    q = np.round(np.where(np.isfinite(x), x, 0.0) / QUANTUM).astype(np.int64)
    return np.diff(q, axis=0, prepend=np.zeros((1,) + q.shape[1:], dtype=np.int64))


def decode(d: np.ndarray) -> np.ndarray:
    return np.cumsum(d, axis=0) * QUANTUM


def load_reference_log(path) -> dict:
    """{signal: (T, width) float array, 'time': (T,), 'commit': str} from a stored file."""
    with np.load(path) as f:
        out = {key: decode(f[key]) for key in f.files
               if key not in ("time", "commit", "quantum") and "@" not in key}
        for key in f.files:  # the non-finite values: "<signal>@where" (flat indices), "@what"
            if key.endswith("@where"):
                name = key[:-len("@where")]
                out[name].flat[f[key]] = f[name + "@what"]
        out["time"] = f["time"]
        out["commit"] = str(f["commit"])
        out["quantum"] = float(f["quantum"])
    return out


def git_commit() -> str:
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], check=True,
                            capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--",
                            "cdpm_drake"], check=True, capture_output=True, text=True).stdout
    return commit + ("+dirty" if dirty.strip() else "")


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("names", nargs="*")
    parser.add_argument("--out", default=None, help="output directory (default: "
                        "tests/data/reference_logs, with --dynamic tests/data/dynamic_reference)")
    parser.add_argument("--dynamic", action="store_true",
                        help="the dynamic plant's reference runs (tests/data/dynamic_reference)")
    parser.add_argument("--promise", action="store_true",
                        help="the shipped experiments as shipped, every safety signal "
                        "(tests/data/reference_logs/promise)")
    parser.add_argument("--commit", help="what to record as the code's commit (default: this "
                        "checkout's git HEAD, +dirty when cdpm_drake/ has changes): for a tree "
                        "that is not a git checkout, e.g. an old commit with a patch")
    args = parser.parse_args()
    commit = args.commit or git_commit()
    if args.dynamic:
        out = Path(args.out or DYNAMIC_DIR)
        for name in args.names or dynamic_names():
            log = run_dynamic_reference(name)
            store(out / f"{name}.npz", log, commit)
        return
    # The Fig. 5 references are the paper's diagram (the safety filter off; the monitor, which
    # only watches, on); --promise's the diagram as shipped.
    out = Path(args.out or (PROMISE_DIR if args.promise else ROOT / "tests" / "data"
                            / "reference_logs"))
    signals, overlay = (PROMISE_SIGNALS, None) if args.promise else (SIGNALS, FIG_5)
    for name in args.names or EXPERIMENTS:
        result = simulate(scenario=load_scenario(name, overlay))
        if result.error is not None:
            raise SystemExit(f"{name}: the run failed: {result.error}")
        store(out / f"{name}.npz", {k: result.log[k] for k in ("time",) + signals}, commit)


def store(path: Path, log: dict, commit: str) -> None:
    """Write every signal of `log` (all but 'time', which is stored as is) encoded; check the
    round trip."""
    signals = [key for key in log if key != "time"]
    path.parent.mkdir(parents=True, exist_ok=True)
    apart = {}
    for key in signals:
        x = np.asarray(log[key], dtype=float)
        where = np.flatnonzero(~np.isfinite(x))
        if where.size:
            apart[key + "@where"], apart[key + "@what"] = where, x.flat[where]
    np.savez_compressed(path, time=log["time"], commit=np.array(commit),
                        quantum=np.array(QUANTUM), **{key: encode(log[key]) for key in signals},
                        **apart)
    back = load_reference_log(path)
    worst = max(float(np.max(np.abs(np.nan_to_num(back[k] - log[k])))) for k in signals)
    same = all(np.array_equal(~np.isfinite(back[k]), ~np.isfinite(log[k])) for k in signals)
    assert same, "the non-finite values did not round-trip"
    print(f"{path.stem}: {len(log['time'])} ticks, {path.stat().st_size / 1e6:.2f} MB, "
          f"round trip within {worst:.1e}, commit {commit}")


if __name__ == "__main__":
    main()
