"""Comparisons, validation reports, benchmarks and the ``prioik`` command line.

Importing this package (the ``prioik`` command does) sets ``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS`` and ``MKL_NUM_THREADS`` to 1 unless they are already set: every
matrix here is small, and a multi-threaded BLAS spends more on waking threads than on
arithmetic (measured: ``operational_space`` at n = 35 took 9.7 ms with threads, 1.1 ms
without). It must happen before numpy is first imported to take effect.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
