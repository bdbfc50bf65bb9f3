"""Test sets in qpbenchmark's shape: problems as classes, tolerance profiles, success
as "solved and within tolerance", shifted geometric means normalised to the best.

* :mod:`.base` — :class:`TestSet` and :class:`Problem`;
* the test sets — :mod:`.g1` (the G1 fencing stacks, equality and with joint limits as
  bounds), :mod:`.robot_loops` (closed-loop TALOS, Panda and Go2 stacks),
  :mod:`.random_families` (the seeded families of :mod:`prioik.hierarchy.families`),
  :mod:`.peers` (the peers' hierarchies with their stated solutions);
* :mod:`.metrics` — the profiles, the success rules, the shifted geometric mean;
* :mod:`.run` — the run (every formulation row timed with its prepared solver) and its
  CSV; :mod:`.report` — the markdown report, generated from the CSV.

``prioik bench --test-set NAME --profile mid`` runs one (``--test-set list`` lists them).
"""

from __future__ import annotations

from .base import Problem, TestSet
from .g1 import G1BoundsCompatible, G1BoundsIncompatible, G1Compatible, G1Incompatible
from .metrics import PROFILES, shifted_geometric_mean
from .peers import Peers
from .random_families import RandomEquality, RandomInequality
from .robot_loops import Go2Reach, PandaReach, TalosReach

__all__ = ["Problem", "TestSet", "TEST_SETS", "PROFILES", "get", "shifted_geometric_mean"]

#: name → test-set class, in the order of the reports
TEST_SETS: dict[str, type[TestSet]] = {cls.name: cls for cls in (
    G1Compatible, G1Incompatible, G1BoundsCompatible, G1BoundsIncompatible,
    TalosReach, PandaReach, Go2Reach, RandomEquality, RandomInequality, Peers)}


def get(name: str, **sizes) -> TestSet:
    """The test set called ``name``, built with its size options ``sizes``.

    Raises:
        ValueError: unknown name (lists the known ones), or a size it does not take.
    """
    if name not in TEST_SETS:
        raise ValueError(f"unknown test set {name!r}; known: {', '.join(TEST_SETS)}")
    try:
        return TEST_SETS[name](**sizes)
    except TypeError as exc:
        raise ValueError(f"test set {name!r}: {exc}") from None
