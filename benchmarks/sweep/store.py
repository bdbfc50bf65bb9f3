"""The rows file of a sweep: one CSV line appended, flushed and synced per finished run.

Only the process that drives the sweep writes (workers return rows), so a worker that
dies loses no written row; a driver killed mid-line leaves a partial last line, which
:class:`RowStore` drops when it reopens the file. Rows already present are the ones a
resumed sweep skips.
"""

from __future__ import annotations

import csv
import fcntl
import io
import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = ["RowStore", "read_rows"]

_INT = ("point", "steps")
_BOOL = ("failed",)
_STR = ("run_id", "scenario", "label", "formulation", "options", "level", "status",
        "message", "worker", "robot")


def _format(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("nan" if math.isnan(value) else
                                                         ("inf" if value > 0 else "-inf"))
    return str(value)


def _parse(column: str, text: str) -> Any:
    if column in _STR:
        return text
    if text == "":
        return None
    if column in _BOOL:
        return text == "true"
    if column in _INT:
        return int(text)
    return float(text)


def read_rows(path) -> list[dict[str, Any]]:
    """Every complete row of a rows file, typed (numbers, booleans, ``None`` for empty)."""
    path = Path(path)
    text = path.read_text()
    if not text:
        return []
    if not text.endswith("\n"):
        text = text[:text.rfind("\n") + 1]
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if header is None:
        return []
    return [{c: _parse(c, v) for c, v in zip(header, line, strict=False)} for line in reader
            if len(line) == len(header)]


class RowStore:
    """Append-only rows of one sweep (``rows.csv`` in the output folder).

    Args:
        path: The CSV file (created with ``columns`` as header if missing).
        columns: The sweep's columns (:func:`.schema.columns`).

    Raises:
        ValueError: the file holds rows of another shape, or another sweep is writing
            it now (an exclusive ``flock`` on ``rows.csv.lock``; names the file).
    """

    def __init__(self, path, columns: Iterable[str]) -> None:
        self.path = Path(path)
        self.columns = list(columns)
        self.rows: dict[str, dict[str, Any]] = {}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = open(self.path.with_name(self.path.name + ".lock"), "w")
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock.close()
            raise ValueError(f"{self.path} is being written by another prioik sweep; "
                             f"wait for it or use another --out") from None
        if self.path.exists() and self.path.stat().st_size:
            raw = self.path.read_bytes()
            header = raw.split(b"\n", 1)[0].decode().rstrip("\r").split(",")
            if header != self.columns:
                raise ValueError(f"{self.path} holds rows of another sweep (its columns "
                                 f"differ); use another --out")
            if not raw.endswith(b"\n"):            # a write cut short: drop its partial line
                with open(self.path, "r+b") as f:
                    f.truncate(raw.rfind(b"\n") + 1)
            for row in read_rows(self.path):
                self.rows[row["run_id"]] = row
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(self.path, "w", newline="") as f:
                csv.writer(f, lineterminator="\n").writerow(self.columns)
                f.flush()
                os.fsync(f.fileno())
        self._file = open(self.path, "a", newline="")
        self._writer = csv.writer(self._file, lineterminator="\n")

    def __contains__(self, run_id: str) -> bool:
        return run_id in self.rows

    def append(self, row: dict[str, Any]) -> None:
        """Write ``row`` and sync it to disk (a second row of the same run is refused)."""
        if row["run_id"] in self.rows:
            raise ValueError(f"run {row['run_id']} is already in {self.path}")
        self._writer.writerow([_format(row.get(c)) for c in self.columns])
        self._file.flush()
        os.fsync(self._file.fileno())
        self.rows[row["run_id"]] = {c: _parse(c, _format(row.get(c))) for c in self.columns}

    def close(self) -> None:
        self._file.close()
        self._lock.close()

    def __enter__(self) -> RowStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
