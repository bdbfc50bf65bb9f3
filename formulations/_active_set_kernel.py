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

from ._extended_jacobian_kernel import _dot, _small_lstsq, _swap

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

#: values of ``flags``
FLAG_OK = 0
FLAG_ITERATION_CAP = 1


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


@njit(cache=True, fastmath=_FAST)
def _eqp(B, y, col, rows, nh, nw, tgt, rnorm, rcond, soft_tol, T, rhs, norms, V, beta,
         vpos, Lw, p, reach):
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
        ``(hr, rs, nref)``: hard rows kept (``rows[hr:nh]`` depend on them and are
        not enforced), rank of the soft rows on the rest, reflectors used (the
        first ``hr`` factor the hard rows; :func:`_hard_multipliers` uses them).
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
        if not (np.sqrt(exact) > soft_tol) or soft_tol <= 0.0:
            break
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
            _small_lstsq(Lw, rhs[nh:], nw, rs, 0.0, p, hr)
    # p = H_1 … H_R [u; 0]
    for t in range(nref - 1, -1, -1):
        q = vpos[t]
        v = V[t, q:d]
        pq = p[q:d]
        f = beta[t] * _dot(v, pq)
        if f != 0.0:
            for c in range(d - q):
                pq[c] -= f * v[c]
    return hr, rs, nref


@njit(cache=True, fastmath=_FAST)
def _hard_multipliers(B, y, col, rows, nh, hr, nw, tgt, T, V, beta, vpos, g, nu):
    """Multipliers ``ν`` of the kept hard rows at the step's end point.

    ``g = Σ_soft (B_j y − tgt_j) B_j[col:]`` is the gradient of the level objective on
    the free coordinates; ``C_Hᵀ ν = g`` is solved through the LQ of the hard rows
    (``Qᵀ g`` by their reflectors, then ``Lᵀ ν = (Qᵀ g)[:hr]``). Returns ``‖g‖``.
    """
    n = B.shape[1]
    d = n - col
    for c in range(d):
        g[c] = 0.0
    for i in range(nh, nh + nw):
        j = rows[i]
        res = _dot(B[j], y) - tgt[i]
        if res != 0.0:
            Bj = B[j, col:]
            for c in range(d):
                g[c] += res * Bj[c]
    gn = np.sqrt(_dot(g[:d], g[:d]))
    for t in range(hr):
        q = vpos[t]
        v = V[t, q:d]
        gq = g[q:d]
        f = beta[t] * _dot(v, gq)
        if f != 0.0:
            for c in range(d - q):
                gq[c] -= f * v[c]
    for i in range(hr - 1, -1, -1):
        acc = g[i]
        for c in range(i + 1, hr):
            acc -= T[c, i] * nu[c]
        nu[i] = acc / T[i, i]
    return gn


@njit(cache=True, inline="always")
def _tol(primal_tol, rnorm_j, ynorm, bound):
    """Feasibility tolerance of one row: relative to ``‖a_j‖ ‖y‖ + |bound|``."""
    return primal_tol * (rnorm_j * ynorm + abs(bound))


@njit(cache=True, fastmath=_FAST)
def _gather(state, hard_end, s0, s1, blo, bup, rows, tgt):
    """Working rows: hard ones (``j < hard_end``, state ±1) first, then the level's."""
    nh = 0
    for j in range(hard_end):
        st = state[j]
        if st == -1 or st == 1:
            rows[nh] = j
            tgt[nh] = blo[j] if st == -1 else bup[j]
            nh += 1
    nw = 0
    for j in range(s0, s1):
        st = state[j]
        if st != 0:
            rows[nh + nw] = j
            tgt[nh + nw] = bup[j] if st == 1 else blo[j]
            nw += 1
    return nh, nw


@njit(cache=True, fastmath=_FAST)
def _violated_side(r, lo, up, tol_lo, tol_up):
    if r < lo - tol_lo:
        return -1
    if r > up + tol_up:
        return 1
    return 0


@njit(cache=True, fastmath=_FAST)
def solve_kernel(A, b, lower, upper, sw, row_eq, starts, rcond, primal_tol, dual_tol,
                 max_iter, use_warm, warm_state, warm_valid,
                 B, blo, bup, rnorm, eqr, state, saved, T, rhs, norms, rows, tgt,
                 V, beta, vpos, Vf, betaf, posf, y, p, g, nu, Lw,
                 x, iters, flags, ranks, w2):
    """Solve one stack; see the module docstring.

    Args:
        A, b, lower, upper, sw, row_eq, starts: The stack's rows (``M × n``), targets,
            bounds, ``√w`` per row, equality flags and ``k + 1`` level offsets.
        rcond: Relative rank threshold (soft rows: ``rcond ‖A_i‖_F``; hard and fixed
            rows: as the extended Jacobian, and relative to the row's norm).
        primal_tol, dual_tol: Relative feasibility and multiplier tolerances.
        max_iter: Iteration cap of each level.
        use_warm: Start every level from ``warm_state`` where ``warm_valid``.
        warm_state, warm_valid: ``(k + 1) × (M + n)`` working sets at each level's end
            (read when ``use_warm``, always written).
        B … Lw: Workspaces (``B``, ``T``: ``(M + n) × n``; the ``n`` extra rows are the
            minimum-norm level ``y[col:] = 0``).
        x: Output ``n``.
        iters, flags, ranks: Outputs per level (``k + 1``, the last is the minimum-norm
            level): iterations, :data:`FLAG_ITERATION_CAP` when the cap was hit, rank
            fixed.
        w2: Output ``k``: each level's weighted squared violation at ``x``.

    Returns:
        ``False`` (nothing solved) when a value is not valid: a non-finite entry of
        ``A``, of an equality target or of ``√w``, ``√w ≤ 0``, a NaN bound,
        ``lower = +inf``, ``upper = −inf`` or ``lower > upper``; the caller names it.
    """
    M, n = A.shape
    k = starts.shape[0] - 1
    for j in range(M):
        s = sw[j]
        if not (np.isfinite(s) and s > 0.0):
            return False
        for c in range(n):
            B[j, c] = s * A[j, c]
        if row_eq[j]:
            if not np.isfinite(b[j]):
                return False
            blo[j] = s * b[j]
            bup[j] = blo[j]
            eqr[j] = True
        else:
            lo = lower[j]
            up = upper[j]
            if np.isnan(lo) or np.isnan(up) or lo == np.inf or up == -np.inf or lo > up:
                return False
            blo[j] = s * lo
            bup[j] = s * up
            eqr[j] = lo == up
        rnorm[j] = np.sqrt(_dot(B[j], B[j]))
        if not np.isfinite(rnorm[j]):
            return False
        state[j] = 0
    for j in range(M, M + n):
        blo[j] = 0.0
        bup[j] = 0.0
        eqr[j] = True
        rnorm[j] = 1.0
        state[j] = 0
    for c in range(n):
        y[c] = 0.0
    col = 0
    nf = 0
    for lev in range(k + 1):
        iters[lev] = 0
        flags[lev] = FLAG_OK
        ranks[lev] = 0
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
                r = _dot(B[j], y)
                state[j] = _violated_side(r, blo[j], bup[j],
                                          _tol(primal_tol, rnorm[j], ynorm, blo[j]),
                                          _tol(primal_tol, rnorm[j], ynorm, bup[j]))
        # ---- warm start: jump to the step of last time's working set if it is feasible
        have_step = False
        nh = 0
        nw = 0
        hr = 0
        rs = 0
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
            nh, nw = _gather(state, hard_end, s0, s1, blo, bup, rows, tgt)
            hr, rs, nref = _eqp(B, y, col, rows, nh, nw, tgt, rnorm, rcond, soft_tol, T,
                                rhs, norms, V, beta, vpos, Lw, p, True)
            iters[lev] += 1
            for i in range(hr, nh):
                state[rows[i]] = 0
            for c in range(d):
                g[c] = y[col + c]
                y[col + c] += p[c]
            ynorm = np.sqrt(_dot(y, y))
            feasible = True
            for j in range(hard_end):
                if state[j] != 0 or eqr[j]:
                    continue
                r = _dot(B[j], y)
                if _violated_side(r, blo[j], bup[j],
                                  _tol(primal_tol, rnorm[j], ynorm, blo[j]),
                                  _tol(primal_tol, rnorm[j], ynorm, bup[j])) != 0:
                    feasible = False
                    break
            if feasible:
                # the point is the step's end for this working set: go straight to the
                # optimality test unless rows had to leave or join it
                have_step = hr == nh
                for j in range(s0, s1):
                    if state[j] == 0:
                        r = _dot(B[j], y)
                        state[j] = _violated_side(r, blo[j], bup[j],
                                                  _tol(primal_tol, rnorm[j], ynorm, blo[j]),
                                                  _tol(primal_tol, rnorm[j], ynorm, bup[j]))
                        if state[j] != 0:
                            have_step = False
            else:
                for c in range(d):
                    y[col + c] = g[c]
                for j in range(s1):
                    state[j] = saved[j]
        # ---- primal active-set iterations
        bland = False
        settled = False
        while True:
            if have_step:
                have_step = False
            else:
                if iters[lev] >= max_iter:
                    flags[lev] = FLAG_ITERATION_CAP
                    break
                iters[lev] += 1
                nh, nw = _gather(state, hard_end, s0, s1, blo, bup, rows, tgt)
                hr, rs, nref = _eqp(B, y, col, rows, nh, nw, tgt, rnorm, rcond, soft_tol, T,
                                    rhs, norms, V, beta, vpos, Lw, p, False)
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
                    for j in range(s1):
                        if state[j] != 0 or eqr[j] or (j >= hard_end and j < s0):
                            continue
                        cp = _dot(B[j, col:], p[:d])
                        thr = block_eps * rnorm[j] * pn
                        if cp < -thr and np.isfinite(blo[j]):
                            a = (blo[j] - _dot(B[j], y)) / cp
                            side = -1
                        elif cp > thr and np.isfinite(bup[j]):
                            a = (bup[j] - _dot(B[j], y)) / cp
                            side = 1
                        else:
                            continue
                        if a < 0.0:
                            a = 0.0
                        if a < alpha:
                            alpha = a
                            blk = j
                            bside = side
                for c in range(d):
                    y[col + c] += alpha * p[c]
                if blk >= 0:
                    state[blk] = bside
                    bland = alpha <= _DEGENERATE
                    continue
            bland = False
            ynorm = np.sqrt(_dot(y, y))
            # soft rows on the wrong side of their bound: release or switch sides
            changed = False
            for j in range(s0, s1):
                st = state[j]
                if st == -1 or st == 1:
                    r = _dot(B[j], y)
                    tl = _tol(primal_tol, rnorm[j], ynorm, blo[j])
                    tu = _tol(primal_tol, rnorm[j], ynorm, bup[j])
                    if st == -1 and r > blo[j] + tl:
                        state[j] = 1 if r > bup[j] + tu else 0
                        changed = True
                    elif st == 1 and r < bup[j] - tu:
                        state[j] = -1 if r < blo[j] - tl else 0
                        changed = True
            if changed:
                continue
            if hr == 0:
                settled = True
                break
            gn = _hard_multipliers(B, y, col, rows, nh, hr, nw, tgt, T, V, beta, vpos, g, nu)
            tn = 0.0
            for i in range(nh, nh + nw):
                tn += tgt[i] * tgt[i]
            gscale = dual_tol * max(gn, scale * (scale * ynorm + np.sqrt(tn)))
            drop = -1
            worst = 0.0
            for i in range(hr):
                j = rows[i]
                wrong = (-nu[i] if state[j] == -1 else nu[i]) * rnorm[j]
                if wrong > gscale:
                    if bland:
                        if drop < 0 or j < drop:
                            drop = j
                    elif wrong > worst:
                        worst = wrong
                        drop = j
            if drop < 0:
                settled = True
                break
            state[drop] = 0
        # ---- level done: remember its working set, fix its non-zero slacks
        for j in range(s1):
            st = state[j]
            warm_state[lev, j] = st if (st == -1 or st == 1) else 0
        warm_valid[lev] = True
        if lev == k:
            break
        ynorm = np.sqrt(_dot(y, y))
        nfix = 0
        for j in range(s0, s1):
            st = state[j]
            fix = eqr[j]
            if st == -1 or st == 1:
                tb = blo[j] if st == -1 else bup[j]
                fix = abs(_dot(B[j], y) - tb) > _tol(primal_tol, rnorm[j], ynorm, tb)
            if fix:
                rows[nfix] = j
                norms[nfix] = _dot(B[j, col:], B[j, col:])
                nfix += 1
                state[j] = 5            # being fixed: rotated until its pivot is taken
        rf = 0
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
                for i in range(M):
                    if state[i] == 2 or state[i] == 5:
                        continue
                    other = B[i, q:]
                    f = bt * _dot(other, vf)
                    if f != 0.0:
                        for c in range(n - q):
                            other[c] -= f * vf[c]
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
            if not (np.sqrt(exact) > soft_tol) or soft_tol <= 0.0:
                break
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
            for i in range(M):
                if i == jp or state[i] == 2:   # fixed rows above are done with
                    continue
                other = B[i, col:]
                f = bt * _dot(other, vf)
                if f != 0.0:
                    for c in range(n - col):
                        other[c] -= f * vf[c]
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
    for tf in range(nf - 1, -1, -1):
        q = posf[tf]
        vx = Vf[tf, q:]
        xq = x[q:]
        f = betaf[tf] * _dot(vx, xq)
        for c in range(n - q):
            xq[c] -= f * vx[c]
    # each level's weighted squared violation at x
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
    return True


@njit(cache=True)
def solve_data(A, b, lower, upper, sw, row_eq, starts, params, use_warm, warm_state,
               warm_valid, fmat, fsq, fvec, ivec, bvec, eqr, x, counts, w2):
    """:func:`solve_kernel` with its workspaces packed into a few arrays (one compiled
    call with few arguments: numba's dispatch costs per argument).

    ``params`` = ``(rcond, primal_tol, dual_tol, max_iter)``; ``fmat`` ``3 × R × n``
    (``B``, ``T``, ``Lw``), ``fsq`` ``2 × n × n`` (``V``, ``Vf``), ``fvec`` ``12 × R``,
    ``ivec`` ``3 × R`` (int64), ``bvec`` ``2 × R`` (int8), ``eqr`` ``R`` (bool) with
    ``R = M + n``; ``counts`` ``3 × (k + 1)`` (iterations, flags, ranks).
    """
    n = A.shape[1]
    return solve_kernel(A, b, lower, upper, sw, row_eq, starts, params[0], params[1],
                        params[2], int(params[3]), use_warm, warm_state, warm_valid,
                        fmat[0], fvec[0], fvec[1], fvec[2], eqr, bvec[0], bvec[1], fmat[1],
                        fvec[3], fvec[4], ivec[0], fvec[5], fsq[0], fvec[6, :n],
                        ivec[1, :n], fsq[1], fvec[7, :n], ivec[2, :n], fvec[8, :n],
                        fvec[9, :n], fvec[10, :n], fvec[11], fmat[2], x, counts[0],
                        counts[1], counts[2], w2)
