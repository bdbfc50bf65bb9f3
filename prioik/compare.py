"""Side-by-side comparison of every available formulation on task stacks.

``prioik compare FILE...`` (and ``make demo`` until the fencing scenario lands) solves
each stack with every formulation that can take it and prints, per formulation, the
per-level residuals, the distance to ``reference`` and the median solve time.
"""

from __future__ import annotations

import argparse
import statistics
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prioik import formulations
from prioik.formulations.registry import check_support
from prioik.hierarchy import (
    TaskStack,
    UnsupportedTaskError,
    check_lexicographic,
    load_stack,
    relative_distance,
)


@dataclass
class Row:
    """One formulation's result on one stack."""

    formulation: str
    status: str
    residuals: np.ndarray
    distance: float
    lexicographic: str
    median_time_s: float


def compare_stack(stack: TaskStack, repeats: int = 20,
                  names: list[str] | None = None) -> tuple[list[Row], list[str]]:
    """Solve ``stack`` with each formulation; returns rows and the skipped reasons."""
    ref = formulations.solve(stack, "reference").x if stack.is_equality else None
    rows, skipped = [], []
    for info in formulations.available():
        if names and info.name not in names:
            continue
        if not info.available:
            skipped.append(f"{info.name}: not available ({info.reason})")
            continue
        try:
            check_support(info.name, info.capabilities, stack)
        except UnsupportedTaskError as exc:
            skipped.append(f"{info.name}: {exc}")
            continue
        if info.capabilities.needs_mass_matrix:
            skipped.append(f"{info.name}: needs a mass matrix (robot stacks only)")
            continue
        times = []
        for _ in range(repeats):
            sol = formulations.solve(stack, info.name)
            times.append(sol.time_s)
        dist = relative_distance(sol.x, ref) \
            if ref is not None and sol.ok else float("nan")
        lex = "-"
        if stack.is_equality and sol.ok:
            lex = "yes" if check_lexicographic(stack, sol.x).ok else "no"
        rows.append(Row(info.name, sol.status, sol.residuals, dist, lex,
                        statistics.median(times)))
    return rows, skipped


def format_table(rows: list[Row]) -> str:
    """A plain-text table of :class:`Row`."""
    head = (f"{'formulation':<22} {'status':<11} {'residual per level':<36} "
            f"{'dist. to ref':>12} {'lex. opt.':>9} {'median time':>12}")
    out = [head, "-" * len(head)]
    for r in rows:
        res = " ".join(f"{v:.2e}" for v in r.residuals[:4]) + (" …" if len(r.residuals) > 4 else "")
        out.append(f"{r.formulation:<22} {r.status:<11} {res:<36} {r.distance:>12.2e} "
                   f"{r.lexicographic:>9} {r.median_time_s * 1e6:>9.1f} µs")
    return "\n".join(out)


def examples_dir() -> Path:
    """The example stacks shipped with the package (``prioik/hierarchy/examples``,
    installed as package data: ``prioik compare`` works from a wheel)."""
    from importlib.resources import files
    return Path(str(files("prioik.hierarchy") / "examples"))


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="solve stacks with every formulation, side by side",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("files", nargs="*", type=Path,
                   help="task-stack JSON files (default: the shipped examples, "
                        "hierarchy/examples/*.json)")
    p.add_argument("--formulations", default="", help="comma-separated names (default: all)")
    p.add_argument("--repeats", type=int, default=20, help="solves per formulation (median)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    files = args.files or sorted(examples_dir().glob("*.json"))
    names = [s.strip() for s in args.formulations.split(",") if s.strip()] or None
    unknown = [name for name in names or [] if name not in formulations.names()]
    if unknown:
        raise formulations.FormulationError(
            f"unknown formulation {', '.join(map(repr, unknown))}; known: "
            f"{', '.join(formulations.names())}")
    for path in files:
        stack = load_stack(path)
        rows, skipped = compare_stack(stack, args.repeats, names)
        print(f"\n== {path.name}: {len(stack)} levels, n = {stack.n}")
        print(format_table(rows))
        for s in skipped:
            print(f"   skipped {s}")
    return 0
