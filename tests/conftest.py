"""Test configuration: single-threaded BLAS (small matrices; see prioik.benchmarks.threads).

Set here, for the test process only: importing prioik changes no environment variable.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
