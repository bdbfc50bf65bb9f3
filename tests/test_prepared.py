"""formulations.prepared and the typed options: the contract every plugin keeps.

Parametrized over the registry: every available formulation can be prepared once and
solve many stacks of its layout (the same answers as one-off solves), refuses another
layout naming both, refuses every wrong option type and value with a FormulationError
naming the option, and is never wrong when called from two threads. Its verification
stage is its own: the same answers and statuses under every ``verify`` mode as one-off
solves; its answers are typed (no open ``info`` dict).
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

import prioik
from prioik import formulations
from prioik.formulations import ConcurrentUseError, FormulationError, Option
from prioik.hierarchy import StackLayout, Task, TaskStack
from prioik.hierarchy.families import FAMILIES, random_spd, with_inequalities

AVAILABLE = [f for f in formulations.available() if f.available]


def _options_for(info, n: int) -> dict:
    """The options a formulation needs to run at all (a mass matrix)."""
    if info.capabilities.needs_mass_matrix:
        return {"mass_matrix": random_spd(np.random.default_rng(1), n)}
    return {}


def _stacks_for(info, count: int = 3, seed: int = 0) -> list[TaskStack]:
    """``count`` stacks of one layout the formulation can take."""
    rng = np.random.default_rng(seed)
    if info.capabilities.inequalities and not info.capabilities.equalities:
        pytest.skip("no such plugin")
    family = "weighted" if info.capabilities.weights else "compatible"
    base = FAMILIES[family](rng, 8, 3)
    out = []
    for _ in range(count):
        out.append(TaskStack([[Task(t.name, rng.standard_normal(t.A.shape),
                                    rng.standard_normal(t.m), weight=t.weight)
                               for t in level] for level in base.levels]))
    return out


@pytest.mark.parametrize("info", AVAILABLE, ids=lambda f: f.name)
def test_reset_makes_the_next_solve_a_fresh_solvers(info):
    """After ``reset()`` a prepared solver answers as one just prepared: the same x (bit
    for bit where the computation is deterministic) and status; it refuses a call while
    another thread holds it."""
    stacks = _stacks_for(info)
    opts = _options_for(info, stacks[0].n)
    used = prioik.prepare(stacks[0].layout, info.name, **opts)
    for stack in stacks:
        used.solve(stack)
    used.reset()
    got = used.solve(stacks[0])
    fresh = prioik.prepare(stacks[0].layout, info.name, **opts).solve(stacks[0])
    assert got.status == fresh.status
    if info.name == "extended_jacobian" or not info.capabilities.inequalities:
        assert np.array_equal(got.x, fresh.x), info.name
    else:
        np.testing.assert_allclose(got.x, fresh.x, rtol=1e-8, atol=1e-10)
    if hasattr(used._impl, "reset"):
        used._acquire(False)        # as if another thread were inside solve()
        try:
            with pytest.raises(ConcurrentUseError, match="busy in another thread"):
                used.reset()
        finally:
            used._release()


@pytest.mark.parametrize("info", AVAILABLE, ids=lambda f: f.name)
def test_prepared_solver_equals_one_off_solves_over_many_stacks(info):
    stacks = _stacks_for(info)
    opts = _options_for(info, stacks[0].n)
    solver = prioik.prepare(stacks[0].layout, info.name, **opts)
    for stack in stacks + stacks[:1]:        # the first again: nothing leaks between solves
        one = prioik.solve(stack, info.name, **opts)
        got = solver.solve(stack)
        assert got.status == one.status
        if info.name == "extended_jacobian" or not info.capabilities.inequalities:
            assert np.array_equal(got.x, one.x), info.name     # same computation
        else:   # QP back-ends may differ in the last digits between calls
            np.testing.assert_allclose(got.x, one.x, rtol=1e-8, atol=1e-10)
    data = stacks[1].layout.data()             # written data of the same layout
    for t in stacks[1].tasks:
        A, b = data.rows(t.name)
        A[:], b[:] = t.A, t.b
        data.weights(t.name)[:] = np.sqrt(t.weight)
    np.testing.assert_allclose(solver.solve(data).x, prioik.solve(stacks[1], info.name,
                                                                  **opts).x,
                               rtol=1e-9, atol=1e-12)


def _same_value(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and \
            np.array_equal(a, b)
    return bool(a == b)


@pytest.mark.parametrize("info", AVAILABLE, ids=lambda f: f.name)
def test_the_plugin_is_built_with_its_typed_settings(info, monkeypatch):
    """``Prepared(layout, settings)``: the plugin's prepared solver receives an instance
    of its own ``Formulation.settings`` (frozen), holding every validated option (the
    given ones and the defaults), the same object as ``PreparedSolver.settings``; the
    options mapping stays the same values by name."""
    import dataclasses

    form = formulations.registry.get(info.name)
    received = []
    init = form.prepared.__init__

    def spy(self, layout, settings, *args, **kwargs):
        received.append(settings)
        init(self, layout, settings, *args, **kwargs)

    monkeypatch.setattr(form.prepared, "__init__", spy)
    stack = _stacks_for(info, 1)[0]
    opts = _options_for(info, stack.n)
    rcond = {"rcond": 1e-7} if "rcond" in form.options else {}
    solver = prioik.prepare(stack.layout, info.name, **opts, **rcond)
    assert len(received) == 1
    settings = received[0]
    assert type(settings) is form.settings, type(settings).__name__
    assert solver.settings is settings
    assert [f.name for f in dataclasses.fields(settings)] == list(form.options)
    for name in form.options:
        assert _same_value(getattr(settings, name), solver.options[name]), name
    if rcond:
        assert settings.rcond == 1e-7
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.rcond = 0.5
    assert solver.solve(stack).status != "failed"
    with pytest.raises(FormulationError, match=f"{form.settings.__name__}, got dict"):
        form.prepare(stack.layout, dict(solver.options))


@pytest.mark.parametrize("info", [f for f in AVAILABLE if f.capabilities.needs_mass_matrix],
                         ids=lambda f: f.name)
def test_step_options_reach_the_plugin_as_its_settings_replaced(info, monkeypatch):
    """A step's options (``mass_matrix``) reach the plugin's solve as its settings with
    them replaced (``dataclasses.replace``); the prepared settings are unchanged."""
    form = formulations.registry.get(info.name)
    stack = _stacks_for(info, 1)[0]
    prepared_mass = random_spd(np.random.default_rng(1), stack.n)
    step_mass = random_spd(np.random.default_rng(2), stack.n)
    solver = prioik.prepare(stack.layout, info.name, mass_matrix=prepared_mass)
    seen = []
    solve = solver._impl.solve

    def spy(data, settings=None):
        seen.append(settings)
        return solve(data, settings)

    monkeypatch.setattr(solver._impl, "solve", spy)
    got = solver.solve(stack, mass_matrix=step_mass)
    assert type(seen[0]) is form.settings
    np.testing.assert_array_equal(seen[0].mass_matrix, step_mass)
    np.testing.assert_array_equal(solver.settings.mass_matrix, prepared_mass)
    assert seen[0].rcond == solver.settings.rcond
    want = prioik.solve(stack, info.name, mass_matrix=step_mass)
    np.testing.assert_array_equal(got.x, want.x)


@pytest.mark.parametrize("info", AVAILABLE, ids=lambda f: f.name)
def test_another_layout_is_refused_naming_both(info):
    stacks = _stacks_for(info, 1)
    solver = prioik.prepare(stacks[0], info.name, **_options_for(info, stacks[0].n))
    other = StackLayout(stacks[0].n, [[("elsewhere", 2)]]).data()
    with pytest.raises(FormulationError, match=r"prepared for the layout n=8: .* got a stack "
                                               r"of the layout n=8: elsewhere\[2\]"):
        solver.solve(other)


def _bad_values(opt: Option) -> list:
    """Values of the wrong type or out of range for ``opt``."""
    bad = [object()]
    if not opt.optional:
        bad.append(None)
    if opt.kind == "float":
        bad += ["abc", float("nan"), True, [1.0]]
        if opt.minimum is not None:
            bad.append(opt.minimum - 1.0)
        if opt.maximum is not None:
            bad.append(opt.maximum + 1.0)
    elif opt.kind == "int":
        bad += [1.5, "3", True]
    elif opt.kind == "bool":
        bad += ["no", 1, None]
    elif opt.kind == "str":
        bad += [3]
        if opt.choices:
            bad.append("not-a-choice")
    elif opt.kind in ("matrix", "vector"):
        bad += ["a", np.eye(3), np.full(8, np.nan), [[1j] * 8] * 8]
    return bad


CASES = [(info, key, value) for info in AVAILABLE for key, opt in info.options.items()
         for value in _bad_values(opt)]


@pytest.mark.parametrize("info, key, value", CASES,
                         ids=[f"{i.name}-{k}-{type(v).__name__}" for i, k, v in CASES])
def test_wrong_option_types_and_values_name_the_option(info, key, value):
    stack = _stacks_for(info, 1)[0]
    opts = _options_for(info, stack.n)
    opts[key] = value
    with pytest.raises(FormulationError, match=f"'{key}'"):
        prioik.prepare(stack.layout, info.name, **opts)
    with pytest.raises(FormulationError, match=f"'{key}'"):
        prioik.solve(stack, info.name, **opts)


def test_every_plugin_declares_typed_options():
    for info in AVAILABLE:
        for key, opt in info.options.items():
            assert isinstance(opt, Option), (info.name, key)
            assert opt.description, (info.name, key)
            if opt.default is not None or not opt.optional:
                assert opt.validate(key, opt.default, 8) is not None or opt.optional


def test_unknown_option_lists_the_known_ones():
    stack = FAMILIES["compatible"](np.random.default_rng(0), 6, 2)
    with pytest.raises(FormulationError, match="no option dampnig; its options: nullspace, "
                                               "damping"):
        prioik.prepare(stack.layout, "extended_jacobian", dampnig=0.1)


@pytest.mark.parametrize("name", ["extended_jacobian", "reference"])
def test_one_solver_from_two_threads_is_never_wrong(name):
    """Two threads hammer one prepared solver: each call either returns the serial answer
    of its own stack or raises ConcurrentUseError."""
    rng = np.random.default_rng(7)
    base = FAMILIES["conflicting"](rng, 20, 4)
    stacks = [TaskStack([[Task(t.name, rng.standard_normal(t.A.shape), rng.standard_normal(t.m))
                          for t in level] for level in base.levels]) for _ in range(2)]
    serial = [prioik.solve(s, name).x for s in stacks]
    solver = prioik.prepare(base.layout, name)
    wrong, busy, done = [], [], []

    def work(i):
        for _ in range(300):
            try:
                x = solver.solve(stacks[i]).x
            except ConcurrentUseError:
                busy.append(i)
                continue
            done.append(i)
            if not np.array_equal(x, serial[i]):
                wrong.append(i)

    threads = [threading.Thread(target=work, args=(i,)) for i in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not wrong
    assert len(done) + len(busy) == 600 and done


def test_inequality_layout_is_refused_by_equality_solvers_at_prepare():
    stack = with_inequalities(np.random.default_rng(0), 8, 3)
    with pytest.raises(prioik.UnsupportedTaskError, match="inequality tasks are not supported"):
        prioik.prepare(stack.layout, "extended_jacobian")


def test_solve_batch_is_one_prepared_solver_over_many_stacks():
    rng = np.random.default_rng(3)
    base = FAMILIES["weighted"](rng, 12, 3)
    stacks = [TaskStack([[Task(t.name, rng.standard_normal(t.A.shape), rng.standard_normal(t.m),
                                weight=t.weight) for t in level] for level in base.levels])
              for _ in range(6)]
    solver = prioik.prepare(base.layout, "extended_jacobian")
    batch = solver.solve_batch(stacks)
    assert batch.batched and batch.X.shape == (6, 12)
    for x, s in zip(batch.X, stacks, strict=False):
        np.testing.assert_allclose(x, prioik.solve(s, "extended_jacobian").x, rtol=1e-12,
                                   atol=1e-13)
    again = prioik.solve_batch(stacks, "extended_jacobian")
    assert np.array_equal(again.X, batch.X)


@pytest.mark.parametrize("name, options, compiled", [
    ("extended_jacobian", {}, True), ("extended_jacobian", {"nullspace": "svd"}, False),
    ("hierarchical_active_set", {}, True), ("reference", {}, False),
    ("nullspace", {}, False)])
def test_compiled_says_whether_a_kernel_reads_the_datas_arrays(name, options, compiled):
    # a compiled solver reads a TaskStack's read-only data and a writable copy alike
    stack = FAMILIES["compatible"](np.random.default_rng(3), 8, 3)
    solver = prioik.prepare(stack.layout, name, **options)
    assert solver.compiled is compiled
    assert np.array_equal(prioik.solve(stack, name, **options).x, solver.solve(stack.data.copy()).x)


@pytest.mark.parametrize("name", ["extended_jacobian", "hierarchical_active_set", "reference",
                                  "nullspace"])
@pytest.mark.parametrize("scale", [1e-120, 1e120])
def test_an_equilibrated_solve_reports_residuals_in_the_users_units(name, scale):
    """Levels of extreme scale are solved rescaled by powers of two; the residuals (and
    the active set's level violations) are read on the user's stack: 1.58 for the
    second level here, not 1.58 times the power of two (1e120 before)."""
    from prioik.hierarchy import lexicographic_residuals
    eye = np.eye(2)
    stack = TaskStack([[Task("a", scale * eye, np.array([1.0, 2.0]))],
                       [Task("p", scale * eye, np.array([0.5, 0.5]))]])
    sol = prioik.solve(stack, name)
    assert sol.status == "optimal" and sol.diagnostics.equilibrated_levels == [0, 1]
    assert sol.x * scale == pytest.approx([1.0, 2.0], rel=1e-14)
    assert sol.residuals == pytest.approx(lexicographic_residuals(stack, sol.x), rel=1e-12,
                                          abs=1e-12)
    assert sol.residuals[1] == pytest.approx(np.sqrt(2.5), rel=1e-12)
    if name == "hierarchical_active_set":
        assert sol.detail.level_violation == pytest.approx(sol.residuals ** 2, rel=1e-12)


@pytest.mark.parametrize("info", AVAILABLE, ids=lambda f: f.name)
@pytest.mark.parametrize("verify", ["none", "certificate"])
def test_a_prepared_solvers_verification_equals_one_off_solves(info, verify):
    """Each ``verify`` mode gives a prepared solver the statuses and verdicts of one-off
    solves with that mode, over many stacks (the stage and its prepared verifier keep
    nothing between answers that changes them); ``none`` takes no verification time."""
    stacks = _stacks_for(info, seed=5)
    opts = _options_for(info, stacks[0].n)
    solver = prioik.prepare(stacks[0].layout, info.name, verify=verify, **opts)
    assert solver.verify == verify
    for stack in stacks:
        if "warm_start" in info.options or "hot_start" in info.options:
            solver.reset()
        got = solver.solve(stack)
        one = prioik.solve(stack, info.name, verify=verify, **opts)
        assert got.status == one.status, (info.name, got.diagnostics.reason)
        np.testing.assert_allclose(got.x, one.x, rtol=1e-12, atol=1e-12)
        assert (got.diagnostics.verification is None) == (one.diagnostics.verification is None)
        if verify == "none":
            assert got.verify_time_s == 0.0


@pytest.mark.parametrize("info", AVAILABLE, ids=lambda f: f.name)
def test_the_answer_is_typed_through_and_through(info):
    """No open dict: the solution holds a Diagnostics whose every field is typed, the
    formulation's record a dataclass of its own module, and no ``info``."""
    import dataclasses
    stack = _stacks_for(info, count=1)[0]
    sol = prioik.solve(stack, info.name, **_options_for(info, stack.n))
    assert not hasattr(sol, "info")
    assert type(sol.detail).__module__ == formulations.get(info.name).prepared.__module__
    assert dataclasses.is_dataclass(sol.detail)
    flat = sol.diagnostics.as_dict()
    assert set(flat) == {f.name for f in dataclasses.fields(sol.diagnostics)}
    assert set(flat["detail"]) == {f.name for f in dataclasses.fields(sol.detail)}


# ------------------------------------------ a clean answer's diagnostics, built when read
#: the formulations whose compiled clean answer builds its diagnostics at the first read
LAZY = ("hierarchical_active_set", "extended_jacobian")


def _steps(name: str, seed: int, count: int = 8) -> list[TaskStack]:
    """``count`` stacks of one layout, each a small move of the last (a control loop's
    steps): a seeded family stack, its rows, targets and bounds moved at every step. The
    active set's: inequality levels above equality ones (some level infeasible) for an
    even seed, compatible equality levels (none infeasible) for an odd one."""
    rng = np.random.default_rng(seed)
    if name != "hierarchical_active_set":
        stack = FAMILIES["weighted"](rng, 8, 3)
    elif seed % 2 == 0:
        stack = with_inequalities(rng, 8, 4)
    else:
        stack = FAMILIES["compatible"](rng, 8, 3)
    out = []
    for _ in range(count):
        levels = []
        for level in stack.levels:
            tasks = []
            for t in level:
                A = t.A + 0.05 * rng.standard_normal(t.A.shape)
                if t.is_equality:
                    tasks.append(Task(t.name, A, t.b + 0.2 * rng.standard_normal(t.m),
                                      weight=t.weight))
                else:
                    lower, upper = t.bounds()
                    shift = 0.05 * rng.standard_normal(t.m)
                    tasks.append(Task(t.name, A, lower=lower + shift, upper=upper + shift,
                                      weight=t.weight))
            levels.append(tasks)
        stack = TaskStack(levels)
        out.append(stack)
    return out


def _kernel_values(solver) -> dict:
    """What the solver's compiled kernel holds after its last solve, copied: the values a
    clean answer's diagnostics must give."""
    impl = solver._impl
    if solver.formulation == "hierarchical_active_set":
        cpp, k = impl._cpp, solver.layout.k
        return {"ranks": cpp.ranks[:k].copy(), "iterations": cpp.iterations.copy(),
                "level_violation": cpp.w2.copy(), "residuals": cpp.res.copy(),
                "infeasible_levels": np.flatnonzero(cpp.over[:k]).tolist()}
    return {}


def _assert_same_diagnostics(got, want) -> None:
    """Every field of two Diagnostics (and of their detail records) equal, arrays bit
    for bit and of the same dtype."""
    a, b = got.as_dict(), want.as_dict()
    assert set(a) == set(b)
    for key in a:
        x, y = a[key], b[key]
        if key == "detail":
            assert type(got.detail) is type(want.detail)
            assert set(x) == set(y)
            for field in x:
                _assert_same_value(x[field], y[field], f"detail.{field}")
        else:
            _assert_same_value(x, y, key)


def _assert_same_value(x, y, what: str) -> None:
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        assert isinstance(x, np.ndarray) and isinstance(y, np.ndarray), what
        assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), what
    else:
        assert type(x) is type(y) and x == y, (what, x, y)


@pytest.mark.parametrize("name", LAZY)
@pytest.mark.parametrize("seed", range(4))
def test_a_clean_answers_diagnostics_read_late_are_those_of_its_own_solve(name, seed):
    """Solve after solve on one prepared solver, every answer's diagnostics read only
    after the whole sequence: each equals the diagnostics the plugin builds at once for
    the same solve (a twin solver, the same sequence, through its Outcome), field by
    field, arrays bit for bit; the active set's ranks, iterations, level violations,
    residuals and infeasible levels are the kernel's right after that solve. At least
    one answer of each sequence took the clean path (diagnostics not yet built)."""
    steps = _steps(name, seed)
    solver = prioik.prepare(steps[0].layout, name)
    twin = prioik.prepare(steps[0].layout, name)
    answers, kernel, eager = [], [], []
    for stack in steps:
        data = stack.data
        sol = solver.solve(data)
        answers.append((sol, sol._snapshot is not None))
        kernel.append(_kernel_values(solver))
        out = twin._impl.solve(data)
        eager.append(out)
        assert np.array_equal(sol.x, out.x) and np.array_equal(sol.residuals, out.residuals)
    assert any(pending for _, pending in answers)
    for (sol, pending), want, out in zip(answers, kernel, eager, strict=True):
        _assert_same_diagnostics(sol.diagnostics, out.diagnostics)
        if pending and want:
            d = sol.diagnostics
            assert d.ranks.dtype == np.int64 and d.iterations.dtype == np.int64
            np.testing.assert_array_equal(d.ranks, want["ranks"])
            np.testing.assert_array_equal(d.iterations, want["iterations"])
            np.testing.assert_array_equal(d.detail.level_violation, want["level_violation"])
            np.testing.assert_array_equal(sol.residuals, want["residuals"])
            assert list(d.infeasible_levels) == want["infeasible_levels"]


@pytest.mark.parametrize("name", LAZY)
def test_a_solution_keeps_its_values_when_the_solver_solves_again(name):
    """Snapshot semantics: the first answer, its diagnostics not read yet, still gives
    its own solve's values after the solver solved another stack (whose values differ),
    and reading it twice gives the same object."""
    first_stack, second_stack = _steps(name, seed=11, count=2)
    solver = prioik.prepare(first_stack.layout, name)
    first = solver.solve(first_stack)
    assert first._snapshot is not None        # its diagnostics are not built yet
    x, residuals = first.x.copy(), first.residuals.copy()
    want = prioik.prepare(first_stack.layout, name)._impl.solve(first_stack.data).diagnostics
    second = solver.solve(second_stack)
    assert not np.array_equal(second.residuals, residuals)
    np.testing.assert_array_equal(first.x, x)
    np.testing.assert_array_equal(first.residuals, residuals)
    _assert_same_diagnostics(first.diagnostics, want)
    assert first.diagnostics is first.diagnostics
    if name == "hierarchical_active_set":
        assert not np.array_equal(second.detail.level_violation,
                                  first.detail.level_violation)


def test_a_solutions_diagnostics_can_be_set_and_default_to_empty():
    """A Solution made directly holds an empty Diagnostics; one assigned replaces a
    clean answer's pending one; a pending one survives a copy and a pickle."""
    import copy
    import pickle
    sol = prioik.Solution(np.zeros(2), "x", {}, prioik.Status.OPTIMAL, np.zeros(1), 0.0)
    assert sol.diagnostics == prioik.Diagnostics()
    stack = _steps("hierarchical_active_set", seed=3, count=1)[0]
    solver = prioik.prepare(stack.layout, "hierarchical_active_set")
    lazy = solver.solve(stack)
    assert lazy._snapshot is not None
    for other in (copy.deepcopy(lazy), pickle.loads(pickle.dumps(lazy))):
        _assert_same_diagnostics(other.diagnostics, lazy.diagnostics)
    mine = prioik.Diagnostics(reason="mine")
    again = solver.solve(stack)
    again.diagnostics = mine
    assert again.diagnostics is mine and again.detail is None


@pytest.mark.parametrize("name", LAZY)
def test_a_verify_mode_set_after_prepare_applies_to_clean_answers(name):
    """``solver.verify`` set after :func:`prioik.prepare` is validated and takes effect on
    the next clean answer: ``"certificate"`` certifies it (a verification recorded),
    ``"auto"`` leaves it unchecked again; an unknown mode is refused, naming the modes."""
    stack = _steps(name, seed=5, count=1)[0]
    solver = prioik.prepare(stack.layout, name)
    assert solver.solve(stack).diagnostics.verification is None
    solver.verify = "certificate"
    certified = solver.solve(stack)
    assert certified.status == "optimal"
    assert certified.diagnostics.verification.method == "certificate"
    assert certified.diagnostics.verification.ok
    solver.verify = "auto"
    assert solver.solve(stack).diagnostics.verification is None
    with pytest.raises(FormulationError, match="lower_point"):
        solver.verify = "everything"
    assert solver.verify == "auto"
