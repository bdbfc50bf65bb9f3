"""BLAS thread control for the ``prioik`` commands (``threadpoolctl``).

A control loop solves one small problem at a time on one core; with a multi-threaded
BLAS on a shared 2-core machine, n ≥ 100 solves were up to 100× slower and erratic.
The commands therefore run with one BLAS thread unless told otherwise; the library
itself never changes the process's threads or environment.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from threadpoolctl import threadpool_info, threadpool_limits

__all__ = ["blas_threads", "blas_info"]


@contextlib.contextmanager
def blas_threads(threads: int | None) -> Iterator[None]:
    """Limit every loaded BLAS to ``threads`` threads inside the block (``None`` or
    ``≤ 0``: leave them as they are); the previous counts come back on exit."""
    if threads is None or threads <= 0:
        yield
        return
    with threadpool_limits(limits=int(threads), user_api="blas"):
        yield


def blas_info() -> list[dict]:
    """``threadpoolctl``'s description of every BLAS loaded in this process."""
    return [dict(p) for p in threadpool_info() if p.get("user_api") == "blas"]
