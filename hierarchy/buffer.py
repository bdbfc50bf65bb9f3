"""A preallocated equality stack, refilled in place at every control step.

:class:`~hierarchy.TaskStack` copies and validates every task it is given, which is
what a one-off problem wants and what a 500 Hz control loop cannot afford (on the
G1 fencing stack, building ``Task`` objects and the stack cost ~3× the solve). A
:class:`StackBuffer` fixes the layout once — levels, task names and row counts — and
holds every level's rows ``A`` (``M × n``) and targets ``b`` (``M``) in two arrays
that task builders write into (``buffer.rows(name)`` gives writable views). The
packed layout is the one of :class:`~hierarchy.PackedRows`, so compiled kernels take
it without copying; :meth:`StackBuffer.check` is the boundary check (finite
values), and :meth:`StackBuffer.to_stack` gives an ordinary, validated
:class:`~hierarchy.TaskStack` of the current contents for any formulation.

Only equality tasks with unit weights are held (scale a task's rows and target by
``√w`` to weight it).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .errors import TaskStackError
from .stack import TaskStack
from .task import Task

__all__ = ["StackBuffer"]


class StackBuffer:
    """Rows ``A x ≈ b`` of a fixed stack layout, in preallocated arrays.

    Args:
        n: Number of unknowns (columns).
        levels: Highest priority first; each level a sequence of ``(task name, rows)``.

    Raises:
        TaskStackError: naming the level (and task) for an empty stack or level, a
            row count below 1, a duplicate name, or ``n < 1``.

    Attributes:
        n: Columns.
        A: ``M × n`` rows of every level, level after level (zeros at first).
        b: ``M`` targets.
        starts: ``k + 1`` row offsets of the levels (``int64``).
        names: Task names per level.
    """

    __slots__ = ("n", "A", "b", "starts", "names", "_slices", "_level_of")

    def __init__(self, n: int, levels: Sequence[Sequence[tuple[str, int]]]) -> None:
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise TaskStackError(f"a buffer needs n ≥ 1 columns, got {n!r}")
        levels = [list(level) for level in levels]
        if not levels:
            raise TaskStackError("the stack is empty: give at least one level")
        self.n = int(n)
        self._slices: dict[str, slice] = {}
        self._level_of: dict[str, int] = {}
        starts = [0]
        names = []
        for i, level in enumerate(levels):
            if not level:
                raise TaskStackError("the level is empty: give at least one task", level=i)
            row = starts[-1]
            for entry in level:
                try:
                    name, m = entry
                except (TypeError, ValueError):
                    raise TaskStackError(f"a buffer task is a (name, rows) pair, got "
                                         f"{entry!r}", level=i) from None
                if not isinstance(name, str) or not name:
                    raise TaskStackError(f"a task name must be a non-empty string, got "
                                         f"{name!r}", level=i)
                if name in self._slices:
                    raise TaskStackError(f"duplicate task name (also at level "
                                         f"{self._level_of[name]})", task=name, level=i)
                if not isinstance(m, (int, np.integer)) or m < 1:
                    raise TaskStackError(f"a task needs at least one row, got {m!r}",
                                         task=name, level=i)
                self._slices[name] = slice(row, row + int(m))
                self._level_of[name] = i
                row += int(m)
            starts.append(row)
            names.append(tuple(name for name, _ in level))
        self.starts = np.array(starts, dtype=np.int64)
        self.starts.setflags(write=False)
        self.names = tuple(names)
        self.A = np.zeros((starts[-1], self.n))
        self.b = np.zeros(starts[-1])

    def __len__(self) -> int:
        return len(self.names)

    @property
    def m(self) -> int:
        """Total number of rows."""
        return int(self.starts[-1])

    def task_slice(self, name: str) -> slice:
        """Row range of a task in :attr:`A` and :attr:`b`.

        Raises:
            TaskStackError: no such task (listing the buffer's tasks).
        """
        try:
            return self._slices[name]
        except KeyError:
            raise TaskStackError(f"no task {name!r} in the buffer (tasks: "
                                 f"{', '.join(self._slices)})") from None

    def rows(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Writable views ``(A_t, b_t)`` of one task's rows."""
        sl = self.task_slice(name)
        return self.A[sl], self.b[sl]

    def level_of(self, name: str) -> int:
        """Level index of a task (:class:`KeyError` if absent, as
        :meth:`TaskStack.level_of`)."""
        return self._level_of[name]

    def check(self) -> None:
        """The boundary check: every value finite.

        Raises:
            TaskStackError: naming the first task (and its level) holding a NaN or
                an infinite value, with the offending row.
        """
        if np.isfinite(self.A).all() and np.isfinite(self.b).all():
            return
        for name, sl in self._slices.items():
            bad_a = ~np.isfinite(self.A[sl]).all(axis=1)
            bad_b = ~np.isfinite(self.b[sl])
            bad = np.flatnonzero(bad_a | bad_b)
            if bad.size:
                what = "A" if bad_a[bad[0]] else "b"
                raise TaskStackError(f"{what} holds a non-finite value in row {int(bad[0])}",
                                     task=name, level=self._level_of[name],
                                     row=int(bad[0]))

    def to_stack(self) -> TaskStack:
        """A validated :class:`~hierarchy.TaskStack` of the current rows (copied)."""
        return TaskStack([[Task(name, self.A[self._slices[name]], self.b[self._slices[name]])
                           for name in level] for level in self.names])
