"""Task-stack JSON files: round trip and errors that name the fault."""

import json

import numpy as np
import pytest

from prioik.compare import examples_dir
from prioik.hierarchy import (
    Task,
    TaskStack,
    TaskStackError,
    load_stack,
    save_stack,
    stack_from_dict,
)


def test_round_trip_keeps_everything(tmp_path):
    s = TaskStack([Task("a", np.eye(3)[[0]], [1.0], weight=2.0),
                   [Task("box", np.eye(3), lower=[-1, -np.inf, 0], upper=[1, 2, np.inf]),
                    Task("c", np.ones((1, 3)), [0.5])]])
    path = tmp_path / "s.json"
    save_stack(s, path, "test stack")
    back = load_stack(path)
    assert [lv.names for lv in back] == [lv.names for lv in s]
    for t, u in zip(s.tasks, back.tasks, strict=False):
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


def _file(tmp_path, text: str | bytes, name: str = "f.json"):
    path = tmp_path / name
    (path.write_bytes if isinstance(text, bytes) else path.write_text)(text)
    return path


GOOD_TASK = '{"name": "t", "A": [[1.0, 2.0]], "b": [1.0]}'


@pytest.mark.parametrize("text, message", [
    ('{"levels": [[' + GOOD_TASK + ']], "levls": 1}', r"unknown top-level keys \['levls'\]"),
    ('{"format": 2, "levels": [[' + GOOD_TASK + ']]}', "unsupported format 2"),
    ('{"format": "1", "levels": [[' + GOOD_TASK + ']]}', "unsupported format '1'"),
    ('{"format": true, "levels": [[' + GOOD_TASK + ']]}', "unsupported format True"),
    ('{"n": 2.5, "levels": [[' + GOOD_TASK + ']]}', "'n' must be a positive integer"),
    ('{"description": 3, "levels": [[' + GOOD_TASK + ']]}', "'description' must be a string"),
    ('{"levels": [[{"name": 7, "A": [[1.0]], "b": [1.0]}]]}', "'name' must be a string"),
    ('{"levels": [[{"A": [[' + "9" * 400 + ']], "b": [1]}]]}',
     "an integer of 400 digits is beyond float64"),
    ('{"levels": ' + "[" * 100_000 + "]" * 100_000 + '}', "nested too deeply"),
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ('{"levels": [[{"A": ' + "[" * 40 + "1" + "]" * 40 + ', "b": [1]}]]}',
     "A must be a 2-D matrix"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe", "not a UTF-8 JSON text file"),
])
def test_bad_files_name_the_file_and_the_fault(tmp_path, text, message):
    path = _file(tmp_path, text, "bad_file.json")
    with pytest.raises(TaskStackError, match=message) as exc:
        load_stack(path)
    assert "bad_file.json: " in str(exc.value)


def test_format_1_and_known_keys_load(tmp_path):
    path = _file(tmp_path, '{"description": "d", "format": 1, "n": 2, "levels": [['
                 + GOOD_TASK + ']]}')
    assert load_stack(path).n == 2


def test_hard_levels_are_saved_and_read(tmp_path):
    from prioik.hierarchy import hard
    a = Task("a", np.eye(2), np.ones(2))
    b = Task("b", np.eye(2), np.zeros(2))
    stack = a / hard(b)
    path = tmp_path / "hard.json"
    save_stack(stack, path)
    assert json.loads(path.read_text())["hard"] == [1]
    assert load_stack(path).layout == stack.layout
    assert "hard" not in json.loads(json.dumps(
        __import__("prioik").hierarchy.stack_to_dict(a / b)))
    for bad in ([2], [-1], "1", [True], [1.0]):
        with pytest.raises(TaskStackError, match="'hard' must be a list of level indices "
                                                 r"0 … 1"):
            stack_from_dict({"levels": [{"name": "a", "A": [[1.0]], "b": [1.0]},
                                        {"name": "b", "A": [[1.0]], "b": [0.0]}],
                             "hard": bad})
