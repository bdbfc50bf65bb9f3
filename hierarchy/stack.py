"""The task stack: levels of tasks, highest priority first, validated once."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

import numpy as np

from prioik.errors import UnknownNameError

from .errors import TaskStackError
from .layout import StackData, StackLayout
from .task import Level, Task


class TaskStack:
    """A prioritized stack of tasks over ``n`` unknowns.

    Args:
        levels: Highest priority first; each level is a :class:`Task` or a sequence
            of tasks (``[[t1], [t2, t3]]``, ``[t1, t2 + t3]``).

    Raises:
        TaskStackError: naming the task and level at fault, for differing column
            counts, a ``b`` of the wrong length, NaN anywhere, inf in ``A`` or ``b``,
            ``lower > upper``, a task with neither ``b`` nor bounds, an empty stack or
            level, or duplicate task names.

    A stack is immutable; ``stack / task`` returns a new stack with one more level.
    The compact form ``t1 / (t2 + t3) / t4`` builds the same stacks. It is a
    :class:`~prioik.hierarchy.StackLayout` (:attr:`layout`) with frozen
    :class:`~prioik.hierarchy.StackData` (:attr:`data`), which is what every solver reads.
    """

    __slots__ = ("_levels", "_n", "_layout", "_data", "_hard")

    def __init__(self, levels: Sequence) -> None:
        if isinstance(levels, (Task, Level)):
            levels = [levels]
        if isinstance(levels, TaskStack):
            levels = levels.levels
        try:
            raw = list(levels)
        except TypeError:
            raise TaskStackError(f"a stack is a sequence of levels, got "
                                 f"{type(levels).__name__}") from None
        if not raw:
            raise TaskStackError("the stack is empty: give at least one level")
        parsed: list[Level] = []
        seen: dict[str, int] = {}
        n: int | None = None
        for i, item in enumerate(raw):
            try:
                level = Level.of(item)
            except TaskStackError as exc:
                raise TaskStackError(str(exc), level=i) from None
            if len(level) == 0:
                raise TaskStackError("the level is empty: give at least one task", level=i)
            for task in level:
                task.validate(level=i, n=n)
                if n is None:
                    n = task.n
                if task.name in seen:
                    raise TaskStackError(f"duplicate task name (also at level "
                                         f"{seen[task.name]})", task=task.name, level=i)
                seen[task.name] = i
            parsed.append(level)
        self._levels = tuple(parsed)
        assert n is not None            # (a non-empty level has a task)
        self._n = int(n)
        self._hard = tuple(i for i, level in enumerate(parsed) if level.hard)
        self._layout: StackLayout | None = None
        self._data: StackData | None = None

    # ------------------------------------------------------------------ access
    @property
    def n(self) -> int:
        """Number of unknowns (columns of every task)."""
        return self._n

    @property
    def levels(self) -> tuple[Level, ...]:
        """The levels, highest priority first."""
        return self._levels

    @property
    def tasks(self) -> tuple[Task, ...]:
        """Every task, level by level."""
        return tuple(t for level in self._levels for t in level)

    @property
    def is_equality(self) -> bool:
        """``True`` when every task is an equality task."""
        return all(level.is_equality for level in self._levels)

    @property
    def hard(self) -> tuple[int, ...]:
        """The indices of the levels declared hard (:func:`~prioik.hierarchy.hard`)."""
        return self._hard

    def __len__(self) -> int:
        return len(self._levels)

    def __iter__(self) -> Iterator[Level]:
        return iter(self._levels)

    def __getitem__(self, i: int) -> Level:
        return self._levels[i]

    def task(self, name: str) -> Task:
        """The task called ``name`` (:class:`~prioik.errors.UnknownNameError`, a
        :class:`KeyError`, listing the tasks if absent)."""
        for t in self.tasks:
            if t.name == name:
                return t
        raise self._unknown(name)

    def level_of(self, name: str) -> int:
        """Level index of the task called ``name`` (as :meth:`task` if absent)."""
        for i, level in enumerate(self._levels):
            if name in level.names:
                return i
        raise self._unknown(name)

    def _unknown(self, name) -> UnknownNameError:
        return UnknownNameError(f"no task {name!r} in the stack (tasks: "
                                f"{', '.join(t.name for t in self.tasks)})")

    # ------------------------------------------------------------- composition
    def __truediv__(self, other) -> TaskStack:
        if isinstance(other, TaskStack):
            return TaskStack(self._levels + other.levels)
        return TaskStack(self._levels + (Level.of(other),))

    def __rtruediv__(self, other) -> TaskStack:
        return TaskStack((Level.of(other),) + self._levels)

    @property
    def layout(self) -> StackLayout:
        """The stack's shape: ``n`` and per level ``(task name, rows, kind)``."""
        if self._layout is None:
            self._layout = StackLayout.shared(
                self._n, tuple(tuple((t.name, t.m, t.kind) for t in level)
                               for level in self._levels), hard=self._hard)
        return self._layout

    @property
    def data(self) -> StackData:
        """The stack's rows, targets, bounds and ``√w`` in one read-only
        :class:`~prioik.hierarchy.StackData` (built once)."""
        if self._data is None:
            layout = self.layout
            data = StackData(layout)
            for t in self.tasks:
                sl = layout.task_slice(t.name)
                data.A[sl] = t.A
                if t.is_equality:
                    data.b[sl] = t.b
                else:
                    data.lower[sl], data.upper[sl] = t.bounds()
                if not t._unit_weight:
                    data.sqrt_weight[sl] = np.sqrt(t.weight)
            data._source = self
            self._data = data.freeze()
        return self._data

    def equilibrated(self) -> tuple[TaskStack, list[int]]:
        """The stack with every level of extreme scale rescaled, and those levels.

        A level whose largest entry lies outside ``[EQUILIBRATE_BELOW,
        EQUILIBRATE_ABOVE]`` has its tasks' ``A``, ``b`` and bounds multiplied by the
        power of two that brings that entry into ``[0.5, 1)``. The lexicographic
        optimal set (and every minimum-norm tie-break) is unchanged: each level's
        objective is multiplied by a constant. Without it, squares of entries below
        ~1e-154 underflow (a ``1e-200·I`` level read as zero gave ``x = 0``,
        "optimal"). Returns ``self`` (and ``[]``) when no level needs it.
        """
        levels = self.data.extreme_levels()
        if not levels:
            return self, []
        peaks = self.data.level_peaks()
        out = list(self._levels)
        for i in levels:
            # 2^-e: the peak into [0.5, 1)
            factor = math.ldexp(1.0, -math.frexp(float(peaks[i]))[1])
            out[i] = Level.of([t.scaled(factor) for t in self._levels[i]],
                              hard=self._levels[i].hard)
        return TaskStack(out), levels

    def equality_matrices(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per level, the weighted equality rows ``(A_i, b_i)``."""
        return [(level.A, level.b) for level in self._levels]

    # ------------------------------------------------------------------ display
    def summary(self) -> str:
        """A table: level, task, rows, kind, rank of the task, rank gained (eq. 12)."""
        from .analysis import rank_profile
        from .linalg import matrix_rank
        profile = rank_profile(self)
        lines = [f"TaskStack: {len(self)} levels, n = {self.n}",
                 f"{'level':>5}  {'task':<24} {'rows':>4}  {'kind':<10} {'rank':>4}  {'r_i':>4}"]
        for i, level in enumerate(self._levels):
            for j, t in enumerate(level):
                r_i = str(profile[i]) if j == 0 else ""
                lines.append(f"{i:>5}  {t.name:<24} {t.m:>4}  {t.kind:<10} "
                             f"{matrix_rank(t.A):>4}  {r_i:>4}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        """One line: levels (``task[rows]``, ``≤`` marks inequality tasks) and ``n``;
        :meth:`summary` gives the table with ranks."""
        parts = []
        for level in self._levels[:8]:
            parts.append(("hard " if level.hard else "") + " + ".join(
                f"{t.name}[{t.m}{'' if t.is_equality else '≤'}]"
                                    for t in level[:4]) + (" + …" if len(level) > 4 else ""))
        more = f" / … ({len(self) - 8} more)" if len(self) > 8 else ""
        return f"TaskStack(n={self.n}, {len(self)} levels: {' / '.join(parts)}{more})"

    def _repr_html_(self) -> str:
        from html import escape
        rows = "".join(f"<tr><td>{i}</td><td>{escape(t.name)}</td><td>{t.m}</td>"
                       f"<td>{t.kind}</td></tr>"
                       for i, level in enumerate(self._levels) for t in level)
        return (f"<table><caption>TaskStack, n = {self.n}, {len(self)} levels</caption>"
                f"<tr><th>level</th><th>task</th><th>rows</th><th>kind</th></tr>{rows}</table>")
