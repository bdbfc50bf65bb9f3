"""The task stack: tasks and levels, highest priority first, validated once; and the
stack as a layout plus data.

Tasks and levels
----------------
Tasks and levels: the rows ``A x ≈ b`` or ``lower ≤ A x ≤ upper`` of a stack.

A task is the paper's ``J_i θ̈ = h_i`` (eq. 3) with ``A = J_i`` and ``b = h_i``; the
library is agnostic of what ``x`` is (accelerations, velocities, torques).

Layout and data
---------------
A stack as a layout plus data: the fixed shape of a hierarchy and its rows.

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

import math
import numbers
import weakref
from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from prioik.errors import UnknownNameError

from .errors import TaskStackError
from .linalg import DEFAULT_CERTIFICATE_TOL, X_PRECISION, level_scale, matrix_rank, rank_profile


def _as_float_array(value, name: str, what: str) -> np.ndarray:
    """``value`` as a read-only float64 copy; only real numbers are accepted.

    Complex values (their imaginary part would be dropped), strings (``"1"`` would
    be parsed), booleans and other objects raise :class:`TaskStackError` naming the
    task and the array.
    """
    if isinstance(value, np.ndarray):
        raw = value
    else:
        try:
            raw = np.asarray(value)
        except (TypeError, ValueError) as exc:
            raise TaskStackError(f"{what} cannot be read as an array of numbers ({exc})",
                                 task=name) from None
    kind = raw.dtype.kind
    if kind == "O":     # e.g. Python ints beyond int64: accept real numbers only
        for v in raw.flat:
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (numbers.Real)):
                raise TaskStackError(f"{what} must hold real numbers, got "
                                     f"{type(v).__name__} {v!r}", task=name)
    elif kind not in "iuf":
        what_kind = {"c": "complex numbers", "b": "booleans", "U": "strings",
                     "S": "bytes", "M": "dates", "m": "time deltas", "V": "records"}
        raise TaskStackError(f"{what} must hold real numbers, got "
                             f"{what_kind.get(kind, raw.dtype.name)} (dtype {raw.dtype})",
                             task=name)
    try:
        arr = np.array(raw, dtype=np.float64, copy=True)
    except (TypeError, ValueError, OverflowError) as exc:
        raise TaskStackError(f"{what} cannot be read as float64 numbers ({exc})",
                             task=name) from None
    arr.setflags(write=False)
    return arr


class Task:
    """One task of a stack.

    Args:
        name: Unique name within a stack; every error message uses it.
        A: Task matrix (``m × n``); a 1-D array is read as one row.
        b: Target of an equality task ``A x ≈ b`` (length ``m``; a scalar for one row).
        lower: Lower bounds of an inequality task ``lower ≤ A x``; ``-inf`` entries
            are unbounded. Only used when ``b`` is ``None``.
        upper: Upper bounds ``A x ≤ upper``; ``+inf`` entries are unbounded.
        weight: Weight of the task among the tasks that share its level, a scalar or
            one value per row. A level minimises ``Σ_t ‖√w_t ∘ (A_t x − b_t)‖²``.

    The arrays are copied and made read-only: a task never aliases caller data.
    Values are checked when the task is placed in a :class:`~hierarchy.TaskStack`
    so that errors can name the level as well as the task.
    """

    __slots__ = ("name", "A", "b", "lower", "upper", "weight", "_unit_weight")

    def __init__(self, name: str, A, b=None, *, lower=None, upper=None,
                 weight=1.0) -> None:
        if not isinstance(name, str) or not name:
            raise TaskStackError(f"a task name must be a non-empty string, got {name!r}")
        self.name = name
        A = _as_float_array(A, name, "A")
        if A.ndim == 1:
            A = A.reshape(1, -1)
            A.setflags(write=False)
        self.A = A
        m = A.shape[0] if A.ndim == 2 else None

        def vec(v, what):
            if v is None:
                return None
            arr = _as_float_array(v, name, what)
            if arr.ndim == 0 and m is not None:
                arr = np.full(m, float(arr))
                arr.setflags(write=False)
            return arr

        self.b = vec(b, "b")
        if self.b is not None and (lower is not None or upper is not None):
            raise TaskStackError("give either b (equality) or lower/upper "
                                 "(inequality), not both", task=name)
        self.lower = vec(lower, "lower")
        self.upper = vec(upper, "upper")
        unit = isinstance(weight, (int, float)) and weight == 1.0
        if unit and m is not None:
            w = np.ones(m)
            w.setflags(write=False)
        else:
            w = _as_float_array(weight, name, "weight")
            if w.ndim == 0 and m is not None:
                w = np.full(m, float(w))
                w.setflags(write=False)
            unit = False
        self.weight = w
        self._unit_weight = unit

    # ------------------------------------------------------------------ checks
    def validate(self, level: int | None = None, n: int | None = None) -> None:
        """Raise :class:`TaskStackError` naming this task (and ``level``) if malformed.

        Args:
            level: Level index used in the message.
            n: Expected number of columns, if known.
        """
        # fast path (one vectorised check per array); the detailed diagnosis below
        # runs only when something is off, or for inequality tasks
        A, b = self.A, self.b
        if (b is not None and self._unit_weight and A.ndim == 2 and A.shape[0]
                and A.shape[1] and (n is None or A.shape[1] == n)
                and b.shape == (A.shape[0],) and np.isfinite(A).all()
                and np.isfinite(b).all()):
            return
        self._diagnose(level, n)

    def _diagnose(self, level: int | None, n: int | None) -> None:
        name = self.name

        def fail(msg, **detail):
            raise TaskStackError(msg, task=name, level=level, **detail)

        A = self.A
        if A.ndim != 2:
            fail(f"A must be a 2-D matrix, got an array of shape {A.shape}", shape=A.shape)
        m, cols = A.shape
        if m == 0 or cols == 0:
            fail(f"A is empty (shape {A.shape})", shape=A.shape)
        if n is not None and cols != n:
            fail(f"A has {cols} columns but the stack has {n} (from its first task)",
                 columns=cols, expected=n)
        if np.isnan(A).any():
            fail(f"A holds NaN at {np.argwhere(np.isnan(A))[:3].tolist()}")
        if np.isinf(A).any():
            fail(f"A holds inf at {np.argwhere(np.isinf(A))[:3].tolist()}")
        if self.b is None and self.lower is None and self.upper is None:
            fail("the task has neither b (equality) nor lower/upper bounds (inequality)")
        for what, v in (("b", self.b), ("lower", self.lower), ("upper", self.upper),
                        ("weight", self.weight)):
            if v is None:
                continue
            if v.shape != (m,):
                fail(f"{what} has shape {v.shape} but A has {m} rows (shape {A.shape})",
                     shape=v.shape, rows=m)
            if np.isnan(v).any():
                fail(f"{what} holds NaN at rows {np.flatnonzero(np.isnan(v))[:5].tolist()}")
        if self.b is not None and np.isinf(self.b).any():
            fail(f"b holds inf at rows {np.flatnonzero(np.isinf(self.b))[:5].tolist()}")
        if self.lower is not None and np.isposinf(self.lower).any():
            fail(f"lower holds +inf at rows {np.flatnonzero(np.isposinf(self.lower))[:5].tolist()}")
        if self.upper is not None and np.isneginf(self.upper).any():
            fail(f"upper holds -inf at rows {np.flatnonzero(np.isneginf(self.upper))[:5].tolist()}")
        if self.lower is not None and self.upper is not None:
            bad = np.flatnonzero(self.lower > self.upper)
            if bad.size:
                i = int(bad[0])
                fail(f"lower > upper at rows {bad[:5].tolist()} (row {i}: "
                     f"{self.lower[i]} > {self.upper[i]})", rows=bad.tolist())
        if not np.isfinite(self.weight).all() or (self.weight <= 0).any():
            fail(f"weight must be finite and > 0, got {self.weight.tolist()[:5]}")

    # ------------------------------------------------------------- properties
    @property
    def m(self) -> int:
        """Number of rows."""
        return int(self.A.shape[0])

    @property
    def n(self) -> int:
        """Number of columns (unknowns)."""
        return int(self.A.shape[1])

    @property
    def is_equality(self) -> bool:
        """``True`` for ``A x ≈ b``, ``False`` for ``lower ≤ A x ≤ upper``."""
        return self.b is not None

    @property
    def kind(self) -> str:
        """``"equality"`` or ``"inequality"``."""
        return "equality" if self.is_equality else "inequality"

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds with omitted sides filled by ``∓inf``."""
        lo = self.lower if self.lower is not None else np.full(self.m, -np.inf)
        up = self.upper if self.upper is not None else np.full(self.m, np.inf)
        return lo, up

    # ------------------------------------------------------------- composition
    def rows(self, indices: Sequence[int] | slice) -> Task:
        """A task made of the selected rows, named ``name[i,j,...]``."""
        if self.A.ndim != 2:
            self.validate()
        idx = np.arange(self.m)[indices] if isinstance(indices, slice) else np.asarray(indices)
        if idx.ndim != 1 or idx.size == 0 or idx.dtype.kind not in "iu":
            raise TaskStackError(f"rows() takes a non-empty list of integer row indices, "
                                 f"got {indices!r}", task=self.name)
        if (idx < -self.m).any() or (idx >= self.m).any():
            raise TaskStackError(f"rows {idx.tolist()} out of range for a task of "
                                 f"{self.m} rows", task=self.name)
        pick = lambda v: None if v is None else v[idx]  # noqa: E731
        return Task(f"{self.name}[{','.join(str(int(i)) for i in idx)}]", self.A[idx],
                    pick(self.b), lower=pick(self.lower), upper=pick(self.upper),
                    weight=self.weight[idx] if self.weight.ndim == 1 else self.weight)

    def scaled(self, factor: float) -> Task:
        """A copy with ``A``, ``b`` and the bounds multiplied by ``factor > 0`` (same
        weight): the task's optimal set is unchanged."""
        w = self.weight if not self._unit_weight else 1.0
        if self.is_equality:
            return Task(self.name, self.A * factor, self.b * factor, weight=w)
        lo = None if self.lower is None else self.lower * factor
        up = None if self.upper is None else self.upper * factor
        return Task(self.name, self.A * factor, lower=lo, upper=up, weight=w)

    def with_weight(self, weight) -> Task:
        """A copy of this task with another weight."""
        if self.is_equality:
            return Task(self.name, self.A, self.b, weight=weight)
        return Task(self.name, self.A, lower=self.lower, upper=self.upper, weight=weight)

    def __add__(self, other) -> Level:
        return Level.of(self) + other

    def __truediv__(self, other) -> TaskStack:
        return TaskStack([self]) / other

    def __repr__(self) -> str:
        shape = "x".join(str(s) for s in self.A.shape)
        return f"Task({self.name!r}, {self.kind}, A {shape})"


class Level(tuple):
    """Tasks that share one priority level (a tuple of :class:`Task`).

    Built by ``t1 + t2``; a stack's levels are :class:`Level` instances, which also
    carry the level's weighted equality rows (see :attr:`A` and :attr:`b`).

    A level is *hard* (:attr:`hard`; declared with :func:`hard`) when its tasks are
    constraints rather than objectives: the lexicographic optimum is solved as for any
    level, and an answer that leaves a hard level violated beyond the certificate's
    tolerance is not ``optimal`` (see :func:`hard`).
    """

    @classmethod
    def of(cls, item, hard: bool | None = None) -> Level:
        """``item`` (a :class:`Level`, a :class:`Task` or a sequence of tasks) as a
        level; ``hard``: declare it hard or not (``None``: as ``item`` is, else not)."""
        if isinstance(item, Level):
            level = item
        elif isinstance(item, Task):
            level = cls((item,))
        elif isinstance(item, Iterable) and not isinstance(item, (str, bytes, np.ndarray)):
            items = tuple(item)
            for t in items:
                if not isinstance(t, Task):
                    raise TaskStackError(f"a level holds Task objects, got {type(t).__name__}")
            level = cls(items)
        else:
            raise TaskStackError(f"a level is a Task or a sequence of Tasks, got "
                                 f"{type(item).__name__}")
        if hard is None or bool(hard) == level.hard:
            return level
        out = cls(tuple(level))
        out.__dict__["_hard"] = bool(hard)
        return out

    @property
    def hard(self) -> bool:
        """Whether the level is declared hard (:func:`hard`)."""
        return self.__dict__.get("_hard", False)

    def __add__(self, other) -> Level:
        other = Level.of(other)
        return Level.of(tuple(self) + tuple(other), hard=self.hard or other.hard)

    def __radd__(self, other) -> Level:
        other = Level.of(other)
        return Level.of(tuple(other) + tuple(self), hard=self.hard or other.hard)

    def __truediv__(self, other) -> TaskStack:
        return TaskStack([self]) / other

    @property
    def tasks(self) -> tuple[Task, ...]:
        """The tasks of the level."""
        return tuple(self)

    @property
    def names(self) -> tuple[str, ...]:
        """The tasks' names."""
        return tuple(t.name for t in self)

    @property
    def m(self) -> int:
        """Total number of rows."""
        return sum(t.m for t in self)

    @property
    def is_equality(self) -> bool:
        """``True`` when every task of the level is an equality task."""
        return all(t.is_equality for t in self)

    @property
    def has_inequality(self) -> bool:
        """``True`` when some task of the level is an inequality task."""
        return any(not t.is_equality for t in self)

    @property
    def A(self) -> np.ndarray:
        """Equality rows scaled by ``√weight`` (stacked, ``Σ m_t × n``)."""
        return self._cached("_A")

    @property
    def b(self) -> np.ndarray:
        """Equality targets scaled by ``√weight``."""
        return self._cached("_b")

    def __repr__(self) -> str:
        return f"{'hard ' if self.hard else ''}Level({tuple.__repr__(self)})"

    def _cached(self, key):
        if key in self.__dict__:
            return self.__dict__[key]
        if len(self) == 1 and self[0].is_equality and self[0]._unit_weight:
            self.__dict__["_A"], self.__dict__["_b"] = self[0].A, self[0].b  # read-only
            return self.__dict__[key]
        eq = [t for t in self if t.is_equality]
        n = self[0].n
        if eq:
            s = [np.sqrt(t.weight) for t in eq]
            A = np.vstack([si[:, None] * t.A for si, t in zip(s, eq, strict=False)])
            b = np.concatenate([si * t.b for si, t in zip(s, eq, strict=False)])
        else:
            A, b = np.zeros((0, n)), np.zeros(0)
        A.setflags(write=False)
        b.setflags(write=False)
        self.__dict__["_A"], self.__dict__["_b"] = A, b
        return self.__dict__[key]


def hard(item) -> Level:
    """The level of ``item`` (a :class:`Task`, a sequence of tasks or a :class:`Level`)
    declared *hard*: ``hard(contact) / reach / posture``, or
    ``TaskStack([hard([left, right]), reach])``.

    A hard level is solved as any level (the lexicographic optimum is the same), but
    its tasks are meant as constraints, as PlaCo's hard tasks are: when the answer leaves
    the level violated — its residual ``‖√w ∘ violation‖`` beyond
    :data:`~prioik.hierarchy.DEFAULT_CERTIFICATE_TOL` times the level's scale (the
    certificate's: ``‖√w ∘ (|A| |x| + |t|)‖ + ‖√W A‖_F``) — the solution's status is
    ``"failed"`` (``x`` stays the least-squares compromise) and its
    ``diagnostics.fault`` names the first such level (code ``"hard_level"``, its level,
    tasks and message), and ``diagnostics.hard_violated_levels`` lists every such level.
    Every formulation is checked the same way, in :class:`~prioik.PreparedSolver`.

    Raises:
        TaskStackError: ``item`` is not a task, tasks or a level.
    """
    return Level.of(item, hard=True)


# ----------------------------------------------------------------------- layout and data
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


# ----------------------------------------------------------------------------- the stack
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
