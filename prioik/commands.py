"""``prioik list``, ``prioik solve`` and ``prioik compile``, core commands of
:mod:`prioik.cli`: the library itself from the command line (the formulations, their
options and back-ends; one task-stack file solved; ``compile``, which says there is
nothing to compile)."""

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


#: ``prioik solve --format`` values and the reader each names (``auto``: by the file)
FORMATS = ("auto", "stack", "lexls", "soth", "peer-json")


def _file_format(path: str) -> str:
    """``--format auto``: ``.dat`` lexls, ``.txt`` soth, and a ``.json`` file whose
    first level is an object with ``lb`` or ``ub`` (the peer JSON of
    ``load_peer_json``); anything else is a task-stack file."""
    import json
    from pathlib import Path
    suffix = Path(path).suffix
    if suffix == ".dat":
        return "lexls"
    if suffix == ".txt":
        return "soth"
    if suffix == ".json":
        try:
            levels = json.loads(Path(path).read_text(encoding="utf-8")).get("levels")
        except (OSError, ValueError, AttributeError, RecursionError):
            return "stack"        # load_stack names what is wrong with it
        if isinstance(levels, list) and levels and isinstance(levels[0], dict) \
                and ("lb" in levels[0] or "ub" in levels[0]):
            return "peer-json"
    return "stack"


def _problems(path: str, fmt: str, which: str | None) -> list:
    """``(name, stack, peer)`` of each problem of the file (``peer``: the
    :class:`~prioik.hierarchy.PeerProblem` of another project's file, else ``None``);
    ``which``: the ``--problems`` of a soth file."""
    from prioik.hierarchy import load_lexls, load_peer_json, load_soth, load_stack
    fmt = _file_format(path) if fmt == "auto" else fmt
    indices = None
    if which is not None:
        if fmt != "soth":
            raise ValueError(f"--problems picks problems of a soth file; {path} is read as "
                             f"{fmt}")
        try:
            indices = [int(v) for v in which.split(",")]
        except ValueError:
            raise ValueError(f"--problems takes comma-separated indices, got {which!r}") \
                from None
    if fmt == "stack":
        return [(path, load_stack(path), None)]
    peers = {"lexls": lambda: [load_lexls(path)],
             "soth": lambda: load_soth(path, problems=indices),
             "peer-json": lambda: [load_peer_json(path)]}[fmt]()
    return [(p.name, p.stack, p) for p in peers]


def _peer_levels(peer) -> tuple[np.ndarray | None, str]:
    """The per-level ``‖w_i‖²`` another project's file states (its stored solution's,
    else its hand-derived values) and where they come from."""
    from prioik.hierarchy import lexicographic_residuals
    if peer is None:
        return None, ""
    if peer.x_stored is not None:
        return lexicographic_residuals(peer.stack, peer.x_stored) ** 2, "stored solution"
    if peer.level_targets is not None:
        return np.asarray(peer.level_targets, dtype=float), "stated values"
    return None, ""


def cmd_solve(args: argparse.Namespace) -> int:
    from prioik import formulations
    from prioik.hierarchy import check_lexicographic, lexicographic_residuals
    options = {}
    for item in args.option:
        if "=" not in item:
            raise ValueError(f"--option takes key=value, got {item!r}")
        k, v = item.split("=", 1)
        options[k] = _parse_value(v)
    problems = _problems(args.file, args.format, args.problems)
    np.set_printoptions(precision=6, suppress=False, linewidth=100)
    code = 0
    for name, stack, peer in problems:
        sol = formulations.solve(stack, args.formulation, verify=args.verify, **options)
        if len(problems) > 1 or peer is not None:
            print(f"problem: {name}  ({stack.n} unknowns, {len(stack.levels)} levels)")
        verified = (f"  verification ({args.verify}): {sol.verify_time_s * 1e6:.1f} µs"
                    if sol.verify_time_s > 0 else "")
        print(f"formulation: {sol.formulation}  status: {sol.status}  "
              f"time: {sol.time_s * 1e6:.1f} µs{verified}")
        if sol.status == "approximate" and sol.diagnostics.reason:
            print(f"approximate: {sol.diagnostics.reason}")
        print(f"x = {sol.x}")
        finite = bool(np.isfinite(sol.x).all())
        w2 = lexicographic_residuals(stack, sol.x) ** 2 if finite else None
        target, source = _peer_levels(peer)
        for i, (level, r) in enumerate(zip(stack.levels, sol.residuals, strict=False)):
            line = f"level {i} ({', '.join(level.names)}): residual {r:.3e}"
            if w2 is not None:
                line += f"  ‖w‖² {w2[i]:.6e}"
            if target is not None and w2 is not None:
                rel = abs(w2[i] - target[i]) / max(1.0, abs(target[i]))
                line += f"  peer {target[i]:.6e} (Δ {rel:.1e} of max(1, peer))"
            print(line)
        if source:
            print(f"peer: the file's {source}")
        if sol.status == "failed":
            print(f"failed: {sol.diagnostics.reason}")
            code = 1
        elif args.check and finite:
            report = check_lexicographic(stack, sol.x, minimum_norm=True)
            bad = report.first_failure
            if bad is None:
                print(f"certificate: passes (tol {report.tol:g}; largest relative KKT "
                      f"residual {report.worst_relative:.1e})")
            else:
                print(f"certificate: fails at level {bad.level} ({', '.join(bad.tasks)}): "
                      f"{bad.failure(report.tol)}")
                code = 1
    return code


def cmd_compile(args: argparse.Namespace) -> int:
    from prioik import formulations
    from prioik.formulations.registry import NOTHING_TO_COMPILE
    names = args.formulations.split(",") if args.formulations else None
    formulations.compile_kernels(names)       # checks the names
    print(NOTHING_TO_COMPILE)
    return 0


def add_parser(sub) -> None:
    """Register ``prioik list``, ``prioik solve`` and ``prioik compile``."""
    p = sub.add_parser("list", help="list formulations, their availability and QP back-ends")
    p.add_argument("--options", action="store_true",
                   help="also print every option: meaning, default and range")
    p.set_defaults(func=cmd_list)
    p = sub.add_parser(
        "solve", help="solve a task-stack JSON file and print x and residuals",
        description="Solve a task-stack JSON file (docs/task-stack-format.md), or another "
                    "project's hierarchy file (lexls .dat, soth .txt, the peer JSON of "
                    "load_peer_json), and print x, each level's residual and ‖w‖² (and a "
                    "peer file's own per-level ‖w‖² beside them). Exit status: 2 on a bad "
                    "file, name or option; 1 when the formulation reports failed, or with "
                    "--check when the answer fails the certificate; 0 otherwise.")
    p.add_argument("file", help="task-stack JSON file, or a lexls / soth / peer JSON file")
    p.add_argument("--format", choices=FORMATS, default="auto",
                   help="file format (default auto: .dat lexls, .txt soth, .json a task "
                        "stack, or peer JSON when its levels hold lb/ub)")
    p.add_argument("--problems", metavar="I,J", default=None,
                   help="of a soth file holding several problems, these (0-based; default "
                        "all)")
    p.add_argument("--check", action="store_true",
                   help="also run check_lexicographic (minimum-norm tie-break) on the answer")
    p.add_argument("--formulation", "-f", default="extended_jacobian",
                   help="formulation name (see `prioik list`)")
    from prioik.formulations.base import VERIFY_MODES
    p.add_argument("--verify", choices=VERIFY_MODES, default="auto",
                   help="the verification stage after the solve (default auto: what the "
                        "formulation asks for; none: nothing; certificate: "
                        "check_lexicographic on every optimal answer; lower_point: that and "
                        "the exact active set's comparison), timed apart")
    p.add_argument("--option", "-o", action="append", default=[], metavar="KEY=VALUE",
                   help="formulation option, repeatable (e.g. -o damping=0.01)")
    p.set_defaults(func=cmd_solve)
    p = sub.add_parser(
        "compile", help="nothing to compile (kept for scripts): the C++ core is built at install",
        description="Does nothing but say so: prioik's compiled solvers are C++ "
                    "(prioik._core), built when prioik is installed, so a first solve does "
                    "not wait for a compiler. Kept so that scripts running it do not break; "
                    "exit status 2 when --formulations names an unknown or unavailable "
                    "formulation.")
    p.add_argument("--formulations", default="", metavar="A,B",
                   help="formulation names, checked to be known and available here")
    p.set_defaults(func=cmd_compile)
