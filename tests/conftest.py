"""Test configuration: single-threaded BLAS (small matrices; see prioik.benchmarks.threads).

Set here, for the test process only: importing prioik changes no environment variable.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


def assert_truthful(sol, stack, metric=None):
    """A Solution says "optimal" exactly when its answer passes the certificate
    (issue 13, point 4), and an "approximate" one names the level at fault."""
    from prioik.hierarchy import check_lexicographic
    assert sol.status in ("optimal", "approximate"), sol.info.get("message")
    passes = check_lexicographic(stack, sol.x, minimum_norm=True, metric=metric).ok
    assert (sol.status == "optimal") == passes, (sol.status, sol.info.get("message"))
    if sol.status == "approximate" and "certificate" in sol.info:
        assert sol.info["fault_level"] is not None and sol.info["fault_tasks"]


# tests/core checks the core-only environment (`make test` runs it in .venv-core); where any
# extra is installed its premise does not hold, so it is collected only where none is.
from prioik import extras as _extras  # noqa: E402

collect_ignore = ["core"] if _extras.installed() else []
