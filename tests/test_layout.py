"""hierarchy.stack, layout and data: the stack layout (immutable, hashable), its
preallocated data, views and boundary check; a TaskStack is a layout with frozen data."""

import numpy as np
import pytest

from prioik.hierarchy import (
    StackLayout,
    Task,
    TaskStack,
    TaskStackError,
    precision_limited_levels,
    precision_reason,
)
from prioik.hierarchy.families import FAMILIES

LAYOUT = [[("a", 2)], [("b", 1), ("c", 3)], [("d", 4)]]


def test_layout_offsets_and_views_are_writable_slices():
    layout = StackLayout(5, LAYOUT)
    buf = layout.data()
    assert layout.starts.tolist() == [0, 2, 6, 10] and layout.m == 10 and len(layout) == 3
    assert layout.names == (("a",), ("b", "c"), ("d",))
    assert not layout.starts.flags.writeable
    A, b = buf.rows("c")
    A[:] = 7.0
    b[:] = [1.0, 2.0, 3.0]
    assert np.all(buf.A[3:6] == 7.0) and buf.b[3:6].tolist() == [1.0, 2.0, 3.0]
    assert np.all(buf.A[:3] == 0.0) and np.all(buf.A[6:] == 0.0)
    assert layout.task_slice("d") == slice(6, 10)


@pytest.mark.parametrize("name", ["layout", "A", "b", "lower", "upper", "sqrt_weight"])
def test_data_arrays_are_written_in_place_not_replaced(name):
    """A prepared solver's compiled kernel reads the arrays as the layout's C-contiguous
    float64 ones: replacing one (another shape, dtype or order) is refused by name."""
    buf = StackLayout(5, LAYOUT).data()
    before = getattr(buf, name)
    with pytest.raises(TaskStackError, match=f"StackData.{name} is written in place"):
        setattr(buf, name, np.asfortranarray(np.zeros((10, 5))))
    assert getattr(buf, name) is before
    buf.A[...] = 1.0                                   # in place: allowed
    assert np.all(buf.copy().A == 1.0)


def test_layouts_are_values_hashable_and_immutable():
    a, b = StackLayout(5, LAYOUT), StackLayout(5, [list(level) for level in LAYOUT])
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1
    assert StackLayout(6, LAYOUT) != a
    assert StackLayout(5, [[("a", 2, "inequality")], *LAYOUT[1:]]) != a
    with pytest.raises(AttributeError):
        a.n = 3


def test_inequality_rows_bounds_and_weights_are_first_class():
    layout = StackLayout(3, [[("box", 3, "inequality")], [("t", 2)]])
    assert layout.row_is_equality.tolist() == [False, False, False, True, True]
    assert not layout.is_equality and layout.kind_of("box") == "inequality"
    data = layout.data()
    A, lo, up = data.bounds("box")
    A[:] = np.eye(3)
    lo[:], up[:] = -1.0, [1.0, 2.0, np.inf]
    data.rows("t")[0][:] = [[1.0, 0, 0], [0, 1.0, 0]]
    data.weights("t")[:] = [2.0, 3.0]
    stack = data.to_stack()
    assert stack.layout == layout
    np.testing.assert_array_equal(stack.task("box").upper, [1.0, 2.0, np.inf])
    np.testing.assert_array_equal(stack.task("t").weight, [4.0, 9.0])
    back = stack.data
    for key in ("A", "b", "lower", "upper", "sqrt_weight"):
        np.testing.assert_array_equal(getattr(back, key)[layout.task_slice("box")]
                                      if key != "b" else back.b[3:],
                                      getattr(data, key)[layout.task_slice("box")]
                                      if key != "b" else data.b[3:])


def test_a_stack_is_a_layout_with_frozen_data():
    rng = np.random.default_rng(1)
    stack = TaskStack([[Task("a", rng.standard_normal((2, 4)), [1.0, 2.0], weight=4.0)],
                       [Task("box", np.eye(4), lower=-np.ones(4), upper=np.ones(4))]])
    data = stack.data
    assert data is stack.data and data.as_stack() is stack
    assert not data.writeable and not data.A.flags.writeable
    np.testing.assert_array_equal(data.sqrt_weight[:2], [2.0, 2.0])
    np.testing.assert_array_equal(data.lower[2:], -np.ones(4))
    assert stack.layout.levels == ((("a", 2, "equality"),), (("box", 4, "inequality"),))
    copy = data.copy()
    assert copy.writeable and copy.as_stack() is not stack


@pytest.mark.parametrize("family", ["compatible", "conflicting", "rank_deficient"])
def test_to_stack_round_trips_a_stack(family):
    stack = FAMILIES[family](np.random.default_rng(4), 9, 3)
    buf = StackLayout(stack.n, [[(t.name, t.m) for t in level] for level in stack.levels]).data()
    for t in stack.tasks:
        A, b = buf.rows(t.name)
        A[:], b[:] = t.A, t.b
    back = buf.to_stack()
    for level, other in zip(stack.levels, back.levels, strict=False):
        assert np.array_equal(level.A, other.A) and np.array_equal(level.b, other.b)
    assert not back.tasks[0].A.flags.writeable       # validated Task copies, not views
    buf.A[:] = 0.0
    assert np.any(back.levels[0].A != 0.0)


@pytest.mark.parametrize("where, value, what", [("A", np.nan, "A"), ("b", np.inf, "b")])
def test_check_names_the_task_level_and_row(where, value, what):
    buf = StackLayout(5, LAYOUT).data()
    buf.A[:] = 1.0
    A, b = buf.rows("c")
    (A if where == "A" else b)[1] = value      # a whole row (A) or one target (b)
    with pytest.raises(TaskStackError, match=r"level 1, task 'c': " + what) as err:
        buf.check()
    assert err.value.task == "c" and err.value.level == 1 and err.value.detail["row"] == 1


def test_check_passes_finite_values():
    StackLayout(5, LAYOUT).data().check()


@pytest.mark.parametrize("field, value, what", [
    ("lower", np.nan, "lower is NaN"), ("upper", -np.inf, "upper is NaN or -inf"),
    ("sqrt_weight", 0.0, "√w is not finite and > 0")])
def test_check_names_bad_bounds_and_weights(field, value, what):
    data = StackLayout(2, [[("box", 2, "inequality")]]).data()
    getattr(data, field)[1] = value
    with pytest.raises(TaskStackError, match=f"level 0, task 'box': {what}.*row 1"):
        data.check()
    data = StackLayout(2, [[("box", 2, "inequality")]]).data()
    data.lower[0], data.upper[0] = 2.0, 1.0
    with pytest.raises(TaskStackError, match="lower > upper in row 0"):
        data.check()


@pytest.mark.parametrize("n, levels, message", [
    (0, LAYOUT, "n ≥ 1"),
    (3, [], "empty"),
    (3, [[("a", 1)], []], "level 1: the level is empty"),
    (3, [[("a", 1)], [("a", 2)]], "duplicate task name"),
    (3, [[("a", 0)]], "at least one row"),
    (3, [[("", 1)]], "non-empty string"),
    (3, [["a"]], r"\(name, rows\[, kind\]\)"),
    (3, [[("a", 1, "soft")]], "kind must be one of"),
    (True, LAYOUT, "n ≥ 1"),
])
def test_bad_layouts_are_refused_with_the_place(n, levels, message):
    with pytest.raises(TaskStackError, match=message):
        StackLayout(n, levels)


def test_unknown_task_names_the_known_ones():
    with pytest.raises(TaskStackError, match="no task 'z'.*a, b, c, d"):
        StackLayout(5, LAYOUT).data().rows("z")


def _tiny_above_unit_stack(tiny: float) -> TaskStack:
    """Level 0 ``tiny · x0 = 1`` drives ``x0`` to ``1/tiny``; level 1 ``x1 = 1`` does
    not touch it."""
    return TaskStack([Task("far", np.array([[tiny, 0.0]]), np.array([1.0])),
                      Task("near", np.array([[0.0, 1.0]]), np.array([1.0]))])


@pytest.mark.parametrize("tiny, limited", [(1e-3, []), (1e-5, []), (1e-12, [1])])
def test_precision_limited_levels_names_levels_float64_cannot_give(tiny, limited):
    # x = (1/tiny, 1): level 1's precision bound X_PRECISION·‖x‖·‖A_1‖ against 1e-8 of its
    # scale (|A_1||x| + |b_1| + ‖A_1‖ = 3): 3.6e-12 and 3.6e-10 pass, 3.6e-3 does not;
    # level 0's own scale holds the huge term (|A_0||x| = 1)
    stack = _tiny_above_unit_stack(tiny)
    x = np.array([1.0 / tiny, 1.0])
    assert precision_limited_levels(stack.data, x) == limited
    if limited:
        reason = precision_reason(limited, float(np.linalg.norm(x)))
        assert "level 1 " in reason and "1e+12" in reason


def test_precision_limited_levels_reads_inequality_targets_and_weights():
    # the same far level as an inequality row held at its lower bound, weights on both
    far = Task("far", np.array([[1e-12, 0.0]]), lower=np.array([1.0]), weight=4.0)
    near = Task("near", np.array([[0.0, 1.0]]), lower=np.array([0.5]), upper=np.array([2.0]),
                weight=9.0)
    stack = TaskStack([far, near])
    assert precision_limited_levels(stack.data, np.array([1e12, 1.0])) == [1]
    assert precision_limited_levels(stack.data, np.array([1e5, 1.0])) == []


def test_stacks_of_one_shape_share_their_layout():
    """TaskStack takes its layout from StackLayout.shared: one object per shape (so a
    prepared solver knows their data by identity), another for another shape, equal to
    a layout built directly, not kept alive by the sharing, and picklable."""
    import gc
    import pickle
    import weakref

    def stack(m):
        return TaskStack([[Task("a", np.ones((m, 3)), np.zeros(m))],
                          [Task("b", np.eye(3), lower=-np.ones(3), upper=np.ones(3))]])

    one, two, other = stack(2), stack(2), stack(1)
    assert one.layout is two.layout and one.layout is not other.layout
    direct = StackLayout(3, [[("a", 2)], [("b", 3, "inequality")]])
    assert direct == one.layout and direct is not one.layout
    assert StackLayout.shared(3, [[("a", 2, "equality")], [("b", 3, "inequality")]]) \
        is one.layout
    assert pickle.loads(pickle.dumps(one.layout)) == one.layout
    ref = weakref.ref(other.layout)
    del other
    gc.collect()
    assert ref() is None
    with pytest.raises(TaskStackError, match="at least one row"):
        StackLayout.shared(3, [[("a", 0)]])
    StackLayout.shared(1, [[("a", 1, "equality")]])
    with pytest.raises(TaskStackError, match="n ≥ 1"):
        StackLayout.shared(True, [[("a", 1, "equality")]])
    assert StackLayout.shared(3, [[("a", 2)], [("b", 3, "inequality")]]) is one.layout


def test_hard_violations_reads_each_hard_level_against_its_scale():
    """A hard level is violated beyond the certificate's tolerance times its scale;
    rounding-sized residuals are not violations; inequality levels count their distance
    to the bounds; levels not declared hard are never listed."""
    from prioik.hierarchy import DEFAULT_CERTIFICATE_TOL, hard, hard_violations
    box = Task("box", np.eye(2), lower=np.array([-1.0, -1.0]), upper=np.array([1.0, 1.0]))
    line = Task("line", np.array([[1.0, 1.0]]), np.array([4.0]))
    stack = TaskStack([hard(box), hard(line), Task("free", np.eye(2), np.zeros(2))])
    data = stack.data
    assert hard_violations(data, np.array([2.0, 2.0])) == [
        (0, pytest.approx(np.sqrt(2.0)), pytest.approx(4.0 * np.sqrt(2.0)))]   # 3√2 + √2
    assert hard_violations(data, np.array([1.0, 3.0]))[0][0] == 0       # row 1 beyond 1
    (level, r, scale), = hard_violations(data, np.array([0.5, 0.5]))
    assert (level, r) == (1, 3.0) and scale == pytest.approx(5.0 + np.sqrt(2.0))
    # within the tolerance of the scale: held (rounding, not a violation)
    x = np.array([1.0, 3.0 + 0.5 * DEFAULT_CERTIFICATE_TOL])
    ok = TaskStack([hard(line), Task("free", np.eye(2), np.zeros(2))])
    assert hard_violations(ok.data, x) == []
    assert hard_violations(ok.data, np.array([1.0, 3.0 + 1e-6]))[0][0] == 0
    assert hard_violations(ok.data, np.array([np.nan, 0.0]))[0][0] == 0
    assert hard_violations(TaskStack([line]).data, np.zeros(2)) == []    # none declared
