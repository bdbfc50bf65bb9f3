"""The lexls plugin (prioik._lexls, built when lexls's headers are found): its answers
against prioik's exact active set, its hot start, its cap, its boundary."""

from pathlib import Path

import numpy as np
import pytest

import prioik
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import Task, TaskStack, check_lexicographic
from prioik.hierarchy.families import FAMILIES, INEQUALITY_FAMILIES
from prioik.hierarchy.io import load_peer

try:
    from prioik import _lexls
except ImportError:
    _lexls = None
#: the tests that run lexls: skipped where prioik was built without its headers
needs_lexls = pytest.mark.skipif(_lexls is None, reason="lexls's headers were not found "
                                 "when prioik was built (PRIOIK_LEXLS_DIR)")

NAME = "lexls"
PEER_DIR = Path(__file__).parent / "data" / "peer"
#: per-level ‖w_i‖² agreement with the active set, relative to max(1, value)
LEVEL_TOL = 1e-8


def _values(stack, x):
    return np.array([float(np.sum(r ** 2)) for r in _violations(stack, x)])


def _violations(stack, x):
    out = []
    for level in stack.levels:
        parts = []
        for t in level:
            sw = np.sqrt(np.broadcast_to(t.weight, (t.m,)))
            a = t.A @ x
            if t.is_equality:
                parts.append(sw * (a - t.b))
            else:
                lo, up = t.bounds()
                parts.append(sw * (a - np.clip(a, lo, up)))
        out.append(np.concatenate(parts))
    return out


@needs_lexls
@pytest.mark.parametrize("family", sorted(set(FAMILIES) | set(INEQUALITY_FAMILIES)))
@pytest.mark.parametrize("seed", range(4))
def test_lexls_reaches_the_active_sets_level_values(family, seed):
    """Where lexls's answer is certified its level values ‖w_i‖² are the active set's
    (x may differ: lexls has no minimum-norm tie-break); where the certificate rejects
    it, the active set's answer is lexicographically no worse at the level at fault."""
    rng = np.random.default_rng(seed)
    build = FAMILIES.get(family) or INEQUALITY_FAMILIES[family]
    stack = build(rng, 12, 4)
    ours = prioik.solve(stack, "hierarchical_active_set")
    sol = prioik.solve(stack, NAME, max_factorizations=10_000)
    assert sol.detail.termination.startswith("solved"), sol.diagnostics
    assert ours.status == "optimal", ours.diagnostics
    w_ours, w_lexls = _values(stack, ours.x), _values(stack, sol.x)
    if sol.status == "optimal":
        assert check_lexicographic(stack, sol.x).ok
        assert np.all(np.abs(w_lexls - w_ours) <= LEVEL_TOL * np.maximum(1.0, w_ours)), \
            (w_ours, w_lexls)
        return
    assert sol.status == "approximate" and sol.diagnostics.fault is not None, sol.diagnostics
    bad = sol.diagnostics.fault.level
    above = slice(0, bad)
    assert np.all(np.abs(w_lexls[above] - w_ours[above])
                  <= LEVEL_TOL * np.maximum(1.0, w_ours[above]))
    assert w_ours[bad] <= w_lexls[bad] * (1 + LEVEL_TOL) + LEVEL_TOL, (w_ours, w_lexls)


@needs_lexls
def test_lexls_solves_its_own_test_hierarchy():
    """lexls's own test file (its #Solution: the last level's value 1.58890)."""
    problem = load_peer(PEER_DIR / "lexls_test_01.dat")[0]
    sol = prioik.solve(problem.stack, NAME)
    assert sol.status == "optimal", sol.diagnostics
    assert abs(_values(problem.stack, sol.x)[-1] - 1.58890) <= 1e-5


@needs_lexls
def test_a_hot_start_from_the_same_data_reuses_the_working_set():
    rng = np.random.default_rng(5)
    stack = INEQUALITY_FAMILIES["random_inequality"](rng, 20, 4)
    solver = prioik.prepare(stack.layout, NAME)
    cold = solver.solve(stack)
    hot = solver.solve(stack)
    assert not cold.detail.hot_started and hot.detail.hot_started
    assert hot.detail.factorizations <= cold.detail.factorizations
    np.testing.assert_allclose(_values(stack, hot.x), _values(stack, cold.x),
                               rtol=1e-9, atol=1e-12)
    solver.reset()
    assert not solver.solve(stack).detail.hot_started
    again = prioik.prepare(stack.layout, NAME, hot_start=False)
    again.solve(stack)
    assert not again.solve(stack).detail.hot_started


@needs_lexls
def test_a_capped_solve_is_not_optimal():
    """At lexls's factorization cap the answer is where it stopped: 'approximate' with
    detail.capped, never 'optimal'."""
    n = 10
    rng = np.random.default_rng(2)
    box = Task("box", np.eye(n), lower=-0.1 * np.ones(n), upper=0.1 * np.ones(n))
    pull = Task("pull", rng.standard_normal((n, n)), 10 * rng.standard_normal(n))
    stack = TaskStack([[box], [pull]])
    full = prioik.solve(stack, NAME)
    assert full.status == "optimal" and full.detail.factorizations > 2, full.diagnostics
    capped = prioik.solve(stack, NAME, max_factorizations=1)
    assert capped.status == "approximate" and capped.detail.capped, capped.diagnostics
    assert "factorization" in capped.diagnostics.reason


@needs_lexls
def test_the_certificate_demotes_a_wrong_answer(monkeypatch):
    """check=True: the status is the certificate's (a corrupted x is 'approximate', with
    the level at fault); check=False: lexls's own word."""
    rng = np.random.default_rng(0)
    stack = FAMILIES["conflicting"](rng, 8, 3)
    solver = prioik.prepare(stack.layout, NAME)
    original = solver._impl._solver.solve

    class Shifted:
        def __init__(self, inner):
            self._inner = inner

        def solve(self, *args):
            res = original(*args)
            self._inner.x[0] += 1.0
            return res

        def __getattr__(self, name):
            return getattr(self._inner, name)

    solver._impl._solver = Shifted(solver._impl._solver)
    sol = solver.solve(stack)
    assert sol.status == "approximate" and sol.diagnostics.fault.level == 0, sol.diagnostics
    raw = prioik.prepare(stack.layout, NAME, check=False)
    raw._impl._solver = Shifted(raw._impl._solver)
    assert raw.solve(stack).status == "optimal"


@needs_lexls
@pytest.mark.parametrize("case", ["shape", "dtype", "strided", "nan_A", "nan_bound",
                                  "crossed", "levels"])
def test_bad_input_to_the_binding_names_it(case):
    n, rows = 3, [2, 1]
    A, lo, up = np.ones((3, n)), np.zeros(3), np.ones(3)
    if case == "levels":
        with pytest.raises(CoreInputError, match="level_rows"):
            _lexls.LexlsSolver(n, [2, 0])
        return
    solver = _lexls.LexlsSolver(n, rows)
    if case == "shape":
        A, what = np.ones((2, n)), "A"
    elif case == "dtype":
        A, what = np.ones((3, n), dtype=np.float32), "A"
    elif case == "strided":
        A, what = np.ones((3, 2 * n))[:, ::2], "A"
    elif case == "nan_A":
        A[1, 2], what = np.nan, r"A\[1, 2\]"
    elif case == "nan_bound":
        lo[2], what = np.nan, r"lower/upper\[2\]"
    else:
        lo[0], what = 2.0, r"lower\[0\] > upper\[0\]"
    with pytest.raises(CoreInputError, match=what):
        solver.solve(A, lo, up)


def test_without_the_binding_the_plugin_says_how_to_build_it(monkeypatch):
    """Where prioik was built without lexls's headers, importing the plugin raises an
    ImportError naming PRIOIK_LEXLS_DIR (the registry's reason for 'lexls')."""
    import importlib
    import sys
    monkeypatch.setitem(sys.modules, "prioik._lexls", None)
    monkeypatch.delattr(prioik, "_lexls", raising=False)
    monkeypatch.delitem(sys.modules, "prioik.formulations.lexls_", raising=False)
    with pytest.raises(ImportError, match="PRIOIK_LEXLS_DIR"):
        importlib.import_module("prioik.formulations.lexls_")
