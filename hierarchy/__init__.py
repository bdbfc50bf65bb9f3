"""The task-stack spec: tasks, levels, stacks, validation and lexicographic analysis.

Pure numpy: this package knows nothing of robots or solvers.
"""

from .analysis import (
    FeasibleSplit,
    LevelCheck,
    LexicographicReport,
    algorithmic_error,
    algorithmic_error_norms,
    check_lexicographic,
    conflicting_levels,
    feasible_split,
    lexicographic_residuals,
    nested_null_spaces,
    rank_profile,
    relative_distance,
    singularity_distance,
)
from .errors import TaskStackError, UnsupportedTaskError
from .io import (
    PeerProblem,
    load_lexls,
    load_peer,
    load_peer_json,
    load_soth,
    load_stack,
    save_stack,
    stack_from_dict,
    stack_to_dict,
)
from .linalg import (
    AMBIGUITY,
    DEFAULT_CERTIFICATE_TOL,
    DEFAULT_RCOND,
    NEAR_AMBIGUITY,
    X_PRECISION,
    ambiguity_reason,
    ambiguous_decision,
    decision_margin,
    level_scale,
    matrix_rank,
    near_ambiguity_reason,
    nonnegative_least_squares,
    null_space_basis,
    range_basis,
    rank_threshold,
    row_activity,
)
from .stack import (
    Level,
    StackData,
    StackLayout,
    Task,
    TaskStack,
    hard,
    hard_violations,
    level_residuals,
    precision_limited_levels,
    precision_reason,
)

__all__ = [
    "AMBIGUITY", "DEFAULT_CERTIFICATE_TOL", "DEFAULT_RCOND", "FeasibleSplit", "Level",
    "LevelCheck", "LexicographicReport", "NEAR_AMBIGUITY", "Task", "ambiguity_reason",
    "ambiguous_decision", "decision_margin", "near_ambiguity_reason",
    "level_scale", "rank_threshold",
    "StackData", "StackLayout", "TaskStack", "level_residuals", "TaskStackError",
    "UnsupportedTaskError", "algorithmic_error",
    "algorithmic_error_norms", "check_lexicographic", "conflicting_levels",
    "feasible_split", "lexicographic_residuals", "matrix_rank", "nested_null_spaces",
    "nonnegative_least_squares", "null_space_basis", "range_basis", "rank_profile",
    "relative_distance", "row_activity", "precision_limited_levels", "precision_reason",
    "X_PRECISION",
    "singularity_distance",
    "PeerProblem", "load_lexls", "load_peer", "load_peer_json", "load_soth",
    "load_stack", "save_stack", "stack_from_dict", "stack_to_dict", "hard",
    "hard_violations",
]
