"""Timing of ``hierarchical_active_set``'s two kernels side by side in one process: the
C++ port (``kernel="cpp"``, ``prioik._core.ActiveSetSolver``) against the numba kernel.

The stacks: the G1 fencing run's bounds stacks (:func:`.active_set_bench.bounds_stacks`,
acceleration and velocity level, ``windows × steps`` consecutive steps) solved through
the prepared path (``Prepared.solve_checked``) cold (``warm_start=False``) and warm (each
step after its own predecessor: the pair timed together, halved), and seeded random
inequality hierarchies (:func:`~prioik.hierarchy.families.random_inequality_hierarchy`,
``n`` 20-39, 3-5 levels) by the kernel call alone (their flagged answers' Python
certificate would otherwise dominate both).

Times: the two kernels interleaved call block by call block (5 calls a block, the
kernels' order alternating from one round to the next), per stack the fastest block of
``rounds``; a ratio is C++'s total over numba's (and the median of the per-stack
ratios). Both kernels are compiled beforehand (numba's from its cache). The C++ build's
flags are printed (``prioik._core.build_info()``: tuned for the building machine or
portable).

Run: ``python -m prioik.benchmarks.active_set_kernels [--windows 4 --steps 6 --rounds 60
--random 20]``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

#: calls per timed block
BLOCK = 5
#: the solver options both kernels take (hierarchical_active_set's defaults)
_OPTIONS = {"rcond": 1e-9, "primal_tol": 1e-10, "dual_tol": 1e-12, "max_iter": 500}


def _prepared(stack, kernel: str, warm: bool):
    from prioik.formulations import hierarchical_active_set as has
    return has.Prepared(stack.layout, dict(_OPTIONS, warm_start=warm, kernel=kernel))


def _block(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    for _ in range(BLOCK):
        fn()
    return (time.perf_counter() - t0) / BLOCK


def interleaved(pairs: list[tuple[Callable, Callable]], rounds: int) -> np.ndarray:
    """Per pair ``(cpp, numba)`` the fastest block of each over ``rounds`` rounds, the two
    interleaved (their order alternating): an array ``len(pairs) × 2`` of seconds."""
    best = np.full((len(pairs), 2), np.inf)
    for r in range(rounds):
        for i, pair in enumerate(pairs):
            for which in ((0, 1) if r % 2 == 0 else (1, 0)):
                best[i, which] = min(best[i, which], _block(pair[which]))
    return best


def _row(label: str, t: np.ndarray) -> str:
    return (f"| {label} | {t[:, 0].mean() * 1e6:.1f} | {t[:, 1].mean() * 1e6:.1f} | "
            f"{t[:, 0].sum() / t[:, 1].sum():.2f} | {np.median(t[:, 0] / t[:, 1]):.2f} |")


def g1_rows(windows: int, steps: int, rounds: int) -> list[str]:
    """The G1 bounds stacks' rows (cold and warm, each level)."""
    from .active_set_bench import bounds_stacks
    out = []
    for level in ("acceleration", "velocity"):
        stacks, before = bounds_stacks("incompatible", windows, steps, level)
        cold = []
        for st in stacks:
            c, n = _prepared(st, "cpp", False), _prepared(st, "numba", False)
            cold.append((lambda c=c, d=st.data: c.solve_checked(d),
                         lambda n=n, d=st.data: n.solve_checked(d)))
        warm, prev, wc, wn = [], None, None, None
        for i, st in enumerate(stacks):
            if i in before:
                wc, wn = _prepared(st, "cpp", True), _prepared(st, "numba", True)
                prev = before[i].data
            warm.append((lambda w=wc, p=prev, d=st.data: (w.solve_checked(p), w.solve_checked(d)),
                         lambda w=wn, p=prev, d=st.data: (w.solve_checked(p), w.solve_checked(d))))
            prev = st.data
        n = len(stacks)
        out.append(_row(f"G1 bounds {level}, {n} stacks, cold", interleaved(cold, rounds)))
        out.append(_row(f"G1 bounds {level}, {n} stacks, warm", interleaved(warm, rounds) / 2))
    return out


def random_row(count: int, rounds: int) -> str:
    """Random inequality hierarchies, the kernel call alone (cold)."""
    from prioik.hierarchy.families import random_inequality_hierarchy
    rng = np.random.default_rng(2026)
    pairs = []
    for _ in range(count):
        st = random_inequality_hierarchy(rng, int(rng.integers(20, 40)), int(rng.integers(3, 6)))
        c, n, d = _prepared(st, "cpp", False), _prepared(st, "numba", False), st.data
        args = (d.A, d.b, d.lower, d.upper, d.sqrt_weight)
        pairs.append((lambda c=c, a=args: c._solve_data(*a),
                      lambda n=n, a=args: n._solve_data(*a, *n._work)))
    return _row(f"random inequality hierarchies, {count} stacks, kernel call",
                interleaved(pairs, max(1, rounds // 2)))


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--windows", type=int, default=4, help="stretches of the G1 run")
    p.add_argument("--steps", type=int, default=6, help="consecutive steps per stretch")
    p.add_argument("--rounds", type=int, default=60, help="timing rounds (per stack the "
                   "fastest block)")
    p.add_argument("--random", type=int, default=20, help="random hierarchies")
    p.add_argument("--no-g1", action="store_true", help="skip the G1 bounds stacks")
    a = p.parse_args(argv)
    import prioik._core as core
    from prioik.formulations import hierarchical_active_set as has
    has.compile_kernels()
    info = core.build_info()
    tuning = "tuned for this machine (-march=native)" if info.native else "portable"
    print(f"C++ core: {info.compiler}, {tuning}, fast math {info.fast_math}, "
          f"contraction {info.fp_contract}")
    print("| stacks | C++ µs (mean) | numba µs (mean) | C++ / numba (total) | median per stack |")
    print("|---|---:|---:|---:|---:|")
    if not a.no_g1:
        from prioik.extras import MissingExtraError, require
        try:
            require("robots", what="active_set_kernels' G1 stacks (or --no-g1)")
        except MissingExtraError as exc:
            raise SystemExit(f"active_set_kernels: error: {exc}") from None
        for row in g1_rows(a.windows, a.steps, a.rounds):
            print(row)
    print(random_row(a.random, a.rounds))


if __name__ == "__main__":
    main()
