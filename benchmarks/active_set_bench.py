"""Timing of ``hierarchical_active_set`` on the G1 fencing stacks with joint limits as
bounds, cold and warm, beside ``cascaded_qp[daqp]`` and DAQP's raw hierarchical call.

The stacks: the fencing run of :func:`prioik.benchmarks.stacks.g1_fencing_samples`
(each variant), at consecutive simulated steps (``dt = 5 ms``) spread over the run in
``windows`` stretches of ``steps`` steps; at each step the acceleration-level stack with
joint position/velocity limits as bounds on ``q̈`` (``limits="bounds"``) and the
velocity-level stack with bounds on ``q̇``. Every solver gets the same stacks:

* ``active_set cold``: ``prioik.prepare(layout, "hierarchical_active_set",
  warm_start=False).solve(stack)`` (the registry's prepared path);
* ``active_set warm``: the same with ``warm_start=True``, the steps solved in order
  (each solve starts from the previous step's working sets; before a window's first
  step the warm solver solves, untimed, the step before it, so that no timed solve
  starts from another window's state);
* ``daqp raw``: ``daqp.solve(None, None, A, bu, bl, sense, break_points=…)`` alone, on
  arrays built beforehand (:func:`prioik.formulations.daqp_hierarchical.build` without
  level compression, as ``daqp_hierarchical[raw]``);
* ``cascaded_qp[daqp]``: ``prioik.solve(stack, "cascaded_qp", solver="daqp")``;
* ``equality floor``: ``extended_jacobian`` (prepared) on the same stack without its
  inequality rows (:func:`equality_part`): what any exact method pays to factorize the
  step's equality rows, whatever the active set (along a trajectory every row changes,
  so a warm start cannot skip that factorization);
* ``warm re-solve``: a third prepared ``hierarchical_active_set`` (warm-started) solves
  each stack twice in a row, the second solve timed: the warm start on data that did not
  change, against the equality floor (issue 46's ``≤ 1.2×``).

Times: each solver runs ``repeats`` passes over the trajectory in order (as a control
loop runs it), the passes of the five interleaved; per stack the fastest pass's
``perf_counter`` wall time, then the median over the stacks (each solver's first solve
before timing, BLAS limited to one thread). Ten passes by default (a pass of the five over the 24
stacks takes ~3 ms): with fewer, the fastest pass of a ~10 µs solve still carries the
noise of a shared machine. Beside the medians
(issue 13's targets), per stack against DAQP raw: the slowest stack's ratio, and the
ratio of the whole trajectory's times (where limits are active the active set iterates:
those steps weigh on both). Exactness: every level's ``‖w_i‖²`` of the active-set
answer against the strict reference's (relative to ``max(1, value)``):
:data:`STRICT_REFERENCE`, ``cascaded_qp`` on ProxQP at a tolerance of ``1e-12``, whose
answers meet every level the active set's meet to ``≤ 1.1e-10``. (``cascaded_qp[quadprog]``
at its defaults is not strict here: its regularization ``1e-12 ‖A_i‖_F²`` leaves the
higher levels up to ``2e-8`` unmet on the incompatible stacks, where the active set's
meet them to ``1e-14``, and gives the posture ``2e-8`` (relative) of it back.)

Also the whole G1 velocity IK step and the Panda reach with joint position and velocity
limits against PlaCo (:func:`g1_limits_step`, :func:`panda_limits_step`), and the G1
balance reach with the CoM over the support polygon
(:func:`prioik.benchmarks.balance_step.balance_step_times`, reported); :func:`run`
returns every row and the ratios against issue 13's targets (issue 46's where it set
tighter ones: warm ``≤ 0.25×`` DAQP raw, the re-solve ``≤ 1.2×`` the floor).

Run: ``python -m prioik.benchmarks.active_set_bench [--windows 4 --steps 6 --repeats 10
--ik-steps 300 --no-ik --no-stacks]``.
"""

from __future__ import annotations

import argparse
import math
import time
from ctypes import c_int
from typing import Any

import numpy as np

from .balance_step import balance_step_times

NAME = "hierarchical_active_set"
#: timing passes over each trajectory (per stack the fastest; see the module docstring)
REPEATS = 10


def bounds_stacks(variant: str, windows: int, steps: int, level: str
                  ) -> tuple[list, dict[int, Any]]:
    """Stacks with joint limits as bounds at ``windows × steps`` consecutive steps of
    the fencing run (``level``: ``"acceleration"`` or ``"velocity"``), in time order, and
    for each window the stack of the step before it, keyed by the window's first index
    in that list (:func:`measure`'s warm solver solves it, untimed, before the window:
    every timed warm solve then follows its own previous step, as in a control loop)."""
    from prioik.benchmarks.stacks import g1_fencing_samples
    from prioik.robots.tasks import KinematicState
    run_samples = g1_fencing_samples(variant, 2)
    run, scenario = run_samples.run, run_samples.scenario
    data = scenario.robot.model.createData()
    firsts = np.linspace(1, run.steps - steps, windows).round().astype(int)

    def stack(i: int):
        state = KinematicState(scenario.robot, run.q[i], run.v[i], data)
        t = float(run.t[i])
        if level == "acceleration":
            return scenario.acceleration_stack(state, t, limits="bounds").stack
        return scenario.velocity_stack(state, t, limits="bounds").stack

    out, before = [], {}
    for f in firsts:
        before[len(out)] = stack(f - 1)
        out += [stack(i) for i in range(f, f + steps)]
    return out, before


def equality_part(stack):
    """``stack`` without its inequality tasks (levels left empty dropped): the rows an
    exact method must factorize whatever the active set."""
    from prioik.hierarchy import TaskStack
    levels = [[t for t in level if t.kind == "equality"] for level in stack.levels]
    return TaskStack([level for level in levels if level])


#: the exactness reference of :func:`measure`: ``prioik.solve(stack, "cascaded_qp",
#: **STRICT_REFERENCE)`` (every G1 bounds stack ``optimal``; Clarabel at the same tolerance
#: fails 6 of the 96)
STRICT_REFERENCE = {"solver": "proxqp", "tolerance": 1e-12}


def _time(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def measure(stacks: list, repeats: int = REPEATS, cascade_every: int = 1,
            before: dict[int, Any] | None = None) -> dict[str, Any]:
    """Median per-solve times (s) of each solver on ``stacks`` and the active set's
    agreement with the strict reference (:data:`STRICT_REFERENCE`). ``before``: stacks
    the warm solver solves, untimed, before the stack of their index (the step before a
    window of :func:`bounds_stacks`)."""
    import daqp

    import prioik
    from prioik.formulations.daqp_hierarchical import build
    from prioik.hierarchy import lexicographic_residuals

    layout = stacks[0].layout
    keep = [i for i, s in enumerate(stacks) if s.layout == layout]
    same = [stacks[i] for i in keep]
    before = {j: before[i] for j, i in enumerate(keep) if before and i in before}
    cold = prioik.prepare(layout, NAME, warm_start=False)
    warm = prioik.prepare(layout, NAME)
    cold.solve(same[0])                       # the first solve before timing
    daqp_args = []
    for s in same:
        A, bu, bl, bps, _ = build(s, False, 1e-9)
        daqp_args.append((A, bu, bl, bps, np.zeros(len(bu), dtype=c_int)))

    def daqp_raw(i: int) -> None:
        A, bu, bl, bps, sense = daqp_args[i]
        daqp.solve(None, None, A, bu.copy(), bl.copy(), sense, break_points=bps,
                   primal_tol=1e-10, dual_tol=1e-12)

    # the floor of any exact method that factorizes each step's rows: the extended
    # Jacobian on the same stack without its inequality rows (joint-limit bounds)
    equality = [equality_part(s) for s in same]
    floor = prioik.prepare(equality[0].layout, "extended_jacobian")
    floor.solve(equality[0])
    # every solver as a control loop runs it: passes over the trajectory in order, the
    # passes of the five interleaved (same machine load); per stack the fastest pass
    again = prioik.prepare(layout, NAME)
    paths = {"cold": lambda i: cold.solve(same[i]), "warm": lambda i: warm.solve(same[i]),
             "daqp": daqp_raw, "floor": lambda i: floor.solve(equality[i]),
             "again": lambda i: again.solve(same[i])}
    # lexls (when built with its headers), its own C++ solve timed (no certificate): cold,
    # and hot-started from the previous step's x and working set, as its docs say
    lexls = lexls_available()
    if lexls:
        lexls_cold = prioik.prepare(layout, "lexls", hot_start=False, check=False)
        lexls_hot = prioik.prepare(layout, "lexls", check=False)
        lexls_cold.solve(same[0])
        paths.update({"lexls cold": lambda i: lexls_cold.solve(same[i]),
                      "lexls hot": lambda i: lexls_hot.solve(same[i])})
    times = {name: np.full(len(same), np.inf) for name in paths}
    for _ in range(repeats):
        for name, fn in paths.items():
            t = times[name]
            for i in range(len(same)):
                if name == "warm" and i in before:
                    warm.solve(before[i])   # the window's previous step (untimed)
                elif name == "lexls hot" and i in before:
                    lexls_hot.solve(before[i])
                if name == "again":
                    again.solve(same[i])    # the same stack first (untimed)
                t0 = time.perf_counter()
                fn(i)
                t[i] = min(t[i], time.perf_counter() - t0)
    t_cold, t_warm, t_daqp, t_floor = times["cold"], times["warm"], times["daqp"], times["floor"]
    t_again = times["again"]
    sub = same[::cascade_every]
    t_cas = [_time(lambda s=s: prioik.solve(s, "cascaded_qp", solver="daqp"), 1) for s in sub]
    worst, statuses, statuses_reference, cold_warm = 0.0, set(), set(), 0.0
    for i, s in enumerate(same):    # in order: the warm solver follows the trajectory
        if i in before:
            warm.solve(before[i])
        a = cold.solve(s)
        statuses.add(a.status)
        q = prioik.solve(s, "cascaded_qp", **STRICT_REFERENCE)
        statuses_reference.add(q.status)
        wa = lexicographic_residuals(s, a.x) ** 2
        wq = lexicographic_residuals(s, q.x) ** 2
        worst = max(worst, float(np.max(np.abs(wa - wq) / np.maximum(1.0, wq))))
        b = warm.solve(s)
        cold_warm = max(cold_warm, float(np.linalg.norm(a.x - b.x)
                                         / max(1.0, np.linalg.norm(a.x))))
    med = {k: float(np.median(v)) for k, v in (("active_set cold", t_cold),
                                               ("active_set warm", t_warm),
                                               ("daqp raw", t_daqp),
                                               ("equality floor", t_floor),
                                               ("warm re-solve", t_again),
                                               ("cascaded_qp[daqp]", t_cas))}
    # beyond the medians (the targets): the stack where each is slowest against DAQP, and
    # the whole trajectory's time (what a control loop spends), on the same passes
    per_cold, per_warm = t_cold / t_daqp, t_warm / t_daqp
    against_lexls = {}
    if lexls:
        t_lc, t_lh = times["lexls cold"], times["lexls hot"]
        capped = sum(lexls_cold.solve(s).detail.capped for s in same)
        med.update({"lexls cold": float(np.median(t_lc)), "lexls hot": float(np.median(t_lh))})
        against_lexls = {"cold/lexls_cold": med["active_set cold"] / med["lexls cold"],
                         "warm/lexls_hot": med["active_set warm"] / med["lexls hot"],
                         "worst cold vs lexls": float(t_cold.max() / t_lc.max()),
                         "worst warm vs lexls": float(t_warm.max() / t_lh.max()),
                         "lexls_capped": int(capped)}
    return {**against_lexls,"stacks": len(same), "n": layout.n, "rows": layout.m, "median_s": med,
            "worst cold/daqp_raw": float(per_cold.max()),
            "worst warm/daqp_raw": float(per_warm.max()),
            "total cold/daqp_raw": float(t_cold.sum() / t_daqp.sum()),
            "total warm/daqp_raw": float(t_warm.sum() / t_daqp.sum()),
            "cold/daqp_raw": med["active_set cold"] / med["daqp raw"],
            "warm/daqp_raw": med["active_set warm"] / med["daqp raw"],
            "floor/daqp_raw": med["equality floor"] / med["daqp raw"],
            "re-solve/floor": med["warm re-solve"] / med["equality floor"],
            "warm/cascaded_qp[daqp]": med["active_set warm"] / med["cascaded_qp[daqp]"],
            "cold/cascaded_qp[daqp]": med["active_set cold"] / med["cascaded_qp[daqp]"],
            "max_level_rel_diff_vs_reference": worst, "statuses": sorted(str(s) for s in statuses),
            "reference_statuses": sorted(str(s) for s in statuses_reference),
            "max_warm_vs_cold_rel": cold_warm}


def lexls_available() -> bool:
    """Whether the ``lexls`` formulation can run here (prioik built with its headers)."""
    from prioik.formulations import available
    return any(f.name == "lexls" and f.available for f in available())


def g1_limits_step(steps: int = 300, rounds: int = 5) -> dict[str, Any]:
    """The whole G1 velocity IK step with joint position and velocity limits, prioik's
    prepared path against PlaCo's ``KinematicsSolver`` step with the same limits.

    prioik: six strict levels (support foot, joint-limit bounds on ``q̇`` — ``q + q̇ dt``
    within the position limits, ``|q̇| ≤ q̇_max`` —, CoM, left foot, sword tip, posture),
    the scenario's writers
    (:meth:`~prioik.robots.fencing.FencingScenario.velocity_rows` ``limits="bounds"``)
    and a ``hierarchical_active_set`` solver prepared once (warm-started), two ways:
    :class:`~prioik.robots.ControlStep` (the references of
    :meth:`~prioik.robots.fencing.FencingScenario.step_references`, then one step: the
    ratio's path) and the writer loop it compiles (``KinematicState(drift=False)`` + the
    writers + ``PreparedSolver.solve``, its parts timed; checked to give the same
    answers). PlaCo:
    ``update_kinematics`` + target updates + ``KinematicsSolver.solve(True)`` with
    ``enable_joint_limits`` and ``enable_velocity_limits``
    (:func:`prioik.benchmarks.placo_baseline.run_placo`), at the same states (PlaCo's
    trajectory). Both are timed in ``rounds`` passes over the trajectory, PlaCo's and
    prioik's passes interleaved (PlaCo's run repeated from the start: it is
    deterministic), the fastest pass's median reported for each."""
    import prioik
    from prioik.robots import ControlStep
    from prioik.robots.fencing import FencingScenario
    from prioik.robots.tasks import KinematicState
    from prioik.smoke import cap

    from .placo_baseline import run_placo
    from .placo_step import DT, GAIN

    rounds = cap(rounds, 1)                  # PRIOIK_SMOKE=1: PlaCo set up twice, not 6 times
    scenario = FencingScenario("compatible")
    robot = scenario.robot
    placo_run = run_placo(scenario, duration=steps * DT, dt=DT)
    if placo_run.failed or placo_run.steps == 0:
        raise RuntimeError(f"PlaCo's run failed: {placo_run.message}")
    placo = placo_run.kinematics_time_s + placo_run.solve_time_s
    states = [(placo_run.q[i], placo_run.v[i], float(placo_run.t[i]))
              for i in range(placo_run.steps)]
    data = robot.model.createData()
    rows = scenario.velocity_rows(GAIN, limits="bounds", dt=DT)
    solver = prioik.prepare(rows.layout, NAME)
    control = ControlStep(scenario.velocity_rows(GAIN, limits="bounds", dt=DT), NAME, dt=DT)
    scenario.step_references(control, 0.0)
    statuses = set()
    best = None
    best_control = None
    placo_kin, placo_solve = placo_run.kinematics_time_s, placo_run.solve_time_s
    for r in range(rounds):
        if r > 0:
            again = run_placo(scenario, duration=steps * DT, dt=DT)
            step = again.kinematics_time_s + again.solve_time_s
            if again.steps == placo_run.steps and np.median(step) < np.median(placo):
                placo, placo_kin, placo_solve = step, again.kinematics_time_s, again.solve_time_s
        times = np.empty((3, len(states)))
        for i, (q, v, t) in enumerate(states):
            t0 = time.perf_counter()
            state = KinematicState(robot, q, v, data, drift=False)
            t1 = time.perf_counter()
            d = scenario.write_rows(rows, state, t)
            t2 = time.perf_counter()
            sol = solver.solve(d)
            t3 = time.perf_counter()
            statuses.add(sol.status)
            times[:, i] = (t1 - t0, t2 - t1, t3 - t2)
        if best is None or np.median(times.sum(0)) < np.median(best.sum(0)):
            best = times
        control_times = np.empty(len(states))
        for i, (q, _v, t) in enumerate(states):
            t0 = time.perf_counter()
            scenario.step_references(control, t, fixed=False)
            control(q)
            control_times[i] = time.perf_counter() - t0
        if best_control is None or np.median(control_times) < np.median(best_control):
            best_control = control_times
    solver.reset()                    # both from a cold start: the same steps
    control.reset()
    for q, v, t in states:
        sol = solver.solve(scenario.write_rows(rows, KinematicState(robot, q, v, data,
                                                                    drift=False), t))
        scenario.step_references(control, t, fixed=False)
        control(q)
        if not np.allclose(control.velocity, sol.x, rtol=1e-12, atol=1e-12):
            raise RuntimeError(f"ControlStep and the writer loop differ at t = {t}")
    step = best.sum(0)
    return {"steps": len(states), "layout": rows.layout.describe(),
            "prioik_step_us": float(np.median(best_control)) * 1e6,
            "prioik_writer_loop_us": float(np.median(step)) * 1e6,
            "prioik_kinematics_us": float(np.median(best[0])) * 1e6,
            "prioik_rows_us": float(np.median(best[1])) * 1e6,
            "prioik_solve_us": float(np.median(best[2])) * 1e6,
            "placo_step_us": float(np.median(placo)) * 1e6,
            "placo_kinematics_us": float(np.median(placo_kin)) * 1e6,
            "placo_solve_us": float(np.median(placo_solve)) * 1e6,
            "statuses": sorted(str(s) for s in statuses)}


def panda_limits_step(steps: int = 300, rounds: int = 7) -> dict[str, Any]:
    """The 9-DoF Panda reach of :mod:`prioik.benchmarks.panda_step` with joint position
    and velocity limits (joint-limit bounds on ``q̇`` above the hand position above the
    posture, ``hierarchical_active_set``, warm-started) against PlaCo's
    ``KinematicsSolver`` (the same soft tasks, ``enable_joint_limits`` and
    ``enable_velocity_limits``), at PlaCo's states, interleaved rounds (fastest round's
    median per path). prioik's step two ways: the README's loop,
    :class:`~prioik.robots.ControlStep` (kinematics, rows, solve and ``q ⊕ q̇ dt`` in
    one compiled call after pinocchio's Jacobians), and the writer loop it compiles
    (``KinematicState`` + the writers + ``PreparedSolver.solve`` + ``pin.integrate``).

    Raises:
        RuntimeError: the two prioik paths give different steps.
    """
    import pinocchio as pin

    import prioik
    from prioik.robots import ControlStep, KinematicState, load

    from .panda_step import DT, HAND_TARGET, _rounds, placo_panda, reach_rows

    robot = load("panda")
    model, q0, nv = robot.model, robot.q0, robot.nv
    placo_step, states, placo_reset = placo_panda(robot, steps, limits=True)

    data = model.createData()
    zero = np.zeros(nv)
    rows = reach_rows(robot, limits=True)
    solver = prioik.prepare(rows.layout, NAME)
    step = ControlStep(reach_rows(robot, limits=True), NAME, dt=DT)
    step.reference("hand", HAND_TARGET)
    step.reference("posture", q0)
    statuses = set()
    loop_q: list = [None] * steps
    step_q: list = [None] * steps

    def writer_loop(i: int) -> None:
        state = KinematicState(robot, states[i], zero, data, drift=False)
        rows.joint_limits(state, "joint_limits")
        rows.frame_position(state, "hand", HAND_TARGET)
        rows.posture(state, "posture", q0)
        sol = solver.solve(rows.targets(state))
        loop_q[i] = pin.integrate(model, states[i], sol.x * DT)
        statuses.add(sol.status)

    def control_step(i: int) -> None:
        step_q[i] = step(states[i])

    for path in (writer_loop, control_step, placo_step):
        for i in range(min(50, steps)):
            path(i)
    placo_reset()
    best = _rounds({"control_step": control_step, "writer_loop": writer_loop,
                    "placo": placo_step}, steps, rounds)
    solver.reset()                  # both from a cold start: the same steps
    step.reset()
    for i in range(steps):
        writer_loop(i)
        control_step(i)
        if not np.allclose(step_q[i], loop_q[i], rtol=1e-12, atol=1e-12):
            raise RuntimeError(f"ControlStep and the writer loop differ at step {i}")
    return {"steps": steps,
            "prioik_step_us": float(np.median(best["control_step"])) * 1e6,
            "prioik_writer_loop_us": float(np.median(best["writer_loop"])) * 1e6,
            "placo_step_us": float(np.median(best["placo"])) * 1e6,
            "statuses": sorted(str(s) for s in statuses)}


def run(windows: int = 4, steps: int = 6, repeats: int = REPEATS, ik_steps: int = 300,
        stacks: bool = True, ik: bool = True) -> dict[str, Any]:
    """Every timing of this module in one run: :func:`measure` on both fencing variants
    at acceleration and velocity level (``stacks``), :func:`g1_limits_step` and
    :func:`panda_limits_step` (``ik``), and the ratios against issue 13's targets.

    Returns:
        ``{"rows": [...], "g1_step": {...}, "panda_step": {...}, "ratios": [...]}``; each
        ratio a dict ``name, value, target`` (``value ≤ target`` meets it).
    """
    from prioik.threads import blas_threads
    out: dict[str, Any] = {"rows": [], "ratios": []}
    with blas_threads(1):
        if stacks:
            for variant in ("compatible", "incompatible"):
                for level in ("acceleration", "velocity"):
                    trajectory, before = bounds_stacks(variant, windows, steps, level)
                    res = measure(trajectory, repeats, before=before)
                    res.update(variant=variant, level=level)
                    out["rows"].append(res)
        if ik:
            out["g1_step"] = g1_limits_step(ik_steps)
            out["panda_step"] = panda_limits_step(ik_steps)
            out["balance_step"] = balance_step_times(ik_steps)
    for r in out["rows"]:
        tag = f"{r['variant']} {r['level']}"
        out["ratios"] += [
            {"name": f"active_set cold / DAQP raw ({tag})", "value": r["cold/daqp_raw"],
             "target": 1.0},
            # issue 46's target
            {"name": f"active_set warm / DAQP raw ({tag})", "value": r["warm/daqp_raw"],
             "target": 0.25},
            {"name": f"active_set warm / cascaded_qp[daqp] ({tag})",
             "value": r["warm/cascaded_qp[daqp]"], "target": 0.03},
            {"name": f"active_set warm re-solve of unchanged data / equality floor ({tag})",
             "value": r["re-solve/floor"], "target": 1.2}]
        if "cold/lexls_cold" in r:
            out["ratios"] += [
                {"name": f"active_set cold / lexls cold ({tag})",
                 "value": r["cold/lexls_cold"], "target": 0.5},
                {"name": f"active_set warm / lexls hot ({tag})",
                 "value": r["warm/lexls_hot"], "target": 0.5}]
    for key, what, target in (("g1_step", "G1 velocity IK step with limits", 0.8),
                              ("panda_step", "Panda reach with limits", 1.0)):
        if key in out:
            s = out[key]
            out["ratios"].append({"name": f"{what} / PlaCo", "target": target,
                                  "value": s["prioik_step_us"] / s["placo_step_us"]})
    for key, what in (("g1_step", "G1 velocity IK step with limits"),
                      ("panda_step", "Panda reach with limits")):
        if key in out:         # the writer loop ControlStep compiles: reported
            s = out[key]
            out["ratios"].append({"name": f"{what}, the writer loop / PlaCo",
                                  "target": math.inf,
                                  "value": s["prioik_writer_loop_us"] / s["placo_step_us"]})
    if "balance_step" in out:      # no target of issue 13's: reported
        s = out["balance_step"]
        out["ratios"] += [
            {"name": "G1 balance reach step (feet, limits, CoM polygon), each on its own "
                     "loop / PlaCo", "target": math.inf,
             "value": s["prioik_step_us"] / s["placo_step_us"]},
            {"name": "G1 balance reach step, prioik at PlaCo's states / PlaCo",
             "target": math.inf,
             "value": s["prioik_at_placo_states_us"] / s["placo_step_us"]}]
    return out


def format_table(results: dict[str, Any]) -> str:
    """Markdown tables of :func:`run`'s result."""
    head = ("| stacks | n, rows | cold µs | warm µs | DAQP raw µs | cascaded_qp[daqp] µs | "
            "equality floor µs | cold/raw | warm/raw | floor/raw | warm/cascade | "
            "max Δ‖w‖² vs strict reference |")
    lines = [head, "|" + "---|" * 12] if results["rows"] else []
    for r in results["rows"]:
        m = r["median_s"]
        lines.append(f"| {r['variant']} {r['level']} ({r['stacks']}) | {r['n']}, {r['rows']} | "
                     f"{m['active_set cold'] * 1e6:.1f} | {m['active_set warm'] * 1e6:.1f} | "
                     f"{m['daqp raw'] * 1e6:.1f} | {m['cascaded_qp[daqp]'] * 1e6:.0f} | "
                     f"{m['equality floor'] * 1e6:.1f} | "
                     f"{r['cold/daqp_raw']:.2f} | {r['warm/daqp_raw']:.2f} | "
                     f"{r['floor/daqp_raw']:.2f} | "
                     f"{r['warm/cascaded_qp[daqp]']:.3f} | "
                     f"{r['max_level_rel_diff_vs_reference']:.1e} |")
    if results["rows"]:
        lines += ["", "Beyond the medians, against DAQP raw on the same passes (not targets): "
                  "the slowest stack's ratio, and the whole trajectory's time (Σ over the "
                  "stacks).", "",
                  "| stacks | worst cold/raw | worst warm/raw | Σ cold / Σ raw | "
                  "Σ warm / Σ raw |", "|---|---|---|---|---|"]
        for r in results["rows"]:
            lines.append(f"| {r['variant']} {r['level']} | {r['worst cold/daqp_raw']:.2f} | "
                         f"{r['worst warm/daqp_raw']:.2f} | "
                         f"{r['total cold/daqp_raw']:.2f} | "
                         f"{r['total warm/daqp_raw']:.2f} |")
    if any("cold/lexls_cold" in r for r in results["rows"]):
        lines += ["", "Against lexls (the C++ lexicographic solver, built from its headers, "
                  "its defaults; its solve timed alone, cold and hot-started from the "
                  "previous step's x and working set), on the same passes:", "",
                  "| stacks | lexls cold µs | lexls hot µs | cold / lexls cold | "
                  "warm / lexls hot | slowest cold / lexls's slowest | "
                  "slowest warm / lexls's slowest | lexls capped |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in results["rows"]:
            if "cold/lexls_cold" not in r:
                continue
            m = r["median_s"]
            lines.append(f"| {r['variant']} {r['level']} | {m['lexls cold'] * 1e6:.1f} | "
                         f"{m['lexls hot'] * 1e6:.1f} | {r['cold/lexls_cold']:.2f} | "
                         f"{r['warm/lexls_hot']:.2f} | {r['worst cold vs lexls']:.2f} | "
                         f"{r['worst warm vs lexls']:.2f} | {r['lexls_capped']} |")
    for key, what in (("g1_step", "G1 velocity IK step, limits"),
                      ("panda_step", "Panda reach, limits")):
        if key in results:
            s = results[key]
            extra = (f", of which kinematics {s['prioik_kinematics_us']:.1f}, rows "
                     f"{s['prioik_rows_us']:.1f}, solve {s['prioik_solve_us']:.1f}"
                     if "prioik_solve_us" in s else "")
            extra = (f" (ControlStep; the writer loop it compiles "
                     f"{s['prioik_writer_loop_us']:.1f} µs{extra})")
            lines.append(f"\n{what}: prioik prepared {s['prioik_step_us']:.1f} µs{extra}, "
                         f"PlaCo {s['placo_step_us']:.1f} µs, statuses {s['statuses']}")
    if "balance_step" in results:
        s = results["balance_step"]
        lines.append(f"\nG1 balance reach (feet, limits, CoM polygon): prioik prepared "
                     f"{s['prioik_step_us']:.1f} µs on its own loop, "
                     f"{s['prioik_at_placo_states_us']:.1f} µs at PlaCo's states; PlaCo "
                     f"{s['placo_step_us']:.1f} µs; CoM past the polygon: prioik "
                     f"{s['prioik_com_excursion_m']:.1e} m, PlaCo "
                     f"{s['placo_com_excursion_m']:.1e} m; hand error: prioik "
                     f"{s['prioik_hand_error_m']:.1e} m, PlaCo {s['placo_hand_error_m']:.1e} m;"
                     f" equality-first {100 * s['equality_first_share']:.0f}% of prioik's "
                     f"own steps; statuses {s['statuses']}")
    lines.append("")
    for r in results["ratios"]:
        if math.isinf(r["target"]):
            lines.append(f"- {r['name']}: {r['value']:.3f} (reported)")
            continue
        ok = "met" if r["value"] <= r["target"] else "MISSED"
        lines.append(f"- {r['name']}: {r['value']:.3f} (target ≤ {r['target']}) {ok}")
    return "\n".join(lines)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--windows", type=int, default=4, help="stretches of the run")
    p.add_argument("--steps", type=int, default=6, help="consecutive steps per stretch")
    p.add_argument("--repeats", type=int, default=REPEATS, help="timing passes (per stack the "
                   "fastest)")
    p.add_argument("--ik-steps", type=int, default=300, help="IK steps (G1, Panda)")
    p.add_argument("--no-ik", action="store_true", help="skip the IK-step timings")
    p.add_argument("--no-stacks", action="store_true", help="skip the G1 bounds stacks")
    a = p.parse_args(argv)
    from prioik.extras import MissingExtraError, require
    try:
        require("robots", "qp", what="active_set_bench")
        if not a.no_ik:
            require("placo", what="active_set_bench's IK steps (or --no-ik)")
    except MissingExtraError as exc:
        raise SystemExit(f"active_set_bench: error: {exc}") from None
    results = run(a.windows, a.steps, a.repeats, a.ik_steps, stacks=not a.no_stacks,
                  ik=not a.no_ik)
    print(format_table(results))
    for r in results["rows"]:
        print(r["variant"], r["level"], "statuses", r["statuses"], "warm vs cold",
              f"{r['max_warm_vs_cold_rel']:.1e}")

if __name__ == "__main__":
    main()
