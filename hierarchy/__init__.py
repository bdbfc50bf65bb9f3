"""The task-stack spec: tasks, levels, stacks, validation and lexicographic analysis.

Pure numpy: this package knows nothing of robots or solvers.
"""

from .analysis import (FeasibleSplit, LevelCheck, LexicographicReport, algorithmic_error,
                       algorithmic_error_norms, check_lexicographic, conflicting_levels,
                       feasible_split, lexicographic_residuals, nested_null_spaces, relative_distance,
                       rank_profile, singularity_distance)
from .buffer import StackBuffer
from .errors import TaskStackError, UnsupportedTaskError
from .io import load_stack, save_stack, stack_from_dict, stack_to_dict
from .linalg import (AMBIGUITY, DEFAULT_RCOND, ambiguity_reason, ambiguous_decision,
                     level_scale, matrix_rank, null_space_basis, range_basis, rank_threshold)
from .stack import PackedRows, TaskStack
from .task import Level, Task

__all__ = [
    "AMBIGUITY", "DEFAULT_RCOND", "ambiguity_reason", "ambiguous_decision", "level_scale",
    "rank_threshold", "FeasibleSplit", "PackedRows", "Level", "LevelCheck", "LexicographicReport", "Task",
    "StackBuffer", "TaskStack", "TaskStackError", "UnsupportedTaskError", "algorithmic_error",
    "algorithmic_error_norms", "check_lexicographic", "conflicting_levels",
    "feasible_split", "lexicographic_residuals", "matrix_rank", "nested_null_spaces",
    "null_space_basis", "range_basis", "rank_profile", "relative_distance",
    "singularity_distance",
    "load_stack", "save_stack", "stack_from_dict", "stack_to_dict",
]
