"""The ``prioik`` command line: argument parsing and dispatch only.

Every sub-command is declared by the module that runs it (``add_parser(subparsers)``,
listed in :data:`SUBCOMMAND_MODULES`); this module builds the parser from them, runs the
chosen command with BLAS limited to its ``--blas-threads`` (one by default,
:mod:`.threads`) and turns the library's errors (every :class:`~prioik.PrioikError`, and
the ``ValueError``/``OSError`` of a bad argument or file) into one line on stderr (exit
status 2).

Building the parser imports no optional dependency: a sub-command module imports what
it needs when it runs, and a sub-command that needs extras names them in its defaults
(``p.set_defaults(extras=("robots", "plots"))``); a missing one is reported in one
line naming the ``pip install prioik[EXTRA]`` to run (exit status 2).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from .smoke import ENV, EPILOG, active, shrink_arguments

#: modules that contribute a sub-command through ``add_parser(subparsers)``
SUBCOMMAND_MODULES = [
    "prioik.benchmarks.library",
    "prioik.benchmarks.fencing",
    "prioik.benchmarks.arm",
    "prioik.benchmarks.saved_runs",
    "prioik.benchmarks.compare",
    "prioik.benchmarks.bench.command",
    "prioik.benchmarks.properties",
    "prioik.benchmarks.validation",
    "prioik.benchmarks.sweep.command",
    "prioik.benchmarks.fuzz",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="prioik",
        description="Task-priority inverse kinematics: one task-stack spec, every formulation.",
        epilog=EPILOG)
    from prioik import __version__
    parser.add_argument("--version", action="version", version=f"prioik {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in SUBCOMMAND_MODULES:
        importlib.import_module(name).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``prioik`` console script."""
    from prioik.errors import PrioikError
    from prioik.extras import require

    from .threads import blas_threads
    args = shrink_arguments(build_parser().parse_args(argv))     # PRIOIK_SMOKE=1: a few steps
    args.command_line = list(sys.argv[1:] if argv is None else argv)
    if active():
        print(f"prioik {args.command}: {ENV} is set: a few steps, stacks and solves "
              "(a testing aid; its numbers are not measurements)", file=sys.stderr)
    try:
        require(*getattr(args, "extras", ()), what="this command")
        with blas_threads(getattr(args, "blas_threads", 1)):
            code = int(args.func(args) or 0)
            sys.stdout.flush()          # a closed pipe shows here, not at exit
            return code
    except BrokenPipeError:
        # the reader (e.g. `| head -1`) closed the pipe: exit quietly, and keep
        # Python's own flush at exit from failing on the closed descriptor again
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 0
    except (PrioikError, ValueError, OSError) as exc:
        print(f"prioik {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2


def _one_line(exc: BaseException) -> str:
    """The error message on one line (a multi-line message is joined with ' | ')."""
    return " | ".join(line.strip() for line in str(exc).splitlines() if line.strip())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
