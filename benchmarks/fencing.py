"""``prioik fencing``: the paper's fencing scenario on the G1 with every formulation.

Runs :class:`robots.fencing.FencingScenario` (variants ``compatible`` and
``incompatible``) with the runs of its report — every available formulation of the
registry (with the settings plugins declare for scenarios), the studies of this
experiment (:data:`STUDIES`) and the external IK libraries, see
:mod:`prioik.benchmarks.variants` — through :func:`benchmarks.scenario_runs.run_scenario`;
prints one table per variant and writes into ``--out``:

* ``summary.json`` — ``{variant: {run: {final_tip_error_m, max_algorithmic_error,
  max_com_error_m, max_support_foot_error_m, max_left_foot_error_m,
  max_joint_limit_violation_rad, max_qdd_norm, median_step_time_s, p90_step_time_s,
  median_solve_time_s, failed}}}`` (:class:`~prioik.benchmarks.results.RunSummary`);
* with ``--save-runs`` only: ``<variant>_<run>.csv`` — the trajectory of each run
  (time, recorded errors, algorithmic error, ``‖q̈‖``, phase times, ``q``, ``q̇``,
  ``q̈``, ``τ``) and ``<variant>_<run>.npz``, the saved run (about 3 MB each);
* ``<variant>_replay.html`` — every run of the variant animated in one page;
* ``<variant>_tip_error.png`` (the paper's Fig. 2 / Fig. 4), ``<variant>_algorithmic_error.png``
  (Fig. 3), ``<variant>_qdd.png`` (acceleration spikes) and ``step_time.png``
  (Sec. III-B.3);
* ``crosscheck.json`` — ``extended_jacobian``'s ``q̈`` against ``cascaded_qp`` on the
  same stacks along its own trajectory;
* in ``run_info.json`` (``headline_timing``), when both runs are selected: the median
  step of ``extended_jacobian`` and of PlaCo's ``KinematicsSolver`` side by side
  (:func:`headline_timing`: the two simulated in alternation, the fastest round of each),
  also marked on ``step_time.png``;
* in ``run_info.json`` (``diagnostics``): each level's projected ``σ_min / ‖A_i‖_F`` at
  the standing posture and along the incompatible ``extended_jacobian`` run, and the
  largest joint-limit row target of ``extended_jacobian[step_bound]``;
* in ``run_info.json`` (``like_for_like``, unless ``--like-for-like-samples 0``): the
  closed-form formulations' median solve times and flop counts on the same G1 stacks,
  side by side (:mod:`benchmarks.like_for_like`), printed as their ratios to the
  extended Jacobian's beside the paper's;

and, with ``--doc PATH``, regenerates the reproduction page (``docs/reproduction.md``,
:mod:`benchmarks.reproduction`) with the measured numbers, copying the plots it shows
to ``img/`` beside it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from .stacks import TIP_STEP_BOUND
from .variants import Variant

#: Armature (kg·m²) of the ``unifying[armature]`` run (``unifying[armature_low]`` shows
#: that 0.02 is not enough; both are measured by the command).
UNIFYING_ARMATURE = 0.1
#: Armature (kg·m²) of the ``unifying[armature_low]`` run, which shows that less is not
#: enough (its divergence time is measured and printed)
UNIFYING_ARMATURE_LOW = 0.02

#: This experiment's own runs beside the registry's (they answer the questions of the
#: reproduction page): settings that name the scenario's tasks or change its robot, and
#: variants of the extended Jacobian for the incompatible case.
STUDIES: tuple[Variant, ...] = (
    Variant("extended_jacobian", "step_bound", {"step_bound": {"sword_tip": TIP_STEP_BOUND}},
            "prioik's own variant, not the paper's: the sword-tip level's step is bounded "
            f"(trust-region damping, ‖Δq̈_tip‖ ≤ {TIP_STEP_BOUND:g} rad/s²); every higher "
            "level stays exact", only_in=("incompatible",), origin="study"),
    Variant("extended_jacobian", "step_bound_all", {"step_bound": TIP_STEP_BOUND},
            f"prioik's own variant: every level's step bounded by {TIP_STEP_BOUND:g} "
            "(the joint-limit rows included)", only_in=("incompatible",), origin="study"),
    Variant("extended_jacobian", "selective",
            {"level_damping": 0.1, "singular_threshold": 0.05},
            "prioik's own variant: any level whose projected σ_min < 0.05·‖A_i‖_F is "
            "damped (μ² ≤ 0.1)", only_in=("incompatible",), origin="study"),
    Variant("unifying", "armature", {},
            f"the same with {UNIFYING_ARMATURE:g} kg·m² of rotor inertia on every actuated "
            "joint (cond(M) measured below)", armature=UNIFYING_ARMATURE, origin="study"),
    Variant("unifying", "armature_low", {},
            f"the same with {UNIFYING_ARMATURE_LOW:g} kg·m² of rotor inertia",
            armature=UNIFYING_ARMATURE_LOW, only_in=("compatible",), origin="study"),
)

#: runs whose ``q̈`` is cross-checked against ``cascaded_qp`` with the same per-level
#: Tikhonov terms (``sol.detail.level_damping``), and in which variants
CROSSCHECK_RUNS = {"extended_jacobian": ("compatible",),
                   "extended_jacobian[step_bound]": ("incompatible",),
                   "extended_jacobian[eq27]": ("compatible", "incompatible")}


# ---------------------------------------------------------- cross-check
def crosscheck(variant: str, res, dt: float, every: int = 25,
               run_options: dict | None = None) -> dict[str, Any] | None:
    """``extended_jacobian`` against ``cascaded_qp`` on the same stacks.

    Along the recorded trajectory of an ``extended_jacobian`` run, every ``every``
    steps the activation-form stack is rebuilt and solved by ``extended_jacobian``
    with the run's options and by ``cascaded_qp`` (DAQP) given the same per-level
    Tikhonov terms (``level_damping`` = the extended Jacobian's
    ``sol.detail.level_damping``, zero where a level was solved exactly): the two must
    give the same whole ``q̈`` (``‖Δq̈‖ / max(1, ‖q̈‖)``), damped or not. ``None`` when
    ``cascaded_qp`` is not available.
    """
    from prioik import formulations
    from prioik.robots import KinematicState
    from prioik.robots.fencing import FencingScenario
    try:
        formulations.get("cascaded_qp")
    except formulations.FormulationError:
        return None
    scenario = FencingScenario(variant)
    exact, damped_diff, damped_names = [], [], []
    for k in range(0, res.steps, every):
        state = KinematicState(scenario.robot, res.q[k], res.v[k])
        stack = scenario.acceleration_stack(state, float(res.t[k]), "activation", dt).stack
        a = formulations.solve(stack, "extended_jacobian", **(run_options or {}))
        mu2 = a.detail.level_damping
        b = formulations.solve(stack, "cascaded_qp", solver="daqp", level_damping=mu2)
        if not (a.ok and b.ok):
            continue
        diff = float(np.linalg.norm(a.x - b.x) / max(1.0, np.linalg.norm(b.x)))
        damped = a.detail.damped_levels or []
        if damped:
            damped_diff.append(diff)
            damped_names += [stack.levels[i].names[0] for i in damped]
        else:
            exact.append(diff)
    names = sorted(set(damped_names))
    return {"steps_compared": len(exact) + len(damped_diff),
            "steps_with_damping": len(damped_diff),
            "damped_levels": {n: damped_names.count(n) for n in names},
            "max_rel_diff_qdd_undamped_steps": max(exact) if exact else None,
            "max_rel_diff_qdd_damped_steps": max(damped_diff) if damped_diff else None}


def crosscheck_table(checks: dict[str, dict[str, dict]]) -> str:
    """The :func:`crosscheck` results as a labelled table (crosscheck.json holds them):
    per variant and run, the steps compared and the largest relative ``q̈`` difference
    on the steps where no level was damped and on those where one was."""
    if not checks:
        return ""
    lines = ["cross-check: the run's q̈ against cascaded_qp (DAQP, same per-level damping) "
             "on the same stacks, ‖Δq̈‖ / max(1, ‖q̈‖)",
             f"  {'variant':<13} {'run':<30} {'steps':>5} {'damped':>6} "
             f"{'undamped steps':>14} {'damped steps':>12}"]

    def f(x):
        return f"{x:.1e}" if x is not None else "—"

    for variant, by_label in checks.items():
        for label, c in by_label.items():
            lines.append(f"  {variant:<13} {label:<30} {c['steps_compared']:>5} "
                         f"{c['steps_with_damping']:>6} "
                         f"{f(c['max_rel_diff_qdd_undamped_steps']):>14} "
                         f"{f(c['max_rel_diff_qdd_damped_steps']):>12}")
    return "\n".join(lines)


def unifying_diagnostic(dt: float = 0.002) -> dict[str, float] | None:
    """Why ``unifying`` misbehaves on the G1: at the standing posture (``q̇ = 0``,
    ``t = 5 dt``), ``‖q̈‖`` of ``unifying`` with the G1's ``M``, with ``M = I`` (Chiaverini's method
    for two levels only: beyond, eq. 40 projects with ``Π (I − J_j⁺ J_j)`` instead of
    ``N^A_{i-1}``), and of ``extended_jacobian``; ``cond(M)`` without armature and with
    the armature of the ``unifying[armature*]`` runs.
    ``None`` when ``unifying`` is not available."""
    import pinocchio as pin

    from prioik import formulations
    from prioik.robots import KinematicState
    from prioik.robots.fencing import FencingScenario
    try:
        formulations.get("unifying")
    except formulations.FormulationError:
        return None
    sc = FencingScenario("compatible")
    r = sc.robot

    def cond_mass(robot) -> float:
        M = pin.crba(robot.model, robot.data(), robot.q0)
        M = np.triu(M) + np.triu(M, 1).T
        w = np.linalg.eigvalsh(M)
        return float(w[-1] / w[0])

    M = pin.crba(r.model, r.data(), r.q0)
    M = np.triu(M) + np.triu(M, 1).T
    state = KinematicState(r, r.q0, np.zeros(r.nv))
    stack = sc.acceleration_stack(state, 5 * dt, "activation", dt).stack
    return {"cond_M": cond_mass(r),
            "cond_M_armature": {f"{a:g}": cond_mass(r.with_armature(a))
                                for a in (UNIFYING_ARMATURE_LOW, UNIFYING_ARMATURE)},
            "qdd_unifying": float(np.linalg.norm(
                formulations.solve(stack, "unifying", mass_matrix=M).x)),
            "qdd_unifying_identity_M": float(np.linalg.norm(
                formulations.solve(stack, "unifying", mass_matrix=np.eye(r.nv)).x)),
            "qdd_extended_jacobian": float(np.linalg.norm(
                formulations.solve(stack, "extended_jacobian").x))}


def projected_sigmas(stack) -> dict[str, float]:
    """Each level's distance to an algorithmic singularity relative to its own scale:
    ``σ_min(A_i Z_i) / ‖A_i‖_F`` (:func:`hierarchy.singularity_distance`; 0 when the
    level has no direction left), by the level's first task name."""
    from prioik.hierarchy import singularity_distance
    out = {}
    for level, sigma in zip(stack.levels, singularity_distance(stack), strict=False):
        scale = float(np.linalg.norm(level.A))
        out[level.names[0]] = sigma / scale if scale > 0 else 0.0
    return out


def standing_sigmas(dt: float = 0.002) -> dict[str, float]:
    """:func:`projected_sigmas` of the incompatible scenario's stack at the standing
    posture (``q̇ = 0``, ``t = 5 dt``): what the selective damping's trigger sees
    before anything moves."""
    from prioik.robots import KinematicState
    from prioik.robots.fencing import FencingScenario
    sc = FencingScenario("incompatible")
    state = KinematicState(sc.robot, sc.robot.q0, np.zeros(sc.robot.nv))
    return projected_sigmas(sc.acceleration_stack(state, 5 * dt, "activation", dt).stack)


def sigma_trace(variant: str, res, dt: float, samples: int = 8, last: int = 6
                ) -> list[dict[str, float]]:
    """Projected ``σ_min / ‖A_i‖_F`` along a recorded run — the sword tip's, and the
    smallest over the task levels (posture left out) with its name — beside ``‖q̈‖``,
    the number of joint-limit rows and their largest target ``|h|``: at ``samples``
    evenly spaced steps and at the ``last`` steps before it stopped (the rebuilt
    activation-form stacks of the recorded states)."""
    from prioik.robots import KinematicState
    from prioik.robots.fencing import FencingScenario
    if res.steps == 0:
        return []
    sc = FencingScenario(variant)
    picks = sorted(set(np.linspace(0, res.steps - 1, samples).astype(int).tolist()
                       + list(range(max(0, res.steps - last), res.steps))))
    rows = []
    for k in picks:
        state = KinematicState(sc.robot, res.q[k], res.v[k])
        stack = sc.acceleration_stack(state, float(res.t[k]), "activation", dt).stack
        sig = projected_sigmas(stack)
        owned = {name: v for name, v in sig.items() if v > 0 and name != "posture"}
        low = min(owned, key=owned.get) if owned else ""
        jl = [lv for lv in stack.levels if "joint_limits" in lv.names]
        rows.append({"t": float(res.t[k]), "sigma_tip": sig.get("sword_tip", 0.0),
                     "lowest_level": low, "sigma_lowest": owned.get(low, 0.0),
                     "qdd_norm": float(np.linalg.norm(res.a[k])),
                     "limit_rows": int(jl[0].m) if jl else 0,
                     "limit_target": float(np.abs(jl[0].b).max()) if jl else 0.0})
    return rows


def max_limit_target(variant: str, res, dt: float, every: int = 25) -> float:
    """The largest ``|h|`` of the joint-limit activation rows (rad/s²) along a recorded
    run (every ``every`` steps): the push-back a per-level step bound would cap."""
    from prioik.robots import KinematicState
    from prioik.robots.fencing import FencingScenario
    sc = FencingScenario(variant)
    top = 0.0
    for k in range(0, res.steps, every):
        state = KinematicState(sc.robot, res.q[k], res.v[k])
        stack = sc.acceleration_stack(state, float(res.t[k]), "activation", dt).stack
        for level in stack.levels:
            if "joint_limits" in level.names:
                top = max(top, float(np.abs(level.b).max()))
    return top


# ------------------------------------------------------------------ command
#: the two runs compared side by side (:func:`headline_timing`)
HEADLINE = ("extended_jacobian", "placo_kinematics_solver")
#: rounds of :func:`headline_timing`
HEADLINE_ROUNDS = 5
#: states per variant of the like-for-like measurement (``--like-for-like-samples``)
LIKE_FOR_LIKE_SAMPLES = 16


def headline_timing(variant: str, duration: float, dt: float,
                    rounds: int = HEADLINE_ROUNDS) -> dict[str, Any]:
    """The median step of the :data:`HEADLINE` runs measured side by side: each simulated
    ``rounds`` times, the two in alternation (timing only: no algorithmic error), the
    fastest round of each and their ratio. The table's runs advance in turns
    (:func:`~prioik.benchmarks.scenario_runs.in_turns`) beside every other run of the
    table; here the two run alone, each one's fastest round kept, which a machine whose
    speed drifts over minutes (the same run's median step varied by 1.5x between runs
    on a shared 2-core machine) slows least."""
    from .scenario_runs import run_one, run_table
    table = run_table("fencing")
    steps: dict[str, list[float]] = {label: [] for label in HEADLINE}
    for _ in range(rounds):
        for label in HEADLINE:
            res = run_one(table[label], variant, duration, dt, algorithmic_error=False)
            steps[label].append(float(np.median(res.step_time_s)))
    best = {label: min(v) for label, v in steps.items()}
    return {"rounds": rounds, "median_step_s": steps, "best_median_step_s": best,
            "ratio": best[HEADLINE[0]] / best[HEADLINE[1]]}


def like_for_like_table(lfl: dict[str, Any]) -> str:
    """:func:`benchmarks.like_for_like.measure_fencing`'s result as a labelled table of
    ratios to the extended Jacobian's (the reproduction page's, in plain text)."""
    from .like_for_like import ratio_rows

    def f(x, spec=".2f"):
        return "—" if x is None else format(x, spec)

    lines = [f"like for like: median solve on {lfl['stacks']} G1 stacks (n = {lfl['n']}), "
             f"{lfl['repeats']} solves each, ratios to extended_jacobian",
             f"  {'formulation':<18} {'paper':>6} {'kernel':>7} {'solve µs':>9} "
             f"{'time':>6} {'flops':>8} {'flops×':>7} {'rate×':>6}"]
    for r in ratio_rows(lfl["measured"]):
        lines.append(f"  {r['formulation']:<18} {f(r['paper_ratio']):>6} "
                     f"{'C++' if r['compiled'] else 'numpy':>7} {1e6 * r['time_s']:>9.1f} "
                     f"{f(r['time_ratio']):>6} {f(r['flops'], '.3g'):>8} "
                     f"{f(r['flop_ratio']):>7} {f(r['rate_ratio']):>6}")
    return "\n".join(lines)


def run_command(args: argparse.Namespace) -> int:
    """``prioik fencing``: see the module docstring."""
    from .reproduction import write_page
    from .scenario_runs import VELOCITY_GAIN, run_scenario, run_table
    variants = ["compatible", "incompatible"] if args.variant == "both" else [args.variant]
    if args.like_for_like_samples < 0:
        raise ValueError(f"--like-for-like-samples must be ≥ 0, got "
                         f"{args.like_for_like_samples}")
    run_table("fencing").select(args.formulations)     # an unknown label: fail before anything
    diagnostics: dict[str, Any] = {"standing_sigmas": standing_sigmas(args.dt)}
    checks: dict[str, Any] = {}

    def on_run(variant: str, run: Variant, res) -> None:
        if variant in CROSSCHECK_RUNS.get(run.label, ()) and not args.no_crosscheck:
            c = crosscheck(variant, res, args.dt, run_options=run.options)
            if c is not None:
                checks.setdefault(variant, {})[run.label] = c

    def on_variant(variant: str, results: dict) -> None:
        if variant != "incompatible":
            return
        if "extended_jacobian" in results:
            diagnostics["sigma_trace"] = sigma_trace(variant, results["extended_jacobian"],
                                                     args.dt)
        if "extended_jacobian[step_bound]" in results:
            diagnostics["max_limit_target"] = max_limit_target(
                variant, results["extended_jacobian[step_bound]"], args.dt)

    runs = run_scenario("fencing", variants, args.out, args.formulations, args.duration,
                        args.dt, args.progress, on_run, on_variant, diagnostics,
                        args.turn_steps, args.save_runs)
    meta = runs.meta
    meta["crosscheck"] = checks
    ran = {label for by_label in runs.summary.values() for label in by_label}
    if all(label in ran for label in HEADLINE) and args.headline_rounds > 0:
        meta["headline_timing"] = {}
        for variant in variants:
            h = headline_timing(variant, args.duration, args.dt, args.headline_rounds)
            meta["headline_timing"][variant] = h
            b = h["best_median_step_s"]
            print(f"median step time side by side [{variant}] ({h['rounds']} alternating "
                  f"rounds, the fastest of each): {HEADLINE[0]} {1e3 * b[HEADLINE[0]]:.3f} ms, "
                  f"{HEADLINE[1]} {1e3 * b[HEADLINE[1]]:.3f} ms, ratio {h['ratio']:.2f}")
        # the chart again, with the side-by-side medians marked on it
        from .plots import step_time_figure
        step_time_figure(args.out, runs.summary, "fencing", meta["headline_timing"])
    if args.like_for_like_samples > 0:
        from .like_for_like import measure_fencing
        meta["like_for_like"] = measure_fencing(variants, args.like_for_like_samples)
        print(like_for_like_table(meta["like_for_like"]))
    meta["unifying_diagnostic"] = (unifying_diagnostic(args.dt)
                                   if any(r["formulation"] == "unifying"
                                          for r in meta["runs"].values()) else None)
    out = Path(args.out)
    (out / "crosscheck.json").write_text(json.dumps(checks, indent=2) + "\n")
    (out / "run_info.json").write_text(json.dumps(meta, indent=2, default=str) + "\n")
    if meta["unifying_diagnostic"]:
        ud = meta["unifying_diagnostic"]
        print(f"unifying: cond(M) of the G1 at the standing posture {ud['cond_M']:.3g} "
              "(no rotor inertia); "
              + ", ".join(f"{v:.3g} ({a} kg·m² armature)"
                          for a, v in ud["cond_M_armature"].items()))
    print(crosscheck_table(checks))
    if args.doc:
        command = (f"prioik fencing --variant {args.variant} --duration {args.duration:g} "
                   f"--dt {args.dt:g} --doc {Path(args.doc).as_posix()}")
        path = write_page(Path(args.doc), runs.summary, meta, runs.pngs, command,
                          VELOCITY_GAIN)
        print(f"wrote {path}", file=sys.stderr)
    return 0


def add_parser(subparsers) -> None:
    """Register ``prioik fencing``."""
    from .scenario_runs import add_save_runs_argument, add_turn_steps_argument
    p = subparsers.add_parser(
        "fencing", help="the paper's fencing scenario on the G1, every formulation",
        description="Simulate the fencing scenario (Jeong & Chang 2009, Sec. III) on the "
                    "Unitree G1 with each formulation and the PlaCo, pink, mink and TSID "
                    "baselines (TSID in its own environment, `make tsid`, and process; not "
                    "installed, it is left out); print a summary table per variant, write "
                    "summary.json, run_info.json, plots and replay pages (every run's "
                    "trajectory too with --save-runs).")
    p.add_argument("--variant", choices=["compatible", "incompatible", "both"],
                   default="both")
    p.add_argument("--formulations", default=None, metavar="A,B,...",
                   help="run labels, e.g. extended_jacobian,cascaded_qp[daqp] (default: "
                        "every run of the scenario's table whose formulation is available; "
                        "an unknown label is an error that lists the known ones)")
    p.add_argument("--duration", type=float, default=3.0, help="simulated seconds")
    p.add_argument("--dt", type=float, default=0.002, help="control step (s)")
    p.add_argument("--out", default="results", help="output folder")
    p.add_argument("--doc", default=None, metavar="PATH",
                   help="also (re)generate the reproduction page here "
                        "(e.g. docs/reproduction.md; plots copied to img/ beside it)")
    p.add_argument("--headline-rounds", type=int, default=HEADLINE_ROUNDS,
                   help="rounds of the side-by-side timing of extended_jacobian and PlaCo's "
                        "KinematicsSolver (alternating, the fastest of each; 0: skip)")
    p.add_argument("--like-for-like-samples", type=int, default=LIKE_FOR_LIKE_SAMPLES,
                   metavar="N",
                   help="states per variant of the side-by-side timing and flop count of "
                        "the closed-form formulations on the same G1 stacks (ratios to "
                        "the extended Jacobian's beside the paper's; 0: skip)")
    add_turn_steps_argument(p)
    add_save_runs_argument(p)
    p.add_argument("--no-crosscheck", action="store_true",
                   help="skip the extended_jacobian vs cascaded_qp q̈ comparison")
    p.add_argument("--quiet", dest="progress", action="store_false",
                   help="no progress bars on stderr")
    p.set_defaults(func=run_command, extras=("robots", "plots"))
