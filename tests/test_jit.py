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
