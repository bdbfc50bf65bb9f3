"""Compiled kernel of the extended-Jacobian ``qr`` path (numba).

The same algorithm as ``extended_jacobian._solve_qr`` (the readable LAPACK version),
written as one loop nest so that a whole G1-size stack costs one call instead of
several LAPACK calls per level, each with Python overhead.

Level by level, an LQ factorization with row pivoting of the level's rows restricted
to the still-free coordinates (``A_i Z_i`` in rotated coordinates) finds the level's
rank ``r_i`` (pivot norm ``> rcond‖A_i‖_F``) and a Householder reflector per feasible
direction. Each reflector is applied, from the right, to the rows of the levels below
only, so the free coordinates of the next level are the trailing columns (``Z_{i+1}``
implicitly). The level's feasible rows are then lower-trapezoidal ``L`` (eq. 26) and
its unknowns follow by forward substitution, or by a small least-squares solve when
the level conflicts (``r_i < m_i``), optionally damped (selective damping, and the
trust-region ``step_bound`` of :func:`_bounded_step`). A level with ``m_i`` rows on
``d ≤ m_i`` free coordinates (undamped, unbounded) is first tried with one column-pivoted
QR (:func:`_pivoted_lstsq_if_full_rank`): with full column rank it is solved by that one
factorization and leaves no null space. Finally ``x = H_1 H_2 … H_R y``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from prioik._jit import kernel

from prioik.hierarchy.linalg import AMBIGUITY as _AMBIGUITY
from prioik.hierarchy.linalg import NEAR_AMBIGUITY as _NEAR_AMBIGUITY
from prioik.hierarchy.linalg import PRECISION_LIMIT_NORM as _PRECISION_LIMIT_NORM

#: LLVM may reassociate and contract (vectorised reductions, FMA) but not assume
#: finite values: inputs are validated finite and a non-finite result must show.
_FAST = {"reassoc", "contract", "nsz", "arcp"}


@njit(cache=True, fastmath=_FAST, inline="always")
def _dot(a, b):
    """``a · b`` of two 1-D views of equal length."""
    acc = 0.0
    for j in range(a.shape[0]):
        acc += a[j] * b[j]
    return acc


@njit(cache=True, inline="always")
def _swap(a, i, j):
    """Exchange ``a[i]`` and ``a[j]``."""
    tmp = a[i]
    a[i] = a[j]
    a[j] = tmp


@njit(cache=True, inline="always")
def _swap_rows(M, i, j):
    """Exchange rows ``i`` and ``j`` of ``M``."""
    for k in range(M.shape[1]):
        tmp = M[i, k]
        M[i, k] = M[j, k]
        M[j, k] = tmp


@njit(cache=True, inline="always")
def _argmax_from(values, start, stop):
    """Index of the largest of ``values[start:stop]`` (the first on ties)."""
    p = start
    best = values[start]
    for i in range(start + 1, stop):
        if values[i] > best:
            best = values[i]
            p = i
    return p


@njit(cache=True, fastmath=_FAST, inline="always")
def _reflect_column(Tt, j, t, exact):
    """One Householder step of a QR held transposed (``Tt[k]`` is column ``k``).

    Reflects column ``j``'s tail ``Tt[j, j:]`` (squared norm ``exact > 0``) onto
    ``α e₁`` and applies the reflector to the later columns and to ``t``.
    """
    cj = Tt[j, j:]
    norm = np.sqrt(exact)
    c0 = cj[0]
    alpha = -norm if c0 >= 0.0 else norm
    cj[0] = c0 - alpha                  # cj is now v; H = I − 2 v vᵀ / vᵀv
    vtv = 2.0 * (exact - alpha * c0)    # ‖v‖² = ‖c‖² − 2αc₀ + α², α² = ‖c‖²
    w = cj.shape[0]
    for k in range(j + 1, Tt.shape[0]):
        ck = Tt[k, j:]
        f = 2.0 * _dot(ck, cj) / vtv
        for i in range(w):
            ck[i] -= f * cj[i]
    tj = t[j:]
    f = 2.0 * _dot(tj, cj) / vtv
    for i in range(w):
        tj[i] -= f * cj[i]
    cj[0] = alpha


@njit(cache=True, fastmath=_FAST, inline="always")
def _back_substitute(Tt, t, r, out, col):
    """``R z = t[:r]`` for the upper-triangular ``R`` held transposed
    (``R[j, k] = Tt[k, j]``), into ``out[col:col + r]``."""
    for j in range(r - 1, -1, -1):
        acc = t[j]
        for k in range(j + 1, r):
            acc -= Tt[k, j] * out[col + k]
        out[col + j] = acc / Tt[j, j]


@njit(cache=True, fastmath=_FAST, inline="always")
def _refine_step(Tt, g, r, out, col):
    """``out[col:col + r] += R⁻¹ R⁻ᵀ g`` for the upper-triangular ``R`` held transposed
    (``R[j, k] = Tt[k, j]``), ``g`` overwritten: with ``g = Kᵀ (p − K z)`` the step of
    the corrected semi-normal equations that refines a least-squares solution ``z`` of
    ``K = Q R``. Householder QR is backward stable in norm only: rows of ``K`` far
    smaller than its norm (zero rows with targets, tasks decades apart in one level)
    are read with errors of ``ε ‖K‖`` and their large targets leak into ``Qᵀ p``;
    ``Kᵀ (p − K z)``, formed row by row, has no such term."""
    _csne_correction(Tt, g, r)
    for j in range(r):
        out[col + j] += g[j]


@njit(cache=True, fastmath=_FAST, inline="always")
def _csne_correction(Tt, g, r):
    """``g ← R⁻¹ R⁻ᵀ g`` in place, ``R`` held transposed as in :func:`_refine_step`."""
    for j in range(r):                        # Rᵀ w = g (forward)
        acc = g[j]
        for k in range(j):
            acc -= Tt[j, k] * g[k]
        g[j] = acc / Tt[j, j]
    for j in range(r - 1, -1, -1):            # R δ = w (backward)
        acc = g[j]
        for k in range(j + 1, r):
            acc -= Tt[k, j] * g[k]
        g[j] = acc / Tt[j, j]


@njit(cache=True, fastmath=_FAST, inline="always")
def _small_lstsq_ws(L, rhs, m, r, mu2, out, col, flat, tbuf):
    """min ‖L[:m, :r] z − rhs‖² + mu2 ‖z‖², by Householder QR of [L; √mu2 I], into
    ``out[col:col + r]``, on the scratch ``flat`` (``≥ r (m + r)``) and ``tbuf`` (``≥ m + r``):
    no allocation, so that a kernel without numba's runtime can inline it.

    The matrix is held transposed (``Tt[j]`` is column ``j``) so that every inner
    loop runs over contiguous memory.
    """
    rows = m + r if mu2 > 0.0 else m
    Tt = flat[:r * rows].reshape((r, rows))
    t = tbuf[:rows]          # (its length is the reflectors' length)
    for j in range(r):
        for i in range(rows):
            Tt[j, i] = 0.0
    for i in range(rows):
        t[i] = 0.0
    for i in range(m):
        for j in range(r):
            Tt[j, i] = L[i, j]
        t[i] = rhs[i]
    if mu2 > 0.0:
        s = np.sqrt(mu2)
        for j in range(r):
            Tt[j, m + j] = s
    for j in range(r):
        tail = Tt[j, j:]
        exact = _dot(tail, tail)
        if exact > 0.0:
            _reflect_column(Tt, j, t, exact)
    _back_substitute(Tt, t, r, out, col)
    if mu2 == 0.0:
        # one step of refinement by the corrected semi-normal equations (the residual
        # row by row; tbuf's first m entries hold it, the next r the correction)
        res = tbuf[:m]
        g = tbuf[m:m + r]
        for i in range(m):
            acc = rhs[i]
            for j in range(r):
                acc -= L[i, j] * out[col + j]
            res[i] = acc
        for j in range(r):
            acc = 0.0
            for i in range(m):
                acc += L[i, j] * res[i]
            g[j] = acc
        _refine_step(Tt, g, r, out, col)


@njit(cache=True, fastmath=_FAST, inline="always")
def _apply_reflectors(v, nf, V, beta, pos, transposed):
    """``v = Qᵀ v`` (``transposed``: ``H_0`` first) or ``v = Q v`` (``H_{nf-1}`` first) in
    place, ``Q = H_0 … H_{nf-1}`` (reflector ``t`` in ``V[t, pos[t]:]``, ``beta[t]``)."""
    n = v.shape[0]
    for i in range(nf):
        t = i if transposed else nf - 1 - i
        q = pos[t]
        vt = V[t, q:]
        vq = v[q:]
        f = beta[t] * _dot(vt, vq)
        if f != 0.0:
            for c in range(n - q):
                vq[c] -= f * vt[c]


@njit(cache=True, fastmath=_FAST, inline="always")
def _apply_qt(v, nf, V, beta, pos):
    """``v = Qᵀ v`` in place (:func:`_apply_reflectors`)."""
    _apply_reflectors(v, nf, V, beta, pos, True)


@njit(cache=True, fastmath=_FAST, inline="always")
def _apply_q(v, nf, V, beta, pos):
    """``v = Q v`` in place (:func:`_apply_reflectors`)."""
    _apply_reflectors(v, nf, V, beta, pos, False)


#: the unit-rows step is taken only when the smallest eigenvalue of ``I − Z_U Z_Uᵀ``
#: exceeds this: the normal equations' ``κ²`` is then below ``1 / this`` (their rounding
#: ~``eps κ²`` relative, 2e-13), else the general path (a column-pivoted QR)
_UNIT_ROWS_GAP = 1e-3


@njit(cache=True, fastmath=_FAST, inline="always")
def _cholesky_lower(G, m):
    """``G[:m, :m] = L Lᵀ`` in place (the lower triangle read and overwritten by ``L``);
    ``False`` at a pivot that is not positive (``G`` not positive definite)."""
    for a in range(m):
        for b in range(a + 1):
            acc = G[a, b]
            for c in range(b):
                acc -= G[a, c] * G[b, c]
            if a == b:
                if not acc > 0.0:
                    return False
                G[a, a] = np.sqrt(acc)
            else:
                G[a, b] = acc / G[b, b]
    return True


@njit(cache=True, fastmath=_FAST, inline="always")
def _free_directions(cols, m, Z, nf, Vf, betaf, posf, g):
    """``Z[i] = Qᵀ e_{cols[i]}`` for ``i < m`` (``cols``: column indices, any numeric
    dtype; ``Q = H_0 … H_{nf-1}``; ``Z``'s rows hold ``n``), whose entries from ``col``
    on are the rows ``cols`` of the free directions ``Z = Q[:, col:]``
    (:func:`_drop_fixed` moves them to the front), and ``g = Qᵀ g`` in place when ``g``
    has ``n`` entries (else it is left alone).

    Each vector gets the operations of :func:`_apply_qt`, in its order; the loop runs
    over the reflectors outside and the vectors inside, because one vector's sweep is a
    chain of dependent dot products and several interleaved hide their latency
    (measured on G1's 17 reflectors: ~375 ns a sweep alone, ~230 interleaved by 7)."""
    n = Vf.shape[1]
    dog = g.shape[0] == n
    for i in range(m):
        Zi = Z[i]
        for k in range(n):
            Zi[k] = 0.0
        Zi[int(cols[i])] = 1.0
    for t in range(nf):
        q = posf[t]
        vt = Vf[t, q:]
        bt = betaf[t]
        w = n - q
        for i in range(m):
            zq = Z[i, q:]
            f = bt * _dot(vt, zq)
            if f != 0.0:
                for c in range(w):
                    zq[c] -= f * vt[c]
        if dog:
            gq = g[q:]
            f = bt * _dot(vt, gq)
            if f != 0.0:
                for c in range(w):
                    gq[c] -= f * vt[c]


@njit(cache=True, inline="always")
def _drop_fixed(Z, m, col):
    """``Z[i, :n − col] = Z[i, col:]`` for ``i < m``: the free part of each rotated vector
    moved to the front."""
    n = Z.shape[1]
    if col > 0:
        for i in range(m):
            Zi = Z[i]
            for k in range(n - col):
                Zi[k] = Zi[col + k]


@njit(cache=True, fastmath=_FAST, inline="always")
def _unit_rows_solve(cover, g, col, p, nf, Vf, betaf, posf, Zu, G, yfix):
    """The least-squares step of a level of *unit rows* on the free coordinates.

    The level's rows ``S`` are ``±s e_cᵀ`` in ``x`` (one non-zero each, one magnitude
    ``s``, distinct columns: a posture task of uniform weight), ``cover[c] < 0`` marks
    the columns ``U`` no row covers (a floating base). With ``Q = H_0 … H_{nf-1}`` the
    fixing reflectors (``Vf[t, posf[t]:]``, ``betaf[t]``) and ``Z = Q[:, col:]`` the free
    directions (orthonormal), ``SᵀS = s² (I − P_U)``, so ``min ‖S Z p − t‖`` solves
    ``(I − Z_Uᵀ Z_U) p = h``, ``h = Zᵀ g``, ``g = Sᵀ t / s²`` (given, overwritten), ``Z_U``
    the rows ``U`` of ``Z``: a rank-``|U|`` update of the identity, solved by Woodbury,
    ``p = h + Z_Uᵀ (I − Z_U Z_Uᵀ)⁻¹ Z_U h``. The reflectors are applied to ``|U| + 1``
    vectors (``Qᵀ e_u``, ``Qᵀ g``) instead of the level's rows, and nothing of size
    ``rows × d`` is factorized. With ``yfix`` (the fixed coordinates ``y[:col]`` of the
    levels above, ``x_p = Q [y[:col]; 0]``), ``g`` is given as ``Sᵀ c / s²`` (the targets
    alone) and ``h`` is taken as ``(Qᵀ g)[col:] + Σ_u (x_p)_u (Qᵀ e_u)[col:]``, which is
    ``Zᵀ Sᵀ (c − S x_p) / s²`` (``Zᵀ x_p = 0``, ``SᵀS = s² (I − P_U)``) without bringing
    ``x_p`` through the reflectors: ``(x_p)_u = (Qᵀ e_u)[:col] · y[:col]``, read from the
    same pass.

    Taken only when ``I − Z_U Z_Uᵀ − g I`` is positive definite (its Cholesky
    factorization exists), ``g`` = :data:`_UNIT_ROWS_GAP`: then ``σ_min(S Z) ≥ s √g`` and
    the normal equations' rounding is ``≲ eps / g`` relative. Writes ``p[:n − col]``;
    returns ``|U|``, or ``-1`` when the test fails (``p`` may be written). Scratch:
    ``Zu`` (``≥ |U| × n``), ``G`` (``≥ max(1, 2|U|) × n``)."""
    n = Vf.shape[1]
    d = n - col
    nu = 0
    ucols = G[0, :n]        # (G: scratch until the Gram matrix)
    for u in range(n):
        if cover[u] < 0:
            ucols[nu] = u
            nu += 1
    _free_directions(ucols, nu, Zu, nf, Vf, betaf, posf, g[:n])
    for c in range(d):
        p[c] = g[col + c]
    if yfix.shape[0] > 0:   # h += Σ_u (x_p)_u (Qᵀ e_u)[col:], (x_p)_u = (Qᵀ e_u)[:col]·y
        for i in range(nu):
            xu = _dot(Zu[i, :col], yfix[:col])
            Zi = Zu[i, col:]
            for c in range(d):
                p[c] += xu * Zi[c]
    _drop_fixed(Zu, nu, col)
    if nu == 0:
        return 0
    # G = I − Z_U Z_Uᵀ (lower triangle), and below it G − gap·I
    for a in range(nu):
        for b in range(a + 1):
            v = (1.0 if a == b else 0.0) - _dot(Zu[a, :d], Zu[b, :d])
            G[a, b] = v
            G[nu + a, b] = v - _UNIT_ROWS_GAP if a == b else v
    if not _cholesky_lower(G[nu:2 * nu], nu):
        return -1
    _cholesky_lower(G, nu)
    _woodbury_apply(p, Zu, G, nu, d, g)      # p = h + Z_Uᵀ G⁻¹ Z_U h (scratch g[:nu])
    return nu


@njit(cache=True, fastmath=_FAST, inline="always")
def _cholesky_solve(L, t, m):
    """``t = (L Lᵀ)⁻¹ t`` in place, ``L`` in the lower triangle of ``L[:m, :m]``."""
    for a in range(m):
        acc = t[a]
        for c in range(a):
            acc -= L[a, c] * t[c]
        t[a] = acc / L[a, a]
    for a in range(m - 1, -1, -1):
        acc = t[a]
        for c in range(a + 1, m):
            acc -= L[c, a] * t[c]
        t[a] = acc / L[a, a]


@njit(cache=True, fastmath=_FAST, inline="always")
def _woodbury_apply(v, Zu, G, nu, d, t):
    """``v = (I − Z_Uᵀ Z_U)⁻¹ v`` in place: ``v + Z_Uᵀ (L Lᵀ)⁻¹ Z_U v`` with ``Z_U`` in
    ``Zu[:nu, :d]`` and ``L`` (Cholesky of ``I − Z_U Z_Uᵀ``) in ``G[:nu, :nu]``, as
    :func:`_unit_rows_solve` leaves them; scratch ``t`` (``nu``)."""
    for a in range(nu):
        t[a] = _dot(Zu[a, :d], v[:d])
    _cholesky_solve(G, t, nu)
    for a in range(nu):
        ta = t[a]
        Za = Zu[a]
        for c in range(d):
            v[c] += ta * Za[c]


@njit(cache=True, inline="always")
def _unit_rows_of(B, s0, s1, cover):
    """Whether the rows ``B[s0:s1]`` are unit rows (one non-zero each, of one magnitude,
    on distinct columns): their magnitude ``s``, else ``-1.0``. ``cover[c]`` is then the
    row (offset from ``s0``) on column ``c``, ``-1`` where none is.

    One pass per row of selects, no branch: it counts the row's non-zeros and sums
    their columns (the column, when there is one), so that it vectorises (a loop that
    stops at a second non-zero does not, and the posture's scan is ~5% of a G1 solve)."""
    n = B.shape[1]
    for c in range(n):
        cover[c] = -1
    s = -1.0
    for i in range(s1 - s0):
        row = B[s0 + i]
        nz = 0
        at = 0
        for c in range(n):
            nonzero = row[c] != 0.0
            nz += 1 if nonzero else 0
            at += c if nonzero else 0
        if nz != 1 or cover[at] >= 0:
            return -1.0
        a = abs(row[at])
        if s < 0.0:
            s = a
        elif a != s:
            return -1.0
        cover[at] = i
    return s


@njit(cache=True, fastmath=_FAST)
def _pivoted_lstsq_if_full_rank(B, s0, m, col, rhs, tol, out, margin, spare, ispare):
    """One level with ``m ≥ d`` rows on its ``d = n − col`` free coordinates.

    Householder QR with column pivoting of ``A_i Z_i = B[s0:s0+m, col:]`` (held
    transposed, so that the inner loops run over contiguous memory), with the rank
    test of the row-pivoted path (pivot norm ``> tol``). When all ``d`` pivots pass,
    the level has full column rank: its least-squares solution ``R⁻¹ Qᵀ rhs`` (one
    factorization instead of an LQ and then a least-squares QR) is written into
    ``out[col:]`` and ``True`` returned; the level leaves no null space. Otherwise
    nothing is written and ``False`` returned (``B`` is never modified).
    ``margin[0]`` receives the smallest pivot norm (the rank decision's margin).
    Scratch: ``spare`` (``≥ d m + m + 2 d`` floats), ``ispare`` (``≥ d`` ints); it
    allocates nothing (a kernel without numba's runtime calls it).
    """
    n = B.shape[1]
    d = n - col
    margin[0] = np.inf
    Tt = spare[:d * m].reshape((d, m))
    t = spare[d * m:d * m + m]
    norms = spare[d * m + m:d * m + m + d]
    z = spare[d * m + m + d:d * m + m + 2 * d]
    perm = ispare[:d]
    for i in range(m):
        row = B[s0 + i]
        for j in range(d):
            Tt[j, i] = row[col + j]
        t[i] = rhs[i]
    for j in range(d):
        norms[j] = _dot(Tt[j], Tt[j])
        perm[j] = j
    for j in range(d):
        p = _argmax_from(norms, j, d)
        if p != j:
            _swap_rows(Tt, j, p)
            _swap(norms, j, p)
            _swap(perm, j, p)
        tail = Tt[j, j:]
        exact = _dot(tail, tail)      # exactly (downdated norms lose accuracy)
        if not (np.sqrt(exact) > tol) or tol <= 0.0:
            return False
        margin[0] = min(margin[0], np.sqrt(exact))
        # the step of _reflect_column with the pivot norms downdated in the same pass
        # (calling the shared step and downdating after measured ~0.5 µs slower on G1)
        cj = Tt[j, j:]
        norm = np.sqrt(exact)
        c0 = cj[0]
        alpha = -norm if c0 >= 0.0 else norm
        cj[0] = c0 - alpha
        vtv = 2.0 * (exact - alpha * c0)
        w = m - j
        for k in range(j + 1, d):
            ck = Tt[k, j:]
            f = 2.0 * _dot(ck, cj) / vtv
            for i in range(w):
                ck[i] -= f * cj[i]
            norms[k] -= ck[0] * ck[0]
        tj = t[j:]
        f = 2.0 * _dot(tj, cj) / vtv
        for i in range(w):
            tj[i] -= f * cj[i]
        cj[0] = alpha
    _back_substitute(Tt, t, d, z, 0)
    # one step of refinement by the corrected semi-normal equations (the residual row by
    # row, in t; the correction in norms): see _refine_step
    for i in range(m):
        row = B[s0 + i]
        acc = rhs[i]
        for j in range(d):
            acc -= row[col + perm[j]] * z[j]
        t[i] = acc
    for j in range(d):
        acc = 0.0
        for i in range(m):
            acc += B[s0 + i, col + perm[j]] * t[i]
        norms[j] = acc
    _refine_step(Tt, norms, d, z, 0)
    for j in range(d):
        out[col + perm[j]] = z[j]
    return True


@njit(cache=True, fastmath=_FAST)
def _bounded_step(L, rhs, m, r, mu2_min, step_bound, out, col):
    """Trust-region least squares of one level: ``min ‖L z − rhs‖ s.t. ‖z‖ ≤ Δ``.

    ``L[:m, :r]`` has full column rank. Finds the smallest ``μ² ≥ mu2_min`` whose damped
    step ``(LᵀL + μ² I)⁻¹ Lᵀ rhs`` has ``‖z‖ ≤ Δ`` (Newton on ``1/‖z‖ − 1/Δ`` in the SVD
    basis), writes ``z`` into ``out[col:col + r]`` and returns ``μ²``.
    """
    u, s, vt = np.linalg.svd(np.ascontiguousarray(L[:m, :r]), full_matrices=False)
    c = np.zeros(r)
    for j in range(r):
        acc = 0.0
        for i in range(m):
            acc += u[i, j] * rhs[i]
        c[j] = s[j] * acc
    mu2 = mu2_min
    w = np.zeros(r)
    norm = 0.0
    for j in range(r):
        w[j] = c[j] / (s[j] * s[j] + mu2)
        norm += w[j] * w[j]
    norm = np.sqrt(norm)
    if norm > step_bound:
        for _ in range(100):
            dn = 0.0
            for j in range(r):
                dn += w[j] * w[j] / (s[j] * s[j] + mu2)
            dn = -dn / norm
            mu2 = max(mu2 + (1.0 / norm - 1.0 / step_bound) * norm * norm / dn, mu2_min)
            norm = 0.0
            for j in range(r):
                w[j] = c[j] / (s[j] * s[j] + mu2)
                norm += w[j] * w[j]
            norm = np.sqrt(norm)
            if abs(norm - step_bound) <= 1e-12 * step_bound:
                break
    for i in range(r):
        acc = 0.0
        for j in range(r):
            acc += vt[j, i] * w[j]
        out[col + i] = acc
    return mu2


@njit(cache=True, fastmath=_FAST)
def solve_kernel(B, c, starts, scales, rcond, level_damping, singular_threshold,
                 step_bound, x, ranks, level_mu2, margins):
    """Solve one stack in place.

    Args:
        B: ``M × n`` working copy of every level's weighted rows (overwritten).
        c: ``M`` targets (overwritten).
        starts: ``k + 1`` row offsets of the levels.
        scales: ``‖A_i‖_F`` per level.
        rcond: Relative rank threshold.
        level_damping, singular_threshold: Selective damping (0: off).
        step_bound: ``k`` bounds ``Δ_i`` on the levels' steps (0: unbounded).
        x: Output, ``n``.
        ranks: Output, ``k`` ranks ``r_i``.
        level_mu2: Output, ``k`` damping values ``μ_i²`` (0 where the level is exact).
        margins: Output, ``k`` margins of the rank decisions: the smallest of (kept
            pivot norm / threshold) and (threshold / largest rejected pivot norm),
            ``inf`` when the level decided nothing (``hierarchy.linalg``: a margin
            ``≤ AMBIGUITY`` is an ambiguous decision).
    """
    M, n = B.shape
    solve_kernel_ws(B, c, starts, scales, rcond, level_damping, singular_threshold,
                    step_bound, x, ranks, level_mu2, margins, np.empty((n, n)), np.empty(n),
                    np.empty(n, dtype=np.int64), np.empty(n), np.empty(M),
                    np.empty((M, n)), np.empty(M), np.empty(0, dtype=np.int64),
                    # spare_size(M, n) written out: compiled code cannot call it
                    np.empty(n * (M + n) + M + 2 * n), np.empty(n, dtype=np.int64))


@kernel(fastmath=_FAST)
def solve_kernel_into(B, c, starts, scales, rcond, level_damping, singular_threshold,
                      step_bound, x, ranks, level_mu2, margins, V, beta, pos, y, norms, L,
                      rhs, rowperm, spare, ispare):
    """:func:`solve_kernel` without the trust-region step
    (:func:`solve_kernel_ws_unbounded`: ``step_bound`` must be zeros) on scratch the
    caller owns (:func:`solve_kernel_ws`'s, with ``rowperm``, ``spare`` and ``ispare``):
    for compiled callers in other modules that keep workspaces. It allocates nothing
    and runs without numba's runtime (no reference count kept for its views); a call,
    not inlined there, so that this module's compiled code stays its own."""
    solve_kernel_ws_unbounded(B, c, starts, scales, rcond, level_damping,
                              singular_threshold, step_bound, x, ranks, level_mu2, margins,
                              V, beta, pos, y, norms, L, rhs, rowperm, spare, ispare)


def _nested_qr(trust_region: bool):
    """:func:`solve_kernel_ws`, compiled with the trust-region step of
    :func:`_bounded_step` (``trust_region``) or without it (``step_bound`` then never
    bounds a step; numba prunes the branch, and with it the only part that allocates:
    the SVD, so that a kernel without numba's runtime can inline it)."""

    @njit(fastmath=_FAST, inline="always")
    def solve_kernel_ws(B, c, starts, scales, rcond, level_damping, singular_threshold,
                        step_bound, x, ranks, level_mu2, margins, V, beta, pos, y, norms, L,
                        rhs, rowperm, spare, ispare):
        """:func:`solve_kernel` with its scratch arrays given (a prepared solver owns them:
        no allocation per solve). ``V`` (``n × n``: reflector ``j`` in ``V[j, pos_j:]``),
        ``beta``, ``pos`` (int), ``y`` (``n``), ``norms``, ``rhs`` (``M``), ``L``
        (``M × n``); their contents on entry do not matter. ``rowperm`` (int): empty, or
        ``M`` entries permuted as the rows of ``B`` are (row pivoting within each level),
        for a caller that reads the rotated pivot rows back. ``spare`` (:func:`spare_size`
        floats) and ``ispare`` (``n`` ints): the full-rank and least-squares steps' scratch.
        Inlined into its callers (the call of a function of 19 arguments cost the G1 solve
        ~0.3 µs, the Panda's ~0.1)."""
        M, n = B.shape
        k = starts.shape[0] - 1
        nref = 0
        y[:] = 0.0            # coordinates no level claims stay 0 (the minimum norm)
        # int64 from the start: a literal 0 carried through the loop made numba compile each
        # called helper twice (once for Literal[int](0), before inference settles on int64)
        col = np.int64(0)
        # A last level of unit rows (a posture of uniform weight, x marking its columns
        # until x is written) is not rotated with the others: at its turn it is solved by
        # _unit_rows_solve on its rows as given, or else brought through the reflectors then
        # (the same operations, in the same order, as rotating it level by level)
        rot_end = M
        unit_s = -1.0
        if (k > 0 and rcond > 0.0 and step_bound[k - 1] <= 0.0
                and not (level_damping > 0.0 and singular_threshold > 0.0)
                and starts[k - 1] < M):
            unit_s = _unit_rows_of(B, starts[k - 1], M, x)
            if unit_s > 0.0:
                rot_end = starts[k - 1]
        for lev in range(k):
            s0 = starts[lev]
            s1 = starts[lev + 1]
            m = s1 - s0
            ranks[lev] = 0
            level_mu2[lev] = 0.0
            margins[lev] = np.inf
            if m == 0 or col >= n:
                continue
            tol = rcond * scales[lev]
            if lev == k - 1 and rot_end < M:          # the deferred unit-row level's turn
                d = n - col
                nu = n - m
                if m >= d and nu + max(1, 2 * nu) <= M:
                    g = norms[:n]                     # Sᵀ c / s² (x_p's part: yfix)
                    for j in range(n):
                        g[j] = 0.0
                        i = int(x[j])
                        if i >= 0:
                            a = B[s0 + i, j]
                            g[j] = a * c[s0 + i] / (unit_s * unit_s)
                    got = _unit_rows_solve(x, g, col, y[col:], nref, V, beta, pos, L[:nu],
                                           L[nu:nu + max(1, 2 * nu)], y[:col])
                    margin = unit_s * np.sqrt(_UNIT_ROWS_GAP) if got > 0 else unit_s
                    if got >= 0 and margin > _AMBIGUITY * tol:
                        ranks[lev] = d
                        margins[lev] = margin / tol
                        col = n
                        continue
                    for j in range(col, n):
                        y[j] = 0.0
                for i in range(rot_end, M):
                    _apply_qt(B[i], nref, V, beta, pos)
                rot_end = M
            # right-hand side in rotated coordinates: c_i - B_i[:, :col] y[:col]
            # (1-D views throughout: they let LLVM vectorise the loops; measured 2x on G1)
            yc = y[:col]
            for i in range(m):
                rhs[i] = c[s0 + i] - _dot(B[s0 + i, :col], yc)
                free = B[s0 + i, col:]
                norms[i] = _dot(free, free)
            d = n - col
            if (m >= d and step_bound[lev] <= 0.0
                    and not (level_damping > 0.0 and singular_threshold > 0.0)
                    and _pivoted_lstsq_if_full_rank(B, s0, m, col, rhs, tol, y,
                                                    margins[lev:lev + 1], spare, ispare)):
                ranks[lev] = d
                margins[lev] = margins[lev] / tol
                col = n
                continue
            margins[lev] = np.inf        # (a full-rank attempt that failed wrote its pivots)
            r = 0
            kept_min = np.inf
            while r < m and r < d:
                # pivot: the remaining row of largest norm on the free columns
                p = _argmax_from(norms, r, m)
                # recompute exactly (downdating loses accuracy)
                tail = B[s0 + p, col + r:]
                exact = _dot(tail, tail)
                if not (np.sqrt(exact) > tol) and tol > 0.0:
                    # the downdated norms may have lost the largest remaining row (their
                    # cancellation error is ~ε·‖row‖², above the rows a heavy first pivot
                    # leaves; fuzzing found ranks 1 for 3): recompute them before stopping
                    for i in range(r, m):
                        rest = B[s0 + i, col + r:]
                        norms[i] = _dot(rest, rest)
                    p = _argmax_from(norms, r, m)
                    tail = B[s0 + p, col + r:]
                    exact = _dot(tail, tail)
                if not (np.sqrt(exact) > tol) or tol <= 0.0:
                    if tol > 0.0 and exact > 0.0:
                        margins[lev] = min(kept_min / tol, tol / np.sqrt(exact))
                    break
                kept_min = min(kept_min, np.sqrt(exact))
                if p != r:
                    _swap_rows(B, s0 + r, s0 + p)
                    _swap(rhs, r, p)
                    _swap(norms, r, p)
                    if rowperm.shape[0] > 0:
                        _swap(rowperm, s0 + r, s0 + p)
                q = col + r
                norm = np.sqrt(exact)
                alpha = -norm if B[s0 + r, q] >= 0.0 else norm
                # v = row[q:] - alpha e_1 ; H = I - beta v vᵀ
                V[nref, q] = B[s0 + r, q] - alpha
                vtv = V[nref, q] * V[nref, q]
                for j in range(q + 1, n):
                    V[nref, j] = B[s0 + r, j]
                    vtv += V[nref, j] * V[nref, j]
                bt = 2.0 / vtv if vtv > 0.0 else 0.0
                beta[nref] = bt
                pos[nref] = q
                B[s0 + r, q] = alpha
                for j in range(q + 1, n):
                    B[s0 + r, j] = 0.0
                # apply to the level's other rows and to every lower level's rows
                vq = V[nref, q:]
                w = n - q
                for i in range(s0 + r + 1, rot_end):
                    row = B[i, q:]
                    dot = _dot(row, vq)
                    if dot != 0.0:
                        f = bt * dot
                        for j in range(w):
                            row[j] -= f * vq[j]
                for i in range(r + 1, m):
                    norms[i] -= B[s0 + i, q] * B[s0 + i, q]
                nref += 1
                r += 1
            ranks[lev] = r
            if tol > 0.0:
                margins[lev] = min(margins[lev], kept_min / tol)
            if r == 0:
                continue
            # L = B_i[:, col:col+r] (lower trapezoidal, rows in pivot order)
            mu2 = 0.0
            if level_damping > 0.0 and singular_threshold > 0.0:
                sig = abs(B[s0 + r - 1, col + r - 1])   # RRQR estimate of σ_min
                eps_abs = singular_threshold * scales[lev]
                if sig < eps_abs:
                    mu2 = level_damping * (1.0 - (sig / eps_abs) ** 2)
            if r == m and mu2 == 0.0:
                for i in range(r):
                    acc = rhs[i]
                    for j in range(i):
                        acc -= B[s0 + i, col + j] * y[col + j]
                    y[col + i] = acc / B[s0 + i, col + i]
            else:
                for i in range(m):
                    for j in range(r):
                        L[i, j] = B[s0 + i, col + j] if j <= i else 0.0
                _small_lstsq_ws(L, rhs, m, r, mu2, y, col, spare, spare[r * (m + r):])
            if trust_region and step_bound[lev] > 0.0:
                znorm = 0.0
                for j in range(r):
                    znorm += y[col + j] * y[col + j]
                if np.sqrt(znorm) > step_bound[lev]:
                    for i in range(m):
                        for j in range(r):
                            L[i, j] = B[s0 + i, col + j] if j <= i else 0.0
                    mu2 = _bounded_step(L, rhs, m, r, mu2, step_bound[lev], y, col)
            level_mu2[lev] = mu2
            col += r
        for j in range(n):
            x[j] = y[j]
        _apply_q(x, nref, V, beta, pos)
    return solve_kernel_ws


solve_kernel_ws = _nested_qr(True)
#: :func:`solve_kernel_ws` without the trust-region step (``step_bound`` must be ``≤ 0``):
#: it allocates nothing
solve_kernel_ws_unbounded = _nested_qr(False)


def spare_size(M: int, n: int) -> int:
    """Floats of :func:`solve_kernel_ws`'s ``spare`` for ``M`` rows and ``n`` columns: the
    full-rank step's ``d m + m + 2 d`` and the least-squares step's ``r (m + r) + m + r``
    at their largest (``d, r ≤ n``, ``m ≤ M``)."""
    return n * (M + n) + M + 2 * n


#: a level's ``‖A_i‖_F`` beyond which (or below which, with a non-zero entry) its squares
#: overflow, lose precision or underflow: the caller equilibrates it
#: (``TaskStack.equilibrated``); the active-set kernel's bounds too
SCALE_HIGH = 1e100
SCALE_LOW = 1e-100


@njit(cache=True, fastmath=_FAST, inline="always")
def _level_extreme(A, lev_sq, s0, s1):
    """Whether a level (rows ``s0:s1``) with ``‖A_i‖_F² = lev_sq`` is of extreme scale:
    beyond :data:`SCALE_HIGH` (or not finite), or below :data:`SCALE_LOW` with a
    non-zero entry (a zero level is fine). Squares of entries below ~1e-154 underflow:
    a ``1e-200·I`` level was read as zero rows and gave ``x = 0``. Ordered comparisons
    (LLVM keeps them; ``np.isfinite`` was once folded to true under fast math)."""
    if not lev_sq <= SCALE_HIGH * SCALE_HIGH:
        return True
    if lev_sq < SCALE_LOW * SCALE_LOW:
        for i in range(s0, s1):
            for c in range(A.shape[1]):
                if A[i, c] != 0.0:
                    return True
    return False


@kernel(fastmath=_FAST)
def level_scales(A, b, starts, scales):
    """``scales[i] = ‖A_i‖_F`` of every level (rows ``starts[i]:starts[i+1]``).

    Returns ``False`` when a scale or ``‖b‖`` is not finite — a NaN or inf in the
    rows (or an overflow of the squares) — or when a level's scale is outside
    ``[1e-100, 1e100]`` with a non-zero entry (its squares lose precision or
    underflow: the caller equilibrates it, ``TaskStack.equilibrated``): the caller
    then looks for the entry at fault. The same pass serves as the finite check of
    the hot path.
    """
    M, n = A.shape
    finite = True
    for lev in range(starts.shape[0] - 1):
        acc = 0.0
        for i in range(starts[lev], starts[lev + 1]):
            acc += _dot(A[i], A[i])
        scales[lev] = np.sqrt(acc)
        if _level_extreme(A, acc, starts[lev], starts[lev + 1]):
            finite = False
    for i in range(b.shape[0]):      # entry by entry: b may be large (x is then large)
        if not np.isfinite(b[i]):
            finite = False
    return finite


@kernel(fastmath=_FAST)
def weigh_rows(A, b, w, B, c):
    """``B = diag(w) A``, ``c = w ∘ b`` (the level's weighted rows, into the workspace);
    returns ``False`` when a ``√w`` is not finite and > 0."""
    M, n = A.shape
    ok = True
    for i in range(M):
        wi = w[i]
        if not (wi > 0.0 and wi < np.inf):
            ok = False
        for j in range(n):
            B[i, j] = wi * A[i, j]
        c[i] = wi * b[i]
    return ok


@kernel(fastmath=_FAST)
def level_residuals(A, b, w, starts, x, out):
    """``out[i] = ‖w ∘ (A_i x − b_i)‖`` per level (equality rows)."""
    for lev in range(starts.shape[0] - 1):
        acc = 0.0
        for i in range(starts[lev], starts[lev + 1]):
            r = w[i] * (_dot(A[i], x) - b[i])
            acc += r * r
        out[lev] = np.sqrt(acc)


def work_size(M: int, n: int, k: int) -> int:
    """Floats of :func:`solve_data`'s workspace for ``M`` rows, ``n`` columns, ``k``
    levels (its parameters included)."""
    return 3 + k + 2 * M * n + 3 * M + k + n * n + 2 * n + spare_size(M, n)


def iwork_size(n: int, k: int) -> int:
    """Ints of :func:`solve_data`'s integer workspace: ``k``, the ``k + 1`` level
    offsets, the ``k`` ranks, ``2 n`` of scratch."""
    return 1 + (k + 1) + k + 2 * n


def prepare_workspaces(starts: np.ndarray, n: int, params: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The ``(work, iwork)`` of :func:`solve_data` for a layout's ``starts``, ``n``
    columns and the ``3 + k`` parameters (``rcond``, ``level_damping``,
    ``singular_threshold``, the ``k`` step bounds), which they hold from then on."""
    k = starts.shape[0] - 1
    M = int(starts[-1])
    work = np.empty(work_size(M, n, k))
    work[:3 + k] = params
    iwork = np.zeros(iwork_size(n, k), dtype=np.int64)
    iwork[0] = k
    iwork[1:k + 2] = starts
    return work, iwork


def _prepared_solve(trust_region: bool):
    """The body of :func:`solve_data` (``trust_region``: of :func:`solve_data_bounded`),
    on the nested QR of the same flag."""
    qr = solve_kernel_ws if trust_region else solve_kernel_ws_unbounded

    @njit(fastmath=_FAST, inline="always")
    def solve(A, b, w, work, out, iwork):
        k = iwork[0]
        starts = iwork[1:k + 2]
        ranks = iwork[k + 2:]
        params = work[:3 + k]
        ws = work[3 + k:]                     # the scratch (see work_size)
        M, n = A.shape
        B = ws[:M * n].reshape((M, n))
        c = ws[M * n:M * n + M]
        scales = ws[M * n + M:M * n + M + k]
        o = M * n + M + k                     # scratch of the kernel
        V = ws[o:o + n * n].reshape((n, n))
        o += n * n
        beta = ws[o:o + n]
        y = ws[o + n:o + 2 * n]
        norms = ws[o + 2 * n:o + 2 * n + M]
        rhs = ws[o + 2 * n + M:o + 2 * n + 2 * M]
        o += 2 * n + 2 * M
        L = ws[o:o + M * n].reshape((M, n))
        spare = ws[o + M * n:]
        x = out[:n]
        residuals = out[n:n + k]
        mu2 = out[n + k:n + 2 * k]
        margins = out[n + 2 * k:n + 3 * k]
        if not weigh_rows(A, b, w, B, c):
            return 0
        if not level_scales(B, c, starts, scales):
            return 0
        qr(B, c, starts, scales, params[0], params[1], params[2], params[3:], x, ranks[:k],
           mu2, margins, V, beta, ranks[k:k + n], y, norms, L, rhs, ranks[:0], spare,
           ranks[k + n:])
        level_residuals(A, b, w, starts, x, residuals)
        acc = 0.0
        ambiguous = False
        near = False
        for lev in range(k):
            acc += residuals[lev]
            if margins[lev] <= _AMBIGUITY:
                ambiguous = True
            elif margins[lev] <= _NEAR_AMBIGUITY * _AMBIGUITY:
                near = True
        code = 1 if np.isfinite(acc) else 2
        if ambiguous:
            code += 4
        if near:
            code += 16
        xx = 0.0
        for c in range(n):
            xx += x[c] * x[c]
        if xx > _PRECISION_LIMIT_NORM * _PRECISION_LIMIT_NORM:
            code += 8
        return code
    return solve


_solve_unbounded = _prepared_solve(False)
_solve_bounded = _prepared_solve(True)


@kernel(fastmath=_FAST)
def solve_data(A, b, w, work, out, iwork):
    """The prepared solve of a stack's data, in one call with few arguments (the call's
    cost on small stacks is mostly numba unboxing its arguments).

    Weighs the rows into the workspace, takes the level scales and, if every value is
    finite, runs :func:`solve_kernel` and the per-level residuals.

    Args:
        A, b, w: The data's rows, targets and ``√w`` (``M × n``, ``M``, ``M``).
        work: Workspace of :func:`work_size` floats: the parameters ``rcond,
            level_damping, singular_threshold`` then the ``k`` step bounds, and the
            scratch (weighted rows, targets, scales and the kernel's own).
        out: Output of ``n + 3 k`` floats: ``x``, the residuals, the damping ``μ_i²``,
            the rank decisions' margins (see :func:`solve_kernel`).
        iwork: :func:`iwork_size` ints: ``k``, the ``k + 1`` row offsets of the levels,
            the ``k`` ranks (output), then the kernel's scratch
            (:func:`prepare_workspaces` fills the first two).

    Returns 0 when an input is not finite (nothing solved), 1 when ``x`` and the
    residuals are finite, 2 when they are not (the caller reports a failure); plus 4
    when some level's rank decision margin is within :data:`AMBIGUITY` of its threshold;
    plus 16 when another's is within ``NEAR_AMBIGUITY · AMBIGUITY`` (near-ambiguous: the
    caller certifies the answer); plus 8 when ``‖x‖`` exceeds
    :data:`~prioik.hierarchy.linalg.PRECISION_LIMIT_NORM` (the caller asks
    :func:`~prioik.hierarchy.precision_limited_levels`).

    Without the trust-region step (the step bounds ``params[3:]`` must be zeros;
    :func:`solve_data_bounded` takes them) and without numba's runtime: it allocates
    nothing, and no reference count is kept for its views (on G1 the runtime's counts
    cost ~0.5 µs of a ~8 µs solve).
    """
    return _solve_unbounded(A, b, w, work, out, iwork)


@njit(cache=True, fastmath=_FAST)
def solve_data_bounded(A, b, w, work, out, iwork):
    """:func:`solve_data` with the levels' step bounds ``params[3:]`` (the trust-region
    step of :func:`_bounded_step`, whose SVD allocates: compiled with numba's runtime)."""
    return _solve_bounded(A, b, w, work, out, iwork)


@njit(cache=True, parallel=True)
def weigh_batch(B, c, W, starts, scales, ok):
    """:func:`weigh_rows` and :func:`level_scales` over a batch, in place and in
    parallel: ``B`` (``N × M × n``) and ``c`` (``N × M``) hold the stacks' rows and
    targets and become ``diag(√w) A`` and ``√w ∘ b`` (``W``: ``N × M`` of ``√w``);
    ``ok[s]`` as the two functions' verdicts on stack ``s``."""
    for s in prange(B.shape[0]):
        good = True
        Bs = B[s]
        cs = c[s]
        for i in range(Bs.shape[0]):
            wi = W[s, i]
            if not (wi > 0.0 and wi < np.inf):
                good = False
            for j in range(Bs.shape[1]):
                Bs[i, j] = wi * Bs[i, j]
            cs[i] = wi * cs[i]
        ok[s] = level_scales(Bs, cs, starts, scales[s]) and good


@njit(cache=True, parallel=True)
def solve_batch_kernel(B, c, starts, scales, rcond, level_damping, singular_threshold,
                       step_bound, X, ranks, level_mu2, margins):
    """:func:`solve_kernel` over a batch (``B``: ``N × M × n``), in parallel."""
    for b in prange(B.shape[0]):
        solve_kernel(B[b], c[b], starts, scales[b], rcond, level_damping,
                     singular_threshold, step_bound[b], X[b], ranks[b], level_mu2[b],
                     margins[b])
