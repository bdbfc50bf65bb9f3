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
"NRT required but not enabled", or for an array it returns "Only accept returning of
array passed into the function as argument"). Nor can the ``njit`` helpers it calls:
numba compiles a callee with its caller's flags (an allocating helper reached from such
a kernel was refused the same way). A helper shared by a kernel without the runtime and
a function with it is compiled once, with the flags of whichever caller came first, so
one that returns arrays must be inlined (``inline="always"``): compiled without the
runtime, the views it returned were released once too often by the other caller (heap
corruption; ``formulations/_active_set_kernel.py``'s ``_outputs``). Helpers that return
scalars may be calls (the views they receive carry no count, which numba's increments
skip).
"""

from __future__ import annotations

from collections.abc import Callable

from numba import njit, types

__all__ = ["kernel", "compile_once", "ROWS_2D", "ROWS_1D", "WORK_F", "WORK_I", "WORK_B"]

#: a stack's rows as a kernel reads them (:class:`~prioik.hierarchy.StackData`'s
#: C-contiguous float64 arrays), typed read-only: a writable array converts to it
ROWS_2D = types.Array(types.float64, 2, "C", readonly=True)
ROWS_1D = types.Array(types.float64, 1, "C", readonly=True)
#: a prepared solver's flat workspaces (float64, int64, int8)
WORK_F = types.Array(types.float64, 1, "C")
WORK_I = types.Array(types.int64, 1, "C")
WORK_B = types.Array(types.int8, 1, "C")


def kernel(**options):
    """``numba.njit`` for an entry point that allocates nothing: cached on disk, without
    numba's reference-counting runtime (see the module docstring); ``options`` are
    ``njit``'s (e.g. ``fastmath``)."""
    return njit(cache=True, _nrt=False, **options)


def compile_once(dispatcher, signature: tuple) -> Callable:
    """Compile ``dispatcher`` for ``signature`` alone (loaded from numba's disk cache when
    there), stop it compiling any other, and return that compilation's entry point.

    A kernel that reads a stack's rows is called with a
    :class:`~prioik.hierarchy.TaskStack`'s frozen (read-only) arrays and with a
    writable :class:`~prioik.hierarchy.StackData`; left to itself numba compiles one
    specialization for each (the active-set kernel: minutes each on a fresh cache), and
    the two may round differently. With the rows typed read-only (:data:`ROWS_2D`,
    :data:`ROWS_1D`) both calls run the same machine code; the conversion costs nothing
    at the call. Idempotent; call it where the solver is prepared, not at import.

    The entry point is the compiled function's own wrapper: it unboxes its arguments as
    ``signature`` types them, without the dispatcher's resolution of each call (the
    type of every argument, then the overload lookup): on the active-set kernel's eight
    arrays the call cost 0.38 µs through the dispatcher and 0.11 µs through its entry
    point (numba 0.68). It checks only each array's item size, so its callers pass what
    ``signature`` says by construction: a :class:`~prioik.hierarchy.StackData`'s arrays
    (C-contiguous float64 of the layout's shapes, never replaced) and the solver's own
    workspaces.

    Returns:
        The compiled entry point of ``signature``: call it with the same arguments as
        ``dispatcher``.
    """
    signature = tuple(signature)
    if signature not in {tuple(s) for s in dispatcher.signatures}:
        dispatcher.compile(signature)
    dispatcher.disable_compile()
    return dispatcher.overloads[signature].entry_point
