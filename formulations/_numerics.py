"""Numerics shared by the formulation plugins (private: plugins import it, no plugin
imports another's helpers).

* The recursive null-space projection (:func:`project_levels`, one level for ``B``
  stacks at once, and :func:`project_level` on one stack) with the truncated SVD, the
  (damped) generalized inverse and the least-squares refinement its steps use:
  ``nullspace``, ``chiaverini``, ``unifying``, ``operational_space``, ``sns`` and
  ``reference``.
* The QP cascade's levels (:class:`LevelRows`, :class:`Fixed`, the strongly-active and
  infeasibility tolerances, :func:`record_level`) and a back-end's printing silenced
  per thread (:func:`quiet_unless_verbose`): ``cascaded_qp`` and ``cvxpy``.
"""

from __future__ import annotations

import contextlib
import sys
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from prioik.hierarchy import AMBIGUITY, ambiguous_decision

from .base import Diagnostics, FormulationError, Outcome


def check_nonnegative(**values: float) -> None:
    """Raise :class:`FormulationError` for an option that is not a finite number ≥ 0."""
    for key, val in values.items():
        try:
            v = float(val)
        except (TypeError, ValueError):
            raise FormulationError(f"{key} must be a number ≥ 0, got {val!r}") from None
        if not np.isfinite(v) or v < 0:
            raise FormulationError(f"{key} must be a finite number ≥ 0, got {val}")


def truncated_svd(M: np.ndarray, tol: float, report: bool = False):
    """``(U_r, s_r, V_r)`` of ``M`` keeping the singular values ``σ > tol``.

    ``U_r`` is ``m × r``, ``V_r`` is ``n × r``. An empty ``M`` (or ``tol ≤ 0`` with a
    zero scale) gives ``r = 0``. With ``report``, a fourth value says whether the
    decision was ambiguous (:func:`hierarchy.ambiguous_decision`).
    """
    m, n = M.shape
    if M.size == 0:
        out = np.zeros((m, 0)), np.zeros(0), np.zeros((n, 0))
        return (*out, False) if report else out
    u, s, vt = np.linalg.svd(M, full_matrices=False)
    r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
    out = u[:, :r], s[:r], vt[:r].T
    return (*out, ambiguous_decision(s, tol)) if report else out


def generalized_inverse(M: np.ndarray, tol: float, damping: float = 0.0
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``M^#`` and the orthonormal bases of ``M``'s kept row and column spaces.

    ``M^# = V diag(σ/(σ² + λ)) Uᵀ`` over the singular values ``σ > tol``; with
    ``damping = λ = 0`` that is the truncated pseudo-inverse ``M⁺``.

    Returns:
        ``(M^#, V_r, U_r)``; ``V_r V_rᵀ = M⁺ M`` is the projector onto the kept row space.
    """
    U, s, V = truncated_svd(M, tol)
    gain = s / (s * s + damping) if damping > 0 else 1.0 / s
    return (V * gain) @ U.T, V, U


#: Steps of :func:`refinement` a level's least-squares step gets: one left a level of a
#: task at 6e-10 beside rows of 0.5 and zero rows with targets 6e-6 off, two reach ε.
REFINEMENT_STEPS = 2


def refinement(M: np.ndarray, c: np.ndarray, y: np.ndarray, Vt: np.ndarray,
               keep: np.ndarray, sv: np.ndarray) -> np.ndarray:
    """The correction of a least-squares step ``y ≈ M_r⁺ c`` computed from an SVD
    ``M = U Σ Vᵀ`` (rank rule ``keep``): ``V_r Σ_r⁻² V_rᵀ Mᵀ (c − M y)``, one step of
    iterative refinement, for ``B`` stacks at once (``B × m × d`` ``M``, ``B × m × 1``
    ``c``, ``B × d × 1`` ``y``, ``B × p × d`` ``Vt``, ``B × p`` ``keep`` and ``sv``).

    An SVD is backward stable in norm only: a level's rows far smaller than its norm
    (zero or tiny rows beside large ones, tasks decades apart) are read with errors of
    ``ε ‖M‖``, and where their targets are large their residuals leak into ``U_rᵀ c``
    and the step by ``ε ‖M‖ ‖c‖ / σ²``. ``Mᵀ (c − M y)`` is formed row by row, each
    row's term on its own scale (a zero row adds exactly nothing), so the correction
    removes that error; on a level whose rows share one scale it is at rounding level.
    """
    r = c - M @ y                                                      # B × m × 1
    g = Vt @ (np.swapaxes(M, 1, 2) @ r)                                # B × p × 1
    safe = np.where(keep, sv, 1.0)
    return np.swapaxes(Vt, 1, 2) @ (np.where(keep, 1.0 / (safe * safe), 0.0)[:, :, None] * g)


def project_levels(A: np.ndarray, b: np.ndarray, X: np.ndarray, N: np.ndarray,
                   tol: np.ndarray, damping: float = 0.0, reproject: bool = True
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One level of null-space projection (:mod:`formulations.nullspace`) for ``B``
    stacks at once: ``Ĵ_i = A N_{i-1}``, the step
    ``x_i = x_{i-1} + N_{i-1} Ĵ_i^# (b − A x_{i-1})`` (without the leading ``N_{i-1}``
    when not ``reproject``) and
    ``N_i = N_{i-1} − V Vᵀ`` with ``V`` re-orthonormalised in ``range(N_{i-1})``.

    The one implementation of a level: ``nullspace.solve`` runs it on one stack
    (``B = 1``), ``nullspace.solve_batch`` on many, ``sns`` for its unbounded step — so
    every path makes the same rank decisions with the same arithmetic (a stacked SVD or
    product is the per-matrix one), and ``solve`` equals ``solve_batch`` bit for bit.
    Singular values are masked by the rank rule instead of truncated, so stacks of
    different ranks share the arrays.

    Args:
        A, b: ``B × m × n`` rows and ``B × m`` targets of the level (weighted).
        X, N: ``B × n`` answers and ``B × n × n`` projectors so far (not modified).
        tol: ``B`` absolute rank thresholds (:func:`hierarchy.rank_threshold` of each
            ``A``; ``≤ 0``: the level keeps nothing).
        damping: ``λ`` of the damped inverse (0: pseudo-inverse).
        reproject: Multiply the step by ``N_{i-1}`` once more.

    Returns:
        ``(X_i, N_i, keep, σ, ambiguous)``: ``keep`` (``B × p``) masks the kept singular
        values ``σ`` of ``Ĵ_i`` (sorted, largest first); ``ambiguous`` (``B``) flags a
        singular value within :data:`hierarchy.AMBIGUITY` of ``tol``.
    """
    count, m, n = A.shape
    if m == 0:
        return (X, N, np.zeros((count, 0), dtype=bool), np.zeros((count, 0)),
                np.zeros(count, dtype=bool))
    J = A @ N
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    t = tol[:, None]
    keep = (sv > t) & (t > 0)
    near = ((sv > t / AMBIGUITY) & (sv <= t * AMBIGUITY) & (t > 0)).any(axis=1)
    safe = np.where(keep, sv, 1.0)
    gain = np.where(keep, safe / (safe * safe + damping) if damping > 0 else 1.0 / safe, 0.0)
    residual = b[:, :, None] - A @ X[:, :, None]                       # B × m × 1
    step = np.swapaxes(Vt, 1, 2) @ (gain[:, :, None] * (np.swapaxes(U, 1, 2) @ residual))
    if damping == 0:
        for _ in range(REFINEMENT_STEPS):
            step = step + refinement(J, residual, step, Vt, keep, sv)
    if reproject:
        step = N @ step                                            # N_{i-1} Ĵ_i^# = Ĵ_i^#
    X = X + step[:, :, 0]
    # V in range(N_{i-1}) to rounding (module docstring): the kept singular vectors come
    # first (σ sorted), so the QR's leading columns span N V_r; the others are masked
    V, _ = np.linalg.qr(N @ np.swapaxes(Vt, 1, 2))                  # B × n × p
    V = V * keep[:, None, :]
    return X, N - V @ np.swapaxes(V, 1, 2), keep, sv, near         # N_i = N_{i-1} − Ĵ⁺Ĵ


def project_level(A: np.ndarray, b: np.ndarray, x: np.ndarray, N: np.ndarray, tol: float,
                  damping: float = 0.0, reproject: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """:func:`project_levels` on one stack: ``(x_i, N_i, σ_kept, ambiguous)``."""
    X, N, keep, sv, near = project_levels(A[None], b[None], x[None], N[None],
                                          np.array([tol]), damping, reproject)
    return X[0], N[0], sv[0][keep[0]], bool(near[0])


class _ThreadSilencer:
    """A ``sys.stdout`` stand-in that drops the writes of the threads it silences and
    passes every other thread's writes to the stream it replaced."""

    def __init__(self, target) -> None:
        self.target = target
        self.silenced: dict[int, int] = {}          # thread id -> nesting depth

    def write(self, text: str) -> int:
        if threading.get_ident() in self.silenced:
            return len(text)
        return self.target.write(text)

    def __getattr__(self, name: str):
        return getattr(self.target, name)


_silencer_lock = threading.Lock()
_silencer: _ThreadSilencer | None = None


@contextlib.contextmanager
def _silence_this_thread():
    global _silencer
    tid = threading.get_ident()
    with _silencer_lock:
        if _silencer is None or sys.stdout is not _silencer:
            _silencer = _ThreadSilencer(sys.stdout)
            sys.stdout = _silencer
        _silencer.silenced[tid] = _silencer.silenced.get(tid, 0) + 1
        mine = _silencer
    try:
        yield
    finally:
        with _silencer_lock:
            depth = mine.silenced.pop(tid) - 1
            if depth:
                mine.silenced[tid] = depth
            if not mine.silenced and sys.stdout is mine:
                sys.stdout = mine.target
                _silencer = None


def quiet_unless_verbose(settings: dict[str, Any]):
    """A context that discards what a back-end prints unless ``settings["verbose"]``.

    OSQP prints "Polishing not needed ..." through Python's ``sys.stdout`` at every
    solve with ``polishing=True`` (which ``cascaded_qp.backend_settings`` sets), even with
    ``verbose=False``; a back-end's own log is asked for with
    ``backend_options={"verbose": True}``. Only the calling thread is silenced
    (``contextlib.redirect_stdout`` swaps the stream of every thread, and concurrent
    solves could leave it swapped).
    """
    if settings.get("verbose"):
        return contextlib.nullcontext()
    return _silence_this_thread()


# ----------------------------------------------------------------- the levels
@dataclass
class LevelRows:
    """The rows of one level in QP form.

    Attributes:
        A_eq: Weighted equality rows ``√W A`` (``m_e × n``).
        b_eq: ``√W b``.
        A_in: Inequality rows with at least one finite bound.
        lower: Their lower bounds (``-inf`` allowed).
        upper: Their upper bounds (``+inf`` allowed).
        w_in: Weight of each inequality row.
        task_of_row: Task name of each inequality row.
    """

    A_eq: np.ndarray
    b_eq: np.ndarray
    A_in: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    w_in: np.ndarray
    task_of_row: list[str] = field(default_factory=list)


def level_rows(level) -> LevelRows:
    """Split a :class:`~hierarchy.Level` into weighted equality and inequality rows.

    Inequality rows without a finite bound, and zero rows (whose violation no ``x``
    changes), are left out.
    """
    n = level[0].n
    A_in, lo, up, w, names = [], [], [], [], []
    for t in level:
        if t.is_equality:
            continue
        tl, tu = t.bounds()
        # a zero row has a fixed violation (0 ∉ [l, u] stays violated whatever x is):
        # it stays in the level's ‖w_i‖² but not in the QP, where normalising it gave NaN
        keep = (np.isfinite(tl) | np.isfinite(tu)) & np.any(t.A != 0.0, axis=1)
        A_in.append(t.A[keep])
        lo.append(tl[keep])
        up.append(tu[keep])
        w.append(np.broadcast_to(t.weight, (t.m,))[keep])
        names += [t.name] * int(keep.sum())
    if A_in:
        return LevelRows(level.A, level.b, np.vstack(A_in), np.concatenate(lo),
                         np.concatenate(up), np.concatenate(w), names)
    return LevelRows(level.A, level.b, np.zeros((0, n)), np.zeros(0), np.zeros(0),
                     np.zeros(0), names)


def slacks(A: np.ndarray, lower: np.ndarray, upper: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Signed violation ``v = A x − clip(A x, lower, upper)`` of inequality rows."""
    Ax = A @ x
    return Ax - np.clip(Ax, lower, upper)


def split_null_space(A: np.ndarray, Z: np.ndarray, rcond: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Split ``range(Z)`` into the directions ``A`` sees and its null space (eq. 13).

    Returns:
        ``(Z V_r, Z V_0)``: orthonormal ``n × r`` and ``n × (d − r)`` bases, ``r`` the
        rank of ``A Z`` with threshold ``rcond · ‖A‖_F``.
    """
    if A.shape[0] == 0 or Z.shape[1] == 0:
        return Z[:, :0], Z
    _, s, vt = np.linalg.svd(A @ Z, full_matrices=True)
    tol = rcond * float(np.linalg.norm(A))
    r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
    return Z @ vt[:r].T, Z @ vt[r:].T


@dataclass
class Fixed:
    """What the levels solved so far impose on the next ones.

    Attributes:
        x: The latest level's answer ``x*``.
        Z: Orthonormal basis of the null space of every higher equality row.
        R: Orthonormal basis of their row space (``[R Z]`` is orthogonal).
        eq_rows: The literal higher equality rows (``fixing="rows"``).
        A_in, lower, upper: Higher inequality rows with bounds relaxed by slacks.
        tasks: Names of the tasks fixed so far.
    """

    x: np.ndarray
    Z: np.ndarray
    R: np.ndarray
    eq_rows: list[np.ndarray]
    A_in: list[np.ndarray]
    lower: list[np.ndarray]
    upper: list[np.ndarray]
    tasks: list[str]

    @classmethod
    def start(cls, n: int) -> Fixed:
        return cls(np.zeros(n), np.eye(n), np.zeros((n, 0)), [], [], [], [], [])

    def add(self, rows: LevelRows, names, x: np.ndarray, rcond: float,
            active: np.ndarray | None = None) -> np.ndarray:
        """Fix a solved level at ``x``; returns the slacks of its inequality rows.

        ``active`` holds unit rows of inequality constraints that are strongly active
        at ``x`` (positive multiplier): every optimum of the level satisfies them with
        equality (complementary slackness), so they join the equality fixing.
        """
        self.x = x
        v = slacks(rows.A_in, rows.lower, rows.upper, x)
        extra = [] if active is None else [active]
        if rows.A_in.shape[0]:
            # a violated row keeps A x = bound + v at every optimum (v is unique)
            viol = np.abs(v) > ACTIVE_TOL * np.maximum(1.0, np.abs(rows.A_in @ x))
            norms = np.linalg.norm(rows.A_in, axis=1)
            viol &= norms > 0     # a violated zero row (0 ∉ [lower, upper]) fixes nothing
            if viol.any():
                extra.append(rows.A_in[viol] / norms[viol, None])
        eq = rows.A_eq
        if extra:
            blocks = [eq / max(float(np.linalg.norm(eq)) / np.sqrt(eq.shape[0]), 1e-300)] \
                if eq.shape[0] else []
            eq = np.vstack(blocks + extra)
        if eq.shape[0]:
            Rn, self.Z = split_null_space(eq, self.Z, rcond)
            self.R = np.hstack([self.R, Rn])
            self.eq_rows.append(eq)
        if rows.A_in.shape[0]:
            self.A_in.append(rows.A_in)
            self.lower.append(rows.lower + v)
            self.upper.append(rows.upper + v)
        # An inequality row inside the fixed row space has a constant value on the
        # optimal set (the value it has at x), so it is implied: drop it.
        for i in range(len(self.A_in)):
            A = self.A_in[i]
            keep = np.linalg.norm(A @ self.Z, axis=1) > 1e-8 * np.linalg.norm(A, axis=1)
            if not keep.all():
                self.A_in[i], self.lower[i], self.upper[i] = \
                    A[keep], self.lower[i][keep], self.upper[i][keep]
        self.tasks += list(names)
        return v


def unit_rows(A: np.ndarray, lower: np.ndarray, upper: np.ndarray):
    """``lower ≤ A x ≤ upper`` with every row scaled to unit norm (same set)."""
    s = np.linalg.norm(A, axis=1)
    s[s == 0] = 1.0
    return A / s[:, None], lower / s, upper / s


def level_scale(rows: LevelRows) -> float:
    """The level's RMS row norm (1 when it is zero or not finite)."""
    m = rows.A_eq.shape[0] + rows.A_in.shape[0]
    s = np.sqrt((float(np.sum(rows.A_eq ** 2)) + float(np.sum(rows.A_in ** 2))) / max(m, 1))
    return s if np.isfinite(s) and s > 0 else 1.0


def scaled_level(rows: LevelRows) -> LevelRows:
    """The level divided by its RMS row norm: same minimiser, better-scaled QP."""
    s = level_scale(rows)
    if s == 1.0:
        return rows
    return LevelRows(rows.A_eq / s, rows.b_eq / s, rows.A_in / s, rows.lower / s,
                     rows.upper / s, rows.w_in, rows.task_of_row)


#: A constraint ``g z ≤ h`` counts as strongly active when its multiplier exceeds
#: ``MULTIPLIER_TOL · max(1, ‖λ‖_∞)`` and its slack ``h − g z`` is below
#: ``ACTIVE_TOL · max(1, |h|)``.
MULTIPLIER_TOL = 1e-7


ACTIVE_TOL = 1e-7


def record_level(diagnostics: Diagnostics, rec: dict, level, x: np.ndarray, tol: float,
                 on_infeasible: str, fail) -> Outcome | None:
    """Append level ``rec["level"]``'s record to the cascade's detail record
    (``diagnostics.detail``: its ``levels`` and ``violated``) and diagnose its
    inequalities.

    Inequality tasks of the level that ``x`` violates beyond ``tol`` are named in
    ``rec["violated"]`` and the detail's ``violated``, the level in
    ``diagnostics.infeasible_levels``; with ``on_infeasible="fail"`` the failed
    :class:`~prioik.formulations.Outcome` from ``fail(level, tasks, message, x)`` is
    returned (``None`` otherwise), shared by every cascade.
    """
    j = rec["level"]
    detail = diagnostics.detail
    bad = violated_tasks(level, x, tol)
    if bad:
        rec["violated"] = bad
        diagnostics.infeasible_levels = [*diagnostics.infeasible_levels, j]
        detail.violated.append({"level": j, "tasks": sorted(bad), "violation": bad})
    detail.levels.append(rec)
    if bad and on_infeasible == "fail":
        names = ", ".join(f"{k} (violation {v:.3g})" for k, v in bad.items())
        return fail(j, sorted(bad), f"level {j}: inequality tasks {names} cannot "
                    f"hold together with the levels above", x)
    return None


def violated_tasks(level, x: np.ndarray, tol: float) -> dict[str, float]:
    """Inequality tasks of ``level`` violated at ``x`` beyond ``tol`` (relative)."""
    out = {}
    for t in level:
        if t.is_equality:
            continue
        lo, up = t.bounds()
        v = slacks(t.A, lo, up, x)
        viol = float(np.sqrt(np.sum(np.broadcast_to(t.weight, (t.m,)) * v * v)))
        if viol > tol * max(1.0, float(np.linalg.norm(t.A)) * float(np.linalg.norm(x))):
            out[t.name] = viol
    return out

