"""Comparisons, validation reports, benchmarks and the ``prioik`` command line.

Importing this package changes nothing in the process: the ``prioik`` command limits
BLAS to one thread itself (:mod:`prioik.benchmarks.threads`, with ``threadpoolctl``),
because every matrix here is small and a multi-threaded BLAS spends more on waking
threads than on arithmetic (measured: ``operational_space`` at n = 35 took 9.7 ms with
threads, 1.1 ms without).
"""
