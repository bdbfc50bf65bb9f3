"""The one decorator of prioik's compiled entry points (numba).

:func:`kernel` is ``numba.njit(cache=True, _nrt=False, ...)``: the kernels of the
solve and row-writing paths only read and write arrays their caller allocated (the
prepared workspaces), so they do not need numba's reference-counting runtime (NRT).
Without it numba neither creates a reference-counted handle for every array argument
when the call unboxes it, nor increments and decrements the parent's count for every
view a kernel takes (``B[j]``, ``T[i, q:w]``, the workspace parts): on the 9-DoF Panda
limits stack the active-set kernel took 6.1 µs with the runtime and 3.8 µs without,
the call of eight arrays alone 0.55 µs and 0.32 µs (interleaved timings of the same
rows; ``prioik bench`` times the solves that result).

A kernel compiled this way cannot allocate an array (numba refuses to compile it:
"NRT required but not enabled"); helpers that allocate stay ordinary ``njit``
functions that it calls (they keep their runtime; the views they receive carry no
count, which numba's increments skip).
"""

from __future__ import annotations

from numba import njit

__all__ = ["kernel"]


def kernel(**options):
    """``numba.njit`` for an entry point that allocates nothing: cached on disk, without
    numba's reference-counting runtime (see the module docstring); ``options`` are
    ``njit``'s (e.g. ``fastmath``)."""
    return njit(cache=True, _nrt=False, **options)
