"""The C++ core against the numba kernels it replaced, on the rows of ``prioik bench``'s
extended-Jacobian and active-set tables, each side in its own environment.

The numba kernels are no longer in prioik; this module times them from a second checkout
that still has them, with its own virtual environment. The last commit with them is
:data:`NUMBA_COMMIT`; make that checkout once (its ``pyproject.toml`` declares numba)::

    git worktree add --detach ../prioik-numba 7e9ce39
    cd ../prioik-numba && python3.11 -m venv .venv && .venv/bin/pip install -e . \\
        && .venv/bin/prioik compile     # numba compiles the kernels once and caches them

Then, from this checkout's environment::

    python -m prioik.benchmarks.numba_compare --old-python ../prioik-numba/.venv/bin/python

What is timed. This environment builds the stacks and saves them (``stacks.npz`` and
``rows.json`` in ``--work``): the G1 fencing cases and the random cases of ``prioik
bench`` (:func:`~prioik.benchmarks.stacks.g1_fencing_cases`,
:func:`~prioik.benchmarks.stacks.random_case`, the ``conflicting`` family, the default
sizes and levels), and the G1 bounds trajectories of
:mod:`~prioik.benchmarks.active_set_bench` (:func:`.active_set_bench.bounds_stacks`,
both variants, both levels). A worker process per side (this file run as a script by
that environment's Python) loads them and times, per row, the same solve through the
registry's prepared path (``prioik.prepare(layout, formulation, kernel=K, ...)``):
``K = "numba"`` in the old environment, ``K = "cpp"`` in this one (or in
``--cpp-python``'s, e.g. one whose core is tuned for this machine), every other option
at its default. The rows:

* ``extended_jacobian`` and ``hierarchical_active_set`` on every case of the tables,
  timed as ``prioik bench`` times a row (:mod:`prioik.benchmarks.bench.tables`): one
  prepared solver per layout, warm-up solves, then up to ``--repeats`` solves cycling
  over the case's stacks within ``--cap`` seconds; a row's time is the median of
  ``Solution.time_s`` (the plugin's solve, as in the bench's tables), and beside it the
  median of the whole ``PreparedSolver.solve`` call (``perf_counter`` around it).
  At ``n = 300`` both kernels are forced: the extended Jacobian's ``kernel="auto"``
  takes the LAPACK path above ``n = 160`` in both versions.
* ``hierarchical_active_set`` along each G1 bounds trajectory, timed as
  :func:`.active_set_bench.measure` times it: ``cold`` (``warm_start=False``), ``warm``
  (each step after its predecessor, the step before a window solved untimed first) and
  ``re-solve`` (warm, each stack solved twice, the second timed); ``--passes`` passes
  over the trajectory, per stack the fastest whole ``PreparedSolver.solve`` call, a
  row's time the median over the stacks.

Rounds. Both workers stay alive and take turns, one at a time (the other waits): each
first times every row once and saves its answers (imports, numba's cache, first calls),
then in each of ``--rounds`` rounds every row is timed by numba's worker and right after
by C++'s (BLAS limited to one thread in both). A row's figure per side is the median of
its per-round times, its ratio the quotient of the two medians (and, beside it, the
smallest and largest ratio of one round's pair).

Answers. Each side's saved answers: ``x``, the level residuals ``‖w_i‖`` and the status
of each stack's solve (the table rows: a fresh solver per layout, the case's stacks once
in order; the trajectory rows: the last pass). Two
answers agree when their statuses are equal and ``‖x_cpp − x_numba‖ ≤``
:data:`X_RTOL` ``· max(1, ‖x_numba‖)``; the table gives the count of agreeing answers,
the largest such distance of a row, the largest change of a level residual (relative to
``max(1, ‖w_i‖)``) and numba's statuses (an ``approximate`` answer is one its solver
does not stand behind: its ``x`` need not be within :data:`X_RTOL` of another's).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: the last commit of prioik with the numba kernels (the next, 46be3d8, deleted them)
NUMBA_COMMIT = "7e9ce39"
#: relative distance within which two answers' ``x`` agree (see the module docstring)
X_RTOL = 1e-9
#: each side's kernel option per formulation
KERNELS = {"numba": {"extended_jacobian": "numba", "hierarchical_active_set": "numba"},
           "cpp": {"extended_jacobian": "cpp", "hierarchical_active_set": "cpp"}}
SIDES = ("numba", "cpp")
#: a worker's environment: BLAS on one thread (as ``prioik bench`` measures)
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
_TASK_ARRAYS = ("A", "b", "lower", "upper", "weight")


# ------------------------------------------------------------------ stacks on disk
def save_stacks(stacks: list, path: Path) -> list[list[list[list]]]:
    """Write every task array of ``stacks`` into the npz ``path``; returns the manifest
    that :func:`load_stacks` reads with it (per stack, level and task: its name and the
    arrays it has). Raises ``ValueError`` for a hard level (the numba-era code has none)."""
    arrays, manifest = {}, []
    for s, stack in enumerate(stacks):
        levels = []
        for lv, level in enumerate(stack.levels):
            if getattr(level, "hard", False):
                raise ValueError(f"stack {s}, level {lv} is hard: the numba-era prioik "
                                 f"has no hard levels")
            tasks = []
            for t, task in enumerate(level):
                present = [a for a in _TASK_ARRAYS if getattr(task, a) is not None]
                for a in present:
                    arrays[f"{s}/{lv}/{t}/{a}"] = np.asarray(getattr(task, a))
                tasks.append([task.name, present])
            levels.append(tasks)
        manifest.append(levels)
    np.savez(path, **arrays)
    return manifest


def load_stacks(manifest: list, path: Path) -> list:
    """The stacks :func:`save_stacks` wrote, as this environment's ``TaskStack``."""
    from prioik.hierarchy import Task, TaskStack
    with np.load(path) as arrays:
        out = []
        for s, levels in enumerate(manifest):
            built = []
            for lv, tasks in enumerate(levels):
                level = []
                for t, (name, present) in enumerate(tasks):
                    kw = {a: arrays[f"{s}/{lv}/{t}/{a}"] for a in present}
                    A = kw.pop("A")
                    level.append(Task(name, A, kw.pop("b", None), **kw))
                built.append(level)
            out.append(TaskStack(built))
    return out


# ------------------------------------------------------------------ the worker
def _time_table(stacks: list, formulation: str, options: dict, repeats: int, cap_s: float
                ) -> dict[str, float]:
    """Median seconds of a solve, cycling over ``stacks`` as ``prioik bench`` does:
    ``solve``, the plugin's solve (``Solution.time_s``, what the bench's tables give), and
    ``wall``, the whole ``PreparedSolver.solve`` call."""
    import prioik
    solvers = {}

    def call(i: int) -> tuple[float, float]:
        stack = stacks[i % len(stacks)]
        solver = solvers.get(stack.layout)
        if solver is None:
            solver = solvers[stack.layout] = prioik.prepare(stack.layout, formulation,
                                                            **options)
        t0 = time.perf_counter()
        sol = solver.solve(stack)
        return sol.time_s, time.perf_counter() - t0

    call(0)
    estimate = float(np.median([call(i)[0] for i in range(1, 4)]))
    count = max(10, min(repeats, int(cap_s / max(estimate, 1e-9))))
    times = np.array([call(i) for i in range(count)])
    return {"solve": float(np.median(times[:, 0])), "wall": float(np.median(times[:, 1]))}


def _table_answers(stacks: list, formulation: str, options: dict) -> list:
    import prioik
    solvers, out = {}, []
    for stack in stacks:
        solver = solvers.get(stack.layout)
        if solver is None:
            solver = solvers[stack.layout] = prioik.prepare(stack.layout, formulation,
                                                            **options)
        out.append(solver.solve(stack))
    return out


def _time_trajectory(stacks: list, before: dict[int, int], mode: str, options: dict,
                     passes: int, all_stacks: list) -> tuple[float, list]:
    """:func:`.active_set_bench.measure`'s timing of one solver (``mode``: ``cold``,
    ``warm`` or ``again``): the median over the stacks of each one's fastest pass, and
    the last pass's answers."""
    import prioik
    layout = stacks[0].layout
    solver = prioik.prepare(layout, "hierarchical_active_set",
                            **dict(options, warm_start=mode != "cold"))
    if mode == "cold":
        solver.solve(stacks[0])             # the first solve before timing
    best = np.full(len(stacks), np.inf)
    answers: list = []
    for _ in range(passes):
        answers = []
        for i, stack in enumerate(stacks):
            if mode == "warm" and i in before:
                solver.solve(all_stacks[before[i]])     # the window's previous step
            elif mode == "again":
                solver.solve(stack)                     # the same stack first, untimed
            t0 = time.perf_counter()
            sol = solver.solve(stack)
            best[i] = min(best[i], time.perf_counter() - t0)
            answers.append(sol)
    return float(np.median(best)), answers


def _time_row(row: dict, stacks: list, kernels: dict, spec: dict, answers: bool
              ) -> tuple[dict[str, float], list]:
    """One row's times (``{"solve": s, "wall": s}``) and, with ``answers``, its answers."""
    options = {"kernel": kernels[row["formulation"]]}
    these = [stacks[i] for i in row["stacks"]]
    if row["mode"] == "table":
        times = _time_table(these, row["formulation"], options, spec["repeats"],
                            spec["cap_s"])
        return times, _table_answers(these, row["formulation"], options) if answers else []
    before = {int(k): v for k, v in row["before"].items()}
    wall, sols = _time_trajectory(these, before, row["mode"], options, spec["passes"],
                                  stacks)
    return {"solve": wall, "wall": wall}, sols


def worker(work: Path, side: str) -> None:
    """Serve timings of the rows of ``work/rows.json`` with ``side``'s kernels: per line
    of stdin, ``{"row": NAME}`` is answered on stdout by ``{"solve": s, "wall": s}``;
    ``{"answers": PATH}`` times every row once and writes every answer's ``x`` and level
    residuals (npz ``PATH``) and statuses (``PATH`` with ``.json``), then ``{}``."""
    reply, sys.stdout = sys.stdout, sys.stderr     # stray prints leave the protocol alone
    spec = json.loads((work / "rows.json").read_text())
    stacks = load_stacks(spec["manifest"], work / "stacks.npz")
    rows = {row["name"]: row for row in spec["rows"]}
    kernels = KERNELS[side]
    for line in sys.stdin:
        request = json.loads(line)
        if "row" in request:
            times, _ = _time_row(rows[request["row"]], stacks, kernels, spec, False)
            print(json.dumps(times), file=reply, flush=True)
            continue
        xs, statuses = {}, {}
        for name, row in rows.items():
            _, sols = _time_row(row, stacks, kernels, spec, True)
            for j, sol in enumerate(sols):
                xs[f"{name}#{j}"] = np.asarray(sol.x, dtype=float)
                xs[f"{name}#{j}/residuals"] = np.asarray(sol.residuals, dtype=float)
            statuses[name] = [str(sol.status) for sol in sols]
        path = Path(request["answers"])
        np.savez(path, **xs)
        path.with_suffix(".json").write_text(json.dumps(statuses))
        print("{}", file=reply, flush=True)


# ------------------------------------------------------------------ the rows
def build_rows(work: Path, repeats: int, cap_s: float, passes: int, windows: int,
               steps: int, sizes=None, levels=None, g1: bool = True) -> list[dict]:
    """Build and save the stacks of every row (see the module docstring) into ``work``;
    returns the rows (name, formulation, mode, stack indices, ``before`` map)."""
    from prioik.benchmarks.bench.settings import LEVELS, SIZES, Settings
    from prioik.benchmarks.stacks import g1_fencing_cases, random_case
    settings = Settings()
    stacks: list = []
    rows: list[dict] = []

    def add(new: list) -> list[int]:
        stacks.extend(new)
        return list(range(len(stacks) - len(new), len(stacks)))

    cases = []
    if g1:
        g1_cases, _, reason = g1_fencing_cases(settings.g1_samples)
        if reason:
            raise SystemExit(f"numba_compare: the G1 stacks cannot be built: {reason} "
                             f"(or --no-g1)")
        cases += g1_cases
    cases += [random_case(n, k, settings.samples, settings.family)
              for n in (sizes or SIZES) for k in (levels or LEVELS)]
    indices = [add(case.stacks) for case in cases]
    for formulation in ("extended_jacobian", "hierarchical_active_set"):
        for case, idx in zip(cases, indices, strict=True):
            rows.append({"name": f"{formulation}, {case.name}", "formulation": formulation,
                         "mode": "table", "stacks": idx, "before": {}})
    if g1:
        from prioik.benchmarks.active_set_bench import bounds_stacks
        for variant in ("compatible", "incompatible"):
            for level in ("acceleration", "velocity"):
                trajectory, before = bounds_stacks(variant, windows, steps, level)
                layout = trajectory[0].layout
                keep = [i for i, s in enumerate(trajectory) if s.layout == layout]
                idx = add([trajectory[i] for i in keep])
                pairs = [(j, before[i]) for j, i in enumerate(keep) if i in before]
                prev = add([stack for _, stack in pairs])
                before_map = {str(j): p for (j, _), p in zip(pairs, prev, strict=True)}
                for mode in ("cold", "warm", "again"):
                    what = {"again": "re-solve"}.get(mode, mode)
                    rows.append({"name": f"hierarchical_active_set, G1 bounds {variant} "
                                         f"{level} ({len(keep)}), {what}",
                                 "formulation": "hierarchical_active_set", "mode": mode,
                                 "stacks": idx, "before": before_map})
    manifest = save_stacks(stacks, work / "stacks.npz")
    (work / "rows.json").write_text(json.dumps({
        "manifest": manifest, "rows": rows, "repeats": repeats, "cap_s": cap_s,
        "passes": passes}))
    return rows


# ------------------------------------------------------------------ comparison
@dataclass
class RowResult:
    """One row's figures: per side the per-round seconds (``seconds``: the row's own
    measure, ``wall``: the whole prepared call), and its answers' agreement."""

    name: str
    seconds: dict[str, list[float]] = field(default_factory=lambda: {s: [] for s in SIDES})
    wall: dict[str, list[float]] = field(default_factory=lambda: {s: [] for s in SIDES})
    max_distance: float = math.nan
    max_residual_change: float = math.nan
    agree: int = 0
    answers: int = 0
    statuses: str = ""

    def median_us(self, side: str, wall: bool = False) -> float:
        """The median over the rounds of ``side``'s times (µs)."""
        values = (self.wall if wall else self.seconds)[side]
        return float(np.median(values)) * 1e6 if values else math.nan

    @property
    def ratio(self) -> float:
        """C++'s median over numba's."""
        return self.median_us("cpp") / self.median_us("numba")

    @property
    def wall_ratio(self) -> float:
        """C++'s median over numba's, the whole prepared call."""
        return self.median_us("cpp", True) / self.median_us("numba", True)

    @property
    def round_ratios(self) -> np.ndarray:
        """Each round's C++ time over the same round's numba time."""
        n = min(len(self.seconds["cpp"]), len(self.seconds["numba"]))
        return np.array(self.seconds["cpp"][:n]) / np.array(self.seconds["numba"][:n])


def compare_answers(result: RowResult, x: dict[str, dict[str, np.ndarray]],
                    statuses: dict[str, dict[str, list[str]]]) -> None:
    """Fill ``result``'s agreement from both sides' answers (``x[side][row#j]``,
    ``statuses[side][row]``)."""
    names = statuses["numba"].get(result.name, [])
    result.answers = len(names)
    result.agree, worst, worst_residual = 0, 0.0, 0.0
    for j, status in enumerate(names):
        key = f"{result.name}#{j}"
        xn, xc = x["numba"][key], x["cpp"][key]
        dist = float(np.linalg.norm(xc - xn) / max(1.0, float(np.linalg.norm(xn))))
        rn, rc = x["numba"][key + "/residuals"], x["cpp"][key + "/residuals"]
        worst_residual = max(worst_residual,
                             float(np.max(np.abs(rc - rn) / np.maximum(1.0, rn))))
        worst = max(worst, dist)
        if status == statuses["cpp"][result.name][j] and dist <= X_RTOL:
            result.agree += 1
    result.max_distance, result.max_residual_change = worst, worst_residual
    counts = {s: names.count(s) for s in sorted(set(names))}
    result.statuses = ", ".join(f"{s} {c}" for s, c in counts.items())


def markdown_table(results: list[RowResult]) -> str:
    """The table: row, numba µs, C++ µs, C++/numba, the per-round ratios' range, the
    ratio of the whole prepared calls, and the answers' agreement."""
    lines = ["| row | numba µs | C++ µs | C++/numba | per round | whole call C++/numba | "
             "answers agree | max ‖Δx‖ rel. | max Δ‖w_i‖ rel. | numba's statuses |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in results:
        rr = r.round_ratios
        spread = f"{rr.min():.2f}–{rr.max():.2f}" if rr.size else "–"
        lines.append(f"| {r.name} | {r.median_us('numba'):.1f} | {r.median_us('cpp'):.1f} | "
                     f"{r.ratio:.2f} | {spread} | {r.wall_ratio:.2f} | {r.agree}/{r.answers} "
                     f"| {r.max_distance:.1e} | {r.max_residual_change:.1e} | {r.statuses} |")
    return "\n".join(lines)


class _Worker:
    """One side's worker process (:func:`worker`), asked row by row."""

    def __init__(self, python: str, work: Path, side: str, env: dict[str, str]) -> None:
        # -P: the script's directory (benchmarks/) is not put on sys.path, so that its
        # modules cannot shadow the environment's packages
        self.side = side
        self.process = subprocess.Popen(
            [python, "-P", str(Path(__file__).resolve()), "--worker", str(work),
             "--side", side], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
            env=env)

    def ask(self, request: dict) -> dict:
        self.process.stdin.write(json.dumps(request) + "\n")
        self.process.stdin.flush()
        line = self.process.stdout.readline()
        if not line:
            raise SystemExit(f"numba_compare: the {self.side} worker ended "
                             f"(exit {self.process.wait()}) on {request}")
        return json.loads(line)

    def close(self) -> None:
        self.process.stdin.close()
        self.process.wait()


def _describe_builds(pythons: dict[str, str]) -> list[str]:
    """A line per side: the C++ core's build flags, numba's version and target CPU."""
    probes = {
        "cpp": "import prioik._core as c; b = c.build_info(); "
               "print(f\"C++ core: {b.compiler}, {'-march=native' if b.native else 'portable'} "
               "(vector clones: {b.vector_clones}), -O3, fast math {b.fast_math}, "
               "FP contraction {b.fp_contract}, Eigen {b.eigen}\")",
        "numba": "import numba, llvmlite.binding as b; print(f'numba {numba.__version__}, "
                 "compiled for this CPU ({b.get_host_cpu_name()})')"}
    lines = []
    for side, probe in probes.items():
        got = subprocess.run([pythons[side], "-P", "-c", probe], capture_output=True,
                             text=True, cwd=tempfile.gettempdir())
        lines.append(got.stdout.strip() or f"{side}: {got.stderr.strip()[-200:]}")
    return lines


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        prog="python -m prioik.benchmarks.numba_compare",
        description="Time prioik bench's extended-Jacobian and active-set rows with the "
                    f"C++ core here and with the numba kernels of a checkout of commit "
                    f"{NUMBA_COMMIT} (see the module docstring), two processes taking turns.")
    p.add_argument("--old-python", help="the Python of the checkout with the numba kernels")
    p.add_argument("--cpp-python", default=sys.executable, help="the Python whose prioik "
                   "times the C++ core (default: this one; e.g. an environment with the "
                   "core built with -C cmake.define.PRIOIK_NATIVE=ON)")
    p.add_argument("--rounds", type=int, default=7, help="rounds, each row timed by numba's "
                   "worker then C++'s (at least 5)")
    p.add_argument("--repeats", type=int, default=200, help="table rows: timed solves")
    p.add_argument("--cap", type=float, default=0.3, help="table rows: seconds per row "
                   "and round (fewer repeats above it, at least 10)")
    p.add_argument("--passes", type=int, default=10, help="trajectory rows: passes")
    p.add_argument("--windows", type=int, default=4, help="G1 bounds: stretches of the run")
    p.add_argument("--steps", type=int, default=6, help="G1 bounds: steps per stretch")
    p.add_argument("--sizes", type=lambda s: tuple(int(v) for v in s.split(",")),
                   help="random cases' n (default: prioik bench's)")
    p.add_argument("--levels", type=lambda s: tuple(int(v) for v in s.split(",")),
                   help="random cases' k (default: prioik bench's)")
    p.add_argument("--no-g1", action="store_true", help="only the random cases")
    p.add_argument("--work", type=Path, help="directory for the stacks and both sides' "
                   "answers (default: a new temporary directory)")
    p.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    p.add_argument("--side", choices=SIDES, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker is not None:
        worker(a.worker, a.side)
        return
    if not a.old_python:
        p.error("--old-python is required (the numba checkout's Python; see --help)")
    if a.rounds < 5:
        p.error("--rounds must be at least 5")
    work = a.work or Path(tempfile.mkdtemp(prefix="numba_compare-"))
    work.mkdir(parents=True, exist_ok=True)
    print(f"numba_compare: building the stacks into {work} ...", file=sys.stderr, flush=True)
    rows = build_rows(work, a.repeats, a.cap, a.passes, a.windows, a.steps, a.sizes,
                      a.levels, not a.no_g1)
    env = dict(os.environ, **{v: "1" for v in THREAD_VARIABLES})
    pythons = {"numba": a.old_python, "cpp": a.cpp_python}
    workers = {side: _Worker(pythons[side], work, side, env) for side in SIDES}
    results = {r["name"]: RowResult(r["name"]) for r in rows}
    start = time.perf_counter()
    try:
        for side in SIDES:      # every row once (compiles, caches), every answer saved
            workers[side].ask({"answers": str(work / f"answers-{side}.npz")})
        for rnd in range(a.rounds):
            for row in rows:
                for side in SIDES:
                    got = workers[side].ask({"row": row["name"]})
                    results[row["name"]].seconds[side].append(got["solve"])
                    results[row["name"]].wall[side].append(got["wall"])
            print(f"numba_compare: round {rnd + 1}/{a.rounds} done "
                  f"({time.perf_counter() - start:.0f} s)", file=sys.stderr, flush=True)
    finally:
        for w in workers.values():
            w.close()
    x, statuses = {}, {}
    for side in SIDES:
        with np.load(work / f"answers-{side}.npz") as f:
            x[side] = {k: f[k] for k in f.files}
        statuses[side] = json.loads((work / f"answers-{side}.json").read_text())
    for r in results.values():
        compare_answers(r, x, statuses)
    print("\n".join(_describe_builds(pythons)))
    print(f"{a.rounds} rounds, each row numba then C++; BLAS on one thread; "
          f"answers agree: same status and ‖Δx‖ ≤ {X_RTOL:g}·max(1, ‖x‖)")
    print(markdown_table(list(results.values())))


if __name__ == "__main__":
    main()
