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
from typing import Any, ClassVar

import numpy as np

from prioik.hierarchy import StackData, StackLayout

from . import contract
from ._numerics import check_nonnegative
from .base import (
    CoreInputError,
    Diagnostics,
    FormulationError,
    Outcome,
    in_original_units,
    solve_equilibrated,
)

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


def solve_readable_equilibrated(solve_stack: Callable[[Any], Outcome], data: StackData
                                ) -> Outcome:
    """A readable (``kernel="numpy"``) path's answer for ``data``: ``solve_stack`` on its
    stack with the levels of extreme scale equilibrated
    (:meth:`~prioik.hierarchy.TaskStack.equilibrated`), read in the user's units."""
    stack, levels = data.as_stack().equilibrated()
    out = solve_stack(stack)
    return in_original_units(out, data, levels) if levels else out


def solve_each(solve: Callable[[StackData], Outcome], datas: list[StackData]
               ) -> tuple[np.ndarray, list[str], list[Any]]:
    """``(X, statuses, checks)`` (a batched kernel's answer,
    :meth:`~.contract.Prepared.solve_batch`) of ``solve`` on each data in turn."""
    outs = [solve(d) for d in datas]
    return np.array([o.x for o in outs]), [o.status for o in outs], [o.check for o in outs]


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


class MassMatrixPrepared(contract.Prepared):
    """A closed form solved in the metric of a mass matrix given with every solve
    (``unifying``, ``operational_space``) prepared for one layout: the options ``kernel``
    and ``rcond`` read here, the compiled kernel ``self._core`` (the subclass's
    :meth:`compiled_solver`) when ``self._cpp``; ``mass_matrix`` (required) and ``bias``
    read per call, the subclass's :meth:`readable` on ``kernel="numpy"``;
    :meth:`outcome` reads a compiled result.

    Args:
        layout: The stack layout (equality tasks only; the registry checked it).
        settings: The formulation's settings (every option of its ``OPTIONS``,
            validated).

    Raises:
        FormulationError: ``rcond`` is negative or not finite, or ``kernel="cpp"`` where
            the compiled core is not built.
    """

    accepts_step_options = True
    #: the formulation's registry name (in messages)
    name: ClassVar[str]

    def __init__(self, layout: StackLayout, settings: Any) -> None:
        self.layout = layout
        self.settings = settings
        self.kernel = resolve_kernel(settings.kernel)
        check_nonnegative(rcond=settings.rcond)
        self.rcond = float(settings.rcond)
        self._cpp = self.kernel == "cpp"
        if self._cpp:
            self._core = self.compiled_solver([int(s) for s in layout.starts], layout.n)

    def compiled_solver(self, starts: list[int], n: int) -> Any:
        """The compiled solver of the layout (``starts``, ``n``) with this one's options."""
        raise NotImplementedError

    def readable(self, data: StackData, mass: Any, bias: Any) -> Outcome:
        """The readable path's answer (``kernel="numpy"``)."""
        raise NotImplementedError

    def outcome(self, res: Any, M: np.ndarray, bias: Any) -> Outcome | None:
        """The answer of the compiled result ``res`` (``None``: rescale,
        :func:`mass_matrix_outcome`)."""
        raise NotImplementedError

    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        """Solve one stack of the layout (``settings``: this call's, else the prepared
        ones).

        Raises:
            FormulationError: no ``mass_matrix``, or one that is not positive definite.
            TaskStackError: a value is not finite (naming the task, level and row).
        """
        if settings is None:
            settings = self.settings
        mass, bias = settings.mass_matrix, settings.bias
        if mass is None:
            raise FormulationError(f"formulation {self.name!r} needs mass_matrix=M")
        if not self._cpp:
            return self.readable(data, mass, bias)
        M = np.ascontiguousarray(mass, dtype=np.float64)
        out = self.outcome(solve_compiled(self._core, data, M), M, bias)
        if out is None:
            return solve_rescaled(lambda d: self.solve(d, settings), data)
        return out
