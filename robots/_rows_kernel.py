"""The row writers of :class:`robots.rows.TaskWriter` in numba: the oracle of the C++
writers it calls (``prioik._core.rows``, ``core/src/rows.cpp``, the same operations in the
same order), which ``tests/test_rows_cpp.py`` compares with these.

Each function writes one task's rows of a :class:`~prioik.hierarchy.StackData` and its
per-row error, reference velocity and feed-forward from views of a ``pin.Data``
(joint Jacobians ``data.J``, frame placements ``data.oMf``, ``data.Jcom``,
``data.com[0]``), so that one task costs one call.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from prioik._jit import kernel


@njit(cache=True, inline="always")
def _log3(r00, r01, r02, r10, r11, r12, r20, r21, r22, out, o):
    """``out[o:o+3] = log(R)``, the rotation vector ``θ u`` of ``R`` (``θ ∈ [0, π]``),
    from its nine entries (no array: the kernels that call it allocate nothing).

    ``θ = atan2(‖w‖/2, (tr R − 1)/2)`` with ``w = vee(R − Rᵀ) = 2 sin θ u``; then
    ``θ u = θ/(2 sin θ) w`` (a Taylor series below ``θ = 1e-4``), and near ``π``,
    where ``sin θ`` vanishes, ``u`` from the symmetric part
    ``R + Rᵀ = 2 cos θ I + 2 (1 − cos θ) u uᵀ``, its sign from ``w``.
    """
    wx = r21 - r12
    wy = r02 - r20
    wz = r10 - r01
    s = 0.5 * np.sqrt(wx * wx + wy * wy + wz * wz)
    c = 0.5 * (r00 + r11 + r22 - 1.0)
    theta = np.arctan2(s, c)
    if theta < 1e-4:
        f = 0.5 + theta * theta / 12.0
        out[o] = f * wx
        out[o + 1] = f * wy
        out[o + 2] = f * wz
    elif theta < np.pi - 1e-3:
        f = 0.5 * theta / s
        out[o] = f * wx
        out[o + 1] = f * wy
        out[o + 2] = f * wz
    else:
        # u uᵀ = (R + Rᵀ − 2c I) / (2 (1 − c)); the column of the largest diagonal
        one_c = 2.0 * (1.0 - c)
        if r00 >= r11 and r00 >= r22:
            u0, u1, u2 = 2.0 * r00 - 2.0 * c, r10 + r01, r20 + r02
        elif r11 >= r22:
            u0, u1, u2 = r01 + r10, 2.0 * r11 - 2.0 * c, r21 + r12
        else:
            u0, u1, u2 = r02 + r20, r12 + r21, 2.0 * r22 - 2.0 * c
        u0 /= one_c
        u1 /= one_c
        u2 /= one_c
        norm = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        sign = 1.0 if u0 * wx + u1 * wy + u2 * wz >= 0.0 else -1.0
        out[o] = sign * theta * u0 / norm
        out[o + 1] = sign * theta * u1 / norm
        out[o + 2] = sign * theta * u2 / norm


@kernel()
def log3(R, out, o):
    """``out[o:o+3] = log(R)`` of a ``3 × 3`` rotation matrix (see :func:`_log3`)."""
    _log3(R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2], R[2, 0], R[2, 1], R[2, 2],
          out, o)


#: rows of the per-row array ``Q`` (``6 × M``) of :class:`robots.rows.TaskWriter`
ERROR, VELOCITY_REF, FEEDFORWARD, DRIFT, KP, KD = range(6)


#: row sets of :func:`frame_rows`
POSITION, ORIENTATION, POSE = 0, 1, 2

#: layout of a frame task's ``spec`` (int64): first row, row set, whether to zero the
#: drift (else it is computed), then the columns of the frame's supporting joints (fixed
#: at declaration: one array instead of four arguments, as every argument costs the
#: call ~50 ns to unbox)
SPEC_START, SPEC_MODE, SPEC_ZERO_DRIFT, SPEC_COLS = 0, 1, 2, 3

#: rows of a frame task's constant geometry ``geo`` (``5 × 3``): the point's offset in
#: the frame, the point in the parent joint's frame (``r = p_jf + R_jf offset``), then
#: the frame's rotation in the joint's frame ``R_jf`` (three rows)
GEO_OFFSET, GEO_POINT, GEO_ROTATION = 0, 1, 2


@njit(cache=True, inline="always")
def _frame_drift(Q, s, mode, R, geo, aj, vj):
    """The drift ``J̇ q̇`` of a frame task's rows at ``s`` (LOCAL_WORLD_ALIGNED, as
    ``pin.getFrameClassicalAcceleration``), from the parent joint's spatial velocity
    ``vj`` and its acceleration at ``q̈ = 0`` ``aj`` (``data.v[j]``, ``data.a[j]``: linear
    then angular, joint frame).

    In the joint frame, the point ``r`` moves at ``v_r = v + ω × r`` and its classical
    acceleration is ``a + α × r + ω × v_r``; the angular rows take ``α``. Both are turned
    to world axes by ``R R_jfᵀ`` (the joint's rotation; ``R``: the frame's).
    """
    r0 = geo[GEO_POINT, 0]
    r1 = geo[GEO_POINT, 1]
    r2 = geo[GEO_POINT, 2]
    w0, w1, w2 = vj[3], vj[4], vj[5]
    al0, al1, al2 = aj[3], aj[4], aj[5]
    v0 = vj[0] + w1 * r2 - w2 * r1
    v1 = vj[1] + w2 * r0 - w0 * r2
    v2 = vj[2] + w0 * r1 - w1 * r0
    a0 = aj[0] + al1 * r2 - al2 * r1 + w1 * v2 - w2 * v1
    a1 = aj[1] + al2 * r0 - al0 * r2 + w2 * v0 - w0 * v2
    a2 = aj[2] + al0 * r1 - al1 * r0 + w0 * v1 - w1 * v0
    C = geo[GEO_ROTATION:GEO_ROTATION + 3]
    if mode != ORIENTATION:
        # frame axes: R_jfᵀ y, then world axes: R (R_jfᵀ y)
        f0 = C[0, 0] * a0 + C[1, 0] * a1 + C[2, 0] * a2
        f1 = C[0, 1] * a0 + C[1, 1] * a1 + C[2, 1] * a2
        f2 = C[0, 2] * a0 + C[1, 2] * a1 + C[2, 2] * a2
        for i in range(3):
            Q[DRIFT, s + i] = R[i, 0] * f0 + R[i, 1] * f1 + R[i, 2] * f2
    if mode != POSITION:
        o = s + 3 if mode == POSE else s
        f0 = C[0, 0] * al0 + C[1, 0] * al1 + C[2, 0] * al2
        f1 = C[0, 1] * al0 + C[1, 1] * al1 + C[2, 1] * al2
        f2 = C[0, 2] * al0 + C[1, 2] * al1 + C[2, 2] * al2
        for i in range(3):
            Q[DRIFT, o + i] = R[i, 0] * f0 + R[i, 1] * f1 + R[i, 2] * f2


@njit(cache=True, inline="always")
def _position_rows(A, Q, J, t, R, spec, geo, x, xd, xdd, rates):
    """Position rows of a frame task (see :func:`frame_rows`); ``ẋ* = ẍ* = 0`` unless
    ``rates``."""
    s = spec[SPEC_START]
    off = geo[GEO_OFFSET]
    p0 = t[0] + R[0, 0] * off[0] + R[0, 1] * off[1] + R[0, 2] * off[2]
    p1 = t[1] + R[1, 0] * off[0] + R[1, 1] * off[1] + R[1, 2] * off[2]
    p2 = t[2] + R[2, 0] * off[0] + R[2, 1] * off[1] + R[2, 2] * off[2]
    for k in range(SPEC_COLS, spec.shape[0]):
        c = spec[k]
        wx = J[3, c]
        wy = J[4, c]
        wz = J[5, c]
        A[s, c] = J[0, c] + wy * p2 - wz * p1
        A[s + 1, c] = J[1, c] + wz * p0 - wx * p2
        A[s + 2, c] = J[2, c] + wx * p1 - wy * p0
    Q[ERROR, s] = x[0] - p0
    Q[ERROR, s + 1] = x[1] - p1
    Q[ERROR, s + 2] = x[2] - p2
    for i in range(3):
        Q[VELOCITY_REF, s + i] = xd[i] if rates else 0.0
        Q[FEEDFORWARD, s + i] = xdd[i] if rates else 0.0


@njit(cache=True, inline="always")
def _zero_rows(A, Q, s, nrows, zero_drift):
    for i in range(nrows):
        row = A[s + i]
        for j in range(row.shape[0]):
            row[j] = 0.0
        if zero_drift:
            Q[DRIFT, s + i] = 0.0


@njit(cache=True, inline="always")
def _point_rows(A, Q, J, t, R, spec, geo, aj, vj, x, xd, xdd, rates):
    """:func:`position_rows` (``ẋ* = ẍ* = 0`` unless ``rates``)."""
    s = spec[SPEC_START]
    zero_drift = spec[SPEC_ZERO_DRIFT] != 0
    _zero_rows(A, Q, s, 3, zero_drift)
    _position_rows(A, Q, J, t, R, spec, geo, x, xd, xdd, rates)
    if not zero_drift:
        _frame_drift(Q, s, POSITION, R, geo, aj, vj)


@kernel()
def position_rows(A, Q, J, t, R, spec, geo, aj, vj, x, xd, xdd):
    """A point's position rows (3, ``spec``: see :data:`SPEC_COLS`): the point
    ``p = t + R off`` of the frame at ``(t, R)``; :func:`frame_rows` with
    ``mode = POSITION`` in fewer arguments."""
    _point_rows(A, Q, J, t, R, spec, geo, aj, vj, x, xd, xdd, True)


@kernel()
def position_target_rows(A, Q, J, t, R, spec, geo, aj, vj, x):
    """:func:`position_rows` with ``ẋ* = ẍ* = 0`` (a fixed target: two arguments fewer)."""
    _point_rows(A, Q, J, t, R, spec, geo, aj, vj, x, x, x, False)


@njit(cache=True, inline="always")
def _rrt(A, B, i, j):
    """``(A Bᵀ)[i, j]`` of two ``3 × 3`` matrices."""
    return A[i, 0] * B[j, 0] + A[i, 1] * B[j, 1] + A[i, 2] * B[j, 2]


@kernel()
def frame_rows(A, Q, J, t, R, spec, geo, aj, vj, x, xd, xdd, Rstar, w, wd):
    """One frame's rows at ``s = spec[0]``: position of the point ``p = t + R off``
    (3 rows, ``spec[1] = POSITION``), orientation (3 rows, ``ORIENTATION``) or both (6,
    ``POSE``); ``spec[2]``: zero the drift, else compute it (:func:`_frame_drift`, from
    the joint motion ``aj``, ``vj``); ``spec[3:]``: the columns ``cols`` of the
    frame's supporting joints; ``geo``: the constant geometry (:data:`GEO_POINT`).

    Position rows: ``J_lin + J_ang × p`` on the columns ``cols`` (zero elsewhere) — the
    LOCAL_WORLD_ALIGNED Jacobian of the point ``p`` from the world-frame joint Jacobians
    ``J`` (``v_p = v_O + ω × p``) —, error ``x − p``, ``ẋ* = xd``, ``ẍ* = xdd``.
    Orientation rows: ``J_ang``, error ``log(R* Rᵀ)``, ``ω* = w``, ``ω̇* = wd``.
    """
    s = spec[SPEC_START]
    mode = spec[SPEC_MODE]
    nrows = 6 if mode == POSE else 3
    zero_drift = spec[SPEC_ZERO_DRIFT] != 0
    _zero_rows(A, Q, s, nrows, zero_drift)
    if not zero_drift:
        _frame_drift(Q, s, mode, R, geo, aj, vj)
    o = s + 3 if mode == POSE else s        # first orientation row
    if mode != ORIENTATION:
        _position_rows(A, Q, J, t, R, spec, geo, x, xd, xdd, True)
    if mode != POSITION:
        for k in range(SPEC_COLS, spec.shape[0]):
            c = spec[k]
            A[o, c] = J[3, c]
            A[o + 1, c] = J[4, c]
            A[o + 2, c] = J[5, c]
        _log3(_rrt(Rstar, R, 0, 0), _rrt(Rstar, R, 0, 1), _rrt(Rstar, R, 0, 2),
              _rrt(Rstar, R, 1, 0), _rrt(Rstar, R, 1, 1), _rrt(Rstar, R, 1, 2),
              _rrt(Rstar, R, 2, 0), _rrt(Rstar, R, 2, 1), _rrt(Rstar, R, 2, 2), Q[ERROR], o)
        for i in range(3):
            Q[VELOCITY_REF, o + i] = w[i]
            Q[FEEDFORWARD, o + i] = wd[i]


@kernel()
def com_rows(A, Q, s, Jcom, com, acom, axes, x, xd, xdd, zero_drift):
    """Centre-of-mass rows at ``s`` on ``axes``: ``A = J_com[axes]``, error
    ``x − c[axes]``, ``ẋ* = xd``, ``ẍ* = xdd``, drift ``acom[axes]`` (the centre of
    mass's acceleration at ``q̈ = 0``, ``J̇_com q̇``), zeroed if ``zero_drift``."""
    for i in range(axes.shape[0]):
        a = axes[i]
        row = A[s + i]
        for j in range(row.shape[0]):
            row[j] = Jcom[a, j]
        Q[ERROR, s + i] = x[i] - com[a]
        Q[VELOCITY_REF, s + i] = xd[i]
        Q[FEEDFORWARD, s + i] = xdd[i]
        Q[DRIFT, s + i] = 0.0 if zero_drift else acom[a]


@kernel()
def posture_error(Q, s, q, q_ref, iq):
    """Posture rows' targets at ``s`` for joints whose configuration is their
    coordinate (``n_q = n_v``, where ``q_ref ⊖ q = q_ref − q``): error
    ``q_ref[iq] − q[iq]``, zero ``ẋ*``, ``ẍ*`` and drift."""
    for i in range(iq.shape[0]):
        Q[ERROR, s + i] = q_ref[iq[i]] - q[iq[i]]
        Q[VELOCITY_REF, s + i] = 0.0
        Q[FEEDFORWARD, s + i] = 0.0
        Q[DRIFT, s + i] = 0.0


@kernel()
def actuated_positions(q, iq, out):
    """``out[k] = q[iq[k]]`` (0 where ``iq[k] < 0``: a row without one coordinate)."""
    for k in range(iq.shape[0]):
        out[k] = q[iq[k]] if iq[k] >= 0 else 0.0


@kernel()
def limit_activation_rows(A, Q, s, nb, qa, lo, hi, width, kp, kd):
    """Joint-limit activation rows at ``s``, one per actuated joint (fixed size): row
    ``k`` is the unit row of column ``nb + k`` while the joint is inside its margin
    ``width[k]`` of a limit, else masked (all zero, target 0).

    Inside, with ``y > 0`` the depth into the margin and ``σ = min(y / width, 1)``: error
    ``±σ y`` (towards the inside), ``K_p = kp``, ``K_d = σ kd``, so the acceleration target
    ``K_d (0 − q̇_j) + K_p e`` is ``σ (K_p y − K_d q̇_j)`` in the lower margin and
    ``−σ (K_p y + K_d q̇_j)`` in the upper one (``kd = 0`` at velocity level: ``q̇_j = ±σ K y``).
    Returns the number of active rows.
    """
    active = 0
    for k in range(qa.shape[0]):
        r = s + k
        c = nb + k
        e = 0.0
        g = 0.0
        on = False
        if np.isfinite(lo[k]) and np.isfinite(hi[k]):
            y_lo = lo[k] + width[k] - qa[k]
            y_hi = qa[k] - (hi[k] - width[k])
            if y_lo > 0.0:
                sig = min(y_lo / width[k], 1.0)
                e = sig * y_lo
                g = sig
                on = True
            elif y_hi > 0.0:
                sig = min(y_hi / width[k], 1.0)
                e = -sig * y_hi
                g = sig
                on = True
        A[r, c] = 1.0 if on else 0.0
        Q[ERROR, r] = e
        Q[KP, r] = kp if on else 0.0
        Q[KD, r] = g * kd
        Q[VELOCITY_REF, r] = 0.0
        Q[FEEDFORWARD, r] = 0.0
        Q[DRIFT, r] = 0.0
        if on:
            active += 1
    return active


@kernel()
def acceleration_bounds(lower, upper, s, qa, va, lo, hi, vmax, T, dt, position, velocity):
    """Bounds on ``q̈`` of the actuated joints at ``s`` (see
    :func:`robots.tasks.joint_limit_bounds`): position at the horizon ``T`` and after the
    next step ``dt`` within limits, braking of at least ``q̇²/2d`` when the horizon bound
    would make the constant-acceleration path peak before ``T``, and ``|q̇ + q̈ dt| ≤
    q̇_max``; where they do not intersect, both bounds become the hardest admissible
    braking. ``position`` / ``velocity`` switch the two kinds of limit."""
    inf = np.inf
    for k in range(qa.shape[0]):
        q = qa[k]
        v = va[k]
        p_lo = -inf
        p_hi = inf
        if position:
            h_lo = 2.0 * (lo[k] - q - v * T) / (T * T)
            h_hi = 2.0 * (hi[k] - q - v * T) / (T * T)
            d_hi = max(hi[k] - q, 1e-9)
            d_lo = max(q - lo[k], 1e-9)
            p_hi = min(h_hi, (hi[k] - q - v * dt) / (dt * dt))
            p_lo = max(h_lo, (lo[k] - q - v * dt) / (dt * dt))
            if v > 0.0 and h_hi < -v / T:
                p_hi = min(p_hi, -v * v / (2.0 * d_hi))
            if v < 0.0 and h_lo > -v / T:
                p_lo = max(p_lo, v * v / (2.0 * d_lo))
        v_lo = -inf
        v_hi = inf
        if velocity and np.isfinite(vmax[k]):
            v_lo = (-vmax[k] - v) / dt
            v_hi = (vmax[k] - v) / dt
        a = max(p_lo, v_lo)
        b = min(p_hi, v_hi)
        if a > b:
            mid = min(max(p_hi if v > 0.0 else p_lo, v_lo), v_hi)
            if not np.isfinite(mid):
                mid = 0.0
            a = mid
            b = mid
        lower[s + k] = a
        upper[s + k] = b


@kernel()
def velocity_bounds(lower, upper, s, qa, lo, hi, vmax, T, position, velocity):
    """Bounds on ``q̇`` of the actuated joints at ``s``: ``q + q̇ T`` within the position
    limits and ``|q̇| ≤ q̇_max``; where they do not intersect (a joint already past a limit
    by more than ``q̇_max T``) the lower bound is lowered to the upper one."""
    inf = np.inf
    for k in range(qa.shape[0]):
        a = -inf
        b = inf
        if position:
            a = (lo[k] - qa[k]) / T
            b = (hi[k] - qa[k]) / T
        if velocity:
            a = max(a, -vmax[k])
            b = min(b, vmax[k])
        lower[s + k] = min(a, b)
        upper[s + k] = b


@kernel()
def region_rows(A, lower, upper, s, C, Jp, p, psign, v, drift, lo, hi, y, yd, vmax, T, dt,
                accel):
    """A region task's rows at ``s`` (:meth:`robots.rows.TaskWriter.add_frame_region`):
    ``A = C J_p``; with ``y = C p`` (``p`` given as ``psign · p``, the frame writer's
    error ``−p`` for a target 0) the bounds of :func:`velocity_bounds` (``accel`` false)
    or of :func:`acceleration_bounds` on ``y`` and ``ẏ = C J_p q̇`` (position rules only,
    no speed limit) less the drift ``C J̇_p q̇`` (they bound ``C J_p q̈``)."""
    n = Jp.shape[1]
    for i in range(C.shape[0]):
        c0, c1, c2 = C[i, 0], C[i, 1], C[i, 2]
        row = A[s + i]
        for c in range(n):
            row[c] = c0 * Jp[0, c] + c1 * Jp[1, c] + c2 * Jp[2, c]
        y[i] = psign * (c0 * p[0] + c1 * p[1] + c2 * p[2])
    if not accel:
        velocity_bounds(lower, upper, s, y, lo, hi, vmax, T, True, False)
        return
    for i in range(C.shape[0]):
        row = A[s + i]
        acc = 0.0
        for c in range(n):
            acc += row[c] * v[c]
        yd[i] = acc
    acceleration_bounds(lower, upper, s, y, yd, lo, hi, vmax, T, dt, True, False)
    for i in range(C.shape[0]):
        cd = C[i, 0] * drift[0] + C[i, 1] * drift[1] + C[i, 2] * drift[2]
        lower[s + i] -= cd
        upper[s + i] -= cd


@kernel()
def bounds_at(lower, upper, q, v, iq, lim, params, qa):
    """The joint-limit bounds of one task in one call, from the state itself: ``lim``
    holds the task's fixed ``lo``, ``hi``, ``q̇_max`` (``3 × n_a``) and ``q̇`` of the
    actuated joints (``v[n_v − n_a:]``); ``params``: row start, horizon ``T``, ``dt``,
    position, velocity, acceleration level (flags as 0/1) — then
    :func:`acceleration_bounds` or :func:`velocity_bounds` on the positions
    ``q[iq[k]]`` (one call: the two calls and ten arguments of the writer's other
    path cost ~1.5 µs of dispatch)."""
    na = iq.shape[0]
    actuated_positions(q, iq, qa)
    s = int(params[0])
    if params[5] != 0.0:
        va = v[v.shape[0] - na:]
        acceleration_bounds(lower, upper, s, qa, va, lim[0], lim[1], lim[2], params[1],
                            params[2], params[3] != 0.0, params[4] != 0.0)
    else:
        velocity_bounds(lower, upper, s, qa, lim[0], lim[1], lim[2], params[1],
                        params[3] != 0.0, params[4] != 0.0)


@kernel()
def activation_at(A, Q, q, iq, lim, params, qa):
    """The activation rows of one joint-limit task in one call, from the state itself:
    ``lim`` holds the task's fixed ``lo``, ``hi`` and margin widths (``3 × n_a``);
    ``params``: row start, ``n_base``, ``K_p``, ``K_d`` — then
    :func:`limit_activation_rows` on the positions ``q[iq[k]]`` (scratch ``qa``).
    Returns the number of active rows."""
    actuated_positions(q, iq, qa)
    return limit_activation_rows(A, Q, int(params[0]), int(params[1]), qa, lim[0],
                                 lim[1], lim[2], params[2], params[3])


@kernel()
def velocity_targets(b, Q):
    """``b = ẋ* + K e`` (per row)."""
    for i in range(b.shape[0]):
        b[i] = Q[VELOCITY_REF, i] + Q[KP, i] * Q[ERROR, i]


@kernel()
def acceleration_targets(A, b, Q, v):
    """``b = ẍ* + K_d (ẋ* − J q̇) + K_p e − J̇ q̇`` (eq. 2-4, per row)."""
    n = A.shape[1]
    for i in range(b.shape[0]):
        jv = 0.0
        for j in range(n):
            jv += A[i, j] * v[j]
        b[i] = (Q[KD, i] * (Q[VELOCITY_REF, i] - jv) + Q[KP, i] * Q[ERROR, i]
                + Q[FEEDFORWARD, i] - Q[DRIFT, i])


@kernel()
def state_is_valid(q, v, unit, tol):
    """Every entry of ``q`` and ``v`` finite and every unit-norm part of ``q``
    (quaternions, unit complexes: ``unit = [start_0, size_0, start_1, size_1, …]``) of
    norm 1 within ``tol`` — the fast check of a control step's state (the slow one names
    the fault)."""
    for i in range(q.shape[0]):
        if not np.isfinite(q[i]):
            return False
    for i in range(v.shape[0]):
        if not np.isfinite(v[i]):
            return False
    for p in range(0, unit.shape[0], 2):
        acc = 0.0
        for i in range(unit[p], unit[p] + unit[p + 1]):
            acc += q[i] * q[i]
        if abs(np.sqrt(acc) - 1.0) > tol:
            return False
    return True
