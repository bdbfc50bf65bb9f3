"""A stack as a layout plus data: the fixed shape of a hierarchy and its rows.

A :class:`StackLayout` is what stays fixed from one control step to the next: ``n``,
and per level its tasks' names, row counts and kinds (equality ``A x ≈ b`` or
inequality ``lower ≤ A x ≤ upper``). It is immutable and hashable, so solvers can be
prepared for it once (:func:`prioik.prepare`).

A :class:`StackData` holds one layout's rows in preallocated arrays that task writers
fill in place at every step:

* ``A`` (``m × n``): every task's rows, level after level (the row offsets of the levels
  are ``layout.starts``);
* ``b`` (``m``): the targets of equality rows (unused on inequality rows);
* ``lower``, ``upper`` (``m``): the bounds of inequality rows (``∓inf``: unbounded side;
  unused on equality rows);
* ``sqrt_weight`` (``m``): ``√w`` per row; a level minimises
  ``Σ_rows (√w · violation)²`` where the violation is ``A x − b`` for an equality row and
  the distance of ``A x`` to ``[lower, upper]`` for an inequality row.

A :class:`~prioik.hierarchy.TaskStack` is a layout with frozen (read-only) data
(``stack.layout``, ``stack.data``): a formulation reads one kind of object whichever
way the rows were written.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from prioik.errors import UnknownNameError

from .errors import TaskStackError
from .linalg import DEFAULT_CERTIFICATE_TOL, X_PRECISION, level_scale

if TYPE_CHECKING:
    from .stack import TaskStack

__all__ = ["KINDS", "StackData", "StackLayout", "hard_violations", "level_residuals",
           "precision_limited_levels", "precision_reason"]

#: Task kinds of a layout.
KINDS = ("equality", "inequality")

#: Levels whose largest entry lies outside this range are equilibrated
#: (:meth:`TaskStack.equilibrated`): their squares would lose precision in float64.
EQUILIBRATE_BELOW = 1e-100
EQUILIBRATE_ABOVE = 1e100


#: the layouts :meth:`StackLayout.shared` hands out, by ``(n, levels)``; an entry lives as
#: long as its layout does
_SHARED: weakref.WeakValueDictionary[tuple, StackLayout] = weakref.WeakValueDictionary()


class StackLayout:
    """The fixed shape of a stack: ``n`` and, per level, ``(task name, rows, kind)``.

    Args:
        n: Number of unknowns (columns).
        levels: Highest priority first; each level a sequence of ``(name, rows)`` or
            ``(name, rows, kind)`` with ``kind`` ``"equality"`` (default) or
            ``"inequality"``.
        hard: Indices of the levels declared hard (:func:`~prioik.hierarchy.hard`: an
            answer that leaves one violated is not ``optimal``).

    Raises:
        TaskStackError: naming the level (and task) for an empty stack or level, a row
            count below 1, a duplicate name, an unknown kind, ``n < 1``, or a hard
            index that is not a level.

    Layouts compare equal (and hash alike) when ``n``, every level's tasks and the hard
    levels agree.
    """

    __slots__ = ("_n", "_levels", "_starts", "_slices", "_level_of", "_kind_of",
                 "_row_is_equality", "_hash", "_names", "_hard", "__weakref__")

    def __init__(self, n: int, levels: Sequence[Sequence[tuple]],
                 hard: Sequence[int] = ()) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise TaskStackError(f"a layout needs n ≥ 1 columns, got {n!r}")
        try:
            raw = [list(level) for level in levels]
        except TypeError:
            raise TaskStackError(f"a layout's levels are sequences of (name, rows[, kind]), "
                                 f"got {levels!r}") from None
        if not raw:
            raise TaskStackError("the stack is empty: give at least one level")
        self._n = int(n)
        self._slices: dict[str, slice] = {}
        self._level_of: dict[str, int] = {}
        self._kind_of: dict[str, str] = {}
        parsed = []
        starts = [0]
        flags: list[bool] = []
        for i, level in enumerate(raw):
            if not level:
                raise TaskStackError("the level is empty: give at least one task", level=i)
            row = starts[-1]
            entries = []
            for entry in level:
                if not isinstance(entry, (tuple, list)) or len(entry) not in (2, 3):
                    raise TaskStackError(f"a layout task is (name, rows[, kind]), got "
                                         f"{entry!r}", level=i)
                name, m = entry[0], entry[1]
                kind = entry[2] if len(entry) == 3 else "equality"
                if not isinstance(name, str) or not name:
                    raise TaskStackError(f"a task name must be a non-empty string, got "
                                         f"{name!r}", level=i)
                if name in self._slices:
                    raise TaskStackError(f"duplicate task name (also at level "
                                         f"{self._level_of[name]})", task=name, level=i)
                if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
                    raise TaskStackError(f"a task needs at least one row, got {m!r}",
                                         task=name, level=i)
                if kind not in KINDS:
                    raise TaskStackError(f"kind must be one of {', '.join(KINDS)}, got "
                                         f"{kind!r}", task=name, level=i)
                m = int(m)
                self._slices[name] = slice(row, row + m)
                self._level_of[name] = i
                self._kind_of[name] = kind
                flags.extend([kind == "equality"] * m)
                entries.append((name, m, kind))
                row += m
            starts.append(row)
            parsed.append(tuple(entries))
        self._levels = tuple(parsed)
        self._names = tuple(tuple(e[0] for e in level) for level in parsed)
        self._starts = np.array(starts, dtype=np.int64)
        self._starts.setflags(write=False)
        self._row_is_equality = np.array(flags, dtype=np.bool_)
        self._row_is_equality.setflags(write=False)
        self._hard = _hard_levels(hard, len(parsed))
        self._hash = hash((self._n, self._levels, self._hard))

    @classmethod
    def shared(cls, n: int, levels: Sequence[Sequence[tuple]],
               hard: Sequence[int] = ()) -> StackLayout:
        """The layout of ``n`` and ``levels`` (as for the constructor), one object per
        distinct shape while something holds it: the stacks of one shape share it, and a
        prepared solver recognises their data by identity instead of comparing layouts
        (~0.25 µs a call, against a ~10 µs G1 solve). :class:`TaskStack` takes its
        layout here.

        Raises:
            TaskStackError: as the constructor.
        """
        if type(n) is int:        # (a bool or a float goes to the constructor, which says)
            try:
                key = (n, tuple(tuple(tuple(entry) for entry in level) for level in levels),
                       tuple(hard))
                return _SHARED[key]
            except (KeyError, TypeError):  # (unhashable entries: the constructor says)
                pass
        layout = cls(n, levels, hard)
        return _SHARED.setdefault((layout._n, layout._levels, layout._hard), layout)

    # ------------------------------------------------------------------ access
    @property
    def n(self) -> int:
        """Number of unknowns."""
        return self._n

    @property
    def k(self) -> int:
        """Number of levels."""
        return len(self._levels)

    @property
    def m(self) -> int:
        """Total number of rows."""
        return int(self._starts[-1])

    @property
    def levels(self) -> tuple[tuple[tuple[str, int, str], ...], ...]:
        """Per level, its tasks as ``(name, rows, kind)``."""
        return self._levels

    @property
    def names(self) -> tuple[tuple[str, ...], ...]:
        """Per level, its tasks' names."""
        return self._names

    @property
    def hard(self) -> tuple[int, ...]:
        """The indices of the levels declared hard, increasing."""
        return self._hard

    @property
    def starts(self) -> np.ndarray:
        """``k + 1`` row offsets of the levels (``int64``, read-only)."""
        return self._starts

    @property
    def row_is_equality(self) -> np.ndarray:
        """Per row, whether it is an equality row (read-only)."""
        return self._row_is_equality

    @property
    def is_equality(self) -> bool:
        """``True`` when every row is an equality row."""
        return bool(self._row_is_equality.all())

    def __len__(self) -> int:
        return len(self._levels)

    def task_slice(self, name: str) -> slice:
        """Row range of a task.

        Raises:
            TaskStackError: no such task (listing the layout's tasks).
        """
        try:
            return self._slices[name]
        except KeyError:
            raise TaskStackError(f"no task {name!r} in the layout (tasks: "
                                 f"{', '.join(self._slices)})") from None

    def level_of(self, name: str) -> int:
        """Level index of a task (:class:`~prioik.errors.UnknownNameError`, a
        :class:`KeyError`, listing the tasks if absent, as :meth:`TaskStack.level_of`)."""
        try:
            return self._level_of[name]
        except (KeyError, TypeError):
            raise UnknownNameError(f"no task {name!r} in the layout (tasks: "
                                   f"{', '.join(self._slices)})") from None

    def kind_of(self, name: str) -> str:
        """``"equality"`` or ``"inequality"``."""
        self.task_slice(name)
        return self._kind_of[name]

    def task_names(self) -> tuple[str, ...]:
        """Every task, level by level."""
        return tuple(self._slices)

    def data(self) -> StackData:
        """New preallocated data of this layout: zero rows and targets, unbounded
        inequality rows, unit weights."""
        return StackData(self)

    # ---------------------------------------------------------------- identity
    def __eq__(self, other) -> bool:
        if self is other:
            return True
        if not isinstance(other, StackLayout):
            return NotImplemented
        return self._hash == other._hash and self._n == other._n \
            and self._levels == other._levels and self._hard == other._hard

    def __hash__(self) -> int:
        return self._hash

    def describe(self) -> str:
        """One line: ``n`` and the levels' tasks (``name[rows]``, ``≤`` for inequalities)."""
        def task(e):
            return f"{e[0]}[{e[1]}{'≤' if e[2] == 'inequality' else ''}]"
        return f"n={self._n}: " + " / ".join(
            ("hard " if i in self._hard else "") + " + ".join(task(e) for e in level)
            for i, level in enumerate(self._levels))

    def __repr__(self) -> str:
        return f"StackLayout({self.describe()})"


def _hard_levels(hard, k: int) -> tuple[int, ...]:
    """``hard`` (level indices) as an increasing tuple of distinct levels of ``k``."""
    try:
        out = sorted({int(i) for i in hard if not isinstance(i, bool) and i == int(i)})
        ok = len(out) == len(tuple(hard))
    except (TypeError, ValueError):
        ok = False
    if not ok or (out and not 0 <= out[0] <= out[-1] < k):
        raise TaskStackError(f"hard levels must be distinct level indices 0 … {k - 1}, got "
                             f"{hard!r}")
    return tuple(out)


class StackData:
    """The rows of one :class:`StackLayout`, in preallocated arrays.

    Args:
        layout: The layout.

    Attributes:
        layout: The layout (fixed).
        A: ``m × n`` rows, level after level.
        b: ``m`` targets of equality rows.
        lower, upper: ``m`` bounds of inequality rows.
        sqrt_weight: ``m`` values ``√w`` (1 by default).

    The arrays are written in place (``data.rows(name)`` gives views), never replaced
    (assigning one raises :class:`TaskStackError`); a formulation reads them without
    copying. :meth:`check` is the boundary check a prepared solver
    runs when a value looks wrong.
    """

    __slots__ = ("layout", "A", "b", "lower", "upper", "sqrt_weight", "_source")

    def __setattr__(self, name: str, value) -> None:
        # the arrays are the ones the prepared solvers' compiled kernels read (typed
        # C-contiguous float64 of the layout's shape): written in place, never replaced
        # (a replaced array of another shape would be read past its end)
        if name != "_source" and hasattr(self, name):
            raise TaskStackError(f"StackData.{name} is written in place "
                                 f"(data.{name}[...] = values), not replaced")
        object.__setattr__(self, name, value)

    def __init__(self, layout: StackLayout) -> None:
        if not isinstance(layout, StackLayout):
            raise TaskStackError(f"StackData takes a StackLayout, got {type(layout).__name__}")
        m, n = layout.m, layout.n
        self.layout = layout
        self.A = np.zeros((m, n))
        self.b = np.zeros(m)
        self.lower = np.full(m, -np.inf)
        self.upper = np.full(m, np.inf)
        self.sqrt_weight = np.ones(m)
        self._source: TaskStack | None = None   # the TaskStack whose frozen data this is

    @property
    def n(self) -> int:
        """Columns."""
        return self.layout.n

    @property
    def m(self) -> int:
        """Rows."""
        return self.layout.m

    @property
    def writeable(self) -> bool:
        """``False`` for the frozen data of a :class:`~prioik.hierarchy.TaskStack`."""
        return bool(self.A.flags.writeable)

    def rows(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Views ``(A_t, b_t)`` of one task's rows and targets."""
        sl = self.layout.task_slice(name)
        return self.A[sl], self.b[sl]

    def bounds(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Views ``(A_t, lower_t, upper_t)`` of one task's rows and bounds."""
        sl = self.layout.task_slice(name)
        return self.A[sl], self.lower[sl], self.upper[sl]

    def weights(self, name: str) -> np.ndarray:
        """View of one task's ``√w`` per row."""
        return self.sqrt_weight[self.layout.task_slice(name)]

    def level_peaks(self) -> np.ndarray:
        """Per level, the largest ``|entry|`` of its rows (every level has a row)."""
        return np.maximum.reduceat(np.abs(self.A).max(axis=1), self.layout.starts[:-1])

    def extreme_levels(self) -> list[int]:
        """The levels :meth:`~prioik.hierarchy.TaskStack.equilibrated` rescales: their
        largest entry non-zero and outside ``[EQUILIBRATE_BELOW, EQUILIBRATE_ABOVE]``."""
        return [i for i, p in enumerate(self.level_peaks().tolist())
                if p > 0 and not EQUILIBRATE_BELOW <= p <= EQUILIBRATE_ABOVE]

    def copy(self) -> StackData:
        """A writable copy."""
        out = StackData(self.layout)
        for key in ("A", "b", "lower", "upper", "sqrt_weight"):
            getattr(out, key)[...] = getattr(self, key)
        return out

    def freeze(self) -> StackData:
        """Make the arrays read-only (returns ``self``)."""
        for key in ("A", "b", "lower", "upper", "sqrt_weight"):
            getattr(self, key).setflags(write=False)
        return self

    def check(self) -> None:
        """The boundary check.

        Raises:
            TaskStackError: naming the first task (and its level and row) whose ``A`` or
                target is not finite, whose bound is NaN (or ``lower = +inf`` /
                ``upper = -inf``), whose ``lower > upper``, or whose ``√w`` is not
                finite and > 0.
        """
        eq = self.layout.row_is_equality
        ok = (np.isfinite(self.A).all() and np.isfinite(self.b[eq]).all()
              and np.isfinite(self.sqrt_weight).all() and (self.sqrt_weight > 0).all())
        if ok and not eq.all():
            lo, up = self.lower[~eq], self.upper[~eq]
            ok = not (np.isnan(lo).any() or np.isnan(up).any() or np.isposinf(lo).any()
                      or np.isneginf(up).any() or (lo > up).any())
        if ok:
            return
        layout = self.layout
        for name in layout.task_names():
            sl = layout.task_slice(name)
            level = layout.level_of(name)
            problems = [("A holds a non-finite value", ~np.isfinite(self.A[sl]).all(axis=1)),
                        ("√w is not finite and > 0",
                         ~(np.isfinite(self.sqrt_weight[sl]) & (self.sqrt_weight[sl] > 0)))]
            if layout.kind_of(name) == "equality":
                problems.append(("b holds a non-finite value", ~np.isfinite(self.b[sl])))
            else:
                lo, up = self.lower[sl], self.upper[sl]
                problems += [("lower is NaN or +inf", np.isnan(lo) | np.isposinf(lo)),
                             ("upper is NaN or -inf", np.isnan(up) | np.isneginf(up)),
                             ("lower > upper", lo > up)]
            for what, bad in problems:
                rows = np.flatnonzero(bad)
                if rows.size:
                    raise TaskStackError(f"{what} in row {int(rows[0])}", task=name,
                                         level=level, row=int(rows[0]))

    def as_stack(self):
        """The :class:`~prioik.hierarchy.TaskStack` of these rows: the stack itself for a
        stack's frozen data, else :meth:`to_stack` (copied, validated)."""
        return self._source if self._source is not None else self.to_stack()

    def to_stack(self):
        """A validated :class:`~prioik.hierarchy.TaskStack` of the current rows (copied)."""
        from .stack import TaskStack
        from .task import Level, Task
        levels = []
        for level in self.layout.levels:
            tasks = []
            for name, _, kind in level:
                sl = self.layout.task_slice(name)
                w = self.sqrt_weight[sl] ** 2
                weight = 1.0 if np.all(self.sqrt_weight[sl] == 1.0) else w
                if kind == "equality":
                    tasks.append(Task(name, self.A[sl], self.b[sl], weight=weight))
                else:
                    tasks.append(Task(name, self.A[sl], lower=self.lower[sl],
                                      upper=self.upper[sl], weight=weight))
            levels.append(Level.of(tasks, hard=len(levels) in self.layout.hard))
        return TaskStack(levels)

    def __repr__(self) -> str:
        return f"StackData({self.layout.describe()})"


def level_residuals(data: StackData, x: np.ndarray) -> np.ndarray:
    """Per level, ``‖√w ∘ violation‖`` of ``x`` (equality: ``A x − b``; inequality: the
    distance of ``A x`` to ``[lower, upper]``)."""
    layout = data.layout
    r = data.A @ x
    if layout.is_equality:
        r -= data.b
    else:
        eq = layout.row_is_equality
        v = np.maximum(data.lower - r, 0.0) + np.maximum(r - data.upper, 0.0)
        r = np.where(eq, r - data.b, v)
    r *= data.sqrt_weight
    return np.sqrt(np.add.reduceat(r * r, layout.starts[:-1]))


def precision_limited_levels(data: StackData, x: np.ndarray,
                             tol: float = DEFAULT_CERTIFICATE_TOL) -> list[int]:
    """The levels whose values at ``x`` float64 cannot give to ``tol``.

    An answer computed through orthogonal transformations has every coordinate rounded
    to about :data:`~prioik.hierarchy.linalg.X_PRECISION` ``‖x‖``, which moves a level's
    ``√W_i A_i x`` by up to ``X_PRECISION ‖x‖ ‖√W_i A_i‖_F``. When a level far above
    drives ``‖x‖`` to 1e12 along directions another level does not touch, that level's
    rows are small numbers computed from huge ones: its values are rounding at a
    precision coarser than ``tol`` times its scale (the scale of
    :func:`~prioik.hierarchy.check_lexicographic`:
    ``‖√w ∘ (|A_i| |x| + |t_i|)‖ + ‖√W_i A_i‖_F``, ``t_i`` the level's targets), and no
    float64 method can stand behind them. Such a level is listed; a solver then says
    ``approximate``.

    Args:
        data: The stack's rows.
        x: The answer (``n``, finite).
        tol: The relative accuracy asked of a level (the certificate's default).

    Returns:
        The indices of the levels whose precision bound exceeds ``tol`` times their
        scale (empty when ``X_PRECISION ‖x‖ ≤ tol``: no level can be).
    """
    x = np.asarray(x, dtype=np.float64)
    top = float(np.max(np.abs(x))) if x.size else 0.0
    if not (top > 0.0 and np.isfinite(top)):
        return []
    # in units of max|x|: the same test, and no overflow at ‖x‖ ~ 1e200
    xs = x / top
    xsn = float(np.linalg.norm(xs))
    if not X_PRECISION * top * xsn > tol:
        return []
    layout = data.layout
    WA = data.sqrt_weight[:, None] * data.A
    ax = data.A @ xs
    if layout.is_equality:
        target = data.b / top
    else:
        target = np.where(layout.row_is_equality, data.b / top,
                          np.clip(ax, data.lower / top, data.upper / top))
    size = data.sqrt_weight * (np.abs(data.A) @ np.abs(xs) + np.abs(target))
    starts = layout.starts[:-1]
    fro = np.sqrt(np.add.reduceat((WA * WA).sum(axis=1), starts))
    scale = np.sqrt(np.add.reduceat(size * size, starts)) + fro / top
    return np.flatnonzero(X_PRECISION * xsn * fro > tol * scale).tolist()


def hard_violations(data: StackData, x: np.ndarray, residuals: np.ndarray | None = None,
                    tol: float = DEFAULT_CERTIFICATE_TOL) -> list[tuple[int, float, float]]:
    """The hard levels of ``data.layout`` (:func:`~prioik.hierarchy.hard`) that ``x``
    leaves violated.

    A hard level ``i`` is violated when its residual ``r_i = ‖√w ∘ violation‖``
    (:func:`level_residuals`) exceeds ``tol`` times its scale, the certificate's
    ``‖√w ∘ (|A_i| |x| + |t_i|)‖ + ‖√W_i A_i‖_F`` (``t_i``: the equality targets and,
    on inequality rows, ``A_i x`` clipped to its bounds): what rounding alone can leave.

    Args:
        data: The stack's rows.
        x: The answer (``n``).
        residuals: Per level ``r_i`` when already computed (else computed here).
        tol: The relative tolerance (the certificate's default).

    Returns:
        ``(level, r_i, scale)`` per violated hard level, increasing (empty when the
        layout has no hard level).
    """
    hard = data.layout.hard
    if not hard:
        return []
    x = np.asarray(x, dtype=np.float64)
    if residuals is None:
        residuals = level_residuals(data, x)
    starts, eq = data.layout.starts, data.layout.row_is_equality
    out = []
    for i in hard:
        sl = slice(int(starts[i]), int(starts[i + 1]))
        A, w = data.A[sl], data.sqrt_weight[sl]
        target = np.where(eq[sl], data.b[sl], np.clip(A @ x, data.lower[sl], data.upper[sl]))
        scale = (level_scale(w * (np.abs(A) @ np.abs(x) + np.abs(target)))
                 + level_scale(w[:, None] * A))
        r = float(residuals[i])
        if not r <= tol * scale:          # (NaN: violated)
            out.append((i, r, scale))
    return out


def precision_reason(levels: list[int], x_norm: float) -> str:
    """The ``diagnostics.reason`` of an ``approximate`` status due to
    :func:`precision_limited_levels`."""
    return (f"‖x‖ = {x_norm:.3g}: x's coordinates are known to about "
            f"{X_PRECISION * x_norm:.2g}, too coarse for level"
            f"{'s' if len(levels) > 1 else ''} {', '.join(map(str, levels))} to "
            f"{DEFAULT_CERTIFICATE_TOL:g} of its scale (float64's limit: another level drives "
            f"‖x‖ up along directions this one does not take)")
