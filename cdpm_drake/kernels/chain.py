"""Moving values between the kernels one fused block calls in a tick (systems/fused_kernels.py):
its stacked inputs into each kernel's input slots, one kernel's results into a later one's
inputs, and the results out. numpy and numba, no Drake."""

import numba


@numba.njit(cache=True)
def put(x, buf, at):
    """buf[at[i]] = x[i] for every i."""
    for i in range(at.size):
        buf[at[i]] = x[i]


@numba.njit(cache=True)
def move(buf, source, target):
    """buf[target[i]] = buf[source[i]] for every i, in order."""
    for i in range(source.size):
        buf[target[i]] = buf[source[i]]


@numba.njit(cache=True)
def take(buf, start, out):
    """out = buf[start:start + out.size]."""
    for i in range(out.size):
        out[i] = buf[start + i]


@numba.njit(cache=True)
def view(buf, start, stop):
    """buf[start:stop], returned by numba: the view keeps buf's numba memory as its base, so
    a kernel is handed it without a new MemInfo a call (a NumPy slice would cost one)."""
    return buf[start:stop]
