"""Compiled kernel of ``hierarchical_active_set`` (numba, ``cache=True``).

One call solves a whole stack of equality and inequality rows lexicographically.
The notation follows the module docstring of
:mod:`prioik.formulations.hierarchical_active_set`; in short:

* every row ``j`` is pre-scaled by ``√w_j`` and lives in the rotated coordinates
  ``y = Qᵀ x`` of the nested pivoted QR of the extended Jacobian
  (:mod:`prioik.formulations._extended_jacobian_kernel`): the rows fixed as
  equalities by the levels above own the leading ``col`` coordinates and the
  trailing ``d = n − col`` are free;
* level by level, a primal active-set method minimises the level's squared
  violation over the free coordinates, subject to the inequality rows of the
  levels above (hard: they must keep zero violation). Each iteration solves one
  equality-constrained least-squares problem (:func:`_eqp`) by a row-pivoted LQ of
  the working hard rows, then of the working soft rows on what they leave free,
  both by Householder reflections (no SVD);
* after the level, its rows with a non-zero optimal violation and its equality
  rows are fixed at their values (their optimal slacks are unique) by one more
  row-pivoted LQ whose reflectors rotate every row below and the point ``y``.

Row states (``state``): ``0`` not in the working set, ``-1``/``+1`` in it at the
lower/upper bound, ``3`` an equality row of the current level, ``2`` fixed.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from prioik._jit import kernel

from prioik.hierarchy.linalg import AMBIGUITY as _AMBIGUITY
# the factor over AMBIGUITY within which a clear rank decision still has its answer
# certified (FLAG_NEAR_AMBIGUOUS; the G1 bounds stacks' smallest margin is 3e6)
from prioik.hierarchy.linalg import NEAR_AMBIGUITY
from prioik.hierarchy.linalg import PRECISION_LIMIT_NORM as _PRECISION_LIMIT_NORM
from prioik.hierarchy.linalg import X_PRECISION

from ._extended_jacobian_kernel import (_UNIT_ROWS_GAP, _apply_q, _apply_qt,
                                        _cholesky_lower, _cholesky_solve, _dot,
                                        _drop_fixed, _free_directions, _level_extreme,
                                        _csne_correction, _small_lstsq_ws, _swap,
                                        _unit_rows_of,
                                        _unit_rows_solve, _woodbury_apply,
                                        solve_kernel_into, spare_size)

#: the same fast-math set as the extended-Jacobian kernel (no finite-math assumption)
_FAST = {"reassoc", "contract", "nsz", "arcp"}

#: a non-working row blocks the step only if it moves by more than ``max(this, rcond)``
#: times ``‖a_j‖ ‖p‖``: a row that the step leaves unchanged to rounding, or that
#: depends on the working hard rows by the rank rule (``rcond``), never blocks
_BLOCK_EPS = 1e-13
#: a step shorter than this fraction of ``‖y‖`` is rounding noise and taken as zero
_ZERO_STEP = 1e-13
#: a step of at most this length (of the full step) counts as degenerate
_DEGENERATE = 1e-12
#: a hard row's wrong-signed multiplier below this times the level's gradient scale
#: (``max(‖∇f‖, ‖A_i‖_F (‖A_i‖_F ‖x‖ + ‖targets‖))``, ~50 eps) is rounding: the release
#: test by the level's gain (:func:`_freed_gain`) never reads one smaller
_DUAL_FLOOR = 1e-14
#: a soft row of the working set leaves it when on the satisfied side of its bound by
#: more than this times ``primal_tol`` (relative to its size)
_RELEASE = 1e-3
#: values of ``flags``
FLAG_OK = 0
FLAG_ITERATION_CAP = 1
#: the level's last step decided its ranks clearly, an earlier step of it did not
FLAG_AMBIGUOUS_PATH = 2
#: a held soft row ended inside its bound by more than x's precision but within its
#: release tolerance: whether releasing it lowers the level is below that tolerance's
#: resolution (a row of norm 739 held beside one of norm 0.0021: 2.6x the level's
#: optimum, bounds-31-1103); the caller certifies the answer
FLAG_NEAR_RELEASE = 3
#: a held hard-for-below row ended off its bound beyond the primal tolerance but within
#: the dual one, so it was kept held (a hard row at its bound for the levels below), not
#: fixed at its violation: rows 1e-3 the size of their level's others, held so, blocked
#: a direction they take only below the rank rule and left a lower level at 180x its
#: optimum (fuzz inequality-7002-1384); the caller certifies the answer
FLAG_HELD_OFF_BOUND = 4
#: the level settled on rank decisions all clear of the ambiguity band, one of them by
#: less than NEAR_AMBIGUITY times it: a drifting fuzz stack (n 24, level 1's 17 rows of
#: norm 1e-3 beside two of norm 8, margins 1.6e3 and 2.0e3) ended 1.4e-8 (relative)
#: above its level-1 optimum, called optimal; the caller certifies the answer
FLAG_NEAR_AMBIGUOUS = 5
#: the level's working set kept changing without a step that moved (more than
#: :func:`_stall_limit` iterations): its multipliers and steps disagree (rank decisions
#: at the threshold; fuzz bounds-1205-1331 cycled so to the iteration cap, releasing a
#: row whose next step it blocked at once), so the level settles at the point they all
#: share and the caller certifies the answer
FLAG_STALLED = 6

#: what :func:`solve_data` returns
NOT_SOLVED = 0
SOLVED_CLEAN = 1
SOLVED_INFEASIBLE = 2
SOLVED_OTHER = 3


@njit(cache=True, inline="always")
def _swap_rows_upto(M, i, j, w):
    """Exchange ``M[i, :w]`` and ``M[j, :w]``."""
    for c in range(w):
        tmp = M[i, c]
        M[i, c] = M[j, c]
        M[j, c] = tmp


@njit(cache=True, fastmath=_FAST, inline="always")
def _reflect_row(T, i, q, w, V, beta, nref, first, last):
    """Householder reflector mapping ``T[i, q:w]`` onto ``α e₁``; stored as
    ``V[nref, q:w]``, ``beta[nref]``, applied to ``T[first:last, q:w]``."""
    row = T[i, q:w]
    exact = _dot(row, row)
    norm = np.sqrt(exact)
    alpha = -norm if row[0] >= 0.0 else norm
    v = V[nref, q:w]
    v[0] = row[0] - alpha
    for c in range(1, w - q):
        v[c] = row[c]
    vtv = 2.0 * (exact - alpha * row[0])
    bt = 2.0 / vtv if vtv > 0.0 else 0.0
    beta[nref] = bt
    row[0] = alpha
    for c in range(1, w - q):
        row[c] = 0.0
    for r in range(first, last):
        other = T[r, q:w]
        f = bt * _dot(other, v)
        if f != 0.0:
            for c in range(w - q):
                other[c] -= f * v[c]


@njit(cache=True, fastmath=_FAST, inline="always")
def _eqp(B, y, col, rows, nh, nw, tgt, rnorm, rcond, soft_tol, T, rhs, norms, V, beta,
         vpos, Lw, p, reach, flat, tq, Ts, ts_rows):
    """One equality-constrained least-squares step from ``y``.

    Finds the minimum-norm step ``p`` (free coordinates ``col:``) that keeps the
    ``nh`` working hard rows ``rows[:nh]`` at their bounds ``tgt[:nh]`` (``reach``: moves
    them onto their bounds; else ``C_H p = 0``: inside an active-set iteration they are
    on their bounds already, and correcting rounding there would move the rows that
    depend on them) and minimises
    ``Σ (B_j (y + p) − tgt_j)²`` over the ``nw`` working soft rows ``rows[nh:nh+nw]``.

    The hard rows are factorized first (row-pivoted LQ, pivot on the residual norm
    relative to the row's own norm ``rnorm``, kept when ``> rcond``), the soft rows
    on the directions they leave (row-pivoted LQ with the level's threshold
    ``soft_tol``; a small least-squares solve when they conflict). ``rows`` and
    ``tgt`` are permuted in place into pivot order.

    Returns:
        ``(hr, rs, nref, margin)``: hard rows kept (``rows[hr:nh]`` depend on them and
        are not enforced), rank of the soft rows on the rest, reflectors used (the
        first ``hr`` factor the hard rows; :func:`_hard_multipliers` uses them), and the
        soft rows' rank decisions' margin (``hierarchy.linalg``: the smallest of kept
        pivot / ``soft_tol`` and ``soft_tol`` / first rejected pivot; ``inf`` when none
        was made). The hard rows' dependency test is not a margin: held hard rows are
        at their bounds together, so a nearly dependent one left out does not move the
        step's answer (the step test watches it).

    When every hard row is kept, the soft rows as the hard reflectors left them (and
    their rows and targets) are kept in ``Ts``/``ts_rows`` (``ts_rows[:nw]`` the rows,
    ``ts_rows[R:R + nw]`` the targets): :func:`_eqp_append` adds a hard row to this
    factorization from them.
    """
    n = B.shape[1]
    d = n - col
    nr = nh + nw
    for i in range(nr):
        j = rows[i]
        Bj = B[j]
        rhs[i] = tgt[i] - _dot(Bj, y) if (reach or i >= nh) else 0.0
        for c in range(d):
            T[i, c] = Bj[col + c]
    nref = 0
    margin = np.inf
    # --- hard rows: row-pivoted LQ, scale-free pivot (residual² / ‖a_j‖²)
    for i in range(nh):
        norms[i] = _dot(T[i, :d], T[i, :d])
    hr = 0
    while hr < nh and hr < d:
        best = -1.0
        piv = hr
        for i in range(hr, nh):
            s = rnorm[rows[i]]
            rel = norms[i] / (s * s) if s > 0.0 else 0.0
            if rel > best:
                best = rel
                piv = i
        tail = T[piv, hr:d]
        exact = _dot(tail, tail)
        s = rnorm[rows[piv]]
        if not (exact > (rcond * s) * (rcond * s)) or s <= 0.0:
            break
        if piv != hr:
            _swap_rows_upto(T, hr, piv, d)
            _swap(rhs, hr, piv)
            _swap(norms, hr, piv)
            _swap(rows, hr, piv)
            _swap(tgt, hr, piv)
        vpos[nref] = hr
        _reflect_row(T, hr, hr, d, V, beta, nref, hr + 1, nr)
        for i in range(hr + 1, nh):
            norms[i] -= T[i, hr] * T[i, hr]
        nref += 1
        hr += 1
    for c in range(d):
        p[c] = 0.0
    for i in range(hr):
        acc = rhs[i]
        for c in range(i):
            acc -= T[i, c] * p[c]
        p[i] = acc / T[i, i]
    if hr == nh:
        R = Ts.shape[0]
        for i in range(nw):
            for c in range(d):
                Ts[i, c] = T[nh + i, c]
            ts_rows[i] = rows[nh + i]
            ts_rows[R + i] = tgt[nh + i]
    rs, nref, margin = _eqp_soft(T, rhs, norms, rows, tgt, nh, nw, hr, d, soft_tol, V, beta,
                                 vpos, nref, margin, Lw, p, flat, tq)
    return hr, rs, nref, margin


# _eqp_soft, _eqp_append, _rows_at_bounds and _nnls_working_set are calls, not inlined:
# inlined, the kernels took 118 s to compile on a fresh cache against 95 s (85 s without
# them), for no measurable speed on the G1 bounds stacks
@njit(cache=True, fastmath=_FAST)
def _eqp_soft(T, rhs, norms, rows, tgt, nh, nw, hr, d, soft_tol, V, beta, vpos, nref, margin,
              Lw, p, flat, tq):
    """:func:`_eqp`'s second half: the soft rows ``T[nh:nh + nw]`` (as the ``hr`` hard
    reflectors left them; ``p[:hr]`` the hard part of the step) by a row-pivoted LQ on
    the directions the hard rows leave, then ``p`` in the free coordinates. Returns
    ``(rs, nref, margin)``."""
    nr = nh + nw
    # --- soft rows on the directions the hard rows leave
    for i in range(nh, nr):
        acc = rhs[i]
        for c in range(hr):
            acc -= T[i, c] * p[c]
        rhs[i] = acc
        tail = T[i, hr:d]
        norms[i] = _dot(tail, tail)
    rs = 0
    while rs < nw and hr + rs < d:
        q = hr + rs
        top = nh + rs
        piv = top
        best = norms[top]
        for i in range(top + 1, nr):
            if norms[i] > best:
                best = norms[i]
                piv = i
        tail = T[piv, q:d]
        exact = _dot(tail, tail)
        if not (np.sqrt(exact) > soft_tol) and soft_tol > 0.0:
            # the downdated norms may have lost the largest remaining row (cancellation
            # ~ε‖row‖², as in the extended Jacobian's kernel): recompute before stopping
            for i in range(top, nr):
                rest = T[i, q:d]
                norms[i] = _dot(rest, rest)
                if norms[i] > exact:
                    exact = norms[i]
                    piv = i
        if not (np.sqrt(exact) > soft_tol) or soft_tol <= 0.0:
            if exact > 0.0 and soft_tol > 0.0:
                margin = min(margin, soft_tol / np.sqrt(exact))
            break
        margin = min(margin, np.sqrt(exact) / soft_tol)
        if piv != top:
            _swap_rows_upto(T, top, piv, d)
            _swap(rhs, top, piv)
            _swap(norms, top, piv)
            _swap(rows, top, piv)
            _swap(tgt, top, piv)
        vpos[nref] = q
        _reflect_row(T, top, q, d, V, beta, nref, top + 1, nr)
        for i in range(top + 1, nr):
            norms[i] -= T[i, q] * T[i, q]
        nref += 1
        rs += 1
    if rs > 0:
        if rs == nw:
            for i in range(rs):
                acc = rhs[nh + i]
                for c in range(i):
                    acc -= T[nh + i, hr + c] * p[hr + c]
                p[hr + i] = acc / T[nh + i, hr + i]
        else:
            for i in range(nw):
                for c in range(rs):
                    Lw[i, c] = T[nh + i, hr + c] if c <= i else 0.0
            _small_lstsq_ws(Lw, rhs[nh:], nw, rs, 0.0, p, hr, flat, tq)
    _reflect_vector(p, d, nref, V, beta, vpos, False)       # p = H_1 … H_R [u; 0]
    return rs, nref, margin


@njit(cache=True, fastmath=_FAST)
def _eqp_append(B, y, col, rows, nh, nw, tgt, rnorm, rcond, soft_tol, T, rhs, norms, V, beta,
                vpos, Lw, p, flat, tq, Ts, ts_rows, jb, tb):
    """:func:`_eqp` after the hard row ``jb`` (brought up to date; its bound ``tb``) joined
    the working set of the last step, which kept all its ``nh`` hard rows and whose soft
    rows :func:`_eqp` kept in ``Ts``: the new row is reduced by the hard reflectors and
    takes one of its own (applied to ``Ts``), then the soft rows are factorized again —
    ``O(nh d + nw d²)`` instead of ``O((nh + nw) nh d)``, the primal iteration's common
    case (a step cut by a row that then joins: on G1's sword-tip level, 13 joint limits in
    a row). As inside any iteration, the hard rows are held where they are (``C_H p =
    0``). The hard rows keep their order (the new one last: a fresh factorization would
    pivot them by their residuals; another factorization of the same rows, the same step
    in exact arithmetic).

    Returns ``(hr, rs, nref, margin)`` as :func:`_eqp` with ``hr = nh + 1``, or ``hr = -1``
    when the new row is not clearly independent of the others (the hard-row rule) or
    leaves no free direction: the caller takes :func:`_eqp`."""
    n = B.shape[1]
    d = n - col
    if nh + 1 >= d:         # (the new row would take the last free direction)
        return -1, 0, 0, np.inf
    u = T[nh]
    for c in range(d):
        u[c] = B[jb, col + c]
    _reflect_vector(u, d, nh, V, beta, vpos, True)        # (the hard ones: vpos[t] = t)
    tail = u[nh:d]
    s = rnorm[jb]
    if not (_dot(tail, tail) > (rcond * s) * (rcond * s)) or s <= 0.0:
        return -1, 0, 0, np.inf
    vpos[nh] = nh
    _reflect_row(T, nh, nh, d, V, beta, nh, nh, nh)
    hr = nh + 1
    rows[nh] = jb
    tgt[nh] = tb
    rhs[nh] = 0.0
    R = Ts.shape[0]
    v = V[nh, nh:d]
    bt = beta[nh]
    for i in range(nw):
        ti = Ts[i]
        f = bt * _dot(v, ti[nh:d])
        if f != 0.0:
            for c in range(d - nh):
                ti[nh + c] -= f * v[c]
        j = int(ts_rows[i])
        rows[hr + i] = j
        tgt[hr + i] = ts_rows[R + i]
        rhs[hr + i] = ts_rows[R + i] - _dot(B[j], y)
        Ti = T[hr + i]
        for c in range(d):
            Ti[c] = ti[c]
    for c in range(d):
        p[c] = 0.0
    rs, nref, margin = _eqp_soft(T, rhs, norms, rows, tgt, hr, nw, hr, d, soft_tol, V, beta,
                                 vpos, hr, np.inf, Lw, p, flat, tq)
    return hr, rs, nref, margin


@njit(cache=True, fastmath=_FAST, inline="always")
def _full_rank_step(B, y, col, rows, nw, tgt, soft_tol, flat, t, norms, perm, p, nrot, nf,
                    Vf, betaf, posf, T):
    """The step of ``nw ≥ d`` working soft rows and no hard row, when they have full
    column rank on the ``d`` free coordinates: ``p = R⁻¹ Qᵀ (tgt − B y)`` by one
    column-pivoted Householder QR (the extended Jacobian's
    ``_pivoted_lstsq_if_full_rank`` with the level's threshold ``soft_tol`` on every
    pivot). Such a level leaves no free coordinate.

    The rows are copied transposed into ``flat`` (``n × nw``) and the fixing
    reflectors they still lack are applied there, all rows at once: every inner loop
    then runs over the ``nw`` rows, contiguous (a posture level of a humanoid brought
    row by row through ~20 reflectors costs several times more). ``B`` itself is not
    rotated (``nrot`` unchanged: a row brought here is brought again if it enters
    another factorization). Returns the smallest pivot / ``soft_tol`` (the rank
    decision's margin), or ``-1`` (``p`` not written) when the rows lack different
    numbers of reflectors or a pivot fails the threshold: the caller then brings them
    and takes the row-pivoted LQ of :func:`_eqp`."""
    n = B.shape[1]
    d = n - col
    r0 = nrot[rows[0]]
    for i in range(1, nw):
        if nrot[rows[i]] != r0:
            return -1.0
    W = flat[:n * nw].reshape((n, nw))
    for i in range(nw):
        Bj = B[rows[i]]
        for c in range(n):
            W[c, i] = Bj[c]
    w = norms[:nw]                 # scratch until the column norms
    for tf in range(r0, nf):
        q = posf[tf]
        v = Vf[tf]
        for i in range(nw):
            w[i] = 0.0
        for c in range(q, n):
            vc = v[c]
            Wc = W[c]
            for i in range(nw):
                w[i] += vc * Wc[i]
        bt = betaf[tf]
        for i in range(nw):
            w[i] *= bt
        for c in range(q, n):
            vc = v[c]
            Wc = W[c]
            for i in range(nw):
                Wc[i] -= vc * w[i]
    for i in range(nw):
        t[i] = tgt[i]
    for c in range(n):
        yc = y[c]
        Wc = W[c]
        for i in range(nw):
            t[i] -= yc * Wc[i]
    Tt = W[col:]
    for i in range(nw):            # the rows on the free coordinates, kept for the
        for c in range(d):         # refinement below (T: R × n scratch, _eqp refills it)
            T[i, c] = Tt[c, i]
    for c in range(d):
        norms[c] = _dot(Tt[c], Tt[c])
        perm[c] = c
    margin = np.inf
    for c in range(d):
        piv = c
        best = norms[c]
        for k in range(c + 1, d):
            if norms[k] > best:
                best = norms[k]
                piv = k
        if piv != c:
            _swap_rows_upto(Tt, c, piv, nw)
            _swap(norms, c, piv)
            _swap(perm, c, piv)
        cj = Tt[c, c:]
        exact = _dot(cj, cj)
        if not (np.sqrt(exact) > soft_tol) or soft_tol <= 0.0:
            return -1.0
        margin = min(margin, np.sqrt(exact) / soft_tol)
        norm = np.sqrt(exact)
        c0 = cj[0]
        alpha = -norm if c0 >= 0.0 else norm
        cj[0] = c0 - alpha
        vtv = 2.0 * (exact - alpha * c0)
        wn = nw - c
        for k in range(c + 1, d):
            ck = Tt[k, c:]
            f = 2.0 * _dot(ck, cj) / vtv
            for i in range(wn):
                ck[i] -= f * cj[i]
            norms[k] -= ck[0] * ck[0]
        tj = t[c:nw]
        f = 2.0 * _dot(tj, cj) / vtv
        for i in range(wn):
            tj[i] -= f * cj[i]
        cj[0] = alpha
    for c in range(d - 1, -1, -1):
        acc = t[c]
        for k in range(c + 1, d):
            acc -= Tt[k, c] * norms[k]
        norms[c] = acc / Tt[c, c]          # norms: z in pivot order
    for c in range(d):
        p[perm[c]] = norms[c]
    # one step of refinement by the corrected semi-normal equations (the extended
    # Jacobian's _refine_step): the residual of the rows, formed row by row, in t
    for i in range(nw):
        acc = tgt[i]
        for c in range(col):
            acc -= y[c] * W[c, i]
        Ti = T[i]
        for c in range(d):
            acc -= Ti[c] * (y[col + c] + p[c])
        t[i] = acc
    for j in range(d):
        acc = 0.0
        pj = perm[j]
        for i in range(nw):
            acc += T[i, pj] * t[i]
        norms[j] = acc
    _csne_correction(Tt, norms, d)
    for c in range(d):
        p[perm[c]] += norms[c]
    return margin


@njit(cache=True, fastmath=_FAST, inline="always")
def _unit_rows_step(Bo, ucol, xc, col, rows, nh, nw, tgt, soft_tol, reach, colrow, p,
                    nf, Vf, betaf, posf, Zu, G, flat, nu_out):
    """The step of a level of *unit rows* — ``nw`` working rows, each ``±s e_cᵀ`` in ``x``
    (one non-zero, the same magnitude ``s``, distinct columns: a posture task of uniform
    weight) — under ``nh`` working hard rows that are box rows (``a_i e_cᵀ x = β_i``, one
    column each, distinct): :func:`_unit_rows_solve` of the extended Jacobian's kernel
    (a rank-``|U|`` update of the identity instead of bringing the ``nw`` rows through
    the fixing reflectors and factorizing them: on G1's posture, 29 rows on 18 free
    coordinates below 17 reflectors, a fifth of :func:`_full_rank_step`'s work).

    The hard rows, ``Z_H p = ρ`` (``Z_H``: their columns' rows of the free directions
    ``Z``; ``ρ_i = (β_i − a_i x_c)/a_i`` when ``reach``, else 0), enter by the Schur
    complement of the normal equations ``N p = h`` (``N = I − Z_Uᵀ Z_U``, applied by
    Woodbury): ``W = N⁻¹ Z_Hᵀ``, ``(Z_H W) λ = Z_H N⁻¹ h − ρ``, ``p = N⁻¹ h − W λ``. Their
    multipliers in the convention of :func:`_hard_multipliers` (``C_Hᵀ ν = g``, the
    level objective's half gradient ``g = s² (N p − h) = −s² Z_Hᵀ λ``) are
    ``ν_i = −s² λ_i / a_i``, written to ``nu_out``.

    Returns ``(margin, ‖g‖)``: the level's margin over ``soft_tol`` (``s √g / soft_tol``,
    a lower bound of the pivots' margin, ``g`` = ``_UNIT_ROWS_GAP``; ``s / soft_tol`` with
    no uncovered column), or ``(-1.0, -1.0)`` — the rows are not such unit rows, ``S Z``
    is not far from rank deficient, the bound is within :data:`~hierarchy.AMBIGUITY` of
    ``soft_tol``, a hard row is not a box row or the hard rows' free directions are
    not well conditioned (``Z_H Z_Hᵀ − g I`` not positive definite, ``g`` =
    ``_UNIT_ROWS_GAP``: the general path's LQ and its hard-row rule decide then) — and
    the caller takes the general path (``p`` may be written). Scratch: ``colrow``
    (``n`` ints), ``Zu``, ``G`` (``≥ 2n × n``), ``flat`` (``≥ 3n``)."""
    n = Bo.shape[1]
    d = n - col
    R = Zu.shape[0]
    if not soft_tol > 0.0:       # (as _full_rank_step: no rank rule, no full-rank step)
        return -1.0, -1.0
    s0 = rows[nh]
    if rows[nh + nw - 1] - s0 != nw - 1:    # (in order: the level's rows, all working)
        return -1.0, -1.0
    if nh >= d:
        return -1.0, -1.0
    for i in range(nh):
        if ucol[rows[i]] < 0:
            return -1.0, -1.0
    s = _unit_rows_of(Bo, s0, s0 + nw, colrow)
    if s < 0.0:
        return -1.0, -1.0
    nun = 0
    for c in range(n):
        if colrow[c] < 0:
            nun += 1
    if nun + 2 * nh > R or 2 * nun + 2 * nh > G.shape[0]:
        return -1.0, -1.0
    g = flat[:n]
    z = flat[n:2 * n]
    t = flat[2 * n:3 * n]
    # g = Sᵀ t / s², t = tgt − S x
    for c in range(n):
        g[c] = 0.0
        i = colrow[c]
        if i >= 0:
            a = Bo[s0 + i, c]
            g[c] = a * (tgt[nh + i] - a * xc[c]) / (s * s)
    nu = _unit_rows_solve(colrow, g, col, p, nf, Vf, betaf, posf, Zu, G, g[:0])
    if nu < 0:
        return -1.0, -1.0
    margin = s * np.sqrt(_UNIT_ROWS_GAP) if nu > 0 else s
    if not margin > _AMBIGUITY * soft_tol:
        return -1.0, -1.0
    if nh == 0:
        return margin / soft_tol, 0.0
    # the hard rows: Z_H (rows nu:nu+nh of Zu), W = N⁻¹ Z_Hᵀ (rows nu+nh:nu+2nh)
    Zh = Zu[nu:nu + nh]
    W = Zu[nu + nh:nu + 2 * nh]
    for i in range(nh):
        z[i] = ucol[rows[i]]
    _free_directions(z, nh, Zh, nf, Vf, betaf, posf, z[:0])
    _drop_fixed(Zh, nh, col)
    for i in range(nh):
        for k in range(d):
            W[i, k] = Zh[i, k]
        _woodbury_apply(W[i], Zu, G, nu, d, t)
    # conditioning: K = Z_H Z_Hᵀ − g I positive definite (Cholesky), g = _UNIT_ROWS_GAP,
    # so that λ_min(S) ≥ λ_min(Z_H Z_Hᵀ) > g (N⁻¹ ⪰ I) and the Schur complement's
    # rounding stays ≲ eps / g² relative (N's: eps / g): near-dependent hard rows (an
    # xArm7's aligned joints, λ_min 6e-12, which the test this replaced — the Cholesky
    # factor's diagonal, ~σ, above 1e3 rcond — passed at 2.5e-6) put a step's rounding
    # of 2e-5 on q̈ (its sign set by the compiled kernel's reassociation)
    K = G[2 * nu:2 * nu + nh]
    S = G[2 * nu + nh:2 * nu + 2 * nh]
    for a in range(nh):
        for b in range(a + 1):
            K[a, b] = _dot(Zh[a, :d], Zh[b, :d]) - (_UNIT_ROWS_GAP if a == b else 0.0)
            S[a, b] = _dot(Zh[a, :d], W[b, :d])
    if not _cholesky_lower(K, nh):
        return -1.0, -1.0
    if not _cholesky_lower(S, nh):
        return -1.0, -1.0
    # λ = S⁻¹ (Z_H p0 − ρ), in t
    for i in range(nh):
        j = rows[i]
        c = ucol[j]
        a = Bo[j, c]
        rho = (tgt[i] - a * xc[c]) / a if reach else 0.0
        t[i] = _dot(Zh[i, :d], p[:d]) - rho
    _cholesky_solve(S, t, nh)
    # p = p0 − Wᵀ λ; ν = −s² λ / a; ‖g‖ = s² ‖Z_Hᵀ λ‖ (z: Z_Hᵀ λ)
    for k in range(d):
        z[k] = 0.0
    for i in range(nh):
        li = t[i]
        Wi = W[i]
        Zi = Zh[i]
        for k in range(d):
            p[k] -= li * Wi[k]
            z[k] += li * Zi[k]
        j = rows[i]
        nu_out[i] = -s * s * li / Bo[j, ucol[j]]
    return margin / soft_tol, s * s * np.sqrt(_dot(z[:d], z[:d]))


# not inlined (the other helpers are): inlined at both its call sites, its subtree
# (_eqp, _full_rank_step, _unit_rows_step) doubled solve_data's compile time (~280 s
# against ~150 s per signature on a fresh cache) for no measurable speed (interleaved
# G1 bounds stacks: cold 0.99-1.07, warm 0.99-1.02, the same answers bit for bit)
@njit(cache=True, fastmath=_FAST)
def _step(B, y, col, rows, nh, nw, fvec, rcond, soft_tol, T, V, beta, vpos, Lw, p, reach,
          flat, perm, nrot, nf, Vf, betaf, posf, Bo, xc, ucol, held_rows_step, Ts, ts_rows):
    """:func:`_unit_rows_step` or :func:`_full_rank_step` when one applies, else
    :func:`_eqp`; returns ``(hr, rs, nref, full, margin, gn)`` (``margin``: of the soft
    rows' rank decisions; ``gn ≥ 0``: the hard rows' multipliers are in ``nu`` already
    and ``gn`` is :func:`_hard_multipliers`' ``‖g‖``, ``-1``: they are not). The rows of
    ``fvec`` it uses are taken here (a call of more than 30 arguments compiles to
    ``f(*args)``, which numba does not inline). ``held_rows_step``: the unit-row step may
    take held hard rows (a level's first step only — after a refuted warm step, which is
    undone, the cold start's first: mixed with the general path's steps
    inside one level's iterations, its different rounding made ratio tests tie the other
    way at degenerate points and cycle — a Panda reach and a G1 stack, 500 iterations)."""
    rnorm = fvec[2]
    rhs = fvec[3]
    norms = fvec[4]
    tgt = fvec[5]
    nu = fvec[11]
    tq = fvec[15]
    d = B.shape[1] - col
    if nw >= d and (nh == 0 or held_rows_step):
        margin, gn = _unit_rows_step(Bo, ucol, xc, col, rows, nh, nw, tgt, soft_tol,
                                     reach, perm, p, nf, Vf, betaf, posf, T, Lw, flat, nu)
        if margin >= 0.0:
            return nh, d - nh, 0, True, margin, gn
        if nh == 0:
            margin = _full_rank_step(B, y, col, rows, nw, tgt, soft_tol, flat, rhs, norms,
                                     perm, p, nrot, nf, Vf, betaf, posf, T)
            if margin >= 0.0:
                return 0, d, 0, True, margin, -1.0
    for i in range(nh + nw):
        _bring(B, rows[i], nrot, nf, Vf, betaf, posf)
    hr, rs, nref, margin = _eqp(B, y, col, rows, nh, nw, tgt, rnorm, rcond, soft_tol, T, rhs,
                                norms, V, beta, vpos, Lw, p, reach, flat, tq, Ts, ts_rows)
    return hr, rs, nref, False, margin, -1.0


@njit(cache=True, fastmath=_FAST, inline="always")
def _hard_multipliers(B, y, col, rows, nh, hr, nw, tgt, T, V, beta, vpos, g, nu):
    """Multipliers ``ν`` of the kept hard rows at the step's end point.

    ``g = Σ_soft (B_j y − tgt_j) B_j[col:]`` is the gradient of the level objective on
    the free coordinates; ``C_Hᵀ ν = g`` is solved through the LQ of the hard rows
    (``Qᵀ g`` by their reflectors, then ``Lᵀ ν = (Qᵀ g)[:hr]``). Returns ``‖g‖``.
    """
    d = B.shape[1] - col
    _soft_gradient(B, y, col, rows, nh, nw, tgt, g)
    gn = np.sqrt(_dot(g[:d], g[:d]))
    _lq_multipliers(g, d, hr, T, V, beta, vpos, nu)
    return gn


@njit(cache=True, fastmath=_FAST, inline="always")
def _soft_gradient(B, y, col, rows, nh, nw, tgt, g):
    """``g = Σ_soft (B_j y − tgt_j) B_j[col:]`` over the working soft rows
    ``rows[nh:nh + nw]`` (brought up to date): the level objective's half gradient on the
    free coordinates."""
    d = B.shape[1] - col
    for c in range(d):
        g[c] = 0.0
    for i in range(nh, nh + nw):
        j = rows[i]
        res = _dot(B[j], y) - tgt[i]
        if res != 0.0:
            Bj = B[j, col:]
            for c in range(d):
                g[c] += res * Bj[c]


@njit(cache=True, fastmath=_FAST, inline="always")
def _soft_gradient_x(Bo, ucol, xc, rows, nh, nw, tgt, col, nf, Vf, betaf, posf, gx, g):
    """:func:`_soft_gradient` read in ``x``: ``g = (Qᵀ Σ_soft (Bo_j xc − tgt_j) Bo_j)[col:]``
    (``B_j y = Bo_j xc`` and ``Σ r_j B_j = Qᵀ Σ r_j Bo_j``): one rotation of the sum by the
    fixing reflectors instead of one per soft row, which the unit-rows step leaves
    unrotated (the G1 posture's 27 rows: ~8 µs brought one by one). ``gx``: scratch
    (``n``)."""
    n = gx.shape[0]
    for c in range(n):
        gx[c] = 0.0
    for i in range(nh, nh + nw):
        j = rows[i]
        res = _odot(Bo, ucol, j, xc) - tgt[i]
        if res != 0.0:
            uc = ucol[j]
            if uc >= 0:
                gx[uc] += res * Bo[j, uc]
            else:
                Bj = Bo[j]
                for c in range(n):
                    gx[c] += res * Bj[c]
    _apply_qt(gx, nf, Vf, betaf, posf)
    for c in range(n - col):
        g[c] = gx[col + c]


@njit(cache=True, fastmath=_FAST, inline="always")
def _reflect_vector(x, d, r, V, beta, vpos, transposed):
    """``x[:d] = Qᵀ x`` (``transposed``: ``H_0`` first) or ``Q x`` (``H_{r−1}`` first) in
    place, ``Q = H_0 … H_{r−1}``, reflector ``t`` in ``V[t, q:d]`` from ``q = vpos[t]``
    (``t`` when ``vpos`` is empty): the extended Jacobian's ``_apply_reflectors`` on
    the first ``d`` coordinates (this kernel's reflectors end there; ``V``'s rows are
    longer)."""
    for i in range(r):
        t = i if transposed else r - 1 - i
        q = vpos[t] if vpos.shape[0] > 0 else t
        v = V[t, q:d]
        xq = x[q:d]
        f = beta[t] * _dot(v, xq)
        if f != 0.0:
            for c in range(d - q):
                xq[c] -= f * v[c]


@njit(cache=True, fastmath=_FAST, inline="always")
def _lq_multipliers(g, d, r, T, V, beta, vpos, out):
    """The multipliers of the ``r`` rows of an LQ factorization (``L = T[:r, :r]``,
    reflector ``t`` in ``V[t]`` from column ``vpos[t]``, or from ``t`` when ``vpos`` is
    empty) for the gradient ``g``: ``Qᵀ g`` by the reflectors (in place), then
    ``Lᵀ out = (Qᵀ g)[:r]``."""
    _reflect_vector(g, d, r, V, beta, vpos, True)
    for i in range(r - 1, -1, -1):
        acc = g[i]
        for c in range(i + 1, r):
            acc -= T[c, i] * out[c]
        out[i] = acc / T[i, i]


@njit(cache=True, inline="always")
def _stall_limit(rows):
    """Iterations without a step that moves after which a level of ``rows`` rows (its
    own and those above) settles (:data:`FLAG_STALLED`): Bland's rule ends a degenerate
    run of exact arithmetic in far fewer; one that lasts longer is a cycle of
    rounding."""
    return 2 * rows + 10


@njit(cache=True, inline="always")
def _pick_release(bland, j, value, drop, worst):
    """The row to release among the wrong-signed ones so far: by Bland's rule the
    lowest row (anti-cycling), else the largest ``value``; returns ``(drop, worst)``."""
    if bland:
        if drop < 0 or j < drop:
            return j, worst
        return drop, worst
    if value > worst:
        return j, value
    return drop, worst


@njit(cache=True, fastmath=_FAST, inline="always")
def _freed_gain(T, nh, hr, nw, rs, i, w, v, p, flat, tq):
    """What releasing the kept hard row ``i`` (pivot order) of :func:`_eqp`'s last
    factorization frees, from that factorization (``T`` as :func:`_eqp` left it).

    The released row frees the direction ``u = Q_H L⁻¹ e_i`` of the hard rows' row
    space (orthogonal to the other kept hard rows): the level's gradient along ``u/‖u‖``
    is ``ν_i / ‖u‖``. The soft rows move along it by ``T_soft[:, :hr] u/‖u‖``, of which
    only the part outside the range of their factor ``L_s`` on the directions already
    free (``T_soft[:, hr:hr+rs]``) is new: its norm ``γ`` is the level's gain along
    the freed direction, and releasing the row changes the soft rows' values by
    ``|ν_i| / (‖u‖ γ)`` (the minimum of ``h α + γ² α²/2``).

    Scratch: ``w`` (``≥ hr``), ``v`` (``≥ nw``), ``p[hr:hr+rs]``, ``flat``, ``tq``.

    Returns:
        ``(‖u‖, γ)``.
    """
    for c in range(i):
        w[c] = 0.0
    w[i] = 1.0 / T[i, i]
    for c in range(i + 1, hr):
        acc = 0.0
        for t in range(i, c):
            acc -= T[c, t] * w[t]
        w[c] = acc / T[c, c]
    un = np.sqrt(_dot(w[:hr], w[:hr]))
    for r in range(nw):
        v[r] = _dot(T[nh + r, :hr], w[:hr]) / un
    # Qᵀ v by the Householder QR of L_s: its trailing nw − rs entries are v's part
    # outside range(L_s)
    _small_lstsq_ws(T[nh:, hr:], v, nw, rs, 0.0, p, hr, flat, tq)
    return un, np.sqrt(_dot(tq[rs:nw], tq[rs:nw]))


@njit(cache=True, fastmath=_FAST)
def _rows_at_bounds(state, eqr, hard_end, Bo, ucol, xc, blo, bup, rnorm, ynorm, primal_tol,
                    B, nrot, nf, Vf, betaf, posf, col, E, cand, side, inP):
    """The hard rows (``j < hard_end``, not fixed) at a bound at the point ``xc``: the
    working ones (state ±1) and those at a bound within the primal tolerance outside
    the working set. Row ``i`` of ``E`` is the row's free part ``σ B_j[col:]`` (``σ =
    +1`` at its lower bound, ``−1`` at its upper: the directions it allows have ``E_i p
    ≥ 0``), ``cand[i] = j``, ``side[i]`` its state at that bound, ``inP[i] = 1`` when it
    is in the working set. Returns ``(m, extra)``: rows found, of them outside the
    working set."""
    d = B.shape[1] - col
    m = 0
    extra = 0
    for j in range(hard_end):
        st = state[j]
        if eqr[j] or st == 2:
            continue
        working = st == -1 or st == 1
        if not working:
            r = _odot(Bo, ucol, j, xc)
            sz = _size(Bo, ucol, j, rnorm[j], ynorm, xc)
            if np.isfinite(blo[j]) and abs(r - blo[j]) <= _tol(primal_tol, sz, blo[j]):
                st = -1
            elif np.isfinite(bup[j]) and abs(r - bup[j]) <= _tol(primal_tol, sz, bup[j]):
                st = 1
            else:
                continue
            extra += 1
        _bring(B, j, nrot, nf, Vf, betaf, posf)
        sg = 1.0 if st == -1 else -1.0
        for c in range(d):
            E[m, c] = sg * B[j, col + c]
        cand[m] = j
        side[m] = st
        inP[m] = 1.0 if working else 0.0
        m += 1
    return m, extra


@njit(cache=True, fastmath=_FAST)
def _nnls_working_set(E, m, d, g, cand, inP, rnorm, rcond, gscale, T, V, beta, z, h, r,
                      order):
    """The working set of a degenerate point (hard rows at their bounds beyond the
    working ones) by the multipliers it needs: the non-negative least-squares problem
    ``min ‖E_Pᵀ μ − g‖, μ ≥ 0`` over the rows ``E`` at their bounds (Lawson-Hanson): a
    row whose multiplier is wrong-signed beyond ``gscale`` (the release test's, relative
    to ``rnorm``) leaves ``P``, the row the residual most wants enters. ``x*`` is the
    level's optimum over these rows iff the residual is zero (its KKT conditions); a
    primal active-set method walks there one exchange at a time, each a step of length
    zero (G1 with 18 limits at their bounds on 18 free coordinates: 12 iterations of the
    posture level).

    ``P`` starts as the working set ``inP``. Every row whose multiplier is wrong-signed
    there leaves at once; after that one row leaves or enters per pass (released one
    per pass from the working set, 13-15 of its 18 rows left and entries brought them
    back: 31 passes on the G1 stacks whose sword tip holds 19 limits). ``P`` is one LQ
    (``T``, ``V``, ``beta``), built row by row (:func:`_lq_append`): an entering row is
    appended to it, a leaving one has it built again. Returns whether it
    settled (``inP`` the set) within ``2m + 2`` passes with ``P`` clearly independent
    (the hard-row rule, ``rcond``); the caller's iterations verify the set either way."""
    refactor = True
    working = True          # P is the working set as given
    p = 0
    for it in range(2 * m + 2):
        if refactor:
            refactor = False
            p = 0
            for i in range(m):
                if inP[i] != 0.0:
                    if p >= d or not _lq_append(T, p, E[i], d, V, beta,
                                                rcond * rnorm[cand[i]], order[:0]):
                        return False
                    order[p] = i
                    p += 1
        for c in range(d):
            h[c] = g[c]
        _lq_multipliers(h, d, p, T, V, beta, order[:0], z)
        worst = gscale
        out = -1
        for i in range(p):
            wrong = -z[i] * rnorm[cand[order[i]]]
            if wrong > worst:
                worst = wrong
                out = order[i]
        if out >= 0:
            if working:
                # the working set's own multipliers: every wrong-signed row leaves at once
                working = False
                for i in range(p):
                    if -z[i] * rnorm[cand[order[i]]] > gscale:
                        inP[order[i]] = 0.0
            else:
                inP[out] = 0.0
            refactor = True
            continue
        # the residual g − E_Pᵀ μ = Q_P [0; h[p:]]
        for c in range(p):
            r[c] = 0.0
        for c in range(p, d):
            r[c] = h[c]
        _reflect_vector(r, d, p, V, beta, order[:0], False)
        best = gscale
        enter = -1
        if p < d:
            for i in range(m):
                if inP[i] != 0.0:
                    continue
                ee = _dot(E[i, :d], E[i, :d])
                if not ee > 0.0:
                    continue
                want = _dot(E[i, :d], r[:d]) * rnorm[cand[i]] / ee
                if want > best:
                    best = want
                    enter = i
        if enter < 0:
            return True
        inP[enter] = 1.0
        working = False
        if not _lq_append(T, p, E[enter], d, V, beta, rcond * rnorm[cand[enter]],
                          order[:0]):
            return False
        order[p] = enter
        p += 1
    return False


@njit(cache=True, fastmath=_FAST, inline="always")
def _lq_append(T, p, row, d, V, beta, floor, no_pos):
    """Row ``p`` of the LQ factorization ``T[:p]`` (reflector ``t`` in ``V[t, t:d]``,
    ``beta[t]``): ``row[:d]`` copied to ``T[p]``, the ``p`` reflectors applied to it
    (``H_0`` first, as a factorization of all the rows at once applies them to it), and
    a reflector of its own made when what they leave of it, ``‖T[p, p:d]‖``, exceeds
    ``floor`` (the hard-row rule); ``False`` (and no reflector) otherwise. ``no_pos``:
    an empty int array (:func:`_reflect_vector`'s reflector ``t`` starts at ``t``)."""
    u = T[p, :d]
    for c in range(d):
        u[c] = row[c]
    _reflect_vector(u, d, p, V, beta, no_pos, True)
    tail = T[p, p:d]
    if not _dot(tail, tail) > floor * floor:
        return False
    _reflect_row(T, p, p, d, V, beta, p, p + 1, p + 1)
    return True


@njit(cache=True, fastmath=_FAST, inline="always")
def _bring(B, j, nrot, nf, Vf, betaf, posf):
    """Apply the fixing reflectors ``nrot[j] … nf − 1`` to row ``B[j]`` (rows are
    rotated lazily: only when they enter a factorization)."""
    Bj = B[j]
    for t in range(nrot[j], nf):
        q = posf[t]
        v = Vf[t, q:]
        row = Bj[q:]
        f = betaf[t] * _dot(row, v)
        if f != 0.0:
            for c in range(row.shape[0]):
                row[c] -= f * v[c]
    nrot[j] = nf


@njit(cache=True, fastmath=_FAST, inline="always")
def _lift(p, col, px, nf, Vf, betaf, posf):
    """``px = Q [0; p]``: the step ``p`` of the free coordinates ``col:`` in ``x``."""
    n = px.shape[0]
    for c in range(col):
        px[c] = 0.0
    for c in range(n - col):
        px[col + c] = p[c]
    _apply_q(px, nf, Vf, betaf, posf)


@njit(cache=True, fastmath=_FAST, inline="always")
def _odot(Bo, ucol, j, v):
    """``Bo[j] · v``; ``ucol[j] ≥ 0``: the row's only non-zero column (a bound on one
    variable, e.g. a joint limit: one product instead of ``n``)."""
    c = ucol[j]
    if c >= 0:
        return Bo[j, c] * v[c]
    return _dot(Bo[j], v)


@njit(cache=True, inline="always")
def _tol(primal_tol, size_j, bound):
    """Feasibility tolerance of one row: relative to its size (:func:`_size`) plus
    ``|bound|``."""
    return primal_tol * (size_j + abs(bound))


@njit(cache=True, inline="always")
def _size(Bo, ucol, j, rnorm_j, ynorm, x):
    """The size of the terms that make ``a_j x``: ``|a_jc| (|x_c| + 1)`` for a row of one
    column ``c`` (a box bound: one product, rounded to ``eps |a_jc x_c|``, and absolute
    for ``|x_c| ≲ 1`` as in :func:`hierarchy.linalg.row_activity`; bounded by
    ``‖a_j‖ ‖x‖`` it would let ``x_c`` off its bound by ``primal_tol ‖x‖``, which is
    not small when another level drives ``‖x‖`` to 1e10), else ``‖a_j‖ ‖x‖``."""
    c = ucol[j]
    if c >= 0:
        return abs(Bo[j, c]) * (abs(x[c]) + 1.0)
    return rnorm_j * ynorm


@njit(cache=True, inline="always")
def _box_row_unresolved(a, xc, ax, lo, up, xn, primal_tol):
    """Whether ``x``'s precision cannot resolve a box row ``a x_c`` (weighted, ``ax``
    its value, ``[lo, up]`` its weighted interval): a finite bound within that
    precision (``X_PRECISION ‖x‖ |a|``) plus the row's tolerance (:func:`_tol` at
    :func:`_size`'s ``|a| (|x_c| + 1)``) while the precision is the coarser.

    Never at ``X_PRECISION ‖x‖ < primal_tol / 2`` (the common case, decided first):
    the precision is then below ``primal_tol |a| / 2``, under every row's tolerance."""
    if X_PRECISION * xn < 0.5 * primal_tol:
        return False
    precision = X_PRECISION * xn * abs(a)
    size = abs(a) * (abs(xc) + 1.0)
    for bound in (lo, up):
        if np.isfinite(bound):
            tol = _tol(primal_tol, size, bound)
            if precision > tol and abs(ax - bound) <= precision + tol:
                return True
    return False


@njit(cache=True, fastmath=_FAST, inline="always")
def _gather(state, hard_end, s0, s1, blo, bup, rows, tgt, B, nrot, nf, Vf, betaf, posf):
    """Working rows: hard ones (``j < hard_end``, state ±1) first, then the level's;
    each brought up to date with the fixing reflectors. The counts are int64 from the
    start (see :func:`solve_data`: a literal 0 makes numba compile ``_step`` again)."""
    nh = np.int64(0)
    for j in range(hard_end):
        st = state[j]
        if st == -1 or st == 1:
            rows[nh] = j
            tgt[nh] = blo[j] if st == -1 else bup[j]
            nh += 1
    nw = np.int64(0)
    for j in range(s0, s1):
        st = state[j]
        if st != 0:
            rows[nh + nw] = j
            tgt[nh + nw] = bup[j] if st == 1 else blo[j]
            nw += 1
    return nh, nw


@njit(cache=True, inline="always")
def _dual_scale(dual_tol, scale, ynorm, tgt, nh, nw):
    """The level's multiplier tolerance without its gradient term (as in the dual
    test): ``dual_tol ‖A_i‖_F (‖A_i‖_F ‖x‖ + ‖targets of the working soft rows‖)``."""
    tn = 0.0
    for i in range(nh, nh + nw):
        tn += tgt[i] * tgt[i]
    return dual_tol * scale * (scale * ynorm + np.sqrt(tn))


@njit(cache=True, fastmath=_FAST, inline="always")
def _violated_side(r, lo, up, tol_lo, tol_up):
    if r < lo - tol_lo:
        return -1
    if r > up + tol_up:
        return 1
    return 0


@njit(cache=True, inline="always")
def _rows_valid(row_eq, b, lower, upper, sw, flags):
    """Whether every row's interval ``[lo, up]`` (an equality row's: ``b_j`` twice) and
    ``√w`` are valid — finite target, no NaN bound, ``lower < +inf``, ``upper > −inf``,
    ``lower ≤ upper`` (one test, ``lo ≤ up`` being false when either is NaN), ``√w``
    finite and ``> 0`` — with ``flags[j] = 1`` where the row is an equality
    (``lo = up``), else ``0``.

    One pass of its own over the 1-D arrays, written out without a branch or a helper:
    selects, the tests combined bitwise, the invalid rows counted and decided once at
    the end. (The G1 bounds stack's 75 rows: 0.1 µs; with a branch per row, or with the
    interval taken from an inlined helper returning a tuple, 1.1 µs.)"""
    bad = 0
    for j in range(row_eq.shape[0]):
        e = row_eq[j] != 0
        lo = b[j] if e else lower[j]
        up = b[j] if e else upper[j]
        s = sw[j]
        ok = (lo <= up) & (lo < np.inf) & (up > -np.inf) & (s > 0.0) & (s < np.inf)
        bad += 0 if ok else 1
        flags[j] = 1 if lo == up else 0
    return bad == 0


@njit(cache=True, fastmath=_FAST, inline="always")
def _sparsity(a, hint):
    """``(a · a, c)``: the squared norm of the row ``a`` and its one non-zero column
    ``c`` (``-1`` unless exactly one entry is non-zero). The count runs vectorised; the
    column is looked up only for a row with one non-zero, and not at all when it is
    ``hint`` (the row's column at the last solve: a joint limit keeps its joint)."""
    nn = 0.0
    nz = 0
    for c in range(a.shape[0]):
        v = a[c]
        nn += v * v
        nz += 1 if v != 0.0 else 0
    return nn, _one_column(a, nz, hint)


@njit(cache=True, inline="always")
def _one_column(a, nz, hint):
    """The column of the row ``a``'s one non-zero when it has ``nz = 1`` of them (``hint``
    first: the row's column at the last solve), else ``-1``."""
    n = a.shape[0]
    if nz != 1:
        return -1
    if hint >= 0 and hint < n and a[hint] != 0.0:
        return hint
    for c in range(n):
        if a[c] != 0.0:
            return c
    return -1


@njit(cache=True, fastmath=_FAST, inline="always")
def _extreme_scale_rows(A, rnorm, sw, starts, k):
    """Whether a level of ``A`` is of extreme scale (:func:`_level_extreme`), from the
    weighed rows' norms ``rnorm`` (``‖√w_j a_j‖``; no second pass over ``A`` unless a
    level is tiny): the caller solves the equilibrated stack
    (``TaskStack.equilibrated``, the same optimum)."""
    for lev in range(k):
        acc = 0.0
        for i in range(starts[lev], starts[lev + 1]):
            r = rnorm[i] / sw[i]
            acc += r * r
        if _level_extreme(A, acc, starts[lev], starts[lev + 1]):
            return True
    return False


@njit(cache=True, fastmath=_FAST, inline="always")
def _load_rows(A, b, lower, upper, sw, row_eq, B, Bo, blo, bup, rnorm, eqr, ucol, nrot,
               state):
    """The first pass over the data: every row weighed by ``√w`` into ``B`` and ``Bo``,
    its bounds (``blo``, ``bup``, weighed), norm, equality flag (``lower = upper``
    included) and single column (``ucol``, ``-1`` if none), the ``n`` minimum-norm rows
    after them; ``False`` at the first value that is not valid (see
    :func:`solve_data`)."""
    M, n = A.shape
    if not _rows_valid(row_eq, b, lower, upper, sw, eqr):
        return False
    for j in range(M):
        s = sw[j]
        Bj = B[j]
        Boj = Bo[j]
        Aj = A[j]
        nn = 0.0
        for c in range(n):
            v = s * Aj[c]
            Bj[c] = v
            Boj[c] = v
            nn += v * v
        ucol[j] = -1 if row_eq[j] else _sparsity(Aj, ucol[j])[1]
        nrot[j] = 0
        e = row_eq[j] != 0
        blo[j] = s * (b[j] if e else lower[j])
        bup[j] = s * (b[j] if e else upper[j])
        rnorm[j] = np.sqrt(nn)
        if not np.isfinite(rnorm[j]):
            return False
        state[j] = 0
    for j in range(M, M + n):
        blo[j] = 0.0
        bup[j] = 0.0
        eqr[j] = 1
        rnorm[j] = 1.0
        state[j] = 0
    return True


@njit(cache=True, fastmath=_FAST, inline="always")
def _add_level_gradient(A, b, lower, row_eq, sw, ucol, ecol, s0, s1, x, g):
    """``g += Σ_j s_j² (a_j·x − t_j) a_j`` over the equality rows (``ucol[j] = -2``) of
    ``s0:s1`` (a level's gradient of ``½ f_ℓ`` in ``x``; a unit row, ``ecol[j] ≥ 0``, one
    product); returns ``Σ_j s_j² t_j²`` (the targets' scale)."""
    n = A.shape[1]
    tn = 0.0
    for j in range(s0, s1):
        if ucol[j] != -2:
            continue
        s = sw[j]
        t = b[j] if row_eq[j] else lower[j]
        ec = ecol[j]
        if ec >= 0:             # a unit row (a posture's): one product
            e = s * s * (A[j, ec] * x[ec] - t)
            g[ec] += e * A[j, ec]
        else:
            e = s * s * (_dot(A[j], x) - t)
            if e != 0.0:
                Aj = A[j]
                for c in range(n):
                    g[c] += e * Aj[c]
        tn += s * s * t * t
    return tn


@njit(cache=True, fastmath=_FAST, inline="always")
def _held_rows_optimal(A, b, lower, row_eq, sw, starts, k, x, y, eB, estarts, eranks, ucol,
                       ecol, erow, rowperm, held, scales, dual_tol, V, beta, pos, Z, g, cn,
                       prow, pside, pinned, hcol):
    """Whether the held rows' multipliers prove the equality-first answer ``x*`` (the
    nested QR's, the held rows solved as equalities at their bounds) lexicographically
    optimal with those rows as the inequalities they are: ``-1`` when they do, else the
    data row of the most wrong-signed multiplier at the first level that has one (the
    row to release), ``-2`` when the test cannot be read.

    Level ``ℓ`` below a held row minimises ``f_ℓ`` over ``X_{ℓ−1}``, the polyhedron of
    the levels above; ``x*`` does iff ``−∇f_ℓ(x*)`` lies in its normal cone, which holds
    the span of every row of the equality levels above and, for a held row ``h`` on
    side ``s_h`` (``+1`` upper, ``−1`` lower), the ray ``s_h a_h`` — or the line of
    ``a_h`` once ``h`` is *pinned*: a level above held it with a multiplier clearly of
    the right sign, so every point of that level's optimal set has ``h`` on its bound.
    In the rotated coordinates of the nested QR the pivot rows ``C`` of the levels above
    are lower triangular on the ``col_ℓ`` coordinates they fix, and the optimality of
    ``x*`` on the rest makes ``(Qᵀ ∇f_ℓ)[col_ℓ:]`` zero: ``Cᵀ μ = (Qᵀ ∇f_ℓ)[:col_ℓ]``, of
    which only the held rows' ``μ_h = (C⁻¹ e_h) · (Qᵀ ∇f_ℓ)[:col_ℓ]`` are read, and ``x*``
    passes when no unpinned held row's ``s_h μ_h ‖c_h‖``
    exceeds :data:`_DUAL_FLOOR` times the level's gradient scale (that of
    :func:`_dual_scale`). A multiplier of the right sign beyond ``dual_tol`` times that
    scale pins its row. The minimum-norm tie-break is read the same way, its gradient
    being ``y = Qᵀ x*``. Once every held row is pinned the levels below (and the
    tie-break) need no reading: the optimal set above then has each held row on its
    bound, so it lies in the QR's (the held rows as equalities), over which ``x*`` is
    optimal level by level and of minimum norm. The test is sufficient, not necessary:
    a refusal sends the stack on (another guess, then the active set, which decides).
    ``-2`` when a held row or a level whose gradient is read lies in or below a level
    the QR did not leave triangular (a level with at least as many rows as free
    coordinates: its full-rank or unit-rows step), with a held row still unpinned.

    ``held[j]``: the side of data row ``j`` (``0``: not held); ``ecol[j]``: an equality
    row's one non-zero column (``-1``: more than one); ``erow`` maps the rows of
    ``eB`` (before pivoting) to the data's, ``rowperm`` the pivoting. Scratch: ``Z``
    (``≥ n × n``: the ``C⁻¹ e_h``), ``g``, ``cn`` (``n``: a gradient, the held pivot rows'
    norms), ``prow``, ``pside``, ``pinned``, ``hcol`` (``n`` ints).
    """
    M, n = A.shape
    col = 0
    complete = k            # the first level the QR left in another form
    ctri = -1               # the coordinates the levels above it fix
    first_held = k
    for lev in range(k):
        e0 = estarts[lev]
        m = estarts[lev + 1] - e0
        if m > 0 and col < n and m >= n - col and complete == k:
            complete = lev
            ctri = col
        for i in range(eranks[lev]):
            p = col + i
            prow[p] = e0 + i
            j = erow[rowperm[e0 + i]]
            pside[p] = held[j] if ucol[j] != -2 else 0
            if pside[p] != 0 and first_held == k:
                first_held = lev
        col += eranks[lev]
    ncol = col
    if ctri < 0:
        ctri = ncol
    if first_held == k:
        return -1
    xn = np.sqrt(_dot(x, x))
    # z_h = C⁻¹ e_h of each held pivot h, by forward substitution over the pivot rows
    # (lower triangular, rows contiguous) of the levels the QR left triangular, once: a
    # level's multiplier of h is then μ_h = z_h · (Qᵀ ∇f_ℓ)[:col_ℓ] (C's leading block
    # is the levels above's)
    nh = 0
    for h in range(ncol):
        if pside[h] == 0:
            continue
        if h >= ctri:           # a held row the QR left in another form: not read
            return -2
        z = Z[nh]
        for p in range(h):
            z[p] = 0.0
        row = eB[prow[h]]
        z[h] = 1.0 / row[h]
        cn[nh] = np.sqrt(_dot(row[:h + 1], row[:h + 1]))
        for p in range(h + 1, ctri):
            row = eB[prow[p]]
            z[p] = -_dot(row[h:p], z[h:p]) / row[p]
        hcol[nh] = h
        pinned[nh] = 0
        nh += 1
    npinned = 0
    # each level below the first held row that has equality rows (its other rows are
    # satisfied: no gradient), in order, then the tie-break
    col = 0
    for lev in range(k + 1):
        if lev > first_held and npinned == nh:
            # every held row pinned: the optimal set above has each on its bound, so it
            # lies in the QR's (the held rows as equalities), where x* is optimal
            break
        if lev < k:
            colv = col
            col += eranks[lev]
            if lev <= first_held or estarts[lev + 1] == estarts[lev]:
                continue
            if ucol[erow[estarts[lev]]] != -2:
                # a held row's level (its equality rows beside it or not) is met exactly
                # (_equality_first's rank check): no gradient
                continue
            if lev > complete:
                return -2
            for c in range(n):
                g[c] = 0.0
            tn = 0.0
            if lev < k - 1:
                # its rows, rotated by the levels above's reflectors: (Qᵀ ∇f_ℓ)[:col_ℓ]
                # = Σ_i r_i (eB_i)[:col_ℓ], r_i the weighted residual of the row's data
                for i in range(estarts[lev], estarts[lev + 1]):
                    j = erow[rowperm[i]]
                    s = sw[j]
                    t = b[j] if row_eq[j] else lower[j]
                    ec = ecol[j]
                    r = s * ((A[j, ec] * x[ec] if ec >= 0 else _dot(A[j], x)) - t)
                    tn += s * s * t * t
                    if r != 0.0:
                        Bi = eB[i]
                        for c in range(colv):
                            g[c] += r * Bi[c]
            else:
                # the last level's rows may be the unit rows the QR left unrotated: its
                # gradient in x, brought through the reflectors that fix the first col_ℓ
                tn = _add_level_gradient(A, b, lower, row_eq, sw, ucol, ecol, starts[lev],
                                         starts[lev + 1], x, g)
                _apply_qt(g, colv, V, beta, pos)      # the reflectors t < col_ℓ fix [:col_ℓ]
            gh = g
            scale = max(np.sqrt(_dot(g[:colv], g[:colv])),
                        scales[lev] * (scales[lev] * xn + np.sqrt(tn)))
        else:                       # the tie-break: ∇ ½‖x‖² = x, Qᵀ x = y
            if complete < k:
                return -2
            colv = ncol
            gh = y
            scale = np.sqrt(_dot(y[:ncol], y[:ncol]))
        worst = _DUAL_FLOOR * scale
        release = -1
        for i in range(nh):
            h = hcol[i]
            if h >= colv or pinned[i] != 0:
                continue
            wrong = pside[h] * _dot(Z[i, h:colv], gh[h:colv]) * cn[i]
            if wrong > worst:
                worst = wrong
                release = h
            elif -wrong > dual_tol * scale:
                pinned[i] = 1
                npinned += 1
        if release >= 0:
            return erow[rowperm[prow[release]]]
    return -1


@njit(cache=True, fastmath=_FAST, inline="always")
def _fixed_columns_optimal(A, b, lower, row_eq, sw, starts, k, x, eR, estarts, eranks,
                           ucol, ecol, erow, rowperm, held, fixedc, last_held, scales,
                           dual_tol, V, fs, pos, work, prow, prowj, pinned, hrow, nh):
    """:func:`_held_rows_optimal` for held rows that are box rows eliminated as fixed
    coordinates (:func:`_equality_first`'s reduced solve): ``-1`` when their
    multipliers prove ``x*`` lexicographically optimal, else the data row to release
    (the most wrong-signed multiplier at the first level that has one), ``-2`` when the
    test cannot be read.

    The reduced nested QR solved the equality levels on the free coordinates (``fixedc[c]
    = 0``) with every held row's coordinate ``x_c`` at its bound, its pivot rows ``C``
    lower triangular in the rotated free coordinates. Every level down to ``last_held``
    (the lowest level with a held row) is met exactly (the caller checked its rank), and
    so is a level below whose equality rows ``x*`` meets to its precision
    (``‖r_ℓ‖ ≤ X_PRECISION (‖√W_ℓ A_ℓ‖_F ‖x*‖ + ‖√W_ℓ t_ℓ‖)``): their value is the least
    there is, and they have no gradient to read. For another level ``ℓ`` below, ``x*``
    minimises ``f_ℓ`` over ``X_{ℓ−1}`` iff ``−∇f_ℓ(x*)`` lies in the normal cone: the span
    of the pivot rows above plus, for each held row ``h`` on side ``s_h`` on column
    ``c``, the ray ``s_h a_hc e_c`` (the line once ``h`` is pinned, as in
    :func:`_held_rows_optimal`). The free part fixes the rows' multipliers: ``Cᵀ μ =
    (Qᵀ ∇f_ℓ)_free[:col_ℓ]`` (the rest is zero where the reduced QR is optimal), by back
    substitution; each held column's multiplier is then what they leave of the
    gradient there, ``ν_c = (∇f_ℓ)_c − Σ_p μ_p a_pc``, and ``x*`` passes when no unpinned
    held row's ``s_h sign(a_hc) ν_c`` exceeds :data:`_DUAL_FLOOR` times the level's
    gradient scale. ``(Qᵀ ∇f_ℓ)_free[:col_ℓ]`` is ``Σ_i r_i (eR_i)[:col_ℓ]`` over the
    level's rows as the QR rotated them; the last level's may be the unit rows it left
    unrotated, whose gradient is brought through the reflectors instead. The
    minimum-norm tie-break is read the same way, with ``∇ = x*`` (``Qᵀ x*_free``: the
    QR's ``y``). Sufficient, not necessary: a refusal sends the stack on. ``-2`` when a
    gradient must be read in or below a level the QR did not leave triangular (its
    full-rank or unit-rows step).

    ``fs``: the reduced QR's ``beta`` and ``y`` in its rows 0 and 1; rows 2 and 3 (``≥ n``)
    scratch for a gradient in ``x`` and its free part. Scratch: ``work`` (``≥ 2n + M``
    floats: the multipliers, the rows' residuals, the held columns' gradient),
    ``prow``, ``prowj`` (the pivot rows' rows in ``eR`` and in the data), ``pinned``
    (``n`` ints). ``hrow[:nh]``: the held rows (the caller's list).
    """
    M, n = A.shape
    n2 = eR.shape[1]
    beta = fs[0, :n2]
    y = fs[1, :n2]
    g = fs[2, :n]
    gf = fs[3, :n2]
    mu = work[:n]
    rs = work[n:n + M]
    gc = work[n + M:n + M + n]
    col = 0
    complete = k            # the first level the QR left in another form
    for lev in range(k):
        e0 = estarts[lev]
        m = estarts[lev + 1] - e0
        if m > 0 and col < n2 and m >= n2 - col and complete == k:
            complete = lev
        for i in range(eranks[lev]):
            prow[col + i] = e0 + i
            prowj[col + i] = erow[rowperm[e0 + i]]
        col += eranks[lev]
    ncol = col
    for i in range(nh):
        pinned[i] = 0
    npinned = 0
    xn = np.sqrt(_dot(x, x))
    col = 0
    for lev in range(k + 1):
        if lev > last_held and npinned == nh:
            # every held row pinned: the optimal set above has each on its bound, so it
            # lies in the reduced QR's, where x* is optimal
            break
        if lev < k:
            colv = col
            col += eranks[lev]
            if lev <= last_held:
                continue
            tn = 0.0
            rr = 0.0
            some = False
            for j in range(starts[lev], starts[lev + 1]):
                if ucol[j] != -2:
                    continue
                some = True
                s = sw[j]
                t = b[j] if row_eq[j] else lower[j]
                ec = ecol[j]
                r = s * ((A[j, ec] * x[ec] if ec >= 0 else _dot(A[j], x)) - t)
                rs[j] = r
                rr += r * r
                tn += s * s * t * t
            if not some:            # inequality rows alone, all inside: no gradient
                continue
            if np.sqrt(rr) <= X_PRECISION * (scales[lev] * xn + np.sqrt(tn)):
                continue            # met to x's precision
            if lev > complete:
                return -2
            if lev < k - 1:
                # its rows as the QR rotated them: (Qᵀ ∇f_ℓ)[:col_ℓ] = Σ_i r_i (eR_i)[:col_ℓ]
                for q in range(colv):
                    gf[q] = 0.0
                for i in range(estarts[lev], estarts[lev + 1]):
                    r = rs[erow[rowperm[i]]]
                    if r != 0.0:
                        Ri = eR[i]
                        for q in range(colv):
                            gf[q] += r * Ri[q]
                gn = _dot(gf[:colv], gf[:colv])
                for i in range(nh):
                    c = ucol[hrow[i]]
                    acc = 0.0
                    for j in range(starts[lev], starts[lev + 1]):
                        if ucol[j] == -2:
                            acc += rs[j] * sw[j] * A[j, c]
                    gc[i] = acc
                    gn += acc * acc
            else:
                # the last level's rows may be the unit rows the QR left unrotated: its
                # gradient in x, its free part brought through the reflectors t < col_ℓ
                for c in range(n):
                    g[c] = 0.0
                _add_level_gradient(A, b, lower, row_eq, sw, ucol, ecol, starts[lev],
                                    starts[lev + 1], x, g)
                q = 0
                for c in range(n):
                    if fixedc[c] == 0:
                        gf[q] = g[c]
                        q += 1
                gn = _dot(g, g)
                _apply_qt(gf, colv, V, beta, pos)
                for i in range(nh):
                    gc[i] = g[ucol[hrow[i]]]
            gh = gf
            scale = max(np.sqrt(gn), scales[lev] * (scales[lev] * xn + np.sqrt(tn)))
        else:                       # the tie-break: ∇ ½‖x‖² = x, Qᵀ x_free = y
            if complete < k:
                return -2
            colv = ncol
            gh = y
            for i in range(nh):
                gc[i] = x[ucol[hrow[i]]]
            scale = xn
        # the pivot rows' multipliers: Cᵀ μ = gh[:colv], C lower triangular, by columns
        # of Cᵀ (C's rows: contiguous)
        for q in range(colv):
            mu[q] = gh[q]
        for pp in range(colv):
            p = colv - 1 - pp
            Cp = eR[prow[p]]
            mp = mu[p] / Cp[p]
            mu[p] = mp
            for q in range(p):
                mu[q] -= Cp[q] * mp
        worst = _DUAL_FLOOR * scale
        release = -1
        for i in range(nh):
            if pinned[i] != 0:
                continue
            j = hrow[i]
            c = ucol[j]
            nu = gc[i]
            for p in range(colv):
                jp = prowj[p]
                nu -= mu[p] * sw[jp] * A[jp, c]
            wrong = held[j] * (nu if A[j, c] > 0.0 else -nu)
            if wrong > worst:
                worst = wrong
                release = j
            elif -wrong > dual_tol * scale:
                pinned[i] = 1
                npinned += 1
        if release >= 0:
            return release
    return -1


@njit(cache=True, fastmath=_FAST, inline="always")
def _equality_first(A, b, lower, upper, sw, row_eq, starts, k, rcond, primal_tol, dual_tol,
                    eflat, evec, eint, x, ranks, margins, w2, res, Vflat, Lflat, fs, pos, eqr,
                    held, spare, ispare, allow_fixed):
    """The stack's equality rows (rows with ``lower = upper`` included) with the rows the
    last answer held (``held[j]``: ``±1``, at their upper/lower bound; ``0`` for
    none), as equalities at those bounds, weighed into ``eB`` and solved by the
    extended Jacobian's nested QR (its compiled :func:`solve_kernel_into`) with this
    kernel's rank rule (``rcond`` times each level's whole ``‖√W_i A_i‖_F``); when that
    answer ``x*`` is the stack's, ``x``, ``ranks[:k]``, ``margins[:k]`` and the levels'
    violations ``w2``, ``res`` are written.

    When every held row is a box row (one non-zero ``a_c``, distinct columns) and
    ``allow_fixed``, the held rows are not rows of the QR: each fixes its coordinate,
    ``x_c = bound / a_c``, and the equality rows are solved on the other coordinates
    with ``a_ic x_c`` moved to their right-hand side (an equality row on fixed
    coordinates alone leaves the QR: a constant residual). This is the same problem when
    every level down to the lowest held one is met exactly on the free coordinates (its
    rank is its count): the held rows are then independent of those levels, and fixing
    them before or after is the same point set. Otherwise the verdict is
    :data:`FIXED_REFUSED` and the caller tries the same guess again with the rows held
    as equalities. Its multipliers are read by :func:`_fixed_columns_optimal`.

    Returns ``(verdict, row, side)``: ``verdict = -1`` when ``x*`` is the answer; ``-3``
    with a next guess when it is not because a row is violated (the most violated, with
    the side to hold it on) or a held row's multiplier is wrong-signed (the row to
    release, ``side = 0``); :data:`FIXED_REFUSED` as above; ``-2`` when it is not for
    another reason.

    It is when every other row is inside its interval (no tolerance), every rank
    decision is clear, ``x``'s precision resolves every box row, and the held rows are
    met: each on its bound within the primal tolerance (a box row put on it exactly
    when within ``x``'s precision, as the active set does), in levels met exactly
    (a held row's level, its equality rows included, has rank equal to its row count:
    it is independent of everything above, and the level's violation is zero, the
    least there is) and their multipliers say
    so (:func:`_held_rows_optimal`, :func:`_fixed_columns_optimal`). With no held row: by induction over the levels,
    ``X_i ⊆ X_i^E`` (the optimal sets without the inequality rows) and ``x* ∈ X_i`` (its
    inequality rows are satisfied, so each level's value equals its equality part's
    least value), and ``x*``, the minimum-norm point of ``X_k^E``, is that of ``X_k``.
    A value :func:`_rows_valid` refuses gives ``-2`` (:func:`solve_data` names it).
    Reads the data directly (one pass; the active set's own rows are not built).
    Scratch (the active set's, unused on this path), flat where the fixed coordinates'
    solve reshapes it to its own size: ``eflat`` (``≥ M n``: the weighed rows),
    ``Vflat`` (``n²``), ``Lflat`` (``≥ M n``), ``fs`` (``4 × ≥ max(M, n)``), ``pos``
    (``≥ n`` ints), ``eqr`` (``≥ M`` int8: each row's equality flag); the nested QR's
    own ``spare`` and ``ispare``.
    """
    M, n = A.shape
    eB = eflat[:M * n].reshape((M, n))
    V = Vflat[:n * n].reshape((n, n))
    L = Lflat[:M * n].reshape((M, n))
    c = evec[:M]
    o = M
    scales = evec[o:o + k]
    mu2 = evec[o + k:o + 2 * k]
    emargins = evec[o + 2 * k:o + 3 * k]
    step_bound = evec[o + 3 * k:o + 4 * k]
    estarts = eint[:k + 1]
    eranks = eint[k + 1:2 * k + 1]
    o = 2 * k + 1
    ucol = eint[o:o + M]      # -2: an equality row
    erow = eint[o + M:o + 2 * M]
    rowperm = eint[o + 2 * M:o + 3 * M]
    o += 3 * M
    prow = eint[o:o + n]
    pside = eint[o + n:o + 2 * n]
    pinned = eint[o + 2 * n:o + 3 * n]
    hcol = eint[o + 3 * n:o + 4 * n]
    ecol = eint[o + 4 * n:o + 4 * n + M]      # an equality row's one column, or -1
    iseq = eqr[:M]
    if not _rows_valid(row_eq, b, lower, upper, sw, iseq):
        return -2, -1, 0
    # the held rows: box rows (one non-zero, on distinct columns) fix their coordinates,
    # x_c = bound / a_c, and the equality rows are solved on the free coordinates with
    # a_ic x_c on the right-hand side: fewer rows and columns for the QR than holding the
    # rows as equalities (G1 with 5 held limits: they added ~60% of the work). Every
    # level down to the lowest held one must then be met exactly on the rest (checked
    # after the solve: its rank is its count), where fixing x_c before or after those
    # levels is the same. Other held rows are held as equalities in the QR.
    fixedc = pside          # (the other path's _held_rows_optimal uses it otherwise)
    fcol = prow             # the free columns (prow and pinned are rewritten after)
    hlist = hcol            # the held rows, read again by _fixed_columns_optimal
    colmap = pinned         # each free column's place among them
    nheld = 0
    last_held = -1
    fixed = allow_fixed
    for lev in range(k):
        for j in range(starts[lev], starts[lev + 1]):
            if held[j] != 0:
                if iseq[j] or nheld >= n - 1:
                    fixed = False
                else:
                    hlist[nheld] = j
                nheld += 1
                last_held = lev
    n2 = n
    if nheld == 0:
        fixed = False
    if fixed:
        for cc in range(n):
            fixedc[cc] = 0
        for i in range(nheld):
            j = hlist[i]
            _, uc = _sparsity(A[j], ucol[j])
            ucol[j] = uc
            if uc < 0 or sw[j] == 0.0 or fixedc[uc] != 0:
                fixed = False
                break
            fixedc[uc] = 1
            x[uc] = (upper[j] if held[j] > 0 else lower[j]) / A[j, uc]
    if fixed:
        n2 = 0
        for cc in range(n):
            if fixedc[cc] == 0:
                fcol[n2] = cc
                colmap[cc] = n2
                n2 += 1
    m = 0
    estarts[0] = 0
    for lev in range(k):
        acc = 0.0
        if fixed:
            for j in range(starts[lev], starts[lev + 1]):
                s = sw[j]
                Aj = A[j]
                if iseq[j]:
                    nn = 0.0
                    nz = 0
                    for col in range(n):
                        a = Aj[col]
                        nn += a * a
                        nz += 1 if a != 0.0 else 0
                    nn *= s * s
                    ucol[j] = -2
                    ecol[j] = _one_column(Aj, nz, ecol[j])
                    t = b[j] if row_eq[j] else lower[j]
                    ec = ecol[j]
                    if ec >= 0:                 # a unit row (a posture's)
                        if fixedc[ec] != 0:
                            t -= Aj[ec] * x[ec]
                            nz = 0
                    else:
                        for i in range(nheld):
                            cc = ucol[hlist[i]]
                            a = Aj[cc]
                            if a != 0.0:
                                t -= a * x[cc]
                                nz -= 1
                    if nz == 0:         # on fixed coordinates alone: a constant residual
                        if lev <= last_held:
                            return FIXED_REFUSED, -1, 0
                    else:
                        row = eflat[m * n2:(m + 1) * n2]
                        if ec >= 0:
                            row[:] = 0.0
                            row[colmap[ec]] = s * Aj[ec]
                        else:
                            for q in range(n2):
                                row[q] = s * Aj[fcol[q]]
                        c[m] = s * t
                        erow[m] = j
                        rowperm[m] = m
                        m += 1
                elif held[j] != 0:
                    nn = s * A[j, ucol[j]]
                    nn *= nn
                else:
                    nn, ucol[j] = _sparsity(Aj, ucol[j])
                    nn *= s * s
                acc += nn
        else:
            for j in range(starts[lev], starts[lev + 1]):
                s = sw[j]
                Aj = A[j]
                if iseq[j] or held[j] != 0:
                    row = eB[m]
                    nn = 0.0
                    nz = 0
                    for col in range(n):
                        a = Aj[col]
                        v = s * a
                        row[col] = v
                        nn += v * v
                        nz += 1 if a != 0.0 else 0
                    if iseq[j]:
                        c[m] = s * (b[j] if row_eq[j] else lower[j])
                        ucol[j] = -2
                        ecol[j] = _one_column(Aj, nz, ecol[j])
                    else:
                        c[m] = s * (upper[j] if held[j] > 0 else lower[j])
                        ucol[j] = _one_column(Aj, nz, ucol[j])
                    erow[m] = j
                    rowperm[m] = m
                    m += 1
                else:
                    nn, ucol[j] = _sparsity(Aj, ucol[j])
                    nn *= s * s
                acc += nn
        # (a sum of squares: finite iff every term is; ordered comparisons, which LLVM
        # keeps: np.isfinite here was folded to true once this loop took its fixed branch).
        # A level of extreme scale is refused here, and by solve_data: the caller
        # equilibrates it
        if _level_extreme(A, acc, starts[lev], starts[lev + 1]):
            return -2, -1, 0
        scales[lev] = np.sqrt(acc)
        step_bound[lev] = 0.0
        estarts[lev + 1] = m
    eR = eflat[:0].reshape((0, 1))      # the reduced rows (typed here for both paths)
    if fixed:
        eR = eflat[:m * n2].reshape((m, n2))
        solve_kernel_into(eR, c[:m], estarts, scales, rcond, 0.0, 0.0, step_bound, x[:n2],
                          eranks, mu2, emargins, Vflat[:n2 * n2].reshape((n2, n2)),
                          fs[0, :n2], pos, fs[1, :n2], fs[2, :m],
                          Lflat[:m * n2].reshape((m, n2)), fs[3, :m], rowperm[:m], spare,
                          ispare)
        q = n2
        for cc in range(n - 1, -1, -1):     # the free coordinates to their columns
            if fixedc[cc] == 0:
                q -= 1
                x[cc] = x[q]
        for i in range(nheld):
            j = hlist[i]
            uc = ucol[j]
            x[uc] = (upper[j] if held[j] > 0 else lower[j]) / A[j, uc]
    else:
        # the extended Jacobian's own compiled solve, on this kernel's scratch (not its
        # body inlined here: inlined into a second module it changed that kernel's
        # rounding in the first one)
        solve_kernel_into(eB[:m], c[:m], estarts, scales, rcond, 0.0, 0.0, step_bound, x,
                          eranks, mu2, emargins, V, fs[0, :n], pos, fs[1, :n], fs[2, :M],
                          L[:M], fs[3, :M], rowperm[:m] if nheld > 0 else rowperm[:0],
                          spare, ispare)
    xx = _dot(x, x)
    if not (xx <= _PRECISION_LIMIT_NORM * _PRECISION_LIMIT_NORM):
        return -2, -1, 0
    for lev in range(k):
        if emargins[lev] <= _AMBIGUITY:
            return -2, -1, 0
        if fixed:
            if lev <= last_held and eranks[lev] != estarts[lev + 1] - estarts[lev]:
                return FIXED_REFUSED, -1, 0     # not met exactly above a held row
        elif nheld > 0 and estarts[lev + 1] > estarts[lev]:
            # a level with a held row (its equality rows beside it or not) is met exactly
            # (its rank is its count): its violation is then zero, the least there is
            for e in range(estarts[lev], estarts[lev + 1]):
                if ucol[erow[e]] != -2:
                    if eranks[lev] != estarts[lev + 1] - estarts[lev]:
                        return -2, -1, 0
                    break
    xn = np.sqrt(xx)
    if nheld > 0 and not fixed:     # a held box row off its bound by x's precision is put on it
        for j in range(M):
            uc = ucol[j]
            if held[j] != 0 and uc >= 0:
                bound = upper[j] if held[j] > 0 else lower[j]
                if abs(A[j, uc] * x[uc] - bound) <= X_PRECISION * xn * abs(A[j, uc]):
                    x[uc] = bound / A[j, uc]
    worst = 0.0
    add = -1
    side = 0
    for j in range(M):
        uc = ucol[j]
        if uc == -2:
            continue
        lo = lower[j]
        up = upper[j]
        r = A[j, uc] * x[uc] if uc >= 0 else _dot(A[j], x)
        held_row = held[j] != 0
        size = 0.0
        if held_row or r < lo or r > up:
            size = _size(A, ucol, j, np.sqrt(_dot(A[j], A[j])) if uc < 0 else 0.0, xn, x)
        if held_row:
            bound = up if held[j] > 0 else lo
            s = sw[j]
            if not abs(s * (r - bound)) <= _tol(primal_tol, s * size, s * bound):
                return -2, -1, 0
        elif r < lo or r > up:
            # the most violated row (relative to its size) is the guess to hold next
            v = (lo - r if r < lo else r - up) / max(size, 1e-300)
            if v > worst:
                worst = v
                add = j
                side = -1 if r < lo else 1
            continue
        if uc >= 0:        # as the active set's box-row pass: x's precision decides
            s = sw[j]
            if _box_row_unresolved(s * A[j, uc], x[uc], s * r, s * lo, s * up, xn,
                                   primal_tol):
                return -2, -1, 0
    if add >= 0:
        return -3, add, side
    if fixed:
        release = _fixed_columns_optimal(
            A, b, lower, row_eq, sw, starts, k, x, eR, estarts, eranks, ucol, ecol, erow,
            rowperm, held, fixedc, last_held, scales, dual_tol,
            Vflat[:n2 * n2].reshape((n2, n2)), fs, pos, Lflat, prow, ispare, pinned,
            hlist, nheld)
        if release != -1:
            return -3 if release >= 0 else -2, release, 0
    elif nheld > 0:
        release = _held_rows_optimal(
            A, b, lower, row_eq, sw, starts, k, x, fs[1, :n], eB, estarts, eranks, ucol,
            ecol, erow, rowperm, held, scales, dual_tol, V, fs[0, :n], pos, L, fs[2, :n],
            fs[3, :n], prow, pside, pinned, hcol)
        if release != -1:
            return -3 if release >= 0 else -2, release, 0
    for lev in range(k):
        acc = 0.0
        for j in range(starts[lev], starts[lev + 1]):
            if ucol[j] == -2:
                ec = ecol[j]
                ax = A[j, ec] * x[ec] if ec >= 0 else _dot(A[j], x)
                e = sw[j] * (ax - (b[j] if row_eq[j] else lower[j]))
            elif held[j] == 0:
                continue        # inside its interval: the pass above tested it so
            else:
                uc = ucol[j]
                r = A[j, uc] * x[uc] if uc >= 0 else _dot(A[j], x)
                e = sw[j] * (lower[j] - r if r < lower[j] else
                             (r - upper[j] if r > upper[j] else 0.0))
            acc += e * e
        w2[lev] = acc
        res[lev] = np.sqrt(acc)
        ranks[lev] = eranks[lev]
        margins[lev] = emargins[lev]
        if fixed:           # the held rows, independent (their level met exactly above)
            for j in range(starts[lev], starts[lev + 1]):
                if held[j] != 0:
                    ranks[lev] += 1
    return -1, -1, 0


@njit(cache=True, fastmath=_FAST, inline="always")
def _keep_held(state, eqr, M, held):
    """``params[11]`` after a solve: ``0`` when an inequality row ended it fixed at a
    violation (the next solve runs the active set), else ``1`` when no row was held at a
    bound at any level's end, ``2`` when some were (``held[j]``: the side, ``±1``, it was
    last held on, written by :func:`solve_data` at each level's end, the last one's
    included; ``0`` for the rest). A row held by one level may leave the working set
    below it when the rows that level fixed keep it on its bound: it is still the
    active set's guess."""
    some = False
    for j in range(M):
        st = state[j]
        if st != 0 and st != 1 and st != -1 and not eqr[j]:
            return 0.0
        if held[j] != 0:
            some = True
    return 2.0 if some else 1.0


@njit(cache=True, fastmath=_FAST, inline="always")
def _finish(A, b, lower, upper, sw, row_eq, starts, k, primal_tol, x, w2, res, counts,
            flags, margins, fwork, unresolved):
    """Each level's weighted squared violation at ``x`` and :func:`_summary`."""
    total = 0.0
    for lev in range(k):
        acc = 0.0
        for j in range(starts[lev], starts[lev + 1]):
            ax = sw[j] * _dot(A[j], x)
            if row_eq[j]:
                e = ax - sw[j] * b[j]
            else:
                lo = sw[j] * lower[j]
                up = sw[j] * upper[j]
                e = lo - ax if ax < lo else (ax - up if ax > up else 0.0)
            acc += e * e
        w2[lev] = acc
        res[lev] = np.sqrt(acc)
        total += acc
    return _summary(k, primal_tol, x, res, total, counts, flags, margins, fwork, unresolved)


@njit(cache=True, fastmath=_FAST, inline="always")
def _summary(k, primal_tol, x, res, total, counts, flags, margins, fwork, unresolved):
    """The summary in ``params`` (see :func:`workspace_offsets`) from the levels'
    violations ``res`` (``total``: the sum of their squares); returns
    :func:`solve_data`'s code."""
    xn = np.sqrt(_dot(x, x))
    if not xn <= 1e150:
        # ‖x‖² overflows beyond ~1e154, where an equilibrated level's exact answer
        # may lie (1e-200·I x = 1): the norm in units of max|x|
        top = 0.0
        for c in range(x.shape[0]):
            top = max(top, abs(x[c]))
        if top <= 1e308:
            acc = 0.0
            for c in range(x.shape[0]):
                acc += (x[c] / top) * (x[c] / top)
            xn = top * np.sqrt(acc)
    fwork[5] = xn
    infeasible = 0
    for lev in range(k):
        over = res[lev] > primal_tol * max(1.0, xn)
        counts[3, lev] = over
        infeasible += over
    large = xn > _PRECISION_LIMIT_NORM
    fwork[7] = 1.0 if large else 0.0
    capped = 0.0
    for lev in range(k + 1):
        if flags[lev] == FLAG_ITERATION_CAP:
            capped = 1.0
    fwork[6] = capped if (np.isfinite(xn) and np.isfinite(total)) else -1.0
    ambiguous = 0
    for lev in range(k + 1):
        if flags[lev] == FLAG_OK and _AMBIGUITY < margins[lev] <= NEAR_AMBIGUITY * _AMBIGUITY:
            flags[lev] = FLAG_NEAR_AMBIGUOUS
        # every flag but OK and the cap asks for the certificate (_CERTIFIED_FLAGS)
        if (margins[lev] <= _AMBIGUITY
                or (flags[lev] != FLAG_OK and flags[lev] != FLAG_ITERATION_CAP)):
            ambiguous += 1
    fwork[8] = ambiguous
    fwork[9] = unresolved
    if fwork[6] != 0.0 or ambiguous or unresolved or large:
        return SOLVED_OTHER
    return SOLVED_INFEASIBLE if infeasible else SOLVED_CLEAN


#: floats of the ``params`` header of the float workspace
N_PARAMS = 12
#: float rows of length ``R`` in the float workspace (``fvec``)
N_FVEC = 16


@njit(cache=True, inline="always")
def _outputs(fwork, M, n, k):
    """The float workspace's outputs (:func:`workspace_offsets`): ``x``, ``w2``, ``res``,
    ``margins``, and the offset after them.

    Inlined, never called: it returns views. When :func:`equality_first_data` was
    compiled with numba's runtime and :func:`solve_data` without, numba compiled such a
    call once, with the flags of the caller that came first: compiled without the
    runtime, it returned views without a reference the other caller then released (heap
    corruption, "malloc(): unaligned tcache chunk", on the second equality-first
    answer); both now run without it, and a helper that returns views stays inlined."""
    R = M + n
    o = N_PARAMS + 5 * R * n + 2 * n * n + N_FVEC * R      # after B … fvec
    return (fwork[o:o + n], fwork[o + n:o + n + k], fwork[o + n + k:o + n + 2 * k],
            fwork[o + n + 2 * k:o + n + 3 * k + 1], o + n + 3 * k + 1)


def workspace_offsets(M: int, n: int, k: int) -> dict[str, tuple[int, int]]:
    """``name -> (start, stop)`` of every part of the three flat workspaces of
    :func:`solve_data` (``R = M + n``); ``"size"`` gives each workspace's length.

    float64: ``params`` (rcond, primal_tol, dual_tol, max_iter, use_warm), ``B``,
    ``T``, ``Lw``, ``Bo``, ``flat`` (``R × n`` each), ``V``, ``Vf`` (``n × n``), ``fvec``
    (``16 × R``), ``x`` (``n``), ``w2`` and ``res = √w2`` (``k``), ``margins`` (``k + 1``:
    each level's and the tie-break's rank-decision margin), and the equality-first
    solve's ``eB`` (``M × n``), ``evec`` (``M + 4 k``) and its nested QR's ``espare``
    (:func:`~._extended_jacobian_kernel.spare_size`), then ``Ts`` (``R × n``) and
    ``ts_rows`` (``2 R``): the last step's soft rows for :func:`_eqp_append`;
    the kernel writes
    ``‖x‖`` into ``params[5]``, into ``params[6]`` ``1`` when an iteration cap was
    hit, ``-1`` when ``x`` or a residual is not finite, into ``params[7]`` ``1`` when
    ``‖x‖`` exceeds :data:`~prioik.hierarchy.linalg.PRECISION_LIMIT_NORM` (the caller
    then asks :func:`~prioik.hierarchy.precision_limited_levels`), into ``params[8]`` the
    number of levels (the tie-break included) whose ``margins`` are ambiguous or whose
    path was (:data:`FLAG_AMBIGUOUS_PATH`), into
    ``params[9]`` the number of box rows near a bound that ``x``'s precision (``eps ‖x‖``)
    cannot resolve, into ``params[10]`` ``1`` when the answer is the equality-first
    solve's (``-1`` when that try, holding no row, was refuted: the next
    :func:`solve_data` call starts cold; ``-2`` when it held rows) and ``params[11]``
    ``1`` when the next warm solve should try it (the answer held no inequality row),
    ``2`` when it should try it with the rows the answer held (``held``), ``0`` not;
    int64: ``k``, ``starts`` (``k + 1``), ``ivec`` (``5 × R``), ``perm`` (``n``),
    ``counts`` (``4 × (k + 1)``), ``eint`` (``2 k + 1 + 4 M + 4 n``), ``eispare``
    (``n``); int8: ``row_eq``
    (``M``), ``bvec`` (``2 × R``), ``eqr`` (``R``), ``warm_state`` (``(k + 1) × R``),
    ``warm_valid`` (``k + 1``), ``held`` (``M``: the side, ``±1``, of each row the last
    answer held, ``0`` for the others).
    """
    R = M + n
    out: dict[str, tuple[int, int]] = {}
    for kind, parts in (("f", (("params", N_PARAMS), ("B", R * n), ("T", R * n),
                                ("Lw", R * n), ("Bo", R * n), ("flat", R * n),
                                ("V", n * n), ("Vf", n * n), ("fvec", N_FVEC * R),
                                ("x", n), ("w2", k), ("res", k), ("margins", k + 1),
                                ("eB", M * n), ("evec", M + 4 * k),
                                ("espare", spare_size(M, n)), ("Ts", R * n),
                                ("ts_rows", 2 * R))),
                        ("i", (("k", 1), ("starts", k + 1), ("ivec", 5 * R), ("perm", n),
                               ("counts", 4 * (k + 1)),
                               ("eint", 2 * k + 1 + 4 * M + 4 * n), ("eispare", n))),
                        ("b", (("row_eq", M), ("bvec", 2 * R), ("eqr", R),
                               ("warm_state", (k + 1) * R), ("warm_valid", k + 1),
                               ("held", M)))):
        at = 0
        for name, size in parts:
            out[name] = (at, at + size)
            at += size
        out["size_" + kind] = (0, at)
    return out


@kernel(fastmath=_FAST)
def solve_data(A, b, lower, upper, sw, fwork, iwork, bwork):
    """Solve one stack; see the module docstring.

    One compiled call with few arguments: every workspace, parameter and output lives
    in three flat arrays (float64, int64, int8; parts at :func:`workspace_offsets`)
    and the helpers are inlined (in numba, each array passed to a compiled call costs
    about as much as a short loop: 50 of them cost ~2 µs per call).

    Args:
        A, b, lower, upper, sw: The stack's rows (``M × n``), targets, bounds and ``√w``
            per row (a :class:`~prioik.hierarchy.StackData`'s arrays).
        fwork: float64: ``params`` (``rcond``: relative rank threshold, soft and fixed
            rows ``rcond ‖A_i‖_F``, hard rows relative to the row's norm;
            ``primal_tol``, ``dual_tol``: relative feasibility and multiplier
            tolerances; ``max_iter``: iteration cap of each level; ``use_warm``: start
            every level from ``warm_state`` where ``warm_valid``), workspaces (``B``,
            ``T``: ``(M + n) × n``; the ``n`` extra rows are the minimum-norm level
            ``y[col:] = 0``; ``B`` holds the rows in rotated coordinates, brought up to
            date lazily (``nrot``), ``Bo`` the weighted rows in ``x``, where rows outside
            the working set are checked against ``xc = Q y``), outputs ``x`` (``n``) and
            ``w2`` (``k``: each level's weighted squared violation at ``x``), ``margins``
            (``k + 1``: the margin of the rank decisions of each level's last step and
            of its fixing, the tie-break last; ``≤ hierarchy.AMBIGUITY``: ambiguous).
        iwork: int64: ``k``, the ``k + 1`` level offsets, workspaces, outputs
            ``counts`` (``4 × (k + 1)``, the last column the minimum-norm level:
            iterations, :data:`FLAG_ITERATION_CAP` when the cap was hit or
            :data:`FLAG_AMBIGUOUS_PATH` when a step before the last made an ambiguous
            rank decision, :data:`FLAG_NEAR_RELEASE` when a held soft row ended inside
            its bound within its release tolerance, :data:`FLAG_HELD_OFF_BOUND` when a
            row off its bound was kept held for the levels below, rank fixed,
            ``1`` where the level's violation exceeds ``primal_tol max(1, ‖x‖)``).
        bwork: int8: the rows' equality flags, workspaces, ``warm_state`` and
            ``warm_valid`` (``(k + 1) × (M + n)`` working sets at each level's end, read
            when ``use_warm``, always written).

    Returns:
        :data:`NOT_SOLVED` when a value is not valid (a non-finite entry of ``A``, of
        an equality target or of ``√w``, ``√w ≤ 0``, a NaN bound, ``lower = +inf``,
        ``upper = −inf`` or ``lower > upper``; the caller names it) or a level is of
        extreme scale (:func:`_level_extreme`; the caller equilibrates it); else
        :data:`SOLVED_CLEAN` (finite, every level settled, every rank decision clear,
        every box row resolved, every level's violation within ``primal_tol``),
        :data:`SOLVED_INFEASIBLE` (the same with some levels' violation above it) or
        :data:`SOLVED_OTHER` (the caller reads the summary in ``params``).
    """
    M, n = A.shape
    k = iwork[0]
    R = M + n
    Rn = R * n
    o = N_PARAMS
    B = fwork[o:o + Rn].reshape((R, n))
    o += Rn
    T = fwork[o:o + Rn].reshape((R, n))
    o += Rn
    Lw = fwork[o:o + Rn].reshape((R, n))
    o += Rn
    Bo = fwork[o:o + Rn].reshape((R, n))
    o += Rn
    flat = fwork[o:o + Rn]
    o += Rn
    V = fwork[o:o + n * n].reshape((n, n))
    o += n * n
    Vf = fwork[o:o + n * n].reshape((n, n))
    o += n * n
    fvec = fwork[o:o + N_FVEC * R].reshape((N_FVEC, R))
    x, w2, res, margins, o = _outputs(fwork, M, n, k)
    starts = iwork[1:k + 2]
    o = k + 2
    ivec = iwork[o:o + 5 * R].reshape((5, R))
    o += 5 * R
    perm = iwork[o:o + n]
    o += n
    counts = iwork[o:o + 4 * (k + 1)].reshape((4, k + 1))
    row_eq = bwork[:M]
    o = M
    bvec = bwork[o:o + 2 * R].reshape((2, R))
    o += 2 * R
    eqr = bwork[o:o + R]
    o += R
    warm_state = bwork[o:o + (k + 1) * R].reshape((k + 1, R))
    o += (k + 1) * R
    warm_valid = bwork[o:o + k + 1]
    o += k + 1
    held = bwork[o:o + M]
    rcond = fwork[0]
    primal_tol = fwork[1]
    dual_tol = fwork[2]
    max_iter = int(fwork[3])
    # a refuted equality-first try (params[10] = -1) refuted the kept working sets too:
    # they held no inequality row, which is what it tried; this solve starts cold
    use_warm = fwork[4] != 0.0 and fwork[10] != -1.0
    blo = fvec[0]
    bup = fvec[1]
    rnorm = fvec[2]
    state = bvec[0]
    saved = bvec[1]
    rhs = fvec[3]
    norms = fvec[4]
    rows = ivec[0]
    tgt = fvec[5]
    beta = fvec[6, :n]
    vpos = ivec[1, :n]
    betaf = fvec[7, :n]
    posf = ivec[2, :n]
    y = fvec[8, :n]
    p = fvec[9, :n]
    g = fvec[10, :n]
    nu = fvec[11]
    nrot = ivec[3]
    ucol = ivec[4]
    cand = ivec[1]          # (vpos's row: _step's scratch, rewritten by every step)
    tail_at = fwork.shape[0] - Rn - 2 * R           # Ts, ts_rows: the workspace's end
    Ts = fwork[tail_at:tail_at + Rn].reshape((R, n))
    ts_rows = fwork[tail_at + Rn:]
    px = fvec[12, :n]
    xc = fvec[13, :n]
    xs = fvec[14, :n]
    tq = fvec[15]
    iters = counts[0]
    flags = counts[1]
    ranks = counts[2]
    if not _load_rows(A, b, lower, upper, sw, row_eq, B, Bo, blo, bup, rnorm, eqr, ucol,
                      nrot, state):
        return NOT_SOLVED
    if _extreme_scale_rows(A, rnorm, sw, starts, k):
        return NOT_SOLVED           # the caller solves the equilibrated stack
    fwork[10] = 0.0
    for j in range(M):
        held[j] = 0
    for c in range(n):
        y[c] = 0.0
        xc[c] = 0.0
    # The arguments of the _step calls are typed as they settle (int64, bool), never as
    # literals: numba compiles a called function once per argument type it meets, and
    # a loop-carried `col = 0` is Literal[int](0) until type inference reaches the
    # loop's back edge, a `True` is Literal[bool](True). _step, most of this kernel's
    # code, had been compiled four times (~100 of the 143 s a fresh install's first
    # solve took).
    col = np.int64(0)
    nf = np.int64(0)
    yes = col == 0
    no = not yes
    for lev in range(k + 1):
        iters[lev] = 0
        flags[lev] = FLAG_OK
        ranks[lev] = 0
        margins[lev] = np.inf
        if col >= n:
            continue
        if lev < k:
            s0 = starts[lev]
            s1 = starts[lev + 1]
            hard_end = s0
        else:
            alive = False
            for j in range(M):
                if state[j] != 2 and not eqr[j] and (np.isfinite(blo[j]) or np.isfinite(bup[j])):
                    alive = True
                    break
            if not alive:
                for c in range(col, n):
                    y[c] = 0.0
                break
            s0 = M + col
            s1 = M + n
            hard_end = M
            for j in range(s0, s1):
                for c in range(n):
                    B[j, c] = 0.0
                B[j, j - M] = 1.0
                nrot[j] = nf
        if s1 == s0:
            continue
        d = n - col
        acc = 0.0
        for j in range(s0, s1):
            acc += rnorm[j] * rnorm[j]
        scale = np.sqrt(acc)
        soft_tol = rcond * scale
        ynorm = np.sqrt(_dot(y, y))
        for j in range(s0, s1):
            if eqr[j]:
                state[j] = 3
            else:
                r = _odot(Bo, ucol, j, xc)
                sz = _size(Bo, ucol, j, rnorm[j], ynorm, xc)
                state[j] = _violated_side(r, blo[j], bup[j], _tol(primal_tol, sz, blo[j]),
                                          _tol(primal_tol, sz, bup[j]))
        # ---- warm start: jump to the step of last time's working set if it is feasible
        have_step = False
        refuted = False         # a warm step tried and undone: the level starts cold
        nh = np.int64(0)
        nw = np.int64(0)
        hr = 0
        rs = 0
        full = False
        step_margin = np.inf
        path_margin = np.inf    # the least margin of the steps the level took
        gn_step = -1.0
        if use_warm and warm_valid[lev]:
            for j in range(s1):
                saved[j] = state[j]
            for j in range(s1):
                if state[j] == 2 or eqr[j]:
                    continue
                ws = warm_state[lev, j]
                if ws == -1 and np.isfinite(blo[j]):
                    state[j] = -1
                elif ws == 1 and np.isfinite(bup[j]):
                    state[j] = 1
                elif j < hard_end:
                    state[j] = 0
            nh, nw = _gather(state, hard_end, s0, s1, blo, bup, rows, tgt, B, nrot, nf,
                                 Vf, betaf, posf)
            hr, rs, nref, full, step_margin, gn_step = _step(
                B, y, col, rows, nh, nw, fvec, rcond, soft_tol, T, V, beta, vpos, Lw, p,
                yes, flat, perm, nrot, nf, Vf, betaf, posf, Bo, xc, ucol, yes, Ts, ts_rows)
            iters[lev] += 1
            for i in range(hr, nh):
                state[rows[i]] = 0
            for c in range(d):
                g[c] = y[col + c]
                y[col + c] += p[c]
            _lift(p, col, px, nf, Vf, betaf, posf)
            for c in range(n):
                xs[c] = xc[c]
                xc[c] += px[c]
            ynorm = np.sqrt(_dot(y, y))
            feasible = True
            for j in range(hard_end):
                if state[j] != 0 or eqr[j]:
                    continue
                r = _odot(Bo, ucol, j, xc)
                sz = _size(Bo, ucol, j, rnorm[j], ynorm, xc)
                if _violated_side(r, blo[j], bup[j], _tol(primal_tol, sz, blo[j]),
                                  _tol(primal_tol, sz, bup[j])) != 0:
                    feasible = False
                    break
            if feasible:
                # the point is the step's end for this working set: go straight to the
                # optimality test unless rows had to leave or join it
                path_margin = step_margin
                have_step = hr == nh
                for j in range(s0, s1):
                    if state[j] == 0:
                        r = _odot(Bo, ucol, j, xc)
                        sz = _size(Bo, ucol, j, rnorm[j], ynorm, xc)
                        state[j] = _violated_side(r, blo[j], bup[j],
                                                  _tol(primal_tol, sz, blo[j]),
                                                  _tol(primal_tol, sz, bup[j]))
                        if state[j] != 0:
                            have_step = False
            else:
                refuted = True
                for c in range(d):
                    y[col + c] = g[c]
                for c in range(n):
                    xc[c] = xs[c]
                for j in range(s1):
                    state[j] = saved[j]
        # ---- primal active-set iterations
        bland = False
        joined = -1             # a hard row that cut the last step and joins its factorization
        proposed = False        # the degenerate point's working set tried (once a level)
        stall = 0               # iterations since a step last moved
        stalled = False
        settled = False
        near_release = False
        while True:
            if have_step:
                have_step = False
            else:
                if iters[lev] >= max_iter:
                    flags[lev] = FLAG_ITERATION_CAP
                    break
                iters[lev] += 1
                appended = False
                if joined >= 0:
                    # the last step's factorization with the row that cut it added
                    _bring(B, joined, nrot, nf, Vf, betaf, posf)
                    ha, ra, na, ma = _eqp_append(
                        B, y, col, rows, nh, nw, tgt, rnorm, rcond, soft_tol, T, rhs, norms,
                        V, beta, vpos, Lw, p, flat, tq, Ts, ts_rows, joined,
                        blo[joined] if state[joined] == -1 else bup[joined])
                    joined = -1
                    if ha >= 0:
                        nh += 1
                        hr, rs, nref, full, step_margin, gn_step = ha, ra, na, no, ma, -1.0
                        appended = True
                if not appended:
                    nh, nw = _gather(state, hard_end, s0, s1, blo, bup, rows, tgt, B, nrot,
                                     nf, Vf, betaf, posf)
                    hr, rs, nref, full, step_margin, gn_step = _step(
                        B, y, col, rows, nh, nw, fvec, rcond, soft_tol, T, V, beta, vpos, Lw,
                        p, no, flat, perm, nrot, nf, Vf, betaf, posf, Bo, xc, ucol,
                        iters[lev] == 1 or (refuted and iters[lev] == 2), Ts, ts_rows)
                path_margin = min(path_margin, step_margin)
                for i in range(hr, nh):
                    state[rows[i]] = 0          # dependent on the kept hard rows
                pn = np.sqrt(_dot(p[:d], p[:d]))
                if pn <= _ZERO_STEP * np.sqrt(_dot(y, y)):
                    for c in range(d):      # rounding noise: no move (and nothing blocks)
                        p[c] = 0.0
                    pn = 0.0
                alpha = 1.0
                blk = -1
                block_eps = max(_BLOCK_EPS, rcond)
                bside = 0
                if pn > 0.0:
                    _lift(p, col, px, nf, Vf, betaf, posf)
                    for j in range(s1):
                        if state[j] != 0 or eqr[j] or (j >= hard_end and j < s0):
                            continue
                        cp = _odot(Bo, ucol, j, px)
                        thr = block_eps * rnorm[j] * pn
                        if cp < -thr and np.isfinite(blo[j]):
                            a = (blo[j] - _odot(Bo, ucol, j, xc)) / cp
                            side = -1
                        elif cp > thr and np.isfinite(bup[j]):
                            a = (bup[j] - _odot(Bo, ucol, j, xc)) / cp
                            side = 1
                        else:
                            continue
                        if a < 0.0:
                            a = 0.0
                        if a < alpha:
                            alpha = a
                            blk = j
                            bside = side
                if pn > 0.0 and alpha > _DEGENERATE:
                    stall = 0
                    bland = False
                else:
                    stall += 1
                if pn > 0.0:
                    for c in range(d):
                        y[col + c] += alpha * p[c]
                    for c in range(n):
                        xc[c] += alpha * px[c]
                if blk >= 0:
                    state[blk] = bside
                    # Bland's rule from a step of length 0 until one moves
                    bland = bland or alpha <= _DEGENERATE
                    if blk < hard_end and not full and gn_step < 0.0 and hr == nh:
                        joined = blk        # the next step adds it to this factorization
                    continue
            ynorm = np.sqrt(_dot(y, y))
            # soft rows on the wrong side of their bound: release or switch sides; a
            # held row left inside its bound beyond x's precision but within the
            # release tolerance is noted (FLAG_NEAR_RELEASE if the level settles here)
            changed = False
            near_release = False
            for j in range(s0, s1):
                st = state[j]
                if st == -1 or st == 1:
                    r = _odot(Bo, ucol, j, xc)
                    # released beyond rounding, not beyond primal_tol: a row of the
                    # level 1e-5 the size of the others moves the optimum by what the
                    # large rows' slack at primal_tol would hide (fuzzing: 1.9x worse)
                    sz = _size(Bo, ucol, j, rnorm[j], ynorm, xc)
                    tl = _tol(primal_tol * _RELEASE, sz, blo[j])
                    tu = _tol(primal_tol * _RELEASE, sz, bup[j])
                    if st == -1 and r > blo[j] + tl:
                        state[j] = 1 if r > bup[j] + tu else 0
                        changed = True
                    elif st == 1 and r < bup[j] - tu:
                        state[j] = -1 if r < blo[j] - tl else 0
                        changed = True
                    elif ((r - blo[j] if st == -1 else bup[j] - r)
                          > X_PRECISION * ynorm * rnorm[j]):
                        near_release = True
            if changed:
                continue
            if hr == 0:
                settled = True
                break
            if gn_step >= 0.0:      # the unit-row step's Schur complement gave them
                gn = gn_step
            else:
                gn = _hard_multipliers(B, y, col, rows, nh, hr, nw, tgt, T, V, beta, vpos,
                                       g, nu)
            tn = 0.0
            for i in range(nh, nh + nw):
                tn += tgt[i] * tgt[i]
            gfull = max(gn, scale * (scale * ynorm + np.sqrt(tn)))
            gscale = dual_tol * gfull
            drop = -1
            worst = 0.0
            for i in range(hr):
                j = rows[i]
                wrong = (-nu[i] if state[j] == -1 else nu[i]) * rnorm[j]
                if wrong > gscale:
                    drop, worst = _pick_release(bland, j, wrong, drop, worst)
            if drop < 0 and gn_step < 0.0 and rs < nw:
                # gscale is a gradient: at the level's full gain ‖A_i‖_F it stands for
                # a change of the level's values of gscale / ‖A_i‖_F, but releasing a
                # row frees a direction of gain γ, where the same multiplier changes
                # them by ν / γ (the certificate's reading): on a level whose rows differ
                # widely in scale, multipliers under gscale can hold rows whose release
                # moves the level's values far beyond the tolerance. Directions the
                # level cannot move (γ at the rank rule) keep the test above, as the
                # certificate reads them at ‖A_i‖_F
                floor = _DUAL_FLOOR * gfull
                worst = 0.0
                for i in range(hr):
                    j = rows[i]
                    wrong = (-nu[i] if state[j] == -1 else nu[i]) * rnorm[j]
                    if not wrong > floor:
                        continue
                    un, gain = _freed_gain(T, nh, hr, nw, rs, i, px, rhs, p, flat, tq)
                    if not gain > soft_tol:
                        continue
                    move = abs(nu[i]) / (un * gain)
                    if move * scale > gscale:
                        drop, worst = _pick_release(bland, j, move, drop, worst)
            if drop < 0:
                settled = True
                break
            if stall > _stall_limit(s1):
                # a cycle of rounding: every working set of it shares this point
                settled = True
                stalled = True
                break
            if not proposed:
                # a release at a degenerate point (hard rows at their bounds outside the
                # working set): the working set its multipliers need, in one small
                # non-negative least squares instead of one exchange per iteration
                proposed = True
                m_at, extra = _rows_at_bounds(state, eqr, hard_end, Bo, ucol, xc, blo, bup,
                                              rnorm, ynorm, primal_tol, B, nrot, nf, Vf,
                                              betaf, posf, col, Lw, cand, tq, rhs)
                if extra > 0:
                    if lev < k:
                        _soft_gradient_x(Bo, ucol, xc, rows, nh, nw, tgt, col, nf, Vf,
                                         betaf, posf, px, g)
                    else:       # the tie-break's rows are made rotated (B), not in Bo
                        _soft_gradient(B, y, col, rows, nh, nw, tgt, g)
                    if _nnls_working_set(Lw, m_at, d, g, cand, rhs, rnorm, rcond, gscale, T,
                                         V, beta, nu, px, p, perm):
                        moved_set = False
                        for i in range(m_at):
                            j = cand[i]
                            want = (-1 if tq[i] < 0.0 else 1) if rhs[i] != 0.0 else 0
                            if state[j] != want:
                                state[j] = want
                                moved_set = True
                        if moved_set:
                            continue
            state[drop] = 0
        # ---- level done: remember its working set, fix its non-zero slacks. The margin:
        # the last step's rank decisions (they made the level's point) and the fixing's.
        # An earlier step's ambiguous decision may have led the level to a working set
        # whose clear last step is not its optimum (a pair of rows 2e-9 from parallel:
        # taken as independent, a huge step; an answer 2.8x worse than the optimum):
        # flagged, the caller certifies the answer
        margins[lev] = step_margin
        if (path_margin <= _AMBIGUITY and step_margin > _AMBIGUITY
                and flags[lev] == FLAG_OK):
            flags[lev] = FLAG_AMBIGUOUS_PATH
        if settled and near_release and flags[lev] == FLAG_OK:
            flags[lev] = FLAG_NEAR_RELEASE
        if stalled and flags[lev] == FLAG_OK:
            flags[lev] = FLAG_STALLED
        for j in range(s1):
            st = state[j]
            warm_state[lev, j] = st if (st == -1 or st == 1) else 0
            if (st == -1 or st == 1) and j < M:
                held[j] = st
        warm_valid[lev] = 1
        if lev == k:
            break
        ynorm = np.sqrt(_dot(y, y))
        # a held row is off its bound (violated: fixed at its violation for every level
        # below) beyond the primal tolerance and beyond the dual one, its violation
        # being its multiplier: a row 1e-4 the size of the level's others is off by the
        # level's rounding (~1e-12) at an optimum where it meets its bound, and fixing it
        # took a direction the lower levels need (fuzzing: a level 4x worse, 'optimal')
        dscale = _dual_scale(dual_tol, scale, ynorm, tgt, nh, nw)
        nfix = 0
        held_off = no
        for j in range(s0, s1):
            st = state[j]
            fix = eqr[j]
            if st == -1 or st == 1:
                tb = blo[j] if st == -1 else bup[j]
                off = abs(_odot(Bo, ucol, j, xc) - tb)
                sz = _size(Bo, ucol, j, rnorm[j], ynorm, xc)
                beyond = off > _tol(primal_tol, sz, tb)
                fix = beyond and off * rnorm[j] > dscale
                if beyond and not fix:
                    held_off = yes
            if fix:
                rows[nfix] = j
                nfix += 1
                state[j] = 5            # being fixed: rotated until its pivot is taken
        if held_off and flags[lev] == FLAG_OK:
            flags[lev] = FLAG_HELD_OFF_BOUND
        rf = 0
        if settled and full and nfix == nw:
            # the level has full column rank on the free coordinates (the step's
            # column-pivoted QR): it fixes them all, y[col:] is its answer
            ranks[lev] = d
            col = n
            for i in range(nfix):
                state[rows[i]] = 2
            continue
        if settled and hr == 0 and nfix == nw:
            # the last step's factorization is that of exactly these rows (no hard row
            # was held, every held row is fixed): its reflectors are the fixing ones
            nfix = 0
            for t in range(rs):
                q = col + vpos[t]
                vf = Vf[nf, q:]
                vt = V[t, vpos[t]:d]
                for c in range(n - q):
                    vf[c] = vt[c]
                bt = beta[t]
                betaf[nf] = bt
                posf[nf] = q
                yq = y[q:]
                f = bt * _dot(yq, vf)
                for c in range(n - q):
                    yq[c] -= f * vf[c]
                nf += 1
            col += rs
            rf = rs
            for j in range(s0, s1):
                if state[j] == 5:
                    state[j] = 2
        for i in range(nfix):
            j = rows[i]
            _bring(B, j, nrot, nf, Vf, betaf, posf)
            norms[i] = _dot(B[j, col:], B[j, col:])
        while rf < nfix and col < n:
            piv = rf
            best = norms[rf]
            for i in range(rf + 1, nfix):
                if norms[i] > best:
                    best = norms[i]
                    piv = i
            jp = rows[piv]
            tail = B[jp, col:]
            exact = _dot(tail, tail)
            if not (np.sqrt(exact) > soft_tol) and soft_tol > 0.0:
                for i in range(rf, nfix):       # downdated norms: as in _eqp
                    norms[i] = _dot(B[rows[i], col:], B[rows[i], col:])
                    if norms[i] > exact:
                        exact = norms[i]
                        piv = i
                jp = rows[piv]
                tail = B[jp, col:]
            if not (np.sqrt(exact) > soft_tol) or soft_tol <= 0.0:
                if exact > 0.0 and soft_tol > 0.0:
                    margins[lev] = min(margins[lev], soft_tol / np.sqrt(exact))
                break
            margins[lev] = min(margins[lev], np.sqrt(exact) / soft_tol)
            if piv != rf:
                _swap(rows, rf, piv)
                _swap(norms, rf, piv)
            norm = np.sqrt(exact)
            alpha = -norm if tail[0] >= 0.0 else norm
            vf = Vf[nf, col:]
            vf[0] = tail[0] - alpha
            for c in range(1, n - col):
                vf[c] = tail[c]
            vtv = 2.0 * (exact - alpha * tail[0])
            bt = 2.0 / vtv if vtv > 0.0 else 0.0
            betaf[nf] = bt
            posf[nf] = col
            tail[0] = alpha
            for c in range(1, n - col):
                tail[c] = 0.0
            for i in range(rf + 1, nfix):   # the other rows: lazily, when needed
                other = B[rows[i], col:]
                f = bt * _dot(other, vf)
                if f != 0.0:
                    for c in range(n - col):
                        other[c] -= f * vf[c]
                nrot[rows[i]] = nf + 1
            yq = y[col:]
            f = bt * _dot(yq, vf)
            for c in range(n - col):
                yq[c] -= f * vf[c]
            for i in range(rf + 1, nfix):
                norms[i] -= B[rows[i], col] * B[rows[i], col]
            state[jp] = 2
            nf += 1
            col += 1
            rf += 1
        ranks[lev] = rf
        for i in range(nfix):
            state[rows[i]] = 2
    # x = H_1 … H_F y
    for c in range(n):
        x[c] = y[c]
    _apply_q(x, nf, Vf, betaf, posf)
    # box rows, one pass. x's coordinates are known to about X_PRECISION ‖x‖ (the
    # reflectors round every coordinate to eps ‖x‖: not small for a bounded joint when
    # another level drives ‖x‖ to 1e10, a held row then reads as off by 1e-5). A held
    # row off its bound by no more than that is put on it exactly (a row of the last
    # level off by its least-squares slack keeps it); a row near a bound whose primal
    # tolerance is finer than that precision is counted as unresolved (whether it is
    # held is then rounding)
    xn = np.sqrt(_dot(x, x))
    unresolved = 0
    for j in range(M):
        c = ucol[j]
        if c < 0:
            continue
        a = Bo[j, c]
        precision = X_PRECISION * xn * abs(a)
        if state[j] == 1 or state[j] == -1:
            bound = bup[j] if state[j] == 1 else blo[j]
            if abs(a * x[c] - bound) <= precision:
                x[c] = bound / a
        if _box_row_unresolved(a, x[c], a * x[c], blo[j], bup[j], xn, primal_tol):
            unresolved += 1
    fwork[11] = _keep_held(state, eqr, M, held)
    return _finish(A, b, lower, upper, sw, row_eq, starts, k, primal_tol, x, w2, res,
                   counts, flags, margins, fwork, unresolved)



#: what :func:`equality_first_data` returns when its answer is not the stack's (the
#: caller then runs :func:`solve_data`)
NOT_TRIED = -1
#: :func:`_equality_first`'s verdict when its held box rows cannot be taken as fixed
#: coordinates (a level above the lowest held one is not met exactly on the free ones):
#: the same guess is then tried with them held as equalities
FIXED_REFUSED = -4
#: the guesses :func:`equality_first_data` tries: the kept held rows, then each
#: refutation's next (hold the row that first leaves its interval on the way from the
#: last feasible guess, else the most violated; or release the held row of the most
#: wrong-signed multiplier), one nested QR each (two for a guess whose box rows
#: :data:`FIXED_REFUSED` refused as fixed coordinates). Of the 600 steps of each G1
#: fencing run with limits as bounds (warm, in order), six guesses leave 1-5 to the
#: active set; three guesses of the most violated row left 1-22
GUESSES = 6


@njit(cache=True, fastmath=_FAST)
def _first_blocking(A, lower, upper, iseq, held, x, xref, row, side):
    """The inequality row, not held, that first leaves its interval on the segment from
    ``xref`` (a refuted guess's answer with every row inside its interval) to ``x`` (a
    later guess's, some row outside): the primal active-set method's ratio test, the row
    a guess should hold next (holding the most violated one instead can skip the row
    that blocks first and wander: a G1 step released one limit, which then overshot
    its other bound). ``xref`` moves to the blocking point. Returns the row and the side
    it leaves by (``-1`` lower, ``1`` upper); the ``row, side`` given when no row is
    outside its interval at ``x``."""
    M = A.shape[0]
    best = 2.0
    for j in range(M):
        if iseq[j] or held[j] != 0:
            continue
        r1 = _dot(A[j], x)
        if r1 < lower[j]:
            bound = lower[j]
            s = -1
        elif r1 > upper[j]:
            bound = upper[j]
            s = 1
        else:
            continue
        r0 = _dot(A[j], xref)
        t = (bound - r0) / (r1 - r0) if r1 != r0 else 0.0
        t = min(max(t, 0.0), 1.0)
        if t < best:
            best = t
            row = j
            side = s
    if best <= 1.0:
        for c in range(x.shape[0]):
            xref[c] += best * (x[c] - xref[c])
    return row, side


@kernel(fastmath=_FAST)
def equality_first_data(A, b, lower, upper, sw, fwork, iwork, bwork):
    """The warm start's first try, with :func:`solve_data`'s arguments: when the last
    answer fixed no inequality row at a violation (``params[11]``: ``1``, and it held
    none; ``2``, it held the rows ``held``), the stack's equality rows and those held
    rows by the extended Jacobian's nested QR (:func:`_equality_first`); if that answer
    is proved the stack's it is written as :func:`solve_data` writes its own (zero
    iterations, ``params[10] = 1``) and its code returned. A refuted try that names a
    next guess (:func:`_equality_first`) is followed by that guess, up to
    :data:`GUESSES` tries, the last refuted one returning :data:`NOT_TRIED` (also when a
    value is not valid: :func:`solve_data` names it). After it ``params[10] = -1`` when
    no row was held, and the :func:`solve_data` call that follows starts cold (the kept
    working sets held no inequality row: the guess the try refuted); ``-2`` when rows
    were, and it starts from the kept working sets.

    Compiled without numba's runtime (:func:`~prioik._jit.kernel`), as
    :func:`solve_data`: the nested QR it calls allocates nothing.
    """
    M, n = A.shape
    k = iwork[0]
    fwork[10] = 0.0
    if fwork[4] == 0.0 or fwork[11] == 0.0:
        return NOT_TRIED
    R = M + n
    x, w2, res, margins, o = _outputs(fwork, M, n, k)
    eflat = fwork[o:o + M * n]
    o += M * n
    evec = fwork[o:o + M + 4 * k]
    spare = fwork[o + M + 4 * k:]
    starts = iwork[1:k + 2]
    o = k + 2 + 5 * R + n                                   # after ivec and perm
    counts = iwork[o:o + 4 * (k + 1)].reshape((4, k + 1))
    o += 4 * (k + 1)
    eint = iwork[o:o + 2 * k + 1 + 4 * M + 4 * n]
    ispare = iwork[o + 2 * k + 1 + 4 * M + 4 * n:]
    primal_tol = fwork[1]
    Rn = R * n
    o = N_PARAMS + 2 * Rn                                   # Lw (see solve_data)
    Lflat = fwork[o:o + Rn]
    o = N_PARAMS + 5 * Rn
    Vflat = fwork[o:o + n * n]
    o += 2 * n * n
    fs = fwork[o:o + 4 * R].reshape((4, R))                 # fvec's first rows
    pos = iwork[k + 2:k + 2 + n]                            # ivec's first row
    o = M + 3 * R + (k + 1) * R + k + 1                    # held (workspace_offsets)
    held = bwork[o:o + M]
    # the last feasible guess's answer (on the segment to the next, the first row to
    # leave its interval is the one to hold), in solve_data's scratch (fvec's xs)
    o = N_PARAMS + 5 * Rn + 2 * n * n + 14 * R
    xref = fwork[o:o + n]
    have_ref = False
    iseq = bwork[M + 2 * R:M + 3 * R]
    kept = fwork[11] == 2.0         # the kept working sets held rows
    guessed = False
    allow_fixed = True
    attempt = 0
    while attempt < GUESSES:
        verdict, row, side = _equality_first(
            A, b, lower, upper, sw, bwork[:M], starts, k, fwork[0], primal_tol, fwork[2],
            eflat, evec, eint, x, counts[2], margins, w2, res, Vflat, Lflat, fs, pos,
            iseq, held, spare, ispare, allow_fixed)
        if verdict == FIXED_REFUSED:    # the same guess, its rows held as equalities
            allow_fixed = False
            continue
        attempt += 1
        if verdict == -1:
            break
        if verdict == -2 or attempt == GUESSES:
            # refuted: with no row held, solve_data then starts cold
            fwork[10] = -2.0 if kept else -1.0
            return NOT_TRIED
        if side == 0:               # a release: every row was inside its interval
            for c in range(n):
                xref[c] = x[c]
            have_ref = True
        elif have_ref:
            row, side = _first_blocking(A, lower, upper, iseq, held, x, xref, row, side)
        held[row] = side            # the next guess: hold the row, or release it
        guessed = True
    if guessed:
        fwork[11] = 1.0
        for j in range(M):
            if held[j] != 0:
                fwork[11] = 2.0
                break
    total = 0.0
    for lev in range(k):
        total += w2[lev]
        counts[0, lev] = 0
        counts[1, lev] = FLAG_OK
    counts[0, k] = 0
    counts[1, k] = FLAG_OK
    counts[2, k] = 0
    margins[k] = np.inf
    fwork[10] = 1.0
    return _summary(k, primal_tol, x, res, total, counts, counts[1], margins, fwork, 0)
