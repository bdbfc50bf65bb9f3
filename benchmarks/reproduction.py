"""The reproduction page (``prioik fencing --doc docs/reproduction.md``).

Every number and every verdict on the page comes from what ``prioik fencing`` measured
(``summary``, ``run_info``); the prose is ``templates/reproduction.md``. Which runs a
claim quotes is said here by formulation (its first row in the run table: its default
or the setting its plugin uses in scenarios) or by label (a study).
"""

from __future__ import annotations

from pathlib import Path

from . import paper
from .like_for_like import BASE, ratio_rows
from .report import (
    Page,
    baselines_block,
    copy_figures,
    mm,
    run_settings,
    sci,
    step_time_figure,
    stops_and_figures,
    table,
)
from .variants import is_damped, parse_label

__all__ = ["write_page", "like_for_like_section"]

#: runs quoted by claim 1 (final tip error, compatible) and claim 2 (algorithmic error)
CLAIM_TIP = ("extended_jacobian", "nullspace", "operational_space", "cascaded_qp",
             "daqp_hierarchical", "unifying", "unifying[armature]", "chiaverini",
             "placo_kinematics_solver")
CLAIM_ALGORITHMIC = ("extended_jacobian", "nullspace", "operational_space", "unifying",
                     "unifying[armature]", "chiaverini")
#: the exact QP cascades of the incompatible run
EXACT_QP = ("cascaded_qp", "daqp_hierarchical")


def _main_row(settings: dict) -> bool:
    """A formulation's own run: acceleration level, undamped, the robot's own ``M``; an
    external library's default row."""
    opts = settings.get("options") or {}
    if settings.get("origin") == "baseline":
        return not opts
    return (settings.get("level", "acceleration") == "acceleration"
            and not settings.get("armature") and not is_damped(opts))


def _pick(runs: dict, names, settings: dict) -> list[str]:
    """The labels of ``runs`` that ``names`` name: a label as it is, a formulation by
    its first main row (:func:`_main_row`; ``settings``: ``run_info.json``'s runs)."""
    out = []
    for name in names:
        if "[" in name:
            if name in runs:
                out.append(name)
            continue
        first = next((lb for lb in runs if parse_label(lb)[0] == name
                      and _main_row(settings.get(lb, {}))), None)
        if first is not None:
            out.append(first)
    return out


def _fmt_ms(x) -> str:
    return sci(None if x is None else 1e3 * x, ".3f") + " ms"


def _measured(page: Page, meta: dict, summary: dict, shown: dict) -> str:
    out = []
    head = ["run", "final tip error", "max algorithmic error", "max CoM error",
            "max support-foot error", "max left-foot error", "max joint-limit violation",
            "max ‖q̈‖", "median step", "median solve", "median verify", "status"]
    for variant, runs in summary.items():
        rows = [[f"`{label}`", mm(s["final_tip_error_m"]), sci(s["max_algorithmic_error"]),
                 mm(s.get("max_com_error_m")), mm(s.get("max_support_foot_error_m")),
                 mm(s.get("max_left_foot_error_m")),
                 f"{sci(s.get('max_joint_limit_violation_rad'))} rad",
                 sci(s["max_qdd_norm"], ".3g"), _fmt_ms(s["median_step_time_s"]),
                 _fmt_ms(s["median_solve_time_s"]), _fmt_ms(s.get("median_verify_time_s")),
                 "failed" if s["failed"] else "ran to the end"] for label, s in runs.items()]
        figures = [(key, page.inline(f"{key}_figure", variant=variant))
                   for key in ("tip_error", "algorithmic_error", "qdd")]
        out.append(page.block("measured", variant=variant, table=table(head, rows),
                              after=stops_and_figures(meta, variant, shown, figures)))
    return "\n\n".join(out)


def _claims(page: Page, comp: dict, inc: dict, settings: dict) -> tuple[str, str, str]:
    tip = []
    for label in _pick(comp, CLAIM_TIP, settings):
        s = comp[label]
        e = s["final_tip_error_m"]
        verdict = page.inline("within_1mm" if e is not None and e < 1e-3 else "not_within_1mm")
        failed = "" if not s["failed"] else page.inline("tip_run_failed", tip=mm(e))
        tip.append(page.inline("claim_tip", label=label, tip=mm(e), verdict=verdict,
                               failed=failed))
    alg = [page.inline("claim_algorithmic", label=label,
                       value=sci(comp[label]["max_algorithmic_error"]),
                       failed="" if not comp[label]["failed"] else page.inline("run_failed"))
           for label in _pick(comp, CLAIM_ALGORITHMIC, settings)]
    incompatible = [page.inline("claim_incompatible", label=label,
                               fate=page.inline("FAILED" if s["failed"] else "ran_to_the_end"),
                               tip=mm(s["final_tip_error_m"]),
                               foot=mm(s.get("max_support_foot_error_m")),
                               com=mm(s.get("max_com_error_m")),
                               left=mm(s.get("max_left_foot_error_m")),
                               limits=sci(s.get("max_joint_limit_violation_rad")),
                               qdd=sci(s["max_qdd_norm"], ".3g"))
                    for label, s in inc.items()]
    return "\n".join(tip), "\n".join(alg), "\n".join(incompatible)


def _crosscheck(page: Page, cc: dict) -> str:
    if not cc:
        return ""
    items = [page.inline("crosscheck_item", label=label, variant=variant,
                        compared=c["steps_compared"], damped=c["steps_with_damping"],
                        levels=c["damped_levels"] or "none",
                        undamped_diff=sci(c["max_rel_diff_qdd_undamped_steps"]),
                        damped_diff=sci(c["max_rel_diff_qdd_damped_steps"]))
             for variant, by_label in cc.items() for label, c in by_label.items()]
    return page.block("crosscheck", items="\n".join(items))


def _order(page: Page, comp: dict, inc: dict, settings: dict) -> str:
    src = comp or inc
    timed = [(lb, src[lb]["median_step_time_s"]) for lb in
             _pick(src, paper.STEP_TIMES_MS, settings)
             if src[lb]["median_step_time_s"] is not None]
    if not timed:
        return ""
    measured = [lb for lb, _ in sorted(timed, key=lambda p: p[1])]
    by_name = {parse_label(lb)[0]: lb for lb in measured}
    ranked = [by_name[n] for n in sorted(paper.STEP_TIMES_MS, key=paper.STEP_TIMES_MS.get)
              if n in by_name]
    same = measured == ranked
    return page.inline("order", measured=" < ".join(f"`{m}`" for m in measured),
                      paper=" < ".join(f"`{p}`" for p in ranked),
                      same="the same" if same else "different",
                      why="" if same else page.inline("order_differs"))


def _ratio(x, spec: str = ".2f") -> str:
    return "—" if x is None else format(x, spec)


def _relation(pairs: list[tuple[str, float, float]]) -> str:
    """``"below"``, ``"above"`` or which are which, for ``(name, a, b)``: ``a`` against
    ``b``."""
    below = [n for n, a, b in pairs if a < b]
    above = [n for n, a, b in pairs if a >= b]
    if not above:
        return "all below"
    if not below:
        return "all at or above"
    return (f"below for {', '.join(f'`{n}`' for n in below)} and at or above for "
            f"{', '.join(f'`{n}`' for n in above)}")


def _ranked(rows: list[dict], key: str) -> list[str]:
    return [r["formulation"] for r in sorted(rows, key=lambda r: r[key])]


def like_for_like_section(page: Page, lfl: dict | None) -> str:
    """The like-for-like table and its reading (``run_info.json``'s ``like_for_like``,
    :func:`benchmarks.like_for_like.measure_fencing`): per formulation, the paper's
    per-step ratio, the compiled time ratio and the flop ratio to the extended
    Jacobian's, the flop rate; ``""`` without a measurement."""
    if not lfl or not lfl.get("measured"):
        return ""
    rows = ratio_rows(lfl["measured"])
    cells = [[f"`{r['formulation']}`", r["paper_name"] or "—",
              _ratio(r["paper_ratio"]), "C++" if r["compiled"] else "numpy",
              f"{1e6 * r['time_s']:.1f} µs",
              _ratio(r["time_ratio"]) if r["compiled"] else "— (numpy)",
              "—" if r["flops"] is None else f"{r['flops']:.3g}",
              _ratio(r["flop_ratio"]), _ratio(r["rate_ratio"])] for r in rows]
    tbl = table(["formulation", "the paper's method", "paper: per-step ratio", "kernel here",
                 "median solve", "time ratio (compiled)", "flops", "flop ratio",
                 "flop rate / EJ's"], cells)
    others = [r for r in rows if r["formulation"] != BASE]
    counted = [r for r in others if r["flop_ratio"] is not None]
    reading = []
    if counted:
        reading.append(page.inline("lfl_formulations", items=", ".join(
            f"`{r['formulation']}` does {r['flop_ratio']:.2f}×" for r in counted)))
    rated = [r for r in others if r["rate_ratio"] is not None]
    base = next(r for r in rows if r["formulation"] == BASE)
    if rated:
        above = [r["formulation"] for r in rated if r["rate_ratio"] > 1]
        below = [r["formulation"] for r in rated if r["rate_ratio"] < 1]
        reading.append(page.inline(
            "lfl_rates", items=", ".join(f"`{r['formulation']}` {r['rate_ratio']:.2f}"
                                         for r in rated),
            above=page.inline("lfl_above", names=", ".join(f"`{n}`" for n in above))
            if above else "",
            below=page.inline("lfl_below", names=", ".join(f"`{n}`" for n in below))
            if below else "",
            base_us=f"{1e6 * base['time_s']:.1f}"))
    in_paper = [r for r in counted if r["paper_ratio"] is not None
                and r["time_ratio"] is not None]
    if in_paper:
        by_paper = _ranked(in_paper, "paper_ratio")

        def order(key: str) -> str:
            ranked = _ranked(in_paper, key)
            return ("in the paper's order" if ranked == by_paper else
                    "in another order than the paper's: "
                    + " < ".join(f"`{n}`" for n in ranked) + " (paper: "
                    + " < ".join(f"`{n}`" for n in by_paper) + ")")
        reading.append(page.inline(
            "lfl_paper",
            paper=", ".join(f"`{r['formulation']}` {r['paper_ratio']:.2f}" for r in in_paper),
            flops=", ".join(f"{r['flop_ratio']:.2f}" for r in in_paper),
            times=", ".join(f"{r['time_ratio']:.2f}" for r in in_paper),
            relation=_relation([(r["formulation"], r["paper_ratio"], r["flop_ratio"])
                                for r in in_paper]),
            time_relation=_relation([(r["formulation"], r["time_ratio"], r["paper_ratio"])
                                     for r in in_paper]).replace("all ", ""),
            order=order("flop_ratio"), time_order=order("time_ratio")))
    numpy = [r for r in rows if not r["compiled"]]
    if numpy:
        reading.append(page.inline("lfl_numpy", items=", ".join(
            f"`{r['formulation']}` ({1e6 * r['time_s']:.0f} µs)" for r in numpy)))
    variants = lfl.get("variants") or []
    return page.block("like_for_like", stacks=lfl["stacks"], n=lfl["n"],
                      states=lfl["stacks"] // max(1, len(variants)),
                      variants=" and ".join(variants), repeats=lfl["repeats"],
                      table=tbl, reading="\n\n".join(reading))


def _beyond(page: Page, summary: dict, meta: dict) -> str:
    comp, inc = summary.get("compatible", {}), summary.get("incompatible", {})
    runs = meta["runs"]
    velocity_qp = next((lb for lb, r in runs.items() if r["formulation"] == "cascaded_qp"
                        and r["level"] == "velocity"), None)
    trio = [lb for lb in ("placo_kinematics_solver", velocity_qp, "extended_jacobian",
                          "extended_jacobian[step_bound]") if lb and (lb in comp or lb in inc)]
    if "placo_kinematics_solver" not in trio:
        return ""
    rows = []
    for variant, by_label in summary.items():
        for lb in trio:
            if lb in by_label:
                r = by_label[lb]
                rows.append([f"`{lb}`", variant, mm(r["final_tip_error_m"]),
                             mm(r.get("max_com_error_m")), mm(r.get("max_support_foot_error_m")),
                             f"{sci(r.get('max_joint_limit_violation_rad'))} rad",
                             _fmt_ms(r["median_step_time_s"])])
    head = ["run", "variant", "final tip error", "max CoM error", "max support-foot error",
            "max joint-limit violation", "median step"]
    text = page.block("beyond", velocity_qp=velocity_qp or "cascaded_qp",
                      table=table(head, rows))
    side = meta.get("headline_timing") or {}
    if side:
        rows = []
        for variant, h in side.items():
            (a, b), best = h["median_step_s"].keys(), h["best_median_step_s"]
            rows.append([variant, f"`{a}`", _fmt_ms(best[a]), f"`{b}`", _fmt_ms(best[b]),
                         f"{h['ratio']:.2f}",
                         ", ".join(_fmt_ms(t) for t in h["median_step_s"][a]) + " / "
                         + ", ".join(_fmt_ms(t) for t in h["median_step_s"][b])])
        turn = meta.get("turn_steps", 0)
        turns = (f"advanced in turns of {turn} steps each, so their step times met the same "
                 f"machine speed (which drifts over minutes here)" if turn else
                 "ran one after another, minutes apart, on a machine whose speed drifts "
                 "over minutes")
        text = text.rstrip("\n") + "\n\n" + page.block(
            "side_by_side", rounds=next(iter(side.values()))["rounds"], turns=turns,
            table=table(["variant", "run", "median step", "beside", "median step", "ratio",
                         "each round"], rows))
        text = text.rstrip("\n") + "\n\n"
    return text


def _eq18(page: Page, inc: dict, meta: dict) -> list[str]:
    exact = inc.get("extended_jacobian")
    if exact is None:
        return []
    msgs = meta.get("messages", {}).get("incompatible", {})
    fate = (page.inline("eq18_fate_diverges", message=msgs.get("extended_jacobian", "stopped"))
            if exact["failed"] else
            page.inline("eq18_fate_runs", qdd=sci(exact["max_qdd_norm"], ".3g")))
    trace = meta.get("diagnostics", {}).get("sigma_trace") or []
    text = ""
    if trace:
        before = [r for r in trace if r["limit_rows"] == 0]
        after = [r for r in trace if r["limit_rows"] > 0]
        low = min(trace, key=lambda r: r["sigma_lowest"])
        text = page.inline("trace_smallest", sigma=f"{low['sigma_lowest']:.2g}",
                           level=low["lowest_level"], t=f"{low['t']:.3f}")
        if before:
            text += page.inline("trace_before", t=f"{max(r['t'] for r in before):.3f}",
                                sigma=f"{min(r['sigma_lowest'] for r in before):.2g}",
                                qdd=f"{max(r['qdd_norm'] for r in before):.3g}")
        if after:
            text += page.inline("trace_after", rows=max(r["limit_rows"] for r in after),
                                h=f"{max(r['limit_target'] for r in after):.3g}",
                                qdd=f"{max(r['qdd_norm'] for r in after):.3g}")
        text += "."
        if exact["failed"] and after:
            text += page.inline("trace_not_sigma" if low["sigma_lowest"] > 1e-3
                                else "trace_sigma_falls", sigma=f"{low['sigma_lowest']:.2g}")
    item = page.inline("eq18", fate=fate, trace=text)
    if trace:
        rows = [[f"{r['t']:.3f}", f"{r['sigma_tip']:.3g}",
                 f"{r['sigma_lowest']:.3g} ({r['lowest_level']})", f"{r['qdd_norm']:.3g}",
                 r["limit_rows"], f"{r['limit_target']:.3g}"] for r in trace]
        tbl = table(["t (s)", "sword tip σ_min/‖A‖_F", "smallest (level)", "‖q̈‖",
                     "joint-limit rows", "their max \\|h\\| (rad/s²)"], rows)
        # the table belongs to the list item: indented, blank lines around it
        item += "\n\n  " + tbl.replace("\n", "\n  ") + "\n"
    return [item]


def _errors(s: dict) -> dict[str, str]:
    return {"tip": mm(s["final_tip_error_m"]), "foot": mm(s.get("max_support_foot_error_m")),
            "com": mm(s.get("max_com_error_m")), "left": mm(s.get("max_left_foot_error_m")),
            "limits": sci(s.get("max_joint_limit_violation_rad")),
            "qdd": sci(s["max_qdd_norm"], ".3g")}


def _differences(page: Page, summary: dict, meta: dict) -> str:
    comp, inc = summary.get("compatible", {}), summary.get("incompatible", {})
    runs = meta["runs"]
    diag = meta.get("diagnostics", {})
    out = _eq18(page, inc, meta)
    for label, block in (("extended_jacobian[eq27]", "eq27"),
                         ("extended_jacobian[eq27_null_space]", "eq27_null_space")):
        r = inc.get(label)
        if r is not None:
            out.append(page.inline(block, label=label,
                                  lam=f"{runs[label]['options'].get('damping', 0):g}",
                                  fate=page.inline("FAILED" if r["failed"] else
                                                   "runs_to_the_end"), **_errors(r)))
    if "extended_jacobian[eq27]" in inc:
        out.append("  " + page.inline("eq27_explained").strip())
    sb = inc.get("extended_jacobian[step_bound]")
    if sb is not None:
        bound = runs["extended_jacobian[step_bound]"]["options"]["step_bound"]
        bound = max(bound.values()) if isinstance(bound, dict) else bound
        out.append(page.inline("step_bound", label="extended_jacobian[step_bound]",
                              bound=f"{bound:g}", **_errors(sb)))
        allb = inc.get("extended_jacobian[step_bound_all]")
        top = diag.get("max_limit_target")
        if allb is not None:
            targets = page.inline("step_bound_all_targets", top=f"{top:.3g}") if top else ""
            out.append("  " + page.inline(
                "step_bound_all", label="extended_jacobian[step_bound_all]", targets=targets,
                limits=sci(allb.get("max_joint_limit_violation_rad"))).strip())
    if "extended_jacobian[selective]" in inc:
        threshold = runs["extended_jacobian[selective]"]["options"]["singular_threshold"]
        sig = diag.get("standing_sigmas", {})
        low = [k for k, v in sig.items() if 0 < v < threshold]
        verdict = (page.inline("selective_damped", levels=", ".join(low),
                               threshold=f"{threshold:g}") if low
                   else page.inline("selective_none", threshold=f"{threshold:g}"))
        out.append(page.inline("selective", label="extended_jacobian[selective]",
                              threshold=f"{threshold:g}",
                              sigmas=", ".join(f"{k} {v:.3g}" for k, v in sig.items()),
                              verdict=verdict))
    qp = _pick(inc, EXACT_QP, runs)
    if qp:
        parts = [page.inline("qp_part", label=lb,
                             fate=page.inline("fails" if inc[lb]["failed"] else
                                              "runs_to_the_end"),
                             qdd=sci(inc[lb]["max_qdd_norm"], ".3g")) for lb in qp]
        out.append(page.inline("qp", parts=", ".join(parts)))
    ud = meta.get("unifying_diagnostic")
    if ud and "unifying" in comp:
        out.append(page.inline(
            "unifying", fate=page.inline("diverges" if comp["unifying"]["failed"] else "runs"),
            qdd_unifying=f"{ud['qdd_unifying']:.3g}",
            qdd_exact=f"{ud['qdd_extended_jacobian']:.3g}",
            qdd_identity=f"{ud['qdd_unifying_identity_M']:.3g}", cond=f"{ud['cond_M']:.2g}"))
        arm = comp.get("unifying[armature]")
        conds = ud.get("cond_M_armature", {})
        if arm is not None:
            a = runs["unifying[armature]"]["armature"]
            low = comp.get("unifying[armature_low]")
            low_text = ""
            if low is not None:
                a_low = runs["unifying[armature_low]"]["armature"]
                msg = meta.get("messages", {}).get("compatible", {}).get(
                    "unifying[armature_low]")
                low_text = page.inline(
                    "armature_low", armature=f"{a_low:g}", label="unifying[armature_low]",
                    cond=f"{conds.get(f'{a_low:g}', float('nan')):.2g}",
                    fate=(page.inline("armature_low_diverges", message=msg) if low["failed"]
                          else page.inline("runs_to_the_end")))
            out.append(page.inline(
                "armature", armature=f"{a:g}", label="unifying[armature]",
                cond=f"{ud['cond_M']:.2g}",
                cond_armature=f"{conds.get(f'{a:g}', float('nan')):.2g}",
                fate=page.inline("still_fails" if arm["failed"] else "runs_to_the_end"),
                tip=mm(arm["final_tip_error_m"]), alg=sci(arm["max_algorithmic_error"]),
                low=low_text))
    return "\n".join(out)


def write_page(path: Path, summary: dict, meta: dict, pngs: dict, command: str,
               gain: float) -> Path:
    """Write the reproduction page from measured numbers; copy its plots to ``img/``.

    Args:
        summary: ``summary.json`` of the run.
        meta: ``run_info.json`` (with the cross-check and the diagnostics).
        pngs: The figures (:class:`~prioik.benchmarks.scenario_runs.ScenarioRuns`).
        command: The command line that reproduces the page.
        gain: ``K`` of the velocity-level runs.
    """
    path = Path(path)
    page = Page("reproduction.md")
    shown = copy_figures(pngs, path, "fencing")
    comp, inc = summary.get("compatible", {}), summary.get("incompatible", {})
    variants = list(summary)
    rows = []
    for label, r in meta["runs"].items():
        opts, stack, where = run_settings(r, variants)
        rows.append([f"`{label}`", f"`{r['formulation']}`", opts, stack, where, r["note"]])
    runs_table = table(["run", "formulation", "options", "stack", "runs in", "why"], rows)
    phases = [[f"`{label}`", variant, *(f"{1e3 * x:.3f} ms" for x in ph),
               f"{1e3 * sum(ph):.3f} ms"]
              for variant, by_label in meta.get("phases", {}).items()
              for label, ph in by_label.items()]
    claim_tip, claim_alg, claim_inc = _claims(page, comp, inc, meta["runs"])
    text = page.render(
        command=command, wall_s=f"{meta['wall_time_s']:.0f}", gain=f"{gain:g}",
        runs_table=runs_table, baselines=baselines_block(page, meta, summary),
        not_run=(page.block("not_run", skipped="; ".join(meta["skipped"]))
                 if meta.get("skipped") else ""),
        measured=_measured(page, meta, summary, shown),
        claim_tip=claim_tip, claim_algorithmic=claim_alg, claim_incompatible=claim_inc,
        crosscheck=_crosscheck(page, meta.get("crosscheck", {})),
        phases_table=table(["run", "variant", "kinematics", "solve", "torque",
                            "total (median)"], phases),
        order=_order(page, comp, inc, meta["runs"]),
        like_for_like=like_for_like_section(page, meta.get("like_for_like")),
        step_time=step_time_figure(shown),
        beyond=_beyond(page, summary, meta), differences=_differences(page, summary, meta))
    path.write_text(text)
    return path
