"""The G1 fencing test sets: acceleration-level stacks at consecutive steps of the
simulated fencing run (:func:`prioik.benchmarks.stacks.g1_fencing_samples`), in both
variants (``compatible``: the tasks can all be met; ``incompatible``: the sword-tip
target is out of reach, the levels conflict).

* ``g1_compatible`` / ``g1_incompatible``: equality stacks, the joint limits as
  activation rows (every formulation takes them);
* ``g1_bounds_compatible`` / ``g1_bounds_incompatible``: the joint position and
  velocity limits as bounds on ``q̈`` at level 0 (formulations with inequality tasks).

Each takes ``windows`` stretches of ``steps`` consecutive simulated steps (``dt = 5 ms``)
spread evenly over the run: a sequential test set, one sequence per window. The mass
matrix of each problem is the robot's ``M(q)``.
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import lru_cache

import numpy as np

from .base import Problem, TestSet

__all__ = ["G1Compatible", "G1Incompatible", "G1BoundsCompatible", "G1BoundsIncompatible"]


@lru_cache(maxsize=2)
def _fencing_run(variant: str):
    from prioik.benchmarks.stacks import g1_fencing_samples
    return g1_fencing_samples(variant, 2)


def _fencing_problems(variant: str, limits: str, windows: int, steps: int
                      ) -> Iterator[Problem]:
    from prioik.benchmarks.stacks import _mass_matrix
    from prioik.robots.tasks import KinematicState
    samples = _fencing_run(variant)
    run, scenario = samples.run, samples.scenario
    model = scenario.robot.model
    data, dyn = model.createData(), model.createData()
    firsts = np.linspace(0, run.steps - steps, windows).round().astype(int)
    for w, first in enumerate(firsts):
        for i in range(first, first + steps):
            state = KinematicState(scenario.robot, run.q[i], run.v[i], data)
            stack = scenario.acceleration_stack(state, float(run.t[i]), limits=limits).stack
            yield Problem(f"t={run.t[i]:.3f}", stack, sequence=f"window {w}",
                          mass_matrix=_mass_matrix(model, dyn, run.q[i]))


class _G1(TestSet):
    sequential = True
    needs = ("robots",)
    variant = ""
    limits = ""

    def __init__(self, windows: int = 4, steps: int = 6) -> None:
        if windows < 1 or steps < 1:
            raise ValueError(f"windows and steps must be ≥ 1, got {windows}, {steps}")
        self.windows, self.steps = windows, steps

    def problems(self) -> Iterator[Problem]:
        return _fencing_problems(self.variant, self.limits, self.windows, self.steps)


class G1Compatible(_G1):
    name = "g1_compatible"
    description = ("G1 fencing, compatible tasks: equality stacks (joint limits as "
                   "activation rows), consecutive steps")
    variant, limits = "compatible", "activation"


class G1Incompatible(_G1):
    name = "g1_incompatible"
    description = ("G1 fencing, sword-tip target out of reach: equality stacks (joint "
                   "limits as activation rows), consecutive steps")
    variant, limits = "incompatible", "activation"


class G1BoundsCompatible(_G1):
    name = "g1_bounds_compatible"
    description = ("G1 fencing, compatible tasks, joint position and velocity limits as "
                   "bounds on q̈ at level 0, consecutive steps")
    variant, limits = "compatible", "bounds"


class G1BoundsIncompatible(_G1):
    name = "g1_bounds_incompatible"
    description = ("G1 fencing, sword-tip target out of reach, joint limits as bounds on "
                   "q̈ at level 0, consecutive steps")
    variant, limits = "incompatible", "bounds"
