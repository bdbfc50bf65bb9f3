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


def _bound(values, name: str, what: str, sign: float):
    if values is None:
        return None
    if not isinstance(values, list):
        raise TaskStackError(f"{what} must be a list", task=name)
    return [sign * math.inf if v is None else v for v in values]


def stack_from_dict(data: dict[str, Any]) -> TaskStack:
    """Build a :class:`TaskStack` from the JSON structure (see the format doc)."""
    if not isinstance(data, dict) or "levels" not in data:
        raise TaskStackError("a task-stack file is a JSON object with a 'levels' list")
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
            if "A" not in t:
                raise TaskStackError("missing 'A'", task=name, level=i)
            unknown = set(t) - {"name", "A", "b", "lower", "upper", "weight"}
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
        TaskStackError: unreadable file, invalid JSON or an invalid stack; the
            message names the file and, where it applies, the task and level.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise TaskStackError(f"cannot read {path}: {exc.strerror}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TaskStackError(f"{path}: invalid JSON at line {exc.lineno}: {exc.msg}") from None
    try:
        return stack_from_dict(data)
    except TaskStackError as exc:
        raise TaskStackError(f"{path}: {exc}", task=None) from None


def save_stack(stack: TaskStack, path: str | Path, description: str = "") -> None:
    """Write a stack as JSON."""
    Path(path).write_text(json.dumps(stack_to_dict(stack, description), indent=1) + "\n")
