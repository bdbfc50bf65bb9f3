"""Task-stack files (JSON); the format is documented in ``docs/task-stack-format.md``."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .errors import TaskStackError
from .stack import TaskStack
from .task import Task

FORMAT_VERSION = 1

#: Keys a task-stack file may hold at the top level and in a task object.
TOP_LEVEL_KEYS = ("description", "format", "n", "levels")
TASK_KEYS = ("name", "A", "b", "lower", "upper", "weight")

#: Longest integer literal read (float64 overflows past 309 digits).
MAX_INTEGER_DIGITS = 309


def _read_int(text: str) -> int | float:
    digits = len(text.lstrip("-"))
    if digits > MAX_INTEGER_DIGITS:
        raise TaskStackError(f"an integer of {digits} digits is beyond float64 "
                             f"(at most {MAX_INTEGER_DIGITS} digits)")
    return int(text)


def _bound(values, name: str, what: str, sign: float):
    if values is None:
        return None
    if not isinstance(values, list):
        raise TaskStackError(f"{what} must be a list", task=name)
    return [sign * math.inf if v is None else v for v in values]


def stack_from_dict(data: dict[str, Any]) -> TaskStack:
    """Build a :class:`TaskStack` from the JSON structure (see the format doc).

    Raises:
        TaskStackError: naming the key, level or task at fault: an unknown key
            anywhere, a ``format`` other than :data:`FORMAT_VERSION`, a non-integer
            ``n``, a non-string ``description``, and every :class:`TaskStack` error.
    """
    if not isinstance(data, dict) or "levels" not in data:
        raise TaskStackError("a task-stack file is a JSON object with a 'levels' list")
    unknown = sorted(set(data) - set(TOP_LEVEL_KEYS))
    if unknown:
        raise TaskStackError(f"unknown top-level keys {unknown} (known: "
                             f"{', '.join(TOP_LEVEL_KEYS)})")
    if "format" in data and (type(data["format"]) is not int
                             or data["format"] != FORMAT_VERSION):
        raise TaskStackError(f"unsupported format {data['format']!r}: this prioik reads "
                             f"format {FORMAT_VERSION}")
    if "n" in data and (type(data["n"]) is not int or data["n"] < 1):
        raise TaskStackError(f"'n' must be a positive integer, got {data['n']!r}")
    if "description" in data and not isinstance(data["description"], str):
        raise TaskStackError("'description' must be a string")
    levels = data["levels"]
    if not isinstance(levels, list):
        raise TaskStackError("'levels' must be a list of levels")
    out = []
    for i, level in enumerate(levels):
        items = level if isinstance(level, list) else [level]
        tasks = []
        for j, t in enumerate(items):
            if not isinstance(t, dict):
                raise TaskStackError(f"task {j} must be a JSON object", level=i)
            name = t.get("name", f"level{i}_task{j}")
            if not isinstance(name, str):
                raise TaskStackError(f"task {j}: 'name' must be a string, got {name!r}",
                                     level=i)
            if "A" not in t:
                raise TaskStackError("missing 'A'", task=name, level=i)
            unknown = set(t) - set(TASK_KEYS)
            if unknown:
                raise TaskStackError(f"unknown keys {sorted(unknown)}", task=name, level=i)
            try:
                tasks.append(Task(name, t["A"], t.get("b"),
                                  lower=_bound(t.get("lower"), name, "lower", -1.0),
                                  upper=_bound(t.get("upper"), name, "upper", 1.0),
                                  weight=t.get("weight", 1.0)))
            except TaskStackError as exc:
                raise TaskStackError(str(exc).split(": ", 1)[-1], task=name, level=i) from None
        out.append(tasks)
    stack = TaskStack(out)
    if "n" in data and data["n"] != stack.n:
        raise TaskStackError(f"the file says n = {data['n']} but its tasks have "
                             f"{stack.n} columns")
    return stack


def stack_to_dict(stack: TaskStack, description: str = "") -> dict[str, Any]:
    """The JSON structure of a stack (inverse of :func:`stack_from_dict`)."""
    def bound(v):
        return None if v is None else [None if not np.isfinite(x) else float(x) for x in v]

    levels = []
    for level in stack.levels:
        items = []
        for t in level:
            d: dict[str, Any] = {"name": t.name, "A": t.A.tolist()}
            if t.is_equality:
                d["b"] = t.b.tolist()
            else:
                if t.lower is not None:
                    d["lower"] = bound(t.lower)
                if t.upper is not None:
                    d["upper"] = bound(t.upper)
            if not np.all(t.weight == 1.0):
                d["weight"] = t.weight.tolist()
            items.append(d)
        levels.append(items)
    out: dict[str, Any] = {"format": FORMAT_VERSION, "n": stack.n, "levels": levels}
    if description:
        out = {"description": description, **out}
    return out


def load_stack(path: str | Path) -> TaskStack:
    """Read a task-stack JSON file.

    Raises:
        TaskStackError: unreadable file, not UTF-8 text, invalid JSON, nesting too
            deep, an integer beyond float64, or an invalid stack; the message names
            the file and, where it applies, the key, task and level.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise TaskStackError(f"cannot read {path}: {exc.strerror}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise TaskStackError(f"{path}: not a UTF-8 JSON text file (byte {exc.start} is "
                             f"{raw[exc.start:exc.start + 1]!r})") from None
    try:
        data = json.loads(text, parse_int=_read_int)
    except json.JSONDecodeError as exc:
        raise TaskStackError(f"{path}: invalid JSON at line {exc.lineno}: {exc.msg}") from None
    except RecursionError:
        raise TaskStackError(f"{path}: JSON nested too deeply (a task-stack file nests "
                             f"5 levels: levels, level, task, A, row)") from None
    except TaskStackError as exc:
        raise TaskStackError(f"{path}: {exc}") from None
    try:
        return stack_from_dict(data)
    except TaskStackError as exc:
        raise TaskStackError(f"{path}: {exc}", task=None) from None


def save_stack(stack: TaskStack, path: str | Path, description: str = "") -> None:
    """Write a stack as JSON."""
    Path(path).write_text(json.dumps(stack_to_dict(stack, description), indent=1) + "\n")
