"""The registry: names, availability, option checks, failures as statuses."""

import dataclasses
import importlib

import numpy as np
import pytest
from conftest import stack_formulation

from prioik import formulations
from prioik.formulations import Capabilities, FormulationError, Option, Outcome, registry
from prioik.hierarchy import Task, TaskStack, UnsupportedTaskError
from prioik.hierarchy.families import compatible, same_shape_batch


@pytest.fixture
def stack():
    return compatible(np.random.default_rng(0), 6, 2)


def test_available_lists_every_registered_plugin_with_a_reason_when_not():
    infos = {f.name: f for f in formulations.available()}
    assert set(infos) == set(registry.PLUGINS)
    for f in infos.values():
        assert f.available or f.reason
        if f.available:
            assert f.description and isinstance(f.capabilities, Capabilities)
    assert infos["reference"].available and infos["extended_jacobian"].available


def test_unknown_formulation_lists_known_ones(stack):
    with pytest.raises(FormulationError, match="unknown formulation 'magic'; known: reference"):
        formulations.solve(stack, "magic")


def test_failed_import_is_recorded_and_repeated(monkeypatch, stack):
    monkeypatch.setitem(registry.PLUGINS, "ghost",
                        ("prioik.formulations._no_such_module", "ghostpkg"))
    monkeypatch.delitem(registry._failed, "ghost", raising=False)
    info = {f.name: f for f in formulations.available()}["ghost"]
    assert not info.available and "_no_such_module" in info.reason
    with pytest.raises(FormulationError, match="'ghost' is not available here: .*_no_such_module"):
        formulations.solve(stack, "ghost")


def test_unknown_option_is_named_with_the_accepted_ones(stack):
    with pytest.raises(FormulationError, match="has no option dampnig; its options: .*damping"):
        formulations.solve(stack, "extended_jacobian", dampnig=0.1)


def test_inequality_task_in_closed_form_method_names_the_task():
    s = TaskStack([Task("eq", np.eye(3)[[0]], [1.0]),
                   Task("joint_limits", np.eye(3), lower=[-1, -1, -1], upper=[1, 1, 1])])
    with pytest.raises(UnsupportedTaskError, match="level 1, task 'joint_limits'") as info:
        formulations.solve(s, "extended_jacobian")
    assert info.value.formulation == "extended_jacobian"


def _fake(monkeypatch, name, solve, caps=None):
    form = stack_formulation(name, solve, caps,
                             {"mass_matrix": Option(None, "matrix", "M", optional=True),
                              "bias": Option(None, "vector", "C+G", optional=True)},
                             "test double")
    monkeypatch.setitem(registry.PLUGINS, name, (f"tests.{name}", ""))
    monkeypatch.setitem(registry._loaded, name, form)
    return form


def test_linalg_failure_becomes_failed_status(monkeypatch, stack):
    def boom(stack, **_):
        raise np.linalg.LinAlgError("Singular matrix")
    _fake(monkeypatch, "boom", boom)
    sol = formulations.solve(stack, "boom")
    assert sol.status == "failed" and not sol.ok
    assert "LinAlgError: Singular matrix" in sol.diagnostics.reason
    assert np.isnan(sol.x).all() and np.isnan(sol.residuals).all()


def test_non_finite_answer_is_reported_failed(monkeypatch, stack):
    _fake(monkeypatch, "nanny", lambda stack, **_: Outcome(np.full(stack.n, np.nan)))
    sol = formulations.solve(stack, "nanny")
    assert sol.status == "failed" and "non-finite" in sol.diagnostics.reason


def test_mass_matrix_is_required_validated_and_never_mutated(monkeypatch, stack):
    seen = {}

    def record(stack, mass_matrix=None, bias=None):
        seen["M"] = mass_matrix
        return Outcome(np.zeros(stack.n))
    _fake(monkeypatch, "dyn", record, Capabilities(needs_mass_matrix=True))
    with pytest.raises(FormulationError, match="needs mass_matrix=M .the 6x6"):
        formulations.solve(stack, "dyn")
    with pytest.raises(FormulationError,
                       match="option 'mass_matrix' must be 6x6 .* shape \\(5, 5\\)"):
        formulations.solve(stack, "dyn", mass_matrix=np.eye(5))
    with pytest.raises(FormulationError, match="must be symmetric"):
        formulations.solve(stack, "dyn", mass_matrix=np.triu(np.ones((6, 6))))
    with pytest.raises(FormulationError, match="option 'bias' must be a finite vector of length 6"):
        formulations.solve(stack, "dyn", mass_matrix=np.eye(6), bias=[np.nan] * 6)
    M = np.eye(6)
    formulations.solve(stack, "dyn", mass_matrix=M)
    assert seen["M"] is not M and not seen["M"].flags.writeable


@pytest.mark.parametrize("name", ["reference", "extended_jacobian"])
def test_solve_does_not_mutate_inputs_and_reports_time(name, stack):
    before = [(t.A.copy(), t.b.copy()) for t in stack.tasks]
    sol = formulations.solve(stack, name)
    assert sol.time_s > 0 and sol.formulation == name and sol.residuals.shape == (2,)
    for (A, b), t in zip(before, stack.tasks, strict=False):
        np.testing.assert_array_equal(A, t.A)
        np.testing.assert_array_equal(b, t.b)


def test_solve_accepts_a_plain_list_of_levels():
    sol = formulations.solve([Task("a", np.eye(2), [1.0, 2.0])], "reference")
    np.testing.assert_allclose(sol.x, [1.0, 2.0])


@pytest.mark.parametrize("name, batched", [("reference", True), ("chiaverini", False),
                                           ("cascaded_qp", False)])
def test_solve_batch_loops_and_matches_single_solves(name, batched):
    # four stacks of one shape (same_shape_batch keeps the rows, turns and re-targets
    # them): every one is compared, through the plugin's batched kernel (reference)
    # and through the registry's loop over solve (plugins without solve_batch)
    base = compatible(np.random.default_rng(0), 10, 3)
    stacks = same_shape_batch(base, np.random.default_rng(1), 4)
    assert len(stacks) == 4
    batch = formulations.solve_batch(stacks, name)
    assert batch.batched is batched
    assert batch.X.shape == (4, 10)
    singles = [formulations.solve(s, name) for s in stacks]
    for x, one in zip(batch.X, singles, strict=False):
        np.testing.assert_allclose(x, one.x, atol=1e-9)
    assert batch.statuses == [one.status for one in singles]
    assert "failed" not in batch.statuses and batch.time_per_stack_s > 0


def test_solve_batch_loop_marks_a_failing_stack_failed(monkeypatch):
    def boom(stack, **kw):
        if stack.levels[0].b[0] > 0:
            raise np.linalg.LinAlgError("singular")
        return Outcome(np.zeros(stack.n))
    monkeypatch.setitem(registry._loaded, "fake", stack_formulation("fake", boom))
    monkeypatch.setitem(registry.PLUGINS, "fake", ("fake", ""))
    stacks = [TaskStack([Task("a", np.eye(2), [v, 0.0])]) for v in (-1.0, 1.0)]
    batch = formulations.solve_batch(stacks, "fake")
    assert not batch.batched and batch.statuses == ["optimal", "failed"]
    assert np.isnan(batch.X[1]).all()


def test_solve_batch_rejects_mixed_shapes():
    a = TaskStack([Task("a", np.eye(3)[[0]], [1.0])])
    b = TaskStack([Task("a", np.eye(3)[[0, 1]], [1.0, 2.0])])
    with pytest.raises(FormulationError, match="stack 1 of the batch: .*prepared for the "
                                               "layout n=3: a\\[1\\]; got .* a\\[2\\]"):
        formulations.solve_batch([a, b], "reference")


def test_compile_kernels_does_nothing_and_checks_names():
    """The compiled solvers are C++ built at install: nothing is compiled, nothing
    reported; an unknown name is still refused."""
    seen = []
    assert formulations.compile_kernels(progress=lambda n, s: seen.append(n)) == []
    assert formulations.compile_kernels(["extended_jacobian", "reference"]) == []
    assert seen == []
    with pytest.raises(FormulationError, match="unknown formulation 'nope'"):
        formulations.compile_kernels(["nope"])


def test_a_first_solve_in_a_fresh_process_compiles_nothing():
    """The first solve of each compiled formulation in a new process waits for no
    compiler (the core is built at install): well under a second each (a loose bound
    for a loaded test machine)."""
    import subprocess
    import sys
    code = (
        "import time\n"
        "import numpy as np\n"
        "from prioik import formulations\n"
        "from prioik.hierarchy.families import FAMILIES, random_inequality_hierarchy\n"
        "rng = np.random.default_rng(1)\n"
        "cases = (('extended_jacobian', FAMILIES['conflicting'](rng, 12, 3)),\n"
        "         ('hierarchical_active_set', random_inequality_hierarchy(rng, 12, 3)))\n"
        "for name, stack in cases:\n"
        "    t = time.perf_counter()\n"
        "    formulations.solve(stack, name)\n"
        "    print(time.perf_counter() - t)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True).stdout.split()
    assert len(out) == 2 and all(float(t) < 2.0 for t in out), out



# ------------------------------------------------------------------ hard levels
def _contradictory_hard_top(hard_top: bool = True) -> TaskStack:
    """Level 0 asks x0 = 1 and x0 = -1 (its least-squares optimum: x0 = 0, residual
    √2); level 1 a posture. Declared hard, level 0 cannot hold."""
    from prioik.hierarchy import hard
    up = Task("up", np.array([[1.0, 0.0, 0.0]]), np.array([1.0]))
    down = Task("down", np.array([[1.0, 0.0, 0.0]]), np.array([-1.0]))
    posture = Task("posture", np.eye(3), np.array([0.5, -0.25, 2.0]))
    top = up + down
    return TaskStack([hard(top) if hard_top else top, posture])


def _options(info, n):
    from prioik.hierarchy.families import random_spd
    return ({"mass_matrix": random_spd(np.random.default_rng(1), n)}
            if info.capabilities.needs_mass_matrix else {})


RUNNABLE = [f for f in formulations.available() if f.available and f.capabilities.equalities]


@pytest.mark.parametrize("info", RUNNABLE, ids=lambda f: f.name)
def test_a_contradictory_hard_top_level_fails_naming_it_on_every_formulation(info):
    """The least-squares compromise of a contradictory level is what every formulation
    returns (residual √2 at level 0); declared hard, the answer is "failed" with the
    fault naming level 0 and its tasks — the same check for every plugin, made once
    where statuses are finalised. Undeclared, the status is the formulation's own."""
    stack = _contradictory_hard_top()
    opts = _options(info, stack.n)
    soft = formulations.solve(_contradictory_hard_top(hard_top=False), info.name, **opts)
    sol = formulations.solve(stack, info.name, **opts)
    assert soft.status != "failed", soft.diagnostics.reason
    np.testing.assert_allclose(sol.x, soft.x, rtol=0, atol=1e-12)  # the same answer
    assert sol.residuals[0] == pytest.approx(np.sqrt(2.0), rel=1e-6)
    assert sol.status == "failed"
    fault = sol.diagnostics.fault
    assert fault.level == 0 and fault.tasks == ("up", "down") and fault.code == "hard_level"
    assert sol.diagnostics.hard_violated_levels == [0]
    assert fault.message.startswith("hard level 0 (up, down) is left violated: "
                                    "residual 1.41")
    assert sol.diagnostics.reason == fault.message
    solver = formulations.prepare(stack.layout, info.name, **opts)
    batch = solver.solve_batch([stack, stack])
    assert list(batch.statuses) == ["failed", "failed"]


@pytest.mark.parametrize("info", RUNNABLE, ids=lambda f: f.name)
def test_a_hard_level_that_holds_leaves_the_status_as_it_was(info):
    """Level 1 hard and satisfiable below a free level 0: an exact formulation's answer
    holds it, and its status is unchanged; a formulation with algorithmic error (or soft
    priorities) that leaves it violated is "failed" for it."""
    from prioik.hierarchy import hard, hard_violations
    rng = np.random.default_rng(7)
    top = Task("top", rng.normal(size=(2, 5)), rng.normal(size=2))
    held = Task("held", rng.normal(size=(2, 5)), rng.normal(size=2))
    rest = Task("rest", np.eye(5), np.zeros(5))
    stack = TaskStack([top, hard(held), rest])
    assert stack.hard == (1,) and stack.layout.hard == (1,)
    opts = _options(info, stack.n)
    plain = formulations.solve(TaskStack([top, held, rest]), info.name, **opts)
    sol = formulations.solve(stack, info.name, **opts)
    np.testing.assert_array_equal(sol.x, plain.x)
    violated = hard_violations(stack.data, plain.x)
    if info.capabilities.exact:
        assert violated == [] and sol.status == plain.status == "optimal"
        assert not sol.diagnostics.hard_violated_levels
    else:
        assert sol.status == ("failed" if violated else plain.status)
        assert list(sol.diagnostics.hard_violated_levels) == [v[0] for v in violated]


def test_a_new_formulation_gets_the_hard_check_with_no_edit(toy_plugin):
    from conftest import TOY
    sol = formulations.solve(_contradictory_hard_top(), TOY)
    assert sol.status == "failed" and sol.diagnostics.fault.level == 0
    assert formulations.solve(_contradictory_hard_top(hard_top=False), TOY).status != "failed"


# ------------------------------------------------------------------ typed results
@pytest.mark.parametrize("info", RUNNABLE, ids=lambda f: f.name)
def test_every_formulation_returns_a_status_and_its_own_detail_record(info):
    """Every plugin: the status is a Status equal to its string, the diagnostics a
    Diagnostics, and the detail the plugin module's own dataclass ``Detail``."""
    from prioik.formulations import Diagnostics, Status
    stack = compatible(np.random.default_rng(3), 6, 2)
    sol = formulations.solve(stack, info.name, **_options(info, stack.n))
    assert isinstance(sol.status, Status) and sol.status == sol.status.value
    assert str(sol.status) == f"{sol.status}" == sol.status.value
    assert isinstance(sol.diagnostics, Diagnostics)
    module = importlib.import_module(registry.PLUGINS[info.name][0])
    assert type(sol.detail) is module.Detail
    assert dataclasses.is_dataclass(sol.detail)
    assert (sol.status == "optimal") == (sol.diagnostics.reason == "")
    assert sol.time_s > 0 and sol.verify_time_s >= 0


@pytest.mark.parametrize("info", RUNNABLE, ids=lambda f: f.name)
def test_verify_none_checks_nothing_and_takes_no_time(info):
    """``verify="none"``: no verification stage (no verdict recorded, verify_time_s 0)
    and the formulation's own status, never a demotion: what "auto" says is never more
    than what "none" says."""
    stack = compatible(np.random.default_rng(4), 6, 3)
    opts = _options(info, stack.n)
    none = formulations.solve(stack, info.name, verify="none", **opts)
    auto = formulations.solve(stack, info.name, **opts)
    assert none.verify_time_s == 0.0
    own = none.diagnostics.verification
    assert own is None or own.method == "solver"       # a solver's own certificate only
    np.testing.assert_array_equal(none.x, auto.x)
    rank = {"optimal": 0, "approximate": 1, "failed": 2}
    assert rank[none.status] <= rank[auto.status]


def _perturbed_plugin(monkeypatch, ask: bool):
    """A registered formulation answering the exact optimum moved by 1e-3 along a
    level's rows, and saying ``optimal`` (asking to be certified when ``ask``)."""
    from prioik.formulations.base import CheckRequest, Diagnostics

    @dataclasses.dataclass
    class Detail:
        moved: float

    def solve(stack, **_):
        x = formulations.solve(stack, "reference").x + 1e-3 * stack.levels[0].A[0]
        return Outcome(x, "optimal", Diagnostics(detail=Detail(1e-3)),
                       check=CheckRequest(auto=ask))

    _fake(monkeypatch, "perturbed", solve)


def test_the_certificate_demotes_a_perturbed_answer_and_none_does_not(monkeypatch, stack):
    """An answer 1e-3 off the optimum said ``optimal`` by its plugin: ``"certificate"``
    and ``"lower_point"`` demote it, naming the level at fault; ``"none"`` and ``"auto"``
    (the plugin did not ask) leave it; asked, ``"auto"`` demotes it too."""
    _perturbed_plugin(monkeypatch, ask=False)
    for mode in ("certificate", "lower_point"):
        sol = formulations.solve(stack, "perturbed", verify=mode)
        assert sol.status == "approximate", mode
        v = sol.diagnostics.verification
        assert v.method == mode and v.ok is False
        assert sol.diagnostics.fault.code == "certificate" and sol.diagnostics.fault.level == 0
        assert sol.diagnostics.reason == sol.diagnostics.fault.message
        assert sol.verify_time_s > 0
    for mode in ("none", "auto"):
        sol = formulations.solve(stack, "perturbed", verify=mode)
        assert sol.status == "optimal" and sol.diagnostics.verification is None, mode
    _perturbed_plugin(monkeypatch, ask=True)
    assert formulations.solve(stack, "perturbed").status == "approximate"
    assert formulations.solve(stack, "perturbed", verify="none").status == "optimal"


def _perturbed_batched_plugin(monkeypatch, ask: bool):
    """:func:`_perturbed_plugin` with a batched kernel: each stack's answer moved by 1e-3,
    ``optimal``, a check asked (``ask``) or none."""
    from prioik.formulations.base import CheckRequest

    form = _fake(monkeypatch, "perturbed_batch", lambda stack, **_: None)

    class Batched(form.prepared):
        def solve_batch(self, datas):
            X = np.array([formulations.solve(d.as_stack(), "reference").x
                          + 1e-3 * d.A[0] for d in datas])
            return X, ["optimal"] * len(datas), [CheckRequest() if ask else None] * len(datas)

    monkeypatch.setitem(registry._loaded, "perturbed_batch",
                        dataclasses.replace(form, prepared=Batched))


def test_a_batched_kernels_answers_go_through_the_verification_stage(monkeypatch, stack):
    """A batched kernel's ``optimal`` answers 1e-3 off the optimum: the stage demotes
    them under ``"certificate"``, and under ``"auto"`` when the kernel asked; ``"none"``
    never; nothing in the plugin certifies."""
    stacks = [stack, stack]
    _perturbed_batched_plugin(monkeypatch, ask=False)
    assert formulations.solve_batch(stacks, "perturbed_batch").batched
    for mode, status in (("none", "optimal"), ("auto", "optimal"),
                         ("certificate", "approximate"), ("lower_point", "approximate")):
        got = formulations.solve_batch(stacks, "perturbed_batch", verify=mode).statuses
        assert got == [status, status], mode
    _perturbed_batched_plugin(monkeypatch, ask=True)
    assert formulations.solve_batch(stacks, "perturbed_batch").statuses == ["approximate"] * 2
    assert formulations.solve_batch(stacks, "perturbed_batch",
                                    verify="none").statuses == ["optimal"] * 2


def test_the_extended_jacobian_batch_asks_the_stage_instead_of_certifying():
    """The compiled batch leaves certification to the stage: its module imports no
    certificate, and a near-ambiguous answer's check comes back with the batch."""
    from prioik.formulations import extended_jacobian
    assert not hasattr(extended_jacobian, "certify")
    statuses, checks = extended_jacobian._batch_statuses(
        np.zeros((2, 2)), np.array([[1e6, 1e6], [extended_jacobian.NEAR_AMBIGUITY
                                                 * extended_jacobian.AMBIGUITY * 0.5, 1e6]]))
    assert statuses == ["optimal", "optimal"]
    assert checks[0] is None and checks[1] is not None


def test_an_unknown_verify_mode_is_refused_naming_the_modes(stack):
    with pytest.raises(FormulationError, match="verify must be one of auto, none, "
                                               "certificate, lower_point; got 'all'"):
        formulations.prepare(stack.layout, "reference", verify="all")


@pytest.mark.skipif("daqp_hierarchical" not in {f.name for f in RUNNABLE},
                    reason="daqp is not installed")
def test_daqp_hierarchical_timed_solve_does_not_run_the_active_set(monkeypatch):
    """``check=True`` (default): the active set runs in the verification stage (the
    lower-point comparison), never inside DAQP's timed solve."""
    from prioik.formulations import daqp_hierarchical as dh
    from prioik.formulations import hierarchical_active_set as has
    calls = {"active_set": 0, "inside": 0}
    original_solve, original_active = dh.solve, has.Prepared.solve

    def active(self, data, options=None):
        calls["active_set"] += 1
        return original_active(self, data, options)

    def timed(stack, **options):
        before = calls["active_set"]
        out = original_solve(stack, **options)
        calls["inside"] += calls["active_set"] - before
        return out

    monkeypatch.setattr(has.Prepared, "solve", active)
    monkeypatch.setattr(dh, "solve", timed)
    stack = compatible(np.random.default_rng(5), 6, 3)
    sol = formulations.solve(stack, "daqp_hierarchical")
    assert sol.status == "optimal" and sol.diagnostics.verification.method == "lower_point"
    assert calls["inside"] == 0 and calls["active_set"] >= 1
    assert sol.verify_time_s > 0


def test_the_verification_solver_is_prepared_once_per_prepared_solver(monkeypatch):
    """The exact active set of the lower-point comparison is prepared at the first
    verification and kept for every later one."""
    from prioik.formulations import prepared as prepared_module
    built = []
    original = prepared_module.lower_point_solver

    def counting(layout):
        built.append(layout)
        return original(layout)

    monkeypatch.setattr(prepared_module, "lower_point_solver", counting)
    base = compatible(np.random.default_rng(6), 6, 3)
    stacks = same_shape_batch(base, np.random.default_rng(7), 5)
    solver = formulations.prepare(base.layout, "reference", verify="lower_point")
    sols = [solver.solve(s) for s in stacks]
    assert [s.diagnostics.verification.method for s in sols] == ["lower_point"] * 5
    assert all(s.status == "optimal" for s in sols)
    assert len(built) == 1


# ------------------------------------------------------------------ the contract
def test_every_plugin_declares_a_formulation_with_its_own_prepared_class():
    """Each registered module's FORMULATION is a Formulation of its name whose prepared
    solver is a subclass of contract.Prepared defined in that module."""
    import importlib

    from prioik.formulations import contract
    for name, (module, _) in registry.PLUGINS.items():
        try:
            mod = importlib.import_module(module)
        except ImportError:
            continue            # its extra is not installed here
        form = mod.FORMULATION
        assert isinstance(form, contract.Formulation) and form.name == name
        assert issubclass(form.prepared, contract.Prepared), name
        assert form.prepared.__module__ == module, name
        assert form.prepared is not contract.StackPrepared
        assert registry.get(name) is form


def test_the_registry_and_the_prepared_solver_probe_nothing():
    """The plugin contract is declared (contract.py), not discovered: no getattr or
    hasattr call in registry.py or prepared.py."""
    import ast
    import pathlib
    root = pathlib.Path(registry.__file__).parent
    for path in (root / "registry.py", root / "prepared.py"):
        calls = [node.func.id for node in ast.walk(ast.parse(path.read_text()))
                 if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                 and node.func.id in ("getattr", "hasattr")]
        assert calls == [], path.name


def test_a_formulations_settings_are_a_typed_dataclass_of_its_options():
    import dataclasses

    import numpy as np
    form = registry.get("extended_jacobian")
    settings = form.settings
    assert settings.__name__ == "ExtendedJacobianSettings"
    fields = {f.name: f for f in dataclasses.fields(settings)}
    assert list(fields) == list(form.options)
    assert fields["damping"].type is float and fields["kernel"].type is str
    assert fields["damping"].metadata["description"] == form.options["damping"].description
    values = settings()
    assert values.damping == form.options["damping"].default
    with pytest.raises(dataclasses.FrozenInstanceError):
        values.damping = 1.0
    solver = formulations.prepare(TaskStack([Task("a", np.eye(2), [1.0, 2.0])]),
                                  "extended_jacobian", damping=0.1)
    assert settings(**solver.options).damping == 0.1
    metric = registry.get("reference").settings.__dataclass_fields__["metric"]
    assert metric.type == np.ndarray | None and metric.default is None
