"""``prioik fencing``: the paper's fencing scenario on the G1 with every formulation.

Runs :class:`robots.fencing.FencingScenario` (variants ``compatible`` and
``incompatible``) with each selected formulation through :func:`robots.simulate`,
prints one table per variant and writes into ``--out``:

* ``summary.json`` — ``{variant: {run: {final_tip_error_m, max_algorithmic_error,
  max_com_error_m, max_support_foot_error_m, max_joint_limit_violation_rad,
  max_qdd_norm, median_step_time_s, median_solve_time_s, failed}}}``;
* ``<variant>_<run>.csv`` — the trajectory of each run (time, recorded errors,
  algorithmic error, ``‖q̈‖``, phase times, ``q``, ``q̇``, ``q̈``, ``τ``);
* ``<variant>_tip_error.png`` (the paper's Fig. 2 / Fig. 4), ``<variant>_algorithmic_error.png``
  (Fig. 3), ``<variant>_qdd.png`` (acceleration spikes) and ``step_time.png``
  (Sec. III-B.3);
* ``crosscheck.json`` — ``extended_jacobian``'s ``q̈`` against ``cascaded_qp`` on the
  same stacks along its own trajectory;

and, with ``--doc PATH``, regenerates the reproduction page (``docs/reproduction.md``)
with the measured numbers, copying the plots it shows to ``img/`` beside it.

Stacks: formulations that take inequality tasks (QP formulations) get joint limits as
bounds on ``q̈`` (:func:`robots.tasks.joint_limit_bounds`); the others get the
activation rows (:func:`robots.tasks.joint_limit_rows`). Torque-level formulations
(``CAPABILITIES.needs_mass_matrix``) get ``M`` and ``b`` and their own torques;
the others' torques come from RNEA.

Runs and their options per variant are in :data:`RUNS`, the one table of
per-scenario settings; see its comments for why each option is there.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: the keys of one run in summary.json, in order
SUMMARY_KEYS = ("final_tip_error_m", "max_algorithmic_error", "max_com_error_m",
                "max_support_foot_error_m", "max_left_foot_error_m",
                "max_joint_limit_violation_rad", "max_qdd_norm",
                "median_step_time_s", "median_solve_time_s", "failed")


@dataclass(frozen=True)
class RunSpec:
    """One row of the comparison.

    Attributes:
        label: Row name (``formulation`` or ``formulation:variant``).
        formulation: Registry name; ``"placo_kinematics_solver"`` is PlaCo's own
            ``KinematicsSolver`` (``benchmarks/placo_baseline.py``).
        options: Scenario variant → options passed to ``formulations.solve``.
        note: Why these options (printed in the reproduction page).
        default: Part of the default selection.
        variants: The scenario variants it is run in.
        level: ``"acceleration"`` (the paper's stacks) or ``"velocity"`` (the same
            tasks as ``J q̇ = ẋ* + K e``, ``K = VELOCITY_GAIN``, joint limits as
            bounds on ``q̇``; QP formulations only).
        armature: Rotor inertia (kg·m²) added to every actuated joint's diagonal of
            ``M(q)`` (pinocchio's ``model.armature``, on a copy of the model; the
            URDF has none). Only formulations that use ``M`` see it.
        limits: The joint-limit form of the stack (``"activation"``, ``"bounds"``,
            ``"hard_bounds"``); default: bounds for formulations that take inequality
            tasks, activation rows for the others.
        backend: QP back-end of the ``"pink"`` baseline (qpsolvers name).
    """

    label: str
    formulation: str
    options: dict[str, dict[str, Any]] = field(default_factory=dict)
    note: str = ""
    default: bool = True
    variants: tuple[str, ...] = ("compatible", "incompatible")
    level: str = "acceleration"
    armature: float = 0.0
    limits: str | None = None
    backend: str = ""


#: the runs that are external libraries, not registry formulations
EXTERNAL = ("placo_kinematics_solver", "pink")
#: ``K`` (1/s) of the velocity-level runs
VELOCITY_GAIN = 20.0


#: Bound (rad/s²) on the sword-tip level's step in the incompatible ``extended_jacobian``
#: run (its ``step_bound``). Measured over 3 s (max ‖q̈‖ / final tip error): Δ = 5:
#: 76 / 385 mm, 10: 55 / 382 mm, 20: 142 / 375 mm; support foot, CoM and joint limits
#: exact in all three. Bounding every level instead also caps the joint-limit rows
#: (targets of hundreds of rad/s²) and lets joints pass their limits by 0.3 rad.
TIP_STEP_BOUND = 10.0
#: ``λ`` of the ``nullspace:damped`` run: 1e-2 left q̈ peaks of 355 in the incompatible
#: run, 0.05 keeps them at 65.
NULLSPACE_DAMPING = 0.05

#: Armature (kg·m²) of the ``unifying:armature`` run (``unifying:armature_low`` shows
#: that 0.02 is not enough; both are measured by the command).
UNIFYING_ARMATURE = 0.1

#: ``λ`` of the eq. 27 runs
EQ27_DAMPING = 1e-2
#: Armature (kg·m²) of the ``unifying:armature_low`` run, which shows that less is
#: not enough (its divergence time is measured and printed)
UNIFYING_ARMATURE_LOW = 0.02

#: The per-scenario option table (one row per run).
RUNS: tuple[RunSpec, ...] = (
    RunSpec("extended_jacobian", "extended_jacobian", {"compatible": {}, "incompatible": {}},
            "the paper's eq. 18 as printed: exact, no damping"),
    RunSpec("extended_jacobian:step_bound", "extended_jacobian",
            {"incompatible": {"step_bound": {"sword_tip": TIP_STEP_BOUND}}},
            "prioik's own variant, not the paper's: the sword-tip level's step is bounded "
            f"(trust-region damping, ‖Δq̈_tip‖ ≤ {TIP_STEP_BOUND:g} rad/s²); every higher "
            "level stays exact", variants=("incompatible",)),
    RunSpec("extended_jacobian:step_bound_all", "extended_jacobian",
            {"incompatible": {"step_bound": TIP_STEP_BOUND}},
            f"prioik's own variant: every level's step bounded by {TIP_STEP_BOUND:g} "
            "(the joint-limit rows included)", variants=("incompatible",)),
    RunSpec("extended_jacobian:selective", "extended_jacobian",
            {"incompatible": {"level_damping": 0.1, "singular_threshold": 0.05}},
            "prioik's own variant: any level whose projected σ_min < 0.05·‖A_i‖_F is "
            "damped (μ² ≤ 0.1)", variants=("incompatible",)),
    RunSpec("extended_jacobian:eq27", "extended_jacobian",
            {"compatible": {"damping": EQ27_DAMPING}, "incompatible": {"damping": EQ27_DAMPING}},
            f"the paper's eq. 27, λ = {EQ27_DAMPING:g}, with Z_i of r_i rows spanning "
            "range(N_{i-1} J_iᵀ) (`z_basis='task_range'`, eq. 12-13 and Theorem 1)"),
    RunSpec("extended_jacobian:eq27_null_space", "extended_jacobian",
            {"compatible": {"damping": EQ27_DAMPING, "z_basis": "null_space"},
             "incompatible": {"damping": EQ27_DAMPING, "z_basis": "null_space"}},
            f"eq. 27, λ = {EQ27_DAMPING:g}, read with a basis of the whole null space of the "
            "higher levels (`z_basis='null_space'`; prioik's reading before issue 17)"),
    RunSpec("nullspace", "nullspace", {},
            "resolved acceleration, recursive null-space projection, λ = 0 (the paper's "
            "'resolved acceleration method')"),
    RunSpec("nullspace:damped", "nullspace",
            {"compatible": {"damping": NULLSPACE_DAMPING},
             "incompatible": {"damping": NULLSPACE_DAMPING}},
            f"the same with the SR (damped least-squares) inverse on every level, "
            f"λ = {NULLSPACE_DAMPING:g}"),
    RunSpec("chiaverini", "chiaverini", {}, "Chiaverini's singularity-robust priority"),
    RunSpec("unifying", "unifying", {}, "unifying framework, torques from eq. 40"),
    RunSpec("unifying:armature", "unifying", {},
            f"the same with {UNIFYING_ARMATURE:g} kg·m² of rotor inertia on every actuated "
            "joint (cond(M) measured below)", armature=UNIFYING_ARMATURE),
    RunSpec("unifying:armature_low", "unifying", {},
            f"the same with {UNIFYING_ARMATURE_LOW:g} kg·m² of rotor inertia",
            armature=UNIFYING_ARMATURE_LOW, variants=("compatible",)),
    RunSpec("operational_space", "operational_space", {},
            "prioritized operational-space control, its own torques"),
    RunSpec("cascaded_qp", "cascaded_qp", {"compatible": {"solver": "daqp"},
                                           "incompatible": {"solver": "daqp"}},
            "one QP per level (DAQP back-end), joint limits as bounds on q̈"),
    RunSpec("cascaded_qp:velocity", "cascaded_qp", {"compatible": {"solver": "daqp"},
                                                    "incompatible": {"solver": "daqp"}},
            "the same tasks at velocity level (J q̇ = ẋ* + 20 e, limits as bounds on q̇), "
            "exact hierarchy: the like-for-like counterpart of PlaCo's KinematicsSolver",
            level="velocity"),
    RunSpec("cvxpy", "cvxpy", {}, "the cascaded QP modelled in cvxpy (slow; a check)",
            default=False),
    RunSpec("daqp_hierarchical", "daqp_hierarchical", {},
            "DAQP's hierarchical solve, joint limits as bounds"),
    RunSpec("hierarchical_active_set", "hierarchical_active_set", {},
            "the exact lexicographic optimum with joint position and velocity limits as "
            "bounds on q̈ (compiled active set per level, warm-started; docs/active-set.md)"),
    RunSpec("hierarchical_active_set:velocity", "hierarchical_active_set", {},
            "the same at velocity level (J q̇ = ẋ* + 20 e, the limits as bounds on q̇): "
            "exact, like for like with PlaCo's KinematicsSolver", level="velocity"),
    RunSpec("placo", "placo", {}, "PlaCo's algebraic QP through the registry"),
    RunSpec("reference", "reference", {}, "the test oracle (nested SVD)", default=False),
    RunSpec("sns", "sns", {},
            "Saturation in the Null Space (Flacco et al.): the q̈ bounds as hard limits "
            "above every task (level 0), strict priorities, task scaling when a task "
            "cannot be met within them", limits="hard_bounds"),
    RunSpec("sns:velocity", "sns", {},
            "SNS at velocity level (J q̇ = ẋ* + 20 e, the q̇ bounds as level 0)",
            level="velocity", limits="hard_bounds"),
    RunSpec("placo_kinematics_solver", "placo_kinematics_solver", {},
            "PlaCo's own KinematicsSolver at velocity level (hard contact, soft "
            "weighted tasks, its joint and velocity limits): what users run today"),
    RunSpec("pink", "pink", {},
            "pink's solve_ik at velocity level: every task a weighted cost (one decade "
            "per level), its ConfigurationLimit and VelocityLimit; QP back-end "
            "quadprog (pink's examples' choice)", backend="quadprog"),
    RunSpec("pink:daqp", "pink", {},
            "the same with DAQP, the fastest back-end measured here for pink's QPs "
            "(G1, 0.2 s: daqp 161, quadprog 173, proxqp 293, osqp 1143 µs per solve)",
            backend="daqp"),
)


#: runs whose ``q̈`` is cross-checked against ``cascaded_qp`` with the same per-level
#: Tikhonov terms (``info["level_damping"]``), and in which variants
CROSSCHECK_RUNS = {"extended_jacobian": ("compatible",),
                   "extended_jacobian:step_bound": ("incompatible",),
                   "extended_jacobian:eq27": ("compatible", "incompatible")}


def _runs_by_label(runs=None) -> dict[str, RunSpec]:
    return {r.label: r for r in (RUNS if runs is None else runs)}


# ------------------------------------------------------------------- one run
def _formulation_solver(spec: RunSpec, variant: str):
    """``(solve, needs_dynamics, torque_from_solution, limits)`` for a registry run."""
    from prioik import formulations
    mod = formulations.get(spec.formulation)
    caps = mod.CAPABILITIES
    opts = dict(spec.options.get(variant, {}))
    limits = spec.limits or ("bounds" if caps.inequalities else "activation")

    solvers = {}          # layout -> prepared solver (the joint-limit rows come and go)

    def solve(stack, **kw):
        solver = solvers.get(stack.layout)
        if solver is None:
            solver = solvers[stack.layout] = formulations.prepare(stack.layout,
                                                                  spec.formulation, **opts)
        return solver.solve(stack, **kw)

    return solve, caps.needs_mass_matrix, caps.needs_mass_matrix, limits


def run_one(spec: RunSpec, variant: str, duration: float, dt: float,
            progress=None, scenario="fencing", algorithmic_error: bool = True,
            velocity_gain: float = VELOCITY_GAIN):
    """Simulate one run of a scenario; returns a :class:`robots.SimulationResult` with
    joint names and ``info`` (scenario, variant, run label, formulation, options)
    filled, ready to save and replay.

    Args:
        scenario: A scenario name (built by :func:`robots.scenario.make` in
            ``variant``) or a built :class:`robots.scenario.Scenario` (a sweep's, with
            its own target and gains; ``variant`` then only selects the run's options).
        algorithmic_error: Record eq. 29 at every step (an SVD per level per step).
        velocity_gain: ``K`` of the velocity-level runs.

    Raises:
        UnsupportedTaskError: the formulation cannot take the scenario's stack.
        FormulationError: it is not available here.
    """
    from prioik.robots.scenario import make
    from prioik.robots.simulate import coordinate_names
    sc = make(scenario, variant) if isinstance(scenario, str) else scenario
    if spec.armature:
        sc.robot = sc.robot.with_armature(spec.armature)
    res = _run(spec, sc, variant, duration, dt, progress, algorithmic_error, velocity_gain)
    res.q_names, res.v_names = coordinate_names(sc.robot)
    res.info.update({**sc.info(), "label": spec.label, "formulation": spec.formulation,
                     "options": spec.options.get(variant, {}), "level": spec.level,
                     "limits": spec.limits, "armature": spec.armature,
                     "backend": spec.backend, "dt": dt, "duration": duration})
    return res


def _run(spec: RunSpec, scenario, variant: str, duration: float, dt: float, progress,
         algorithmic_error: bool = True, velocity_gain: float = VELOCITY_GAIN):
    from prioik.robots import simulate
    if spec.formulation == "placo_kinematics_solver":
        from prioik.benchmarks.placo_baseline import run_placo
        return run_placo(scenario, duration=duration, dt=dt, progress=progress,
                         label=spec.label)
    if spec.formulation == "pink":
        from prioik.benchmarks.pink_baseline import run_pink
        return run_pink(scenario, duration=duration, dt=dt, progress=progress,
                        solver=spec.backend or "quadprog", label=spec.label)
    solve, dyn, own_tau, limits = _formulation_solver(spec, variant)
    if spec.level == "velocity":
        if limits not in ("bounds", "hard_bounds") or dyn:
            from prioik.hierarchy import UnsupportedTaskError
            raise UnsupportedTaskError("velocity-level runs need a formulation that takes "
                                       "inequality tasks (joint limits as bounds on q̇)",
                                       formulation=spec.formulation, task="joint_limits")

        if hasattr(scenario, "written_step") and limits == "bounds":
            rows = scenario.velocity_rows(velocity_gain, limits=limits, dt=dt)

            def build_velocity(state, t):      # rows written in place: no per-step objects
                return scenario.written_step(rows, state, t)
        else:
            def build_velocity(state, t):
                return scenario.velocity_stack(state, t, gain=velocity_gain, limits=limits,
                                               dt=dt)

        return simulate(scenario.robot, build_velocity, solve, duration=duration, dt=dt,
                        level="velocity", progress=progress,
                        algorithmic_error=algorithmic_error)

    if hasattr(scenario, "written_step") and limits in ("activation", "bounds"):
        rows = scenario.acceleration_rows(limits=limits, dt=dt)

        def build(state, t):                   # rows written in place: no per-step objects
            return scenario.written_step(rows, state, t)
    else:
        def build(state, t):
            return scenario.acceleration_stack(state, t, limits=limits, dt=dt)

    return simulate(scenario.robot, build, solve, duration=duration, dt=dt,
                    needs_dynamics=dyn, torque_from_solution=own_tau, progress=progress,
                    algorithmic_error=algorithmic_error)


def _finite(x: float) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def summarize(res, extra_errors: tuple[str, ...] = ()) -> dict[str, Any]:
    """The summary.json entry of one run (non-finite values become ``null``); each
    name in ``extra_errors`` adds ``max_<name>``."""
    def mx(a):
        a = np.asarray(a, dtype=float)
        return _finite(np.nanmax(a)) if a.size and not np.isnan(a).all() else None

    tip = res.errors.get("tip_error_m", np.array([]))
    return {
        "final_tip_error_m": _finite(tip[-1]) if tip.size else None,
        "max_algorithmic_error": mx(res.algorithmic_error),
        "max_com_error_m": mx(res.errors.get("com_error_m", [])),
        "max_support_foot_error_m": mx(res.errors.get("support_foot_error_m", [])),
        "max_left_foot_error_m": mx(res.errors.get("left_foot_error_m", [])),
        "max_joint_limit_violation_rad": mx(res.errors.get("joint_limit_violation_rad", [])),
        "max_qdd_norm": mx(np.linalg.norm(res.a, axis=1)) if res.steps else None,
        "median_step_time_s": _finite(np.median(res.step_time_s)) if res.steps else None,
        "median_solve_time_s": _finite(np.median(res.solve_time_s)) if res.steps else None,
        "failed": bool(res.failed),
        **{f"max_{e}": mx(res.errors.get(e, [])) for e in extra_errors},
    }


def write_csv(path: Path, res) -> None:
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
    table = np.column_stack([res.t] + [res.errors[k] for k in res.errors]
                            + [res.algorithmic_error, np.linalg.norm(res.a, axis=1),
                               res.kinematics_time_s, res.solve_time_s, res.torque_time_s,
                               res.q, res.v, res.a, res.tau]) if res.steps else \
        np.zeros((0, len(cols)))
    np.savetxt(path, table, delimiter=",", header=",".join(cols), comments="", fmt="%.9g")


# ------------------------------------------------------------- cross-check
def crosscheck(variant: str, res, dt: float, every: int = 25,
               run_options: dict | None = None) -> dict[str, Any] | None:
    """``extended_jacobian`` against ``cascaded_qp`` on the same stacks.

    Along the recorded trajectory of an ``extended_jacobian`` run, every ``every``
    steps the activation-form stack is rebuilt and solved by ``extended_jacobian``
    with the run's options and by ``cascaded_qp`` (DAQP) given the same per-level
    Tikhonov terms (``level_damping`` = the extended Jacobian's
    ``info["level_damping"]``, zero where a level was solved exactly): the two must
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
        mu2 = a.info.get("level_damping")
        b = formulations.solve(stack, "cascaded_qp", solver="daqp", level_damping=mu2)
        if not (a.ok and b.ok):
            continue
        diff = float(np.linalg.norm(a.x - b.x) / max(1.0, np.linalg.norm(b.x)))
        damped = a.info.get("damped_levels") or []
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


def unifying_diagnostic(dt: float = 0.002) -> dict[str, float] | None:
    """Why ``unifying`` misbehaves on the G1: at the standing posture (``q̇ = 0``,
    ``t = 5 dt``), ``‖q̈‖`` of ``unifying`` with the G1's ``M``, with ``M = I`` (Chiaverini's method
    for two levels only: beyond, eq. 40 projects with ``Π (I − J_j⁺ J_j)`` instead of
    ``N^A_{i-1}``), and of ``extended_jacobian``; ``cond(M)`` without armature and with
    the armature of the ``unifying:armature*`` runs.
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
    for level, sigma in zip(stack.levels, singularity_distance(stack)):
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


# ------------------------------------------------------------------- plots
def plot_variant(out: Path, variant: str, results: dict, scenario: str = "fencing"
                 ) -> list[Path]:
    """Tip error, algorithmic error and ‖q̈‖ over time: grouped panels, one colour per
    run (:mod:`benchmarks.plots`)."""
    from prioik.benchmarks.plots import grouped_series
    tip = "sword-tip" if scenario == "fencing" else "tool"
    series = [("tip_error", f"{tip} error to the target (m)",
               lambda r: r.errors.get("tip_error_m")),
              ("algorithmic_error", "‖e_algorithm‖ (eq. 29)", lambda r: r.algorithmic_error),
              ("qdd", "‖q̈‖ (rad/s², m/s²)", lambda r: np.linalg.norm(r.a, axis=1))]
    return [grouped_series(out / f"{variant}_{key}.png", results, get, ylabel,
                           f"{scenario}, {variant}: {ylabel}")
            for key, ylabel, get in series]


def plot_step_times(out: Path, summary: dict, scenario: str = "fencing") -> Path:
    """Median step time per run and variant (kinematics + solve + torque)."""
    from prioik.benchmarks.plots import step_times
    return step_times(out / "step_time.png", summary,
                      f"{scenario}: compute time per control step (kinematics + solve + torque)")


# ------------------------------------------------------------------- table
def format_table(variant: str, runs: dict[str, dict], phases: dict[str, tuple],
                 scenario: str = "fencing") -> str:
    """One row per run: the summary numbers and the median phase times (the arm
    scenario shows its orientation error and velocity-limit violation where fencing
    shows the CoM and support-foot errors)."""
    arm = scenario != "fencing"
    c3, c4 = ("ori max", "JV viol") if arm else ("CoM max", "foot max")
    k3, k4 = (("max_orientation_error_rad", "max_joint_velocity_violation_rad_s") if arm
              else ("max_com_error_m", "max_support_foot_error_m"))
    head = (f"{'run':<26} {'tip final':>10} {'alg err':>9} {c3:>9} {c4:>9} "
            f"{'JL viol':>9} {'max|q̈|':>9} {'kin ms':>7} {'solve ms':>8} {'tau ms':>7} "
            f"{'step ms':>8}  status")
    lines = [f"{scenario} — {variant}{'' if arm else ' tasks'}", head, "-" * len(head)]

    def f(x, width=9):
        return f"{x:>{width}.2e}" if x is not None else f"{'—':>{width}}"

    for label, s in runs.items():
        kin, sol, tau = phases.get(label, (np.nan, np.nan, np.nan))
        step = s["median_step_time_s"]
        lines.append(
            f"{label:<26} {f(s['final_tip_error_m'], 10)} "
            f"{f(s['max_algorithmic_error'])} {f(s.get(k3))} "
            f"{f(s.get(k4))} {f(s['max_joint_limit_violation_rad'])} "
            f"{f(s['max_qdd_norm'])} {1e3 * kin:>7.3f} {1e3 * sol:>8.3f} {1e3 * tau:>7.3f} "
            f"{(1e3 * step if step is not None else float('nan')):>8.3f}  "
            f"{'FAILED' if s['failed'] else 'ok'}")
    return "\n".join(lines)


# ------------------------------------------------------------------ command
def select_runs(text: str | None, runs=None) -> tuple[list[RunSpec], list[str]]:
    """Runs to do and skip messages: every default run (of ``runs``, default
    :data:`RUNS`) whose formulation is available, or the comma-separated labels of
    ``--formulations``."""
    from prioik import formulations
    runs = RUNS if runs is None else runs
    table = _runs_by_label(runs)
    if text:
        labels = [s.strip() for s in text.split(",") if s.strip()]
        unknown = [lb for lb in labels if lb not in table]
        if unknown:
            raise ValueError(f"unknown run(s) {', '.join(unknown)}; known: "
                             f"{', '.join(table)}")
        specs = [table[lb] for lb in labels]
    else:
        specs = [r for r in runs if r.default]
    chosen, skipped = [], []
    for spec in specs:
        if spec.formulation == "placo_kinematics_solver":
            from prioik.extras import install_hint, missing_distributions
            if missing_distributions("placo"):
                skipped.append(f"{spec.label}: placo is not installed; {install_hint('placo')}")
                continue
            chosen.append(spec)
            continue
        if spec.formulation == "pink":
            from prioik.benchmarks.pink_baseline import unavailable_reason
            reason = unavailable_reason()
            if reason is None:
                import qpsolvers
                if spec.backend and spec.backend not in qpsolvers.available_solvers:
                    reason = f"QP back-end {spec.backend} is not available here"
            if reason:
                skipped.append(f"{spec.label}: {reason}")
                continue
            chosen.append(spec)
            continue
        try:
            formulations.get(spec.formulation)
        except formulations.FormulationError as exc:
            skipped.append(f"{spec.label}: {exc}")
            continue
        chosen.append(spec)
    return chosen, skipped


def _progress_bar(label: str, variant: str, duration: float, enabled: bool):
    """A tqdm bar over simulated seconds (rate and ETA), or ``None``."""
    if not enabled:
        return None, None
    from tqdm import tqdm
    bar = tqdm(total=round(duration, 3), desc=f"[{variant}] {label}", unit="sim s",
               file=sys.stderr, leave=False, bar_format="{desc}: {n:.1f}/{total:.1f} s "
               "[{elapsed}<{remaining}, {rate_fmt}]")

    def progress(t):
        bar.update(round(t - bar.n, 6))

    return bar, progress


def run_scenario(args: argparse.Namespace, scenario: str, variants: list[str], runs=None,
                 extra_errors: tuple[str, ...] = ()) -> tuple[dict, dict, dict, dict]:
    """Run every selected run of ``runs`` (default :data:`RUNS`) on each variant of
    ``scenario``; write CSVs, saved runs (``.npz``), plots, the replay pages,
    ``summary.json`` and ``run_info.json`` into ``args.out``.

    Returns:
        ``(summary, meta, pngs, results)``: ``results[variant][label]`` is the
        :class:`robots.SimulationResult`.
    """
    from prioik.benchmarks.replay import write_replay
    from prioik.hierarchy import UnsupportedTaskError
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    specs, skipped = select_runs(args.formulations, runs)
    for msg in skipped:
        print(f"skipping {msg}", file=sys.stderr)
    summary: dict[str, dict] = {}
    phases: dict[str, dict] = {}
    checks: dict[str, Any] = {}
    pngs: dict[str, list[Path]] = {}
    skipped_runs: list[str] = list(skipped)
    messages: dict[str, dict[str, str]] = {}
    replays: dict[str, str] = {}
    all_results: dict[str, dict] = {}
    fencing = scenario == "fencing"
    diagnostics: dict[str, Any] = {}
    if fencing:
        diagnostics["standing_sigmas"] = standing_sigmas(args.dt)
        print("projected σ_min/‖A_i‖_F per level at the standing posture (incompatible): "
              + ", ".join(f"{k} {v:.3g}" for k, v in diagnostics["standing_sigmas"].items()))
    wall0 = time.perf_counter()
    for variant in variants:
        results = {}
        summary[variant] = {}
        phases[variant] = {}
        for spec in specs:
            if variant not in spec.variants:
                continue
            t0 = time.perf_counter()
            bar, progress = _progress_bar(spec.label, variant, args.duration, args.progress)
            try:
                res = run_one(spec, variant, args.duration, args.dt, progress=progress,
                              scenario=scenario)
            except UnsupportedTaskError as exc:
                msg = f"{spec.label} ({variant}): cannot take the stack: {exc}"
                print(f"skipping {msg}", file=sys.stderr)
                skipped_runs.append(msg)
                continue
            finally:
                if bar is not None:
                    bar.close()
            results[spec.label] = res
            summary[variant][spec.label] = summarize(res, extra_errors)
            phases[variant][spec.label] = tuple(
                float(np.median(x)) if res.steps else float("nan")
                for x in (res.kinematics_time_s, res.solve_time_s, res.torque_time_s))
            stem = f"{variant}_{spec.label.replace(':', '_')}"
            write_csv(out / f"{stem}.csv", res)
            res.save(out / f"{stem}.npz")
            if res.failed:
                messages.setdefault(variant, {})[spec.label] = res.message
            print(f"[{variant}] {spec.label}: {res.steps} steps in "
                  f"{time.perf_counter() - t0:.1f} s"
                  f"{' — FAILED: ' + res.message if res.failed else ''}",
                  file=sys.stderr, flush=True)
            if (fencing and variant in CROSSCHECK_RUNS.get(spec.label, ())
                    and not args.no_crosscheck):
                c = crosscheck(variant, res, args.dt,
                               run_options=spec.options.get(variant, {}))
                if c is not None:
                    checks.setdefault(variant, {})[spec.label] = c
        all_results[variant] = results
        pngs[variant] = plot_variant(out, variant, results, scenario) if results else []
        if results:
            html = write_replay(out / f"{variant}_replay.html", results,
                                title=f"{scenario}, {variant}")
            replays[variant] = html.name
        print(format_table(variant, summary[variant], phases[variant], scenario))
        print()
        if fencing and variant == "incompatible" and "extended_jacobian" in results:
            trace = sigma_trace(variant, results["extended_jacobian"], args.dt)
            diagnostics["sigma_trace"] = trace
            print("extended_jacobian (eq. 18), incompatible: projected σ_min/‖A_i‖_F "
                  "along the run")
            for row in trace:
                print(f"  t = {row['t']:.3f} s  tip {row['sigma_tip']:.3e}  lowest "
                      f"{row['lowest_level']} {row['sigma_lowest']:.3e}  "
                      f"‖q̈‖ = {row['qdd_norm']:.3e}  joint-limit rows {row['limit_rows']} "
                      f"(max |h| {row['limit_target']:.3g})")
        if (fencing and variant == "incompatible"
                and "extended_jacobian:step_bound" in results):
            top = max_limit_target(variant, results["extended_jacobian:step_bound"], args.dt)
            diagnostics["max_limit_target"] = top
            print(f"largest joint-limit row target along extended_jacobian:step_bound: "
                  f"{top:.3g} rad/s²")
    pngs["step_time"] = [plot_step_times(out, summary, scenario)]
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    meta = {"scenario": scenario, "duration_s": args.duration, "dt_s": args.dt,
            "variants": variants,
            "runs": {s.label: {"formulation": s.formulation, "options": s.options,
                               "note": s.note} for s in specs},
            "skipped": skipped_runs, "crosscheck": checks, "phases": phases,
            "messages": messages, "replays": replays, "diagnostics": diagnostics,
            "wall_time_s": time.perf_counter() - wall0}
    (out / "run_info.json").write_text(json.dumps(meta, indent=2, default=str) + "\n")
    print(f"wrote {out / 'summary.json'}, {sum(len(v) for v in pngs.values())} plots and "
          f"{len(replays)} replay page(s) in {time.perf_counter() - wall0:.0f} s",
          file=sys.stderr)
    return summary, meta, pngs, all_results


def run_command(args: argparse.Namespace) -> int:
    """``prioik fencing``: see the module docstring."""
    variants = ["compatible", "incompatible"] if args.variant == "both" else [args.variant]
    summary, meta, pngs, _ = run_scenario(args, "fencing", variants)
    specs = meta["runs"]
    meta["unifying_diagnostic"] = (unifying_diagnostic(args.dt)
                                   if any(r["formulation"] == "unifying"
                                          for r in specs.values()) else None)
    checks = meta["crosscheck"]
    out = Path(args.out)
    (out / "crosscheck.json").write_text(json.dumps(checks, indent=2) + "\n")
    (out / "run_info.json").write_text(json.dumps(meta, indent=2, default=str) + "\n")
    if meta["unifying_diagnostic"]:
        ud = meta["unifying_diagnostic"]
        print(f"cond(M) at the standing posture: {ud['cond_M']:.3g} (no armature); "
              + ", ".join(f"{v:.3g} ({a} kg·m² armature)"
                          for a, v in ud["cond_M_armature"].items()))
    for variant, by_label in checks.items():
        for label, c in by_label.items():
            print(f"cross-check [{variant}] {label} vs cascaded_qp: {c}")
    if args.doc:
        path = write_reproduction(Path(args.doc), summary, meta, pngs)
        print(f"wrote {path}", file=sys.stderr)
    return 0


def add_parser(subparsers) -> None:
    """Register ``prioik fencing``."""
    p = subparsers.add_parser(
        "fencing", help="the paper's fencing scenario on the G1, every formulation",
        description="Simulate the fencing scenario (Jeong & Chang 2009, Sec. III) on the "
                    "Unitree G1 with each formulation; print tables, write summary.json, "
                    "CSV trajectories and plots.")
    p.add_argument("--variant", choices=["compatible", "incompatible", "both"],
                   default="both")
    p.add_argument("--formulations", default=None, metavar="A,B,...",
                   help="runs to do (labels of benchmarks.fencing.RUNS; default: every "
                        "default run whose formulation is available)")
    p.add_argument("--duration", type=float, default=3.0, help="simulated seconds")
    p.add_argument("--dt", type=float, default=0.002, help="control step (s)")
    p.add_argument("--out", default="results", help="output folder")
    p.add_argument("--doc", default=None, metavar="PATH",
                   help="also (re)generate the reproduction page here "
                        "(e.g. docs/reproduction.md; plots copied to img/ beside it)")
    p.add_argument("--no-crosscheck", action="store_true",
                   help="skip the extended_jacobian vs cascaded_qp q̈ comparison")
    p.add_argument("--quiet", dest="progress", action="store_false",
                   help="no progress bars on stderr")
    p.set_defaults(func=run_command, extras=("robots", "plots"))


# ------------------------------------------------------------ reproduction page
def stops_and_figures(add, meta: dict, variant: str, shown: dict, figures) -> None:
    """The page lines after a variant's table (this page's and the arm page's): where
    each stopped run stopped, then the variant's figures ``(key, caption)`` found in
    ``shown`` (stem ``{variant}_{key}`` → path)."""
    stops = meta.get("messages", {}).get(variant, {})
    for label, msg in stops.items():
        add(f"- `{label}` stopped at {msg}.")
    if stops:
        add("")
    for key, caption in figures:
        stem = f"{variant}_{key}"
        if stem in shown:
            add(f"![{caption}]({shown[stem]})")
            add("")


PAPER_STEP_TIMES_MS = {"extended_jacobian": 1.4, "nullspace": 2.7, "unifying": 3.2,
                       "operational_space": 4.8}
PAPER_NAMES = {"extended_jacobian": "proposed framework (extended Jacobian)",
               "nullspace": "resolved acceleration method",
               "nullspace:damped": "resolved acceleration with SR inverse",
               "unifying": "unifying framework",
               "operational_space": "operational space formulation"}


def _fmt(x, spec=".2e"):
    return "—" if x is None else format(x, spec)


def _mm(x):
    return "—" if x is None else f"{1e3 * x:.3g} mm"


def write_reproduction(path: Path, summary: dict, meta: dict, pngs: dict) -> Path:
    """Write the reproduction page from measured numbers; copy its plots to ``img/``.

    Every number and every verdict on the page comes from ``summary`` / ``meta``;
    the fixed text describes the setting and how it differs from the paper's.
    """
    path = Path(path)
    img = path.parent / "img"
    img.mkdir(parents=True, exist_ok=True)
    shown = {}
    for files in pngs.values():
        for f in files:
            target = img / f"fencing_{Path(f).name}"
            shutil.copyfile(f, target)
            shown[Path(f).stem] = f"img/{target.name}"
    L: list[str] = []
    add = L.append
    comp = summary.get("compatible", {})
    inc = summary.get("incompatible", {})
    add("# Reproduction: the fencing experiment of Jeong & Chang (2009), Sec. III")
    add("")
    add("<!-- generated by `prioik fencing --doc docs/reproduction.md`; do not edit -->")
    add("")
    add(f"Generated by `prioik fencing --variant {'both' if len(summary) == 2 else next(iter(summary))}"
        f" --duration {meta['duration_s']:g} --dt {meta['dt_s']:g} --doc {path.as_posix()}` "
        f"(wall time {meta['wall_time_s']:.0f} s on this machine). Every number below is "
        "measured by that command; timings are noisy on a shared machine.")
    add("")
    add("## The setting, and how it differs from the paper's")
    add("")
    add("| | paper | here |")
    add("|---|---|---|")
    add("| robot | 28-DOF humanoid (SimStudio) | Unitree G1, 29 joints + floating base "
        "(`n_v = 35`), `g1_29dof_rev_1_0.urdf` |")
    add("| simulation | full dynamics with contacts | kinematic: the chosen `q̈` is integrated "
        "(semi-implicit Euler, fixed `dt`); torques by RNEA or the formulation's own law "
        "are recorded, not fed back; no contact forces |")
    add("| tasks (priority) | joint limit, self-balance (CoG at the centre of the feet), "
        "left foot steps one pace, sword tip to the target | support (right) foot contact; "
        "joint limits; CoM (horizontal) over the middle of the feet; left foot steps "
        "0.2 m; sword tip (0.5 m along the left hand) to the target; plus a low-gain "
        "posture level at the bottom (see `docs/robots.md`) |")
    add("| references | not stated | minimum-jerk to the target then hold, `K_p = 25`, "
        "`K_d = 10` (contact `K_p = 100`, `K_d = 20`) |")
    add("| joint limits | top task | activation rows with a continuous target for the "
        "equality formulations, bounds on `q̈` for the QP formulations |")
    add("")
    add("Runs and their options (`benchmarks/fencing.py`, `RUNS`):")
    add("")
    add("| run | formulation | options (compatible / incompatible) | why |")
    add("|---|---|---|---|")
    for label, r in meta["runs"].items():
        o = r["options"]
        add(f"| `{label}` | `{r['formulation']}` | `{o.get('compatible', {})}` / "
            f"`{o.get('incompatible', {})}` | {r['note']} |")
    if meta.get("skipped"):
        add("")
        add("Not run here: " + "; ".join(meta["skipped"]) + ".")
    add("")
    for variant, runs in summary.items():
        add(f"## Measured: {variant} tasks")
        add("")
        add("| run | final tip error | max algorithmic error | max CoM error | "
            "max support-foot error | max left-foot error | max joint-limit violation | "
            "max ‖q̈‖ | median step | median solve | status |")
        add("|---|---|---|---|---|---|---|---|---|---|---|")
        for label, s in runs.items():
            add(f"| `{label}` | {_mm(s['final_tip_error_m'])} | "
                f"{_fmt(s['max_algorithmic_error'])} | {_mm(s['max_com_error_m'])} | "
                f"{_mm(s['max_support_foot_error_m'])} | "
                f"{_mm(s.get('max_left_foot_error_m'))} | "
                f"{_fmt(s['max_joint_limit_violation_rad'])} rad | "
                f"{_fmt(s['max_qdd_norm'], '.3g')} | "
                f"{_fmt(None if s['median_step_time_s'] is None else 1e3 * s['median_step_time_s'], '.3f')} ms | "
                f"{_fmt(None if s['median_solve_time_s'] is None else 1e3 * s['median_solve_time_s'], '.3f')} ms | "
                f"{'failed' if s['failed'] else 'ran to the end'} |")
        add("")
        stops_and_figures(add, meta, variant, shown, (
            ("tip_error", f"{variant}: sword-tip error (paper Fig. 2 / Fig. 4)"),
            ("algorithmic_error", f"{variant}: algorithmic error, eq. 29 (paper Fig. 3)"),
            ("qdd", f"{variant}: ‖q̈‖: spikes of algorithmic singularities")))
    # --------------------------------------------------------------- claims
    add("## The paper's claims beside the measurements")
    add("")

    def tip(runs, label):
        return runs.get(label, {}).get("final_tip_error_m")

    def ok(runs, label):
        return label in runs and not runs[label]["failed"]

    add("**1. Compatible tasks: the proposed framework, the resolved acceleration method "
        "and the operational space formulation execute the sub-task (sword tip) "
        "accurately; the unifying framework does not (algorithmic error).**")
    add("")
    for label in ("extended_jacobian", "nullspace", "operational_space", "cascaded_qp",
                  "daqp_hierarchical", "unifying", "unifying:armature", "chiaverini",
                  "placo_kinematics_solver"):
        if label not in comp:
            continue
        e = tip(comp, label)
        verdict = ("within 1 mm of the target" if e is not None and e < 1e-3
                   else "not within 1 mm of the target")
        extra = "" if ok(comp, label) else f" — the run failed ({_mm(e)} when it stopped)"
        add(f"- `{label}`: final tip error {_mm(e)}, {verdict}{extra}.")
    add("")
    add("**2. Algorithmic error (eq. 29): zero for the proposed framework, not for the "
        "unifying framework.**")
    add("")
    for label in ("extended_jacobian", "nullspace", "operational_space", "unifying",
                  "unifying:armature", "chiaverini"):
        if label in comp:
            a = comp[label]["max_algorithmic_error"]
            add(f"- `{label}`: largest ‖e_algorithm‖ over the compatible run "
                f"{_fmt(a)}{'' if ok(comp, label) else ' (run failed)'}.")
    add("")
    add("**3. Incompatible tasks: the proposed framework performs the tasks by priority "
        "without algorithmic singularity; the resolved acceleration method is unstable "
        "without the SR inverse and tracks well with it; the unifying framework "
        "converges to a non-optimal position.**")
    add("")
    for label in inc:
        s = inc[label]
        add(f"- `{label}`: {'ran to the end' if not s['failed'] else 'FAILED'}; final tip "
            f"error {_mm(s['final_tip_error_m'])}; support foot within "
            f"{_mm(s['max_support_foot_error_m'])}, CoM within {_mm(s['max_com_error_m'])}, "
            f"left foot within {_mm(s.get('max_left_foot_error_m'))}, "
            f"joint limits within {_fmt(s['max_joint_limit_violation_rad'])} rad, "
            f"max ‖q̈‖ {_fmt(s['max_qdd_norm'], '.3g')}.")
    cc = meta.get("crosscheck", {})
    if cc:
        add("")
        add("Cross-check against `cascaded_qp` (DAQP) on the same stacks along each "
            "run's own trajectory (every 25th step); where a level was damped, the cascade "
            "gets the same Tikhonov term on that level (`level_damping` = the extended "
            "Jacobian's `info['level_damping']`; for eq. 27 with the paper's `Z_i` that is "
            "`(0, λ, …, λ)`), so the whole `q̈` must agree:")
        add("")
        for variant, by_label in cc.items():
            for label, c in by_label.items():
                add(f"- `{label}`, {variant}: {c['steps_compared']} steps compared, "
                    f"{c['steps_with_damping']} with a damped level "
                    f"(damped levels: {c['damped_levels'] or 'none'}); "
                    f"largest relative ‖Δq̈‖ where nothing was damped: "
                    f"{_fmt(c['max_rel_diff_qdd_undamped_steps'])}; where a level was "
                    f"damped: {_fmt(c['max_rel_diff_qdd_damped_steps'])}.")
    add("")
    add("**4. Computation per control step: proposed 1.4 ms < resolved acceleration "
        "2.7 ms < unifying 3.2 ms < operational space 4.8 ms (2.4 GHz Pentium).**")
    add("")
    phases = meta.get("phases", {})
    add("| run | variant | kinematics | solve | torque | total (median) |")
    add("|---|---|---|---|---|---|")
    for variant, runs in phases.items():
        for label, (k, s_, t) in runs.items():
            add(f"| `{label}` | {variant} | {1e3 * k:.3f} ms | {1e3 * s_:.3f} ms | "
                f"{1e3 * t:.3f} ms | {1e3 * (k + s_ + t):.3f} ms |")
    add("")
    order_src = comp or inc
    timed = [(lb, order_src[lb]["median_step_time_s"]) for lb in PAPER_STEP_TIMES_MS
             if lb in order_src and order_src[lb]["median_step_time_s"] is not None]
    if timed:
        measured = [lb for lb, _ in sorted(timed, key=lambda p: p[1])]
        paper = [lb for lb in sorted(PAPER_STEP_TIMES_MS, key=PAPER_STEP_TIMES_MS.get)
                 if lb in measured]
        same = measured == paper
        add(f"Measured order (fastest first): {' < '.join(f'`{m}`' for m in measured)}; "
            f"the paper's order over the same methods: {' < '.join(f'`{p}`' for p in paper)}"
            f" — {'the same' if same else 'different'}. The kinematics phase (pinocchio "
            "Jacobians, drifts, and building the stack in Python) is shared by all and "
            "is of the same size as the solves; the torque-level formulations also "
            "need `M(q)` (CRBA) and the bias, counted in their kinematics phase."
            + ("" if same else
               " The solve times here are those of this toolkit's implementations "
               "(LAPACK factorizations, `M` used through its Cholesky factor, no "
               "explicit inverses), which need not rank like the paper's 2009 "
               "implementations; the measured gaps between these methods are "
               "fractions of a millisecond."))
        add("")
    if "step_time" in shown:
        add(f"![median step time per run]({shown['step_time']})")
        add("")
    trio = [lb for lb in ("placo_kinematics_solver", "cascaded_qp:velocity", "extended_jacobian",
                          "extended_jacobian:step_bound") if lb in comp or lb in inc]
    if "placo_kinematics_solver" in trio:
        add("**Beyond the paper: what users run today.** PlaCo's `KinematicsSolver` "
            "(two levels, hard contact and CoM, soft weighted foot/tip/posture, velocity "
            "level) beside the same tasks at velocity level with an exact hierarchy "
            "(`cascaded_qp:velocity`) and the extended Jacobian at acceleration level "
            "(eq. 18; in the incompatible run also prioik's step-bounded variant):")
        add("")
        add("| run | variant | final tip error | max CoM error | max support-foot error | "
            "max joint-limit violation | median step |")
        add("|---|---|---|---|---|---|---|")
        for variant, runs in summary.items():
            for lb in trio:
                if lb in runs:
                    r = runs[lb]
                    step = r["median_step_time_s"]
                    add(f"| `{lb}` | {variant} | {_mm(r['final_tip_error_m'])} | "
                        f"{_mm(r['max_com_error_m'])} | {_mm(r['max_support_foot_error_m'])} | "
                        f"{_fmt(r['max_joint_limit_violation_rad'])} rad | "
                        f"{_fmt(None if step is None else 1e3 * step, '.3f')} ms |")
        add("")
        add("PlaCo's step is all C++ (its kinematics, a dense QP with eliminated hard "
            "equalities); the other rows pay for Python stack building in their "
            "kinematics phase.")
        add("")
    add("## Differences, and why")
    add("")
    add("- The simulation is kinematic (integrated `q̈`), not a dynamic simulation with "
        "contacts: a formulation's `q̈` is applied exactly, so differences between runs "
        "are those of the formulations, not of a contact model. Torques are recorded "
        "(RNEA, or the formulation's own law) but not fed back.")
    add("- The floating base is free, held only by the support-foot task; the torque on "
        "the base rows is the wrench the contact would have to supply.")
    add("- The paper's joint-limit task is a black box; here it is either activation rows "
        "(`robots.tasks.joint_limit_rows`) or bounds on `q̈` "
        "(`robots.tasks.joint_limit_bounds`). Rows switching on take directions away "
        "from the lower levels (see the measured trace of the eq. 18 run below).")
    diag = meta.get("diagnostics", {})
    msgs = meta.get("messages", {}).get("incompatible", {})
    exact = inc.get("extended_jacobian")
    add("- Which of its methods the paper ran in the incompatible case is not stated: "
        "it reports the proposed framework performing the tasks \"without algorithmic "
        "singularities\" but does not say whether that was eq. 18 or the damped eq. 27, "
        "and its Remark only says that damping \"may be necessary\". Both are run here.")
    if exact is not None:
        fate = (f"diverges ({msgs.get('extended_jacobian', 'stopped')})" if exact["failed"]
                else f"runs to the end (max ‖q̈‖ {_fmt(exact['max_qdd_norm'], '.3g')})")
        trace = diag.get("sigma_trace") or []
        text = (f"- Eq. 18 as printed (`extended_jacobian`, exact lexicographic `q̈`) {fate}.")
        if trace:
            before = [r for r in trace if r["limit_rows"] == 0]
            after = [r for r in trace if r["limit_rows"] > 0]
            low = min(trace, key=lambda r: r["sigma_lowest"])
            text += (" Measured along that run (every level's projected "
                     "`σ_min(A_i Z_i)/‖A_i‖_F`, posture left out; table below): the "
                     f"smallest is {low['sigma_lowest']:.2g} ({low['lowest_level']}, "
                     f"t = {low['t']:.3f} s)")
            if before:
                text += (f"; while no joint-limit row is active (up to t = "
                         f"{max(r['t'] for r in before):.3f} s) it stays ≥ "
                         f"{min(r['sigma_lowest'] for r in before):.2g} and ‖q̈‖ ≤ "
                         f"{max(r['qdd_norm'] for r in before):.3g}")
            if after:
                text += (f"; in the last steps {max(r['limit_rows'] for r in after)} "
                         "joint-limit rows are active with targets up to "
                         f"|h| = {max(r['limit_target'] for r in after):.3g} rad/s² and "
                         f"‖q̈‖ reaches {max(r['qdd_norm'] for r in after):.3g}")
            text += "."
            if exact["failed"] and after:
                text += (f" The smallest projected σ is {low['sigma_lowest']:.2g} of its "
                         "level's scale, not zero: a level's step is "
                         "`|u_minᵀ(h_i − J_i θ̈_(i−1))|/σ`, and the divergence comes with "
                         "the joint-limit rows switching on with the targets above, not "
                         "with σ → 0." if low["sigma_lowest"] > 1e-3 else
                         f" The projected σ falls to {low['sigma_lowest']:.2g} of its "
                         "level's scale before the run stops.")
        add(text)
        if trace:
            add("")
            add("  | t (s) | sword tip σ_min/‖A‖_F | smallest (level) | ‖q̈‖ | joint-limit "
                "rows | their max \\|h\\| (rad/s²) |")
            add("  |---|---|---|---|---|---|")
            for r in trace:
                add(f"  | {r['t']:.3f} | {r['sigma_tip']:.3g} | {r['sigma_lowest']:.3g} "
                    f"({r['lowest_level']}) | {r['qdd_norm']:.3g} | {r['limit_rows']} | "
                    f"{r['limit_target']:.3g} |")
            add("")
    for label, what in (("extended_jacobian:eq27", "eq. 27 with the paper's `Z_i` (r_i rows "
                         "spanning `range(N_{i-1} J_iᵀ)`)"),
                        ("extended_jacobian:eq27_null_space", "eq. 27 read with a basis of "
                         "the whole null space (`z_basis='null_space'`)")):
        r = inc.get(label)
        if r is not None:
            add(f"- {what}, λ = {EQ27_DAMPING:g} (`{label}`): "
                f"{'FAILED' if r['failed'] else 'runs to the end'}; final tip error "
                f"{_mm(r['final_tip_error_m'])}, support foot within "
                f"{_mm(r['max_support_foot_error_m'])}, CoM within "
                f"{_mm(r['max_com_error_m'])}, left foot within "
                f"{_mm(r.get('max_left_foot_error_m'))}, joint limits within "
                f"{_fmt(r['max_joint_limit_violation_rad'])} rad, max ‖q̈‖ "
                f"{_fmt(r['max_qdd_norm'], '.3g')}.")
    if "extended_jacobian:eq27" in inc:
        add("  With the paper's `Z_i`, eq. 27 is the hierarchy whose every level below the "
            "first (joint limits, CoM, left foot, tip, posture) is solved by damped least "
            "squares with μ² = λ (the cross-check above reproduces it with `cascaded_qp`): "
            "no level disturbs a higher one, but the CoM and joint-limit levels are damped "
            "too, so they are not met exactly. Read with the whole null space, the damped "
            "blocks also pull on the lower levels' directions and the levels trade "
            "accuracy in one least-squares fit.")
    sb = inc.get("extended_jacobian:step_bound")
    if sb is not None:
        add("- `extended_jacobian:step_bound` is prioik's own variant, not the paper's: it "
            f"bounds the sword-tip level's own step (`step_bound`, Δ = {TIP_STEP_BOUND:g} "
            "rad/s²); where the exact step is longer, that level alone is solved by damped "
            "least squares with the damping that makes the step Δ (trust region). Support "
            f"foot ({_mm(sb['max_support_foot_error_m'])}), CoM "
            f"({_mm(sb['max_com_error_m'])}), left foot "
            f"({_mm(sb.get('max_left_foot_error_m'))}) and joint limits "
            f"({_fmt(sb['max_joint_limit_violation_rad'])} rad) are the exact hierarchy's, "
            f"max ‖q̈‖ {_fmt(sb['max_qdd_norm'], '.3g')}, and the whole `q̈` equals the "
            "cascade of QPs with the same Tikhonov term (cross-check above); the price is "
            "the tip's accuracy while the bound is active.")
        allb = inc.get("extended_jacobian:step_bound_all")
        top = diag.get("max_limit_target")
        if allb is not None:
            add(f"  Bounding every level's step by the same Δ (`extended_jacobian:step_bound_all`) "
                "also caps the joint-limit rows"
                + (f" (their targets reach {top:.3g} rad/s² along the step-bounded run)"
                   if top else "")
                + f": joint limits are then violated by up to "
                f"{_fmt(allb['max_joint_limit_violation_rad'])} rad.")
    sel = inc.get("extended_jacobian:selective")
    sig = diag.get("standing_sigmas", {})
    if sel is not None:
        add("- `extended_jacobian:selective` (prioik's own variant) damps any level whose "
            "projected σ_min falls below 0.05·‖A_i‖_F. At the standing posture, before "
            "anything moves, the projected σ_min/‖A_i‖_F are "
            + ", ".join(f"{k} {v:.3g}" for k, v in sig.items())
            + "; "
            + (", ".join(k for k, v in sig.items() if 0 < v < 0.05)
               + " (below 0.05) is damped from the first step, before anything moves and "
               "before any task conflicts." if any(0 < v < 0.05 for v in sig.values())
               else "none is below 0.05 there."))
    qp = [lb for lb in ("cascaded_qp", "daqp_hierarchical") if lb in inc]
    if qp:
        parts = [f"`{lb}` {'fails' if inc[lb]['failed'] else 'runs to the end'} "
                 f"(max ‖q̈‖ {_fmt(inc[lb]['max_qdd_norm'], '.3g')})" for lb in qp]
        add("- The exact lexicographic QP cascades use the bound form of the joint limits "
            "(no rows switching on, limits active only where they bind): in the "
            "incompatible run " + ", ".join(parts) + " without any damping.")
    ud = meta.get("unifying_diagnostic")
    if ud and "unifying" in comp:
        add(f"- `unifying` {'diverges' if comp['unifying']['failed'] else 'runs'} even "
            "with compatible tasks. Measured at the standing posture at rest: its ‖q̈‖ is "
            f"{ud['qdd_unifying']:.3g} where the exact solution's is "
            f"{ud['qdd_extended_jacobian']:.3g}; with `M = I` it is "
            f"{ud['qdd_unifying_identity_M']:.3g}. The G1's "
            f"joint-space inertia has cond(M) = {ud['cond_M']:.2g} (light distal "
            "links against a 33 kg body), so the M²-weighted inverses "
            "`J^{M²+}` and the oblique projectors `N_i` of eq. 40 are ill-conditioned "
            "(cond(M²) ~ cond(M)²); the resulting null-space accelerations feed back "
            "through the PD terms and grow. The first step already shows the problem "
            "(no feedback yet), so it is a property of the method on this model rather "
            "than of the integration: eq. 37's `(J_i M⁻¹)⁺` is the minimum-torque-norm "
            "answer, which moves the light distal joints fastest, and eq. 40 has no "
            "`−J_i θ̈_(i−1)` term, so the lower levels do not correct what the higher "
            "ones did to them. The paper's robot did not show it, and its `M` is not "
            "available to compare.")
        arm = comp.get("unifying:armature")
        conds = ud.get("cond_M_armature", {})
        if arm is not None:
            low = comp.get("unifying:armature_low")
            low_msg = meta.get("messages", {}).get("compatible", {}).get(
                "unifying:armature_low")
            add(f"- With {UNIFYING_ARMATURE:g} kg·m² of rotor inertia added to every "
                "actuated joint (`unifying:armature`; real actuators have some, the URDF "
                f"none), cond(M) at the standing posture falls from {ud['cond_M']:.2g} to "
                f"{conds.get(f'{UNIFYING_ARMATURE:g}', float('nan')):.2g} and `unifying` "
                f"{'still fails' if arm['failed'] else 'runs to the end'}: final tip error "
                f"{_mm(arm['final_tip_error_m'])}, largest algorithmic error "
                f"{_fmt(arm['max_algorithmic_error'])} — the algorithmic error the paper "
                "attributes to it, without the divergence."
                + (f" With {UNIFYING_ARMATURE_LOW:g} kg·m² (`unifying:armature_low`, cond(M) "
                   f"{conds.get(f'{UNIFYING_ARMATURE_LOW:g}', float('nan')):.2g}) it "
                   + (f"diverges: {low_msg}." if low is not None and low["failed"] else
                      "runs to the end.") if low is not None else ""))
    add("- A low-gain posture level is added at the bottom of the stack so that the "
        "null-space motion left by the five tasks is damped; the algorithmic error is "
        "reported over the five tasks only.")
    add("- PlaCo's `KinematicsSolver` is velocity (displacement) level with two priority "
        "levels (hard/soft); its `q̈` is a finite difference of its velocities, so its "
        "max ‖q̈‖ mostly reflects the velocity jump of its first steps.")
    path.write_text("\n".join(L) + "\n")
    return path
