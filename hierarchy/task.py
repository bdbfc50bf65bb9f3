"""Tasks and levels: the rows ``A x ≈ b`` or ``lower ≤ A x ≤ upper`` of a stack.

A task is the paper's ``J_i θ̈ = h_i`` (eq. 3) with ``A = J_i`` and ``b = h_i``; the
library is agnostic of what ``x`` is (accelerations, velocities, torques).
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from .errors import TaskStackError

if TYPE_CHECKING:  # pragma: no cover
    from .stack import TaskStack


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
        from .stack import TaskStack
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
        from .stack import TaskStack
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
