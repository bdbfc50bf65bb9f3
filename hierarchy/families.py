"""Seeded random task-stack families shared by the tests, the validation report and
the benchmarks (one place, so every consumer draws the same problems).

Every generator takes a ``numpy.random.Generator`` and returns a :class:`TaskStack`;
:data:`FAMILIES` maps a family name to ``f(rng, n, k)``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .stack import Task, TaskStack


def _split(rng: np.random.Generator, total: int, k: int, low: int = 1) -> list[int]:
    """``k`` positive row counts summing to about ``total``."""
    total = max(total, k * low)
    cuts = (np.sort(rng.choice(np.arange(1, total), size=k - 1, replace=False)) if k > 1
            else np.zeros(0, dtype=int))
    sizes = np.diff(np.concatenate([[0], cuts, [total]])).astype(int)
    return [max(low, int(s)) for s in sizes]


def compatible(rng: np.random.Generator, n: int, k: int, fill: float = 0.8) -> TaskStack:
    """Full-rank levels with ``Σ m_i ≈ fill · n ≤ n``: every task can be met exactly."""
    k = max(1, min(k, n))
    ms = _split(rng, max(k, int(fill * n)), k)
    while sum(ms) > n:
        ms[int(np.argmax(ms))] -= 1
    return TaskStack([Task(f"task{i}", rng.standard_normal((m, n)), rng.standard_normal(m))
                      for i, m in enumerate(ms)])


def conflicting(rng: np.random.Generator, n: int, k: int) -> TaskStack:
    """Levels that share directions with higher ones (``Σ m_i > n`` for deep stacks).

    From the second level on, about a third of each level's rows are combinations
    of rows of higher levels (with targets that disagree), the rest random.
    """
    k = max(1, k)
    ms = _split(rng, max(k, int(1.3 * n)), k)
    tasks: list[Task] = []
    rows_above: list[np.ndarray] = []
    for i, m in enumerate(ms):
        A = rng.standard_normal((m, n))
        if rows_above:
            above = np.vstack(rows_above)
            shared = max(1, m // 3)
            A[:shared] = rng.standard_normal((shared, above.shape[0])) @ above
        rows_above.append(A)
        tasks.append(Task(f"task{i}", A, rng.standard_normal(m)))
    return TaskStack(tasks)


def rank_deficient(rng: np.random.Generator, n: int, k: int) -> TaskStack:
    """Levels whose own rows are dependent and whose targets are inconsistent
    (no exact solution even on their own), the first level included."""
    k = max(1, k)
    ms = _split(rng, max(2 * k, int(0.9 * n)), k, low=2)
    tasks = []
    for i, m in enumerate(ms):
        rank = max(1, m // 2)
        A = rng.standard_normal((m, rank)) @ rng.standard_normal((rank, n))
        tasks.append(Task(f"task{i}", A, rng.standard_normal(m)))
    return TaskStack(tasks)


def near_singular(sigma: float, n: int = 6, rng: np.random.Generator | None = None
                  ) -> TaskStack:
    """Two levels where the second task's row tends to the row space of the first.

    Level 1: ``x_0 = 0, x_1 = 0``; level 2: ``cos(σ) x_0 + sin(σ) x_2 = 1`` plus a
    free row. The smallest singular value of ``A_2 Z_2`` is ``sin σ ≈ σ``, and the
    exact lexicographic optimum has ``x_2 = 1/sin σ``.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    A1 = np.zeros((2, n))
    A1[0, 0] = A1[1, 1] = 1.0
    A2 = np.zeros((2, n))
    A2[0, 0], A2[0, 2] = np.cos(sigma), np.sin(sigma)
    A2[1, 3:] = rng.standard_normal(n - 3)
    return TaskStack([Task("high", A1, np.zeros(2)), Task("low", A2, np.array([1.0, 0.5]))])


def weighted(rng: np.random.Generator, n: int, k: int) -> TaskStack:
    """Like :func:`conflicting`, with two weighted tasks sharing each level."""
    base = conflicting(rng, n, k)
    levels = []
    for level in base.levels:
        t = level[0]
        if t.m >= 2:
            h = t.m // 2
            levels.append([t.rows(list(range(h))).with_weight(float(rng.uniform(0.5, 4.0))),
                           t.rows(list(range(h, t.m))).with_weight(float(rng.uniform(0.5, 4.0)))])
        else:
            levels.append([t])
    return TaskStack(levels)


def degenerate(rng: np.random.Generator, n: int, k: int) -> TaskStack:
    """Levels of mixed, often degenerate kinds: random, all-zero rows (unreachable
    targets), copies of higher rows with other targets, dependent rows, and rows
    scaled by 1e-6 or 1e4 (the rank rule is relative to each level's own scale)."""
    kinds = ("random", "zero", "repeat", "dependent", "tiny", "huge")
    tasks: list[Task] = []
    above: list[np.ndarray] = []
    for i in range(max(1, k)):
        kind = kinds[int(rng.integers(len(kinds)))] if i else kinds[int(rng.integers(2, 6)) % 6]
        m = int(rng.integers(1, max(2, n // 2) + 1))
        if kind == "zero":
            A = np.zeros((m, n))
        elif kind == "repeat" and above:
            rows = np.vstack(above)
            A = rows[rng.integers(rows.shape[0], size=m)] * rng.uniform(0.5, 2.0, (m, 1))
        elif kind == "dependent" and m > 1:
            A = rng.standard_normal((m, 1)) @ rng.standard_normal((1, n))
        else:
            A = rng.standard_normal((m, n))
            A *= {"tiny": 1e-6, "huge": 1e4}.get(kind, 1.0)
        above.append(A)
        tasks.append(Task(f"{kind}{i}", A, rng.standard_normal(m)))
    return TaskStack(tasks)


def coupled(rng: np.random.Generator, n: int, k: int) -> TaskStack:
    """Compatible full-rank levels (``Σ m_i ≤ 0.8 n``) whose rows lean on the rows above.

    Each row of level ``i > 1`` is a random row plus twice a random unit combination
    of the higher levels' (normalised) rows, so every task can be met exactly but the
    levels are far from orthogonal: methods that solve each task on its own and then
    project (Chiaverini, the unifying framework) show algorithmic error (eq. 29).
    """
    base = compatible(rng, n, k)
    tasks: list[Task] = []
    above: list[np.ndarray] = []
    for i, level in enumerate(base.levels):
        A = np.array(level.A)
        if above:
            U = np.vstack(above)
            U = U / np.linalg.norm(U, axis=1, keepdims=True)
            G = rng.standard_normal((A.shape[0], U.shape[0]))
            G /= np.linalg.norm(G, axis=1, keepdims=True)
            A = A + 2.0 * np.sqrt(n) * (G @ U) / np.sqrt(max(1, U.shape[0]))
        above.append(A)
        tasks.append(Task(f"task{i}", A, rng.standard_normal(A.shape[0])))
    return TaskStack(tasks)


def decoupled(rng: np.random.Generator, n: int, k: int) -> TaskStack:
    """Compatible full-rank levels acting on disjoint sets of columns.

    The levels' row spaces are mutually orthogonal (also under any diagonal metric),
    so solving each task on its own and projecting it is already optimal: the
    algorithmic error of every method is zero. ``k ≤ n``.
    """
    k = max(1, min(k, n))
    blocks = _split(rng, n, k)
    while sum(blocks) > n:
        blocks[int(np.argmax(blocks))] -= 1
    cols = rng.permutation(n)
    tasks, start = [], 0
    for i, d in enumerate(blocks):
        m = max(1, int(0.8 * d))
        A = np.zeros((m, n))
        A[:, cols[start:start + d]] = rng.standard_normal((m, d))
        start += d
        tasks.append(Task(f"task{i}", A, rng.standard_normal(m)))
    return TaskStack(tasks)


def same_shape_batch(base: TaskStack, rng: np.random.Generator, count: int,
                     reduce: float = 0.0) -> list[TaskStack]:
    """``count`` stacks of ``base``'s shape, for batch solvers.

    Each level's rows are turned by one random orthogonal ``Q`` (ranks and conflicts
    kept) and, with probability ``reduce``, cut to a lower rank (down to an all-zero
    level); targets are fresh. Shapes stay uniform, ranks differ between stacks.
    """
    out = []
    n = base.n
    for _ in range(count):
        Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
        levels = []
        for level in base.levels:
            tasks = []
            for t in level:
                A = t.A @ Q
                if rng.random() < reduce:
                    u, s, vt = np.linalg.svd(A, full_matrices=False)
                    r = int(rng.integers(0, max(1, int(np.count_nonzero(s > 1e-9 * s[0])))))
                    A = (u[:, :r] * s[:r]) @ vt[:r]
                tasks.append(Task(t.name, A, rng.standard_normal(t.m), weight=t.weight))
            levels.append(tasks)
        out.append(TaskStack(levels))
    return out


def random_spd(rng: np.random.Generator, n: int, condition: float = 10.0) -> np.ndarray:
    """Seeded SPD ``n × n`` matrix ``Q diag(λ) Qᵀ`` (a stand-in mass matrix): ``λ``
    spread geometrically over ``[1, condition]``, ``Q`` a random rotation, exactly
    symmetric."""
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    M = (Q * np.geomspace(1.0, condition, n)) @ Q.T
    return 0.5 * (M + M.T)


#: family name -> generator ``f(rng, n, k)``
FAMILIES: dict[str, Callable[[np.random.Generator, int, int], TaskStack]] = {
    "compatible": compatible,
    "conflicting": conflicting,
    "rank_deficient": rank_deficient,
    "weighted": weighted,
    "degenerate": degenerate,
    "coupled": coupled,
    "decoupled": decoupled,
}


# ------------------------------------------------------------ inequality stacks
def with_inequalities(rng: np.random.Generator, n: int, k: int) -> TaskStack:
    """Joint-limit-like stacks: inequality levels above equality levels.

    Level 1 is a box ``−u ≤ x ≤ u`` (task ``box``, ``u ∈ [0.3, 1.2]``); level 2 (when
    ``k ≥ 3``) general rows ``lower ≤ A x ≤ upper`` around a point inside the box,
    some rows one-sided (``∓inf``), so levels 1-2 are jointly feasible. The remaining
    levels are equality tasks whose targets (scale 2) usually push ``x`` onto the
    box; from four levels on, one of them also holds a weighted inequality task
    sharing the level with an equality task. ``k`` is at least 2.
    """
    k = max(2, k)
    u = rng.uniform(0.3, 1.2, n)
    levels: list[list[Task]] = [[Task("box", np.eye(n), lower=-u, upper=u)]]
    n_eq = k - 1
    if k >= 3:
        m = max(1, n // 3)
        A = rng.standard_normal((m, n))
        x0 = rng.uniform(-0.5, 0.5, n) * u
        centre = A @ x0
        lower = centre - rng.uniform(0.05, 0.5, m)
        upper = centre + rng.uniform(0.05, 0.5, m)
        side = rng.integers(0, 3, m)              # 0: two-sided, 1: lower only, 2: upper only
        lower[side == 2] = -np.inf
        upper[side == 1] = np.inf
        levels.append([Task("band", A, lower=lower, upper=upper)])
        n_eq = k - 2
    ms = _split(rng, max(n_eq, int(0.9 * n)), n_eq)
    mixed = int(rng.integers(n_eq)) if k >= 4 else -1
    for i, m in enumerate(ms):
        level = [Task(f"task{i}", rng.standard_normal((m, n)), 2.0 * rng.standard_normal(m),
                      weight=float(rng.uniform(0.5, 2.0)))]
        if i == mixed:
            a = rng.standard_normal((2, n))
            level.append(Task(f"limit{i}", a, lower=np.array([-0.5, -np.inf]),
                              upper=np.array([0.5, 0.2]), weight=float(rng.uniform(0.5, 2.0))))
        levels.append(level)
    return TaskStack(levels)


def infeasible_inequality(rng: np.random.Generator, n: int, k: int) -> TaskStack:
    """A first level of hard inequalities that cannot all hold, then equality levels.

    Level 1 holds ``box`` (``|x| ≤ 1``) and ``keepout``: rows ``c x ≥ 1`` and
    ``c x ≤ −1`` for one random unit direction ``c`` (contradictory). The
    lexicographic least-violation answer has ``c x = 0`` (each row violated by 1);
    the lower levels are equality tasks. ``k`` is at least 2.
    """
    k = max(2, k)
    c = rng.standard_normal(n)
    c /= np.linalg.norm(c)
    first = [Task("box", np.eye(n), lower=-np.ones(n), upper=np.ones(n)),
             Task("keepout", np.vstack([c, c]), lower=np.array([1.0, -np.inf]),
                  upper=np.array([np.inf, -1.0]))]
    ms = _split(rng, max(k - 1, int(0.7 * n)), k - 1)
    return TaskStack([first] + [[Task(f"task{i}", rng.standard_normal((m, n)),
                                      rng.standard_normal(m))] for i, m in enumerate(ms)])


def random_inequality_hierarchy(rng: np.random.Generator, n: int, k: int) -> TaskStack:
    """Random hierarchies of equality and inequality tasks, for the inequality solvers
    and the certificate (:func:`~hierarchy.check_lexicographic`).

    * Level 1 is feasible: a box ``−u ≤ x ≤ u`` (task ``box``, ``u ∈ [0.2, 1]``) and, with
      probability ½, two-sided or one-sided general rows around a point inside the box
      (task ``band``).
    * Each lower level holds one or two tasks (two with different weights, with
      probability ½): inequality tasks whose rows are two-sided (``[c − δ, c + δ]``),
      one-sided, or pinned (``lower = upper``), and equality tasks; targets reach
      beyond the box (scale 2), and about a third of the rows of each lower level are
      combinations of the rows above with other bounds, so the levels conflict.
    * With probability ¼ a lower level also holds ``zero``: a zero row with the
      unreachable interval ``[2, 5]`` (a fixed violation, as in DAQP's degenerate test).

    ``k`` is at least 2, ``n`` at least 2.
    """
    n, k = max(2, n), max(2, k)
    u = rng.uniform(0.2, 1.0, n)
    first = [Task("box", np.eye(n), lower=-u, upper=u)]
    above = [np.eye(n)]
    if rng.random() < 0.5:
        m = int(rng.integers(1, max(2, n // 2) + 1))
        A = rng.standard_normal((m, n))
        c = A @ (rng.uniform(-0.6, 0.6, n) * u)
        lo, up = c - rng.uniform(0.02, 0.3, m), c + rng.uniform(0.02, 0.3, m)
        side = rng.integers(0, 3, m)
        lo[side == 1] = -np.inf
        up[side == 2] = np.inf
        first.append(Task("band", A, lower=lo, upper=up))
        above.append(A)
    levels: list[list[Task]] = [first]
    for i in range(1, k):
        tasks = []
        for j in range(1 + int(rng.random() < 0.5)):
            m = int(rng.integers(1, max(2, (2 * n) // 3) + 1))
            A = rng.standard_normal((m, n))
            rows = np.vstack(above)
            shared = int(rng.integers(0, m // 3 + 1)) if m > 1 else int(rng.random() < 0.3)
            if shared:
                A[:shared] = rng.standard_normal((shared, rows.shape[0])) @ rows
            centre = 2.0 * rng.standard_normal(m)
            weight = float(rng.uniform(0.3, 3.0)) if j or rng.random() < 0.5 else 1.0
            if rng.random() < 0.3:
                tasks.append(Task(f"eq{i}_{j}", A, centre, weight=weight))
            else:
                half = rng.uniform(0.0, 0.5, m)
                lo, up = centre - half, centre + half
                # 0 two-sided, 1 upper only, 2 lower only, 3 pinned
                kind = rng.integers(0, 4, m)
                lo[kind == 1] = -np.inf
                up[kind == 2] = np.inf
                lo[kind == 3] = up[kind == 3] = centre[kind == 3]
                tasks.append(Task(f"ineq{i}_{j}", A, lower=lo, upper=up, weight=weight))
            above.append(A)
        if rng.random() < 0.25:
            tasks.append(Task(f"zero{i}", np.zeros((1, n)), lower=[2.0], upper=[5.0]))
        levels.append(tasks)
    return TaskStack(levels)


#: stacks with inequality tasks (kept apart from :data:`FAMILIES`, whose consumers
#: expect equality stacks): family name -> generator ``f(rng, n, k)``
INEQUALITY_FAMILIES: dict[str, Callable[[np.random.Generator, int, int], TaskStack]] = {
    "with_inequalities": with_inequalities,
    "infeasible_inequality": infeasible_inequality,
    "random_inequality": random_inequality_hierarchy,
}


def box_bounded(rng: np.random.Generator, n: int, k: int, target_scale: float = 1.0,
                offset: bool = False) -> TaskStack:
    """Hard box bounds on top of equality tasks: the stacks of joint-limited IK.

    Level 1 is ``box`` (``l ≤ x ≤ u``; ``−u ≤ x ≤ u`` with ``u ∈ [0.2, 1.5]``, or with
    ``offset`` a box that may exclude 0, as braking bounds at acceleration level do);
    then ``k`` equality levels of 1-3 random rows whose targets have norms about
    ``target_scale`` × U(0.2, 2) — small scales leave the bounds inactive, large ones
    make the tasks infeasible within the box. Used by the SNS tests against the QP
    cascade; not in :data:`INEQUALITY_FAMILIES` (the validation report's set).
    """
    k = max(1, k)
    u = rng.uniform(0.2, 1.5, n)
    lo = -u
    if offset:
        shift = rng.uniform(-1.0, 1.0, n) * u
        lo, u = lo + shift, u + shift
    levels = [Task("box", np.eye(n), lower=lo, upper=u)]
    for i in range(k):
        m = int(rng.integers(1, 4))
        levels.append(Task(f"task{i}", rng.standard_normal((m, n)),
                           target_scale * rng.uniform(0.2, 2.0) * rng.standard_normal(m)))
    return TaskStack(levels)
