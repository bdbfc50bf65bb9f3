"""``prioik sweep CONFIG --out DIR``: argument parsing only (see :mod:`prioik.benchmarks.sweep`)."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path


def run_command(args: argparse.Namespace) -> int:
    """Validate the sweep, run the missing rows, write the report."""
    from .config import load_config, plan_from_config
    from .execute import run_sweep
    from .report import write_report
    plan = plan_from_config(load_config(args.config))
    print(f"sweep: {len(plan.runs)} runs ({plan.points} points × {len(plan.variants)} "
          f"formulation variants) into {args.out}", file=sys.stderr)
    if args.dry_run:
        return 0
    if args.throughput:
        from .throughput import measure
        result = measure(plan, args.out, args.throughput, progress=args.progress)
        print(f"sweep: throughput {result['speedup']:.2f} x with "
              f"{result['worker_counts'][-1]} workers against 1"
              if result["speedup"] else "sweep: throughput: one worker count only",
              file=sys.stderr)
    outcome = run_sweep(plan, args.out, workers=args.workers, scheduler=args.scheduler,
                        progress=args.progress)
    command = "prioik " + " ".join(shlex.quote(a) for a in getattr(args, "command_line",
                                                                  ["sweep", args.config]))
    path = write_report(plan, outcome.rows, args.out, outcome.info, command,
                        Path(args.doc) if args.doc else None)
    print(f"wrote {path}", file=sys.stderr)
    return 0 if len(outcome.rows) == len(plan.runs) else 1


def add_parser(subparsers) -> None:
    """Register ``prioik sweep``."""
    p = subparsers.add_parser(
        "sweep", help="a declared grid / random sample of scenario runs on dask.distributed",
        description="Run a sweep file (TOML or JSON: scenario parameters as fixed values, "
                    "grid axes or random ranges × formulation variants; see "
                    "prioik.benchmarks.sweep.config) as independent tasks on an embedded "
                    "LocalCluster (one worker process per core, one BLAS thread each) or "
                    "an existing scheduler. Each run's row is appended to DIR/rows.csv as "
                    "it finishes; rerunning the command resumes, skipping finished runs. "
                    "Writes DIR/report.md with plots.")
    p.add_argument("config", help="sweep file (.toml or .json)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (rows.csv, "
                   "report.md, plots, run_info.json)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the embedded LocalCluster (default: one per "
                        "core; 0: run in this process without dask)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="use the dask scheduler at ADDRESS (e.g. tcp://host:8786) instead "
                        "of an embedded cluster")
    p.add_argument("--doc", default=None, metavar="PATH",
                   help="also write the page at PATH (e.g. docs/sweep.md; plots copied to "
                        "img/ beside it)")
    p.add_argument("--throughput", type=int, default=0, metavar="N",
                   help="first time N of the sweep's runs (spread over it) on 1 worker and "
                        "on one worker per core, twice each, alternating, every pass from "
                        "scratch, and report the fastest passes' speed-up "
                        "(DIR/throughput.json and the page)")
    p.add_argument("--dry-run", action="store_true",
                   help="validate the sweep file and print its size; run nothing")
    p.add_argument("--quiet", dest="progress", action="store_false",
                   help="no progress bar on stderr")
    p.set_defaults(func=run_command, extras=("sweep", "robots", "plots"))
