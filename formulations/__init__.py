"""Formulation plugins: each turns a :class:`~hierarchy.TaskStack` into ``x``.

>>> import formulations
>>> sol = formulations.solve(stack, "extended_jacobian")        # doctest: +SKIP
>>> [f.name for f in formulations.available() if f.available]   # doctest: +SKIP
"""

from .base import STATUSES, Capabilities, FormulationError, Outcome, Solution
from .registry import (PLUGINS, BatchSolution, FormulationInfo, available, get, names, solve,
                       solve_batch)

__all__ = ["BatchSolution", "STATUSES", "Capabilities", "FormulationError", "FormulationInfo", "Outcome",
           "PLUGINS", "Solution", "available", "get", "names", "solve", "solve_batch"]
