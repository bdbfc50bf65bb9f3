"""Task / TaskStack: composition and validation (one test per error)."""

import numpy as np
import pytest

from prioik.hierarchy import Level, Task, TaskStack, TaskStackError

A = np.arange(6.0).reshape(2, 3) + 1.0


def eq(name, A=A, b=(1.0, 2.0), **kw):
    return Task(name, A, np.asarray(b), **kw)


def test_compact_forms_build_the_explicit_stack():
    t1, t2, t3, t4 = eq("t1"), eq("t2"), eq("t3"), eq("t4")
    s = t1 / (t2 + t3) / t4
    assert isinstance(t2 + t3, Level)
    assert [lv.names for lv in s.levels] == [("t1",), ("t2", "t3"), ("t4",)]
    explicit = TaskStack([[t1], [t2, t3], t4])
    assert [lv.names for lv in explicit] == [lv.names for lv in s]
    assert len(t1 / t2 / t3) == 3 and (t1 / t2 / t3).n == 3
    assert [lv.names for lv in (t1 / t2) / (t3 / t4)] == [("t1",), ("t2",), ("t3",), ("t4",)]


def test_rows_selects_rows_and_keeps_bounds():
    t = Task("ineq", A, lower=[0.0, -1.0], upper=[1.0, np.inf], weight=[2.0, 3.0])
    r = t.rows([1])
    assert r.name == "ineq[1]"
    np.testing.assert_array_equal(r.A, A[[1]])
    np.testing.assert_array_equal(r.lower, [-1.0])
    np.testing.assert_array_equal(r.upper, [np.inf])
    np.testing.assert_array_equal(r.weight, [3.0])
    with pytest.raises(TaskStackError, match="'ineq'.*out of range"):
        t.rows([5])


def test_level_rows_are_weighted_by_sqrt_weight():
    s = TaskStack([[eq("a", weight=4.0), eq("b", b=(3.0, 4.0))]])
    np.testing.assert_allclose(s[0].A[:2], 2.0 * A)
    np.testing.assert_allclose(s[0].b, [2.0, 4.0, 3.0, 4.0])


def test_arrays_are_copied_and_read_only():
    M = A.copy()
    b = np.array([1.0, 2.0])
    t = Task("t", M, b)
    M[0, 0] = 99.0
    b[0] = 99.0
    assert t.A[0, 0] == 1.0 and t.b[0] == 1.0
    with pytest.raises(ValueError):
        t.A[0, 0] = 5.0


def test_summary_names_levels_tasks_and_ranks():
    text = (eq("reach") / Task("lim", A, lower=[0, 0])).summary()
    assert "reach" in text and "lim" in text and "inequality" in text and "r_i" in text


def test_repr_is_one_short_line_and_html_is_a_table():
    stack = TaskStack([Task(f"t{i}", np.eye(3)[:1], [0.0]) for i in range(20)])
    text = repr(stack)
    assert "\n" not in text and len(text) < 200 and "t0[1]" in text and "12 more" in text
    assert repr(eq("reach") / Task("lim", A, lower=[0, 0])).endswith("lim[2≤])")
    assert stack._repr_html_().count("<tr>") == 21


# ------------------------------------------------------------------- validation
def _raises(levels, *, task, level, match):
    with pytest.raises(TaskStackError, match=match) as info:
        TaskStack(levels)
    assert info.value.task == task and info.value.level == level
    msg = str(info.value)
    if task is not None:
        assert repr(task) in msg
    if level is not None:
        assert f"level {level}" in msg
    return info.value


def test_error_columns_differ():
    err = _raises([eq("a"), Task("b", np.ones((2, 4)), [0, 0])], task="b", level=1,
                  match="4 columns but the stack has 3")
    assert err.detail["columns"] == 4


def test_error_b_wrong_length():
    _raises([eq("a"), Task("short", A, [1.0, 2.0, 3.0])], task="short", level=1,
            match=r"b has shape \(3,\) but A has 2 rows")


def test_error_nan_in_A():
    bad = A.copy()
    bad[1, 2] = np.nan
    _raises([Task("nanA", bad, [0, 0])], task="nanA", level=0, match="A holds NaN at")


def test_error_nan_in_b():
    _raises([eq("ok"), Task("nanb", A, [0, np.nan])], task="nanb", level=1, match="b holds NaN")


def test_error_nan_in_bounds():
    _raises([Task("nanlo", A, lower=[np.nan, 0])], task="nanlo", level=0,
            match="lower holds NaN")


def test_error_inf_in_A():
    bad = A.copy()
    bad[0, 0] = np.inf
    _raises([Task("infA", bad, [0, 0])], task="infA", level=0, match="A holds inf")


def test_error_inf_in_b():
    _raises([Task("infb", A, [np.inf, 0])], task="infb", level=0, match="b holds inf")


def test_infinite_bounds_mean_unbounded():
    s = TaskStack([Task("box", A, lower=[-np.inf, 0], upper=[1, np.inf])])
    assert not s.is_equality


def test_error_wrong_sided_infinite_bound():
    _raises([Task("lo", A, lower=[np.inf, 0])], task="lo", level=0, match=r"lower holds \+inf")


def test_error_lower_above_upper():
    err = _raises([eq("a"), Task("box", A, lower=[0, 2], upper=[1, 1])], task="box",
                  level=1, match=r"lower > upper at rows \[1\] \(row 1: 2.0 > 1.0\)")
    assert err.detail["rows"] == [1]


def test_error_neither_b_nor_bounds():
    _raises([eq("a"), Task("empty_task", A)], task="empty_task", level=1,
            match="neither b .* nor lower/upper")


def test_error_empty_stack():
    with pytest.raises(TaskStackError, match="the stack is empty"):
        TaskStack([])


def test_error_empty_level():
    _raises([eq("a"), []], task=None, level=1, match="the level is empty")


def test_error_duplicate_names():
    _raises([eq("same"), eq("other"), eq("same")], task="same", level=2,
            match="duplicate task name .also at level 0")


def test_error_b_and_bounds_together():
    with pytest.raises(TaskStackError, match="'both'.*not both"):
        Task("both", A, [0, 0], lower=[0, 0])


def test_error_not_numbers():
    with pytest.raises(TaskStackError, match="'words': A must hold real numbers, got strings"):
        Task("words", [["a", "b"]], [0])


@pytest.mark.parametrize("what, value, message", [
    ("A", [["1", "2"]], "A must hold real numbers, got strings"),      # was read as 1, 2
    ("A", np.array([[1 + 1j, 2.0]]), "A must hold real numbers, got complex"),  # was a warning
    ("A", [[1 + 0j, 2.0]], "A must hold real numbers, got complex"),
    ("A", [[True, False]], "A must hold real numbers, got booleans"),
    ("A", np.array([[1, "x"]], dtype=object), "A must hold real numbers, got str"),
    ("A", [[10 ** 400, 1]], "A cannot be read as float64 numbers"),
    ("A", [[1.0, [2.0]]], "A cannot be read as an array of numbers"),
    ("b", ["1"], "b must hold real numbers, got strings"),
    ("b", [1j], "b must hold real numbers, got complex"),
    ("weight", "2", "weight must hold real numbers, got strings"),
    ("lower", [1 + 2j], "lower must hold real numbers, got complex"),
])
def test_error_only_real_numbers(what, value, message):
    kw = {"A": [[1.0, 2.0]], "b": [1.0]}
    if what in ("lower", "upper"):
        kw.pop("b")
    kw[what] = value
    with pytest.raises(TaskStackError, match=f"task 'real': {message}"):
        Task("real", kw.pop("A"), kw.pop("b", None), **kw)


def test_integer_and_object_real_arrays_are_read():
    np.testing.assert_array_equal(Task("i", np.array([[1, 2]], dtype=np.int32), [3]).A,
                                  [[1.0, 2.0]])
    np.testing.assert_array_equal(Task("o", np.array([[10 ** 30, 2]], dtype=object), [3]).A,
                                  [[1e30, 2.0]])


def test_error_bad_weight():
    _raises([eq("w", weight=-1.0)], task="w", level=0, match="weight must be finite and > 0")


def test_error_not_a_task_in_level():
    _raises([eq("a"), [np.eye(3)]], task=None, level=1, match="a level holds Task objects")


# ------------------------------------------------------------------ hard levels
def _tasks():
    rng = np.random.default_rng(3)
    return [Task(name, rng.normal(size=(2, 4)), rng.normal(size=2)) for name in "abcd"]


def test_a_level_is_declared_hard_and_stays_so_through_composition():
    from prioik.hierarchy import hard
    a, b, c, d = _tasks()
    assert not Level.of(a).hard and hard(a).hard and hard([a, b]).hard
    assert (hard(a) + b).hard and (b + hard(a)).hard and not (a + b).hard
    assert Level.of(hard(a), hard=False).hard is False
    stack = hard(a + b) / c / hard(d)
    assert stack.hard == (0, 2) and stack.layout.hard == (0, 2)
    assert TaskStack([[a, b], hard(c)]).hard == (1,)
    assert (a / hard(b)).hard == (1,) and (hard(a) / TaskStack([b, c])).hard == (0,)
    assert repr(stack).startswith("TaskStack(n=4, 3 levels: hard a[2] + b[2] / c[2] / hard d")
    assert stack.layout.describe() == "n=4: hard a[2] + b[2] / c[2] / hard d[2]"
    # the layout: part of the shape (a solver prepared for one refuses the other)
    plain = TaskStack([[a, b], c, d])
    assert plain.hard == () and plain.layout != stack.layout
    assert hash(plain.layout) != hash(stack.layout)
    assert TaskStack([hard([a, b]), c, hard(d)]).layout is stack.layout      # shared
    # the stack a StackData rebuilds, and the rescaled one, keep their hard levels
    assert stack.data.to_stack().hard == (0, 2)
    assert stack.data.to_stack().layout == stack.layout
    tiny = TaskStack([hard(Task("t", 1e-200 * np.eye(2), np.ones(2)))])
    scaled, levels = tiny.equilibrated()
    assert levels == [0] and scaled.hard == (0,)


def test_hard_levels_of_a_layout_are_level_indices():
    from prioik.hierarchy import StackLayout
    levels = [[("a", 2)], [("b", 1)]]
    assert StackLayout(3, levels, hard=[1]).hard == (1,)
    assert StackLayout(3, levels, hard=(1, 0)).hard == (0, 1)
    for bad in ([2], [-1], [0, 0], [True], [0.5], "0", None):
        with pytest.raises(TaskStackError, match="hard levels must be distinct level "
                                                 r"indices 0 … 1"):
            StackLayout(3, levels, hard=bad)
    with pytest.raises(TaskStackError, match="a level is a Task or a sequence of Tasks"):
        from prioik.hierarchy import hard
        hard(3)
