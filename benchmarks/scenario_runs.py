"""Running a scenario with every variant of its report: what ``prioik fencing``, ``arm``
and ``sweep`` share.

A run is one :class:`~prioik.benchmarks.variants.Variant` on one scenario variant,
through the scenario interface (:class:`prioik.robots.scenario.Scenario`): the
scenario's :meth:`~prioik.robots.scenario.Scenario.step_builder` gives each step's
stack and errors, a solver prepared once per stack layout solves it
(:func:`prioik.prepare`, the path a control loop runs) and :func:`prioik.robots.simulate`
integrates; an external baseline (:data:`~prioik.benchmarks.variants.BASELINES`) runs
its own loop. Joint limits: bounds for formulations that take inequality tasks,
activation rows for the others, unless the variant says otherwise (``limits``).
Torque-level formulations (``CAPABILITIES.needs_mass_matrix``) get ``M`` and ``b`` and
their own torques; the others' torques come from RNEA.

:func:`run_scenario` runs a selection of the scenario's table and writes, into its
output folder, ``summary.json`` (``{variant: {label: RunSummary}}``),
``run_info.json``, the figures and two replay pages per variant (``<variant>_replay.html``,
link segments; ``<variant>_replay_meshes.html``, the robot's meshes, with the ``view``
extra), and, when asked (``save_runs``, the commands' ``--save-runs``), one trajectory
CSV and one saved run (``.npz``) per run.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import sys
import time
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .results import RunSummary
from .variants import BASELINES, Variant, VariantTable, baseline_profiles, capabilities, table

__all__ = ["VELOCITY_GAIN", "TURN_STEPS", "run_table", "run_one", "run_steps", "in_turns",
           "add_turn_steps_argument", "add_save_runs_argument", "table_legend",
           "summarize", "write_trajectory", "format_table", "ScenarioRuns", "run_scenario",
           "file_stem"]

#: ``K`` (1/s) of the velocity-level runs
VELOCITY_GAIN = 20.0
#: steps each run of :func:`run_scenario` takes per turn (:func:`in_turns`): a turn lasts
#: milliseconds (the G1's 50-100 µs steps) to half a second (the slowest QP runs), so the
#: runs meet the same machine speed, and one step in a hundred starts with the caches the
#: other runs left
TURN_STEPS = 100


def run_table(scenario: str, report: str | None = None) -> VariantTable:
    """The runs of ``scenario``'s report (:func:`prioik.benchmarks.variants.table`; the
    report is the scenario's own unless ``report`` says ``"sweep"``)."""
    return table(report or scenario, scenario=scenario)


def scenario_class(name: str):
    """The :class:`~prioik.robots.scenario.Scenario` class called ``name``."""
    from prioik.robots.scenarios import SCENARIOS
    return SCENARIOS[name]


def file_stem(variant: str, label: str) -> str:
    """``<variant>_<label>`` with the label's brackets and commas as ``_``."""
    return f"{variant}_" + "_".join(p for p in
                                    label.replace("[", "_").replace("]", "").split(",") if p)


# ------------------------------------------------------------------- one run
def _solver(formulation: str, options: dict):
    """``solve(stack, **kw)`` through one prepared solver per stack layout (the joint
    limits' activation rows come and go)."""
    from prioik import formulations
    solvers = {}

    def solve(stack, **kw):
        s = solvers.get(stack.layout)
        if s is None:
            s = solvers[stack.layout] = formulations.prepare(stack.layout, formulation,
                                                             **options)
        return s.solve(stack, **kw)

    return solve


def stack_limits(variant: Variant) -> str:
    """The joint-limit form a variant's stacks hold."""
    caps = capabilities(variant.formulation)
    return variant.limits or ("bounds" if caps is not None and caps.inequalities
                              else "activation")


def run_one(variant: Variant, scenario_variant: str, duration: float, dt: float,
            progress=None, scenario="fencing", algorithmic_error: bool = True,
            velocity_gain: float = VELOCITY_GAIN):
    """Simulate one run; returns a :class:`robots.SimulationResult` with joint names and
    ``info`` (scenario, its variant, the run's label, formulation, options, stack form)
    filled, ready to save and replay (:func:`run_steps` to its end).

    Args:
        variant: The run (:func:`run_table` lists a scenario's).
        scenario_variant: The scenario's variant (``"compatible"``, ``"reach"``, ...).
        scenario: A scenario name (built by :func:`robots.scenarios.make` in
            ``scenario_variant``) or a built :class:`robots.scenario.Scenario` (a
            sweep's, with its own target and gains).
        algorithmic_error: Record eq. 29 at every step (an SVD per level per step).
        velocity_gain: ``K`` of the velocity-level runs.

    Raises:
        UnsupportedTaskError: the formulation cannot take the scenario's stack.
        FormulationError: it is not available here.
    """
    from prioik.robots import run_to_end
    return run_to_end(run_steps(variant, scenario_variant, duration, dt, progress, scenario,
                                algorithmic_error, velocity_gain))


def run_steps(variant: Variant, scenario_variant: str, duration: float, dt: float,
              progress=None, scenario="fencing", algorithmic_error: bool = True,
              velocity_gain: float = VELOCITY_GAIN) -> Generator[int, None, Any]:
    """:func:`run_one` one step at a time: the run set up now (its errors raised here),
    as a generator that yields after each step (outside the timed phases) and returns
    the result (:func:`prioik.robots.simulation_steps`); :func:`run_scenario` advances
    its runs in turns.

    Raises:
        UnsupportedTaskError, FormulationError: as :func:`run_one`.
    """
    from prioik.robots.scenarios import make
    sc = make(scenario, scenario_variant) if isinstance(scenario, str) else scenario
    if variant.armature:
        robot = sc.robot.with_armature(variant.armature)
        if dataclasses.is_dataclass(sc):
            sc = dataclasses.replace(sc, robot=robot)
        else:  # pragma: no cover - every scenario is a dataclass
            sc.robot = robot
    steps = _steps(variant, sc, duration, dt, progress, algorithmic_error, velocity_gain)
    return _labelled(steps, variant, sc, dt, duration)


def _labelled(steps, variant: Variant, scenario, dt: float, duration: float):
    """``steps`` whose result gets the joint names and the run's ``info``."""
    from prioik.robots.simulate import coordinate_names
    res = yield from steps
    res.q_names, res.v_names = coordinate_names(scenario.robot)
    res.info.update({**scenario.info(), **variant.to_dict(), "backend": variant.backend,
                     "dt": dt, "duration": duration})
    return res


def _steps(variant: Variant, scenario, duration: float, dt: float, progress,
           algorithmic_error: bool, velocity_gain: float):
    from prioik.hierarchy import UnsupportedTaskError
    from prioik.robots import simulation_steps
    if variant.external:
        mod = importlib.import_module(BASELINES[variant.formulation])
        return mod.steps(scenario, variant, duration=duration, dt=dt, progress=progress)
    from prioik import formulations
    caps = formulations.get(variant.formulation).capabilities
    limits = stack_limits(variant)
    solve = _solver(variant.formulation, dict(variant.options))
    if variant.level == "velocity":
        if limits not in ("bounds", "hard_bounds") or caps.needs_mass_matrix:
            raise UnsupportedTaskError("velocity-level runs need a formulation that takes "
                                       "inequality tasks (joint limits as bounds on q̇)",
                                       formulation=variant.formulation, task="joint_limits")
        build = scenario.step_builder("velocity", limits, dt, velocity_gain)
        return simulation_steps(scenario.robot, build, solve, duration=duration, dt=dt,
                                level="velocity", progress=progress,
                                algorithmic_error=algorithmic_error)
    build = scenario.step_builder("acceleration", limits, dt)
    dyn = caps.needs_mass_matrix
    return simulation_steps(scenario.robot, build, solve, duration=duration, dt=dt,
                            needs_dynamics=dyn, torque_from_solution=dyn,
                            progress=progress, algorithmic_error=algorithmic_error)


def add_turn_steps_argument(parser) -> None:
    """The ``--turn-steps`` option of the scenario commands (:func:`run_scenario`)."""
    def steps(text: str) -> int:
        value = int(text)
        if value < 0:
            raise ValueError(text)
        return value
    steps.__name__ = "non-negative integer"       # argparse's "invalid … value" message
    parser.add_argument("--turn-steps", type=steps, default=TURN_STEPS, metavar="N",
                        help=f"steps each run takes per turn: a variant's runs advance in "
                             f"turns, so their step times meet the same machine speed (0: "
                             f"one run after another; default {TURN_STEPS})")


def add_save_runs_argument(parser) -> None:
    """The ``--save-runs`` option of the scenario commands (:func:`run_scenario`)."""
    parser.add_argument("--save-runs", action="store_true",
                        help="also write every run's full trajectory: <variant>_<run>.csv "
                             "and the saved run <variant>_<run>.npz (for `prioik replay` "
                             "and `prioik plot`; about 3 MB each for the G1's 3 s runs)")


def in_turns(runs: dict[str, Generator], block: int,
             on_turn: Callable[[int], None] | None = None
             ) -> tuple[dict[str, Any], dict[str, float]]:
    """Advance step generators (:func:`run_steps`) in turns, ``block`` steps of each at a
    time (``0``: each to its end before the next), until every one has ended.

    Runs that follow one another are minutes apart, and a shared machine's speed drifts
    over minutes (the same run's median step varied by 1.5x between runs); runs advanced
    in turns of milliseconds to a fraction of a second meet the same drift, so their
    medians compare.

    Args:
        runs: Label → step generator.
        block: Steps per turn.
        on_turn: Called after each turn with the steps it took (a progress bar).

    Returns:
        ``(results, seconds)``: each run's result and the wall time spent in it.
    """
    results: dict[str, Any] = {}
    seconds = {label: 0.0 for label in runs}
    live = dict(runs)
    while live:
        for label, steps in list(live.items()):
            t0 = time.perf_counter()
            taken = 0
            try:
                while block == 0 or taken < block:
                    next(steps)
                    taken += 1
            except StopIteration as stop:
                results[label] = stop.value
                del live[label]
            seconds[label] += time.perf_counter() - t0
            if on_turn is not None:
                on_turn(taken)
    return {label: results[label] for label in runs}, seconds


def summarize(res, errors: tuple[str, ...]) -> dict[str, Any]:
    """The summary of one run (:class:`~prioik.benchmarks.results.RunSummary`, flat;
    non-finite values are ``None``) with the maxima of the recorded ``errors``."""
    return RunSummary.of(res, errors).to_dict()


def write_trajectory(path: Path, res) -> None:
    """Trajectory of one run as CSV (header line, one row per step); the joint columns
    are named ``q:<joint>``, ``v:<joint>``, ``qdd:<joint>``, ``tau:<joint>``
    (:func:`robots.simulate.coordinate_names`)."""
    cols = ["t"] + list(res.errors) + ["algorithmic_error", "qdd_norm", "kinematics_time_s",
                                       "solve_time_s", "torque_time_s"]
    nq, nv = res.q.shape[1], res.v.shape[1]
    qn = list(res.q_names) if len(res.q_names) == nq else [str(i) for i in range(nq)]
    vn = list(res.v_names) if len(res.v_names) == nv else [str(i) for i in range(nv)]
    cols += [f"q:{n}" for n in qn] + [f"v:{n}" for n in vn]
    cols += [f"qdd:{n}" for n in vn] + [f"tau:{n}" for n in vn]
    tbl = np.column_stack([res.t] + [res.errors[k] for k in res.errors]
                          + [res.algorithmic_error, np.linalg.norm(res.a, axis=1),
                             res.kinematics_time_s, res.solve_time_s, res.torque_time_s,
                             res.q, res.v, res.a, res.tau]) if res.steps else \
        np.zeros((0, len(cols)))
    np.savetxt(path, tbl, delimiter=",", header=",".join(cols), comments="", fmt="%.9g")


# --------------------------------------------------------------- console table
def _short(key: str) -> str:
    name = key.removeprefix("max_")
    for suffix in ("_error_m", "_error_rad", "_violation_rad_s", "_violation_rad", "_m",
                   "_rad"):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


#: the console table's fixed columns: header → meaning
_FIXED_COLUMNS = (("tip final", "the tip's final distance to its target (m)"),
                  ("alg err", "largest algorithmic error along the run (eq. 29; — for "
                              "the external baselines, whose rows are not prioik's)"),
                  ("max|q̈|", "largest ‖q̈‖ (rad/s², m/s² for the base)"),
                  ("kin ms", "median time per step in kinematics (ms)"),
                  ("solve ms", "median time per step in the solver (ms)"),
                  ("tau ms", "median time per step computing torques (ms)"),
                  ("step ms", "median time per control step, everything included (ms)"),
                  ("status", "ok, or FAILED (the run stopped; run_info.json says why)"))


def _unit(key: str) -> str:
    for suffix, unit in (("_violation_rad_s", "rad/s"), ("_violation_rad", "rad"),
                         ("_error_rad", "rad"), ("_error_m", "m"), ("_m", "m"),
                         ("_rad", "rad")):
        if key.endswith(suffix):
            return unit
    return ""


def table_legend(errors: tuple[str, ...]) -> str:
    """What each column of :func:`format_table` means, with its unit."""
    cols = list(_FIXED_COLUMNS[:2]) + [
        (_short(f"max_{e}")[:12], f"largest {_short(e).replace('_', ' ')} "
                                  f"{'violation' if 'violation' in e else 'error'}"
                                  f" along the run ({_unit(e)})")
        for e in errors] + list(_FIXED_COLUMNS[2:])
    width = max(len(h) for h, _ in cols)
    return "columns:\n" + "\n".join(f"  {h:<{width}}  {m}" for h, m in cols)


def format_table(scenario: str, variant: str, runs: dict[str, dict],
                 phases: dict[str, tuple], errors: tuple[str, ...]) -> str:
    """One row per run: the summary numbers (the scenario's summary errors as maxima)
    and the median phase times (the columns: :func:`table_legend`)."""
    keys = [f"max_{e}" for e in errors]
    width = max([26] + [len(lb) + 1 for lb in runs])
    head = (f"{'run':<{width}} {'tip final':>10} {'alg err':>9} "
            + " ".join(f"{_short(k)[:12]:>12}" for k in keys)
            + f" {'max|q̈|':>9} {'kin ms':>7} {'solve ms':>8} {'tau ms':>7} {'step ms':>8}"
              "  status")
    lines = [f"{scenario} — {variant} tasks", head, "-" * len(head)]

    def f(x, w=9):
        return f"{x:>{w}.2e}" if x is not None else f"{'—':>{w}}"

    for label, s in runs.items():
        kin, sol, tau = phases.get(label, (np.nan, np.nan, np.nan))
        step = s["median_step_time_s"]
        lines.append(
            f"{label:<{width}} {f(s['final_tip_error_m'], 10)} "
            f"{f(s['max_algorithmic_error'])} " + " ".join(f(s.get(k), 12) for k in keys)
            + f" {f(s['max_qdd_norm'])} {1e3 * kin:>7.3f} {1e3 * sol:>8.3f} "
              f"{1e3 * tau:>7.3f} {(1e3 * step if step is not None else float('nan')):>8.3f}"
              f"  {'FAILED' if s['failed'] else 'ok'}")
    return "\n".join(lines)


# ------------------------------------------------------------ the whole command
@dataclass
class ScenarioRuns:
    """What :func:`run_scenario` measured and wrote.

    Attributes:
        summary: ``{variant: {label: summary}}`` (``summary.json``).
        meta: ``run_info.json``: the runs and their settings, skipped runs, phases,
            messages of stopped runs, replay pages, the experiment's diagnostics.
        pngs: Figures per variant (``"step_time"``: the step-time figure).
        results: ``{variant: {label: SimulationResult}}``.
    """

    summary: dict[str, dict]
    meta: dict[str, Any]
    pngs: dict[str, list[Path]]
    results: dict[str, dict] = field(default_factory=dict)


def _write_mesh_replay(path: Path, scenario: str, variant: str, results: dict):
    """The variant's page with the robot's meshes (``None`` without the ``view`` extra)."""
    from prioik.extras import missing_distributions
    if missing_distributions("view"):
        print(f"not writing {path.name}: the meshed replay needs the `view` extra",
              file=sys.stderr)
        return None
    from prioik.robots import write_mesh_replay
    from prioik.robots.scenarios import make
    sc = make(scenario, variant)
    return write_mesh_replay(path, sc.robot, results, title=f"{scenario}, {variant}",
                             markers=sc.markers)


def run_scenario(scenario: str, variants: list[str], out, labels: str | None = None,
                 duration: float = 3.0, dt: float = 0.002, progress: bool = True,
                 on_run: Callable[[str, Variant, Any], None] | None = None,
                 on_variant: Callable[[str, dict], None] | None = None,
                 diagnostics: dict[str, Any] | None = None,
                 turn_steps: int = TURN_STEPS, save_runs: bool = False) -> ScenarioRuns:
    """Run the selected runs of ``scenario``'s table on each of its ``variants``: the
    runs of a variant advanced in turns of ``turn_steps`` steps (:func:`in_turns`), so
    the table's step times are measured under the same machine conditions.

    Args:
        labels: Comma-separated run labels (``None``: the table's default selection).
        on_run: Called after each run with ``(scenario variant, run, result)`` (the
            experiment's own checks).
        on_variant: Called after each scenario variant with its results by label.
        diagnostics: The experiment's measurements, stored in ``run_info.json``
            (hooks may add to it).
        turn_steps: Steps per run and turn (``0``: each run to its end before the
            next).
        save_runs: Also write each run's trajectory (``<variant>_<label>.csv``,
            :func:`write_trajectory`) and the saved run (``.npz``,
            :meth:`~prioik.robots.SimulationResult.save`).
    """
    from prioik.benchmarks.plots import scenario_figures, step_time_figure
    from prioik.benchmarks.progress import simulated_time_bar
    from prioik.benchmarks.replay import write_replay
    from prioik.hierarchy import UnsupportedTaskError
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cls = scenario_class(scenario)
    errors = tuple(cls.summary_errors)
    runs_table = run_table(scenario)
    chosen, skipped = runs_table.select(labels)
    for msg in skipped:
        print(f"skipping {msg}", file=sys.stderr)
    summary: dict[str, dict] = {}
    phases: dict[str, dict] = {}
    pngs: dict[str, list[Path]] = {}
    skipped_runs: list[str] = list(skipped)
    messages: dict[str, dict[str, str]] = {}
    replays: dict[str, str] = {}
    mesh_replays: dict[str, str] = {}
    all_results: dict[str, dict] = {}
    diagnostics = {} if diagnostics is None else diagnostics
    wall0 = time.perf_counter()
    for sv in variants:
        summary[sv] = {}
        phases[sv] = {}
        started: dict[str, Generator] = {}
        for v in chosen:
            if not v.runs_in(sv):
                continue
            try:
                started[v.label] = run_steps(v, sv, duration, dt, scenario=scenario)
            except UnsupportedTaskError as exc:
                msg = f"{v.label} ({sv}): cannot take the stack: {exc}"
                print(f"skipping {msg}", file=sys.stderr)
                skipped_runs.append(msg)
        bar, tick = simulated_time_bar(f"[{sv}] {len(started)} runs in turns",
                                       duration * len(started), progress)
        simulated = [0.0]

        def on_turn(steps: int, simulated=simulated, tick=tick) -> None:
            simulated[0] += steps * dt
            tick(simulated[0])

        try:
            results, seconds = in_turns(started, turn_steps,
                                        on_turn if tick is not None else None)
        finally:
            if bar is not None:
                bar.close()
        for v in chosen:
            if v.label not in results:
                continue
            res = results[v.label]
            summary[sv][v.label] = summarize(res, errors)
            phases[sv][v.label] = tuple(
                float(np.median(x)) if res.steps else float("nan")
                for x in (res.kinematics_time_s, res.solve_time_s, res.torque_time_s))
            stem = file_stem(sv, v.label)
            if save_runs:
                write_trajectory(out / f"{stem}.csv", res)
                res.save(out / f"{stem}.npz")
            if res.failed:
                messages.setdefault(sv, {})[v.label] = res.message
            print(f"[{sv}] {v.label}: {res.steps} steps in {seconds[v.label]:.1f} s"
                  f"{' — FAILED: ' + res.message if res.failed else ''}",
                  file=sys.stderr, flush=True)
            if on_run is not None:
                on_run(sv, v, res)
        all_results[sv] = results
        pngs[sv] = scenario_figures(out, sv, results, scenario, cls.tip_label) \
            if results else []
        if results:
            html = write_replay(out / f"{sv}_replay.html", results, title=f"{scenario}, {sv}")
            replays[sv] = html.name
            meshed = _write_mesh_replay(out / f"{sv}_replay_meshes.html", scenario, sv,
                                        results)
            if meshed is not None:
                mesh_replays[sv] = meshed.name
        print(format_table(scenario, sv, summary[sv], phases[sv], errors))
        print()
        if on_variant is not None:
            on_variant(sv, results)
    pngs["step_time"] = [step_time_figure(out, summary, scenario)]
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    meta = {"scenario": scenario, "duration_s": duration, "dt_s": dt, "variants": variants,
            "runs": {v.label: {"formulation": v.formulation, "options": v.options,
                               "note": v.note, "level": v.level,
                               "limits": stack_limits(v) if not v.external else None,
                               "armature": v.armature, "only_in": list(v.only_in),
                               "origin": v.origin} for v in chosen},
            "baselines": baseline_profiles(),
            "skipped": skipped_runs, "phases": phases, "messages": messages,
            "replays": replays, "mesh_replays": mesh_replays, "diagnostics": diagnostics,
            "turn_steps": turn_steps, "saved_runs": save_runs,
            "wall_time_s": time.perf_counter() - wall0}
    (out / "run_info.json").write_text(json.dumps(meta, indent=2, default=str) + "\n")
    print(table_legend(errors))
    print()
    saved = (f", {2 * sum(len(r) for r in all_results.values())} trajectory files "
             "(.csv, .npz)" if save_runs else "")
    print(f"wrote {out / 'summary.json'}, run_info.json, "
          f"{sum(len(v) for v in pngs.values())} plots, "
          f"{len(replays) + len(mesh_replays)} replay page(s)"
          f"{saved} in {time.perf_counter() - wall0:.0f} s"
          + ("" if save_runs else " (--save-runs: every run's trajectory too)"),
          file=sys.stderr)
    return ScenarioRuns(summary, meta, pngs, all_results)
