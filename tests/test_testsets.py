"""The test sets in qpbenchmark's shape (prioik.benchmarks.testsets): valid problems, the
shifted geometric mean, success per tolerance profile, the CSV round trip, the report
and ``prioik bench --test-set``."""

import math

import numpy as np
import pytest

from prioik.benchmarks.testsets import TEST_SETS, get
from prioik.benchmarks.testsets.metrics import (
    PROFILES,
    VALUE_JUDGED,
    certificate_success,
    shifted_geometric_mean,
    value_success,
    values_within,
)
from prioik.benchmarks.testsets.report import format_report, summarize
from prioik.benchmarks.testsets.run import CSV_FIELDS, Row, load_csv, run_test_set, write_csv
from prioik.cli import main
from prioik.hierarchy import Task, TaskStack, check_lexicographic

#: the smallest size of every test set (one or two problems per family or trajectory)
TINY = {"g1_compatible": {"windows": 1, "steps": 2},
        "g1_incompatible": {"windows": 1, "steps": 2},
        "g1_bounds_compatible": {"windows": 1, "steps": 2},
        "g1_bounds_incompatible": {"windows": 2, "steps": 1},
        "talos_reach": {"steps": 2}, "panda_reach": {"steps": 2}, "go2_reach": {"steps": 2},
        "random_equality": {"n": 5, "k": 2, "samples": 1},
        "random_inequality": {"n": 5, "k": 2, "samples": 1},
        "peers": {}}


def test_every_test_set_has_a_tiny_size():
    assert set(TINY) == set(TEST_SETS)


@pytest.mark.parametrize("name", list(TEST_SETS))
def test_each_test_set_yields_valid_named_stacks(name):
    if "robots" in TEST_SETS[name].needs:
        pytest.importorskip("pinocchio")
    test_set = get(name, **TINY[name])
    problems = list(test_set.problems())
    assert problems
    assert len({p.name for p in problems}) == len(problems)
    for p in problems:
        assert isinstance(p.stack, TaskStack)
        n = p.stack.n
        assert p.shape[0] == n and p.shape[1] == len(p.stack.levels) >= 1
        assert test_set.sequential == bool(p.sequence)
        if p.mass_matrix is not None:
            assert p.mass_matrix.shape == (n, n)
            assert np.linalg.eigvalsh(p.mass_matrix).min() > 0
        if p.solution is not None:
            assert p.solution.shape == (n,)
        if p.level_values is not None:
            assert p.level_values.shape == (len(p.stack.levels),)
            assert p.stated_by
    if name.startswith("g1_bounds") or name.endswith("_reach") or name == "random_inequality":
        assert all(p.has_inequalities for p in problems) or name == "random_inequality"
        assert any(p.has_inequalities for p in problems)
    if name in ("g1_compatible", "g1_incompatible", "random_equality"):
        assert not any(p.has_inequalities for p in problems)


def test_sequential_steps_differ_and_follow_each_other():
    pytest.importorskip("pinocchio")
    first, second = get("panda_reach", steps=2).problems()
    assert first.sequence == second.sequence
    assert not np.array_equal(first.stack.data.A, second.stack.data.A)


def test_peers_carry_their_stated_answers():
    problems = {p.name: p for p in get("peers").problems()}
    assert problems["lexls_test_01"].stated_by == "the peer's solution"
    assert problems["lexls_test_01"].level_values[4] == pytest.approx(1.58890, abs=1e-5)
    assert problems["nipm_t2"].stated_by.startswith("hand-worked")
    assert problems["soth_sot"].stated_by.startswith("peer_targets.json")


def test_unknown_test_set_and_bad_size_are_named():
    with pytest.raises(ValueError, match="unknown test set 'nope'; known: g1_compatible"):
        get("nope")
    with pytest.raises(ValueError, match="random_equality"):
        get("random_equality", windows=2)
    with pytest.raises(ValueError, match="samples"):
        get("random_equality", samples=0)


def test_shifted_geometric_mean_against_a_hand_computation():
    # exp(mean(log(t + s))) - s with t = 1, 4, 10 µs and s = 10 µs:
    # (11 · 14 · 20)^(1/3) µs - 10 µs = 3080^(1/3) - 10 = 4.5496… µs
    by_hand = (11e-6 * 14e-6 * 20e-6) ** (1 / 3) - 10e-6
    assert shifted_geometric_mean([1e-6, 4e-6, 10e-6], shift=1e-5) == \
        pytest.approx(by_hand, rel=1e-12)
    assert by_hand == pytest.approx(4.5496e-6, rel=1e-4)
    # a constant is its own mean; a tiny shift tends to the geometric mean
    assert shifted_geometric_mean([3e-6] * 4) == pytest.approx(3e-6, rel=1e-12)
    assert shifted_geometric_mean([1.0, 4.0], shift=1e-12) == pytest.approx(2.0, rel=1e-9)
    assert math.isnan(shifted_geometric_mean([]))
    with pytest.raises(ValueError, match="non-negative"):
        shifted_geometric_mean([1e-6, -1e-6])
    with pytest.raises(ValueError, match="shift"):
        shifted_geometric_mean([1e-6], shift=0.0)


def _one_level():
    b = np.array([1.0, -2.0, 0.5])
    return TaskStack([Task("t", np.eye(3), b)]), b


def test_a_slightly_wrong_answer_passes_low_and_fails_mid_and_high():
    """x off the optimum by 1e-5 (relative to a level of scale ~1): within 1e-3, not
    within 1e-6 or 1e-9 — the certificate and the value rule agree."""
    stack, b = _one_level()
    wrong = b + np.array([1e-5, 0.0, 0.0])
    expected = {"low": True, "mid": False, "high": False}
    for profile, tol in PROFILES.items():
        report = check_lexicographic(stack, wrong, tol=tol)
        assert certificate_success("optimal", report) is expected[profile], profile
        assert certificate_success("optimal", check_lexicographic(stack, b, tol=tol))
    # the value rule reads residuals: ‖w‖ = 1e-5 at the wrong x (‖w‖² = 1e-10) against
    # the exact 0 is within 1e-3 but not 1e-6 or 1e-9 (a rule on ‖w‖² would pass 1e-9)
    exact_values = np.array([0.0])
    wrong_values = np.array([float(np.sum((wrong - b) ** 2))])
    for profile, tol in PROFILES.items():
        assert value_success("approximate", wrong_values, exact_values, tol) is \
            expected[profile], profile
        assert value_success("approximate", exact_values, exact_values, tol)
    assert not value_success("failed", exact_values, exact_values, 1e-3)
    assert not value_success("optimal", exact_values, None, 1e-3)


def test_a_status_must_stand_behind_the_answer():
    """The right x with a status that does not say it: 'approximate' fails where no
    rank decision is ambiguous; 'failed' never passes; relative value tolerance."""
    stack, b = _one_level()
    report = check_lexicographic(stack, b, tol=1e-9)
    assert report.ok and not report.ambiguous_levels
    assert certificate_success("optimal", report)
    assert not certificate_success("approximate", report)
    assert not certificate_success("failed", check_lexicographic(stack, b + 1.0, tol=1e-3))
    assert values_within(np.array([100.0 + 5e-5]), np.array([100.0]), 1e-6)
    assert not values_within(np.array([100.0 + 5e-3]), np.array([100.0]), 1e-6)
    assert not values_within(np.array([np.nan]), np.array([0.0]), 1e-3)
    assert not values_within(np.array([0.0, 0.0]), np.array([0.0]), 1e-3)


def test_approximate_is_a_success_at_an_ambiguous_rank_decision():
    """Level 0: two rows 1e-7 apart in direction (within AMBIGUITY of the rank rule's
    threshold: either rank is a fair reading); the exact solver says 'approximate' and
    that counts; 'optimal' there counts too when the certificate holds, 'approximate'
    on a clear decision (1e-5 apart) does not."""
    import prioik

    def near_pair(eps):
        return TaskStack([[Task("pair", np.array([[1.0, 0, 0], [1.0, eps, 0]]), [1.0, 1.0])],
                          [Task("posture", np.eye(3), [0.0, 5.0, 1.0])]])

    sol = prioik.solve(near_pair(1e-7), "hierarchical_active_set")
    assert sol.status == "approximate"
    for tol in PROFILES.values():
        report = check_lexicographic(near_pair(1e-7), sol.x, tol=tol)
        assert report.ambiguous_levels == (0,)
        assert certificate_success("approximate", report)
    clear = check_lexicographic(near_pair(1e-5), np.array([1.0, 0.0, 1.0]), tol=1e-9)
    assert clear.ok and not clear.ambiguous_levels
    assert not certificate_success("approximate", clear)
    assert certificate_success("optimal", clear)


def test_value_judged_formulations_are_not_exact_by_design():
    from prioik import formulations
    for name in VALUE_JUDGED:
        assert formulations.get(name).capabilities.exact is False, name


ROWS = [Row("hierarchical_active_set", "hierarchical_active_set", {"warm_start": False}),
        Row("chiaverini", "chiaverini"),
        Row("cascaded_qp[quadprog]", "cascaded_qp", {"solver": "quadprog"}),
        Row("sns", "sns")]


def _tiny_run():
    return run_test_set(get("random_inequality", n=5, k=2, samples=1), ROWS, repeats=1)


def test_csv_round_trip(tmp_path):
    records = _tiny_run()
    assert len(records) == 3 * len(ROWS)
    path = write_csv(records, tmp_path / "r.csv")
    loaded = load_csv(path)
    assert len(loaded) == len(records)
    for a, b in zip(records, loaded, strict=False):
        assert set(b) == set(CSV_FIELDS)
        for f in CSV_FIELDS:
            if a[f] is None or isinstance(a[f], np.ndarray):
                assert (b[f] is None) == (a[f] is None), f
                if a[f] is not None:
                    np.testing.assert_array_equal(a[f], b[f])
            else:
                assert a[f] == b[f], f
    with pytest.raises(ValueError, match="missing columns"):
        (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
        load_csv(tmp_path / "bad.csv")


def test_tiny_run_judges_rows_as_their_design_says():
    records = _tiny_run()
    by_row = {}
    for r in records:
        by_row.setdefault(r["row"], []).append(r)
    exact = by_row["hierarchical_active_set"]
    assert all(r["judged_by"] == "certificate" for r in exact)
    assert all(r["success_high"] == 1 for r in exact)
    chia = by_row["chiaverini"]          # equality only: the inequality stacks not taken
    assert all(r["status"] == "unsupported" for r in chia)
    assert all(r["judged_by"] == "certificate" for r in by_row["cascaded_qp[quadprog]"])
    # sns refuses inequality rows other than box bounds at level 0: counted as not taken,
    # with its own message (not an error of the run)
    refused = [r for r in by_row["sns"] if r["status"] == "unsupported"]
    assert refused and all("formulation 'sns' cannot take it" in r["message"]
                           for r in refused)
    for r in records:                       # low ⊇ mid ⊇ high
        if r["status"] != "unsupported" and r["success_high"] == 1:
            assert r["success_low"] == r["success_mid"] == 1


def test_flops_column_holds_the_kernels_count_and_reloads(tmp_path):
    """A compiled closed form's flop count is the one its prepared solver reports for
    the same stack; a formulation that does not count them leaves the column empty;
    the CSV reloads the counts as floats, and a file without the column loads empty."""
    import prioik
    rows = [Row("extended_jacobian", "extended_jacobian"),
            Row("reference[numpy]", "reference", {"kernel": "numpy"})]
    test_set = get("random_equality", n=5, k=2, samples=1)
    records = run_test_set(test_set, rows, repeats=1)
    assert "flops" in CSV_FIELDS
    problems = {p.name: p for p in test_set.problems()}
    counted = [r for r in records if r["row"] == "extended_jacobian"]
    assert counted and all(r["flops"] != "" for r in counted)
    for r in counted:
        stack = problems[r["problem"]].stack
        direct = prioik.prepare(stack.layout, "extended_jacobian").solve(stack.data)
        assert r["flops"] == float(direct.flops) > 0
    uncounted = [r for r in records if r["row"] == "reference[numpy]"]
    assert uncounted and all(r["flops"] == "" for r in uncounted)
    loaded = load_csv(write_csv(records, tmp_path / "r.csv"))
    assert [r["flops"] for r in loaded] == [r["flops"] for r in records]
    old = tmp_path / "old.csv"          # a file written before the column existed
    lines = (tmp_path / "r.csv").read_text().splitlines()
    col = lines[0].split(",").index("flops")
    old.write_text("\n".join(",".join(c for i, c in enumerate(line.split(","))
                                       if i != col) for line in lines[:2]) + "\n")
    (first,) = load_csv(old)
    assert first["flops"] == "" and first["row"] == records[0]["row"]


def _record(problem, row, time_s, success, status="optimal", flops=""):
    rec = {f: "" for f in CSV_FIELDS}
    rec.update(test_set="s", problem=problem, row=row, formulation=row, status=status,
               time_s=time_s, flops=flops, judged_by="certificate", n=2, levels=1, rows=2,
               exact_status="optimal", stated_by="")
    for p in PROFILES:
        rec[f"success_{p}"], rec[f"reason_{p}"] = success, ("" if success else "why")
    return rec


def test_summary_normalises_to_the_best_and_counts_within_2x():
    """Row a: 10, 10 µs, both solved; row b: 15, 40 µs, the second fails. Best per
    problem (successful): 10, 10 → b is within 2× on the first only."""
    records = [_record("p1", "a", 10e-6, 1), _record("p1", "b", 15e-6, 1),
               _record("p2", "a", 10e-6, 1), _record("p2", "b", 40e-6, 0, "approximate")]
    a, b = summarize(records, "mid")["s"]
    assert a["sgm_norm"] == pytest.approx(1.0)
    by_hand = ((25e-6 * 50e-6) ** 0.5 - 10e-6) / 10e-6
    assert b["sgm_norm"] == pytest.approx(by_hand, rel=1e-12)
    assert (a["within_2x"], b["within_2x"]) == (1.0, 0.5)
    assert b["success"]["mid"] == 0.5 and b["worst_s"] == 40e-6
    assert b["failures"] == [("p2", "approximate", "why")]
    text = format_report(records, "mid", command="prioik bench --test-set s")
    assert "| `b` | 2/2 | 50 % | 50 % | 50 % |" in text
    assert "- `b` (1) — approximate: why — p2" in text


def test_flop_summary_normalises_to_the_fewest_among_the_rows_that_count():
    """Row a: 1e4 and 4e4 flops; row b: 3e4 and 6e4; row c counts none; row d counts
    one of its two solves (2e4). Shift s = 1e4: SGM(a) = √(2e4 · 5e4) − 1e4,
    SGM(b) = √(4e4 · 7e4) − 1e4, SGM(d) = 2e4; d is the fewest, the others relative to it."""
    records = [_record("p1", "a", 10e-6, 1, flops=1e4), _record("p2", "a", 10e-6, 1, flops=4e4),
               _record("p1", "b", 10e-6, 1, flops=3e4), _record("p2", "b", 10e-6, 1, flops=6e4),
               _record("p1", "c", 10e-6, 1), _record("p2", "c", 10e-6, 1),
               _record("p1", "d", 10e-6, 1, flops=2e4), _record("p2", "d", 10e-6, 1)]
    a, b, c, d = summarize(records, "mid", flop_shift=1e4)["s"]
    sgm_a = (2e4 * 5e4) ** 0.5 - 1e4
    sgm_b = (4e4 * 7e4) ** 0.5 - 1e4
    assert a["sgm_flops"] == pytest.approx(sgm_a, rel=1e-12)
    assert b["sgm_flops"] == pytest.approx(sgm_b, rel=1e-12)
    assert d["sgm_flops"] == pytest.approx(2e4, rel=1e-12)
    assert d["sgm_flops_norm"] == pytest.approx(1.0, rel=1e-12)
    assert a["sgm_flops_norm"] == pytest.approx(sgm_a / 2e4, rel=1e-12)
    assert b["sgm_flops_norm"] == pytest.approx(sgm_b / 2e4, rel=1e-12)
    assert c["flops_counted"] == 0 and math.isnan(c["sgm_flops_norm"])
    assert (d["flops_counted"], d["solves"]) == (1, 2)
    text = format_report(records, "mid", flop_shift=1e4)
    assert f"| `a` | 2/2 | 100 % | 100 % | 100 % | 1.00 | {sgm_a / 2e4:.2f} |" in text
    assert "| `c` | 2/2 | 100 % | 100 % | 100 % | 1.00 | — |" in text
    assert "| `d` | 2/2 | 100 % | 100 % | 100 % | 1.00 | 1.00 (1/2) |" in text
    assert "Flops —: not counted by `c` " in text
    assert "s = 10000 flops" in text


def test_cli_lists_and_runs_one_tiny_test_set(tmp_path, capsys):
    assert main(["bench", "--test-set", "list"]) == 0
    listed = capsys.readouterr().out
    assert all(name in listed for name in TEST_SETS)
    out = tmp_path / "ts"
    doc = tmp_path / "doc.md"
    assert main(["bench", "--test-set", "random_equality", "--profile", "high",
                 "--set-option", "n=4", "--set-option", "k=2", "--set-option", "samples=1",
                 "--formulations", "hierarchical_active_set,extended_jacobian",
                 "--repeats", "1", "--out", str(out), "--doc", str(doc)]) == 0
    records = load_csv(out / "testsets.csv")
    assert {r["row"] for r in records} == {"hierarchical_active_set", "extended_jacobian"}
    assert len(records) == 2 * 7       # one stack of each of the seven families
    text = (out / "testsets.md").read_text()
    assert doc.read_text() == text
    assert "## random_equality" in text and "| `extended_jacobian` | 7/7 |" in text
    assert "--profile high" in text
    # the report again from the CSV alone, at another profile
    again = tmp_path / "again"
    assert main(["bench", "--test-set", "random_equality", "--profile", "low",
                 "--from-csv", str(out / "testsets.csv"), "--out", str(again)]) == 0
    text_low = (again / "testsets.md").read_text()
    assert "Failures at the `low` profile" in text_low

    def table(md):      # row → its taken, success and time cells (profile-independent)
        return {line.split("|")[1]: line.split("|")[2:7] for line in md.splitlines()
                if line.startswith("| `")}

    assert table(text_low) == table(text) and len(table(text)) == 2
    assert main(["bench", "--test-set", "peers", "--from-csv", str(out / "testsets.csv"),
                 "--out", str(again)]) == 2


def test_cli_refuses_unknown_sets_and_bad_options(capsys):
    assert main(["bench", "--test-set", "nope"]) == 2
    assert "unknown test set(s) nope" in capsys.readouterr().err
    assert main(["bench", "--test-set", "peers", "--set-option", "n"]) == 2
    assert "KEY=INTEGER" in capsys.readouterr().err
