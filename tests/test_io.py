"""Task-stack JSON files: round trip and errors that name the fault."""

import json

import numpy as np
import pytest

from prioik.benchmarks.compare import examples_dir
from prioik.hierarchy import Task, TaskStack, TaskStackError, load_stack, save_stack, stack_from_dict


def test_round_trip_keeps_everything(tmp_path):
    s = TaskStack([Task("a", np.eye(3)[[0]], [1.0], weight=2.0),
                   [Task("box", np.eye(3), lower=[-1, -np.inf, 0], upper=[1, 2, np.inf]),
                    Task("c", np.ones((1, 3)), [0.5])]])
    path = tmp_path / "s.json"
    save_stack(s, path, "test stack")
    back = load_stack(path)
    assert [lv.names for lv in back] == [lv.names for lv in s]
    for t, u in zip(s.tasks, back.tasks):
        np.testing.assert_array_equal(t.A, u.A)
        np.testing.assert_array_equal(t.weight, u.weight)
        if t.is_equality:
            np.testing.assert_array_equal(t.b, u.b)
        else:
            np.testing.assert_array_equal(t.bounds()[0], u.bounds()[0])
            np.testing.assert_array_equal(t.bounds()[1], u.bounds()[1])


@pytest.mark.parametrize("path", sorted(examples_dir().glob("*.json")), ids=lambda p: p.name)
def test_shipped_examples_load(path):
    s = load_stack(path)
    assert s.n > 0 and len(s) >= 1


def test_errors_name_file_task_and_level(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"levels": [[{"name": "a", "A": [[1, 0]], "b": [1]}],
                                          [{"name": "wide", "A": [[1, 0, 0]], "b": [0]}]]}))
    with pytest.raises(TaskStackError, match=r"bad.json: level 1, task 'wide': A has 3 columns"):
        load_stack(bad)
    broken = tmp_path / "broken.json"
    broken.write_text("{ not json")
    with pytest.raises(TaskStackError, match="broken.json: invalid JSON at line 1"):
        load_stack(broken)
    with pytest.raises(TaskStackError, match="cannot read"):
        load_stack(tmp_path / "missing.json")
    with pytest.raises(TaskStackError, match="unknown keys \\['B'\\]"):
        stack_from_dict({"levels": [{"name": "x", "A": [[1.0]], "B": [1.0]}]})
    with pytest.raises(TaskStackError, match="the file says n = 3"):
        stack_from_dict({"n": 3, "levels": [{"name": "x", "A": [[1.0]], "b": [1.0]}]})
