"""The like-for-like measurement of the closed forms (prioik.benchmarks.like_for_like):
what counts as compiled is read from the solvers, and the ratios to the extended
Jacobian's are the table's."""

import numpy as np
import pytest

import prioik
from prioik.benchmarks import paper
from prioik.benchmarks.like_for_like import BASE, measure, ratio_rows
from prioik.benchmarks.stacks import random_mass_matrix
from prioik.hierarchy.families import FAMILIES


def _samples(count=2, n=8, k=3):
    rng = np.random.default_rng(5)
    return [(FAMILIES["compatible"](rng, n, k), random_mass_matrix(n)) for _ in range(count)]


def test_measure_reads_compiled_and_flops_from_the_solvers():
    """Every formulation is marked compiled exactly when its prepared solver says so or
    its solve counts flops, and its flop count is the solver's own (the same stack
    gives the same count)."""
    samples = _samples()
    names = (BASE, "nullspace", "unifying", "reference")
    measured = measure(samples, names, repeats=2)
    assert list(measured) == list(names)
    for name, m in measured.items():
        counts, says_compiled = [], False
        for stack, mass in samples:
            solver = prioik.prepare(stack.layout, name)
            says_compiled = says_compiled or bool(solver.compiled)
            step = {"mass_matrix": mass} if name == "unifying" else {}
            count = solver.solve(stack.data, **step).flops
            if count is not None:
                counts.append(float(count))
        assert m["compiled"] is (says_compiled or bool(counts)), name
        assert m["flops"] == (float(np.median(counts)) if counts else None), name
        assert m["solves"] == 2 * len(samples) and m["median_solve_s"] > 0
        assert sum(m["statuses"].values()) == len(samples)
    assert measured[BASE]["compiled"] and measured[BASE]["flops"] > 0
    with pytest.raises(ValueError, match="at least one stack"):
        measure([], names)
    with pytest.raises(ValueError, match="repeats"):
        measure(samples, names, repeats=0)


def _measured(name, seconds, flops, compiled=True):
    return {name: {"compiled": compiled, "median_solve_s": seconds, "flops": flops,
                   "statuses": {"optimal": 1}, "solves": 1}}


def test_ratio_rows_on_a_hand_made_table():
    """EJ 10 µs, 1e4 flops; nullspace 30 µs, 6e4 flops (time 3, flops 6, rate 2);
    a numpy formulation: no time ratio, no flop ratio; a compiled one that does not
    count flops: a time ratio only. The paper's ratios are its times over 1.4 ms."""
    measured = {**_measured(BASE, 10e-6, 1e4), **_measured("nullspace", 30e-6, 6e4),
                **_measured("sns", 500e-6, None, compiled=False),
                **_measured("unifying", 40e-6, None)}
    rows = {r["formulation"]: r for r in ratio_rows(measured)}
    assert list(rows) == [BASE, "nullspace", "sns", "unifying"]
    ej, ns, sns, uni = rows.values()
    assert (ej["time_ratio"], ej["flop_ratio"], ej["rate_ratio"], ej["paper_ratio"]) == \
        (1.0, 1.0, 1.0, 1.0)
    assert ns["time_ratio"] == pytest.approx(3.0, rel=1e-12)
    assert ns["flop_ratio"] == pytest.approx(6.0, rel=1e-12)
    assert ns["rate_ratio"] == pytest.approx(2.0, rel=1e-12)
    assert ns["paper_ratio"] == pytest.approx(2.7 / 1.4, rel=1e-12)
    assert ns["paper_name"] == paper.METHOD_NAMES["nullspace"]
    assert (sns["time_ratio"], sns["flop_ratio"], sns["rate_ratio"]) == (None, None, None)
    assert (sns["paper_ratio"], sns["paper_name"]) == (None, "")
    assert uni["time_ratio"] == pytest.approx(4.0, rel=1e-12)
    assert uni["flop_ratio"] is None and uni["rate_ratio"] is None
    assert uni["paper_ratio"] == pytest.approx(3.2 / 1.4, rel=1e-12)
    # a numpy extended Jacobian: no time ratio for anyone (not like for like)
    numpy_base = {**_measured(BASE, 100e-6, None, compiled=False),
                  **_measured("nullspace", 30e-6, 6e4)}
    assert all(r["time_ratio"] is None and r["flop_ratio"] is None
               for r in ratio_rows(numpy_base))
    with pytest.raises(ValueError, match="extended_jacobian"):
        ratio_rows(_measured("nullspace", 30e-6, 6e4))
