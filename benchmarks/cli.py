"""The ``prioik`` command line: one sub-command per module (each has ``add_parser``).

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

import numpy as np

#: modules that contribute a sub-command through ``add_parser(subparsers)``
SUBCOMMAND_MODULES = [
    "prioik.benchmarks.fencing",
    "prioik.benchmarks.arm",
    "prioik.benchmarks.saved_runs",
    "prioik.benchmarks.compare",
    "prioik.benchmarks.bench",
    "prioik.benchmarks.properties",
    "prioik.benchmarks.validation",
    "prioik.benchmarks.sweep.command",
    "prioik.benchmarks.fuzz",
]


def _qp_backends_line() -> str:
    import importlib.util
    from prioik.extras import install_hint
    if importlib.util.find_spec("qpsolvers") is None:
        return f"QP back-ends: none (qpsolvers is not installed; {install_hint('qp')})"
    import qpsolvers
    return f"QP back-ends qpsolvers sees here: {', '.join(qpsolvers.available_solvers)}"


def _cmd_list(args: argparse.Namespace) -> int:
    from prioik import formulations
    print(f"{'formulation':<22} {'available':<10} {'ineq.':<6} {'exact':<6} description")
    for f in formulations.available():
        if f.available:
            c = f.capabilities
            print(f"{f.name:<22} {'yes':<10} {'yes' if c.inequalities else 'no':<6} "
                  f"{'yes' if c.exact else 'no':<6} {f.description}")
            if f.backends:
                print(f"{'':<22} back-ends: {', '.join(f.backends)}")
            if args.options:
                for key, opt in f.options.items():
                    print(f"{'':<22} {key}: {opt.doc()}")
        else:
            print(f"{f.name:<22} {'no':<10} {'':<6} {'':<6} {f.reason}")
    print(f"\n{_qp_backends_line()}")
    return 0


def _parse_value(text: str):
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    if low in ("none", "null"):
        return None
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return text


def _cmd_solve(args: argparse.Namespace) -> int:
    from prioik import formulations
    from prioik.hierarchy import load_stack
    stack = load_stack(args.file)
    options = {}
    for item in args.option:
        if "=" not in item:
            raise ValueError(f"--option takes key=value, got {item!r}")
        k, v = item.split("=", 1)
        options[k] = _parse_value(v)
    sol = formulations.solve(stack, args.formulation, **options)
    np.set_printoptions(precision=6, suppress=False, linewidth=100)
    print(f"formulation: {sol.formulation}  status: {sol.status}  "
          f"time: {sol.time_s * 1e6:.1f} µs")
    print(f"x = {sol.x}")
    for i, (level, r) in enumerate(zip(stack.levels, sol.residuals)):
        print(f"level {i} ({', '.join(level.names)}): residual {r:.3e}")
    if sol.status == "failed":
        print(f"failed: {sol.info.get('message', '')}")
        return 1
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="prioik",
        description="Task-priority inverse kinematics: one task-stack spec, every formulation.")
    from prioik import __version__
    parser.add_argument("--version", action="version", version=f"prioik {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("list", help="list formulations, their availability and QP back-ends")
    p.add_argument("--options", action="store_true",
                   help="also print every option: meaning, default and range")
    p.set_defaults(func=_cmd_list)
    p = sub.add_parser("solve", help="solve a task-stack JSON file and print x and residuals")
    p.add_argument("file", help="task-stack JSON file (docs/task-stack-format.md)")
    p.add_argument("--formulation", "-f", default="extended_jacobian",
                   help="formulation name (see `prioik list`)")
    p.add_argument("--option", "-o", action="append", default=[], metavar="KEY=VALUE",
                   help="formulation option, repeatable (e.g. -o damping=0.01)")
    p.set_defaults(func=_cmd_solve)
    for name in SUBCOMMAND_MODULES:
        importlib.import_module(name).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``prioik`` console script."""
    from prioik.extras import MissingExtraError, require
    from prioik.formulations import FormulationError
    from prioik.hierarchy import TaskStackError
    from .threads import blas_threads
    args = build_parser().parse_args(argv)
    args.command_line = list(sys.argv[1:] if argv is None else argv)
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
    except (TaskStackError, FormulationError, MissingExtraError, ValueError, OSError) as exc:
        print(f"prioik {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2


def _one_line(exc: BaseException) -> str:
    """The error message on one line (a multi-line message is joined with ' | ')."""
    return " | ".join(line.strip() for line in str(exc).splitlines() if line.strip())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
