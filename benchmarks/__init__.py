"""Comparisons, validation reports, benchmarks and the ``prioik`` command line."""
