"""The extended-Jacobian framework of Jeong & Chang (2009), eq. 15-18 and eq. 27.

Each level ``i > 1`` contributes the rows ``Z_i J_iᵀ J_i θ̈ = Z_i J_iᵀ h_i`` (eq. 14),
the stationarity condition of its least-squares error restricted to the null space
of the levels above; stacked under ``J_1`` they form the extended Jacobian ``J_E``
(eq. 15), ``h_E`` (eq. 16), and ``θ̈ = J_E⁺ h_E`` (eq. 18). Theorem 1 shows that the
system equals the full-row-rank system of the *feasible* rows (eq. 25-26).

Two paths compute the same answer:

* ``nullspace="svd"`` — as the paper: each ``Z_i`` from an SVD of the augmented
  Jacobian ``J_{i-1}^A`` (eq. 7, 13), ``J_E`` built literally, solved with an SVD
  pseudo-inverse keeping ``ρ(J_k^A)`` singular values (the rank Theorem 1 gives).
  When ``J_1`` is rank-deficient its block is ``J_1ᵀ J_1`` (eq. 14 with ``Z_1 = I``),
  so that an inconsistent first level is solved in the least-squares sense
  instead of being mixed with lower levels. Because the blocks hold ``J_iᵀ J_i``
  this path squares the conditioning: its error relative to the exact optimum is
  about ``ε κ(J_E)`` (measured ≤ 200 ε κ over 1500 random stacks;
  ``info["condition_number"]`` reports ``κ(J_E)``), while the ``qr`` path works on
  ``A_i`` itself. The status is therefore ``approximate`` (``info["reason"]`` says
  why) when ``κ(J_E) > SVD_CERTIFIED_CONDITION`` (1e5) or a rank decision is
  ambiguous (:mod:`hierarchy.linalg`).
* ``nullspace="qr"`` (default) — every ``Z_i`` from one nested orthogonal
  factorization, without SVD: level by level, a Householder QR with column pivoting
  of ``(A_i Z_i)ᵀ`` splits the free directions into the level's feasible ones (its
  rank ``r_i``) and the new null space ``Z_{i+1}``; its reflectors are applied to the
  rows of the lower levels only (``O(m n r_i)``, total independent of the number of
  levels). In the rotated coordinates the extended system is block lower-triangular
  and is solved by forward substitution (triangular solves; a small QR where a level
  conflicts), the feasible rows of eq. 26. A level with at least as many rows as
  free directions (``m_i ≥ n − Σ_{j<i} r_j``; e.g. a posture level at the bottom),
  undamped and unbounded, is first tried with one QR with column pivoting of
  ``A_i Z_i`` itself (same rank threshold): when it has full column rank its
  least-squares solution follows from that single factorization (instead of the
  row-pivoted one and then a least-squares QR) and it leaves no null space; when it
  is rank-deficient the row-pivoted path runs as above.

``level_damping=λ_max`` with ``singular_threshold=ε`` (``qr`` path) is a selective
alternative to eq. 27: a level is damped only when the smallest singular value of
its projected rows ``A_i Z_i`` (estimated by the smallest ``|R_jj|`` of the pivoted QR)
falls below ``ε‖A_i‖_F``, with the variable damping ``μ² = λ_max (1 − (σ/ε‖A_i‖_F)²)``
of the singular-robust inverse (Nakamura 1986, Chiaverini 1997). The damped level
still owns its ``r_i`` directions, so every higher level stays exact and no lower
level can use them; θ̈ stays bounded (the level's step is at most
``‖p‖ / (2√μ²)``). The status is ``"approximate"`` when some level was damped, and
``info["damped_levels"]`` lists them.

``step_bound=Δ`` (``qr`` path) bounds every level's own step: the level's part of θ̈,
``z_i`` (``‖x_i − x_{i−1}‖``, the coordinates it adds in its feasible directions),
solves the trust-region least-squares problem ``min ‖A_i Z_i z − p_i‖ s.t. ‖z‖ ≤ Δ``
(Moré 1983). Where the exact step is shorter than ``Δ`` nothing changes; where it is
longer — near an algorithmic or kinematic singularity, or when a far target pulls a
level — the level is solved by damped least squares ``(LᵀL + μ_i² I) z = Lᵀp`` with the
``μ_i`` that makes ``‖z‖ = Δ`` (Newton on ``1/‖z(μ²)‖ − 1/Δ`` from the SVD of the level's
small ``m_i × r_i`` block). It damps only the level and only the steps that need it:
every higher level stays exact, the damped level still owns its ``r_i`` directions,
and ``‖θ̈‖ ≤ √k Δ`` by construction (the steps are orthogonal). It composes with the
selective damping (``μ_i² ≥`` the selective value). ``info["level_damping"]`` holds
every level's ``μ_i²`` (0 where exact), so a cascade of QPs with the same Tikhonov
terms (``cascaded_qp``'s ``level_damping``) reproduces the whole θ̈.

``damping=λ > 0`` is eq. 27: the lower blocks become ``Z_i (J_iᵀ J_i + λ I)`` and the
(generally over-determined) system is solved in the least-squares sense (SVD
pseudo-inverse on the ``svd`` path, complete orthogonal decomposition ``dgelsy`` on
the ``qr`` path). As the paper notes, this bounds θ̈ near algorithmic singularities
at the cost of task accuracy; it also lets lower levels trade accuracy with one
another (every damped block has full rank).
"""

from __future__ import annotations

import math
import threading

import numpy as np
from scipy.linalg import lapack

from prioik.hierarchy import (AMBIGUITY, DEFAULT_RCOND, StackBuffer, TaskStack, ambiguity_reason,
                              ambiguous_decision, level_scale, rank_threshold)

from .base import Capabilities, FormulationError, Outcome

try:  # the compiled kernel is optional: the lapack path is the readable reference
    from . import _extended_jacobian_kernel as _kernel
    _kernel_error = ""
except ImportError as exc:  # pragma: no cover - numba is a declared dependency
    _kernel = None
    _kernel_error = f"{type(exc).__name__}: {exc}"

NAME = "extended_jacobian"
DESCRIPTION = "Jeong & Chang extended Jacobian (eq. 15-18), damped form eq. 27"
CAPABILITIES = Capabilities(equalities=True, inequalities=False, weights=True,
                            needs_mass_matrix=False, exact=True)
OPTIONS = {
    "nullspace": ("qr", "'qr': nested pivoted QR, no SVD; 'svd': SVD of J_{i-1}^A as the paper"),
    "damping": (0.0, "λ ≥ 0 of eq. 27 (0: exact eq. 18)"),
    "rcond": (DEFAULT_RCOND, "relative rank threshold: σ counts if σ > rcond·‖A_i‖_F"),
    "level_damping": (0.0, "λ_max of the selective damping (qr path; 0: off)"),
    "kernel": ("auto", "qr path: 'numba' (compiled), 'lapack' (readable scipy.linalg.lapack), "
                       "'auto' (numba when importable and n ≤ 160, else lapack)"),
    "singular_threshold": (0.0, "ε: damp a level whose projected σ_min < ε·‖A_i‖_F"),
    "step_bound": (0.0, "Δ > 0: every level's step ‖x_i − x_{i−1}‖ ≤ Δ by trust-region "
                        "damping (qr path; 0: off); or k values (one per level, 0: "
                        "unbounded), or {task name: Δ} for the levels holding those tasks"),
}

_dgeqp3 = lapack.dgeqp3
_dgeqrf = lapack.dgeqrf
_dormqr = lapack.dormqr
_dtrtrs = lapack.dtrtrs


#: ``kernel="auto"`` uses the compiled kernel up to this many unknowns. Its loops win
#: where call overhead dominates; LAPACK's blocked Householder code wins on larger
#: problems. Measured median µs numba/lapack (one thread, k = 2/16 levels): compatible
#: n=100 76/122 and 72/304, n=150 200/263 and 191/469, n=200 719/512 and 686/727;
#: conflicting n=150 396/507 and 363/697, n=200 2924/1679 and 1004/1532.
AUTO_NUMBA_MAX_N = 160


def _resolve_kernel(kernel: str, n: int = 0) -> str:
    if kernel not in ("auto", "numba", "lapack"):
        raise FormulationError(f"kernel must be 'auto', 'numba' or 'lapack', got {kernel!r}")
    if kernel == "lapack" or (kernel == "auto" and (_kernel is None or n > AUTO_NUMBA_MAX_N)):
        return "lapack"
    if _kernel is None:
        raise FormulationError(f"kernel='numba' is not available here: {_kernel_error}; "
                               f"install it with `pip install numba`")
    return "numba"


def solve(stack: TaskStack, *, nullspace: str = "qr", damping: float = 0.0,
          rcond: float = DEFAULT_RCOND, level_damping: float = 0.0,
          singular_threshold: float = 0.0, kernel: str = "auto",
          step_bound=0.0) -> Outcome:
    """Solve the extended system (eq. 17) for ``x``; see the module docstring."""
    kernel = _resolve_kernel(kernel, stack.n)
    if nullspace not in ("qr", "svd"):
        raise FormulationError(f"nullspace must be 'qr' or 'svd', got {nullspace!r}")
    _check_nonnegative(damping=damping, level_damping=level_damping,
                       singular_threshold=singular_threshold, rcond=rcond)
    damping = float(damping)
    selective = float(level_damping) > 0 and float(singular_threshold) > 0
    bound = level_step_bounds(stack, step_bound)
    if (selective or bound.any()) and (damping > 0 or nullspace != "qr"):
        raise FormulationError("level_damping and step_bound work on the qr path without "
                               "eq. 27 damping; use one or the other")
    if damping > 0:
        return _solve_damped(stack, damping, rcond, nullspace)
    if nullspace == "svd":
        return _solve_svd(stack, rcond)
    lam = float(level_damping) if selective else 0.0
    if kernel == "numba":
        return _solve_qr_compiled(stack, rcond, lam, float(singular_threshold), bound)
    return _solve_qr(stack, rcond, lam, float(singular_threshold), bound)


def _check_nonnegative(**values: float) -> None:
    """Raise :class:`FormulationError` naming the first option not finite and ≥ 0."""
    for key, val in values.items():
        if not (0.0 <= val < math.inf):   # also False for NaN
            raise FormulationError(f"{key} must be a finite number ≥ 0, got {val}")


def level_step_bounds(stack: TaskStack | StackBuffer, step_bound) -> np.ndarray:
    """The per-level bounds ``Δ_i`` (0: unbounded) of the ``step_bound`` option.

    Args:
        stack: The stack (or buffer layout).
        step_bound: One ``Δ ≥ 0`` for every level, ``k`` values, or a mapping task
            name → ``Δ`` (a level gets the smallest bound of its tasks).

    Raises:
        FormulationError: a value is negative or not finite, the sequence has the
            wrong length, or a task name is not in the stack.
    """
    k = len(stack)
    if isinstance(step_bound, dict):
        out = np.zeros(k)
        for name, val in step_bound.items():
            try:
                i = stack.level_of(name)
            except KeyError:
                names = [n for level in stack.levels for n in level.names] \
                    if isinstance(stack, TaskStack) else [n for lv in stack.names for n in lv]
                raise FormulationError(f"step_bound names task {name!r}, which is not in "
                                       f"the stack (tasks: {', '.join(names)})") from None
            out[i] = float(val) if out[i] == 0 else min(out[i], float(val))
    else:
        try:
            out = np.broadcast_to(np.asarray(step_bound, dtype=np.float64), (k,)).copy()
        except ValueError:
            raise FormulationError(f"step_bound must be one number, {k} numbers (one per "
                                   f"level) or a task-name mapping, got {step_bound!r}"
                                   ) from None
    if not np.all(np.isfinite(out)) or np.any(out < 0):
        raise FormulationError(f"step_bound must be finite and ≥ 0, got {out.tolist()}")
    return out


def _damping_info(info: dict, mu2: np.ndarray, selective: bool, bound: bool) -> str:
    """Record the per-level damping in ``info``; the status it implies."""
    if not (selective or bound):
        return "optimal"            # the kernels damp no level without either option
    flagged = np.flatnonzero(mu2 > 0).tolist()
    info["damped_levels"] = flagged
    info["level_damping"] = mu2.copy()
    return "approximate" if flagged else "optimal"


def _solve_qr_compiled(stack: TaskStack, rcond: float, level_damping: float,
                       singular_threshold: float, step_bound: np.ndarray) -> Outcome:
    packed = stack.packed()
    k = len(stack)
    x, ranks, mu2 = np.empty(stack.n), np.zeros(k, dtype=np.int64), np.zeros(k)
    margins = np.empty(k)
    _kernel.solve_kernel(packed.A.copy(), packed.b.copy(), packed.starts, packed.scales,
                         rcond, level_damping, singular_threshold, step_bound, x, ranks, mu2,
                         margins)
    return _wrap_outcome(x, ranks, mu2, margins, level_damping > 0, bool(step_bound.any()))


def _wrap_outcome(x, ranks, mu2, margins, selective: bool, bounded: bool) -> Outcome:
    """The compiled kernel's outputs (copied out of the workspace) as an
    :class:`Outcome`."""
    info = {"rank_profile": ranks.copy(), "nullspace": "qr", "kernel": "numba"}
    status = _damping_info(info, mu2, selective, bounded)
    if margins.min() <= AMBIGUITY:
        status = _ambiguity_status(info, status, np.flatnonzero(margins <= AMBIGUITY))
    return Outcome(x.copy(), status, info)


class BufferSolver:
    """The compiled ``qr`` path on a :class:`~hierarchy.StackBuffer`, for control loops.

    :func:`solve` takes a :class:`~hierarchy.TaskStack` (validated, packed and copied
    per call); a loop that refills the same layout at every step can instead fill a
    buffer and call :meth:`solve`, which copies the rows into a preallocated
    workspace, checks them (finite, in the same pass that takes the level scales)
    and runs the same kernel (eq. 15-18 by nested
    pivoted QR): no ``Task`` objects, no packing, no allocation but the answer.
    The answer equals ``solve(buffer.to_stack(), ...)`` bit for bit (same kernel,
    same inputs; asserted in ``tests/test_extended_jacobian.py``).

    Args:
        buffer: The layout (and the default rows) to solve.
        rcond, level_damping, singular_threshold, step_bound: As for :func:`solve`
            (``step_bound``: one value, one per level, or a task-name mapping).

    Raises:
        FormulationError: numba is missing, or an option is out of range.
    """

    def __init__(self, buffer: StackBuffer, *, rcond: float = DEFAULT_RCOND,
                 level_damping: float = 0.0, singular_threshold: float = 0.0,
                 step_bound=0.0) -> None:
        if _kernel is None:
            raise FormulationError(f"BufferSolver needs the compiled kernel: {_kernel_error}; "
                                   f"install it with `pip install numba`")
        _check_nonnegative(level_damping=level_damping, rcond=rcond,
                           singular_threshold=singular_threshold)
        k = len(buffer)
        self.buffer = buffer
        self.rcond = float(rcond)
        selective = float(level_damping) > 0 and float(singular_threshold) > 0
        self.level_damping = float(level_damping) if selective else 0.0
        self.singular_threshold = float(singular_threshold)
        self.step_bound = step_bound
        self._B = np.empty_like(buffer.A)
        self._c = np.empty_like(buffer.b)
        self._scales = np.zeros(k)
        self._x = np.empty(buffer.n)
        self._ranks = np.zeros(k, dtype=np.int64)
        self._mu2 = np.zeros(k)
        self._margins = np.zeros(k)
        self._lock = threading.Lock()

    @property
    def step_bound(self) -> np.ndarray:
        """Per-level ``Δ_i`` (0: unbounded); set like the constructor's argument."""
        return self._step_bound

    @step_bound.setter
    def step_bound(self, value) -> None:
        self._step_bound = level_step_bounds(self.buffer, value)
        self._step_bound.flags.writeable = False     # changed only through the setter
        self._bounded = bool(self._step_bound.any())

    def solve(self, buffer: StackBuffer | None = None) -> Outcome:
        """Solve the buffer's current rows (``buffer``: another of the same layout).

        Raises:
            TaskStackError: a value is not finite (naming the task and level).
            FormulationError: ``buffer`` has another layout.
        """
        buf = self.buffer if buffer is None else buffer
        if buf is not self.buffer and (buf.A.shape != self.buffer.A.shape
                                       or not np.array_equal(buf.starts, self.buffer.starts)):
            raise FormulationError(f"buffer layout differs from the solver's: rows "
                                   f"{buf.starts.tolist()} × {buf.n} vs "
                                   f"{self.buffer.starts.tolist()} × {self.buffer.n}")
        # one compiled call: copy into the workspace, level scales (and finite check),
        # kernel; the workspace is the solver's own, so one thread at a time uses it
        # (4 threads sharing a solver gave 59 wrong answers in 8,000 solves)
        with self._lock:
            if not _kernel.solve_buffer(buf.A, buf.b, self._B, self._c, buf.starts,
                                        self._scales, self.rcond, self.level_damping,
                                        self.singular_threshold, self._step_bound, self._x,
                                        self._ranks, self._mu2, self._margins):
                buf.check()     # names the task, level and row of a NaN or inf
            return _wrap_outcome(self._x, self._ranks, self._mu2, self._margins,
                                 self.level_damping > 0, self._bounded)


# --------------------------------------------------------------------------- qr
def _pivoted_lstsq_if_full_rank(K: np.ndarray, p: np.ndarray, tol: float
                                ) -> tuple[np.ndarray, bool] | None:
    """``argmin ‖K z − p‖`` for ``K`` (``m × d``, ``m ≥ d``) of full column rank, by one
    QR with column pivoting (``dgeqp3``), and whether a pivot was ambiguous
    (:func:`hierarchy.ambiguous_decision`); ``None`` when a pivot is ``≤ tol``
    (rank-deficient: the caller takes the row-pivoted path)."""
    d = K.shape[1]
    qr, jpvt, tau, _, _ = _dgeqp3(np.array(K, order="F"), overwrite_a=1)
    pivots = np.abs(np.diagonal(qr)[:d])
    if tol <= 0 or not np.all(pivots > tol):
        return None
    z = np.empty(d)
    z[jpvt - 1] = _qr_least_squares(qr, tau, p)
    return z, ambiguous_decision(pivots, tol)


def _lstsq_full_column_rank(K: np.ndarray, p: np.ndarray) -> np.ndarray:
    """min ‖K z − p‖ for ``K`` (m × r, m > r) of full column rank, by Householder QR."""
    qr, tau, _, _ = _dgeqrf(K)
    return _qr_least_squares(qr, tau, p)


def _qr_least_squares(qr: np.ndarray, tau: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``R⁻¹ (Qᵀ p)[:r]`` from LAPACK's compact QR (``qr``, ``tau``) of an ``m × r``
    matrix of full column rank."""
    m, r = qr.shape
    qtp, _, _ = _dormqr("L", "T", qr, tau, p.reshape(m, 1), max(1, m))
    z, _ = _dtrtrs(qr[:r, :r], qtp[:r])
    return z.ravel()


def _damped_lstsq(K: np.ndarray, p: np.ndarray, mu2: float) -> np.ndarray:
    """min ‖K z − p‖² + μ² ‖z‖² through the QR of ``[K; μ I]``."""
    m, r = K.shape
    aug = np.zeros((m + r, r), order="F")
    aug[:m] = K
    aug[m:] = np.sqrt(mu2) * np.eye(r)
    rhs = np.zeros(m + r)
    rhs[:m] = p
    return _lstsq_full_column_rank(aug, rhs)


def _trust_region_step(K: np.ndarray, p: np.ndarray, mu2_min: float, step_bound: float
                       ) -> tuple[np.ndarray, float]:
    """``z`` of ``min ‖K z − p‖ s.t. ‖z‖ ≤ Δ`` with damping at least ``mu2_min``.

    ``K`` (``m × r``) has full column rank. Returns ``(z, μ²)``: ``z`` solves
    ``(KᵀK + μ² I) z = Kᵀp`` with the smallest ``μ² ≥ mu2_min`` for which ``‖z‖ ≤ Δ``
    (``μ² = mu2_min`` when that step is short enough; otherwise ``‖z‖ = Δ`` to 1e-12).
    """
    u, s, vt = np.linalg.svd(K, full_matrices=False)
    c = s * (u.T @ p)                                    # s_j (u_jᵀ p)
    s2 = s * s
    mu2 = mu2_min
    w = c / (s2 + mu2)
    norm = float(np.linalg.norm(w))
    if step_bound > 0 and norm > step_bound:
        for _ in range(100):   # Newton on 1/‖z(μ²)‖ − 1/Δ: concave, monotone from below
            dnorm = -float(np.sum(w * w / (s2 + mu2))) / norm     # d‖z‖/dμ²
            step = (1.0 / norm - 1.0 / step_bound) * norm * norm / dnorm
            mu2 = max(mu2 + step, mu2_min)
            w = c / (s2 + mu2)
            norm = float(np.linalg.norm(w))
            if abs(norm - step_bound) <= 1e-12 * step_bound:
                break
    return vt.T @ w, mu2


def _solve_qr(stack: TaskStack, rcond: float, level_damping: float = 0.0,
              singular_threshold: float = 0.0, step_bound: np.ndarray | None = None
              ) -> Outcome:
    n = stack.n
    mats = [(level.A, level.b) for level in stack.levels]
    B = np.vstack([A for A, _ in mats])          # working copy of all rows
    c = np.concatenate([b for _, b in mats])
    y = np.zeros(n)                               # solution in rotated coordinates
    reflectors = []                               # (col, qr[:, :r], tau[:r]) per level
    ranks, ambiguous = [], []
    level_mu2 = np.zeros(len(mats))
    bounds = np.zeros(len(mats)) if step_bound is None else step_bound
    col = 0
    start = 0
    for index, (A, _) in enumerate(mats):
        m = A.shape[0]
        stop = start + m
        d = n - col
        if d == 0 or m == 0:
            ranks.append(0)
            start = stop
            continue
        rhs = c[start:stop] - B[start:stop, :col] @ y[:col]
        if m >= d and bounds[index] <= 0 and level_damping <= 0:
            full = _pivoted_lstsq_if_full_rank(B[start:stop, col:], rhs,
                                               rank_threshold(A, rcond))
            if full is not None:              # full column rank: no null space left
                ranks.append(d)
                y[col:] = full[0]
                if full[1]:
                    ambiguous.append(index)
                col = n
                start = stop
                continue
        M_T = np.array(B[start:stop, col:].T, order="F")      # (A_i Z_i)ᵀ, d × m
        qr, jpvt, tau, _, _ = _dgeqp3(M_T, overwrite_a=1)
        diag = np.abs(np.diagonal(qr)[: min(d, m)])
        tol = rank_threshold(A, rcond)
        r = int(np.count_nonzero(diag > tol)) if tol > 0 else 0
        ranks.append(r)
        if ambiguous_decision(diag, tol):
            ambiguous.append(index)
        if r == 0:
            start = stop
            continue
        # In rotated coordinates level i reads  B_i[:, :col] y_prev + Pᵀ-permuted Rᵀ y_new.
        perm = jpvt - 1
        p = rhs[perm]
        mu2 = 0.0
        if level_damping > 0:
            sigma = float(diag[r - 1])                           # RRQR estimate of σ_min
            eps_abs = singular_threshold * float(np.linalg.norm(A))
            if sigma < eps_abs:
                mu2 = level_damping * (1.0 - (sigma / eps_abs) ** 2)
        if mu2 > 0:
            z = _damped_lstsq(np.triu(qr[:r, :]).T.copy(), p, mu2)
        elif r == m:
            z, _ = _dtrtrs(qr[:r, :r], p, trans=1)
        else:
            z = _lstsq_full_column_rank(np.triu(qr[:r, :]).T.copy(), p)
        if bounds[index] > 0 and float(np.linalg.norm(z)) > bounds[index]:
            z, mu2 = _trust_region_step(np.triu(qr[:r, :]).T, p, mu2, bounds[index])
        level_mu2[index] = mu2
        y[col:col + r] = z
        if stop < B.shape[0] and r < d:
            rest = B[stop:, col:]
            B[stop:, col:], _, _ = _dormqr("R", "N", qr[:, :r], tau[:r], rest,
                                           max(1, rest.shape[0]))
        reflectors.append((col, qr[:, :r], tau[:r]))
        col += r
        start = stop
    x = y
    for col_i, v, t in reversed(reflectors):
        seg = x[col_i:].reshape(-1, 1)
        out, _, _ = _dormqr("L", "N", v, t, seg, 1)
        x[col_i:] = out.ravel()
    info = {"rank_profile": np.array(ranks), "nullspace": "qr", "kernel": "lapack"}
    status = _damping_info(info, level_mu2, level_damping > 0, bool(bounds.any()))
    return Outcome(x, _ambiguity_status(info, status, ambiguous), info)


def _ambiguity_status(info: dict, status: str, ambiguous) -> str:
    """``status``, or ``"approximate"`` with ``info["reason"]`` when some level's rank
    decision was ambiguous (``ambiguous``: level indices)."""
    levels = [int(i) for i in ambiguous]
    if not levels:
        return status
    info["ambiguous_levels"] = levels
    info["reason"] = ambiguity_reason(levels)
    return "approximate"


# -------------------------------------------------------------------------- svd
def _extended_blocks(stack: TaskStack, rcond: float, damping: float, zs,
                     equilibrate: bool = False):
    """``J_E`` and ``h_E`` of eq. 15-16 (eq. 27 when ``damping > 0``).

    With ``equilibrate`` each block ``Z_iᵀJ_iᵀJ_i`` is scaled to unit Frobenius norm,
    which leaves the solutions of the (consistent) undamped system unchanged and keeps
    the squared scale of ``J_iᵀJ_i`` from hiding a level's singular values.
    """
    rows, rhs = [], []
    for i, ((A, b), Z) in enumerate(zip(stack.equality_matrices(), zs)):
        n = A.shape[1]
        if damping == 0 and i + 1 < len(zs) and zs[i + 1].shape[1] == Z.shape[1]:
            continue  # r_i = 0: Z_i J_iᵀ J_i = 0 up to rounding, no equation (Theorem 1)
        if i == 0 and Z.shape[1] == n:
            full_row_rank = np.linalg.matrix_rank(A, tol=rcond * float(np.linalg.norm(A))) \
                == A.shape[0]
            if full_row_rank or A.shape[0] == 0:
                rows.append(A)
                rhs.append(b)
                continue
        if Z.shape[1] == 0:
            continue
        G = A.T @ A
        if damping > 0:
            G = G + damping * np.eye(n)
        block, target = Z.T @ G, Z.T @ (A.T @ b)
        if equilibrate:  # a consistent system keeps its solutions under row scaling
            norm = float(np.linalg.norm(block))
            if norm > 0:
                block, target = block / norm, target / norm
        rows.append(block)
        rhs.append(target)
    return np.vstack(rows), np.concatenate(rhs)


def _augmented_null_spaces(stack: TaskStack, rcond: float) -> tuple[list[np.ndarray], int]:
    """``Z_1 … Z_{k+1}`` (columns) from the SVD of each augmented Jacobian (eq. 7, 13),
    and the rank ``ρ(J_k^A)`` (see :func:`_augmented_decomposition`)."""
    zs, rank, _ = _augmented_decomposition(stack, rcond)
    return zs, rank


def _augmented_decomposition(stack: TaskStack, rcond: float
                             ) -> tuple[list[np.ndarray], int, list[int]]:
    """``Z_1 … Z_{k+1}``, ``ρ(J_k^A)`` and the levels whose rank decision is ambiguous.

    Each level's block is first scaled to unit Frobenius norm (row equilibration: the
    null space is unchanged), so one threshold ``rcond`` judges every level on its own
    scale, as the nested rule of ``hierarchy.linalg`` does. ``J_i^A`` is kept as the
    triangular factor ``R_i`` of its QR (``J_i^A = Q_i R_i``, same singular values and
    right singular vectors; ``R_i`` from the QR of ``[R_{i-1}; A_i/‖A_i‖_F]``), so each
    level costs ``O((n + m_i) n²)`` instead of an SVD of all the rows above.
    """
    n = stack.n
    zs = [np.eye(n)]
    R = np.zeros((0, n))
    ambiguous = []
    for i, level in enumerate(stack.levels):
        A = level.A
        norm = level_scale(A)
        R = np.linalg.qr(np.vstack([R, A / norm if norm > 0 else A]), mode="r")
        if R.shape[0] > n:
            R = R[:n]
        _, sv, vt = np.linalg.svd(R, full_matrices=True)
        r = int(np.count_nonzero(sv > rcond)) if rcond > 0 else 0
        if ambiguous_decision(sv, rcond):
            ambiguous.append(i)
        zs.append(vt[r:].T.copy())
    return zs, n - zs[-1].shape[1], ambiguous


#: ``nullspace="svd"`` says ``optimal`` only up to this condition number of ``J_E``:
#: its error is about ``ε κ(J_E)`` (measured ≤ 200 ε κ), ≤ 4.4e-9 relative here.
SVD_CERTIFIED_CONDITION = 1e5


def _solve_svd(stack: TaskStack, rcond: float) -> Outcome:
    zs, rank, ambiguous = _augmented_decomposition(stack, rcond)
    if rank == 0:      # every level is zero: no equation, the minimum-norm x is 0
        return Outcome(np.zeros(stack.n), "optimal",
                       {"rank": 0, "nullspace": "svd", "extended_rows": 0,
                        "condition_number": 1.0})
    JE, hE = _extended_blocks(stack, rcond, 0.0, zs, equilibrate=True)
    u, s, vt = np.linalg.svd(JE, full_matrices=False)
    r = min(rank, int(np.count_nonzero(s > 0)))
    x = vt[:r].T @ ((u[:, :r].T @ hE) / s[:r])
    cond = float(s[0] / s[r - 1]) if r else 1.0
    info = {"rank": rank, "nullspace": "svd", "extended_rows": int(JE.shape[0]),
            "condition_number": cond}
    reasons = []
    if ambiguous:
        info["ambiguous_levels"] = ambiguous
        reasons.append(ambiguity_reason(ambiguous))
    if not cond <= SVD_CERTIFIED_CONDITION:
        reasons.append(f"κ(J_E) = {cond:.3g} > {SVD_CERTIFIED_CONDITION:g}: the svd path's "
                       f"error (≈ ε κ(J_E)) is beyond what it can certify; use "
                       f"nullspace='qr'")
    if reasons:
        info["reason"] = "; ".join(reasons)
    return Outcome(x, "approximate" if reasons else "optimal", info)


# ----------------------------------------------------------------------- damped
def _qr_null_spaces(stack: TaskStack, rcond: float) -> list[np.ndarray]:
    """Explicit ``Z_i`` (columns) from the nested pivoted QR (no SVD)."""
    n = stack.n
    Z = np.eye(n)
    zs = [Z]
    for level in stack.levels[:-1]:
        A = level.A
        d = Z.shape[1]
        if d and A.shape[0]:
            M_T = np.array((A @ Z).T, order="F")
            qr, _, tau, _, _ = _dgeqp3(M_T, overwrite_a=1)
            k = min(M_T.shape)
            tol = rcond * float(np.linalg.norm(A))
            r = int(np.count_nonzero(np.abs(np.diagonal(qr)[:k]) > tol)) if tol > 0 else 0
            if r:
                # columns r.. of the full Q span null(A_i Z_i) in the local coordinates
                Q, _, _ = _dormqr("L", "N", qr[:, :r], tau[:r], np.eye(d, order="F"), d)
                Z = Z @ Q[:, r:]
        zs.append(Z)
    return zs


def _solve_damped(stack: TaskStack, damping: float, rcond: float, nullspace: str) -> Outcome:
    if nullspace == "svd":
        zs, _ = _augmented_null_spaces(stack, rcond)
    else:
        zs = _qr_null_spaces(stack, rcond)
    JE, hE = _extended_blocks(stack, rcond, damping, zs)
    if nullspace == "svd":
        x = np.linalg.pinv(JE) @ hE
    else:
        m, n = JE.shape
        jpvt = np.zeros(n, dtype=np.int32)
        bb = np.zeros(max(m, n))
        bb[:m] = hE
        lwork = max(1, max(m, n) * 8 + 64)
        _, xb, _, _, _ = lapack.dgelsy(JE, bb.reshape(-1, 1), jpvt, 1e-12, lwork)
        x = xb[:n].ravel()
    return Outcome(x, "approximate", {"damping": damping, "nullspace": nullspace,
                                      "extended_rows": int(JE.shape[0])})


def solve_batch(stacks: list[TaskStack], *, nullspace: str = "qr", damping: float = 0.0,
                rcond: float = DEFAULT_RCOND, level_damping: float = 0.0,
                singular_threshold: float = 0.0, kernel: str = "auto",
                step_bound=0.0) -> tuple[np.ndarray, list[str]]:
    """Many stacks of one shape at once (compiled kernel, stacks in parallel).

    Falls back to a loop of :func:`solve` for the ``svd`` path, eq. 27 damping or
    when numba is missing. Returns the solutions (``B × n``) and their statuses.
    """
    kernel = _resolve_kernel(kernel, stacks[0].n if stacks else 0)
    if kernel != "numba" or nullspace != "qr" or damping > 0:
        outs = [solve(s, nullspace=nullspace, damping=damping, rcond=rcond,
                      level_damping=level_damping, singular_threshold=singular_threshold,
                      kernel=kernel, step_bound=step_bound) for s in stacks]
        return np.array([o.x for o in outs]), [o.status for o in outs]
    selective = float(level_damping) > 0 and float(singular_threshold) > 0
    packs = [s.packed() for s in stacks]
    B = np.stack([p.A for p in packs])
    c = np.stack([p.b for p in packs])
    scales = np.stack([p.scales for p in packs])
    N, k, n = len(stacks), len(stacks[0]), stacks[0].n
    X = np.empty((N, n))
    ranks = np.zeros((N, k), dtype=np.int64)
    mu2 = np.zeros((N, k))
    margins = np.empty((N, k))
    if isinstance(step_bound, dict):   # task names may sit on different levels per stack
        bounds = np.stack([level_step_bounds(s, step_bound) for s in stacks])
    else:
        bounds = np.broadcast_to(level_step_bounds(stacks[0], step_bound), (N, k)).copy()
    _kernel.solve_batch_kernel(B, c, packs[0].starts, scales, float(rcond),
                               float(level_damping) if selective else 0.0,
                               float(singular_threshold), bounds, X, ranks, mu2, margins)
    statuses = ["approximate" if (d > 0).any() or (g <= AMBIGUITY).any() else "optimal"
                for d, g in zip(mu2, margins)]
    return X, statuses
