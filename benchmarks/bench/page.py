"""The markdown of ``prioik bench``: ``results.md`` and the documentation page
(``docs/benchmarks.md``), from ``templates/benchmarks.md``."""

from __future__ import annotations

import math
from typing import Any

from prioik.benchmarks import paper
from prioik.benchmarks.report import Page, table, us
from prioik.benchmarks.results import TimingRow
from prioik.benchmarks.stacks import G1_DURATION_S
from prioik.benchmarks.variants import Variant

from .ratios import Ratio
from .settings import SUCCESS_TOL, Settings

__all__ = ["detail_table", "pivot_table", "control_table", "results_markdown", "doc_page",
           "note"]

_PAGE = "benchmarks.md"


def note(name: str, **values: Any) -> str:
    """A line of the Notes section (block ``note_<name>`` of the template)."""
    return Page(_PAGE).inline(f"note_{name}", **values)


def _dist(v: float) -> str:
    return "–" if not math.isfinite(v) else f"{v:.1e}"


def detail_table(rows: list[TimingRow]) -> str:
    """Every row of one case in full, fastest first."""
    body = []
    for r in sorted(rows, key=lambda r: (math.isnan(r.median_us), r.median_us)):
        if r.status in ("skipped", "unsupported", "error"):
            body.append([r.label, "–", "–", "–", "–", "–", "–", "–", 0,
                         f"{r.status}: {r.note}"])
            continue
        status = r.status if r.status == "ok" else f"{r.status}: {r.note}"
        verify = us(r.verify_median_us) if math.isfinite(r.verify_median_us) else "–"
        body.append([r.label, us(r.median_us), us(r.p10_us), us(r.p90_us), verify,
                     f"{r.success_rate:.0%}", _dist(r.dist_median), _dist(r.dist_max),
                     r.repeats, status])
    return table(["formulation", "median µs", "p10 µs", "p90 µs", "verify µs", "success",
                  "dist. median", "dist. max", "repeats", "status"], body, "lrrrrrrrrl")


def pivot_table(rows: list[TimingRow], k: int) -> str:
    """Median µs of every variant (rows) over ``n`` (columns) at ``k`` levels; ``†``
    marks reduced repeats, ``*`` a success rate below 100 %."""
    sub = [r for r in rows if r.suite == "random" and r.k == k]
    ns = sorted({r.n for r in sub})
    labels = sorted({r.label for r in sub},
                    key=lambda lb: min((r.median_us for r in sub if r.label == lb
                                        and math.isfinite(r.median_us)), default=math.inf))
    body = []
    for label in labels:
        cells = []
        for n in ns:
            r = next((r for r in sub if r.label == label and r.n == n), None)
            if r is None:
                cells.append("")
            elif r.status in ("skipped", "unsupported", "error"):
                cells.append(r.status)
            else:
                mark = ("†" if r.status == "reduced" else "") + \
                    ("*" if r.success_rate < 1.0 else "")
                cells.append(f"{us(r.median_us)}{mark}")
        body.append([label, *cells])
    return table(["formulation", *(f"n={n}" for n in ns)], body, "l" + "r" * len(ns))


def control_table(control: list[dict]) -> str:
    """The control-step table, each run's total against the extended Jacobian's and the
    paper's ratio beside it."""
    page = Page(_PAGE)
    base = next((c.get("total_us", math.nan) for c in control
                 if c["label"] == "extended_jacobian"), math.nan)
    base_paper = paper.STEP_TIMES_MS.get("extended_jacobian")
    body = []
    for c in control:
        note_ = c.get("note", "")
        run = (note_ if note_.startswith("shortened") else
               page.inline("control_stopped", note=note_)) if note_ else \
            page.inline("control_completed")
        what = f"`{c['label']}`" + (f" — {paper.METHOD_NAMES[c['formulation']]}"
                                    if c["paper_ms"] and c["formulation"] in paper.METHOD_NAMES
                                    else "")
        pms = f"{c['paper_ms']:g}" if c["paper_ms"] else "–"
        prel = f"{c['paper_ms'] / base_paper:.2f}" if c["paper_ms"] and base_paper else "–"
        if not c.get("steps"):
            body.append([what, 0, "–", "–", "–", "–", "–", pms, prel, run])
            continue
        rel = c["total_us"] / base if math.isfinite(base) else math.nan
        body.append([what, c["steps"], us(c["kinematics_us"]), us(c["solve_us"]),
                     us(c["torque_us"]), us(c["total_us"]), f"{rel:.2f}", pms, prel, run])
    return table(["formulation", "steps", "kinematics µs", "solve µs", "torque µs",
                  "total µs", "total / extended Jacobian", "paper ms",
                  "paper / extended Jacobian", "run"], body, "lrrrrrrrrl")


def _step_table(page: Page, ik: dict, keys) -> str:
    body = [[page.inline(block), us(ik[key + "_step_us"]), us(ik[key + "_p10_us"]),
             us(ik[key + "_p90_us"])] for key, block in keys]
    return table(["step", "median µs", "p10 µs", "p90 µs"], body, "lrrr")


def results_markdown(rows: list[TimingRow], rats: list[Ratio], batch: dict, ik: dict,
                     control: list[dict], notes: list[str], settings: Settings,
                     plots: list[str], plot_prefix: str = "") -> str:
    """The results as markdown (tables, ratios, batch, IK step, control step, notes)."""
    page = Page(_PAGE)
    md = []
    ratio_rows = []
    for r in rats:
        tgt = "report" if math.isinf(r.target) else f"≤ {r.target:g}"
        val = f"{r.value:.2f}" if math.isfinite(r.value) else "n/a"
        met = "–" if math.isinf(r.target) else r.met
        ratio_rows.append([r.name, val, tgt, met, r.detail])
    md.append(page.block("targets", table=table(["ratio", "measured", "target", "met",
                                                 "medians"], ratio_rows, "lrrll")))
    for case in sorted({r.case for r in rows if r.suite == "g1"}):
        sub = [r for r in rows if r.case == case]
        md.append(page.block("g1_case", case=case, n=sub[0].n, k=sub[0].k, rows=sub[0].rows,
                             table=detail_table(sub)))
    if batch:
        body = [[page.inline("batch_own_kernel" if batch["batched"][name]
                             else "batch_loop_inside", name=name), us(v)]
                for name, v in batch["batch_us"].items()]
        body += [[page.inline("batch_loop", name=name), us(v)]
                 for name, v in batch["loop_us"].items()]
        body += [[page.inline("batch_single", name=name), us(v)]
                 for name, v in batch["single_us"].items()]
        md.append(page.block("batch", size=batch["size"], n=batch["n"], k=batch["k"],
                             rows=batch["rows"], note=batch["note"],
                             table=table(["what", "µs per stack"], body, "lr")))
    if ik:
        md.append(page.block("ik_step", description=ik.get("description", ""),
                             table=_step_table(page, ik, (("prioik_prepared", "ik_prepared"),
                                                          ("prioik_oneoff", "ik_oneoff"),
                                                          ("placo", "ik_placo")))))
    if ik and ik.get("active_set_table"):
        md.append(page.block("active_set", table=ik["active_set_table"]))
    if ik and (ik.get("mink_table") or ik.get("mink_error")):
        md.append(page.block("mink", table=ik.get("mink_table")
                             or f"Not measured: {ik['mink_error']}"))
    if ik and ik.get("panda"):
        panda = ik["panda"]
        md.append(page.block("panda", description=panda.get("description", ""),
                             table=_step_table(page, panda, (("control", "panda_control"),
                                                             ("prepared", "panda_prepared"),
                                                             ("oneoff", "panda_oneoff"),
                                                             ("placo", "panda_placo")))))
    if control:
        md.append(page.block("control_step", table=control_table(control)))
    ks = sorted({r.k for r in rows if r.suite == "random"})
    if ks:
        sections = "\n\n".join(page.block("random_k", k=k, table=pivot_table(rows, k))
                               for k in ks)
        md.append(page.block("random", family=settings.family, samples=settings.samples,
                             sections=sections))
    md += [page.block("plot", name=p, path=plot_prefix + p) for p in plots]
    if notes:
        md.append(page.block("notes", items="\n".join(f"- {n}" for n in notes)))
    return "\n\n".join(md) + "\n"


def _count_by_n(rows: list[TimingRow]) -> dict[str, int]:
    """Rows per G1 / random ``n``, in that order."""
    out: dict[str, int] = {}
    for r in sorted(rows, key=lambda r: (r.suite != "g1", r.n)):
        key = "G1" if r.suite == "g1" else f"n={r.n}"
        out[key] = out.get(key, 0) + 1
    return out


def doc_page(report: str, info: dict[str, str], settings: Settings, command: str,
             elapsed_s: float, rows: list[TimingRow] | None = None,
             extra: list[Variant] | None = None) -> str:
    """``docs/benchmarks.md``: how it was measured, the machine, then the report
    (``extra``: the plugin-declared rows, listed with their notes)."""
    page = Page(_PAGE)
    rows = rows or []
    counts = []
    for st in ("ok", "reduced", "skipped", "unsupported", "error"):
        these = [r for r in rows if r.status == st]
        if not these:
            continue
        text = page.inline(f"count_{st}", n=len(these))
        if st in ("reduced", "skipped"):
            text += " (" + ", ".join(f"{n}: {c}" for n, c in _count_by_n(these).items()) + ")"
        counts.append(text)
    threads = (page.inline("threads_limited", threads=settings.blas_threads)
               if settings.blas_threads > 0 else page.inline("threads_default"))
    extra_rows = (page.block("extra_rows", items="\n".join(
        f"- `{v.label}` (`{v.options_text()}`): {v.note}" for v in extra)) if extra else "")
    return page.render(
        command=command, mode="quick" if settings.quick else "default",
        minutes=f"{elapsed_s / 60:.1f}", threads=threads, warmup=settings.warmup + 1,
        repeats=settings.repeats, success_tol=f"{SUCCESS_TOL:g}", cap=f"{settings.cap_s:g}",
        min_repeats=settings.min_repeats,
        skip_ms=f"{2 * settings.cap_s / settings.min_repeats * 1e3:.0f}",
        four_cap=f"{4 * settings.cap_s:g}",
        counts=", ".join(counts) or page.inline("count_none"), extra_rows=extra_rows,
        g1_samples=settings.g1_samples, g1_duration=f"{G1_DURATION_S:g}", report=report,
        **{k: info[k] for k in ("cpu", "cores", "os", "python", "blas", "versions")})
