"""benchmarks/numba_compare.py without the numba checkout: the stacks both sides solve are
the stacks built here, bit for bit, and the answers' agreement is counted as its
docstring says (timings are never asserted)."""

from __future__ import annotations

import numpy as np
import pytest

from prioik.benchmarks import numba_compare as nc
from prioik.hierarchy import Task, TaskStack, hard
from prioik.hierarchy.families import weighted, with_inequalities


def _arrays(stack: TaskStack) -> list:
    return [(t.name, *(getattr(t, a) for a in ("A", "b", "lower", "upper", "weight")))
            for level in stack.levels for t in level]


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def test_saved_stacks_load_bit_for_bit(tmp_path):
    rng = np.random.default_rng(46)
    stacks = [with_inequalities(rng, 9, 3), weighted(rng, 7, 4),
              TaskStack([[Task("box", np.eye(3), lower=[-1, -np.inf, 0],
                               upper=[np.inf, 2, 0.5], weight=[1, 2, 3])],
                         [Task("pose", np.ones((1, 3)), [0.25])]])]
    manifest = nc.save_stacks(stacks, tmp_path / "stacks.npz")
    loaded = nc.load_stacks(manifest, tmp_path / "stacks.npz")
    assert len(loaded) == len(stacks)
    for got, want in zip(loaded, stacks, strict=True):
        assert got.layout == want.layout
        for g, w in zip(_arrays(got), _arrays(want), strict=True):
            assert g[0] == w[0]
            assert all(_same(x, y) for x, y in zip(g[1:], w[1:], strict=True)), g[0]


def test_a_hard_level_is_refused(tmp_path):
    stack = TaskStack([hard(Task("contact", np.eye(2), [0.0, 1.0])),
                       [Task("reach", np.ones((1, 2)), [1.0])]])
    with pytest.raises(ValueError, match="level 0 is hard"):
        nc.save_stacks([stack], tmp_path / "stacks.npz")


def test_answers_agree_by_status_and_relative_distance():
    x = np.array([3.0, 4.0])                        # ‖x‖ = 5
    res = np.array([1.0, 0.5])
    step = nc.X_RTOL * 5 / np.sqrt(2)               # ‖(step, step)‖ = X_RTOL · 5
    cpp = {"r#0": x + 0.5 * step, "r#1": x + 2.0 * step, "r#2": x.copy()}
    numba = {"r#0": x, "r#1": x, "r#2": x}
    for d in (cpp, numba):
        for j in range(3):
            d[f"r#{j}/residuals"] = res.copy()
    cpp["r#2/residuals"] = res * (1 + 1e-6)
    statuses = {"numba": {"r": ["optimal", "optimal", "optimal"]},
                "cpp": {"r": ["optimal", "optimal", "approximate"]}}
    row = nc.RowResult("r")
    nc.compare_answers(row, {"numba": numba, "cpp": cpp}, statuses)
    # #0 within X_RTOL; #1 twice it; #2 the same x but another status
    assert (row.agree, row.answers) == (1, 3)
    assert row.max_distance == pytest.approx(2.0 * nc.X_RTOL, rel=1e-6)
    assert row.max_residual_change == pytest.approx(1e-6, rel=1e-6)
    assert row.statuses == "optimal 3"


def test_ratio_is_the_quotient_of_the_medians_over_rounds():
    row = nc.RowResult("r")
    row.seconds = {"numba": [1.0, 2.0, 9.0], "cpp": [3.0, 1.0, 1.5]}
    row.wall = {"numba": [2.0, 2.0, 2.0], "cpp": [1.0, 1.0, 1.0]}
    assert row.ratio == pytest.approx(1.5 / 2.0)
    assert row.wall_ratio == pytest.approx(0.5)
    np.testing.assert_allclose(row.round_ratios, [3.0, 0.5, 1.5 / 9.0])
    table = nc.markdown_table([row]).splitlines()
    assert len(table) == 3 and table[2].startswith("| r | 2000000.0 | 1500000.0 | 0.75 |")
