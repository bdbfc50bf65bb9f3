"""Property fuzzing of the formulations on seeded random stacks.

``prioik fuzz --n 100000 --seed S --out DIR`` draws stacks with
:func:`hierarchy.fuzz.equality_case`, :func:`~hierarchy.fuzz.inequality_case` or
:func:`~hierarchy.fuzz.bounds_case` (``--kind``; case ``i`` from
``numpy.random.default_rng([S, i])``, so any case can be drawn again alone) and runs
every fuzzed path that takes the kind on each: the formulations of the registry
(:func:`registry_paths`). A path fails a case when:

* ``crash`` — it raised anything but the library's own errors on a valid stack
  (a :class:`~hierarchy.TaskStackError` / ``FormulationError`` refusal is counted
  as ``refused``, not as a crash);
* ``nan`` — ``x`` is not finite while the status is not ``failed``;
* ``above`` — the status is ``optimal`` on a well-conditioned equality stack that has
  an extended-precision truth (:func:`hierarchy.exact.exact_optimum`: ``n ≤``
  :data:`~hierarchy.exact.EXACT_MAX_N`, no rank decision within the ambiguity band;
  the ``mixed_scale`` kind always, ``equality`` with ``exact=True``) but some level's
  value lies above the truth's by more than :data:`~hierarchy.exact.VALUE_TOL`
  relative, beyond what float64 can tell apart (:meth:`~hierarchy.exact.ExactOptimum.
  excess` at the stack's precision, the larger of ``X_PRECISION`` and its
  :attr:`~hierarchy.fuzz.FuzzCase.rounding_error`); on the other stacks with a truth
  such answers are counted (:attr:`FuzzReport.above_ill`), not failed: rounding may
  move their answer further than the value tolerance;
* ``wrong`` — the status is ``optimal`` on a well-conditioned equality stack
  (:attr:`~hierarchy.fuzz.FuzzCase.well_conditioned`) but ``x`` is more than
  :data:`WRONG_TOL` (relative, :func:`hierarchy.relative_distance`) from the
  independent ground truth :func:`hierarchy.fuzz.nested_truth`, or fails
  :func:`hierarchy.check_lexicographic`;
* ``uncertified`` — the status is ``optimal`` on any stack (equality or
  inequality) but :func:`~hierarchy.check_lexicographic` rejects ``x``;
* ``mismatch`` — ``solve_batch`` (on the stack and two same-shape variants) or one
  prepared solver (:func:`prioik.prepare`) reused over those stacks disagree with
  one-off ``solve`` calls: their statuses differ, or on a
  well-conditioned stack their answers differ by more than
  ``MATCH_TOL / min_sigma`` (at most :data:`WRONG_TOL`; ``min_sigma`` is the smallest
  kept ``σ / ‖A_i‖_F``, by which a level amplifies rounding), or on
  another stack two answers both called ``optimal`` differ by more than
  :data:`WRONG_TOL` or ten times the stack's rounding bound
  (:attr:`~hierarchy.fuzz.FuzzCase.rounding_error`, Wedin's least-squares bound and
  the truth's spread under a rotation of the unknowns; a same-shape variant's own: on
  such a stack float64 does not determine ``x`` any closer, and both answers may pass
  the certificate);
* ``threads`` — the same solve run from several threads differs from the serial
  answer: on one shared prepared solver (which may refuse a concurrent call with
  ``ConcurrentUseError``, never answer wrongly) and on one prepared solver per thread;
  bit for bit, against a fresh solver's serial answer and against the answers a reused
  one gives serially (a warm-started solver starts from its last working set: the same
  optimum with other rounding, settled within a few solves; on ill-posed stacks a cycle
  of working sets, whose every answer counts).

Every failing case is saved as ``DIR/<kind>-<seed>-<index>.json``
(:func:`hierarchy.save_stack` format, so ``prioik solve`` reloads it) with the
path, the failure and the reproduction in its description.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from prioik import formulations
from prioik.formulations import ConcurrentUseError, FormulationError
from prioik.hierarchy import (
    TaskStack,
    TaskStackError,
    check_lexicographic,
    relative_distance,
    save_stack,
)
from prioik.hierarchy.exact import ExactOptimum, exact_optimum
from prioik.hierarchy.families import same_shape_batch
from prioik.hierarchy.fuzz import (
    FuzzCase,
    bounds_case,
    equality_case,
    inequality_case,
    mixed_scale_case,
    nested_truth,
    rotation_spread,
    rounding_error,
)

#: Relative distance from the ground truth above which an ``optimal`` answer is wrong.
WRONG_TOL = 1e-6
#: Relative distance between two paths' answers to one stack above which they differ.
MATCH_TOL = 1e-9
#: Failure kinds, in report order.
KINDS = ("crash", "nan", "above", "wrong", "uncertified", "mismatch", "threads")

#: Stack kinds of equality stacks (judged against the truths; the paths that take
#: ``"equality"`` take them all).
EQUALITY_KINDS = ("equality", "mixed_scale")

DOCUMENTED_ERRORS = (TaskStackError, FormulationError)


@dataclass(frozen=True)
class Path_:
    """One fuzzed path: a formulation of the registry with options, and the stack kinds
    it runs on (``None``: the kinds its capabilities take, :func:`kinds_of`)."""

    name: str
    formulation: str
    options: dict
    kinds: tuple[str, ...] | None = None


#: Formulations of the registry fuzzed otherwise than by one path of their defaults on
#: the kinds their capabilities take: name → their paths.
SETTINGS: dict[str, tuple[Path_, ...]] = {
    "extended_jacobian": (
        Path_("ej_qr_cpp", "extended_jacobian", {"kernel": "cpp"}),
        Path_("ej_qr_lapack", "extended_jacobian", {"kernel": "lapack"}),
        Path_("ej_svd", "extended_jacobian", {"nullspace": "svd"}),
    ),
    # the QP cascades on the stacks only they and the active set take
    "cascaded_qp": (Path_("cascaded_qp", "cascaded_qp", {}, kinds=("inequality", "bounds")),),
    "daqp_hierarchical": (Path_("daqp_hierarchical", "daqp_hierarchical", {},
                                kinds=("inequality", "bounds")),),
}

#: Formulations of the registry the fuzz leaves out, and why (``--paths`` cannot name
#: them either).
LEFT_OUT: dict[str, str] = {
    "chiaverini": "approximate by design (singularity-robust inversion): no optimal "
                  "answer for the checks to judge",
    "unifying": "needs a mass matrix, which the fuzzed stacks do not have",
    "operational_space": "needs a mass matrix, which the fuzzed stacks do not have",
    "cvxpy": "a modelling layer, tens of ms per level QP: cascaded_qp fuzzes the same "
             "cascade",
    "placo": "first level hard, the rest soft: not a lexicographic solver",
    "lexls": "a peer library, built only with its headers; its optimal answers are "
             "certified",
}


def registry_paths() -> dict[str, Path_]:
    """The paths ``prioik fuzz`` runs, by name: one per formulation of the registry
    (:func:`prioik.formulations.names`, in its order), its defaults on the stack kinds
    its capabilities take, unless :data:`SETTINGS` gives its own or :data:`LEFT_OUT`
    leaves it out. Reads names alone (no plugin is imported): a formulation added to
    the registry is fuzzed with no edit here."""
    out: dict[str, Path_] = {}
    for name in formulations.names():
        if name in LEFT_OUT:
            continue
        for path in SETTINGS.get(name, (Path_(name, name, {}),)):
            out[path.name] = path
    return out


def kinds_of(path: Path_) -> tuple[str, ...]:
    """The stack kinds ``path`` runs on: its own, or those its formulation's
    capabilities take (``"equality"``; ``"inequality"`` and ``"bounds"``)."""
    if path.kinds is not None:
        return path.kinds
    caps = formulations.get(path.formulation).capabilities
    return (("equality",) if caps.equalities else ()) + \
        (("inequality", "bounds") if caps.inequalities else ())


#: The generator of each stack kind.
GENERATORS = {"equality": equality_case, "inequality": inequality_case,
              "bounds": bounds_case, "mixed_scale": mixed_scale_case}


def takes(path: Path_, kind: str) -> bool:
    """Whether ``path`` runs on stacks of ``kind`` (the equality kinds alike)."""
    kinds = kinds_of(path)
    return kind in kinds or (kind in EQUALITY_KINDS and "equality" in kinds)


@dataclass
class Failure:
    """One failing (case, path)."""

    kind: str
    path: str
    case: str
    message: str


@dataclass
class FuzzReport:
    """Counts of one fuzz run.

    Attributes:
        stacks: Stacks tried, per stack kind.
        well_conditioned: How many equality stacks were well-conditioned.
        exact: Per kind, ``[stacks with an extended-precision truth, stacks whose truth
            is ambiguous, stacks judged by it]`` (judged: unambiguous and
            well-conditioned; see ``above`` in the module docstring).
        above_ill: Per path, ``optimal`` answers above the truth (as ``above``) on
            stacks with a truth that are not well-conditioned.
        solves: Solves per path.
        counts: ``counts[path][kind]`` failures.
        statuses: ``statuses[path][status]``.
        refused: Valid stacks a path refused with a documented error, per path.
        failures: Every failure (the first ``keep`` of them with details).
        time_s: Wall time.
    """

    stacks: dict[str, int] = field(default_factory=dict)
    well_conditioned: int = 0
    exact: dict[str, list[int]] = field(default_factory=dict)
    above_ill: dict[str, int] = field(default_factory=dict)
    solves: dict[str, int] = field(default_factory=dict)
    counts: dict[str, dict[str, int]] = field(default_factory=dict)
    statuses: dict[str, dict[str, int]] = field(default_factory=dict)
    refused: dict[str, int] = field(default_factory=dict)
    failures: list[Failure] = field(default_factory=list)
    time_s: float = 0.0

    @property
    def total_failures(self) -> int:
        return sum(sum(c.values()) for c in self.counts.values())

    def add(self, failure: Failure) -> None:
        self.counts.setdefault(failure.path, dict.fromkeys(KINDS, 0))[failure.kind] += 1
        self.failures.append(failure)

    def table(self) -> str:
        """A markdown table: one row per path, one column per failure kind."""
        head = "| path | solves | " + " | ".join(KINDS) + " | refused | statuses |"
        out = [head, "|---|" + "---:|" * (len(KINDS) + 2) + "---|"]
        for path, solves in self.solves.items():
            c = self.counts.get(path, dict.fromkeys(KINDS, 0))
            st = ", ".join(f"{k} {v}" for k, v in sorted(self.statuses.get(path, {}).items()))
            out.append(f"| {path} | {solves} | " + " | ".join(str(c[k]) for k in KINDS)
                       + f" | {self.refused.get(path, 0)} | {st} |")
        return "\n".join(out)


def _own_rounding(stack: TaskStack) -> float:
    """How far rounding may move the answer of an equality stack (a same-shape variant,
    which keeps its case's ranks but not its rounding): as
    :attr:`~hierarchy.fuzz.FuzzCase.rounding_error`."""
    truth = nested_truth(stack)[0]
    return max(rounding_error(stack, truth), rotation_spread(stack, truth))


def _case(kind: str, seed: int, index: int, sizes: dict | None = None) -> FuzzCase:
    rng = np.random.default_rng([seed, index])
    return GENERATORS[kind](rng, seed=index, **(sizes or {}))


def draw(kind: str, seed: int, index: int, sizes: dict | None = None) -> FuzzCase:
    """Case ``index`` of the run with ``seed`` (what the saved file's description names;
    ``sizes``: the generator's ``max_n``, ``max_levels``, ``max_rows`` if not the
    defaults)."""
    return _case(kind, seed, index, sizes)


def _solve(path: Path_, stack: TaskStack):
    return formulations.solve(stack, path.formulation, **path.options)


class _Runner:
    def __init__(self, report: FuzzReport, threads: int, keep: int) -> None:
        self.report = report
        self.threads = threads
        self.keep = keep
        self.failing: dict[str, tuple[FuzzCase, list[Failure]]] = {}

    def fail(self, case_id: str, case: FuzzCase, kind: str, path: str, msg: str) -> None:
        f = Failure(kind, path, case_id, msg)
        self.report.add(f)
        if len(self.report.failures) > self.keep:
            self.report.failures.pop()
        self.failing.setdefault(case_id, (case, []))[1].append(f)

    def run_case(self, case_id: str, case: FuzzCase, paths: list[Path_],
                 check_threads: bool, check_batch: bool = True,
                 exact: ExactOptimum | None = None) -> None:
        """Every path that takes the case's kind, every check (``exact``: the stack's
        extended-precision truth, for the ``above`` check; ``None``: none)."""
        stack = case.stack
        rep = self.report
        equality = case.kind in EQUALITY_KINDS
        if exact is not None and exact.ambiguous:
            exact = None
        for path in paths:
            if not takes(path, case.kind):
                continue
            rep.solves[path.name] = rep.solves.get(path.name, 0) + 1
            try:
                sol = _solve(path, stack)
            except DOCUMENTED_ERRORS:
                rep.refused[path.name] = rep.refused.get(path.name, 0) + 1
                rep.statuses.setdefault(path.name, {}).setdefault("refused", 0)
                rep.statuses[path.name]["refused"] += 1
                continue
            except Exception as exc:  # noqa: BLE001 - counting crashes is the point
                self.fail(case_id, case, "crash", path.name, f"{type(exc).__name__}: {exc}")
                continue
            st = rep.statuses.setdefault(path.name, {})
            st[sol.status] = st.get(sol.status, 0) + 1
            finite = bool(np.isfinite(sol.x).all())
            if sol.status != "failed" and not finite:
                self.fail(case_id, case, "nan", path.name, f"status {sol.status} with "
                          f"non-finite x")
                continue
            if exact is not None and sol.status == "optimal":
                excess = exact.excess(sol.x, case.rounding_error)
                if float(np.max(excess)) > 1.0 and not case.well_conditioned:
                    rep.above_ill[path.name] = rep.above_ill.get(path.name, 0) + 1
                elif float(np.max(excess)) > 1.0:
                    j = int(np.argmax(excess))
                    rel = float(exact.relative_excess(sol.x)[j])
                    self.fail(case_id, case, "above", path.name,
                              f"optimal but level {j}'s value is {rel:.2e} (relative) "
                              f"above the extended-precision optimum "
                              f"{exact.values[j]:.6g}, {excess[j]:.2g} times what "
                              f"float64 can tell apart")
            if equality and sol.status == "optimal":
                cert = check_lexicographic(stack, sol.x)
                if case.well_conditioned:
                    dist = relative_distance(sol.x, case.truth)
                    if dist > WRONG_TOL or not cert.ok:
                        self.fail(case_id, case, "wrong", path.name,
                                  f"optimal but {dist:.2e} from the truth, certificate "
                                  + ("ok" if cert.ok
                                     else f"fails at level {cert.first_failure.level}"))
                elif not cert.ok:
                    self.fail(case_id, case, "uncertified", path.name,
                              f"optimal but the certificate fails at level "
                              f"{cert.first_failure.level}")
            elif sol.status == "optimal":         # inequality, bounds: the KKT certificate
                cert = check_lexicographic(stack, sol.x)
                if not cert.ok:
                    self.fail(case_id, case, "uncertified", path.name,
                              f"optimal but the certificate fails at level "
                              f"{cert.first_failure.level}")
            if check_batch:
                self._compare_batch(case_id, case, path, sol)
            if check_batch:
                self._compare_prepared(case_id, case, path, sol)
            if check_threads:
                self._compare_threads(case_id, case, path, sol)

    def _mismatch(self, a, b, sa, sb, well: bool, min_sigma: float = 1.0,
                  rounding: float = 0.0) -> str:
        fa, fb = np.isfinite(a).all(), np.isfinite(b).all()
        if sa != sb:
            return f"status {sa} vs {sb}"
        if fa != fb:
            return "one answer is finite, the other not"
        if not fa or sa == "failed":
            return ""
        dist = relative_distance(a, b)
        tol = (min(MATCH_TOL / max(min_sigma, 1e-300), WRONG_TOL) if well
               else max(WRONG_TOL, 10.0 * rounding))
        if dist > tol and (well or sa == "optimal"):
            return f"answers differ by {dist:.2e}"
        return ""

    def _compare_batch(self, case_id, case, path, sol) -> None:
        stack = case.stack
        rng = np.random.default_rng(case.seed + 7)
        try:
            variants = [stack] + (same_shape_batch(stack, rng, 2, reduce=0.3)
                                  if case.kind in EQUALITY_KINDS else [stack])
            batch = formulations.solve_batch(variants, path.formulation, **path.options)
        except DOCUMENTED_ERRORS as exc:
            self.fail(case_id, case, "mismatch", path.name,
                      f"solve_batch refused what solve took: {exc}")
            return
        except Exception as exc:  # noqa: BLE001
            self.fail(case_id, case, "crash", path.name,
                      f"solve_batch: {type(exc).__name__}: {exc}")
            return
        for j, s in enumerate(variants):
            one = sol if j == 0 else _solve(path, s)
            # the variants keep the stack's ranks (or lower them) but not its verdict
            well = case.well_conditioned and j == 0
            why = self._mismatch(batch.X[j], one.x, batch.statuses[j], one.status, well,
                                 case.min_sigma, case.rounding_error if j == 0 else 0.0)
            if why and j > 0 and case.kind in EQUALITY_KINDS:   # the variant's own bound
                why = self._mismatch(batch.X[j], one.x, batch.statuses[j], one.status,
                                     False, 1.0, _own_rounding(s))
            if why:
                self.fail(case_id, case, "mismatch", path.name,
                          f"solve_batch row {j} vs solve: {why}")
                return

    def _compare_prepared(self, case_id, case, path, sol) -> None:
        """One prepared solver reused over same-layout stacks equals one-off solves."""
        stack = case.stack
        rng = np.random.default_rng(case.seed + 11)
        variants = (same_shape_batch(stack, rng, 2, reduce=0.3)
                    if case.kind in EQUALITY_KINDS else []) + [stack]
        try:
            solver = formulations.prepare(stack.layout, path.formulation, **path.options)
            for j, s in enumerate(variants):
                one = sol if s is stack else _solve(path, s)
                got = solver.solve(s)
                well = case.well_conditioned and s is stack
                why = self._mismatch(got.x, one.x, got.status, one.status, well,
                                     case.min_sigma,
                                     case.rounding_error if s is stack else 0.0)
                if why and s is not stack and case.kind in EQUALITY_KINDS:  # its own
                    why = self._mismatch(got.x, one.x, got.status, one.status, False, 1.0,
                                         _own_rounding(s))
                if why:
                    self.fail(case_id, case, "mismatch", path.name,
                              f"prepared solve {j} (reused) vs solve: {why}")
                    return
        except Exception as exc:  # noqa: BLE001
            self.fail(case_id, case, "crash" if not isinstance(exc, DOCUMENTED_ERRORS)
                      else "mismatch", path.name,
                      f"prepared solver: {type(exc).__name__}: {exc}")

    def _compare_threads(self, case_id, case, path, sol) -> None:
        """4 threads: one shared prepared solver (answers or ConcurrentUseError, never a
        wrong answer) and one solver per thread (the serial answers)."""
        reps = 4 * self.threads
        shared = formulations.prepare(case.stack.layout, path.formulation, **path.options)
        serial = shared.solve(case.stack).x          # a fresh solver's answer
        # a reused one's: a warm-started solver starts from its last solve's working set
        # (same optimum, other rounding; on an ill-posed stack it may alternate between
        # working sets): its serial answers once they repeat, every one of the cycle
        reused: list[np.ndarray] = []
        for _ in range(8):
            again = shared.solve(case.stack).x
            if any(np.array_equal(again, r, equal_nan=True) for r in reused):
                break
            reused.append(again)

        def on_shared(_):
            try:
                return shared.solve(case.stack).x, reused
            except ConcurrentUseError:
                return None, None

        def own(_):
            return formulations.prepare(case.stack.layout, path.formulation,
                                        **path.options).solve(case.stack).x, [serial]
        try:
            with ThreadPoolExecutor(self.threads) as pool:
                xs = list(pool.map(on_shared, range(reps))) + list(pool.map(own, range(reps)))
        except Exception as exc:  # noqa: BLE001
            self.fail(case_id, case, "threads", path.name, f"{type(exc).__name__}: {exc}")
            return
        for x, expected in xs:
            if x is not None and not any(np.array_equal(x, e, equal_nan=True)
                                         for e in expected):
                self.fail(case_id, case, "threads", path.name,
                          "a concurrent solve differs from the serial one")
                return


def run(n: int, seed: int, *, kinds=("equality",), paths: list[str] | None = None,
        threads: int = 4, thread_every: int = 10, batch_every: int = 1,
        sizes: dict | None = None, out: Path | None = None, keep: int = 1000,
        progress: Callable[[str], None] | None = None, exact: bool | None = None,
        start: int = 0) -> FuzzReport:
    """Fuzz ``n`` stacks of each kind; see the module docstring.

    Args:
        n: Stacks per kind.
        seed: Run seed.
        kinds: Of :data:`GENERATORS`: ``"equality"``, ``"inequality"``, ``"bounds"``,
            ``"mixed_scale"``.
        paths: Names of :func:`registry_paths` (default: all whose formulation is available).
        threads: Threads of the concurrency check.
        thread_every: Run the concurrency check on every ``thread_every``-th case.
        batch_every: Compare with ``solve_batch`` on every ``batch_every``-th case.
        sizes: ``max_n``, ``max_levels``, ``max_rows`` for the generators (their
            defaults otherwise: the issue's families).
        out: Folder for the failing stacks (not written when ``None``).
        keep: Failures kept with details in the report.
        progress: Called with a line every 1000 cases.
        exact: Judge ``optimal`` answers against the extended-precision truth
            (:func:`hierarchy.exact.exact_optimum`, stacks of ``n ≤ 40``): ``None``
            (default) on the ``mixed_scale`` kind only, ``True`` on every equality kind.
        start: Index of the first case (cases ``start … start + n − 1``: a long run in
            chunks).
    """
    known = registry_paths()
    avail = {f.name for f in formulations.available() if f.available}
    chosen = [known[p] for p in paths] if paths else \
        [p for p in known.values() if p.formulation in avail]
    report = FuzzReport()
    runner = _Runner(report, threads, keep)
    t0 = time.perf_counter()
    for kind in kinds:
        report.stacks[kind] = n
        judge = kind in EQUALITY_KINDS and (exact or (exact is None
                                                      and kind == "mixed_scale"))
        for i in range(start, start + n):
            case = _case(kind, seed, i, sizes)
            if kind in EQUALITY_KINDS:
                report.well_conditioned += int(case.well_conditioned)
            truth = exact_optimum(case.stack) if judge else None
            if truth is not None:
                counts = report.exact.setdefault(kind, [0, 0, 0])
                counts[0] += 1
                counts[1] += int(truth.ambiguous)
                counts[2] += int(case.well_conditioned and not truth.ambiguous)
            runner.run_case(f"{kind}-{seed}-{i}", case, chosen,
                            thread_every > 0 and i % thread_every == 0,
                            batch_every > 0 and i % batch_every == 0, truth)
            if progress is not None and (i + 1 - start) % 1000 == 0:
                progress(f"{kind}: {i + 1 - start}/{n} stacks, {report.total_failures} failures, "
                         f"{time.perf_counter() - t0:.0f} s")
    report.time_s = time.perf_counter() - t0
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        for case_id, (case, fails) in runner.failing.items():
            kind, s, i = case_id.split("-")
            text = "; ".join(f"{f.path}: {f.kind}: {f.message}" for f in fails[:5])
            save_stack(case.stack, out / f"{case_id}.json",
                       description=f"prioik fuzz case {i} of --seed {s} ({kind}, "
                                   f"well-conditioned: {case.well_conditioned}): {text}")
    return report


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fuzz", help="property-fuzz the formulations on seeded random stacks",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=1000, help="stacks per kind (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    p.add_argument("--kind", choices=("equality", "inequality", "bounds", "mixed_scale",
                                      "both", "all"),
                   default="both", help="stack kind (both: equality and inequality; all: "
                                        "the four; default both)")
    p.add_argument("--start", type=int, default=0,
                   help="index of the first case (a long run in chunks; default 0)")
    p.add_argument("--exact", action="store_true",
                   help="judge equality stacks of n <= 40 against the extended-precision "
                        "truth too (mixed_scale stacks always are)")
    p.add_argument("--paths", default="", help=f"comma-separated paths (default: all of "
                                               f"{', '.join(registry_paths())})")
    p.add_argument("--threads", type=int, default=4, help="threads of the concurrency check")
    p.add_argument("--thread-every", type=int, default=10,
                   help="concurrency check on every N-th stack (0: never)")
    p.add_argument("--out", type=Path, default=None,
                   help="folder for failing stacks as JSON (reload with `prioik solve`)")
    p.set_defaults(func=_cmd)


def _cmd(args: argparse.Namespace) -> int:
    if args.n < 1:
        raise ValueError(f"--n must be ≥ 1, got {args.n}")
    chosen = [s for s in args.paths.split(",") if s] or None
    known = registry_paths()
    for p in chosen or []:
        if p not in known:
            raise ValueError(f"unknown fuzz path {p!r}; known: {', '.join(known)}")
    kinds = {"both": ("equality", "inequality"), "all": tuple(GENERATORS)}.get(
        args.kind, (args.kind,))
    report = run(args.n, args.seed, kinds=kinds, paths=chosen, threads=args.threads,
                 thread_every=args.thread_every, out=args.out, exact=args.exact or None,
                 start=args.start, progress=lambda line: print(line, file=sys.stderr, flush=True))
    print(f"prioik fuzz --n {args.n} --seed {args.seed}: "
          + ", ".join(f"{v} {k} stacks" for k, v in report.stacks.items())
          + f" ({report.well_conditioned} equality well-conditioned"
          + "".join(f"; {kind}: {c[0]} with an extended-precision truth, {c[1]} of them "
                    f"ambiguous, {c[2]} judged by it" for kind, c in report.exact.items())
          + f"), {report.time_s:.0f} s")
    print(report.table())
    if report.above_ill:
        print("optimal answers above the extended-precision optimum on stacks that are "
              "not well-conditioned (not failures): "
              + ", ".join(f"{p} {c}" for p, c in report.above_ill.items()))
    for f in report.failures[:20]:
        print(f"  {f.case} {f.path}: {f.kind}: {f.message}")
    if args.out is not None and report.failures:
        print(f"failing stacks saved in {args.out}")
    return 1 if report.total_failures else 0
