"""Test configuration: single-threaded BLAS (small matrices; see prioik.benchmarks.threads).

Set here, for the test process only: importing prioik changes no environment variable.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# tests/core checks the core-only environment (`make test` runs it in .venv-core); where any
# extra is installed its premise does not hold, so it is collected only where none is.
from prioik import extras as _extras  # noqa: E402

collect_ignore = ["core"] if _extras.installed() else []
