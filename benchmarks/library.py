"""``prioik list``, ``prioik solve`` and ``prioik compile``: the library itself from the
command line (the formulations, their options and back-ends; one task-stack file solved;
the compiled kernels built for this machine)."""

from __future__ import annotations

import argparse

import numpy as np

__all__ = ["add_parser"]


def _qp_backends_line() -> str:
    import importlib.util
    from prioik.extras import install_hint
    if importlib.util.find_spec("qpsolvers") is None:
        return f"QP back-ends: none (qpsolvers is not installed; {install_hint('qp')})"
    import qpsolvers
    return f"QP back-ends qpsolvers sees here: {', '.join(qpsolvers.available_solvers)}"


def cmd_list(args: argparse.Namespace) -> int:
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


def cmd_solve(args: argparse.Namespace) -> int:
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


def cmd_compile(args: argparse.Namespace) -> int:
    from prioik import formulations
    names = args.formulations.split(",") if args.formulations else None

    def progress(name: str, seconds: float | None) -> None:
        if seconds is None:
            print(f"{name}: compiling or loading its kernels ...", flush=True)
        else:
            print(f"{name}: done in {seconds:.1f} s", flush=True)

    formulations.compile_kernels(names, progress)
    return 0


def add_parser(sub) -> None:
    """Register ``prioik list``, ``prioik solve`` and ``prioik compile``."""
    p = sub.add_parser("list", help="list formulations, their availability and QP back-ends")
    p.add_argument("--options", action="store_true",
                   help="also print every option: meaning, default and range")
    p.set_defaults(func=cmd_list)
    p = sub.add_parser("solve", help="solve a task-stack JSON file and print x and residuals")
    p.add_argument("file", help="task-stack JSON file (docs/task-stack-format.md)")
    p.add_argument("--formulation", "-f", default="extended_jacobian",
                   help="formulation name (see `prioik list`)")
    p.add_argument("--option", "-o", action="append", default=[], metavar="KEY=VALUE",
                   help="formulation option, repeatable (e.g. -o damping=0.01)")
    p.set_defaults(func=cmd_solve)
    p = sub.add_parser(
        "compile", help="compile the formulations' numba kernels for this machine now",
        description="Compile, or load from numba's disk cache, every compiled kernel of "
                    "the formulations that have them (extended_jacobian, "
                    "hierarchical_active_set), printing the seconds each took. numba "
                    "compiles a kernel on its first use after an install (one to two minutes "
                    "for hierarchical_active_set on a 2-core machine) and caches it; run this "
                    "once after installing so that a control loop's first solve does not "
                    "wait for it.")
    p.add_argument("--formulations", default="", metavar="A,B",
                   help="only these formulations (default: every one with compiled kernels)")
    p.set_defaults(func=cmd_compile)
