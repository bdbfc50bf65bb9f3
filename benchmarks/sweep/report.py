"""The sweep's page: measured tables and plots filled into ``templates/report.md``.

The prose lives in the template; this module computes the tables (success rates with
Wilson intervals, step times, stopped runs, the run's conditions) and the figures.
"""

from __future__ import annotations

import json
import math
import shutil
from importlib import resources
from pathlib import Path
from string import Template
from typing import Any

import numpy as np

from .config import Plan
from .scenarios import SWEEP_SCENARIOS
from .stats import judge_rows, success_table

__all__ = ["write_report"]

_CRITERIA_COLUMNS = (("success", "success"), ("ok_tip", "tip (reachable)"),
                     ("ok_foot", "foot"), ("ok_com", "CoM"), ("ok_divergence", "no divergence"))


def _template() -> Template:
    text = resources.files("prioik.benchmarks.sweep").joinpath("templates/report.md").read_text()
    return Template(text)


def _swept_table(plan: Plan) -> str:
    cfg = plan.config
    lines = ["| parameter | values |", "|---|---|"]
    for name, v in (cfg.get("fixed") or {}).items():
        lines.append(f"| `{name}` | {v} (fixed) |")
    for name, v in (cfg.get("grid") or {}).items():
        desc = (f"{v['n']} values evenly from {v['from']} to {v['to']}" if isinstance(v, dict)
                else ", ".join(map(str, v)))
        lines.append(f"| `{name}` | grid: {desc} |")
    sample = dict(cfg.get("sample") or {})
    n = sample.pop("n", None)
    for name, v in sample.items():
        desc = (f"one of {', '.join(map(str, v['choices']))}" if isinstance(v, dict)
                else f"uniform in [{v[0]}, {v[1]}]")
        lines.append(f"| `{name}` | random ({n} draws, seed {cfg.get('seed', 0)}): {desc} |")
    margins = [r.params["reach_margin_m"] for r in plan.runs]
    lines.append(f"| reach margin (resulting) | {min(margins):+.3f} to {max(margins):+.3f} m |")
    lines.append("| formulations | " + ", ".join(f"`{v.label}`" for v in plan.variants) + " |")
    return "\n".join(lines)


def _success_table(table: dict, labels: list[str]) -> str:
    head = "| formulation | " + " | ".join(n for _, n in _CRITERIA_COLUMNS) + " |"
    lines = [head, "|---|" + "---|" * len(_CRITERIA_COLUMNS)]
    for lb in labels:
        lines.append(f"| `{lb}` | " + " | ".join(table[lb][k].text()
                                                  for k, _ in _CRITERIA_COLUMNS) + " |")
    return "\n".join(lines)


def _ms(x: float | None) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{1e3 * x:.3f}"


def _time_table(judged: list[dict], labels: list[str]) -> str:
    lines = ["| formulation | runs | median step (ms) | 90th pct of run medians (ms) | "
             "median solve (ms) | median run wall (s) |", "|---|---|---|---|---|---|"]
    for lb in labels:
        rs = [r for r in judged if r["label"] == lb and r.get("median_step_time_s")]
        if not rs:
            lines.append(f"| `{lb}` | 0 | — | — | — | — |")
            continue
        step = np.array([r["median_step_time_s"] for r in rs])
        solve = np.array([r["median_solve_time_s"] for r in rs])
        wall = [r["wall_s"] for r in rs if r.get("wall_s") is not None]
        wall_text = f"{float(np.median(wall)):.2f}" if wall else "—"
        lines.append(f"| `{lb}` | {len(rs)} | {_ms(float(np.median(step)))} | "
                     f"{_ms(float(np.percentile(step, 90)))} | {_ms(float(np.median(solve)))} | "
                     f"{wall_text} |")
    return "\n".join(lines)


def _boundary(judged: list[dict], tip_m: float) -> str:
    """Where the tip stops reaching its target, as the runs show it."""
    ok = [r["reach_margin_m"] for r in judged if not r["failed"]
          and r.get("final_tip_error_m") is not None and r["final_tip_error_m"] <= tip_m]
    margins = sorted({r["reach_margin_m"] for r in judged})
    if not margins:
        return "No runs."
    if not ok:
        return f"No run brought the tip within {1e3 * tip_m:g} mm of its target."
    far = max(ok)
    beyond = [m for m in margins if m > far]
    text = (f"The farthest target some formulation reached within {1e3 * tip_m:g} mm has a "
            f"reach margin of {far:+.3f} m")
    if beyond:
        text += (f"; no formulation reached any of the {len(beyond)} target(s) from "
                 f"{beyond[0]:+.3f} m on")
    return text + "."


def _failures(judged: list[dict], labels: list[str]) -> str:
    lines = []
    for lb in labels:
        bad = [r for r in judged if r["label"] == lb and r["failed"]]
        if not bad:
            continue
        margins = sorted(r["reach_margin_m"] for r in bad)
        example = bad[0]["message"] or bad[0]["status"]
        lines.append(f"- `{lb}`: {len(bad)} run(s) stopped, reach margins "
                     f"{margins[0]:+.3f} to {margins[-1]:+.3f} m; e.g. {example}")
    return "\n".join(lines) or "None: every run reached the end."


def write_report(plan: Plan, rows: dict[str, dict[str, Any]], out, info: dict,
                 command: str, doc: Path | None = None) -> Path:
    """Write ``out/report.md`` and its figures (``out/sweep_*.png``); with ``doc``, the
    same page at ``doc`` with the figures copied to ``img/`` beside it.

    Returns:
        The page written last (``doc`` if given).
    """
    from .plots import error_vs_margin, step_times, success_rates
    out = Path(out)
    sc = SWEEP_SCENARIOS[plan.scenario]()
    crit = plan.criteria
    labels = [v.label for v in plan.variants]
    ordered = [rows[r.run_id] for r in plan.runs if r.run_id in rows]
    judged = judge_rows(ordered, sc, crit)
    unsupported = sorted({r["label"] for r in ordered if r["status"] == "unsupported"})
    labels_shown = [lb for lb in labels if lb not in unsupported
                    or any(r["label"] == lb for r in judged)]
    table = success_table(judged, labels_shown)
    name = plan.title or f"{plan.scenario} sweep"
    pngs = {
        "success": success_rates(out / "sweep_success.png", table, labels_shown,
                                 [(k, n) for k, n in _CRITERIA_COLUMNS],
                                 f"{name}: success rate, 95 % Wilson interval"),
        "tip": error_vs_margin(out / "sweep_tip_error.png", judged, labels_shown,
                               "final_tip_error_m", "final tip error (m)", crit["tip_m"],
                               f"{name}: final sword-tip error against reach margin"),
        "foot": error_vs_margin(out / "sweep_foot_error.png", judged, labels_shown,
                                "max_support_foot_error_m", "max support-foot error (m)",
                                crit["support_foot_m"],
                                f"{name}: support-foot displacement against reach margin"),
        "com": error_vs_margin(out / "sweep_com_error.png", judged, labels_shown,
                               "max_com_error_m", "max CoM error (m)", crit["com_m"],
                               f"{name}: CoM error against reach margin"),
        "time": step_times(out / "sweep_step_time.png", judged, labels_shown,
                           f"{name}: time per control step"),
    }
    errors = [r for r in ordered if r["status"] == "error"]
    how = [f"- {len(rows)} of {len(plan.runs)} rows present."]
    runs_info = [i for i in info.get("invocations", [info]) if i.get("runs_computed")]
    for i in runs_info:
        rate = (f", {i['runs_per_minute']:.1f} runs per minute" if i.get("runs_per_minute")
                else "")
        how.append(f"- An invocation computed {i['runs_computed']} run(s) in "
                   f"{i['wall_time_s']:.0f} s ({i['mode']}, {i['workers']} worker "
                   f"process(es), one BLAS thread each; cluster start "
                   f"{i['cluster_start_s']:.1f} s){rate}; load average (1, 5, 15 min) "
                   f"{i['load_average_start']} at start, {i['load_average_end']} at end, "
                   f"{i['cpu_count']} cores"
                   + (f"; CPU pressure (share of time a runnable task waited for a core, "
                      f"60 s average) {i['cpu_pressure_avg60_start']:.0f} % at start"
                      if i.get("cpu_pressure_avg60_start") is not None else "") + ".")
    from .throughput import describe
    from .throughput import load as load_throughput
    throughput = load_throughput(out)
    if throughput is not None:
        how.append(describe(throughput))
    if runs_info:
        info = {**runs_info[-1], **{k: v for k, v in info.items() if k == "invocations"}}
    if errors:
        how.append(f"- {len(errors)} run(s) raised an error (status `error` in rows.csv), "
                   f"e.g. `{errors[0]['label']}`: {errors[0]['message']}")
    if unsupported:
        how.append("- Not run (the formulation cannot take the scenario's stack): "
                   + ", ".join(f"`{u}`" for u in unsupported))
    src = plan.config
    cfg_text, cfg_lang, cfg_name = json.dumps(src, indent=2, default=str), "json", "sweep"
    if plan.source and Path(plan.source).is_file():
        cfg_text = Path(plan.source).read_text().rstrip("\n")
        cfg_lang = "json" if plan.source.endswith(".json") else "toml"
        cfg_name = plan.source
    load = (f"{info.get('load_average_start')} when the runs started and "
            f"{info.get('load_average_end')} when they ended")

    def page(img_prefix: str) -> str:
        return _template().substitute(
            title=name, command=command, runs=len(plan.runs), points=plan.points,
            n_variants=len(plan.variants), config_name=cfg_name,
            scenario=plan.scenario, swept_table=_swept_table(plan),
            tip_mm=f"{1e3 * crit['tip_m']:g}", reachable_m=f"{crit['reachable_margin_m']:g}",
            foot_mm=f"{1e3 * crit['support_foot_m']:g}", com_mm=f"{1e3 * crit['com_m']:g}",
            unsupported_note=("" if not unsupported else
                              "Formulations that cannot take the stack are left out: "
                              + ", ".join(f"`{u}`" for u in unsupported) + "."),
            success_table=_success_table(table, labels_shown),
            img_success=img_prefix + pngs["success"].name, img_tip=img_prefix + pngs["tip"].name,
            img_foot=img_prefix + pngs["foot"].name, img_com=img_prefix + pngs["com"].name,
            img_time=img_prefix + pngs["time"].name, workers=info.get("workers", 0),
            cpus=info.get("cpu_count"), load=load,
            time_table=_time_table(judged, labels_shown),
            failures=_failures(judged, labels_shown), how_it_ran="\n".join(how),
            boundary=_boundary(judged, crit["tip_m"]),
            config_lang=cfg_lang, config_text=cfg_text)

    path = out / "report.md"
    path.write_text(page(""))
    if doc is not None:
        doc = Path(doc)
        img = doc.parent / "img"
        img.mkdir(parents=True, exist_ok=True)
        stem = doc.stem
        for key, p in pngs.items():
            target = img / f"{stem}_{p.name}"
            shutil.copyfile(p, target)
            pngs[key] = target
        doc.write_text(page("img/"))
        path = doc
    return path
