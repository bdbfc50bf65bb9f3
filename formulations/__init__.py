"""Formulation plugins: each turns a :class:`~hierarchy.TaskStack` into ``x``.

>>> import formulations
>>> sol = formulations.solve(stack, "extended_jacobian")        # doctest: +SKIP
>>> [f.name for f in formulations.available() if f.available]   # doctest: +SKIP
"""

from .base import (
                   STATUSES,
                   Capabilities,
                   ConcurrentUseError,
                   FormulationError,
                   Outcome,
                   Solution,
)
from .options import Option
from .prepared import PreparedSolver
from .registry import (
                   PLUGINS,
                   BatchSolution,
                   FormulationInfo,
                   available,
                   compile_kernels,
                   get,
                   names,
                   prepare,
                   solve,
                   solve_batch,
)

__all__ = ["BatchSolution", "STATUSES", "Capabilities", "ConcurrentUseError", "FormulationError",
           "FormulationInfo", "Option", "Outcome", "PLUGINS", "PreparedSolver",
           "Solution", "available", "compile_kernels", "get", "names", "prepare", "solve",
           "solve_batch"]
