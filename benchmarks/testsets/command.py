"""``prioik bench --test-set NAME``: run test sets, write their CSV and report.

Arguments are declared by :func:`add_arguments` on ``prioik bench``'s parser
(:mod:`prioik.benchmarks.bench.command`), which hands the run to :func:`run` when
``--test-set`` is given.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from .metrics import PROFILES

__all__ = ["add_arguments", "run", "parse_set_options"]


class _TestSetAction(argparse.Action):
    """Store the test-set names; the test-set mode needs none of ``bench``'s extras
    (each test set names its own, checked when it runs)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.extras = ()


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The test-set options of ``prioik bench``."""
    g = p.add_argument_group(
        "test sets (qpbenchmark's shape)",
        "With --test-set, bench runs test sets instead of its timing tables: every "
        "formulation row on every problem, success per tolerance profile (low 1e-3, "
        "mid 1e-6, high 1e-9), shifted geometric means of time and of flops (the "
        "compiled closed forms count them) normalised to the best; "
        "writes OUT/testsets.csv (one row per problem × formulation) and "
        "OUT/testsets.md (generated from the CSV). --formulations, --repeats (default 3 "
        "passes), --out and --doc apply.")
    g.add_argument("--test-set", default=None, action=_TestSetAction, metavar="NAME",
                   help="comma-separated test sets, 'all', or 'list' to list them")
    g.add_argument("--profile", default="mid", choices=tuple(PROFILES),
                   help="the tolerance profile of the report's time columns and failure "
                        "list (success is reported at every profile; default mid)")
    g.add_argument("--from-csv", type=Path, default=None, metavar="CSV",
                   help="with --test-set: no run; write the report of the test sets of "
                        "this testsets.csv (those named, or every one with 'all') to "
                        "OUT/testsets.md (and --doc)")
    g.add_argument("--set-option", action="append", default=[], metavar="KEY=VALUE",
                   help="a size option of the test sets (integer), e.g. samples=2, n=8, "
                        "steps=6, windows=2; repeatable; a set ignores keys it does "
                        "not take")


def parse_set_options(items: list[str]) -> dict[str, int]:
    """``["samples=2", "n=8"]`` → ``{"samples": 2, "n": 8}``.

    Raises:
        ValueError: an item is not ``KEY=INTEGER``.
    """
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        try:
            if not sep or not key.strip():
                raise ValueError
            out[key.strip()] = int(value)
        except ValueError:
            raise ValueError(f"--set-option takes KEY=INTEGER, got {item!r}") from None
    return out


def _sizes_for(cls, options: dict[str, int]) -> dict[str, int]:
    import inspect
    accepted = inspect.signature(cls.__init__).parameters
    return {k: v for k, v in options.items() if k in accepted}


def _command(args: argparse.Namespace) -> str:
    parts = ["prioik bench", f"--test-set {args.test_set}", f"--profile {args.profile}"]
    parts += [f"--set-option {o}" for o in args.set_option]
    if args.repeats is not None:
        parts.append(f"--repeats {args.repeats}")
    if args.formulations:
        parts.append(f"--formulations {args.formulations}")
    parts.append(f"--out {args.out}")
    if args.doc:
        parts.append(f"--doc {args.doc}")
    return " ".join(parts)


def run(args: argparse.Namespace) -> int:
    """Run the test sets ``args.test_set`` names (or list them)."""
    from prioik.extras import require

    from . import TEST_SETS
    from .report import format_report
    from .run import default_rows, load_csv, run_test_set, write_csv
    if args.test_set == "list":
        for name, cls in TEST_SETS.items():
            seq = " (sequential)" if cls.sequential else ""
            print(f"{name:24s} {cls.description}{seq}")
        return 0
    names = list(TEST_SETS) if args.test_set == "all" else \
        [s.strip() for s in args.test_set.split(",") if s.strip()]
    unknown = [s for s in names if s not in TEST_SETS]
    if unknown or not names:
        raise ValueError(f"unknown test set(s) {', '.join(unknown) or '(none)'}; known: "
                         f"{', '.join(TEST_SETS)} (or 'all', 'list')")
    if args.from_csv is not None:
        return _report_from_csv(args, names)
    from prioik.smoke import ARGUMENT_CAPS, cap
    repeats = cap(3, ARGUMENT_CAPS["repeats"]) if args.repeats is None else args.repeats
    if repeats < 1:
        raise ValueError(f"--repeats must be ≥ 1, got {repeats}")
    options = parse_set_options(args.set_option)
    from prioik.benchmarks.variants import split_labels
    labels = split_labels(args.formulations) if args.formulations else None
    records, notes = [], []
    start = time.perf_counter()
    for name in names:
        cls = TEST_SETS[name]
        require(*cls.needs, what=f"the test set {name}")
        test_set = cls(**_sizes_for(cls, options))
        rows, row_notes = default_rows(cls.sequential, labels)
        notes += [n for n in row_notes if n not in notes]
        print(f"{name}: {len(rows)} rows", flush=True)
        records += run_test_set(test_set, rows, repeats)
    out = Path(args.out)
    csv_path = write_csv(records, out / "testsets.csv")
    from prioik.benchmarks.machine import machine
    m = machine()
    machine_line = (f"**Machine**: {m.get('cpu', '')}, {m.get('cores', '')} cores, "
                    f"Python {m.get('python', '')}; BLAS {m.get('blas', '')}; "
                    f"{m.get('versions', '')}.")
    text = format_report(load_csv(csv_path), args.profile, command=_command(args),
                         machine=machine_line, notes=notes,
                         descriptions={n: TEST_SETS[n].description for n in names})
    written = [str(csv_path)] + _write_report(args, text)
    print(f"wrote {', '.join(written)} in {time.perf_counter() - start:.0f} s")
    return 0


def _write_report(args: argparse.Namespace, text: str) -> list[str]:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "testsets.md").write_text(text)
    written = [str(out / "testsets.md")]
    if args.doc:
        Path(args.doc).parent.mkdir(parents=True, exist_ok=True)
        Path(args.doc).write_text(text)
        written.append(str(args.doc))
    return written


def _report_from_csv(args: argparse.Namespace, names: list[str]) -> int:
    """The report of ``args.from_csv``'s records of the test sets ``names``."""
    from . import TEST_SETS
    from .report import format_report
    from .run import load_csv
    records = [r for r in load_csv(args.from_csv)
               if args.test_set == "all" or r["test_set"] in names]
    if not records:
        raise ValueError(f"{args.from_csv} holds no record of {', '.join(names)}")
    present = list(dict.fromkeys(r["test_set"] for r in records))
    command = (f"prioik bench --test-set {args.test_set} --profile {args.profile} "
               f"--from-csv {args.from_csv} --out {args.out}"
               + (f" --doc {args.doc}" if args.doc else ""))
    text = format_report(records, args.profile, command=command,
                         descriptions={n: TEST_SETS[n].description for n in present
                                       if n in TEST_SETS})
    print(f"wrote {', '.join(_write_report(args, text))}")
    return 0
