"""Compiled row writers of :class:`robots.rows.TaskRows` (numba).

Each function writes one task's rows of a :class:`~prioik.hierarchy.StackData` and its
per-row error, reference velocity and feed-forward from views of a ``pin.Data``
(joint Jacobians ``data.J``, frame placements ``data.oMf``, ``data.Jcom``,
``data.com[0]``), so that one task costs one call. The readable versions are the
builders of :mod:`robots.tasks`; ``tests/test_rows.py`` compares both.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def log3(R, out, o):
    """``out[o:o+3] = log(R)``, the rotation vector ``θ u`` of ``R`` (``θ ∈ [0, π]``).

    ``θ = atan2(‖w‖/2, (tr R − 1)/2)`` with ``w = vee(R − Rᵀ) = 2 sin θ u``; then
    ``θ u = θ/(2 sin θ) w`` (a Taylor series below ``θ = 1e-4``), and near ``π``,
    where ``sin θ`` vanishes, ``u`` from the symmetric part
    ``R + Rᵀ = 2 cos θ I + 2 (1 − cos θ) u uᵀ``, its sign from ``w``.
    """
    wx = R[2, 1] - R[1, 2]
    wy = R[0, 2] - R[2, 0]
    wz = R[1, 0] - R[0, 1]
    s = 0.5 * np.sqrt(wx * wx + wy * wy + wz * wz)
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
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
        k = 0
        for i in range(1, 3):
            if R[i, i] > R[k, k]:
                k = i
        one_c = 2.0 * (1.0 - c)
        u = np.empty(3)
        for i in range(3):
            u[i] = (R[i, k] + R[k, i] - (2.0 * c if i == k else 0.0)) / one_c
        norm = np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
        sign = 1.0 if u[0] * wx + u[1] * wy + u[2] * wz >= 0.0 else -1.0
        for i in range(3):
            out[o + i] = sign * theta * u[i] / norm


#: rows of the per-row array ``Q`` (``6 × M``) of :class:`robots.rows.TaskRows`
ERROR, VELOCITY_REF, FEEDFORWARD, DRIFT, KP, KD = range(6)


@njit(cache=True)
def frame_rows(A, Q, s, nrows, J, cols, p, R, x, Rstar, xd, xdd, zero_drift):
    """One frame's rows at ``s``: position (3 rows) or pose (``nrows = 6``).

    ``A[s:s+3] = J_lin + J_ang × p`` on the columns ``cols`` of the frame's
    supporting joints (zero elsewhere): the LOCAL_WORLD_ALIGNED Jacobian of the point
    ``p`` from the world-frame joint Jacobians ``J`` (``v_p = v_O + ω × p``);
    ``A[s+3:s+6] = J_ang``. Error ``x − p`` (and ``log(R* Rᵀ)``), ``ẋ* = xd``,
    ``ẍ* = xdd`` (zero on the orientation rows), drift zeroed if ``zero_drift``.
    """
    for i in range(nrows):
        row = A[s + i]
        for j in range(row.shape[0]):
            row[j] = 0.0
    for c in cols:
        wx = J[3, c]
        wy = J[4, c]
        wz = J[5, c]
        A[s, c] = J[0, c] + wy * p[2] - wz * p[1]
        A[s + 1, c] = J[1, c] + wz * p[0] - wx * p[2]
        A[s + 2, c] = J[2, c] + wx * p[1] - wy * p[0]
        if nrows == 6:
            A[s + 3, c] = wx
            A[s + 4, c] = wy
            A[s + 5, c] = wz
    for i in range(3):
        Q[ERROR, s + i] = x[i] - p[i]
        Q[VELOCITY_REF, s + i] = xd[i]
        Q[FEEDFORWARD, s + i] = xdd[i]
    if nrows == 6:
        E = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                E[i, j] = Rstar[i, 0] * R[j, 0] + Rstar[i, 1] * R[j, 1] + Rstar[i, 2] * R[j, 2]
        log3(E, Q[ERROR], s + 3)
        for i in range(3, 6):
            Q[VELOCITY_REF, s + i] = 0.0
            Q[FEEDFORWARD, s + i] = 0.0
    if zero_drift:
        for i in range(nrows):
            Q[DRIFT, s + i] = 0.0


@njit(cache=True)
def com_rows(A, Q, s, Jcom, com, axes, x, xd, xdd, zero_drift):
    """Centre-of-mass rows at ``s`` on ``axes``: ``A = J_com[axes]``, error
    ``x − c[axes]``, ``ẋ* = xd``, ``ẍ* = xdd``, drift zeroed if ``zero_drift``."""
    for i in range(axes.shape[0]):
        a = axes[i]
        row = A[s + i]
        for j in range(row.shape[0]):
            row[j] = Jcom[a, j]
        Q[ERROR, s + i] = x[i] - com[a]
        Q[VELOCITY_REF, s + i] = xd[i]
        Q[FEEDFORWARD, s + i] = xdd[i]
        if zero_drift:
            Q[DRIFT, s + i] = 0.0


@njit(cache=True)
def posture_error(Q, s, q, q_ref, iq):
    """Posture rows' targets at ``s`` for joints whose configuration is their
    coordinate (``n_q = n_v``, where ``q_ref ⊖ q = q_ref − q``): error
    ``q_ref[iq] − q[iq]``, zero ``ẋ*``, ``ẍ*`` and drift."""
    for i in range(iq.shape[0]):
        Q[ERROR, s + i] = q_ref[iq[i]] - q[iq[i]]
        Q[VELOCITY_REF, s + i] = 0.0
        Q[FEEDFORWARD, s + i] = 0.0
        Q[DRIFT, s + i] = 0.0


@njit(cache=True)
def velocity_targets(b, Q):
    """``b = ẋ* + K e`` (per row)."""
    for i in range(b.shape[0]):
        b[i] = Q[VELOCITY_REF, i] + Q[KP, i] * Q[ERROR, i]
