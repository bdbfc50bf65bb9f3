"""An extended-precision ground truth for small equality stacks.

:func:`exact_optimum` solves an equality stack's lexicographic least-squares problem by
nested SVD null spaces in ``mpmath`` (``dps`` decimal digits, 50 by default), from the
stack's own float64 data read exactly (each task's rows, targets and ``√weight`` in
extended precision, not the float64 products ``√w A``):

    M_i = A_i Z_i,   y_i = M_i⁺ (b_i − A_i x),   x ← x + Z_i y_i,   Z_{i+1} = Z_i null(M_i)

with the rank rule of :mod:`hierarchy.linalg` (``σ > rcond · ‖A_i‖_F``, the threshold
computed in float64 from the level's float64 rows, as every formulation computes it).
A singular value within :data:`~hierarchy.linalg.AMBIGUITY` of the threshold makes the
stack *ambiguous* (:attr:`ExactOptimum.ambiguous_levels`): float64 solvers may take
either decision there, and no answer is judged against the truth.

What it gives is each level's optimal value ``v_i* = ‖w_i(x*)‖²`` (the weighted squared
residual at the truth ``x*``), and :meth:`ExactOptimum.excess`, how far an answer's
values lie above them, evaluated exactly (the answer's float64 coordinates read exactly).
An answer is *above the optimum* at level ``i`` when

    v_i(x) − v_i* > max(VALUE_TOL · v_i*, δ_i),   δ_i = 2 ρ_i √v_i* + ρ_i²,
    ρ_i = p · max(1, ‖x*‖) · ‖√W_i A_i‖_F

— ``δ_i`` is what float64 can tell apart: ``x``'s coordinates are known to about
``p max(1, ‖x‖)``, which moves the level's weighted residual by up to ``ρ_i`` and its
value by up to ``δ_i``. ``p`` is at least :data:`~hierarchy.linalg.X_PRECISION` (16 ε:
rounding through orthogonal transformations); a caller that knows how far rounding may
move this stack's answer (:attr:`hierarchy.fuzz.FuzzCase.rounding_error`) passes the
larger value. In the form ``VALUE_TOL · max(v_i*, floor_i)`` the floor is
``δ_i / VALUE_TOL``.

It is a truth, not a solver: pure-Python extended precision, seconds for ``n`` 40;
:func:`exact_optimum` refuses larger stacks (``None``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .linalg import AMBIGUITY, DEFAULT_RCOND, X_PRECISION, rank_threshold
from .stack import TaskStack

__all__ = ["ExactOptimum", "exact_optimum", "VALUE_TOL", "EXACT_MAX_N"]

#: Relative accuracy asked of an ``optimal`` answer's level values (see module docstring).
VALUE_TOL = 1e-8

#: Largest ``n`` :func:`exact_optimum` solves (its cost grows as ``n³`` per level).
EXACT_MAX_N = 40


@dataclass
class ExactOptimum:
    """The extended-precision optimum of an equality stack (:func:`exact_optimum`).

    Attributes:
        values: ``v_i*`` per level (float64 roundings of the extended-precision values).
        x: The minimum-norm optimum ``x*``, rounded to float64.
        x_norm: ``‖x*‖``.
        level_norms: ``‖√W_i A_i‖_F`` per level.
        ranks: The rank each level adds.
        ambiguous_levels: Levels where a singular value lies within
            :data:`~hierarchy.linalg.AMBIGUITY` of the threshold (the stack is then not
            used to judge answers).
        sigma_ratio: Per level, the smallest kept ``σ / ‖A_i‖_F`` (1 when none is kept).
    """

    values: np.ndarray
    x: np.ndarray
    x_norm: float
    level_norms: np.ndarray
    ranks: list[int]
    ambiguous_levels: list[int] = field(default_factory=list)
    sigma_ratio: np.ndarray | None = None
    _rows: list = field(default_factory=list, repr=False)
    _ctx: Any = field(default=None, repr=False)

    @property
    def ambiguous(self) -> bool:
        """Whether some rank decision is within the ambiguity band."""
        return bool(self.ambiguous_levels)

    def floors(self, precision: float = X_PRECISION) -> np.ndarray:
        """``δ_i``: how much a level's value may move by float64's rounding of ``x``, to
        ``precision`` (relative, at least ``X_PRECISION``; see the module docstring)."""
        rho = max(precision, X_PRECISION) * max(1.0, self.x_norm) * self.level_norms
        return 2.0 * rho * np.sqrt(self.values) + rho * rho

    def values_at(self, x: np.ndarray) -> np.ndarray:
        """Each level's value ``‖w_i(x)‖²`` at a float64 ``x``, evaluated exactly (to the
        truth's precision)."""
        ctx = self._ctx
        xm = _mp_array(ctx, np.asarray(x, dtype=np.float64))
        out = np.empty(len(self._rows))
        for i, (A, b) in enumerate(self._rows):
            r = A.dot(xm) - b
            out[i] = float(ctx.fsum(v * v for v in r))
        return out

    def excess(self, x: np.ndarray, precision: float = X_PRECISION) -> np.ndarray:
        """Per level, ``(v_i(x) − v_i*) / max(VALUE_TOL · v_i*, δ_i)`` (``δ_i`` to
        ``precision``, see the module docstring): above 1 where ``x`` is above the
        optimum beyond what float64 can tell apart (``inf`` when ``x`` is not finite)."""
        x = np.asarray(x, dtype=np.float64)
        if not np.isfinite(x).all():
            return np.full(self.values.shape, np.inf)
        v = self.values_at(x)
        allowed = np.maximum(VALUE_TOL * self.values, self.floors(precision))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(allowed > 0, (v - self.values) / np.where(allowed > 0, allowed,
                                                                        1.0),
                            np.where(v > self.values, np.inf, 0.0))

    def relative_excess(self, x: np.ndarray) -> np.ndarray:
        """Per level, ``(v_i(x) − v_i*) / v_i*`` (``0`` where both are zero)."""
        v = self.values_at(np.asarray(x, dtype=np.float64))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.values > 0, (v - self.values) / np.where(
                self.values > 0, self.values, 1.0), np.where(v > 0, np.inf, 0.0))


def _mp_array(ctx, a: np.ndarray) -> np.ndarray:
    """``a`` as an object array of the context's numbers (each float64 read exactly)."""
    flat = np.empty(a.size, dtype=object)
    mpf = ctx.mpf
    for j, v in enumerate(a.ravel().tolist()):
        flat[j] = mpf(v)
    return flat.reshape(a.shape)


def _weighted_rows(ctx, level) -> tuple[np.ndarray, np.ndarray]:
    """A level's ``√w A`` and ``√w b`` in extended precision, from each task's float64
    rows and weight read exactly."""
    As, bs = [], []
    for t in level:
        w = np.broadcast_to(np.asarray(1.0 if t._unit_weight else t.weight,
                                       dtype=np.float64), (t.m,))
        s = np.array([ctx.sqrt(ctx.mpf(v)) for v in w.tolist()], dtype=object)
        As.append(_mp_array(ctx, np.asarray(t.A, dtype=np.float64)) * s[:, None])
        bs.append(_mp_array(ctx, np.asarray(t.b, dtype=np.float64)) * s)
    return np.vstack(As), np.concatenate(bs)


def exact_optimum(stack: TaskStack, rcond: float = DEFAULT_RCOND, dps: int = 50,
                  max_n: int = EXACT_MAX_N) -> ExactOptimum | None:
    """The lexicographic optimum of an equality stack in extended precision (see the
    module docstring).

    Args:
        stack: An equality stack.
        rcond: Relative rank threshold (the formulations' default).
        dps: Decimal digits of the arithmetic.
        max_n: Larger stacks are not solved.

    Returns:
        The :class:`ExactOptimum`, or ``None`` when ``n > max_n`` or a task is not an
        equality task.
    """
    import mpmath
    if stack.n > max_n or not stack.is_equality:
        return None
    ctx = mpmath.MPContext()
    ctx.dps = dps
    n = stack.n
    x = np.array([ctx.mpf(0)] * n, dtype=object)
    Z = _mp_array(ctx, np.eye(n))
    rows, ranks, ambiguous = [], [], []
    ratios = np.ones(len(stack))
    norms = np.empty(len(stack))
    for i, level in enumerate(stack.levels):
        A, b = _weighted_rows(ctx, level)
        rows.append((A, b))
        norms[i] = float(ctx.sqrt(ctx.fsum(v * v for v in A.ravel())))
        tol = rank_threshold(level.A, rcond)
        d = Z.shape[1]
        if d == 0 or tol <= 0:
            ranks.append(0)
            continue
        M = A.dot(Z)
        m = M.shape[0]
        if m >= d:
            U, S, V = ctx.svd_r(ctx.matrix(M.tolist()), full_matrices=False)
            U = np.array(U.tolist(), dtype=object)          # m × d
            V = np.array(V.tolist(), dtype=object)          # d × d (rows: v_jᵀ)
        else:   # the full right basis from the transpose's left one
            Ut, S, Vt = ctx.svd_r(ctx.matrix(M.T.tolist()), full_matrices=True)
            V = np.array(Ut.tolist(), dtype=object).T       # d × d (rows: v_jᵀ)
            U = np.array(Vt.tolist(), dtype=object).T       # m × m
        s = [S[j] for j in range(min(m, d))]
        r = sum(1 for v in s if v > tol)
        if any(tol / AMBIGUITY < v <= tol * AMBIGUITY for v in s):
            ambiguous.append(i)
        if r:
            ratios[i] = float(s[r - 1]) / norms[i]
            c = b - A.dot(x)
            w = np.array([U[:, j].dot(c) / s[j] for j in range(r)], dtype=object)
            y = V[:r].T.dot(w)
            x = x + Z.dot(y)
        Z = Z.dot(V[r:].T) if r < d else np.zeros((n, 0), dtype=object)
        ranks.append(r)
    values = np.empty(len(stack))
    for i, (A, b) in enumerate(rows):
        res = A.dot(x) - b
        values[i] = float(ctx.fsum(v * v for v in res))
    xf = np.array([float(v) for v in x])
    x_norm = float(ctx.sqrt(ctx.fsum(v * v for v in x)))
    return ExactOptimum(values, xf, x_norm, norms, ranks, ambiguous, ratios, rows, ctx)
