"""The rows each formulation and baseline adds to prioik's reports, declared here, by the
benchmarks (the solver modules declare none): a table keyed by registry name (or external
baseline name, :data:`~prioik.benchmarks.variants.BASELINES`).

:data:`REPORT_VARIANTS` lists, per name, the settings worth a row of their own
(:class:`ReportVariant`); :data:`REPORT_OPT_OUTS` the reports whose default selection
leaves a formulation out, and why (``"REPORT:backends"`` keeps one row, the default
back-end, where the report would have one per back-end). :mod:`prioik.benchmarks.variants`
reads both: a formulation missing from them has its default row in every report.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["ReportVariant", "REPORT_VARIANTS", "REPORT_OPT_OUTS", "declared", "opt_outs"]


@dataclass(frozen=True)
class ReportVariant:
    """A setting of a formulation worth a row of its own in prioik's reports.

    Listed in :data:`REPORT_VARIANTS` under the formulation's name;
    :mod:`prioik.benchmarks.variants` turns each into a row of the reports it names,
    labelled ``NAME[tag]``. The reports are ``"bench"``, ``"validate"``, ``"properties"``,
    ``"roundoff"`` (the rotated-coordinates table of ``prioik properties``),
    ``"control_step"`` and the scenario reports ``"fencing"``, ``"arm"`` and ``"sweep"``
    (``"scenario"`` names all three).

    Attributes:
        tag: What distinguishes the row, e.g. ``"svd"`` or ``"clarabel,fixing=rows"``
            (``""`` with ``replaces_default``: the default row itself, changed).
        options: Options of every solve.
        reports: The reports the row appears in (``()``: every report).
        note: Why the row is there (printed where the report lists its rows).
        replaces_default: The row takes the place of the formulation's default row in
            those reports (e.g. the back-end a control loop uses).
        mass: ``"identity"``: the formulation gets ``M = I`` instead of the report's
            mass matrix (formulations that need one).
        level: Scenario reports: ``"acceleration"`` or ``"velocity"`` (the same tasks
            as ``J q̇ = ẋ* + K e``).
        limits: Scenario reports: the joint-limit form of the stack (``"activation"``,
            ``"bounds"``, ``"hard_bounds"``; ``None``: bounds for formulations that
            take inequality tasks, activation rows for the others).
    """

    tag: str
    options: dict[str, Any] = field(default_factory=dict)
    reports: tuple[str, ...] = ()
    note: str = ""
    replaces_default: bool = False
    mass: str | None = None
    level: str = "acceleration"
    limits: str | None = None


#: name → the rows of prioik's reports beside its default one
REPORT_VARIANTS: dict[str, tuple[ReportVariant, ...]] = {
    "cascaded_qp": (
        ReportVariant("daqp", {"solver": "daqp"}, reports=("fencing", "sweep", "control_step"),
                      replaces_default=True,
                      note="one QP per level with DAQP, the fastest exact back-end on the G1 "
                           "stacks; joint limits as bounds"),
        ReportVariant("daqp,velocity", {"solver": "daqp"}, reports=("fencing", "sweep"),
                      level="velocity",
                      note="the same tasks at velocity level (J q̇ = ẋ* + K e, limits as bounds "
                           "on q̇), exact hierarchy: the like-for-like counterpart of PlaCo's "
                           "KinematicsSolver"),
        ReportVariant("quadprog", {"solver": "quadprog"}, reports=("arm",), replaces_default=True,
                      note="one QP per level with quadprog (DAQP finds no solution at the "
                           "Panda's orientation level after 1.7 s), joint limits as bounds"),
        ReportVariant("quadprog,velocity", {"solver": "quadprog"}, reports=("arm",),
                      level="velocity",
                      note="the same at velocity level (J q̇ = ẋ* + K e, bounds on q̇)"),
        # how the higher optima are fixed in the cascade
        ReportVariant("clarabel,fixing=rows", {"solver": "clarabel", "fixing": "rows"},
                      reports=("validate",)),
        ReportVariant("clarabel,fixing=nullspace", {"solver": "clarabel", "fixing": "nullspace"},
                      reports=("validate",)),
        ReportVariant("quadprog,fixing=rows", {"solver": "quadprog", "fixing": "rows"},
                      reports=("validate",)),
        ReportVariant("proxqp,fixing=nullspace", {"solver": "proxqp", "fixing": "nullspace"},
                      reports=("validate",)),
        ReportVariant("quadprog,fix_active=False", {"solver": "quadprog", "fix_active": False},
                      reports=("validate",)),
    ),
    "chiaverini": (
        ReportVariant("numpy", {"kernel": "numpy"}, reports=("bench",),
                      note="the readable numpy SVD sum (the default, kernel='auto', is the "
                           "compiled C++ core)"),
    ),
    "daqp_hierarchical": (
        ReportVariant("raw", {"compress_levels": False, "check": False}, reports=("bench",),
                      note="DAQP's C call alone: no SVD compression of the levels, no "
                           "conflicting-level check (faster, not exact on conflicting levels)"),
        ReportVariant("compress_levels=False", {"compress_levels": False}, reports=("validate",),
                      note="without the SVD compression of the levels"),
    ),
    "extended_jacobian": (
        ReportVariant("svd", {"nullspace": "svd"}, reports=("bench", "properties"),
                      note="the paper's SVD path (J_{i-1}^A by SVD)"),
        ReportVariant("lapack", {"kernel": "lapack"}, reports=("bench",),
                      note="the readable LAPACK nested-QR path (the default, kernel='auto', is "
                           "the compiled C++ core up to n = 160, LAPACK above)"),
        ReportVariant("eq27", {"damping": 1e-2}, reports=("scenario", "properties"),
                      note="the paper's eq. 27, λ = 0.01, with Z_i of r_i rows spanning "
                           "range(N_{i-1} J_iᵀ) (z_basis='task_range', eq. 12-13 and Theorem 1)"),
        ReportVariant("eq27_null_space", {"damping": 1e-2, "z_basis": "null_space"},
                      reports=("fencing", "properties"),
                      note="eq. 27, λ = 0.01, read with a basis of the whole null space of the "
                           "higher levels (z_basis='null_space')"),
        ReportVariant("svd,eq27", {"nullspace": "svd", "damping": 1e-2}, reports=("properties",),
                      note="eq. 27 on the SVD path"),
        ReportVariant("svd,eq27_null_space",
                      {"nullspace": "svd", "damping": 1e-2, "z_basis": "null_space"},
                      reports=("properties",), note="eq. 27, whole null space, on the SVD path"),
    ),
    "hierarchical_active_set": (
        ReportVariant("velocity", level="velocity", reports=("scenario",),
                      note="the same at velocity level (J q̇ = ẋ* + K e, the limits as bounds on "
                           "q̇): exact, like for like with PlaCo's KinematicsSolver"),
    ),
    "lexls": (
        ReportVariant("raw", {"check": False}, reports=("bench",),
                      note="lexls's C++ solve alone (no certificate): its status as it "
                           "reports it"),
    ),
    "nullspace": (
        ReportVariant("numpy", {"kernel": "numpy"}, reports=("bench",),
                      note="the readable numpy SVD recursion (the default, kernel='auto', is the "
                           "compiled C++ core)"),
        ReportVariant("damped", {"damping": 0.05}, reports=("scenario",),
                      note="the SR (damped least-squares) inverse on every level, λ = 0.05 "
                           "(λ = 1e-2 left q̈ peaks of 355 in the incompatible fencing run, 0.05 "
                           "keeps them at 65)"),
        ReportVariant("damping=0.01", {"damping": 1e-2}, reports=("properties",),
                      note="the damped least-squares inverse with the λ of eq. 27's rows"),
        ReportVariant("reproject=False", {"reproject": False}, reports=("roundoff",),
                      note="the textbook projector step, without the extra N_{i-1}"),
    ),
    "operational_space": (
        ReportVariant("numpy", {"kernel": "numpy"}, reports=("bench",),
                      note="the readable numpy recursion (the default, kernel='auto', is the "
                           "compiled C++ core)"),
        ReportVariant("reproject=False", {"reproject": False}, reports=("roundoff",),
                      note="the textbook projector step, without the extra N_{i-1}"),
    ),
    "sns": (
        ReportVariant("", limits="hard_bounds", reports=("scenario", "control_step"),
                      replaces_default=True,
                      note="the joint-limit bounds as hard limits above every task (level 0), "
                           "strict priorities, task scaling when a task cannot be met within "
                           "them"),
        ReportVariant("velocity", level="velocity", limits="hard_bounds", reports=("scenario",),
                      note="SNS at velocity level (J q̇ = ẋ* + K e, the q̇ bounds as level 0)"),
    ),
    "unifying": (
        ReportVariant("numpy", {"kernel": "numpy"}, reports=("bench",),
                      note="the readable numpy eq. 40 (the default, kernel='auto', is the "
                           "compiled C++ core)"),
        ReportVariant("M=I", mass="identity", reports=("properties",),
                      note="with M = I (the report's other row has a seeded SPD M)"),
    ),
    "mink": (
        ReportVariant("quadprog", {"solver": "quadprog"}, reports=("scenario",),
                      note="the same with quadprog, the pink row's back-end"),
    ),
    "pink": (
        ReportVariant("daqp", {"solver": "daqp"}, reports=("scenario",),
                      note="the same with DAQP, the fastest back-end measured here for pink's "
                           "QPs (G1, 0.2 s: daqp 161, quadprog 173, proxqp 293, osqp 1143 µs "
                           "per solve)"),
    ),
}

#: name → ``{report: reason}``: the reports whose default selection leaves it out
REPORT_OPT_OUTS: dict[str, dict[str, str]] = {
    "cvxpy": {
        "scenario": "a modelling layer, tens of ms per level QP: a scenario run takes minutes; "
                    "cascaded_qp solves the same cascade",
        "control_step": "a modelling layer, tens of ms per level QP; cascaded_qp solves the "
                        "same cascade",
        "validate:backends": "a modelling layer over the solvers cascaded_qp's rows cover: "
                             "Clarabel alone unless --cvxpy-backends",
    },
    "reference": {"scenario": "the test oracle: one nested SVD per level and step; "
                               "extended_jacobian gives the same q̈"},
}


def declared(name: str) -> tuple[ReportVariant, ...]:
    """The rows :data:`REPORT_VARIANTS` declares for ``name`` (``()``: none)."""
    return REPORT_VARIANTS.get(name, ())


def opt_outs(name: str) -> dict[str, str]:
    """The opt-outs :data:`REPORT_OPT_OUTS` declares for ``name`` (``{}``: none)."""
    return REPORT_OPT_OUTS.get(name, {})
