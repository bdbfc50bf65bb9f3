"""The ``prioik`` command line: argument parsing and dispatch only.

The core commands (``list``, ``solve``, ``compile``: :mod:`prioik.commands`;
``compare``: :mod:`prioik.compare`) belong to the library; the reports and experiments
(``fencing``, ``bench``, ``validate``, ...) to :mod:`prioik.benchmarks`. Every
sub-command is declared by the module that runs it (``add_parser(subparsers)``);
:data:`COMMANDS` names that module for each command, in the order ``prioik --help``
lists them. A command line naming one command imports its module alone (``prioik
solve`` imports nothing of :mod:`prioik.benchmarks`); ``prioik --help``, no command or
an unknown one builds the whole parser.

The chosen command runs with BLAS limited to its ``--blas-threads`` (one by default,
:mod:`prioik.threads`); the library's errors (every :class:`~prioik.PrioikError`, and
the ``ValueError``/``OSError`` of a bad argument or file) become one line on stderr
(exit status 2).

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

__all__ = ["COMMANDS", "build_parser", "main"]

#: command → the module whose ``add_parser(subparsers)`` declares it, in the order
#: ``prioik --help`` lists them (a module declaring several commands is called once)
COMMANDS: dict[str, str] = {
    "list": "prioik.commands",
    "solve": "prioik.commands",
    "compile": "prioik.commands",
    "fencing": "prioik.benchmarks.fencing",
    "arm": "prioik.benchmarks.arm",
    "replay": "prioik.benchmarks.saved_runs",
    "plot": "prioik.benchmarks.saved_runs",
    "compare": "prioik.compare",
    "bench": "prioik.benchmarks.bench.command",
    "properties": "prioik.benchmarks.properties",
    "validate": "prioik.benchmarks.validation",
    "sweep": "prioik.benchmarks.sweep.command",
    "fuzz": "prioik.benchmarks.fuzz",
}


class _OneModuleParser(argparse.ArgumentParser):
    """A parser that raises ``argparse.ArgumentError`` where argparse would print and
    exit: a command line it refuses is parsed again by the whole parser, which says
    why."""

    def error(self, message: str):  # type: ignore[override]
        raise argparse.ArgumentError(None, message)


def build_parser(command: str | None = None,
                 parser_class: type[argparse.ArgumentParser] = argparse.ArgumentParser
                 ) -> argparse.ArgumentParser:
    """The ``prioik`` parser: every command's (``command=None``), or only the commands of
    the module that declares ``command`` (what :func:`main` parses a command line naming
    it with, importing that module alone)."""
    parser = parser_class(
        prog="prioik",
        description="Task-priority inverse kinematics: one task-stack spec, every formulation.",
        epilog=EPILOG)
    from prioik import __version__
    parser.add_argument("--version", action="version", version=f"prioik {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    modules = [COMMANDS[command]] if command in COMMANDS else list(dict.fromkeys(
        COMMANDS.values()))
    for name in modules:
        importlib.import_module(name).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``prioik`` console script."""
    from prioik.errors import PrioikError
    from prioik.extras import require

    from .threads import blas_threads
    command_line = list(sys.argv[1:] if argv is None else argv)
    args = None
    if command_line and command_line[0] in COMMANDS:
        try:    # the command's own module alone
            args = build_parser(command_line[0], _OneModuleParser).parse_args(command_line)
        except argparse.ArgumentError:
            args = None     # refused: the whole parser prints its usage and the error
    if args is None:
        args = build_parser().parse_args(command_line)
    args = shrink_arguments(args)       # PRIOIK_SMOKE=1: a few steps
    args.command_line = command_line
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
