"""Test configuration: single-threaded BLAS (small matrices; see benchmarks/__init__)."""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
