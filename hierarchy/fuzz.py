"""Seeded random task stacks for fuzzing, and an independent ground truth.

:func:`equality_case`, :func:`inequality_case` and :func:`bounds_case` (box bounds on
top of equality levels, the stacks of joint-limited IK) draw one stack each from a
``numpy.random.Generator``; the draws cover what breaks solvers: ``n`` from 1 to 60,
1 to 12 levels of 1 to 40 rows (a level may hold several weighted tasks),
rank-deficient tasks, rows duplicated from higher levels or within the task, zero
rows and all-zero tasks, rows that repeat higher rows with other targets (exact
conflicts), rows a distance ``σ`` from the row space above (``σ`` down to 1e-14,
near-singular levels), task scales from 1e-12 to 1e8 and weights from 1e-6 to 1e6.
Nothing here is tuned to any solver: each feature is drawn uniformly.

:func:`nested_truth` is the ground truth the fuzz runner compares against: the
minimum-norm lexicographic least-squares point by nested SVD on *equilibrated*
levels (every level divided by its ``‖A_i‖_F``, which changes neither its optimal
set nor the rank rule of :mod:`hierarchy.linalg`), written here independently of
the formulations. It also returns the gap of every rank decision, from which
:attr:`FuzzCase.well_conditioned` is decided: a stack is well-conditioned when no
singular value of a projected level ``A_i Z_i`` lies in the band
``[1e-13, 1e-4]·‖A_i‖_F`` around the rank threshold (so every sound solver makes the
same rank decisions), the exact answer is finite in float64 and rounding moves it by at
most ``CONDITIONED_ERROR``: the larger of Wedin's bound per level
(:func:`rounding_error`) and the spread of the truth under a rotation of the unknowns
(:func:`rotation_spread`, which sees what the bound per level does not: a level of
``κ`` 1e5 below one of ``κ`` 1e6 amplifies how rounding turns the higher null space).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .stack import Task, TaskStack

__all__ = ["FuzzCase", "bounds_case", "equality_case", "inequality_case", "judged",
           "mixed_scale_case", "nested_truth",
           "rounding_error", "rotation_spread", "AMBIGUOUS_BAND", "CONDITIONED_ERROR",
           "ROW_FEATURES"]

#: Singular values ``σ / ‖A_i‖_F`` in this band make a rank decision ambiguous (the
#: solvers' threshold is 1e-9).
AMBIGUOUS_BAND = (1e-13, 1e-6)

#: A stack is well-conditioned only if rounding (ε) amplified by its levels' least-
#: squares condition numbers stays below this relative error in ``x``.
CONDITIONED_ERROR = 1e-8

#: How a task's rows are drawn (uniformly among these).
ROW_FEATURES = ("random", "rank_deficient", "duplicated", "zero_rows", "all_zero",
                "conflict", "near_singular")


@dataclass
class FuzzCase:
    """One fuzz stack and what is known about it.

    Attributes:
        stack: The stack.
        seed: Seed of the generator that drew it (``equality_case(default_rng(seed))``
            draws it again).
        kind: ``"equality"``, ``"mixed_scale"`` (an equality stack of
            :func:`mixed_scale_case`), ``"inequality"`` or ``"bounds"``.
        features: Row feature of every task, level by level.
        well_conditioned: Every rank decision is unambiguous and the exact answer is
            finite (equality stacks; see the module docstring).
        truth: The ground-truth ``x`` (equality stacks), else ``None``.
        min_gap: Smallest distance (in decades) of a projected ``σ / ‖A_i‖_F`` from
            the band ends (negative: inside the band).
        min_sigma: Smallest kept ``σ / ‖A_i‖_F`` of any level (1 when none is kept):
            how much a level amplifies rounding.
        rounding_error: How far rounding may move ``x`` (relative): the larger of the
            Wedin bound per level and the rotation spread (see the module docstring).
    """

    stack: TaskStack
    seed: int
    kind: str
    features: list[list[str]] = field(default_factory=list)
    well_conditioned: bool = False
    truth: np.ndarray | None = None
    min_gap: float = np.inf
    min_sigma: float = 1.0
    rounding_error: float = 0.0


def _log_uniform(rng: np.random.Generator, low: float, high: float) -> float:
    return float(10.0 ** rng.uniform(np.log10(low), np.log10(high)))


def _task_rows(rng: np.random.Generator, feature: str, m: int, n: int,
               above: np.ndarray) -> np.ndarray:
    """``m × n`` rows with the given feature (``above``: the rows of higher levels)."""
    A = rng.standard_normal((m, n))
    if feature == "rank_deficient" and min(m, n) > 1:
        r = int(rng.integers(1, min(m, n)))
        A = rng.standard_normal((m, r)) @ rng.standard_normal((r, n))
    elif feature == "duplicated":
        if above.shape[0] and rng.random() < 0.5:
            A[:] = above[rng.integers(0, above.shape[0], m)]
        elif m > 1:
            A[1:] = A[rng.integers(0, 1, m - 1)] if rng.random() < 0.5 else \
                A[rng.integers(0, max(1, m // 2), m - 1)]
    elif feature == "zero_rows":
        A[rng.random(m) < 0.5] = 0.0
    elif feature == "all_zero":
        A[:] = 0.0
    elif feature == "conflict" and above.shape[0]:
        A[:] = rng.standard_normal((m, above.shape[0])) @ above if rng.random() < 0.5 \
            else above[rng.integers(0, above.shape[0], m)]
    elif feature == "near_singular" and above.shape[0]:
        sigma = _log_uniform(rng, 1e-14, 1e-2)
        A[:] = rng.standard_normal((m, above.shape[0])) @ above \
            + sigma * rng.standard_normal((m, n))
    return A


def equality_case(rng: np.random.Generator, seed: int = -1, *, max_n: int = 60,
                  max_levels: int = 12, max_rows: int = 40, truth: bool = True
                  ) -> FuzzCase:
    """Draw one equality stack (see the module docstring).

    Args:
        rng: The generator (consumed).
        seed: Recorded in the case.
        max_n, max_levels, max_rows: Upper ends of the size draws.
        truth: Compute :func:`nested_truth` and the conditioning verdict.
    """
    n = int(rng.integers(1, max_n + 1))
    k = int(rng.integers(1, max_levels + 1))

    def task(name: str, A: np.ndarray, feature: str) -> Task:
        m = A.shape[0]
        scale = _log_uniform(rng, 1e-12, 1e8) if rng.random() < 0.5 else 1.0
        b = rng.standard_normal(m)
        if feature == "conflict" or rng.random() < 0.5:
            b = b * scale           # targets on the rows' scale (else unit targets)
        weight = _log_uniform(rng, 1e-6, 1e6) if rng.random() < 0.3 else 1.0
        return Task(name, scale * A, b, weight=weight)

    levels, features = _equality_levels(rng, n, range(k), max_rows, task)
    return judged(TaskStack(levels), seed, features) if truth else \
        FuzzCase(TaskStack(levels), seed, "equality", features)


def mixed_scale_case(rng: np.random.Generator, seed: int = -1, *, max_n: int = 60,
                     max_levels: int = 12, max_rows: int = 20, truth: bool = True
                     ) -> FuzzCase:
    """Draw one equality stack whose levels' scales span ``1e-12`` to ``1e18``.

    Each level gets a scale log-uniform in ``[1e-12, 1e18]``, so that levels of tiny
    rows lie above and below levels of huge ones in one stack; a level of several tasks
    spreads its tasks' scales below its own by up to 20 decades (log-uniform spread,
    drawn per level), so one level may hold a task 1e9 beside one 1e-11. Rows are drawn
    with the row features of :func:`equality_case` (relative to the rows above, before
    scaling), targets on the rows' scale or of unit size, weights log-uniform in
    ``[1e-6, 1e6]`` with probability 0.3. The case's kind is ``"mixed_scale"``.

    Args:
        rng: The generator (consumed).
        seed: Recorded in the case.
        max_n, max_levels, max_rows: Upper ends of the size draws.
        truth: Compute :func:`nested_truth` and the conditioning verdict.
    """
    n = int(rng.integers(1, max_n + 1))
    k = int(rng.integers(1, max_levels + 1))
    level_scale = {}

    def task(name: str, A: np.ndarray, feature: str) -> Task:
        i = int(name[1:name.index("t")])
        if i not in level_scale:        # the level's scale and its tasks' spread
            level_scale[i] = (_log_uniform(rng, 1e-12, 1e18),
                              float(rng.uniform(0.0, 20.0)) if rng.random() < 0.5 else 0.0)
        top, spread = level_scale[i]
        scale = top * 10.0 ** -float(rng.uniform(0.0, spread))
        m = A.shape[0]
        b = rng.standard_normal(m)
        if feature == "conflict" or rng.random() < 0.5:
            b = b * scale           # targets on the rows' scale (else unit targets)
        weight = _log_uniform(rng, 1e-6, 1e6) if rng.random() < 0.3 else 1.0
        return Task(name, scale * A, b, weight=weight)

    levels, features = _equality_levels(rng, n, range(k), max_rows, task)
    case = judged(TaskStack(levels), seed, features) if truth else \
        FuzzCase(TaskStack(levels), seed, "equality", features)
    case.kind = "mixed_scale"
    return case


def _equality_levels(rng: np.random.Generator, n: int, indices: range, max_rows: int,
                     task: Callable[[str, np.ndarray, str], Task]
                     ) -> tuple[list[list[Task]], list[list[str]]]:
    """Equality levels ``indices`` of ``n`` columns: per level one task (or 2-3), each of
    1 to ``max_rows`` rows of a random row feature (:func:`_task_rows`, relative to the
    rows above); ``task(name, A, feature)`` draws its scale, targets and weight."""
    levels, features = [], []
    above = np.zeros((0, n))
    for i in indices:
        n_tasks = 1 if rng.random() < 0.7 else int(rng.integers(2, 4))
        tasks, feats, new_rows = [], [], []
        for j in range(n_tasks):
            m = int(rng.integers(1, max_rows + 1))
            feature = ROW_FEATURES[int(rng.integers(len(ROW_FEATURES)))]
            A = _task_rows(rng, feature, m, n, above)
            new_rows.append(A)
            tasks.append(task(f"l{i}t{j}", A, feature))
            feats.append(feature)
        above = np.vstack([above] + new_rows)
        levels.append(tasks)
        features.append(feats)
    return levels, features


def judged(stack: TaskStack, seed: int = -1, features: list[list[str]] | None = None
           ) -> FuzzCase:
    """An equality stack as a :class:`FuzzCase` with its ground truth and conditioning
    verdict (what :func:`equality_case` returns; for stacks saved by ``prioik fuzz``)."""
    case = FuzzCase(stack, seed, "equality", features or [])
    case.truth, case.min_gap, case.min_sigma = nested_truth(case.stack)
    case.rounding_error = max(rounding_error(case.stack, case.truth),
                              rotation_spread(case.stack, case.truth))
    case.well_conditioned = bool(case.min_gap > 0 and np.isfinite(case.truth).all()
                                 and case.rounding_error <= CONDITIONED_ERROR)
    return case


def rotation_spread(stack: TaskStack, truth: np.ndarray, seed: int = 0) -> float:
    """``‖x − Q x'‖ / max(1, ‖x‖)`` with ``x'`` the :func:`nested_truth` of the stack in
    the unknowns ``x = Q x'`` (``Q`` a seeded random rotation): the same problem
    rounded differently, so the spread measures what rounding does to this stack's
    answer (on ill-conditioned stacks it can exceed Wedin's bound per level by orders
    of magnitude)."""
    if not np.isfinite(truth).all():
        return np.inf
    q, r = np.linalg.qr(np.random.default_rng(seed).standard_normal((stack.n, stack.n)))
    rotation = q * np.sign(np.diag(r))
    rotated, _, _ = nested_truth(stack, rotation=rotation)
    return float(np.linalg.norm(truth - rotation @ rotated)
                 / max(1.0, float(np.linalg.norm(truth))))


def nested_truth(stack: TaskStack, rcond: float = 1e-9, rotation: np.ndarray | None = None
                 ) -> tuple[np.ndarray, float, float]:
    """Minimum-norm lexicographic least squares by nested SVD on equilibrated levels
    (with ``rotation`` ``Q``: of the stack in the unknowns ``x = Q x'``, returning
    ``x'``).

    Returns:
        ``(x, min_gap, min_sigma)``: the answer, the smallest distance, in decades,
        of any projected ``σ / ‖A_i‖_F`` from the ambiguous band (negative inside
        it), and the smallest kept ``σ / ‖A_i‖_F``.
    """
    n = stack.n
    x = np.zeros(n)
    Z = np.eye(n)
    lo, hi = np.log10(AMBIGUOUS_BAND[0]), np.log10(AMBIGUOUS_BAND[1])
    gap, sigma = np.inf, 1.0
    for level in stack.levels:
        A, b = level.A, level.b
        if rotation is not None:
            A = A @ rotation
        norm = float(np.linalg.norm(A))
        if norm == 0 or not np.isfinite(norm) or Z.shape[1] == 0:
            continue
        A, b = A / norm, b / norm
        u, s, vt = np.linalg.svd(A @ Z, full_matrices=True)
        with np.errstate(divide="ignore"):
            logs = np.log10(s)
        # an exact zero (log −inf) is far below the band
        dist = np.where(logs < lo, lo - logs, np.where(logs > hi, logs - hi,
                                                       -np.minimum(logs - lo, hi - logs)))
        if dist.size:
            gap = min(gap, float(dist.min()))
        r = int(np.count_nonzero(s > rcond))
        if r:
            sigma = min(sigma, float(s[r - 1]))
            M, c = A @ Z, b - A @ x
            y = vt[:r].T @ ((u[:, :r].T @ c) / s[:r])
            # two steps of refinement, the residual formed row by row: the SVD reads rows
            # far smaller than the level's norm to ε of it, and their large targets
            # leak into y (tasks decades apart in one level, zero rows with targets)
            for _ in range(2):
                y = y + vt[:r].T @ ((vt[:r] @ (M.T @ (c - M @ y))) / s[:r] ** 2)
            x = x + Z @ y
        Z = Z @ vt[r:].T
    return x, gap, sigma


def rounding_error(stack: TaskStack, x: np.ndarray, rcond: float = 1e-9) -> float:
    """``ε Σ_i (κ_i ‖x‖ + κ_i² ‖r_i‖) / max(1, ‖x‖)`` on equilibrated levels: how far
    rounding may move the lexicographic optimum ``x`` (relative; Wedin's bound per
    level, ``κ_i = 1/σ_min(A_i Z_i)``, ``r_i = A_i x − b_i``, ``‖A_i‖_F = 1``)."""
    eps = np.finfo(float).eps
    xn = float(np.linalg.norm(x))
    if not np.isfinite(xn):
        return np.inf
    total = 0.0
    Z = np.eye(stack.n)
    for level in stack.levels:
        norm = float(np.linalg.norm(level.A))
        if norm == 0 or Z.shape[1] == 0:
            continue
        A, b = level.A / norm, level.b / norm
        _, s, vt = np.linalg.svd(A @ Z, full_matrices=True)
        r = int(np.count_nonzero(s > rcond))
        if r:
            kappa = 1.0 / float(s[r - 1])
            total += kappa * xn + kappa ** 2 * float(np.linalg.norm(A @ x - b))
        Z = Z @ vt[r:].T
    return eps * total / max(1.0, xn)


def inequality_case(rng: np.random.Generator, seed: int = -1, *, max_n: int = 30,
                    max_levels: int = 6, max_rows: int = 20) -> FuzzCase:
    """Draw one stack with inequality tasks.

    Inequality tasks (two-sided, one-sided, boxes, equal bounds, and with probability
    1/4 bounds that cannot all hold) share levels with equality tasks drawn as in
    :func:`equality_case` (same row features, scales and weights).
    """
    n = int(rng.integers(1, max_n + 1))
    k = int(rng.integers(1, max_levels + 1))
    levels, features = [], []
    above = np.zeros((0, n))
    x0 = rng.standard_normal(n)
    for i in range(k):
        n_tasks = 1 if rng.random() < 0.6 else 2
        tasks, feats, new_rows = [], [], []
        for j in range(n_tasks):
            m = int(rng.integers(1, max_rows + 1))
            feature = ROW_FEATURES[int(rng.integers(len(ROW_FEATURES)))]
            A = _task_rows(rng, feature, m, n, above)
            if rng.random() < 0.2:
                A = np.eye(n)[rng.integers(0, n, m)]               # a box on some x_j
            new_rows.append(A)
            scale = _log_uniform(rng, 1e-6, 1e4) if rng.random() < 0.3 else 1.0
            weight = _log_uniform(rng, 1e-3, 1e3) if rng.random() < 0.3 else 1.0
            if rng.random() < 0.5:                                   # inequality task
                centre = A @ x0 if rng.random() < 0.75 else rng.standard_normal(m) * 3
                width = rng.uniform(0.0, 2.0, m) * (rng.random(m) < 0.9)
                lower, upper = centre - width, centre + width
                side = rng.integers(0, 3, m)
                lower[side == 2] = -np.inf
                upper[side == 1] = np.inf
                tasks.append(Task(f"l{i}t{j}", scale * A, lower=scale * lower,
                                  upper=scale * upper, weight=weight))
                feats.append(f"inequality/{feature}")
            else:
                tasks.append(Task(f"l{i}t{j}", scale * A, scale * rng.standard_normal(m),
                                  weight=weight))
                feats.append(feature)
        above = np.vstack([above] + new_rows)
        levels.append(tasks)
        features.append(feats)
    return FuzzCase(TaskStack(levels), seed, "inequality", features)


def bounds_case(rng: np.random.Generator, seed: int = -1, *, max_n: int = 30,
                max_levels: int = 6, max_rows: int = 20) -> FuzzCase:
    """Draw one stack of box bounds on top of equality levels (joint-limited IK: the
    stacks ``sns`` takes, which :func:`inequality_case` almost never draws).

    Level 1 is one inequality task of single-column rows ``lower ≤ c·x_j ≤ upper``:
    every column, or a random subset, some columns twice (two boxes that intersect), the
    factor ``c`` of either sign and log-uniform in [1e-3, 1e3]; boxes around 0 or
    shifted so that they may exclude it (braking bounds), some one-sided, some of zero
    width, widths log-uniform in [1e-3, 10]; with probability 1/10 two boxes of one
    column do not intersect (an infeasible first level). Below it, 1 to ``max_levels``
    equality levels drawn as in :func:`equality_case` (row features, scales, weights).
    """
    n = int(rng.integers(1, max_n + 1))
    k = int(rng.integers(1, max_levels + 1))
    cols = np.arange(n) if rng.random() < 0.5 else \
        np.flatnonzero(rng.random(n) < rng.uniform(0.2, 1.0))
    if cols.size == 0:
        cols = np.array([int(rng.integers(n))])
    if rng.random() < 0.3:                                   # a second box on some columns
        cols = np.concatenate([cols, rng.choice(cols, int(rng.integers(1, cols.size + 1)))])
    m = cols.size
    c = np.array([_log_uniform(rng, 1e-3, 1e3) for _ in range(m)]) * rng.choice([-1.0, 1.0], m)
    width = np.array([_log_uniform(rng, 1e-3, 10.0) for _ in range(m)])
    width[rng.random(m) < 0.05] = 0.0
    centre = np.where(rng.random(m) < 0.5, 0.0, rng.uniform(-1.5, 1.5, m) * width)
    centre = centre + (np.where(rng.random(m) < 0.1, 3.0 * width + 1.0, 0.0)
                       if rng.random() < 0.1 else 0.0)        # boxes that miss each other
    lo_x, up_x = centre - width, centre + width
    side = rng.integers(0, 6, m)
    lo_x[side == 4] = -np.inf
    up_x[side == 5] = np.inf
    A = np.zeros((m, n))
    A[np.arange(m), cols] = c
    lower = np.where(c > 0, c * lo_x, c * up_x)
    upper = np.where(c > 0, c * up_x, c * lo_x)

    def task(name: str, Ai: np.ndarray, feature: str) -> Task:
        scale = _log_uniform(rng, 1e-6, 1e4) if rng.random() < 0.3 else 1.0
        weight = _log_uniform(rng, 1e-3, 1e3) if rng.random() < 0.3 else 1.0
        return Task(name, scale * Ai, scale * rng.standard_normal(Ai.shape[0]),
                    weight=weight)

    levels, features = _equality_levels(rng, n, range(1, k + 1), max_rows, task)
    return FuzzCase(TaskStack([[Task("box", A, lower=lower, upper=upper)]] + levels), seed,
                    "bounds", [["bounds"]] + features)
