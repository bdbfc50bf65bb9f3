"""Validation report: every formulation × back-end on N seeded random stacks per family.

``prioik validate --n-stacks 200 --out docs/validation.md`` (or
``python -m benchmarks.validation …``) draws, for each family — ``compatible``,
``conflicting``, ``rank_deficient`` (equality stacks, :data:`hierarchy.families.FAMILIES`)
and ``with_inequalities``, ``infeasible_inequality``, ``random_inequality``
(:data:`hierarchy.families.INEQUALITY_FAMILIES`) — ``N`` stacks with seeded sizes,
solves each with every variant of the ``validate`` report (:mod:`benchmarks.variants`:
every available formulation, one row per back-end of those that have several, and the
ablations plugins declare for ``validate``), and writes a markdown table per family
(``templates/validation.md``):

* distance ``‖x − x_ref‖ / max(1, ‖x_ref‖)`` (max and median, and max over the
  answers reported ``"optimal"``) to ``reference`` on equality stacks, to the
  ``cvxpy``/Clarabel cascade on inequality stacks;
* the lexicographic check pass rate: :func:`hierarchy.check_lexicographic` (the
  certificate, equality and inequality stacks alike) with ``tol = 1e-6``;
* the answers reported ``"optimal"`` that fail the certificate at the statuses'
  tolerance (``DEFAULT_CERTIFICATE_TOL``, minimum-norm tie-break), and how many there
  were with the back-ends' own statuses (before the certificate downgraded them);
* the largest inequality violation beyond the reference answer's own (0 when a
  formulation keeps every bound the reference keeps);
* statuses (optimal / approximate / failed), errors (exceptions), median time.

Formulations that cannot take a family (closed-form methods on inequality
stacks) are skipped and listed; without the ``cvxpy`` extra (the inequality families'
reference) the default run leaves the inequality families out and says so; formulations that need a
mass matrix get
``mass_matrix = I`` (their metric tie-break is then the minimum norm of
``reference``). Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import datetime
import platform
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from prioik import formulations
from prioik.formulations.registry import check_support
from prioik.hierarchy import (
    DEFAULT_CERTIFICATE_TOL,
    TaskStack,
    UnsupportedTaskError,
    check_lexicographic,
    relative_distance,
)
from prioik.hierarchy.families import FAMILIES, INEQUALITY_FAMILIES

from .machine import versions
from .report import Page
from .variants import Variant
from .variants import table as variant_table

EQUALITY_FAMILY_NAMES = ("compatible", "conflicting", "rank_deficient")
INEQUALITY_FAMILY_NAMES = ("with_inequalities", "infeasible_inequality", "random_inequality")
LEX_TOL = 1e-6
#: the libraries whose versions the page gives
LIBRARIES = ("numpy", "qpsolvers", "clarabel", "osqp", "proxsuite", "quadprog", "daqp",
             "highspy", "scs", "cvxpy", "placo")

#: seed offset per family, so that families draw independent streams
_SEED_OFFSET = {name: 10_000 * (i + 1) for i, name in
                enumerate(EQUALITY_FAMILY_NAMES + INEQUALITY_FAMILY_NAMES)}


@dataclass
class Tally:
    """Accumulated results of one variant on one family."""

    distances: list = field(default_factory=list)
    optimal_distances: list = field(default_factory=list)
    lex_pass: int = 0
    lex_total: int = 0
    violation: float = 0.0
    statuses: dict = field(default_factory=dict)
    errors: int = 0
    first_error: str = ""
    first_failure: str = ""
    times: list = field(default_factory=list)
    wrong_optimal: int = 0
    wrong_trusted: int = 0


def variants(include_cvxpy_backends: bool = False, ablations: bool = True
             ) -> tuple[list[Variant], list[str]]:
    """The rows of the report and the notes on what was left out or changed.

    Args:
        include_cvxpy_backends: One row per back-end for every formulation, also those
            whose plugin keeps one row here (``cvxpy``: Clarabel alone otherwise).
        ablations: Keep the rows plugins declare for ``validate``.
    """
    page = Page("validation.md")
    t = variant_table("validate", all_backends=include_cvxpy_backends)
    rows = [v for v in t.rows if ablations or v.origin != "declared"]
    notes = [f"`{n.split(':', 1)[0]}`:{n.split(':', 1)[1]}" for n in t.notes]
    notes += [page.inline("note_mass_matrix", name=v.formulation) for v in rows
              if v.needs_mass_matrix and not v.tag]
    return rows, notes


def draw(family: str, index: int, n_range: tuple[int, int], k_range: tuple[int, int]
         ) -> TaskStack:
    """Stack ``index`` of ``family``: sizes and data from one seeded generator."""
    rng = np.random.default_rng(_SEED_OFFSET.get(family, 0) + index)
    n = int(rng.integers(n_range[0], n_range[1] + 1))
    k = int(rng.integers(k_range[0], k_range[1] + 1))
    gen = FAMILIES.get(family) or INEQUALITY_FAMILIES[family]
    return gen(rng, n, k)


def _violation(stack: TaskStack, x: np.ndarray) -> np.ndarray:
    """Per inequality task, ``‖viol_t(x)‖`` (unweighted)."""
    out = []
    for t in stack.tasks:
        if t.is_equality:
            continue
        lo, up = t.bounds()
        Ax = t.A @ x
        out.append(float(np.linalg.norm(np.maximum(lo - Ax, 0) + np.maximum(Ax - up, 0))))
    return np.array(out)


def run_family(family: str, n_stacks: int, vs: list[Variant], n_range, k_range,
               progress=None) -> tuple[dict[str, Tally], list[str]]:
    """Solve ``n_stacks`` stacks of ``family`` with every variant."""
    tallies = {v.label: Tally() for v in vs}
    skipped: dict[str, str] = {}
    for i in range(n_stacks):
        stack = draw(family, i, n_range, k_range)
        if stack.is_equality:
            ref = formulations.solve(stack, "reference")
        else:
            ref = formulations.solve(stack, "cvxpy", solver="CLARABEL")
        if not ref.ok:
            tallies.setdefault("(reference failed)", Tally()).errors += 1
            continue
        ref_viol = _violation(stack, ref.x)
        for v in vs:
            info = formulations.get(v.formulation)
            try:
                check_support(v.formulation, info.capabilities, stack)
            except UnsupportedTaskError as exc:
                skipped[v.label] = str(exc).split(":")[0]
                continue
            opts = dict(v.options)
            if v.needs_mass_matrix:
                opts["mass_matrix"] = np.eye(stack.n)
            tally = tallies[v.label]
            try:
                sol = formulations.solve(stack, v.formulation, **opts)
            except Exception as exc:  # a report row, not a test: count and show it
                tally.errors += 1
                tally.first_error = tally.first_error or f"{type(exc).__name__}: {exc}"
                continue
            tally.times.append(sol.time_s)
            tally.statuses[sol.status] = tally.statuses.get(sol.status, 0) + 1
            if not sol.ok:
                tally.first_failure = tally.first_failure or sol.diagnostics.reason
                continue
            x = sol.x
            dist = relative_distance(x, ref.x)
            tally.distances.append(dist)
            if sol.status == "optimal":
                tally.optimal_distances.append(dist)
            tally.lex_total += 1
            tally.lex_pass += bool(check_lexicographic(stack, x, tol=LEX_TOL).ok)
            # "optimal" answers that fail the certificate at the statuses' tolerance, with
            # the statuses as they are and as the back-end gave them before the certificate
            cert_ok = check_lexicographic(stack, x, tol=DEFAULT_CERTIFICATE_TOL,
                                          minimum_norm=True).ok
            verdict = sol.diagnostics.verification
            downgraded = verdict is not None and not verdict.ok
            tally.wrong_optimal += sol.status == "optimal" and not cert_ok
            tally.wrong_trusted += (sol.status == "optimal" or downgraded) and not cert_ok
            if not stack.is_equality:
                viol = _violation(stack, x)
                tally.violation = max(tally.violation,
                                      float(np.max(viol - ref_viol, initial=0.0)))
        if progress is not None:
            progress(family, i + 1, n_stacks)
    tallies = {k: t for k, t in tallies.items() if t.times or t.errors}
    page = Page("validation.md")
    notes = [page.inline("skipped", label=k, why=why) for k, why in sorted(skipped.items())
             if k not in tallies]
    return tallies, notes


def _fmt(v: float) -> str:
    return "–" if not np.isfinite(v) else f"{v:.1e}"


def table(family: str, tallies: dict[str, Tally], equality: bool,
          skip_notes: list[str] | None = None) -> str:
    """The markdown section of one family."""
    from .report import table as md_table
    page = Page("validation.md")
    head = (["formulation / back-end", "max dist.", "median dist.", "max dist. if optimal",
             "lex. check"] + ([] if equality else ["max extra violation"])
            + ["optimal / approx. / failed", "optimal ∧ fails cert. (without cert.)",
               "errors", "median time"])
    rows = []
    for label, t in tallies.items():
        d = np.array(t.distances) if t.distances else np.array([np.nan])
        d_opt = float(np.max(t.optimal_distances)) if t.optimal_distances else np.nan
        lex = f"{t.lex_pass}/{t.lex_total}" if t.lex_total else "–"
        st = "/".join(str(t.statuses.get(s, 0)) for s in ("optimal", "approximate", "failed"))
        tm = f"{statistics.median(t.times) * 1e6:.0f} µs" if t.times else "–"
        rows.append([label, _fmt(float(np.max(d))), _fmt(float(np.median(d))), _fmt(d_opt),
                     lex] + ([] if equality else [_fmt(t.violation)])
                    + [st, f"{t.wrong_optimal} ({t.wrong_trusted})", t.errors, tm])
    failures = [page.inline("first_failure", label=k, message=t.first_failure[:300])
                for k, t in tallies.items() if t.first_failure]
    failures += [page.inline("first_error", label=k, message=t.first_error[:300])
                 for k, t in tallies.items() if t.first_error]
    doc = (FAMILIES.get(family) or INEQUALITY_FAMILIES[family]).__doc__ or ""
    return page.block("family", family=family, doc=doc.strip().splitlines()[0],
                      reference=page.inline("reference_equality" if equality
                                            else "reference_inequality"),
                      lex_tol=f"{LEX_TOL:g}", cert_tol=f"{DEFAULT_CERTIFICATE_TOL:g}",
                      table=md_table(head, rows),
                      failures="\n".join(failures),
                      skipped="\n".join(skip_notes or []))


def inequality_reference_reason() -> str:
    """Why the inequality families cannot be checked here (``""``: they can): their
    reference is the ``cvxpy`` formulation."""
    info = {f.name: f for f in formulations.available()}["cvxpy"]
    return "" if info.available else Page("validation.md").inline(
        "inequality_reference_missing", reason=info.reason)


def report(n_stacks: int, families: list[str], n_range, k_range, include_cvxpy_backends=False,
           only: list[str] | None = None, stream=None, ablations: bool = True,
           notes: tuple[str, ...] = ()) -> str:
    """Run everything and return the markdown report (``notes``: more lines for its
    notes)."""
    stream = sys.stderr if stream is None else stream
    page = Page("validation.md")
    vs, variant_notes = variants(include_cvxpy_backends, ablations)
    notes = list(notes) + variant_notes
    if only:
        variant_table("validate", all_backends=True).check_names(only)
        vs = [v for v in vs if v.formulation in only or v.label in only]
    t0 = time.perf_counter()
    last = [0.0]

    def progress(family, i, total):
        now = time.perf_counter()
        if i == total or now - last[0] > 2.0:
            last[0] = now
            print(f"validate: {family} {i}/{total} ({now - t0:.0f} s)", file=stream, flush=True)

    sections = []
    for family in families:
        tallies, skip_notes = run_family(family, n_stacks, vs, n_range, k_range, progress)
        sections.append(table(family, tallies, family in FAMILIES, skip_notes))
    elapsed = time.perf_counter() - t0
    cmd = (f"prioik validate --n-stacks {n_stacks} --n-min {n_range[0]} --n-max {n_range[1]} "
           f"--k-min {k_range[0]} --k-max {k_range[1]}")
    if list(families) != list(EQUALITY_FAMILY_NAMES + INEQUALITY_FAMILY_NAMES):
        cmd += f" --families {','.join(families)}"
    if not ablations:
        cmd += " --no-ablations"
    if include_cvxpy_backends:
        cmd += " --cvxpy-backends"
    if only:
        cmd += f" --formulations {','.join(only)}"
    return page.render(
        command=cmd, date=datetime.date.today().isoformat(), machine=platform.machine(),
        python=platform.python_version(), seconds=f"{elapsed:.0f}", n_stacks=n_stacks,
        n_min=n_range[0], n_max=n_range[1], k_min=k_range[0], k_max=k_range[1],
        versions=versions(LIBRARIES),
        notes=(page.block("notes", items="\n".join(f"- {s}" for s in notes))
               if notes else ""),
        sections="\n\n".join(sections))


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="validation report: every formulation × back-end on "
                                        "N random stacks per family",
                       description=__doc__.split("\n\n")[0])
    _arguments(p)
    p.set_defaults(func=run)


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--n-stacks", type=int, default=200, help="stacks per family (default 200)")
    p.add_argument("--out", type=Path, default=Path("results/validation.md"),
                   help="markdown file to write (default results/validation.md; the "
                        "repository's page is regenerated with --out docs/validation.md)")
    p.add_argument("--families", default=None,
                   help="comma-separated family names (default: "
                        f"{','.join(EQUALITY_FAMILY_NAMES + INEQUALITY_FAMILY_NAMES)}; the "
                        "inequality ones only where the cvxpy extra is installed)")
    p.add_argument("--formulations", default="",
                   help="comma-separated formulation names or row labels (default: all; "
                        "an unknown one exits 2 listing the known ones)")
    p.add_argument("--n-min", type=int, default=4)
    p.add_argument("--n-max", type=int, default=20)
    p.add_argument("--k-min", type=int, default=2)
    p.add_argument("--k-max", type=int, default=5)
    p.add_argument("--cvxpy-backends", action="store_true",
                   help="one row per back-end also for formulations that keep one here "
                        "(cvxpy: every solver it has; default: Clarabel only)")
    p.add_argument("--no-ablations", action="store_true",
                   help="only default settings (drop the rows plugins declare with a "
                        "setting, e.g. cascaded_qp[clarabel,fixing=rows])")


def run(args: argparse.Namespace) -> int:
    from .variants import check_formulations, split_labels
    only = split_labels(args.formulations) or None
    check_formulations(only or ())                # an unknown name: before anything
    named = args.families is not None
    families = ([f for f in args.families.split(",") if f] if named
                else list(EQUALITY_FAMILY_NAMES + INEQUALITY_FAMILY_NAMES))
    unknown = [f for f in families if f not in FAMILIES and f not in INEQUALITY_FAMILIES]
    if unknown:
        raise ValueError(f"unknown families {unknown}; known: "
                         f"{', '.join(list(FAMILIES) + list(INEQUALITY_FAMILIES))}")
    notes = []
    inequality = [f for f in families if f in INEQUALITY_FAMILIES]
    why = inequality_reference_reason() if inequality else ""
    if why and named:
        raise formulations.FormulationError(f"cannot check the inequality families "
                                            f"{', '.join(inequality)}: {why}")
    if why:
        families = [f for f in families if f not in INEQUALITY_FAMILIES]
        notes.append(Page("validation.md").inline("note_inequality_left_out",
                                                  families=", ".join(inequality), why=why))
        print(f"validate: {notes[-1]}", file=sys.stderr)
    if args.n_stacks < 1 or args.n_min < 2 or args.n_max < args.n_min or args.k_min < 1 \
            or args.k_max < args.k_min:
        raise ValueError("need n-stacks ≥ 1, 2 ≤ n-min ≤ n-max, 1 ≤ k-min ≤ k-max")
    text = report(args.n_stacks, families, (args.n_min, args.n_max), (args.k_min, args.k_max),
                  args.cvxpy_backends, only, ablations=not args.no_ablations,
                  notes=tuple(notes))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text, encoding="utf-8")
    print(f"validate: wrote {args.out}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks.validation``."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.validation",
                                description=__doc__.split("\n\n")[0])
    _arguments(p)
    return run(p.parse_args(argv))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
