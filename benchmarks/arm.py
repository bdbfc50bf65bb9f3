"""``prioik arm``: the arm-reach scenario (Panda) with every formulation, PlaCo, pink, mink,
TSID and SNS.

Runs :class:`robots.arm.ArmScenario` through the same machinery as ``prioik fencing``
(:func:`benchmarks.scenario_runs.run_scenario`: the shared scenario interface, the same
summary, CSVs, saved runs, plots and replay page) with the runs of its report (every
available formulation of the registry with the settings plugins declare for ``arm``,
and the external IK libraries; :mod:`prioik.benchmarks.variants`), and with
``--doc PATH`` writes the scenario's page (``docs/arm.md``) from the measured numbers
(``templates/arm.md``), copying its plots to ``img/`` beside it, with — when the TSID
environment is there — the acceleration-level step of TSID and prioik side by side
(:mod:`prioik.benchmarks.tsid_step`). The joint limits are
the first level here (no contact above them), so the QP formulations and SNS receive
the same stack.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .report import (
    Page,
    baselines_block,
    copy_figures,
    ms,
    replays_line,
    run_settings,
    sci,
    step_time_figure,
    stops_and_figures,
    table,
)
from .variants import Variant

VARIANTS = ("reach",)
#: this experiment's own runs beside the registry's (none: every setting it runs is a
#: plugin's declaration for the ``arm`` report)
STUDIES: tuple[Variant, ...] = ()


def write_page(path: Path, summary: dict, meta: dict, pngs: dict, command: str,
               gain: float, tsid_step: dict | None = None) -> Path:
    """The arm scenario's page from measured numbers; plots copied to ``img/``.
    ``tsid_step``: :func:`prioik.benchmarks.tsid_step.run`'s result (its section is
    left out without it)."""
    path = Path(path)
    page = Page("arm.md")
    shown = copy_figures(pngs, path, "arm")
    variants = list(summary)
    rows = []
    for label, r in meta["runs"].items():
        opts, stack, _ = run_settings(r, variants)
        rows.append([f"`{label}`", f"`{r['formulation']}`", opts, stack, r["note"]])
    head = ["run", "final tool error", "max algorithmic error", "max orientation error",
            "max joint-limit violation", "max velocity-limit violation", "max ‖q̈‖",
            "median step", "median solve", "median verify", "status"]
    measured = []
    for variant, runs in summary.items():
        body = [[f"`{label}`", "—" if s["final_tip_error_m"] is None
                 else f"{1e3 * s['final_tip_error_m']:.3g} mm",
                 sci(s["max_algorithmic_error"]),
                 f"{sci(s.get('max_orientation_error_rad'))} rad",
                 f"{sci(s.get('max_joint_limit_violation_rad'))} rad",
                 f"{sci(s.get('max_joint_velocity_violation_rad_s'))} rad/s",
                 sci(s["max_qdd_norm"], ".3g"), ms(s["median_step_time_s"]),
                 ms(s["median_solve_time_s"]), ms(s.get("median_verify_time_s")),
                 "failed" if s["failed"] else "ran to the end"]
                for label, s in runs.items()]
        figures = [(key, page.inline(f"{key}_figure"))
                   for key in ("tip_error", "algorithmic_error", "qdd")]
        measured.append(page.block("measured", table=table(head, body),
                                   after=stops_and_figures(meta, variant, shown, figures)))
    text = page.render(
        command=command, wall_s=f"{meta['wall_time_s']:.0f}", gain=f"{gain:g}",
        runs_table=table(["run", "formulation", "options", "stack", "why"], rows),
        baselines=baselines_block(page, meta, summary),
        not_run=(page.block("not_run", skipped="; ".join(meta["skipped"]))
                 if meta.get("skipped") else ""),
        measured="\n\n".join(measured), step_time=step_time_figure(shown),
        tsid_step=_tsid_step_block(page, tsid_step),
        replays=replays_line(meta))
    path.write_text(text)
    return path


def _tsid_step_block(page: Page, result: dict | None) -> str:
    if not result:
        return ""
    from .tsid_step import DT, format_table
    return page.block("tsid_step", steps=result["steps"], rounds=result["rounds"],
                      seconds=f"{result['steps'] * DT:g}", table=format_table(result))


def run_command(args: argparse.Namespace) -> int:
    """``prioik arm``."""
    from .scenario_runs import VELOCITY_GAIN, run_scenario
    runs = run_scenario("arm", list(VARIANTS), args.out, args.formulations, args.duration,
                        args.dt, args.progress, turn_steps=args.turn_steps,
                        save_runs=args.save_runs)
    if args.doc:
        command = (f"prioik arm --duration {args.duration:g} --dt {args.dt:g} "
                   f"--out {args.out} --doc {args.doc}")
        step = None
        from . import tsid_baseline
        if tsid_baseline.unavailable_reason() is None:
            from . import tsid_step
            step = tsid_step.run()
            print(tsid_step.format_table(step))
        p = write_page(Path(args.doc), runs.summary, runs.meta, runs.pngs, command,
                       VELOCITY_GAIN, tsid_step=step)
        print(f"wrote {p}", file=sys.stderr)
    return 0


def add_parser(subparsers) -> None:
    """Register ``prioik arm``."""
    from .scenario_runs import add_save_runs_argument, add_turn_steps_argument
    p = subparsers.add_parser(
        "arm", help="the arm-reach scenario (Panda, one target out of reach), every "
                    "formulation, PlaCo, pink, mink, TSID and SNS",
        description="Simulate the Panda reaching four targets (one out of reach) under "
                    "joint limits with each formulation and the PlaCo, pink, mink and "
                    "TSID baselines (TSID in its own environment, `make tsid`, and process; "
                    "not installed, it is left out); print a table, write summary.json, "
                    "plots and a replay page into --out (every run's trajectory too with "
                    "--save-runs).")
    p.add_argument("--formulations", default=None, metavar="A,B,...",
                   help="run labels, e.g. extended_jacobian,cascaded_qp[quadprog] (default: "
                        "every run of the scenario's table whose formulation is available; "
                        "an unknown label is an error that lists the known ones)")
    p.add_argument("--duration", type=float, default=6.0, help="simulated seconds")
    p.add_argument("--dt", type=float, default=0.002, help="control step (s)")
    p.add_argument("--out", default="results/arm", help="output folder")
    p.add_argument("--doc", default=None, metavar="PATH",
                   help="also write the scenario page here (e.g. docs/arm.md; plots copied "
                        "to img/ beside it; with the TSID environment, also measures TSID's "
                        "and prioik's acceleration-level step side by side)")
    add_turn_steps_argument(p)
    add_save_runs_argument(p)
    p.add_argument("--quiet", dest="progress", action="store_false",
                   help="no progress bars on stderr")
    p.set_defaults(func=run_command, extras=("robots", "plots"))
