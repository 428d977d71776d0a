"""The encoders' zero, reconciled with the cables' stretch at start-up. numpy and numba, no
Drake.

Encoders count from a homing: the platform at the start pose, its cables taut, each encoder
set to read the rigid length of its cable there, l_i = |a_i - (p + R b_i)|. A taut elastic
cable's rigid length is its unstretched length L0_i stretched by its tension T_i, l_i = L0_i
(1 + T_i / EA), so the encoders read L0_i + s_i, s_i = l_i T_i / (EA + T_i) the stretch at
the homing. The controller's models of elastic cables (the full pose's fit and tension
estimate, the model monitor's residual) take unstretched lengths: `encoder_zero_tick`
subtracts s_i from every reading, with T_i the tension at the homing: the first measured
tension where the plant measures one, else the statics of the start pose (the distribution
the homing leaves, given). SI units: m, N.
"""

import math

import numba
import numpy as np

_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def homing_stretch(lengths, tensions, EA, out):
    """Each cable's stretch (m) at the homing into out (m,): l T / (EA + T) for rigid lengths
    l (m) under tensions T (N; below 0 or NaN counts as 0: a slack cable has no stretch)."""
    for i in range(lengths.shape[0]):
        T = tensions[i]
        T = T if T > 0.0 else 0.0
        out[i] = lengths[i] * T / (EA + T)


def encoder_zero_sizes(m: int) -> dict:
    """Input (x) and output sizes of encoder_zero_tick for m cables, and its memory."""
    return {"x": 2 * m + m + 2, "out": m + 1 + m + 2, "memory": m + 2, "memory_at": m + 1}


@_jit
def encoder_zero_tick(params, x, out):
    """params = [EA N, window (ticks, >= 1), T_home (m, N: the homing's tensions by the
    statics)];
    x = [encoders (m, m), T_measured (m, N; NaN: no reading), memory: stretch (m, m), ticks
    (1), reconciled (1)]; out = [lengths (m, m: the encoders less the homing's stretch),
    reconciled (1), next memory (m + 2)].

    Until reconciled, each tick takes the stretch from the measured tensions when every cable
    has a reading (reconciled from then on); at the `window`-th tick without one, from the
    measured tension where a cable has one and the statics where not (reconciled); before
    that, from the statics alone (not yet reconciled: a plant that measures tensions may not
    have its first reading at the first tick). Once reconciled the stretch is held. Returns
    1 when reconciled, else 0."""
    m = (x.shape[0] - 2) // 3
    EA, window = params[0], params[1]
    home = params[2:2 + m]
    enc = x[0:m]
    measured = x[m:2 * m]
    mem = 2 * m
    stretch = out[m + 1:2 * m + 1]
    reconciled = x[mem + m + 1] != 0.0
    ticks = x[mem + m] + 1.0
    if reconciled:
        for i in range(m):
            stretch[i] = x[mem + i]
    else:
        every = True
        for i in range(m):
            if not math.isfinite(measured[i]):
                every = False
        T = np.empty(m)
        for i in range(m):
            use = math.isfinite(measured[i]) and (every or ticks >= window)
            T[i] = measured[i] if use else home[i]
        homing_stretch(enc, T, EA, stretch)
        reconciled = every or ticks >= window
    for i in range(m):
        out[i] = enc[i] - stretch[i]
    out[m] = 1.0 if reconciled else 0.0
    out[2 * m + 1] = min(ticks, window)
    out[2 * m + 2] = out[m]
    return 1 if reconciled else 0
