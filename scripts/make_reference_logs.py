"""Store the logs of the three shipped experiments as reference data for tests.

Runs exp1_no_interaction, exp2_interaction and exp3_two_pairs for their full durations and
writes tests/data/reference_logs/<name>.npz with the signals p, F_int, F_d, lengths,
pair_distances and velocity (m, N, m/s), plus the git commit the code came from.

Each signal is stored losslessly enough for a 1e-9 (m, N) comparison and small enough to
commit: quantised to QUANTUM (1e-11, so the stored value is within 5e-12 of the simulated
one), first-differenced along time (the signals are smooth, so the differences are small
integers) and zip-compressed. `load_reference_log` undoes that.

Usage: python scripts/make_reference_logs.py [--out tests/data/reference_logs] [names...]
"""

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from cdpm_drake.scenario import load_scenario  # noqa: E402
from cdpm_drake.simulation import simulate  # noqa: E402

EXPERIMENTS = ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs")
SIGNALS = ("p", "F_int", "F_d", "lengths", "pair_distances", "velocity")
QUANTUM = 1e-11  # m, N, m/s per integer step


def encode(x: np.ndarray) -> np.ndarray:
    q = np.round(np.asarray(x, dtype=float) / QUANTUM).astype(np.int64)
    return np.diff(q, axis=0, prepend=np.zeros((1,) + q.shape[1:], dtype=np.int64))


def decode(d: np.ndarray) -> np.ndarray:
    return np.cumsum(d, axis=0) * QUANTUM


def load_reference_log(path) -> dict:
    """{signal: (T, width) float array, 'time': (T,), 'commit': str} from a stored file."""
    with np.load(path) as f:
        out = {key: decode(f[key]) for key in SIGNALS}
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
    parser.add_argument("names", nargs="*", default=list(EXPERIMENTS))
    parser.add_argument("--out", default=str(ROOT / "tests" / "data" / "reference_logs"))
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    commit = git_commit()
    for name in args.names:
        scenario = load_scenario(name)
        result = simulate(scenario=scenario)
        if result.error is not None:
            raise SystemExit(f"{name}: the run failed: {result.error}")
        log = result.log
        arrays = {key: encode(log[key]) for key in SIGNALS}
        path = out / f"{name}.npz"
        np.savez_compressed(path, time=log["time"], commit=np.array(commit),
                            quantum=np.array(QUANTUM), **arrays)
        back = load_reference_log(path)
        worst = max(float(np.max(np.abs(back[k] - log[k]))) for k in SIGNALS)
        print(f"{name}: {len(log['time'])} ticks, {path.stat().st_size / 1e6:.2f} MB, "
              f"round trip within {worst:.1e}, commit {commit}")


if __name__ == "__main__":
    main()
