"""One ``prioik bench`` run: draw the cases, run every experiment, write the outputs."""

from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from prioik.benchmarks.machine import machine
from prioik.benchmarks.plots import time_vs_size
from prioik.benchmarks.progress import Progress
from prioik.benchmarks.results import TimingRow, write_csv
from prioik.benchmarks.stacks import Case, g1_fencing_cases, random_case
from prioik.benchmarks.variants import Variant, table
from prioik.threads import blas_info, blas_threads

from . import tables
from .batch import batched_formulations, measure_batch
from .control_step import measure_control_step
from .ik_step import measure_ik_step
from .page import doc_page, note, results_markdown
from .ratios import SINGLE_SOLVES, ratios
from .settings import Settings

__all__ = ["run_benchmark"]


def _estimates(rows: list[TimingRow], variants: list[Variant]) -> dict[str, float]:
    """Median solve (µs) on the compatible G1 case of each control-step variant: its own
    row, or the row of its formulation's default back-end."""
    from prioik import formulations
    by_label = {r.label: r.median_us for r in rows if r.case == "g1 compatible"
                and math.isfinite(r.median_us)}
    out = {}
    for v in variants:
        label = v.label
        if label not in by_label and not v.options:
            opts = formulations.get(v.formulation).options
            if "solver" in opts:
                label = f"{v.formulation}[{opts['solver'].default}]"
        if label in by_label:
            out[v.label] = by_label[label]
    return out


def run_benchmark(settings: Settings, out: Path, doc: Path | None = None,
                  command: str = "prioik bench") -> dict[str, Any]:
    """Run everything, write the outputs; returns the summary (also ``summary.json``).

    Outputs in ``out``: ``results.csv`` (:class:`~prioik.benchmarks.results.TimingRow`),
    ``results.md``, ``summary.json``, ``time_vs_n.png``, ``time_vs_k.png``; ``doc``: the
    documentation page (plots linked relative to it).
    """
    with blas_threads(settings.blas_threads):
        limited = settings.blas_threads > 0 and bool(blas_info())
        return _run(settings, Path(out), doc, command, limited)


def _run(settings: Settings, out: Path, doc: Path | None, command: str,
         blas_limited: bool) -> dict[str, Any]:
    t_start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    bench = table("bench")
    variants = bench.only(settings.only)
    notes = [note("unavailable", what=f"{name}: {why}")
             for name, why in bench.unavailable.items()
             if not settings.only or name in settings.only]
    if settings.blas_threads > 0 and not blas_limited:
        notes.append(note("no_openblas", threads=settings.blas_threads))

    cases: list[Case] = []
    phases: dict[str, float] = {}
    mark = time.perf_counter()
    if settings.g1:
        print("prioik bench: simulating the G1 fencing runs to sample states ...",
              file=sys.stderr, flush=True)
        g1_cases, runs, reason = g1_fencing_cases(settings.g1_samples)
    else:
        g1_cases, runs, reason = [], [], "--no-g1"
    if reason:
        notes.append(note("g1_skipped", reason=reason))
        print(f"prioik bench: G1 part skipped: {reason}", file=sys.stderr)
    cases.extend(g1_cases)
    for n in settings.sizes:
        for k in settings.levels:
            cases.append(random_case(n, k, settings.samples, settings.family))
    phases["drawing stacks"] = time.perf_counter() - mark

    control_variants = table("control_step").rows if runs else []
    total = (len(cases) * len(variants) + 1 + (len(batched_formulations()) + 1 if runs else 0)
             + len(control_variants) + (1 if runs else 0))
    progress = Progress(total)
    mark = time.perf_counter()
    rows = tables.measure_tables(cases, variants, settings, progress)
    phases["tables"] = time.perf_counter() - mark
    reduced = [r for r in rows if r.status == "reduced"]
    skipped = [r for r in rows if r.status == "skipped"]
    if reduced:
        names = sorted({f"{r.label} @ {r.case}" for r in reduced})
        notes.append(note("reduced", count=len(reduced), repeats=settings.repeats,
                          cap=f"{settings.cap_s:g}",
                          rows=", ".join(names[:40]) + (", …" if len(names) > 40 else "")))
    if skipped:
        notes.append(note("skipped", count=len(skipped),
                          rows=", ".join(sorted({f"{r.label} @ {r.case}" for r in skipped}))))

    batch: dict[str, Any] = {}
    control: list[dict] = []
    ik: dict[str, Any] = {}
    if runs:
        mark = time.perf_counter()
        singles = [bench.known[lb] for lb in SINGLE_SOLVES if lb in bench.known]
        batch = measure_batch(runs, settings, singles, progress=progress)
        phases["batch"] = time.perf_counter() - mark
        mark = time.perf_counter()
        control, why = measure_control_step(control_variants, settings, progress,
                                            _estimates(rows, control_variants))
        phases["control step"] = time.perf_counter() - mark
        if why:
            notes.append(note("control_skipped", reason=why))
        mark = time.perf_counter()
        ik, why = measure_ik_step(settings, progress)
        phases["IK step"] = time.perf_counter() - mark
        if why:
            notes.append(note("ik_skipped", reason=why))
    else:
        notes.append(note("needs_g1"))
    progress.step("writing outputs")
    progress.close()
    notes.append(note("phases", phases=", ".join(f"{k} {v:.0f} s" for k, v in phases.items())))

    rats = ratios(rows, batch, ik)
    write_csv(out / "results.csv", rows, TimingRow)
    plots = time_vs_size(rows, out)
    (out / "results.md").write_text(results_markdown(rows, rats, batch, ik, control, notes,
                                                     settings, plots))
    info = machine()
    elapsed = time.perf_counter() - t_start
    summary = {"machine": info, "elapsed_s": elapsed, "phases_s": phases,
               "settings": asdict(settings),
               "ratios": [{"name": r.name, "value": r.value, "target": r.target,
                           "met": r.met, "detail": r.detail} for r in rats],
               "batch": batch, "ik_step": ik, "control_step": control, "notes": notes}
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    if doc is not None:
        doc = Path(doc)
        doc.parent.mkdir(parents=True, exist_ok=True)
        prefix = os.path.relpath(out.resolve(), doc.parent.resolve()) + "/"
        report = results_markdown(rows, rats, batch, ik, control, notes, settings, plots,
                                  prefix)
        extra = [v for v in variants if v.origin == "declared"]
        doc.write_text(doc_page(report, info, settings, command, elapsed, rows, extra))
    return summary
