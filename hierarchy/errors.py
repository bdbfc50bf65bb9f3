"""The library's own errors: each carries the data at fault and names it."""

from __future__ import annotations

from typing import Any

from prioik.errors import PrioikError


class TaskStackError(PrioikError, ValueError):
    """A task or task stack is malformed.

    Attributes:
        task: Name of the task at fault, or ``None`` when the fault is the stack's.
        level: Zero-based level index of that task, or ``None`` when not known yet.
        detail: Machine-readable data about the fault (shapes, offending values).
        reason: The message without the level and task it names.
    """

    def __init__(self, message: str, *, task: str | None = None,
                 level: int | None = None, **detail: Any) -> None:
        where = []
        if level is not None:
            where.append(f"level {level}")
        if task is not None:
            where.append(f"task {task!r}")
        prefix = (", ".join(where) + ": ") if where else ""
        super().__init__(prefix + message)
        self.task = task
        self.level = level
        self.detail = detail
        self.reason = message


class UnsupportedTaskError(TaskStackError):
    """A formulation was asked for something it cannot do (e.g. an inequality task
    in a closed-form method).

    Attributes:
        formulation: Name of the formulation that refused.
    """

    def __init__(self, message: str, *, formulation: str, task: str | None = None,
                 level: int | None = None, **detail: Any) -> None:
        super().__init__(f"formulation {formulation!r} cannot take it: {message}",
                         task=task, level=level, **detail)
        self.formulation = formulation
