"""The paper's comparative claims, measured: algorithmic singularity and algorithmic error.

``prioik properties --out docs/properties.md`` (or ``python -m benchmarks.properties``)
writes ``docs/properties.md``:

1. **Approaching an algorithmic singularity** — ``hierarchy.families.near_singular(σ)``:
   level 1 fixes ``x_0 = x_1 = 0``, level 2 asks ``cos σ x_0 + sin σ x_2 = 1`` (plus a
   free row). The exact lexicographic optimum has ``x_2 = 1/sin σ``. The table gives
   ``‖θ̈‖`` of every formulation against ``σ``, the fitted slope of ``log‖θ̈‖`` against
   ``log σ`` over ``σ = 1e-1 … 1e-7``, and the lower task's residual.
2. **Algorithmic error** (eq. 29) of every formulation on seeded ``coupled``,
   ``decoupled`` and ``conflicting`` stacks (``hierarchy.analysis.algorithmic_error``).

The columns are the ``properties`` report's variants (:mod:`benchmarks.variants`: every
formulation of the registry, and the settings plugins declare for it); the rotated
table adds the ``roundoff`` report's declared rows. The prose is
``templates/properties.md``; which sentence a column gets follows its capabilities
(exact or not) and options (damped or not), not its name.

Everything is computed when the script runs (deterministic seeds); nothing is typed in.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import platform
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prioik import formulations
from prioik.hierarchy import (
    DEFAULT_RCOND,
    Task,
    TaskStack,
    algorithmic_error_norms,
    check_lexicographic,
    rank_profile,
)
from prioik.hierarchy.families import FAMILIES, near_singular, random_spd

from .report import Page, table
from .variants import Variant, capabilities
from .variants import table as variant_table

#: σ values of the near-singular sweep (0: exactly conflicting)
SIGMAS = (1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-10, 0.0)
#: σ range of the fitted slope
SLOPE_RANGE = (1e-7, 1e-1)
#: condition number of the fixed SPD mass matrices
MASS_CONDITION = 10.0


def report_variants() -> list[Variant]:
    """The columns: the ``properties`` report's variants (:mod:`benchmarks.variants`)."""
    return variant_table("properties").rows


def roundoff_variants() -> list[Variant]:
    """The columns added to the rotated-coordinates table only: the rows plugins declare
    for ``roundoff`` (the textbook step of the projector recursions, without the extra
    ``N_{i-1}``; see ``formulations/nullspace.py``)."""
    return [v for v in variant_table("roundoff").rows if v.origin == "declared"]


def solve_variant(stack: TaskStack, variant: Variant, mass: np.ndarray):
    """Solve ``stack`` with ``variant``; a formulation that takes a mass matrix gets
    ``mass`` (``M = I`` when the variant says ``mass="identity"``)."""
    options = dict(variant.options)
    if variant.needs_mass_matrix:
        options["mass_matrix"] = np.eye(stack.n) if variant.mass == "identity" else mass
    return formulations.solve(stack, variant.formulation, **options)


def _exact(v: Variant) -> bool:
    """An exact formulation's undamped column (its answer is the optimum)."""
    caps = capabilities(v.formulation)
    return bool(caps and caps.exact) and not v.damped


# ------------------------------------------------------------ near singularity
@dataclass
class SingularitySweep:
    """``‖θ̈‖`` and the lower level's residual for each variant and ``σ``."""

    sigmas: tuple[float, ...]
    variants: list[Variant]
    norms: np.ndarray          # len(sigmas) × len(variants)
    residuals: np.ndarray      # lower level's residual ‖A_2 θ̈ − b_2‖
    slopes: np.ndarray         # fitted d log‖θ̈‖ / d log σ over SLOPE_RANGE
    rotated_variants: list[Variant]   # variants + the roundoff columns
    rotated_top: np.ndarray    # level 1's residual on the column-rotated stack
    rotated_lower: np.ndarray  # level 2's residual on the column-rotated stack


def rotate_columns(stack: TaskStack, Q: np.ndarray) -> TaskStack:
    """The same problem in the coordinates ``x' = Qᵀ x``: every ``A_i`` becomes ``A_i Q``."""
    return TaskStack([[Task(t.name, t.A @ Q, t.b, weight=t.weight) for t in level]
                      for level in stack.levels])


def singularity_sweep(sigmas=SIGMAS, variants=None, roundoff=None) -> SingularitySweep:
    """Solve ``near_singular(σ)`` with every variant (one fixed SPD ``M``, seed 0);
    ``variants`` / ``roundoff`` default to :func:`report_variants` /
    :func:`roundoff_variants`."""
    variants = report_variants() if variants is None else list(variants)
    roundoff = roundoff_variants() if roundoff is None else list(roundoff)
    mass = random_spd(np.random.default_rng(0), near_singular(0.1).n, MASS_CONDITION)
    Q, _ = np.linalg.qr(np.random.default_rng(1).standard_normal((mass.shape[0],) * 2))
    norms = np.full((len(sigmas), len(variants)), np.nan)
    residuals = np.full_like(norms, np.nan)
    rot_variants = variants + roundoff
    rot_top = np.full((len(sigmas), len(rot_variants)), np.nan)
    rot_lower = np.full_like(rot_top, np.nan)
    for i, s in enumerate(sigmas):
        stack = near_singular(s)
        rotated = rotate_columns(stack, Q)
        for j, v in enumerate(variants):
            sol = solve_variant(stack, v, mass)
            if sol.ok:
                norms[i, j] = np.linalg.norm(sol.x)
                residuals[i, j] = sol.residuals[1]
        for j, v in enumerate(rot_variants):
            sol = solve_variant(rotated, v, Q.T @ mass @ Q)
            if sol.ok:
                rot_top[i, j], rot_lower[i, j] = sol.residuals[0], sol.residuals[1]
    sig = np.array(sigmas)
    fit = (sig >= SLOPE_RANGE[0]) & (sig <= SLOPE_RANGE[1])
    slopes = np.array([np.polyfit(np.log(sig[fit]), np.log(norms[fit, j]), 1)[0]
                       for j in range(len(variants))])
    return SingularitySweep(tuple(sigmas), variants, norms, residuals, slopes, rot_variants,
                            rot_top, rot_lower)


#: σ values of the conditioning table of ``J_E``
COND_SIGMAS = (1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 0.0)


@dataclass
class Conditioning:
    """Smallest singular values on ``near_singular(σ)``: of the recursion's projected
    Jacobian ``J_2 Z_2`` and of ``J_E`` (eq. 15, undamped, unequilibrated) in each
    reading of ``Z_i``, among the ``ρ(J_k^A)`` a pseudo-inverse keeps."""

    sigmas: tuple[float, ...]
    projected: np.ndarray       # σ_min(J_2 Z_2) above the rank threshold (0: none)
    extended: dict[str, np.ndarray]   # z_basis → kept σ_min(J_E)
    rows: dict[str, np.ndarray]       # z_basis → rows of J_E
    rank: np.ndarray            # ρ(J_2^A)


def conditioning(sigmas=COND_SIGMAS) -> Conditioning:
    """Measure :class:`Conditioning` (the paper's Theorem 1 against the recursion)."""
    from prioik.formulations.extended_jacobian import Z_BASES, extended_system
    from prioik.hierarchy import singularity_distance
    proj, rank = np.zeros(len(sigmas)), np.zeros(len(sigmas), dtype=int)
    ext = {zb: np.zeros(len(sigmas)) for zb in Z_BASES}
    rows = {zb: np.zeros(len(sigmas), dtype=int) for zb in Z_BASES}
    for i, sig in enumerate(sigmas):
        stack = near_singular(sig)
        proj[i] = singularity_distance(stack)[1]
        rank[i] = sum(rank_profile(stack))
        for zb in Z_BASES:
            JE, _ = extended_system(stack, z_basis=zb)
            s = np.linalg.svd(JE, compute_uv=False)
            ext[zb][i] = s[rank[i] - 1]
            rows[zb][i] = JE.shape[0]
    return Conditioning(tuple(sigmas), proj, ext, rows, rank)


# ---------------------------------------------------------- algorithmic error
@dataclass
class ErrorSummary:
    """Relative algorithmic error of one variant over the stacks of one family.

    Attributes:
        top_max: Max over stacks of ``‖e_1‖ / ‖h_1‖`` (the top level).
        lower_median: Median over stacks of ``max_{i≥2} ‖e_i‖ / ‖h_i‖``.
        lower_min: Smallest such value.
        lower_max: Largest such value.
        lexicographic: Fraction of stacks passing ``check_lexicographic`` (tol 1e-8).
        stacks: Number of stacks.
        trivial: Fraction of stacks whose lower levels have no feasible direction
            left (``r_i = 0`` for ``i ≥ 2``, eq. 12): every method is optimal there.
    """

    top_max: float
    lower_median: float
    lower_min: float
    lower_max: float
    lexicographic: float
    stacks: int
    trivial: float


ERROR_FAMILIES = ("coupled", "decoupled", "conflicting")


def error_table(n_stacks: int = 50, families=ERROR_FAMILIES, variants=None,
                seed: int = 12345) -> dict[str, dict[str, ErrorSummary]]:
    """``{family: {variant label: ErrorSummary}}`` over seeded stacks, n 6..30, 2..5 levels.

    Each stack gets its own seeded SPD ``M`` (condition ``MASS_CONDITION``); ``variants``
    defaults to :func:`report_variants`.
    """
    variants = report_variants() if variants is None else list(variants)
    out: dict[str, dict[str, ErrorSummary]] = {}
    for fam_index, family in enumerate(families):
        rows: dict[str, list[tuple[float, float, bool]]] = {v.label: [] for v in variants}
        trivial = 0
        for s in range(n_stacks):
            rng = np.random.default_rng([seed, fam_index, s])
            n = int(rng.integers(6, 31))
            stack = FAMILIES[family](rng, n, int(rng.integers(2, 6)))
            mass = random_spd(rng, n, MASS_CONDITION)
            trivial += int(sum(rank_profile(stack)[1:]) == 0)
            scale = np.array([max(np.linalg.norm(level.b), 1e-300) for level in stack.levels])
            for v in variants:
                sol = solve_variant(stack, v, mass)
                if not sol.ok:
                    rows[v.label].append((np.nan, np.nan, False))
                    continue
                rel = algorithmic_error_norms(stack, sol.x) / scale
                lower = float(rel[1:].max()) if len(rel) > 1 else 0.0
                lex = check_lexicographic(stack, sol.x, tol=1e-8).ok
                rows[v.label].append((float(rel[0]), lower, lex))
        out[family] = {}
        for label, vals in rows.items():
            arr = np.array([(a, b) for a, b, _ in vals])
            out[family][label] = ErrorSummary(
                float(np.nanmax(arr[:, 0])), float(np.nanmedian(arr[:, 1])),
                float(np.nanmin(arr[:, 1])), float(np.nanmax(arr[:, 1])),
                float(np.mean([c for _, _, c in vals])), len(vals), trivial / n_stacks)
    return out


# ------------------------------------------------------------------ report
def _fmt(v: float) -> str:
    if not np.isfinite(v):
        return "failed"
    return "0" if v == 0 else f"{v:.3g}" if 1e-3 <= abs(v) < 1e4 else f"{v:.2e}"


def _sigma(s: float) -> str:
    return "0" if s == 0 else f"{s:.0e}"


def _find(sweep: SingularitySweep, label: str) -> int | None:
    labels = [v.label for v in sweep.variants]
    return labels.index(label) if label in labels else None


def _code(labels) -> str:
    return ", ".join(f"`{lb}`" for lb in labels)


def _lam(variants: list[Variant]) -> str:
    """The damping value(s) of the damped variants."""
    values = sorted({float(v.options["damping"]) for v in variants if v.options.get("damping")})
    return ", ".join(f"{x:g}" for x in values) or "–"


def render(sweep: SingularitySweep, errors: dict[str, dict[str, ErrorSummary]],
           n_stacks: int, cond: Conditioning | None = None) -> str:
    """The Markdown of ``docs/properties.md`` (``templates/properties.md``)."""
    page = Page("properties.md")
    labels = [v.label for v in sweep.variants]
    head = ["σ", *labels]
    align = "l" + "r" * len(labels)
    norms = [[_sigma(s), *(_fmt(v) for v in sweep.norms[i])]
             for i, s in enumerate(sweep.sigmas)]
    norms.append([page.inline("slope_row", low=f"{SLOPE_RANGE[0]:.0e}",
                              high=f"{SLOPE_RANGE[1]:.0e}"),
                  *(f"**{v:+.3f}**" for v in sweep.slopes)])
    residuals = [[_sigma(s), *(_fmt(v) for v in sweep.residuals[i])]
                 for i, s in enumerate(sweep.sigmas)]
    rot = [v.label for v in sweep.rotated_variants]
    rotated = [[_sigma(s), *(f"{_fmt(a)} / {_fmt(b)}" for a, b in
                             zip(sweep.rotated_top[i], sweep.rotated_lower[i], strict=False))]
               for i, s in enumerate(sweep.sigmas)]
    error_tables = []
    for family, tbl in errors.items():
        rows = [[label, _fmt(e.top_max), _fmt(e.lower_median), _fmt(e.lower_min),
                 _fmt(e.lower_max), f"{e.lexicographic:.0%}"] for label, e in tbl.items()]
        error_tables.append(page.block("error_table", family=family, table=table(
            ["formulation", "top level max", "lower levels: median", "min", "max",
             "lex. opt."], rows, "lrrrrr")))
    columns = [page.inline("column", label=v.label, note=v.note)
               for v in sweep.rotated_variants]
    return page.render(
        when=f"{_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M}", numpy=np.__version__,
        python=platform.python_version(), mass_condition=f"{MASS_CONDITION:g}",
        columns="\n".join(columns), norms_table=table(head, norms, align),
        residuals_table=table(head, residuals, align),
        rotated_table=table(["σ", *rot], rotated, "l" + "r" * len(rot)),
        singularity_findings="\n".join(_singularity_findings(sweep, page)),
        conditioning=_conditioning_section(cond, page) if cond is not None else "",
        n_stacks=n_stacks, error_tables="\n\n".join(error_tables),
        error_findings="\n".join(_error_findings(errors, sweep.variants, page)))


def _singularity_findings(sweep: SingularitySweep, page: Page) -> list[str]:
    sig = np.array(sweep.sigmas)
    out = []
    ref = _find(sweep, "reference")
    exact = [v.label for v in sweep.variants if _exact(v) and v.label != "reference"]
    if ref is not None:
        track = [lab for lab in exact if np.allclose(sweep.norms[:, _find(sweep, lab)],
                                                     sweep.norms[:, ref], rtol=1e-6)]
        out.append(page.block(
            "exact_track", slope=f"{sweep.slopes[ref]:+.3f}",
            exact=", ".join(f"`{lab}` (slope {sweep.slopes[_find(sweep, lab)]:+.3f})"
                            for lab in exact),
            track=page.inline("exact_track_equal", labels=_code(track)) if track else ""))
        if "extended_jacobian" in track and "extended_jacobian[svd]" in track:
            out.append(page.block("eq18_tracks"))
        zero = int(np.flatnonzero(sig == 0)[0]) if (sig == 0).any() else None
        if zero is not None:
            finite = bool(np.isfinite(sweep.norms[zero]).all())
            A2 = near_singular(0.0)[1].A
            threshold = DEFAULT_RCOND * float(np.linalg.norm(A2))
            out.append(page.block(
                "at_zero", finite="finite" if finite else "NOT finite",
                largest=_fmt(np.nanmax(sweep.norms[zero])), threshold=f"{threshold:.2g}",
                rows=", ".join(_sigma(v) for v in sig if 0 < v < threshold)))
    threshold = DEFAULT_RCOND * float(np.linalg.norm(near_singular(0.0)[1].A))
    rows = sig > threshold                     # rows where the exact optimum is 1/sin σ
    rot_labels = [v.label for v in sweep.rotated_variants]
    if ref is not None and rows.any():
        worst = np.nanmax(np.maximum(sweep.rotated_top, sweep.rotated_lower)[rows], axis=0)
        candidates = (["reference"] + exact
                      + [v.label for v in sweep.rotated_variants[len(sweep.variants):]])
        candidates = [lab for lab in candidates if lab in rot_labels]
        good = [lab for lab in candidates if worst[rot_labels.index(lab)] <= 1e-6]
        bad = [lab for lab in candidates if worst[rot_labels.index(lab)] > 1e-6]
        show = lambda lab: f"`{lab}` {_fmt(worst[rot_labels.index(lab)])}"  # noqa: E731
        good_text = page.inline("accuracy_good", labels=", ".join(show(lab) for lab in good)) \
            if good else ""
        bad_text = (("; " if good else "") + page.inline(
            "accuracy_bad", labels=", ".join(show(lab) for lab in bad))) if bad else "."
        out.append(page.block("accuracy", low=_sigma(sig[rows].min()),
                              high=_sigma(sig[rows].max()),
                              largest=_fmt(np.nanmax(sweep.norms[rows, ref])),
                              good=good_text, bad=bad_text))
    damped = [v for v in sweep.variants if v.damped]
    lam = [float(v.options["damping"]) for v in damped if v.options.get("damping")]
    if damped:
        parts = [f"`{v.label}` max {_fmt(np.nanmax(sweep.norms[:, _find(sweep, v.label)]))}"
                 for v in damped]
        out.append(page.block("damped_bounded", lam=_lam(damped),
                              bound=f"{1 / (2 * np.sqrt(max(lam))) + 1:.1f}" if lam else "–",
                              parts=", ".join(parts)))
    for v in sweep.variants:
        caps = capabilities(v.formulation)
        if caps is None or caps.exact or v.damped:
            continue
        j = _find(sweep, v.label)
        values = dict(label=v.label, largest=_fmt(np.nanmax(sweep.norms[:, j])),
                      slope=f"{sweep.slopes[j]:+.3f}", residual=_fmt(sweep.residuals[0, j]),
                      sigma=_sigma(sig[0]),
                      exact_residual=_fmt(sweep.residuals[0, ref]) if ref is not None else "-")
        out.append(page.block("approximate_bounded" if abs(sweep.slopes[j]) <= 0.2
                              else "approximate_grows", **values))
    return out


def _conditioning_section(cond: Conditioning, page: Page) -> str:
    """Theorem 1 against the recursion: σ_min of ``J_2 Z_2`` and of ``J_E``."""
    zbs = list(cond.extended)
    rows = [[_sigma(sig), cond.rank[i], _fmt(cond.projected[i]),
             *(f"{_fmt(cond.extended[zb][i])} ({cond.rows[zb][i]})" for zb in zbs)]
            for i, sig in enumerate(cond.sigmas)]
    tbl = table(["σ", "ρ(J_2^A)", "σ_min(J_2 Z_2)",
                 *(f"σ_min(J_E), {zb} (rows)" for zb in zbs)], rows, "l" + "r" * (2 + len(zbs)))
    sig = np.array(cond.sigmas)
    fit = (sig > 0) & (cond.projected > 0)
    slope_p = np.polyfit(np.log(sig[fit]), np.log(cond.projected[fit]), 1)[0]
    slopes = {zb: np.polyfit(np.log(sig[fit]), np.log(cond.extended[zb][fit]), 1)[0]
              for zb in zbs}
    square = all(abs(v - 2 * slope_p) < 0.1 for v in slopes.values())
    return page.block("conditioning", table=tbl, low=_sigma(sig[fit].min()),
                      high=_sigma(sig[fit].max()), slope=f"{slope_p:.2f}",
                      slopes=", ".join(f"σ^{v:.2f} ({zb})" for zb, v in slopes.items()),
                      square=page.inline("square" if square else "not_square").lstrip())


def _error_findings(errors: dict[str, dict[str, ErrorSummary]], variants: list[Variant],
                    page: Page) -> list[str]:
    out = []
    by_label = {v.label: v for v in variants}
    exact = [v.label for v in variants if _exact(v)]
    approx = [v.label for v in variants if not _exact(v) and not v.damped]
    for family, tbl in errors.items():
        ex = {lab: tbl[lab] for lab in exact if lab in tbl}
        if ex:
            worst = {lab: max(e.top_max, e.lower_max) for lab, e in ex.items()}
            clean = [lab for lab in ex if worst[lab] <= 1e-8]
            loose = [lab for lab in ex if worst[lab] > 1e-8]
            if clean:
                out.append(page.block("exact_no_error", family=family, labels=_code(clean),
                                      worst=_fmt(max(worst[lab] for lab in clean)),
                                      lex=f"{min(ex[lab].lexicographic for lab in clean):.0%}"))
            if loose:
                out.append(page.block("exact_tolerance", labels=_code(loose),
                                      worst=_fmt(max(worst[lab] for lab in loose)),
                                      lex=f"{min(ex[lab].lexicographic for lab in loose):.0%}"))
        for lab in approx:
            if lab in tbl:
                e = tbl[lab]
                out.append(page.block("approximate_error", label=lab, top=_fmt(e.top_max),
                                      median=_fmt(e.lower_median), low=_fmt(e.lower_min),
                                      high=_fmt(e.lower_max), lex=f"{e.lexicographic:.0%}"))
        any_e = next(iter(tbl.values()))
        if any_e.trivial > 0:
            out.append(page.block("trivial", share=f"{any_e.trivial:.0%}"))
        unifying_spd = [lab for lab in approx if by_label[lab].formulation == "unifying"
                        and by_label[lab].mass != "identity"]
        if family == "decoupled" and any(lab in tbl for lab in unifying_spd):
            out.append(page.block("decoupled_unifying"))
    damped = [v for v in variants if v.damped]
    if damped:
        top = {v.label: max(errors[f][v.label].top_max for f in errors) for v in damped}
        exact_top = [lab for lab in top if top[lab] <= 1e-10]
        mixed_top = [lab for lab in top if top[lab] > 1e-10]
        out.append(page.block(
            "damped_errors", lam=_lam(damped),
            tops=", ".join(f"`{lab}` {_fmt(v)}" for lab, v in top.items()),
            exact_top=page.inline("damped_exact_top", labels=_code(exact_top))
            if exact_top else "",
            mixed_top=page.inline("damped_mixed_top", labels=_code(mixed_top))
            if mixed_top else ""))
    return out


def write_report(out: Path, n_stacks: int = 50) -> str:
    """Measure everything and write the Markdown report to ``out``; returns the text."""
    text = render(singularity_sweep(), error_table(n_stacks), n_stacks, conditioning())
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    return text


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("properties",
                       help="measure algorithmic singularity and algorithmic error "
                            "(writes results/properties.md unless --out says otherwise)",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path("results/properties.md"),
                   help="Markdown file to write (default: results/properties.md; the "
                        "repository's page is regenerated with --out docs/properties.md)")
    p.add_argument("--stacks", type=int, default=50,
                   help="seeded stacks per family for the algorithmic-error table")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.stacks < 1:
        raise ValueError(f"--stacks must be ≥ 1, got {args.stacks}")
    write_report(args.out, args.stacks)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    import sys

    from prioik.cli import main
    sys.exit(main(["properties", *sys.argv[1:]]))
