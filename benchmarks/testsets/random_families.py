"""The random test sets: seeded stacks of :mod:`prioik.hierarchy.families`.

* ``random_equality``: every family of :data:`~prioik.hierarchy.families.FAMILIES`
  (compatible, conflicting, rank-deficient, weighted, degenerate, coupled, decoupled
  levels);
* ``random_inequality``: every family of
  :data:`~prioik.hierarchy.families.INEQUALITY_FAMILIES` (inequality levels above
  equality levels, infeasible inequality levels, mixed random hierarchies).

``samples`` stacks per family of ``n`` columns and ``k`` levels, the ``i``-th drawn
from ``numpy.random.default_rng([seed, family index, n, k, i])``. Not sequential.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from prioik.hierarchy import TaskStack
from prioik.hierarchy.families import FAMILIES, INEQUALITY_FAMILIES

from .base import Problem, TestSet

__all__ = ["RandomEquality", "RandomInequality"]


class _Random(TestSet):
    families: dict[str, Callable[[np.random.Generator, int, int], TaskStack]] = {}

    def __init__(self, n: int = 20, k: int = 4, samples: int = 4, seed: int = 0) -> None:
        if n < 1 or k < 1 or samples < 1:
            raise ValueError(f"n, k and samples must be ≥ 1, got {n}, {k}, {samples}")
        self.n, self.k, self.samples, self.seed = n, k, samples, seed

    def problems(self) -> Iterator[Problem]:
        for f, (family, draw) in enumerate(self.families.items()):
            for i in range(self.samples):
                rng = np.random.default_rng([self.seed, f, self.n, self.k, i])
                yield Problem(f"{family} #{i}", draw(rng, self.n, self.k))


class RandomEquality(_Random):
    name = "random_equality"
    description = "seeded equality stacks of every family of hierarchy.families.FAMILIES"
    families = FAMILIES


class RandomInequality(_Random):
    name = "random_inequality"
    description = ("seeded stacks with inequality tasks, every family of "
                   "hierarchy.families.INEQUALITY_FAMILIES")
    families = INEQUALITY_FAMILIES
