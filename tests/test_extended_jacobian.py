"""extended_jacobian (eq. 15-18, 27) against the reference on the shared families."""

import numpy as np
import pytest

import formulations
from hierarchy import check_lexicographic
from hierarchy.families import FAMILIES, compatible, near_singular

PATHS = ["qr", "svd"]


@pytest.mark.parametrize("nullspace", PATHS)
@pytest.mark.parametrize("seed", range(20))
def test_compatible_equals_reference_and_meets_every_task(nullspace, seed):
    rng = np.random.default_rng(seed)
    stack = compatible(rng, int(rng.integers(4, 40)), int(rng.integers(1, 6)))
    ref = formulations.solve(stack, "reference").x
    sol = formulations.solve(stack, "extended_jacobian", nullspace=nullspace)
    assert sol.status == "optimal"
    # relative 1e-9 to the reference, and every task met to 1e-9 of its scale
    assert np.linalg.norm(sol.x - ref) <= 1e-9 * max(1.0, np.linalg.norm(ref))
    for level, r in zip(stack.levels, sol.residuals):
        assert r <= 1e-9 * max(1.0, np.linalg.norm(level.b))


@pytest.mark.parametrize("nullspace", PATHS)
@pytest.mark.parametrize("family", ["conflicting", "rank_deficient", "weighted"])
@pytest.mark.parametrize("seed", range(12))
def test_conflicting_equals_reference_and_is_lexicographic(nullspace, family, seed):
    rng = np.random.default_rng(1000 + seed)
    stack = FAMILIES[family](rng, int(rng.integers(3, 40)), int(rng.integers(2, 7)))
    ref = formulations.solve(stack, "reference").x
    sol = formulations.solve(stack, "extended_jacobian", nullspace=nullspace)
    assert np.linalg.norm(sol.x - ref) <= 1e-8 * max(1.0, np.linalg.norm(ref))
    report = check_lexicographic(stack, sol.x, tol=1e-8)
    assert report.ok, str(report)


@pytest.mark.parametrize("nullspace", PATHS)
def test_damped_is_bounded_near_singularity_and_tends_to_reference(nullspace):
    lam = 1e-2
    norms = []
    for sigma in np.logspace(-1, -7, 7):
        stack = near_singular(sigma)
        x = formulations.solve(stack, "extended_jacobian", damping=lam, nullspace=nullspace).x
        norms.append(np.linalg.norm(x))
    # eq. 27 in this family: x_2 = s/(s² + λ) ≤ 1/(2√λ) = 5
    assert max(norms) <= 1.0 / (2 * np.sqrt(lam)) + 1.0
    stack = near_singular(0.3)
    ref = formulations.solve(stack, "reference").x
    errs = [np.linalg.norm(formulations.solve(stack, "extended_jacobian", damping=l,
                                              nullspace=nullspace).x - ref)
            for l in (1e-2, 1e-4, 1e-6, 1e-8)]
    assert all(b < a for a, b in zip(errs, errs[1:]))
    assert errs[-1] < 1e-6
