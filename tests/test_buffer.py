"""hierarchy.buffer: the preallocated stack layout, its views, its boundary check."""

import numpy as np
import pytest

from prioik.hierarchy import StackBuffer, TaskStackError
from prioik.hierarchy.families import FAMILIES

LAYOUT = [[("a", 2)], [("b", 1), ("c", 3)], [("d", 4)]]


def test_layout_offsets_and_views_are_writable_slices():
    buf = StackBuffer(5, LAYOUT)
    assert buf.starts.tolist() == [0, 2, 6, 10] and buf.m == 10 and len(buf) == 3
    assert buf.names == (("a",), ("b", "c"), ("d",))
    A, b = buf.rows("c")
    A[:] = 7.0
    b[:] = [1.0, 2.0, 3.0]
    assert np.all(buf.A[3:6] == 7.0) and buf.b[3:6].tolist() == [1.0, 2.0, 3.0]
    assert np.all(buf.A[:3] == 0.0) and np.all(buf.A[6:] == 0.0)
    assert buf.task_slice("d") == slice(6, 10)


@pytest.mark.parametrize("family", ["compatible", "conflicting", "rank_deficient"])
def test_to_stack_round_trips_a_stack(family):
    stack = FAMILIES[family](np.random.default_rng(4), 9, 3)
    buf = StackBuffer(stack.n, [[(t.name, t.m) for t in level] for level in stack.levels])
    for t in stack.tasks:
        A, b = buf.rows(t.name)
        A[:], b[:] = t.A, t.b
    back = buf.to_stack()
    for level, other in zip(stack.levels, back.levels):
        assert np.array_equal(level.A, other.A) and np.array_equal(level.b, other.b)
    assert not back.tasks[0].A.flags.writeable       # validated Task copies, not views
    buf.A[:] = 0.0
    assert np.any(back.levels[0].A != 0.0)


@pytest.mark.parametrize("where, value, what", [("A", np.nan, "A"), ("b", np.inf, "b")])
def test_check_names_the_task_level_and_row(where, value, what):
    buf = StackBuffer(5, LAYOUT)
    buf.A[:] = 1.0
    A, b = buf.rows("c")
    (A if where == "A" else b)[1] = value      # a whole row (A) or one target (b)
    with pytest.raises(TaskStackError, match=r"level 1, task 'c': " + what) as err:
        buf.check()
    assert err.value.task == "c" and err.value.level == 1 and err.value.detail["row"] == 1


def test_check_passes_finite_values():
    buf = StackBuffer(5, LAYOUT)
    buf.check()


@pytest.mark.parametrize("n, levels, message", [
    (0, LAYOUT, "n ≥ 1"),
    (3, [], "empty"),
    (3, [[("a", 1)], []], "level 1: the level is empty"),
    (3, [[("a", 1)], [("a", 2)]], "duplicate task name"),
    (3, [[("a", 0)]], "at least one row"),
    (3, [[("", 1)]], "non-empty string"),
    (3, [["a"]], r"\(name, rows\) pair"),
])
def test_bad_layouts_are_refused_with_the_place(n, levels, message):
    with pytest.raises(TaskStackError, match=message):
        StackBuffer(n, levels)


def test_unknown_task_names_the_known_ones():
    with pytest.raises(TaskStackError, match="no task 'z'.*a, b, c, d"):
        StackBuffer(5, LAYOUT).rows("z")
