"""Where a measurement was made: CPU, cores, OS, BLAS and library versions."""

from __future__ import annotations

import os
import platform
from importlib import metadata

import numpy as np

__all__ = ["machine", "versions", "LIBRARIES"]

#: the distributions whose versions the pages report
LIBRARIES = ("numpy", "scipy", "pin", "placo", "qpsolvers", "daqp", "cvxpy",
             "clarabel", "osqp", "proxsuite", "quadprog", "scs", "highspy", "matplotlib")


def versions(dists=LIBRARIES) -> str:
    """``"numpy 2.1.0, scipy 1.14.1, ..."`` for the installed ones of ``dists``."""
    out = []
    for dist in dists:
        try:
            out.append(f"{dist} {metadata.version(dist)}")
        except metadata.PackageNotFoundError:
            pass
    return ", ".join(out)


def machine() -> dict[str, str]:
    """CPU model, cores, OS, Python, BLAS and library versions."""
    cpu = platform.processor() or platform.machine()
    fields: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                key = key.strip().lower()
                if key in ("model name", "cpu mhz", "cache size") and key not in fields:
                    fields[key] = value.strip()
    except OSError:
        pass
    if "model name" in fields:
        cpu = fields["model name"]
        extra = [f"{float(fields['cpu mhz']):.0f} MHz" if "cpu mhz" in fields else "",
                 f"cache {fields['cache size']}" if "cache size" in fields else ""]
        extra = [e for e in extra if e]
        if extra:
            cpu += f" ({', '.join(extra)})"
    try:
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        blas_name = f"{blas.get('name', '?')} {blas.get('version', '')}".strip()
    except Exception:  # noqa: BLE001 - older numpy: no dict mode
        blas_name = "unknown"
    return {"cpu": cpu, "cores": str(os.cpu_count()), "python": platform.python_version(),
            "os": f"{platform.system()} {platform.release()}", "blas": blas_name,
            "versions": versions()}
