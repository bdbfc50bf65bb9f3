"""Formulation plugins: each turns a :class:`~hierarchy.TaskStack` into ``x``.

>>> import formulations
>>> sol = formulations.solve(stack, "extended_jacobian")        # doctest: +SKIP
>>> [f.name for f in formulations.available() if f.available]   # doctest: +SKIP
"""

from .base import (
                   STATUSES,
                   VERIFY_MODES,
                   Capabilities,
                   CheckRequest,
                   ConcurrentUseError,
                   Diagnostics,
                   Fault,
                   FormulationError,
                   LowerPoint,
                   Outcome,
                   Solution,
                   Status,
                   Verification,
)
from .contract import Formulation, Prepared, StackPrepared
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

__all__ = ["BatchSolution", "STATUSES", "VERIFY_MODES", "Capabilities", "CheckRequest",
           "ConcurrentUseError", "Diagnostics", "Fault", "Formulation", "FormulationError",
           "FormulationInfo", "LowerPoint", "Option", "Outcome", "PLUGINS", "Prepared",
           "PreparedSolver", "Solution", "StackPrepared", "Status", "Verification",
           "available", "compile_kernels", "get",
           "names", "prepare", "solve", "solve_batch"]
