"""robots.simulate: the loop integrates, records, times and stops cleanly."""

from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from prioik import formulations
from prioik.hierarchy import Task, TaskStack, algorithmic_error_norms
from prioik.robots import (
    Reference,
    SimulationError,
    StepTasks,
    equality_view,
    frame_position,
    posture,
    simulate,
    spatial_chain,
)

TARGET = np.array([1.2, 0.6, 0.4])


@pytest.fixture(scope="module")
def chain():
    return spatial_chain(6)


def _build(robot):
    def build(state, t):
        tip = frame_position(state, "tip", Reference(TARGET, np.zeros(3), np.zeros(3)),
                             name="tip")
        stack = TaskStack([tip.acceleration(25.0, 10.0),
                           posture(state, robot.q0).acceleration(1.0, 2.0)])
        return StepTasks(stack, {"tip_error": float(np.linalg.norm(tip.error))})
    return build


def test_tip_converges_and_everything_is_recorded(chain):
    res = simulate(chain, _build(chain),
                   lambda s, **kw: formulations.solve(s, "extended_jacobian"),
                   duration=2.0, dt=0.002)
    assert not res.failed and res.steps == 1000 and res.message == ""
    assert res.q.shape == (1000, 6) and res.v.shape == res.a.shape == res.tau.shape
    assert res.errors["tip_error"][0] > 0.5 and res.errors["tip_error"][-1] < 1e-3
    assert np.all(res.kinematics_time_s > 0) and np.all(res.solve_time_s > 0)
    assert np.all(res.torque_time_s > 0)     # RNEA ran at every step (it takes µs)
    assert np.allclose(res.step_time_s, res.kinematics_time_s + res.solve_time_s
                       + res.torque_time_s)
    # an exact solution of a compatible-then-conflicting stack: no algorithmic error
    assert np.nanmax(res.algorithmic_error) < 1e-8
    # semi-implicit Euler: v_{k+1} = v_k + a_k dt, q_{k+1} = q_k + v_{k+1} dt
    k = 500
    assert np.allclose(res.v[k + 1], res.v[k] + res.a[k] * 0.002, atol=1e-12)
    assert np.allclose(res.q[k + 1], res.q[k] + res.v[k + 1] * 0.002, atol=1e-12)
    # RNEA torques: τ = M(q) q̈ + b(q, q̇)
    d = chain.model.createData()
    M = pin.crba(chain.model, d, res.q[k])
    M = np.triu(M) + np.triu(M, 1).T
    b = pin.nonLinearEffects(chain.model, d, res.q[k], res.v[k])
    assert np.allclose(res.tau[k], M @ res.a[k] + b, atol=1e-9)


def test_torque_law_of_the_formulation_is_used(chain):
    seen = {}

    def solve(stack, **kw):
        seen.update(kw)
        return SimpleNamespace(x=np.zeros(stack.n), status="optimal",
                               diagnostics=SimpleNamespace(
                                   detail=SimpleNamespace(tau=np.full(stack.n, 7.0))))

    res = simulate(chain, _build(chain), solve, duration=0.01, dt=0.002,
                   needs_dynamics=True, torque_from_solution=True)
    assert set(seen) == {"mass_matrix", "bias"} and seen["mass_matrix"].shape == (6, 6)
    assert np.allclose(seen["mass_matrix"], seen["mass_matrix"].T)
    assert not res.failed and res.steps == 5 and np.all(res.tau == 7.0)


def test_failed_or_nonfinite_solution_stops_cleanly(chain):
    calls = []

    def solve(stack, **kw):
        calls.append(1)
        x = np.zeros(stack.n) if len(calls) < 4 else np.full(stack.n, np.nan)
        return SimpleNamespace(x=x, status="optimal")

    res = simulate(chain, _build(chain), solve, duration=1.0, dt=0.01)
    assert res.failed and res.steps == 3 and "t = 0.030" in res.message
    res = simulate(chain, _build(chain),
                   lambda s, **kw: SimpleNamespace(
                       x=np.zeros(s.n), status="failed",
                       diagnostics=SimpleNamespace(reason="boom")),
                   duration=1.0, dt=0.01)
    assert res.failed and res.steps == 0 and "boom" in res.message


def test_inputs_are_not_mutated(chain):
    q0 = chain.q0.copy()
    v0 = np.full(6, 0.1)
    v_in = v0.copy()
    simulate(chain, _build(chain), lambda s, **kw: formulations.solve(s, "extended_jacobian"),
             duration=0.02, dt=0.002, v0=v0)
    assert np.array_equal(chain.q0, q0) and np.array_equal(v0, v_in)
    with pytest.raises(ValueError, match="dt"):
        simulate(chain, _build(chain), None, duration=1.0, dt=0.0)


def test_equality_view_keeps_active_bounds():
    A = np.eye(3)
    stack = TaskStack([Task("eq", [[1.0, 1.0, 0.0]], [1.0]),
                       Task("box", A, lower=[0.0, 0.0, -1.0], upper=[0.5, 2.0, 1.0]),
                       Task("low", [[0.0, 0.0, 1.0]], [3.0])])
    x = np.array([0.5, 0.5, 1.0])          # row 0 at its upper bound, row 2 at its upper
    eq = equality_view(stack, x)
    assert [lv.names for lv in eq.levels] == [("eq",), ("box",), ("low",)]
    box = eq.levels[1][0]
    assert np.array_equal(box.A, A[[0, 2]]) and np.array_equal(box.b, [0.5, 1.0])
    # x is the lexicographic optimum of that view: no algorithmic error
    assert max(algorithmic_error_norms(eq, x)) < 1e-12
    inner = np.array([0.25, 0.75, 0.0])
    eq2 = equality_view(stack, inner)
    assert [lv.names for lv in eq2.levels] == [("eq",), ("low",)]
    assert equality_view(eq2, inner) is eq2


def test_velocity_level_integrates_the_solved_velocity(chain):
    def build(state, t):
        tip = frame_position(state, "tip", Reference(TARGET, np.zeros(3), np.zeros(3)),
                             name="tip")
        stack = TaskStack([tip.velocity(5.0), posture(state, chain.q0).velocity(1.0)])
        return StepTasks(stack, {"tip_error": float(np.linalg.norm(tip.error))})

    res = simulate(chain, build, lambda s, **kw: formulations.solve(s, "extended_jacobian"),
                   duration=1.0, dt=0.002, level="velocity")
    assert not res.failed and res.steps == 500
    # the tip error decays like exp(-5 t) (up to the Euler step): e(1) ≈ e(0)·e^-5
    assert res.errors["tip_error"][-1] < 1.2 * np.exp(-5.0 * 0.998) * res.errors["tip_error"][0]
    k = 200
    assert np.allclose(res.a[k], (res.v[k + 1] - res.v[k]) / 0.002, atol=1e-9)
    assert np.allclose(res.q[k + 1], res.q[k] + res.v[k + 1] * 0.002, atol=1e-12)
    with pytest.raises(ValueError, match="level"):
        simulate(chain, build, None, duration=0.1, dt=0.01, level="jerk")


def _answer_at_step(bad, at: int = 3):
    """A solver that answers zeros, then ``bad(stack)`` from call ``at`` on."""
    calls = []

    def solve(stack, **kw):
        calls.append(1)
        if len(calls) <= at:
            return SimpleNamespace(x=np.zeros(stack.n), status="optimal")
        return bad(stack)
    return solve


def _raise(stack):
    raise RuntimeError("solver exploded")


@pytest.mark.parametrize("bad, message", [
    (_raise, "solve raised RuntimeError: solver exploded"),
    (lambda s: SimpleNamespace(x=np.full(s.n, np.nan), status="optimal"),
     "non-finite values at [0, 1, 2, 3, 4] although its status is 'optimal'"),
    (lambda s: SimpleNamespace(x=np.zeros(s.n + 1), status="optimal"),
     "solution x has shape (7,), expected (6,)"),
    (lambda s: SimpleNamespace(x=None, status="optimal"),
     "solution x has shape (), expected (6,)"),
    (lambda s: None, "status None"),
    (lambda s: SimpleNamespace(x=np.zeros(s.n), status="great"), "status 'great'"),
    (lambda s: SimpleNamespace(x=np.zeros(s.n), status="failed",
                               diagnostics=SimpleNamespace(reason="boom")),
     "solution failed: boom"),
    (lambda s: SimpleNamespace(x=["a"] * s.n, status="optimal"),
     "solution x cannot be read as numbers"),
])
def test_a_solver_error_or_bad_answer_ends_the_run_with_the_trajectory(chain, bad, message):
    res = simulate(chain, _build(chain), _answer_at_step(bad), duration=1.0, dt=0.01)
    assert res.failed and res.failed_step == 3
    assert message in res.message and "t = 0.030 s (step 3)" in res.message, res.message
    assert res.steps == 3 and res.q.shape == (3, 6) and len(res.statuses) == 3
    assert np.isfinite(res.q).all() and np.isfinite(res.tau).all()


def test_a_build_error_ends_the_run_with_the_trajectory(chain):
    inner = _build(chain)

    def build(state, t):
        if t > 0.015:
            raise KeyError("no frame 'hand'")
        return inner(state, t)

    res = simulate(chain, build, lambda s, **kw: formulations.solve(s, "extended_jacobian"),
                   duration=1.0, dt=0.01)
    assert res.failed and res.failed_step == 2 and res.steps == 2
    assert "build raised KeyError" in res.message


def test_torque_from_solution_without_tau_fails_the_run(chain):
    res = simulate(chain, _build(chain),
                   lambda s, **kw: SimpleNamespace(x=np.zeros(s.n), status="optimal"),
                   duration=0.1, dt=0.01, torque_from_solution=True)
    assert res.failed and res.failed_step == 0 and "no diagnostics.detail.tau" in res.message


@pytest.mark.parametrize("duration, dt, message", [
    (float("inf"), 0.01, "duration must be a finite number > 0"),     # was OverflowError
    (1.0, float("nan"), "dt must be a finite number > 0"),
    (-1.0, 0.01, "duration must be a finite number > 0"),
    (0.01, 0.1, "longer than duration"),                              # was 0 steps, not failed
    (None, 0.01, "duration must be a finite number > 0"),
])
def test_bad_duration_or_step_is_refused(chain, duration, dt, message):
    with pytest.raises(SimulationError, match=message):
        simulate(chain, _build(chain), None, duration=duration, dt=dt)


def test_rows_written_in_place_keep_each_steps_algorithmic_error(chain):
    """A build that writes one StackData in place (as prepared writers do): the loop
    copies each step's rows for the algorithmic error computed after the run (in
    blocks of _RowRecord.CHUNK steps), which equals that of fresh stacks, step by step,
    across block boundaries."""
    from prioik.robots.simulate import _RowRecord
    fresh_build = _build(chain)
    written = {}

    def in_place(state, t):
        step = fresh_build(state, t)
        data = written.setdefault("data", step.stack.layout.data())
        for key in ("A", "b", "lower", "upper", "sqrt_weight"):
            getattr(data, key)[...] = getattr(step.stack.data, key)
        return StepTasks(data, step.errors)

    # eq. 27's damping leaves an algorithmic error that changes from step to step
    def solve(s, **kw):
        return formulations.solve(s, "extended_jacobian", damping=0.05)

    steps = _RowRecord.CHUNK + 44
    runs = [simulate(chain, build, solve, duration=steps * 0.002, dt=0.002)
            for build in (fresh_build, in_place)]
    assert all(r.steps == steps and not r.failed for r in runs)
    errors = [r.algorithmic_error for r in runs]
    assert np.all(errors[0][10:] > 1e-7) and np.ptp(errors[0]) > 1e-3
    np.testing.assert_array_equal(errors[1], errors[0])


def test_simulation_steps_yields_each_step_and_returns_simulates_result(chain):
    """The step generator (what run_scenario advances in turns) checks its arguments
    before the first step, yields once per step and returns what simulate returns."""
    from prioik.robots import run_to_end, simulation_steps
    solve = lambda s, **kw: formulations.solve(s, "extended_jacobian")   # noqa: E731
    with pytest.raises(SimulationError, match="level must be"):
        simulation_steps(chain, _build(chain), solve, duration=0.1, dt=0.002, level="torque")
    steps = simulation_steps(chain, _build(chain), solve, duration=0.1, dt=0.002)
    assert [next(steps) for _ in range(3)] == [0, 1, 2]
    rest = run_to_end(steps)
    whole = simulate(chain, _build(chain), solve, duration=0.1, dt=0.002)
    assert rest.steps == whole.steps == 50
    np.testing.assert_array_equal(rest.q, whole.q)
    np.testing.assert_array_equal(rest.a, whole.a)
    np.testing.assert_array_equal(rest.errors["tip_error"], whole.errors["tip_error"])
