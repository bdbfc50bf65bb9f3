"""What a ``prioik bench`` run measures (``--quick`` shrinks it)."""

from __future__ import annotations

from dataclasses import dataclass

from prioik.benchmarks.timing import Budget

__all__ = ["Settings", "quick_settings", "SIZES", "LEVELS", "QUICK_SIZES", "QUICK_LEVELS",
           "SUCCESS_TOL"]

#: ``n`` and ``k`` of the random cases (default and ``--quick``)
SIZES = (12, 35, 100, 300)
LEVELS = (2, 4, 8, 16)
QUICK_SIZES = (12, 100)
QUICK_LEVELS = (2, 16)
#: residual tolerance of the success test (relative to max(1, ‖b_i‖))
SUCCESS_TOL = 1e-6


@dataclass
class Settings:
    """What a run measures.

    Attributes:
        sizes, levels: ``n`` and ``k`` of the random cases.
        repeats, min_repeats, warmup, cap_s: The time budget of a table row
            (:class:`~prioik.benchmarks.timing.Budget`).
        samples: Stacks per random case.
        g1_samples: States per G1 fencing case.
        family: Random stack family (:data:`prioik.hierarchy.families.FAMILIES`).
        batch_size, batch_rounds: The ``solve_batch`` experiment.
        control_duration_s: Simulated time of the control-step experiment.
        ik_steps: Steps of the IK-step experiment.
        only: Formulation names or labels to time (empty: every one).
        g1: Run the G1 part (its cases, batch, IK-step and control-step experiments).
        blas_threads: BLAS threads while measuring (0: leave BLAS's default).
        quick: A ``--quick`` run.
    """

    sizes: tuple[int, ...] = SIZES
    levels: tuple[int, ...] = LEVELS
    repeats: int = 200
    min_repeats: int = 10
    warmup: int = 3
    cap_s: float = 1.5
    samples: int = 8
    g1_samples: int = 24
    family: str = "conflicting"
    batch_size: int = 1000
    batch_rounds: int = 5
    control_duration_s: float = 1.0
    ik_steps: int = 300
    only: tuple[str, ...] = ()
    g1: bool = True
    blas_threads: int = 1
    quick: bool = False

    @property
    def budget(self) -> Budget:
        """The time budget of one (case, variant) row."""
        return Budget(self.repeats, self.min_repeats, self.warmup, self.cap_s)


def quick_settings() -> Settings:
    """The ``--quick`` run (under a minute): fewer cases, repeats and samples."""
    return Settings(sizes=QUICK_SIZES, levels=QUICK_LEVELS, repeats=30, min_repeats=5,
                    warmup=1, cap_s=0.15, samples=4, g1_samples=6, batch_size=1000,
                    batch_rounds=2, control_duration_s=0.1, ik_steps=50, quick=True)
