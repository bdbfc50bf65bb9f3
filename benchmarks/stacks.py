"""How benchmark stacks are drawn: random families over ``(n, k)`` and the G1 fencing
stacks at states sampled along a simulated run.

Random cases use :mod:`hierarchy.families` (default ``conflicting``: about a third of
each lower level's rows are combinations of higher rows, so levels lose rank and
compete, ``Σ m_i ≈ 1.3 n``). Formulations that need a mass matrix get one fixed SPD
``M`` per ``n`` on random stacks (:func:`random_mass_matrix`) and the robot's
``M(q)`` (``pin.crba``) on robot stacks.

The G1 cases need :mod:`robots` (pinocchio and example-robot-data); when it cannot be
imported, :func:`g1_fencing_cases` returns no case and the reason, and the benchmark
runs the random part alone.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from prioik.hierarchy import TaskStack
from prioik.hierarchy.families import FAMILIES, random_spd

__all__ = ["Case", "random_mass_matrix", "random_case", "FencingSamples",
           "g1_fencing_samples", "g1_fencing_cases", "G1_DURATION_S",
           "TIP_STEP_BOUND"]

#: Bound (rad/s²) on the sword-tip level's step in the incompatible
#: ``extended_jacobian[step_bound]`` run (its ``step_bound``). Measured over 3 s (max
#: ‖q̈‖ / final tip error): Δ = 5: 76 / 385 mm, 10: 55 / 382 mm, 20: 142 / 375 mm; support
#: foot, CoM and joint limits exact in all three. Bounding every level instead also caps
#: the joint-limit rows (targets of hundreds of rad/s²) and lets joints pass their
#: limits by 0.3 rad.
TIP_STEP_BOUND = 10.0
#: simulated time of the fencing run whose states are sampled (covers the step and the
#: sword move, 0.2-2.5 s)
G1_DURATION_S = 3.0
#: what drives the sampled run of each variant: ``reference`` where the tasks are
#: compatible; where they are not, the exact methods' accelerations blow up at the
#: algorithmic singularity (t ≈ 1.8 s), so the run uses ``prioik fencing``'s
#: ``extended_jacobian[step_bound]`` (the sword-tip step bound)
G1_DRIVERS = {"compatible": ("reference", {}),
              "incompatible": ("extended_jacobian",
                               {"step_bound": {"sword_tip": TIP_STEP_BOUND}})}


@dataclass
class Case:
    """Stacks a formulation is timed on (solved in turn), with what they need.

    Attributes:
        suite: ``"random"`` or ``"g1"``.
        name: Unique label, e.g. ``"random n=35 k=4"`` or ``"g1 compatible"``.
        n: Columns of every stack.
        k: Levels (the most common count for G1 samples).
        rows: Total rows ``Σ m_i`` (median over the stacks).
        stacks: The stacks.
        mass_matrices: One SPD ``M`` per stack (for formulations that need it).
        note: How the stacks were drawn.
    """

    suite: str
    name: str
    n: int
    k: int
    rows: int
    stacks: list[TaskStack]
    mass_matrices: list[np.ndarray]
    note: str = ""


def random_mass_matrix(n: int, seed: int = 0) -> np.ndarray:
    """A fixed SPD ``n × n`` matrix ``Q diag(λ) Qᵀ`` with ``λ`` log-spaced in ``[0.1, 10]``
    (condition number 100) and ``Q`` a seeded random rotation."""
    M = 0.1 * random_spd(np.random.default_rng(10_000 + seed), n, 100.0)
    M.setflags(write=False)
    return M


def random_case(n: int, k: int, samples: int = 8, family: str = "conflicting",
                seed: int = 0) -> Case:
    """``samples`` stacks of :data:`hierarchy.families.FAMILIES` ``[family]`` with ``n``
    columns and ``k`` levels, seeded by ``(seed, n, k, i)``."""
    if family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; known: {', '.join(FAMILIES)}")
    stacks = [FAMILIES[family](np.random.default_rng([seed, n, k, i]), n, k)
              for i in range(samples)]
    M = random_mass_matrix(n, seed)
    rows = int(np.median([sum(lvl.m for lvl in s.levels) for s in stacks]))
    return Case("random", f"random n={n} k={k}", n, k, rows, stacks, [M] * len(stacks),
                f"{samples} `{family}` stacks; fixed SPD M (eigenvalues 0.1-10)")


@dataclass
class FencingSamples:
    """States of one simulated fencing run and their acceleration-level stacks.

    Attributes:
        variant: ``"compatible"`` or ``"incompatible"``.
        times: Simulated times of the samples (s).
        stacks: The stack of each sample (joint limits as activation rows, so every
            equality formulation can take it).
        mass_matrices: ``M(q)`` of each sample.
        scenario: The :class:`robots.fencing.FencingScenario`.
        states: ``(q, v)`` of each sample.
        run: The whole simulated run (:class:`robots.simulate.SimulationResult`).
    """

    variant: str
    times: np.ndarray
    stacks: list[TaskStack]
    mass_matrices: list[np.ndarray]
    scenario: object
    states: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    run: object = None

    def stacks_at(self, count: int) -> list[TaskStack]:
        """Stacks at ``count`` states evenly spread over the whole run (at most one
        per simulated step)."""
        from prioik.robots.tasks import KinematicState
        run, scenario = self.run, self.scenario
        pick = np.unique(np.linspace(0, run.steps - 1, count).round().astype(int))
        data = scenario.robot.model.createData()
        return [scenario.acceleration_stack(KinematicState(scenario.robot, run.q[i],
                                                           run.v[i], data),
                                            float(run.t[i])).stack for i in pick]


def _mass_matrix(model, data, q) -> np.ndarray:
    import pinocchio as pin
    M = np.array(pin.crba(model, data, q))
    M = np.triu(M) + np.triu(M, 1).T
    M.setflags(write=False)
    return M


def g1_fencing_samples(variant: str, samples: int, dt: float = 0.005,
                       duration: float = G1_DURATION_S) -> FencingSamples:
    """Simulate the fencing scenario (driven as :data:`G1_DRIVERS` says) and build the
    stacks at ``samples`` states evenly spread over the run.

    Raises:
        ImportError: :mod:`robots` (pinocchio, example-robot-data) is not installed.
        RuntimeError: the simulated run failed.
    """
    from prioik import formulations
    from prioik.robots.fencing import FencingScenario
    from prioik.robots.simulate import simulate
    from prioik.robots.tasks import KinematicState
    from prioik.smoke import SAMPLED_RUN_S, cap
    duration = cap(duration, SAMPLED_RUN_S)              # PRIOIK_SMOKE=1: a few steps
    scenario = FencingScenario(variant)
    robot = scenario.robot
    driver, options = G1_DRIVERS.get(variant, ("reference", {}))
    run = simulate(robot, lambda state, t: scenario.acceleration_stack(state, t),
                   lambda stack, **kw: formulations.solve(stack, driver, **options),
                   duration=duration, dt=dt, algorithmic_error=False)
    if run.failed:
        raise RuntimeError(f"the fencing run ({variant}) failed: {run.message}")
    pick = np.unique(np.linspace(0, run.steps - 1, samples).round().astype(int))
    data = robot.model.createData()
    dyn = robot.model.createData()
    stacks, masses, states = [], [], []
    for i in pick:
        state = KinematicState(robot, run.q[i], run.v[i], data)
        stacks.append(scenario.acceleration_stack(state, float(run.t[i])).stack)
        masses.append(_mass_matrix(robot.model, dyn, run.q[i]))
        states.append((run.q[i].copy(), run.v[i].copy()))
    return FencingSamples(variant, run.t[pick], stacks, masses, scenario, states, run)


def g1_fencing_cases(samples: int, dt: float = 0.005
                     ) -> tuple[list[Case], list[FencingSamples], str]:
    """One :class:`Case` per fencing variant, or ``([], [], reason)`` when the robot
    part cannot run here."""
    try:
        import prioik.robots.fencing  # noqa: F401
        import prioik.robots.simulate  # noqa: F401
    except ImportError as exc:
        return [], [], f"robots cannot be imported here ({type(exc).__name__}: {exc})"
    try:
        from prioik.robots.fencing import VARIANTS
        runs = [g1_fencing_samples(v, samples, dt) for v in VARIANTS]
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        return [], [], f"the G1 fencing stacks cannot be built ({type(exc).__name__}: {exc})"
    cases = []
    for run in runs:
        ks = Counter(len(s) for s in run.stacks)
        rows = int(np.median([sum(lvl.m for lvl in s.levels) for s in run.stacks]))
        cases.append(Case("g1", f"g1 {run.variant}", run.stacks[0].n, ks.most_common(1)[0][0],
                          rows, run.stacks, run.mass_matrices,
                          f"{len(run.stacks)} states of a {G1_DURATION_S:g} s fencing run "
                          f"(driven by {G1_DRIVERS.get(run.variant, ('reference',))[0]}), t = "
                          f"{run.times[0]:.2f}-{run.times[-1]:.2f} s; robot M(q)"))
    return cases, runs, ""


def same_shape_batch(stacks: list[TaskStack], size: int) -> tuple[list[TaskStack], str]:
    """``size`` stacks of the most common shape among ``stacks`` (cycled when fewer)."""
    from prioik.formulations.registry import stack_shape
    shapes = Counter(stack_shape(s) for s in stacks)
    shape, count = shapes.most_common(1)[0]
    same = [s for s in stacks if stack_shape(s) == shape]
    batch = [same[i % len(same)] for i in range(size)]
    note = (f"{count} distinct sampled stacks of the most common shape"
            + (f", cycled to {size}" if count < size else ""))
    return batch, note
