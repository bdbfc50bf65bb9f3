"""The markdown report of test-set runs, generated from their CSV records alone.

Per test set and formulation row, at the report's profile: the problems it takes, the
success rate at every profile, the shifted geometric mean of its solve times (over
every solve it made, success or not: read it beside the success rate) normalised to
the best row's, the same for its flop counts (for the rows whose formulation counts
them, normalised to the best of those rows), its slowest solve, and the share of the
problems where it succeeded within 2× the fastest successful solve of any row. Then
every failure at the profile, grouped by row and reason, and how the exact answers
compare with the stated ones.
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import Any

import numpy as np

from .metrics import FLOP_SHIFT, PROFILES, TIME_SHIFT_S, VALUE_JUDGED, shifted_geometric_mean

__all__ = ["summarize", "format_report", "WITHIN"]

#: the runner's message for a stack with inequality tasks given to an equality-only
#: formulation (the report names those rows once, not each refusal)
GENERIC_UNSUPPORTED = "inequality tasks are not supported"

#: "within 2× the best": a solve counts when its time ≤ WITHIN × the problem's best
WITHIN = 2.0
#: failures named per (row, reason) before "… and N more"
NAMED_FAILURES = 6


def _taken(rec: dict[str, Any]) -> bool:
    return rec["status"] != "unsupported"


def _normalise(summaries: list[dict[str, Any]], key: str, out: str) -> None:
    """``s[out] = s[key] / min over the rows of s[key]`` (NaN where ``s[key]`` is not
    finite or the best is not > 0)."""
    finite = [s[key] for s in summaries if math.isfinite(s[key])]
    low = min(finite) if finite else math.nan
    for s in summaries:
        s[out] = s[key] / low if math.isfinite(s[key]) and low > 0 else math.nan


def summarize(records: list[dict[str, Any]], profile: str = "mid",
              shift: float = TIME_SHIFT_S, flop_shift: float = FLOP_SHIFT
              ) -> dict[str, list[dict[str, Any]]]:
    """Per test set, one summary per row (in the records' order): ``row``, ``taken``,
    ``success`` (profile → rate), ``solves`` (the solves it made), ``sgm_s`` and
    ``sgm_norm`` (the shifted geometric mean
    of times and its ratio to the best row's), ``flops_counted`` (the solves that report
    a flop count), ``sgm_flops`` and ``sgm_flops_norm`` (the shifted geometric mean of
    those counts, shift ``flop_shift``, and its ratio to the best of the rows that count
    them; NaN for a row that counts none), ``worst_s``, ``verify_s`` (the median
    verification stage, NaN where none ran), ``within_2x`` (share of the problems
    taken), ``failures`` ((problem, status, reason) at ``profile``).

    Raises:
        ValueError: unknown profile.
    """
    if profile not in PROFILES:
        raise ValueError(f"unknown profile {profile!r}; known: {', '.join(PROFILES)}")
    by_set: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for rec in records:
        by_set[rec["test_set"]].append(rec)
    out = {}
    for name, recs in by_set.items():
        best: dict[str, float] = {}
        for r in recs:
            if _taken(r) and r[f"success_{profile}"] == 1 and r["time_s"] != "":
                best[r["problem"]] = min(best.get(r["problem"], math.inf), r["time_s"])
        rows: dict[str, list[dict[str, Any]]] = defaultdict(list)
        for r in recs:
            rows[r["row"]].append(r)
        summaries = []
        for label, rr in rows.items():
            taken = [r for r in rr if _taken(r)]
            times = [r["time_s"] for r in taken if r["time_s"] != ""]
            verify = [r.get("verify_time_s", "") for r in taken]
            verify = [v for v in verify if v != "" and v > 0]
            flops = [r["flops"] for r in taken if r.get("flops", "") != ""]
            s = {"row": label, "formulation": rr[0]["formulation"], "taken": len(taken),
                 "problems": len(rr),
                 "judged_by": next((r["judged_by"] for r in taken if r["judged_by"]), ""),
                 "success": {p: (float(np.mean([r[f"success_{p}"] == 1 for r in taken]))
                                 if taken else math.nan) for p in PROFILES},
                 "sgm_s": shifted_geometric_mean(times, shift) if times else math.nan,
                 "solves": len(times), "flops_counted": len(flops),
                 "sgm_flops": (shifted_geometric_mean(flops, flop_shift) if flops
                               else math.nan),
                 "worst_s": max(times) if times else math.nan,
                 "verify_s": float(np.median(verify)) if verify else math.nan,
                 "within_2x": (float(np.mean([
                     r[f"success_{profile}"] == 1 and r["problem"] in best
                     and r["time_s"] <= WITHIN * best[r["problem"]] for r in taken]))
                     if taken else math.nan),
                 "failures": [(r["problem"], r["status"], r[f"reason_{profile}"])
                              for r in taken if r[f"success_{profile}"] != 1]}
            summaries.append(s)
        _normalise(summaries, "sgm_s", "sgm_norm")
        _normalise(summaries, "sgm_flops", "sgm_flops_norm")
        out[name] = summaries
    return out


def _pct(v: float) -> str:
    return "—" if not math.isfinite(v) else f"{100 * v:.0f} %"


def _num(v: float, fmt: str) -> str:
    return "—" if not math.isfinite(v) else format(v, fmt)


def _flop_cell(s: dict[str, Any]) -> str:
    """The flop SGM ratio, with ``(counted/solves)`` when only some solves counted."""
    if not s["flops_counted"]:
        return "—"
    cell = _num(s["sgm_flops_norm"], ".2f")
    solves = s.get("solves", s["flops_counted"])
    return cell if s["flops_counted"] >= solves else f"{cell} ({s['flops_counted']}/{solves})"


def _set_section(name: str, recs: list[dict[str, Any]], summaries: list[dict[str, Any]],
                 profile: str, descriptions: dict[str, str]) -> list[str]:
    problems = list(dict.fromkeys(r["problem"] for r in recs))
    first = {r["problem"]: r for r in recs}
    ns = sorted({first[p]["n"] for p in problems})
    sequences = {first[p]["sequence"] for p in problems} - {""}
    lines = [f"## {name}", ""]
    if name in descriptions:
        lines.append(f"{descriptions[name]}.")
    lines.append(f"{len(problems)} problems, n = {', '.join(map(str, ns))}"
                 + (f", {len(sequences)} sequence(s) of consecutive steps (warm rows follow "
                    "them)" if sequences else "") + ".")
    best = min((s for s in summaries if math.isfinite(s["sgm_s"])),
               key=lambda s: s["sgm_s"], default=None)
    if best is not None:
        lines.append(f"Best shifted geometric mean: `{best['row']}`, "
                     f"{1e6 * best['sgm_s']:.1f} µs.")
    least = min((s for s in summaries if s["taken"] and math.isfinite(s["sgm_flops"])),
                key=lambda s: s["sgm_flops"], default=None)
    if least is not None:
        lines.append(f"Fewest flops (shifted geometric mean): `{least['row']}`, "
                     f"{least['sgm_flops']:.3g}.")
    lines += ["", "| row | taken | success low | mid | high | time (SGM, ×best) "
              f"| flops (SGM, ×best) | worst (µs) | verify (median µs) "
              f"| within {WITHIN:g}× best ({profile}) |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    uncounted = []
    for s in summaries:
        if s["taken"] == 0:
            continue
        mark = " ᵛ" if s["judged_by"] == "values" else ""
        if not s["flops_counted"]:
            uncounted.append(s["row"])
        lines.append(f"| `{s['row']}`{mark} | {s['taken']}/{s['problems']} | "
                     f"{_pct(s['success']['low'])} | {_pct(s['success']['mid'])} | "
                     f"{_pct(s['success']['high'])} | {_num(s['sgm_norm'], '.2f')} | "
                     f"{_flop_cell(s)} | "
                     f"{_num(1e6 * s['worst_s'], '.0f')} | "
                     f"{_num(1e6 * s['verify_s'], '.0f')} | {_pct(s['within_2x'])} |")
    if uncounted:
        lines += ["", "Flops —: not counted by " + ", ".join(f"`{r}`" for r in uncounted)
                  + " (only the compiled closed forms count their floating-point "
                    "operations)."]
    none_taken = [s["row"] for s in summaries if s["taken"] == 0]
    if none_taken:
        lines += ["", "Not taking any problem of this set (inequality tasks they cannot "
                      "take): " + ", ".join(f"`{r}`" for r in none_taken) + "."]
    refused: dict[tuple[str, str], list[str]] = defaultdict(list)
    for r in recs:
        if r["status"] == "unsupported" and r["message"] != GENERIC_UNSUPPORTED:
            refused[(r["row"], r["message"])].append(r["problem"])
    if refused:
        lines += ["", "Refused by the formulation (not taken):", ""]
    for (row, message), probs in refused.items():
        lines.append(f"- `{row}` refuses {len(probs)}: {message}")
    failures = [(s["row"], f) for s in summaries for f in s["failures"]]
    lines += ["", f"Failures at the `{profile}` profile ({len(failures)}):", ""]
    if not failures:
        lines.append("- none")
    for s in summaries:
        groups: dict[str, list[str]] = defaultdict(list)
        for problem, status, reason in s["failures"]:
            groups[f"{status}: {reason}" if reason else status].append(problem)
        for reason, probs in groups.items():
            more = len(probs) - NAMED_FAILURES
            named = ", ".join(probs[:NAMED_FAILURES]) + (f" and {more} more" if more > 0
                                                          else "")
            lines.append(f"- `{s['row']}` ({len(probs)}) — {reason} — {named}")
    stated = [first[p] for p in problems if first[p]["stated_by"]]
    if stated:
        gaps = [r["exact_vs_stated"] for r in stated if r["exact_vs_stated"] != ""]
        lines += ["", f"Stated answers: {len(stated)} problems state a solution or level "
                      "values; the exact answer's (`hierarchical_active_set`, cold) level "
                      "values are within "
                      f"{max(gaps) if gaps else math.nan:.1e}·max(1, v) of them "
                      f"(the worst of {len(gaps)})."]
    not_optimal = [p for p in problems if first[p]["exact_status"] != "optimal"]
    if not_optimal:
        lines += ["", f"The exact answer says other than `optimal` on {len(not_optimal)}: "
                      + ", ".join(f"{p} ({first[p]['exact_status']})"
                                  for p in not_optimal[:NAMED_FAILURES])]
    return lines + [""]


def format_report(records: list[dict[str, Any]], profile: str = "mid", *,
                  command: str = "", machine: str = "", notes: list[str] | None = None,
                  descriptions: dict[str, str] | None = None,
                  shift: float = TIME_SHIFT_S, flop_shift: float = FLOP_SHIFT) -> str:
    """The markdown report of ``records`` (one or several test sets) at ``profile``."""
    summaries = summarize(records, profile, shift, flop_shift)
    by_set: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for rec in records:
        by_set[rec["test_set"]].append(rec)
    tols = ", ".join(f"{p} {t:.0e}" for p, t in PROFILES.items())
    lines = ["# Test sets", ""]
    if command:
        lines += [f"Generated from the CSV of `{command}`; do not edit by hand.", ""]
    if machine:
        lines += [machine, "The machine was shared with other processes: compare ratios "
                  "measured side by side in one run, not absolute times across runs.", ""]
    lines += [
        "**Method** (qpbenchmark's shape). A test set is a class yielding named stacks "
        "(`benchmarks/testsets/`). Tolerance profiles: " + tols + ". **Success** of a "
        "solve at a profile's tolerance: for formulations exact by design, the status is "
        "`optimal` (or `approximate` where the certificate reads a rank decision as "
        "ambiguous) and `check_lexicographic(stack, x, tol)` holds; for those not exact "
        f"by design ({', '.join(f'`{f}`' for f in VALUE_JUDGED)}, marked ᵛ) every "
        "level's residual ‖w_i‖ is within tol·max(1, ‖w_i*‖) of the exact answer's "
        "(`hierarchical_active_set`, cold, cross-checked against the stated answers "
        "where a problem has them). **Time**: the wall time of the prepared solver's "
        "`solve` (`prioik.prepare`, untimed) less its verification stage (reported apart: "
        "**verify**, `Solution.verify_time_s`), per problem the fastest of the passes, "
        "rows interleaved; on sequential test sets warm/hot rows follow each sequence "
        "and `[cold]` rows do not. **SGM** is the shifted geometric mean "
        f"exp(mean(log(t + s))) − s, s = {1e6 * shift:g} µs, over every solve the row "
        "made (success or not), divided by the best row's; rows taking fewer problems "
        "(formulations refusing the stacks' inequality tasks) are compared on those they "
        "take. **Worst**: the slowest solve. **Within 2× best**: the share of "
        "the problems taken where the row succeeded in at most twice the fastest "
        "successful solve of any row. **Flops**: the floating-point operations the "
        "compiled closed forms count in their kernels (`sol.flops`), the same "
        f"shifted geometric mean with s = {flop_shift:g} flops, divided by the "
        "fewest among the rows that count them; `—` for the "
        "rows whose formulation does not count them (QP back-ends, active sets, lexls, "
        "the numpy formulations), `(k/N)` when only k of its N solves were counted.", ""]
    for note in notes or []:
        lines.append(f"- {note}")
    if notes:
        lines.append("")
    for name, recs in by_set.items():
        lines += _set_section(name, recs, summaries[name], profile, descriptions or {})
    return "\n".join(lines).rstrip() + "\n"
