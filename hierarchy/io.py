"""Task-stack files: prioik's JSON (``docs/task-stack-format.md``) and, for checking
answers against other projects, the peers' formats (lexls ``.dat``, soth ``.txt``, the
peer JSON of ``tests/data/peer``; see :class:`PeerProblem`)."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import TaskStackError
from .stack import Level, Task, TaskStack

FORMAT_VERSION = 1

#: Keys a task-stack file may hold at the top level and in a task object.
TOP_LEVEL_KEYS = ("description", "format", "n", "levels", "hard")
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
            extra = set(t) - set(TASK_KEYS)
            if extra:
                raise TaskStackError(f"unknown keys {sorted(extra)}", task=name, level=i)
            try:
                tasks.append(Task(name, t["A"], t.get("b"),
                                  lower=_bound(t.get("lower"), name, "lower", -1.0),
                                  upper=_bound(t.get("upper"), name, "upper", 1.0),
                                  weight=t.get("weight", 1.0)))
            except TaskStackError as exc:
                raise TaskStackError(str(exc).split(": ", 1)[-1], task=name, level=i) from None
        out.append(tasks)
    hard = data.get("hard", [])
    if not isinstance(hard, list) or not all(type(i) is int and 0 <= i < len(out)
                                             for i in hard):
        raise TaskStackError(f"'hard' must be a list of level indices 0 … {len(out) - 1}, "
                             f"got {hard!r}")
    stack = TaskStack([Level.of(tasks, hard=i in hard) for i, tasks in enumerate(out)])
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
    if stack.hard:
        out["hard"] = list(stack.hard)
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


# ------------------------------------------------------------ peers' formats
@dataclass(frozen=True)
class PeerProblem:
    """A hierarchy read from another project's test data, with what the file asserts.

    Attributes:
        name: ``<file stem>`` (``<file stem>#<k>`` for the ``k``-th problem of a file
            holding several).
        stack: The levels as a :class:`TaskStack`. Each peer level becomes one prioik
            level holding up to two tasks: ``L<i>_eq`` (rows with ``lower == upper``, an
            equality task) and ``L<i>_ineq`` (the other rows, ``Task(lower=, upper=)``).
            Peer levels without rows are dropped (they change nothing).
        x_stored: The solution the peer stores or its test asserts (``None`` if none).
        level_targets: Per level of ``stack``, a ``‖w_i‖²`` the file states (``None`` if
            it states none; NIPM-HLSP's JSON carry hand-derived ``f_analytic``).
        source_levels: For each level of ``stack``, its index in the file.
        source: Upstream repository, path and commit, as the file says.
        note: Free text from the file.
        extras: Format-specific data (lexls: ``solution_guess``, ``active_set_guess``,
            ``objective_types``; JSON: ``x_analytic``).
    """

    name: str
    stack: TaskStack
    x_stored: np.ndarray | None = None
    level_targets: np.ndarray | None = None
    source_levels: tuple[int, ...] = ()
    source: str = ""
    note: str = ""
    extras: dict[str, Any] = field(default_factory=dict)


def _peer_stack(levels: list[tuple[np.ndarray, np.ndarray, np.ndarray]], n: int,
                where: str) -> tuple[TaskStack, tuple[int, ...]]:
    """A stack from per-level ``(A, lower, upper)``; ``lower == upper`` rows are equalities."""
    out, kept = [], []
    for i, (A, lo, up) in enumerate(levels):
        A = np.asarray(A, dtype=np.float64).reshape(-1, n)
        lo = np.asarray(lo, dtype=np.float64).reshape(-1)
        up = np.asarray(up, dtype=np.float64).reshape(-1)
        if not (A.shape[0] == lo.shape[0] == up.shape[0]):
            raise TaskStackError(f"{where}: level {i} has {A.shape[0]} rows but "
                                 f"{lo.shape[0]} lower and {up.shape[0]} upper bounds")
        if A.shape[0] == 0:
            continue
        eq = lo == up
        tasks = []
        try:
            if eq.any():
                tasks.append(Task(f"L{i}_eq", A[eq], lo[eq]))
            if (~eq).any():
                tasks.append(Task(f"L{i}_ineq", A[~eq], lower=lo[~eq], upper=up[~eq]))
            for t in tasks:
                t.validate(level=i, n=n)
        except TaskStackError as exc:
            raise TaskStackError(f"{where}: {exc}") from None
        out.append(tasks)
        kept.append(i)
    if not out:
        raise TaskStackError(f"{where}: no level has any row")
    return TaskStack(out), tuple(kept)


def _read_text(path: Path) -> str:
    try:
        return path.read_text()
    except OSError as exc:
        raise TaskStackError(f"cannot read {path}: {exc.strerror}") from None


def _floats(tokens: list[str], where: str) -> np.ndarray:
    try:
        return np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError as exc:
        raise TaskStackError(f"{where}: not a number ({exc})") from None


def load_lexls(path: str | Path) -> PeerProblem:
    """Read a lexls hierarchy file (``tests/*.dat`` of jrl-umi3218/lexls).

    Format (lexls ``tools::HierarchyFileProcessor``): header fields in any order —
    ``#HierType`` (``100``: rows ``A b``, equalities; ``200``: rows ``A lb ub``; ``210``:
    ``A lb ub`` plus an active-set guess per row: 0 inactive, 1 lower, 2 upper,
    3 equality), ``#nVar``, ``#nObj``, ``#nCtr`` (rows per level) and ``#ObjType`` per level
    (``200``: general rows; ``100``: simple bounds ``index lb ub`` on ``x[index]`` with a
    **1-based** index, allowed on the first level only) — then one ``#OBJECTIVE k`` block
    per level in order, and optionally ``#SolGuess`` and ``#Solution`` (``n`` numbers).
    Every row of lexls is soft (``lb ≤ A x − w ≤ ub``); rows with ``lb == ub`` become
    equality tasks. ``#Solution`` becomes :attr:`PeerProblem.x_stored`.

    Raises:
        TaskStackError: naming the file and the field, level or row at fault.
    """
    path = Path(path)
    lines = _read_text(path).splitlines()
    header: dict[str, list[str]] = {}
    i = 0
    keys = ("#HierType", "#nVar", "#nObj", "#nCtr", "#ObjType")
    while i < len(lines) and len(header) < len(keys):
        key = lines[i].strip()
        if key in keys:
            if key in header:
                raise TaskStackError(f"{path}: duplicate header field {key}")
            header[key] = lines[i + 1].split() if i + 1 < len(lines) else []
            i += 2
            continue
        i += 1
    missing = [k for k in keys if k not in header or not header[k]]
    if missing:
        raise TaskStackError(f"{path}: missing header field(s) {', '.join(missing)}")
    try:
        hier = int(header["#HierType"][0])
        n = int(header["#nVar"][0])
        k = int(header["#nObj"][0])
        n_ctr = [int(v) for v in header["#nCtr"]]
        obj_types = [int(v) for v in header["#ObjType"]]
    except ValueError as exc:
        raise TaskStackError(f"{path}: unreadable header ({exc})") from None
    if hier not in (100, 200, 210):
        raise TaskStackError(f"{path}: #HierType {hier} is not 100, 200 or 210")
    if len(n_ctr) != k or len(obj_types) != k:
        raise TaskStackError(f"{path}: #nObj is {k} but #nCtr has {len(n_ctr)} and "
                             f"#ObjType {len(obj_types)} entries")
    n_bounds = 1 if hier == 100 else 2
    levels, guess = [], []
    for j in range(k):
        while i < len(lines) and not lines[i].replace(" ", "").startswith("#OBJECTIVE"):
            i += 1
        if i >= len(lines):
            raise TaskStackError(f"{path}: {j} of {k} #OBJECTIVE blocks found")
        i += 1
        if obj_types[j] == 100 and j != 0:
            raise TaskStackError(f"{path}: level {j}: simple bounds (type 100) are only "
                                 f"allowed on the first level")
        if obj_types[j] not in (100, 200):
            raise TaskStackError(f"{path}: level {j}: #ObjType {obj_types[j]} is not 100 or 200")
        cols = (1 if obj_types[j] == 100 else n) + n_bounds
        rows, act = [], []
        for r in range(n_ctr[j]):
            where = f"{path}: level {j}, row {r}"
            if i >= len(lines):
                raise TaskStackError(f"{where}: the file ends")
            tok = lines[i].split()
            i += 1
            if len(tok) < cols:
                raise TaskStackError(f"{where}: {len(tok)} numbers, {cols} expected")
            rows.append(_floats(tok[:cols], where))
            act.append(int(tok[cols]) if hier == 210 and len(tok) > cols else 0)
        data = np.array(rows).reshape(n_ctr[j], cols)
        lo = data[:, -n_bounds]
        up = data[:, -1]
        if obj_types[j] == 100:
            idx = data[:, 0]
            if np.any(idx != np.round(idx)) or np.any(idx < 1) or np.any(idx > n):
                bad = int(np.flatnonzero((idx != np.round(idx)) | (idx < 1) | (idx > n))[0])
                raise TaskStackError(f"{path}: level {j}, row {bad}: simple-bound index "
                                     f"{idx[bad]:g} is not in 1..{n} (1-based)")
            A = np.zeros((n_ctr[j], n))
            A[np.arange(n_ctr[j]), idx.astype(int) - 1] = 1.0
        else:
            A = data[:, :n]
        levels.append((A, lo, up))
        guess.append(act)
    vectors: dict[str, np.ndarray] = {}
    while i < len(lines):
        key = lines[i].strip()
        i += 1
        if key in ("#SolGuess", "#Solution"):
            tok = []
            while i < len(lines) and len(tok) < n:
                tok += lines[i].split()
                i += 1
            if len(tok) < n:
                raise TaskStackError(f"{path}: {key} holds {len(tok)} numbers, {n} expected")
            vectors[key] = _floats(tok[:n], f"{path}: {key}")
    stack, kept = _peer_stack(levels, n, str(path))
    extras: dict[str, Any] = {"objective_types": obj_types, "hierarchy_type": hier}
    if "#SolGuess" in vectors:
        extras["solution_guess"] = vectors["#SolGuess"]
    if hier == 210:
        extras["active_set_guess"] = guess
    return PeerProblem(path.stem, stack, vectors.get("#Solution"), None, kept,
                       "jrl-umi3218/lexls", "", extras)


#: soth's text format: a bound beyond this magnitude is no bound (soth writes ±1e25).
SOTH_INFINITY = 1e10


def load_soth(path: str | Path, problems: Sequence[int] | None = None) -> list[PeerProblem]:
    """Read soth's text problems (``unitTesting/*.txt`` of stack-of-tasks/soth).

    Format (soth ``readProblemFromFile``): ``variable size N``, then per level ``level``,
    ``equalities m`` and ``m`` rows ``a_1 … a_N b``, ``inequalities m`` and ``m`` rows
    ``a_1 … a_N lb ub``; ``end`` closes a problem. A lower bound below
    ``−SOTH_INFINITY`` or an upper bound above ``SOTH_INFINITY`` is absent (soth writes
    ``±1e25``). A file may hold several problems (``new.txt``); they are named
    ``<stem>#0``, ``<stem>#1``, …

    Args:
        path: The file.
        problems: Indices of the problems to read (default: all of them).

    Raises:
        TaskStackError: naming the file, problem, level and row at fault — also when a
            count disagrees with the rows that follow (soth's own reader would then
            misread the rest of the file); every problem is read first, and the message
            names the other problems that fail and those that parse, with the
            ``problems=`` that reads them alone (its ``detail``: ``failed``, ``parsed``).
    """
    path = Path(path)
    text = _read_text(path)
    blocks: list[list[list[str]]] = []
    current: list[list[str]] | None = None
    for line in text.splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[:2] == ["variable", "size"]:
            current = [tok]
            blocks.append(current)
        elif tok[0] == "end":
            current = None
        elif current is not None:
            current.append(tok)
    if not blocks:
        raise TaskStackError(f"{path}: no 'variable size N' line")
    wanted = range(len(blocks)) if problems is None else list(problems)
    out, failed = [], []
    for p in wanted:
        if not 0 <= p < len(blocks):
            raise TaskStackError(f"{path}: problem {p} requested, the file holds "
                                 f"{len(blocks)}")
        name = path.stem if len(blocks) == 1 else f"{path.stem}#{p}"
        try:
            out.append(_soth_problem(blocks[p], f"{path}: problem {p}", name))
        except TaskStackError as exc:
            failed.append((p, exc))
    if failed:
        raise _soth_failure(failed, [p for p in wanted if p not in dict(failed)]) from None
    return out


def _soth_failure(failed: list[tuple[int, TaskStackError]], parsed: list[int]
                  ) -> TaskStackError:
    """The first problem's error, naming the others that fail and how to read those
    that parse (``problems=`` here, ``--problems`` of ``prioik solve``)."""
    first = failed[0][1]
    message = first.reason
    if len(failed) > 1:
        message += f" (problems {', '.join(str(p) for p, _ in failed[1:])} fail too)"
    if parsed:
        which = ", ".join(map(str, parsed))
        message += (f"; problems {which} parse: read them alone with problems=[{which}] "
                    f"(prioik solve --problems {which.replace(' ', '')})")
    return TaskStackError(message, task=first.task, level=first.level, **first.detail,
                          failed=[p for p, _ in failed], parsed=parsed)


def _soth_problem(block: list[list[str]], where: str, name: str) -> PeerProblem:
    try:
        n = int(block[0][2])
    except (IndexError, ValueError):
        raise TaskStackError(f"{where}: 'variable size N' needs an integer N") from None
    levels: list = []
    i = 1
    while i < len(block):
        if block[i] != ["level"]:
            raise TaskStackError(f"{where}: 'level' expected, got {' '.join(block[i])!r}")
        j = len(levels)
        i += 1
        rows: dict[str, np.ndarray] = {}
        for kind, width in (("equalities", n + 1), ("inequalities", n + 2)):
            if i >= len(block) or len(block[i]) != 2 or block[i][0] != kind:
                raise TaskStackError(f"{where}, level {j}: '{kind} m' expected")
            m = int(block[i][1])
            i += 1
            given = 0
            while i + given < len(block) and block[i + given][0] not in (
                    "level", "equalities", "inequalities"):
                given += 1
            if given != m:
                raise TaskStackError(f"{where}, level {j}: '{kind} {m}' but {given} rows follow")
            data = [_floats(block[i + r], f"{where}, level {j}, {kind} row {r}")
                    for r in range(m)]
            for r, d in enumerate(data):
                if d.shape[0] != width:
                    raise TaskStackError(f"{where}, level {j}, {kind} row {r}: {d.shape[0]} "
                                         f"numbers, {width} expected")
            rows[kind] = np.array(data).reshape(m, width)
            i += m
        eq, ineq = rows["equalities"], rows["inequalities"]
        lo = np.where(ineq[:, n] < -SOTH_INFINITY, -np.inf, ineq[:, n])
        up = np.where(ineq[:, n + 1] > SOTH_INFINITY, np.inf, ineq[:, n + 1])
        levels.append((np.vstack([eq[:, :n], ineq[:, :n]]),
                       np.concatenate([eq[:, n], lo]), np.concatenate([eq[:, n], up])))
    stack, kept = _peer_stack(levels, n, where)
    return PeerProblem(name, stack, None, None, kept, "stack-of-tasks/soth")


def load_peer_json(path: str | Path) -> PeerProblem:
    """Read the peer JSON format of ``tests/data/peer`` (see its README).

    ``{"source", "path", "commit", "n", "levels": [{"A", "lb", "ub"}, …], "x_stored",
    "note"}`` with ``±Infinity`` for absent sides; optional ``f_analytic`` (per-level
    ``‖w_i‖²`` worked out by hand, one per file level) and ``x_analytic``.

    Raises:
        TaskStackError: naming the file and the key or level at fault.
    """
    path = Path(path)
    try:
        data = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise TaskStackError(f"{path}: invalid JSON at line {exc.lineno}: {exc.msg}") from None
    if not isinstance(data, dict) or not isinstance(data.get("levels"), list) \
            or not isinstance(data.get("n"), int):
        raise TaskStackError(f"{path}: a peer file is an object with an integer 'n' and "
                             f"a 'levels' list")
    n = data["n"]
    levels = []
    for i, lv in enumerate(data["levels"]):
        if not isinstance(lv, dict) or not {"A", "lb", "ub"} <= set(lv):
            raise TaskStackError(f"{path}: level {i} needs 'A', 'lb' and 'ub'")
        try:
            levels.append((np.array(lv["A"], dtype=np.float64).reshape(-1, n),
                           np.array(lv["lb"], dtype=np.float64),
                           np.array(lv["ub"], dtype=np.float64)))
        except (TypeError, ValueError) as exc:
            raise TaskStackError(f"{path}: level {i}: {exc}") from None
    stack, kept = _peer_stack(levels, n, str(path))

    def vector(key, size):
        v = data.get(key)
        if v is None:
            return None
        arr = np.array(v, dtype=np.float64).reshape(-1)
        if arr.shape != (size,):
            raise TaskStackError(f"{path}: '{key}' has {arr.shape[0]} entries, {size} expected")
        return arr

    f = vector("f_analytic", len(levels))
    extras = {}
    if data.get("x_analytic") is not None:
        extras["x_analytic"] = vector("x_analytic", n)
    source = " ".join(str(data.get(k, "")) for k in ("source", "path", "commit")).strip()
    return PeerProblem(path.stem, stack, vector("x_stored", n),
                       None if f is None else f[list(kept)], kept, source,
                       str(data.get("note", "")), extras)


def load_peer(path: str | Path) -> list[PeerProblem]:
    """Read any peer file by its suffix: ``.dat`` lexls, ``.txt`` soth, ``.json`` peer JSON."""
    path = Path(path)
    if path.suffix == ".dat":
        return [load_lexls(path)]
    if path.suffix == ".txt":
        return load_soth(path)
    if path.suffix == ".json":
        return [load_peer_json(path)]
    raise TaskStackError(f"{path}: unknown peer format (suffix .dat, .txt or .json)")
