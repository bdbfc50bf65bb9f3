"""Fuzzing: seeded random stacks (hierarchy/fuzz.py) through every fuzzed path
(benchmarks/fuzz.py), plus hypothesis over the generator's seed.

Every property of ``prioik fuzz`` must hold on every stack: no exception but the
library's own, no NaN unless ``failed``, ``optimal`` only when
``check_lexicographic`` passes (and, on well-conditioned stacks, within 1e-6 of the
independent nested-SVD truth), ``solve`` = ``solve_batch`` = a reused prepared solver, and
threads sharing a solver give the serial answers. The bulk runs use the issue's
families at smaller sizes (``n ≤ 12``, ``≤ 5`` levels of ``≤ 8`` rows a task) so that
a few thousand stacks fit in the suite; ``prioik fuzz`` runs the full sizes.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import stack_formulation
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prioik import formulations
from prioik.benchmarks import fuzz
from prioik.cli import main
from prioik.formulations import Outcome, registry
from prioik.hierarchy import check_lexicographic, load_stack, relative_distance
from prioik.hierarchy.fuzz import ROW_FEATURES, equality_case, inequality_case, nested_truth

SMALL = {"max_n": 12, "max_levels": 5, "max_rows": 8}
SMALL_INEQ = {"max_n": 8, "max_levels": 4, "max_rows": 6}


def _assert_clean(report: fuzz.FuzzReport, known: dict | None = None) -> None:
    """No failure but the ``known`` open ones (``{(case, path, kind): why}``), and every
    known one still failing (a fixed one must leave the list)."""
    lines = [f"{f.case} {f.path}: {f.kind}: {f.message}" for f in report.failures[:20]]
    found = {(f.case, f.path, f.kind) for f in report.failures}
    assert found == set(known or {}), "\n" + report.table() + "\n" + "\n".join(lines)


#: Failures of the in-suite runs that are open (reported, not resolved), each with why:
#: none. (inequality-5-363, bounds-5-57: the certificate read rounding along the null
#: directions of a level at 1/floor; bounds-5-77: a box row's tolerance was relative to
#: ‖a_j‖‖x‖ = 1e11 — both fixed, a failure here is new.)
KNOWN_OPEN: dict = {}


# ------------------------------------------------------------------ generator
def test_generator_draws_every_family_and_size():
    cases = [equality_case(np.random.default_rng([7, i])) for i in range(300)]
    features = {f for c in cases for level in c.features for f in level}
    assert features == set(ROW_FEATURES)
    ns = [c.stack.n for c in cases]
    ks = [len(c.stack) for c in cases]
    assert min(ns) <= 3 and max(ns) >= 55 and min(ks) == 1 and max(ks) == 12
    assert max(t.m for c in cases for t in c.stack.tasks) >= 35
    weights = [float(w) for c in cases for t in c.stack.tasks for w in t.weight]
    assert min(weights) < 1e-4 and max(weights) > 1e4
    scales = [np.abs(t.A).max() for c in cases for t in c.stack.tasks if np.abs(t.A).max()]
    assert min(scales) < 1e-10 and max(scales) > 1e7
    well = [c.well_conditioned for c in cases]
    assert 0.3 < np.mean(well) < 0.95          # both kinds are drawn


def test_bounds_generator_draws_every_kind_of_box():
    """Box rows of both signs and scales, boxes that exclude 0, one-sided and zero-width
    ones, columns boxed twice, boxes that do not meet (sns refuses those), and the
    equality families below."""
    from prioik.hierarchy.fuzz import bounds_case
    cases = [bounds_case(np.random.default_rng([7, i])) for i in range(300)]
    boxes = [c.stack.levels[0][0] for c in cases]
    assert all(c.kind == "bounds" and (np.count_nonzero(b.A, axis=1) == 1).all()
               for c, b in zip(cases, boxes, strict=False))
    factors = np.concatenate([b.A[b.A != 0] for b in boxes])
    assert factors.min() < -100 and factors.max() > 100 and np.abs(factors).min() < 1e-2
    lo, up = np.concatenate([b.lower for b in boxes]), np.concatenate([b.upper for b in boxes])
    assert np.isinf(lo).any() and np.isinf(up).any() and (lo == up).any()
    assert ((lo > 0) | (up < 0)).any()                         # 0 outside the box
    assert any(np.count_nonzero(b.A, axis=0).max() > 1 for b in boxes)
    refused = 0
    for c in cases[:100]:
        try:
            formulations.solve(c.stack, "sns")
        except formulations.FormulationError:
            refused += 1
    assert 0 < refused < 30
    features = {f for c in cases for level in c.features[1:] for f in level}
    assert features == set(ROW_FEATURES)


def test_generator_is_reproducible_from_the_seed():
    a = equality_case(np.random.default_rng([3, 17]))
    b = fuzz.draw("equality", 3, 17)
    assert [t.name for t in a.stack.tasks] == [t.name for t in b.stack.tasks]
    assert all(np.array_equal(s.A, t.A) for s, t in zip(a.stack.tasks, b.stack.tasks, strict=False))


def test_truth_is_the_lexicographic_optimum_of_well_conditioned_stacks():
    """The independent truth agrees with reference and passes the certificate."""
    checked = 0
    for i in range(60):
        case = equality_case(np.random.default_rng([11, i]), **SMALL)
        if not case.well_conditioned:
            continue
        checked += 1
        assert check_lexicographic(case.stack, case.truth).ok
        ref = formulations.solve(case.stack, "reference").x
        assert relative_distance(ref, case.truth) <= fuzz.WRONG_TOL
    assert checked >= 20


def test_truth_reports_an_ambiguous_decision():
    from prioik.hierarchy import Task, TaskStack
    A = np.array([[1.0, 0.0], [0.0, 1e-10]])         # σ/‖A‖ = 1e-10: in the band
    x, gap, sigma = nested_truth(TaskStack([Task("a", A, [1.0, 1.0])]))
    assert gap < 0
    x, gap, sigma = nested_truth(TaskStack([Task("a", np.eye(2), [1.0, 1.0])]))
    assert gap > 0 and sigma == pytest.approx(1 / np.sqrt(2))


# ------------------------------------------------------------------ bulk runs
@pytest.mark.slow
@pytest.mark.parametrize("chunk", range(4))
def test_equality_stacks_hold_every_property(chunk):
    """1,600 equality stacks (4 × 400), every path; batch compared on every 4th,
    threads on every 100th."""
    report = fuzz.run(400, 1000 + chunk, sizes=SMALL, batch_every=4, thread_every=100)
    _assert_clean(report, {k: v for k, v in KNOWN_OPEN.items()
                           if k[0].startswith(f"equality-{1000 + chunk}-")})
    assert report.well_conditioned > 100
    for path in ("ej_qr_cpp", "nullspace", "hierarchical_active_set", "sns"):
        assert report.solves[path] == 400


@pytest.mark.slow
def test_full_size_equality_stacks_hold_every_property():
    """Stacks of the full sizes (n ≤ 60, 12 levels of 40 rows a task)."""
    _assert_clean(fuzz.run(40, 77, batch_every=4, thread_every=20))


@pytest.mark.slow
def test_inequality_stacks_hold_every_property():
    """400 inequality stacks through the QP formulations, the active set and SNS (which
    refuses the stacks whose inequality tasks are not first-level boxes)."""
    report = fuzz.run(400, 5, kinds=("inequality",), sizes=SMALL_INEQ, batch_every=4,
                      thread_every=100)
    _assert_clean(report, {k: v for k, v in KNOWN_OPEN.items() if "inequality" in k[0]})
    assert report.solves["cascaded_qp"] == report.solves["hierarchical_active_set"] == 400
    assert report.statuses["sns"].get("optimal", 0) > 20


@pytest.mark.slow
def test_bounds_stacks_hold_every_property():
    """400 stacks of box bounds on top of equality levels (hierarchy.fuzz.bounds_case):
    SNS's bounded path, the active set and the QP formulations."""
    report = fuzz.run(400, 5, kinds=("bounds",), sizes=SMALL_INEQ, batch_every=4,
                      thread_every=100)
    _assert_clean(report, {k: v for k, v in KNOWN_OPEN.items() if "bounds" in k[0]})
    assert report.solves["sns"] == report.solves["hierarchical_active_set"] == 400
    st = report.statuses["sns"]
    assert st.get("optimal", 0) > 50 and st.get("approximate", 0) > 100 and \
        st.get("refused", 0) < 40       # refused: boxes of one column that do not meet


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 32 - 1))
def test_hypothesis_equality_stacks(seed):
    case = equality_case(np.random.default_rng(seed), seed, **SMALL)
    report = fuzz.FuzzReport()
    fuzz._Runner(report, threads=2, keep=20).run_case(
        f"equality-{seed}", case, [p for p in fuzz.registry_paths().values()
                                  if fuzz.takes(p, "equality")],
        check_threads=False)
    _assert_clean(report)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 32 - 1))
def test_hypothesis_inequality_stacks(seed):
    case = inequality_case(np.random.default_rng(seed), seed, **SMALL_INEQ)
    report = fuzz.FuzzReport()
    fuzz._Runner(report, threads=2, keep=20).run_case(
        f"inequality-{seed}", case, [fuzz.registry_paths()["cascaded_qp"]], check_threads=False)
    _assert_clean(report)


@pytest.mark.parametrize("path", sorted(
    (Path(__file__).parent / "data" / "fuzz").glob("*.json")), ids=lambda p: p.stem)
def test_saved_fuzz_failures_now_hold_every_property(path):
    """The stacks ``prioik fuzz`` saved when a path failed on them (tests/data/fuzz, each
    file's description says which and how), through every path that takes their kind."""
    stack = load_stack(path)
    kind = path.stem.split("-")[0]
    exact = None
    if kind in fuzz.EQUALITY_KINDS:
        from prioik.hierarchy.fuzz import judged
        case = judged(stack)
        case.kind = kind
        if kind == "mixed_scale":
            from prioik.hierarchy.exact import exact_optimum
            exact = exact_optimum(stack)
    else:
        from prioik.hierarchy.fuzz import FuzzCase
        case = FuzzCase(stack, 0, kind)
    report = fuzz.FuzzReport()
    fuzz._Runner(report, threads=2, keep=20).run_case(
        path.stem, case, [p for p in fuzz.registry_paths().values() if fuzz.takes(p, kind)],
        check_threads=True, exact=exact)
    _assert_clean(report)


# ------------------------------------------------------------ the fuzz itself
@pytest.fixture
def wrong_plugin(monkeypatch):
    """A formulation that answers 0 and says ``optimal``: every check must see it."""
    form = stack_formulation("always_zero", lambda stack: Outcome(np.zeros(stack.n), "optimal"))
    monkeypatch.setitem(registry._loaded, "always_zero", form)
    monkeypatch.setitem(registry.PLUGINS, "always_zero", ("always_zero", ""))
    return "always_zero"        # fuzzed as registered: no edit of the fuzz


def test_a_wrong_formulation_is_caught_and_its_stacks_saved_for_prioik_solve(
        wrong_plugin, tmp_path, capsys):
    report = fuzz.run(30, 4, paths=[wrong_plugin], sizes=SMALL, thread_every=0,
                      out=tmp_path)
    counts = report.counts[wrong_plugin]
    assert counts["wrong"] > 0 and counts["uncertified"] > 0
    files = sorted(tmp_path.glob("equality-4-*.json"))
    assert len(files) == len({f.case for f in report.failures})
    text = json.loads(files[0].read_text())
    assert "always_zero: " in text["description"]
    index = int(files[0].stem.split("-")[-1])
    saved = load_stack(files[0])
    drawn = fuzz.draw("equality", 4, index, SMALL).stack
    assert all(np.array_equal(a.A, b.A) for a, b in zip(saved.tasks, drawn.tasks, strict=False))
    assert main(["solve", str(files[0]), "-f", "reference"]) == 0
    assert "status: " in capsys.readouterr().out


def test_prioik_fuzz_command(tmp_path, capsys):
    code = main(["fuzz", "--n", "5", "--seed", "3", "--kind", "all", "--thread-every", "0",
                 "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert "5 equality stacks" in out and "5 inequality stacks" in out
    assert "5 bounds stacks" in out and "5 mixed_scale stacks" in out
    assert "| ej_qr_cpp | 10 |" in out and "| cascaded_qp | 10 |" in out
    assert "| hierarchical_active_set | 20 |" in out and "| sns | 20 |" in out
    assert "| above |" in out
    assert code == (1 if "failing stacks saved" in out else 0)


def test_the_fuzz_takes_its_formulations_from_the_registry(toy_plugin):
    """Every registered formulation is fuzzed by its defaults on the kinds its
    capabilities take, unless the fuzz's SETTINGS give its paths or LEFT_OUT leaves it
    out (with a reason): a formulation registered for a test is among the paths."""
    from conftest import TOY
    known = fuzz.registry_paths()
    assert set(fuzz.LEFT_OUT) | set(fuzz.SETTINGS) <= set(formulations.names())
    assert not set(fuzz.LEFT_OUT) & set(known)
    assert all(reason for reason in fuzz.LEFT_OUT.values())
    for name in formulations.names():
        assert name in fuzz.LEFT_OUT or any(p.formulation == name for p in known.values())
    assert known[TOY] == fuzz.Path_(TOY, TOY, {})
    assert fuzz.kinds_of(known[TOY]) == ("equality",)          # its capabilities
    assert fuzz.kinds_of(known["sns"]) == ("equality", "inequality", "bounds")
    assert fuzz.kinds_of(known["cascaded_qp"]) == ("inequality", "bounds")   # SETTINGS
    assert [p.name for p in known.values() if p.formulation == "extended_jacobian"] == \
        ["ej_qr_cpp", "ej_qr_lapack", "ej_svd"]
    report = fuzz.run(3, 1, paths=[TOY], sizes=SMALL, thread_every=0)
    assert report.solves == {TOY: 3} and report.statuses[TOY] == {"approximate": 3}


def test_prioik_fuzz_refuses_an_unknown_path(capsys):
    assert main(["fuzz", "--n", "1", "--paths", "magic"]) == 2
    assert "unknown fuzz path 'magic'" in capsys.readouterr().err


def test_rotation_spread_sees_rounding_the_per_level_bound_misses():
    """Fuzz equality-101-579 (n 55): level 0 keeps a singular value 1.05e-6 of its norm
    (κ 1e6), level 3 one of 6.6e-6 below it. A 40-digit nested SVD (mpmath, same rank
    decisions) puts reference, nullspace and sns 2.4e-5 from it, the extended Jacobian
    1.7e-5, the active set 4.3e-6 and the fuzz's own float64 truth 8.7e-6: rounding
    turns level 0's null space by ~ε κ_0 and level 3 amplifies that. Wedin's bound per
    level read 2e-9 and judged the stack well-conditioned, so three paths were
    'wrong'; the truth of the rotated problem is 2.4e-5 from the truth, and the stack is
    not judged on x. The saved svd-path stacks 972 and 1071 (right to 3e-10 and 5e-10)
    stay judged."""
    from prioik.hierarchy.fuzz import CONDITIONED_ERROR, judged, rotation_spread, rounding_error
    case = judged(load_stack(Path(__file__).parent / "data" / "fuzz" / "equality-101-579.json"))
    assert rounding_error(case.stack, case.truth) < CONDITIONED_ERROR
    assert rotation_spread(case.stack, case.truth) > 10 * CONDITIONED_ERROR
    assert case.rounding_error > 10 * CONDITIONED_ERROR and not case.well_conditioned
    for name in ("equality-2026-972", "equality-2026-1071"):
        kept = judged(load_stack(Path(__file__).parent / "data" / "fuzz" / f"{name}.json"))
        assert kept.well_conditioned and kept.rounding_error < CONDITIONED_ERROR


def test_a_reused_solvers_variant_is_judged_by_its_own_rounding():
    """Seed 303, case 842 (n 58): a prepared hierarchical_active_set reused over the
    stack's same-shape variants answered variant 1 (warm: its equality rows alone)
    1.02e-6 from the one-off solve, both 'optimal' and certified; the variant's own
    rounding bound is 1.1e-5 (the truth 3e-6 from both), but the prepared comparison
    judged variants at the fixed 1e-6. It now takes the variant's own bound, as the
    solve_batch comparison did."""
    case = fuzz.draw("equality", 303, 842)
    report = fuzz.FuzzReport()
    fuzz._Runner(report, threads=2, keep=20).run_case(
        "equality-303-842", case, [fuzz.registry_paths()["hierarchical_active_set"]],
        check_threads=False)
    _assert_clean(report)
