"""Calling the compiled kernels once per tick at the least cost. numpy and numba, no Drake.

A call of a numba dispatcher from Python first types every argument to pick the compiled
version (~0.1-0.3 us a call here), and wraps every NumPy-owned array argument in a new numba
MemInfo (a malloc and a free per array per call). A block calls a kernel with the same
argument types every tick, so it binds the kernel once (`bind`: the compiled entry point of
exactly those types, no typing per call) and keeps its constant arrays in numba-owned memory
(`owned`: passed without a new MemInfo). Measured by scripts/bench/count_instructions.py.
"""

import numba
import numpy as np


@numba.njit(cache=True)
def _copy(a):
    return a.copy()


def owned(array) -> np.ndarray:
    """A float64 C-ordered copy of `array` in numba-managed memory: a kernel reads it without
    the per-call MemInfo a NumPy-owned array costs. Writable; same values and shape."""
    return _copy(np.ascontiguousarray(array, dtype=float))


def owned_scratch(scratch):
    """A kernel's work arrays (an array, or a tuple of them and of such tuples) copied into
    numba-managed memory, dtypes kept: a tuple of NumPy-owned arrays costs a MemInfo per array
    per call."""
    if isinstance(scratch, tuple):
        return tuple(owned_scratch(s) for s in scratch)
    return _copy(np.ascontiguousarray(scratch))


def bind(kernel, *example):
    """`kernel` (a numba dispatcher) compiled, or loaded from the cache, for exactly the
    argument types of `example` (called once with them), as a callable that skips numba's
    per-call typing. Every later call must pass arguments of those same types: float64
    arrays of the same dimensions, layout and writability (a block's port values and its
    `owned` constants always are), Python floats, ints and bools where the example has them.
    Returns `kernel` itself where there is no compiled entry (NUMBA_DISABLE_JIT)."""
    kernel(*example)
    try:
        return kernel.overloads[signature_of(*example)].entry_point
    except (AttributeError, KeyError):
        return kernel


def signature_of(*args) -> tuple:
    """The numba types of `args`, as `bind` keys them (for checks that a block's tick passes
    the types it was bound for)."""
    return tuple(numba.typeof(value) for value in args)
