"""``prioik bench``: its arguments (see :mod:`prioik.benchmarks.bench`)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from prioik.smoke import shrink_bench_settings

from .settings import LEVELS, SIZES, Settings, quick_settings

__all__ = ["add_parser", "run"]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="time every formulation and back-end (G1 and random "
                                     "stacks); CSV, markdown and plots",
                       description="Time every formulation and back-end on G1 fencing "
                                   "and random stacks; with --test-set, run test sets "
                                   "in qpbenchmark's shape instead.")
    p.add_argument("--out", type=Path, default=Path("bench-results"),
                   help="output directory (default: bench-results)")
    p.add_argument("--doc", type=Path, default=None,
                   help="also write the documentation page here (e.g. docs/benchmarks.md)")
    p.add_argument("--quick", action="store_true", help="a smaller run (under a minute)")
    p.add_argument("--repeats", type=int, default=None, help="timed solves per case")
    p.add_argument("--cap", type=float, default=None,
                   help="seconds of timed solves per (case, formulation) before repeats "
                        "are reduced")
    p.add_argument("--family", default=None, help="random stack family (hierarchy.families)")
    p.add_argument("--formulations", default="",
                   help="comma-separated formulation names or row labels (default: all; "
                        "an unknown one exits 2 listing the known ones)")
    p.add_argument("--sizes", default=None, help="comma-separated n of the random cases "
                                                 f"(default: {','.join(map(str, SIZES))})")
    p.add_argument("--levels", default=None, help="comma-separated k of the random cases "
                                                  f"(default: {','.join(map(str, LEVELS))})")
    p.add_argument("--samples", type=int, default=None,
                   help="stacks per random case (default: 8)")
    p.add_argument("--blas-threads", type=int, default=1,
                   help="threads of OpenBLAS while measuring (default 1, as in a control "
                        "loop; 0: leave BLAS's default)")
    p.add_argument("--no-g1", action="store_true",
                   help="random stacks only (no G1 cases, batch, IK-step or control-step runs)")
    from prioik.benchmarks.testsets.command import add_arguments
    add_arguments(p)
    p.set_defaults(func=run, extras=("plots",))


def _command(args: argparse.Namespace) -> str:
    """The command line that reproduces this run (printed in the doc page)."""
    parts = ["prioik bench"]
    if args.quick:
        parts.append("--quick")
    parts.append(f"--out {args.out}")
    if args.doc:
        parts.append(f"--doc {args.doc}")
    for flag, value in (("--repeats", args.repeats), ("--cap", args.cap),
                        ("--family", args.family), ("--formulations", args.formulations),
                        ("--sizes", args.sizes), ("--levels", args.levels),
                        ("--samples", args.samples)):
        if value not in (None, ""):
            parts.append(f"{flag} {value}")
    if args.blas_threads != 1:
        parts.append(f"--blas-threads {args.blas_threads}")
    if args.no_g1:
        parts.append("--no-g1")
    return " ".join(parts)


def _int_list(text: str, what: str) -> tuple[int, ...]:
    try:
        values = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise ValueError(f"{what} takes comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise ValueError(f"{what} takes positive integers, got {text!r}")
    return values


def run(args: argparse.Namespace) -> int:
    if args.test_set is not None:
        from prioik.benchmarks.testsets.command import run as run_test_sets
        return run_test_sets(args)
    from prioik.benchmarks.variants import check_formulations, split_labels, table
    only = tuple(split_labels(args.formulations))
    check_formulations(only)                      # an unknown name: before anything
    settings = quick_settings() if args.quick else Settings()
    if args.repeats is not None:
        if args.repeats < 1:
            raise ValueError(f"--repeats must be ≥ 1, got {args.repeats}")
        settings.repeats = args.repeats
        settings.min_repeats = min(settings.min_repeats, args.repeats)
    if args.cap is not None:
        if not args.cap > 0:
            raise ValueError(f"--cap must be > 0, got {args.cap}")
        settings.cap_s = args.cap
    if args.family:
        from prioik.hierarchy.families import FAMILIES
        if args.family not in FAMILIES:
            raise ValueError(f"unknown family {args.family!r}; known: {', '.join(FAMILIES)}")
        settings.family = args.family
    settings.only = only
    table("bench").check_names(only)              # an unknown row label: before anything runs
    if args.sizes:
        settings.sizes = _int_list(args.sizes, "--sizes")
    if args.levels:
        settings.levels = _int_list(args.levels, "--levels")
    if args.samples is not None:
        if args.samples < 1:
            raise ValueError(f"--samples must be ≥ 1, got {args.samples}")
        settings.samples = args.samples
    settings.g1 = not args.no_g1
    if args.blas_threads < 0:
        raise ValueError(f"--blas-threads must be ≥ 0, got {args.blas_threads}")
    settings.blas_threads = args.blas_threads
    shrink_bench_settings(settings)               # PRIOIK_SMOKE=1: a few cases and solves
    command = _command(args)
    from .run import run_benchmark
    summary = run_benchmark(settings, args.out, args.doc, command)
    print(f"wrote {args.out}/results.csv, results.md, summary.json and plots "
          f"in {summary['elapsed_s']:.0f} s")
    for r in summary["ratios"]:
        v = r["value"]
        if not math.isfinite(v):
            print(f"  {r['name']}: n/a")
        elif math.isinf(r["target"]):
            print(f"  {r['name']}: {v:.2f} (reported beside the target)")
        else:
            print(f"  {r['name']}: {v:.2f} (target ≤ {r['target']:g}, met: {r['met']})")
    return 0
