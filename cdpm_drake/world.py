"""The simulated world's tick: the reels and the person at the handle in one compiled call.
numpy and numba, no Drake.

The state and the step are `kinematics.simulated_reel_step`'s; the hand force is a shipped
operator model's (`operators.operator_force_into`) at the next tick on the new pose, the
sample the force sensor reads there.
"""

import numba

from .kinematics import simulated_reel_step
from .operators import operator_force_into

_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def world_tick(offsets, reel, kind, times, rows, params, t_next, x, out):
    """One tick of the simulated world. x = [reel command (m,) m/s, state]; out = the next
    state (state_size(m) = 2 m + 9: lengths, p, v, lagged reel speeds, hand force).
    reel = [time_step s, lag factor, max_reel_speed m/s]; (kind, times, rows, params) the
    operator's `compiled()` form, evaluated at t_next (s) on the new p and v unless
    kind < 0 (a model without one: the caller adds the force). Returns False when the
    projection's Gauss-Newton does not settle (out then as simulated_reel_step leaves it, no
    force written)."""
    m = offsets.shape[0]
    if not simulated_reel_step(offsets, reel[0], reel[1], reel[2], x[:m], x[m:], out):
        return False
    if kind >= 0:
        operator_force_into(kind, times, rows, params, t_next, out[m:m + 3], out[m + 3:m + 6],
                            out[2 * m + 6:])
    return True
