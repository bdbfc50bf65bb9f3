"""The compiled core as the closed forms' ``Prepared`` classes call it (nullspace,
chiaverini, unifying, operational_space, sns, reference; the extended Jacobian imports
the core from here too).

:data:`_core` is ``prioik._core``, or ``None`` where it is not built (then
:data:`core_error` says why); :func:`resolve_kernel` reads the ``kernel`` option;
:func:`solve_compiled` calls a compiled solver on a stack and names a bad entry by task,
level and row; :func:`solve_rescaled` answers a stack the kernel refused for its scale;
:func:`mass_matrix_outcome` reads the answer of a solve with a mass matrix.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from prioik.hierarchy import StackData

from .base import CoreInputError, Diagnostics, FormulationError, Outcome, solve_equilibrated

try:  # the compiled C++ core (core/, built by pip install)
    from prioik import _core
    core_error = ""
except ImportError as exc:  # pragma: no cover - built with the package
    _core = None
    core_error = f"{type(exc).__name__}: {exc}"

#: the message of a stack no kernel can take at any scale
OVERFLOW_MESSAGE = ("the rows' scale overflows float64 (‖A_i‖_F² is not finite): scale the "
                    "tasks down")


def resolve_kernel(kernel: str) -> str:
    """``"cpp"`` or ``"numpy"`` for the ``kernel`` option (``"auto"``: cpp where the
    compiled core is built).

    Raises:
        FormulationError: ``kernel="cpp"`` and the compiled core is not importable here.
    """
    if kernel == "numpy" or (kernel == "auto" and _core is None):
        return "numpy"
    if _core is None:
        raise FormulationError(f"kernel='cpp' needs prioik's compiled core (prioik._core): "
                               f"{core_error}; reinstall prioik (`pip install -e .`)")
    return "cpp"


def solve_compiled(solver: Any, data: StackData, *mass_matrix: np.ndarray) -> Any:
    """``solver.solve(A, b, sqrt_weight, *mass_matrix)`` on the stack's arrays: the
    compiled solver's result (its own, overwritten by its next solve).

    Raises:
        TaskStackError: a value of the stack is not finite, or a √w is not > 0 (naming the
            task, level and row).
        CoreInputError: the mass matrix has an entry that is not finite, or a wrong shape.
    """
    try:
        return solver.solve(data.A, data.b, data.sqrt_weight, *mass_matrix)
    except CoreInputError as exc:
        if "mass_matrix" not in str(exc):
            data.check()     # names the task, level and row of a NaN, inf or bad √w
        raise


def solve_rescaled(solve: Callable[[StackData], Outcome], data: StackData) -> Outcome:
    """``solve`` on ``data`` with its extreme levels rescaled, for a stack the kernel
    refused for its scale (:func:`~.base.solve_equilibrated`).

    Raises:
        TaskStackError: no level's entries are extreme (rescaling cannot help).
    """
    return solve_equilibrated(solve, data, OVERFLOW_MESSAGE)


def mass_matrix_outcome(res: Any, M: np.ndarray, bias: Any, status: str,
                        detail: Callable[..., Any]) -> Outcome | None:
    """The answer of a compiled solve with the mass matrix ``M`` (``UnifyingResult``):
    ``x`` with ``diagnostics.ranks`` and the plugin's record ``detail(kernel="cpp",
    flops=..., tau=M x + bias)`` (``tau=None`` without ``bias``) in ``status``; ``None``
    when the kernel refused a level's scale (the caller rescales,
    :func:`solve_rescaled`).

    Raises:
        FormulationError: ``M`` is not positive definite (naming its smallest
            eigenvalue, as the readable paths do).
    """
    if not res.mass_positive_definite:
        w = np.linalg.eigvalsh(M)
        raise FormulationError(f"mass_matrix must be positive definite (smallest "
                               f"eigenvalue {w.min():.3e})")
    if not res.solved:
        return None
    x = res.x
    tau = None if bias is None else M @ x + np.asarray(bias, dtype=np.float64)
    return Outcome(x, status, Diagnostics(ranks=res.ranks.copy(),
                                          detail=detail(kernel="cpp", flops=res.flops,
                                                        tau=tau)), res.residuals)
