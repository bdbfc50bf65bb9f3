"""reference.solve_batch (stacked SVDs) against a loop of formulations.solve."""

import numpy as np
import pytest

from prioik import formulations
from prioik.hierarchy import Task, TaskStack, rank_profile
from prioik.hierarchy.families import FAMILIES, same_shape_batch


def _loop(stacks, **options):
    return np.array([formulations.solve(s, "reference", **options).x for s in stacks])


@pytest.mark.parametrize("family", sorted(FAMILIES))
@pytest.mark.parametrize("seed", range(3))
def test_batch_equals_loop_with_per_stack_ranks(family, seed):
    rng = np.random.default_rng(500 + seed)
    n, k = int(rng.integers(3, 30)), int(rng.integers(1, 7))
    base = FAMILIES[family](rng, n, k)
    stacks = same_shape_batch(base, rng, 24, reduce=0.3)
    batch = formulations.solve_batch(stacks, "reference")
    assert batch.batched
    assert batch.statuses == ["optimal"] * len(stacks)
    X = _loop(stacks)
    scale = np.maximum(1.0, np.linalg.norm(X, axis=1))
    # relative 1e-9 per stack: the same SVDs, in another order of summation
    assert np.all(np.linalg.norm(batch.X - X, axis=1) <= 1e-9 * scale)


def test_batch_really_mixes_rank_profiles():
    """The mixed batch of the test above holds stacks of different rank profiles,
    including all-zero levels, so the masks and group splits are exercised."""
    rng = np.random.default_rng(7)
    base = FAMILIES["conflicting"](rng, 20, 5)
    stacks = same_shape_batch(base, rng, 40, reduce=0.4)
    profiles = {tuple(rank_profile(s)) for s in stacks}
    assert len(profiles) >= 5
    assert any(0 in p for p in profiles)
    batch = formulations.solve_batch(stacks, "reference")
    X = _loop(stacks)
    assert np.abs(batch.X - X).max() <= 1e-9 * max(1.0, np.abs(X).max())


@pytest.mark.parametrize("family", ["compatible", "conflicting", "rank_deficient"])
def test_batch_with_metric_equals_loop(family):
    rng = np.random.default_rng(11)
    n = 15
    base = FAMILIES[family](rng, n, 3)
    stacks = same_shape_batch(base, rng, 12, reduce=0.3)
    R = rng.standard_normal((n, n))
    W = R @ R.T + n * np.eye(n)
    batch = formulations.solve_batch(stacks, "reference", metric=W)
    X = _loop(stacks, metric=W)
    assert batch.statuses == ["optimal"] * len(stacks)
    assert np.all(np.linalg.norm(batch.X - X, axis=1)
                  <= 1e-9 * np.maximum(1.0, np.linalg.norm(X, axis=1)))


def test_metric_singular_on_null_space_fails_only_that_stack():
    """W = diag(0, 1, 1, 1): stacks whose remaining null space is span(e_0) fail (a
    failed status and a NaN row, as the loop raises inside and reports failed); the
    others are solved."""
    n = 4
    W = np.diag([0.0, 1.0, 1.0, 1.0])
    fixes_rest = TaskStack([Task("rest", np.eye(n)[1:], np.ones(3))])
    fixes_first = TaskStack([Task("rest", np.eye(n)[[0, 2, 3]], np.ones(3))])
    batch = formulations.solve_batch([fixes_rest, fixes_first], "reference", metric=W)
    assert batch.statuses == ["failed", "optimal"]
    assert np.isnan(batch.X[0]).all()
    assert formulations.solve(fixes_rest, "reference", metric=W).status == "failed"
    expected = formulations.solve(fixes_first, "reference", metric=W).x
    assert np.allclose(batch.X[1], expected, atol=1e-12)
    assert np.allclose(batch.X[1], [1.0, 0.0, 1.0, 1.0], atol=1e-12)


def test_batch_does_not_touch_the_stacks():
    rng = np.random.default_rng(3)
    stacks = same_shape_batch(FAMILIES["conflicting"](rng, 10, 3), rng, 5, reduce=0.3)
    before = [[lvl.A.copy() for lvl in s.levels] for s in stacks]
    formulations.solve_batch(stacks, "reference")
    for s, mats in zip(stacks, before, strict=False):
        for lvl, A in zip(s.levels, mats, strict=False):
            assert np.array_equal(lvl.A, A)
