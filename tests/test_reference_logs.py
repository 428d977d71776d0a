"""Today's diagram reproduces the stored logs of the three shipped experiments (issue 11).

The reference is tests/data/reference_logs/*.npz, written by scripts/make_reference_logs.py
(first from the diagram before its speed-up; rewritten for issue 18's recalibrated robot, the
diagram unchanged; the commit is stored in each file). Agreement within
1e-9 m, N, m/s on every tick of the full 30 s: the rewired diagram computes the same thing.
The stored values are within 5e-12 of what was simulated (quantum 1e-11).
"""

from pathlib import Path

import numpy as np
import pytest

from cdpm_drake.scenario import load_scenario
from cdpm_drake.simulation import simulate

REFERENCE_DIR = Path(__file__).resolve().parent / "data" / "reference_logs"
EXPERIMENTS = ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs")
SIGNALS = ("p", "F_int", "F_d", "lengths", "pair_distances", "velocity")
TOLERANCE = 1e-9  # m, N, m/s


def _reference(name):
    with np.load(REFERENCE_DIR / f"{name}.npz") as f:
        quantum = float(f["quantum"])
        return {key: np.cumsum(f[key], axis=0) * quantum for key in SIGNALS} | {
            "time": f["time"]}


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_shipped_experiment_reproduces_its_reference_log(name):
    reference = _reference(name)
    result = simulate(scenario=load_scenario(name))
    assert result.error is None, result.error
    log = result.log
    np.testing.assert_array_equal(log["time"], reference["time"])
    for key in SIGNALS:
        assert log[key].shape == reference[key].shape, key
        worst = float(np.max(np.abs(log[key] - reference[key])))
        assert worst <= TOLERANCE, f"{key}: off by {worst:.3g} from the reference"

