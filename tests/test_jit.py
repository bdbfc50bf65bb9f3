"""prioik._jit: the compiled entry points' decorator and their one signature."""

import numpy as np
import pytest
from numba import njit

from prioik._jit import ROWS_1D, ROWS_2D, WORK_F, compile_once, kernel


def _row_sums(A, b, out):
    for i in range(A.shape[0]):
        s = b[i]
        for j in range(A.shape[1]):
            s += A[i, j]
        out[i] = s


def test_compile_once_serves_read_only_and_writable_rows_with_one_specialization():
    f = njit(_row_sums)
    compile_once(f, (ROWS_2D, ROWS_1D, WORK_F))
    compile_once(f, (ROWS_2D, ROWS_1D, WORK_F))            # idempotent
    rng = np.random.default_rng(0)
    A, b = rng.standard_normal((4, 3)), rng.standard_normal(4)
    frozen_A, frozen_b = A.copy(), b.copy()
    frozen_A.setflags(write=False)
    frozen_b.setflags(write=False)
    out_writable, out_frozen = np.empty(4), np.empty(4)
    f(A, b, out_writable)
    f(frozen_A, frozen_b, out_frozen)
    assert len(f.signatures) == 1 and f.signatures[0][0].mutable is False
    np.testing.assert_array_equal(out_writable, out_frozen)
    np.testing.assert_allclose(out_writable, A.sum(axis=1) + b, rtol=0, atol=1e-14)
    with pytest.raises(TypeError):      # nothing else compiles: float32 does not convert
        f(A.astype(np.float32), b, out_writable)


def test_kernel_compiles_without_numbas_runtime():
    @kernel()
    def allocates(n):
        return np.zeros(n)

    # numba's words for an allocation without its runtime
    with pytest.raises(Exception, match="NRT required but not enabled|Only accept returning "
                                        "of array passed into the function"):
        allocates(3)


def test_compile_once_returns_the_signatures_entry_point():
    """The entry point compile_once returns is the compiled function itself (no
    dispatch): it gives the dispatcher's answer on writable and read-only rows, and
    is the overload of the signature, not the dispatcher."""
    f = njit(_row_sums)
    signature = (ROWS_2D, ROWS_1D, WORK_F)
    entry = compile_once(f, signature)
    assert entry is f.overloads[signature].entry_point and entry is not f
    assert compile_once(f, signature) is entry
    rng = np.random.default_rng(1)
    A, b = rng.standard_normal((5, 2)), rng.standard_normal(5)
    frozen_A = A.copy()
    frozen_A.setflags(write=False)
    by_dispatch, by_entry, by_entry_frozen = np.empty(5), np.empty(5), np.empty(5)
    f(A, b, by_dispatch)
    entry(A, b, by_entry)
    entry(frozen_A, b, by_entry_frozen)
    np.testing.assert_array_equal(by_entry, by_dispatch)
    np.testing.assert_array_equal(by_entry_frozen, by_dispatch)
    np.testing.assert_allclose(by_entry, A.sum(axis=1) + b, rtol=0, atol=1e-14)
    with pytest.raises(TypeError):      # its unboxing checks the item size
        entry(A.astype(np.float32), b, by_entry)
