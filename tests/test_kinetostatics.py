"""The kinetostatic limit: the max-min of lines (tension.max_min_lines) against scipy's HiGHS,
the margin of a pose against a linear program, its gradient against finite differences, and
the felt cue's logistic."""

import numpy as np
import pytest
from scipy.optimize import linprog

from cdpm_drake.tension import max_min_lines


def _highs_max_min(a, C):
    """max t s.t. t <= a_j + C_j . lam, by HiGHS: (t, status) with status 3 = unbounded."""
    K, k = C.shape
    res = linprog(np.r_[np.zeros(k), -1.0], A_ub=np.hstack([-C, np.ones((K, 1))]), b_ub=a,
                  bounds=[(None, None)] * (k + 1), method="highs")
    return (-res.fun if res.status == 0 else None), res.status


@pytest.mark.parametrize("k", [0, 1, 2, 3, 4])
def test_max_min_lines_equals_the_linear_program(k):
    rng = np.random.default_rng(k)
    unbounded = 0
    for trial in range(200):
        K = int(rng.integers(1, 12))
        a = rng.normal(size=K) * 50.0
        C = rng.normal(size=(K, k))
        if trial % 2 == 0:  # floor and ceiling lines, as in a tension margin: bounded
            a, C = np.r_[a - 10.0, 100.0 - a], np.vstack([C, -C])
        lam = np.empty(k)
        t = max_min_lines(a, C, lam)
        ref, status = _highs_max_min(a, C)
        if status == 3:
            assert t == np.inf
            unbounded += 1
            continue
        assert status == 0
        # Exact for k <= 1; the QP form of k >= 2 is within 1e-8 relative (LINES_WEIGHT).
        assert t == pytest.approx(ref, rel=1e-7, abs=1e-7)
        if k:  # the maximiser returned attains it
            assert np.min(a + C @ lam) == pytest.approx(t, rel=1e-9, abs=1e-9)
    assert k == 0 or unbounded > 0
