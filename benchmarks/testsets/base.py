"""What a test set is: named problems (task stacks) with what is known of their answer.

A :class:`TestSet` subclass has a ``name``, a one-line ``description``, whether it is
``sequential`` and :meth:`TestSet.problems`, which yields :class:`Problem` s. In a
sequential test set consecutive problems with the same :attr:`Problem.sequence` are
consecutive steps of one trajectory: a warm- or hot-started solver follows them in
order (each sequence starts from a freshly prepared, cold, solver).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from prioik.hierarchy import TaskStack

__all__ = ["Problem", "TestSet"]


@dataclass(frozen=True)
class Problem:
    """One stack of a test set.

    Attributes:
        name: Unique within its test set.
        stack: The task stack.
        sequence: Trajectory label in a sequential test set (``""``: none).
        solution: A solution the source states (``None``: none).
        level_values: Per level, a ``‖w_i‖²`` the source states (``None``: none).
        stated_by: Where ``solution`` / ``level_values`` come from (``""``: none).
        mass_matrix: SPD ``M`` for the formulations that need one (``None``: the runner
            uses a fixed SPD matrix of the problem's size).
    """

    name: str
    stack: TaskStack
    sequence: str = ""
    solution: np.ndarray | None = None
    level_values: np.ndarray | None = None
    stated_by: str = ""
    mass_matrix: np.ndarray | None = None

    @property
    def has_inequalities(self) -> bool:
        """Whether any task of the stack is an inequality."""
        return any(t.kind == "inequality" for level in self.stack.levels for t in level)

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(n, levels, rows)`` of the stack."""
        return (self.stack.n, len(self.stack.levels),
                int(sum(level.m for level in self.stack.levels)))


class TestSet:
    """Base of the test sets.

    Class attributes:
        name: Registry name (``prioik bench --test-set NAME``).
        description: One line.
        sequential: Problems of one :attr:`Problem.sequence` are consecutive steps.
        needs: Extras of pyproject.toml it needs (``("robots",)``: pinocchio and the
            robot descriptions).

    Subclasses implement :meth:`problems`; their constructor takes the size options
    (every one with a default giving tens of problems).
    """

    __test__ = False  # not a pytest class, whatever its name

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    sequential: ClassVar[bool] = False
    needs: ClassVar[tuple[str, ...]] = ()

    def problems(self) -> Iterator[Problem]:  # pragma: no cover - abstract
        """The problems, in order (a sequential set: each trajectory's steps in order)."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"
