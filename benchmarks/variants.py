"""The rows of every report: formulation variants derived from the registry.

A :class:`Variant` is a formulation with fixed options — and, in the scenario reports,
the form of the stack it gets — under one label, in one syntax everywhere:
``formulation`` for its defaults, ``formulation[tag]`` otherwise
(``cascaded_qp[daqp]``: a back-end; ``extended_jacobian[svd]``: a declared setting;
``cascaded_qp[daqp,velocity]``: both).

:func:`table` lists the variants of one report (:data:`REPORTS`):

1. every available formulation of :data:`prioik.formulations.registry.PLUGINS` with its
   default options — one row per back-end in the reports that compare back-ends
   (:data:`BACKEND_REPORTS`);
2. the rows :data:`prioik.benchmarks.report_rows.REPORT_VARIANTS` declares for that
   formulation and report (:class:`~prioik.benchmarks.report_rows.ReportVariant`: extra
   rows, or a setting that replaces the default row there);
3. in the scenario reports (:data:`SCENARIO_REPORTS`), the external IK libraries of
   :data:`BASELINES` and the scenario experiment's own studies (``STUDIES`` of
   :data:`STUDY_MODULES`: runs that only make sense for that scenario, such as a step
   bound on its sword-tip task).

A formulation whose :data:`~prioik.benchmarks.report_rows.REPORT_OPT_OUTS` entry names
the report (or ``"scenario"`` for every scenario report) is left out of the report's
default selection, with its reason in the report's notes; its rows stay known, so a
report that takes labels (``prioik fencing --formulations``, a sweep file) can still ask
for them. A key ``"REPORT:backends"``
keeps one row (the default back-end) where the report would have one per back-end.

So a formulation added to the registry appears in ``prioik validate``, ``properties``,
``bench``, ``fencing``, ``arm`` and ``sweep`` without an edit in any of them.
"""

from __future__ import annotations

import dataclasses
import importlib
import re
from dataclasses import dataclass, field
from typing import Any

from . import report_rows
from .report_rows import ReportVariant

__all__ = ["Variant", "VariantTable", "table", "parse_label", "split_labels", "is_damped",
           "capabilities", "REPORTS",
           "SCENARIO_REPORTS", "BACKEND_REPORTS", "BASELINES", "baseline_profiles",
           "STUDY_MODULES",
           "DAMPING_OPTIONS"]

#: every report that lists variants
REPORTS = ("bench", "validate", "properties", "roundoff", "control_step", "fencing", "arm",
           "sweep")
#: the reports that run scenarios (``"scenario"`` in a plugin's declaration names them all)
SCENARIO_REPORTS = ("fencing", "arm", "sweep")
#: the reports that give each back-end of a formulation a row of its own
BACKEND_REPORTS = ("bench", "validate")
#: external IK libraries run in the scenario reports: name → module (``NAME``,
#: ``DESCRIPTION``, ``LEVEL``, ``profile()``,
#: ``unavailable_reason(options)``,
#: ``steps(scenario, variant, duration=, dt=, progress=)``: the run as a step generator
#: that returns its result, as :func:`prioik.robots.simulation_steps`)
BASELINES = {"placo_kinematics_solver": "prioik.benchmarks.placo_baseline",
             "pink": "prioik.benchmarks.pink_baseline",
             "mink": "prioik.benchmarks.mink_baseline",
             "tsid": "prioik.benchmarks.tsid_baseline"}
#: scenario → the experiment module whose ``STUDIES`` (a tuple of :class:`Variant`) add
#: that scenario's own runs
STUDY_MODULES = {"fencing": "prioik.benchmarks.fencing", "arm": "prioik.benchmarks.arm"}
#: options whose non-zero value makes a run a damped (or step-bounded) one
DAMPING_OPTIONS = ("damping", "level_damping", "step_bound", "singular_threshold")

_LABEL = re.compile(r"^([A-Za-z_]\w*)(?:\[([^\[\]]*)\])?$")


def parse_label(label: str) -> tuple[str, str]:
    """``(formulation, tag)`` of a label (``tag`` empty for the defaults).

    Raises:
        ValueError: not ``name`` or ``name[tag]``.
    """
    m = _LABEL.match(label.strip())
    if m is None:
        raise ValueError(f"{label!r} is not a run label (formulation or formulation[tag])")
    return m.group(1), m.group(2) or ""


def check_formulations(labels, baselines: bool = False) -> None:
    """Refuses (``ValueError``, listing the registry's names) a label whose formulation
    is not registered (nor, with ``baselines``, an external baseline): a check by name
    alone, before any plugin is imported; a report's :meth:`VariantTable.check_names`
    then checks the tags."""
    from prioik import formulations
    known = formulations.names() + (list(BASELINES) if baselines else [])
    unknown = []
    for label in labels:
        try:
            name, _ = parse_label(label)
        except ValueError:
            name = ""
        if name not in known:
            unknown.append(label)
    if unknown:
        raise ValueError(f"unknown formulation {', '.join(map(repr, unknown))}; known: "
                         f"{', '.join(known)}")


def split_labels(text: str) -> list[str]:
    """The labels of a comma-separated list (commas inside ``[...]`` belong to a tag)."""
    out, depth, cur = [], 0, []
    for ch in text:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth = max(0, depth - 1)
        if ch == "," and depth == 0:
            out.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    out.append("".join(cur))
    return [s.strip() for s in out if s.strip()]


@dataclass(frozen=True)
class Variant:
    """A formulation with fixed options under one label.

    Attributes:
        formulation: Registry name, or an external baseline's (:data:`BASELINES`).
        tag: ``""`` for the defaults, else what distinguishes the options.
        options: Options of every solve (validated by the registry when solving).
        note: Why the row is there (the plugin's description for a default row).
        mass: ``"identity"``: ``M = I`` instead of the report's mass matrix.
        level: Scenario runs: ``"acceleration"`` or ``"velocity"``.
        limits: Scenario runs: joint-limit form (``None``: the scenario's default for
            the formulation).
        armature: Scenario runs: rotor inertia added to every actuated joint of ``M``
            (kg·m²).
        only_in: Scenario runs: the scenario variants it is run in (``()``: every one).
        origin: ``"default"``, ``"backend"``, ``"declared"``
            (:data:`~prioik.benchmarks.report_rows.REPORT_VARIANTS`), ``"study"`` or
            ``"baseline"``.
    """

    formulation: str
    tag: str = ""
    options: dict[str, Any] = field(default_factory=dict, hash=False)
    note: str = field(default="", compare=False)
    mass: str | None = None
    level: str = "acceleration"
    limits: str | None = None
    armature: float = 0.0
    only_in: tuple[str, ...] = ()
    origin: str = field(default="default", compare=False)

    @property
    def label(self) -> str:
        return f"{self.formulation}[{self.tag}]" if self.tag else self.formulation

    @property
    def external(self) -> bool:
        """An external IK library (not a registry formulation)."""
        return self.formulation in BASELINES

    @property
    def backend(self) -> str:
        """The ``solver`` option (a QP back-end), ``""`` when not set."""
        return str(self.options.get("solver", ""))

    @property
    def damped(self) -> bool:
        """A damping or step-bound option is set (not zero)."""
        return is_damped(self.options)

    @property
    def needs_mass_matrix(self) -> bool:
        """The formulation takes ``mass_matrix`` (from its capabilities)."""
        caps = capabilities(self.formulation)
        return bool(caps and caps.needs_mass_matrix)

    def runs_in(self, scenario_variant: str) -> bool:
        """Whether a scenario run is made in ``scenario_variant``."""
        return not self.only_in or scenario_variant in self.only_in

    def options_text(self) -> str:
        """``key=value`` of every option, space-separated (``""``: the defaults)."""
        return " ".join(f"{k}={v}" for k, v in self.options.items())

    def to_dict(self) -> dict[str, Any]:
        """Plain data (what a sweep's worker receives and its run id hashes)."""
        return {"label": self.label, "formulation": self.formulation, "tag": self.tag,
                "options": dict(self.options), "mass": self.mass, "level": self.level,
                "limits": self.limits, "armature": self.armature,
                "only_in": list(self.only_in)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Variant:
        """The inverse of :meth:`to_dict`."""
        return cls(d["formulation"], d.get("tag", ""), dict(d.get("options") or {}),
                   mass=d.get("mass"), level=d.get("level", "acceleration"),
                   limits=d.get("limits"), armature=float(d.get("armature", 0.0)),
                   only_in=tuple(d.get("only_in") or ()))


def is_damped(options: dict[str, Any]) -> bool:
    """Whether ``options`` set a damping or step-bound option (:data:`DAMPING_OPTIONS`)
    to something other than zero."""
    return any(k in options and options[k] not in (None, 0, 0.0, {}, ())
               for k in DAMPING_OPTIONS)


def capabilities(formulation: str):
    """The :class:`~prioik.formulations.Capabilities` of a registry formulation
    (``None`` for a baseline or one that is not available here)."""
    from prioik import formulations
    if formulation in BASELINES or formulation not in formulations.PLUGINS:
        return None
    try:
        return formulations.get(formulation).capabilities
    except formulations.FormulationError:
        return None


@dataclass
class VariantTable:
    """The variants of one report.

    Attributes:
        report: Its name (:data:`REPORTS`).
        rows: The default selection, in order.
        known: Every label the report knows (the rows, plugins' opted-out rows, and
            for scenario reports the studies and baselines), label → variant.
        notes: Formulations not available here and the opt-outs, with reasons.
        unavailable: Formulation → why it cannot run here.
    """

    report: str
    rows: list[Variant]
    known: dict[str, Variant]
    notes: list[str]
    unavailable: dict[str, str] = field(default_factory=dict)

    @property
    def labels(self) -> list[str]:
        return [v.label for v in self.rows]

    def __getitem__(self, label: str) -> Variant:
        return self.known[label]

    def only(self, names) -> list[Variant]:
        """The rows whose formulation or label is in ``names`` (every row when empty).

        Raises:
            ValueError: a name that is neither a formulation of the report (runnable
                here or not) nor one of its labels; the message lists the known ones.
        """
        names = tuple(names or ())
        self.check_names(names)
        return [v for v in self.rows if not names or v.formulation in names
                or v.label in names]

    def check_names(self, names) -> None:
        """Refuses (``ValueError``) a name that is neither a formulation of the report
        (runnable here or not) nor one of its labels, listing the known ones."""
        formulations = list(dict.fromkeys([v.formulation for v in self.known.values()]
                                          + list(self.unavailable)))
        unknown = [n for n in names if n not in formulations and n not in self.known]
        if unknown:
            labels = [lb for lb in self.known if lb not in formulations]
            raise ValueError(
                f"unknown formulation or row label {', '.join(map(repr, unknown))}; "
                f"known formulations: {', '.join(formulations)}"
                + (f"; row labels: {', '.join(labels)}" if labels else ""))

    def select(self, labels: str | list[str] | None) -> tuple[list[Variant], list[str]]:
        """The default rows (``labels`` empty) or the named ones, and a message for
        each named one that cannot run here.

        Raises:
            ValueError: a label the report does not know (lists the known ones).
        """
        if not labels:
            return list(self.rows), []
        if isinstance(labels, str):
            labels = split_labels(labels)
        chosen, skipped, unknown = [], [], []
        for lb in labels:
            if lb in self.known:
                chosen.append(self.known[lb])
                continue
            try:
                name, _ = parse_label(lb)
            except ValueError:
                name = ""
            if name in self.unavailable:
                skipped.append(f"{lb}: {self.unavailable[name]}")
            else:
                unknown.append(lb)
        if unknown:
            raise ValueError(f"unknown run(s) {', '.join(unknown)}; known: "
                             f"{', '.join(self.known)}")
        return chosen, skipped


def _declared(name: str) -> tuple[ReportVariant, ...]:
    return report_rows.declared(name)


def _names_report(reports: tuple[str, ...], report: str) -> bool:
    return (not reports or report in reports
            or ("scenario" in reports and report in SCENARIO_REPORTS))


def _opt_out(name: str, key: str) -> str | None:
    outs = report_rows.opt_outs(name)
    if key in outs:
        return outs[key]
    if key in SCENARIO_REPORTS and "scenario" in outs:
        return outs["scenario"]
    return None


def _from_declaration(name: str, rv, origin: str = "declared") -> Variant:
    return Variant(name, rv.tag, dict(rv.options), rv.note, rv.mass, rv.level, rv.limits,
                   origin=origin)


def _formulation_rows(info, report: str, all_backends: bool
                      ) -> tuple[list[Variant], list[str]]:
    """The rows of one available formulation in ``report``, and notes."""
    name = info.name
    notes: list[str] = []
    declared = [rv for rv in _declared(name) if _names_report(tuple(rv.reports), report)]
    for rv in declared:
        unknown = sorted(set(rv.options) - set(info.options))
        if unknown:
            raise ValueError(f"formulation {name!r}: report row tag {rv.tag!r} sets "
                             f"unknown option(s) {', '.join(unknown)}")
    usable = []
    for rv in declared:
        solver = rv.options.get("solver")
        if solver is not None and info.backends and solver not in info.backends:
            notes.append(f"{name}[{rv.tag}]: back-end {solver} is not available here")
            continue
        usable.append(rv)
    replacing = [rv for rv in usable if rv.replaces_default]
    rows: list[Variant] = []
    expand = (report in BACKEND_REPORTS and "solver" in info.options
              and len(info.backends) > 1)
    one_row = _opt_out(name, f"{report}:backends")
    if expand and one_row is not None and not all_backends:
        notes.append(f"{name}: one row (its default back-end) in {report} ({one_row})")
        expand = False
    if replacing:
        rows += [_from_declaration(name, rv) for rv in replacing]
    elif expand:
        rows += [Variant(name, b, {"solver": b}, info.description, origin="backend")
                 for b in info.backends]
    else:
        rows.append(Variant(name, "", {}, info.description))
    rows += [_from_declaration(name, rv) for rv in usable if not rv.replaces_default]
    return rows, notes


def _baseline_rows(report: str) -> tuple[list[Variant], dict[str, str]]:
    rows, unavailable = [], {}
    for name, module in BASELINES.items():
        mod = importlib.import_module(module)
        why = mod.unavailable_reason({})
        if why:
            unavailable[name] = why
            continue
        rows.append(Variant(name, "", {}, mod.DESCRIPTION, level=mod.LEVEL,
                            origin="baseline"))
        for rv in _declared(name):
            if not _names_report(tuple(rv.reports), report):
                continue
            if mod.unavailable_reason(rv.options) is None:
                rows.append(dataclasses.replace(_from_declaration(name, rv, "baseline"),
                                                level=mod.LEVEL))
    return rows, unavailable


def baseline_profiles() -> dict[str, dict]:
    """Every baseline of :data:`BASELINES`: its ``profile()`` (library and version,
    level, priority model, what it is given) and ``here``: ``"runs"`` or why it cannot
    run here (``"not installed …"``)."""
    out = {}
    for name, module in BASELINES.items():
        mod = importlib.import_module(module)
        why = mod.unavailable_reason({})
        out[name] = {**mod.profile(), "here": "runs" if why is None else why}
    return out


def _studies(scenario: str) -> tuple[Variant, ...]:
    module = STUDY_MODULES.get(scenario)
    if module is None:
        return ()
    return tuple(getattr(importlib.import_module(module), "STUDIES", ()))


def table(report: str, scenario: str | None = None, all_backends: bool = False
          ) -> VariantTable:
    """The variants of ``report`` (see the module docstring).

    Args:
        report: One of :data:`REPORTS`.
        scenario: The scenario of a scenario report (default: the report's name for
            ``fencing`` and ``arm``; ``sweep`` needs it to add that scenario's studies).
        all_backends: Ignore ``"REPORT:backends"`` opt-outs (one row per back-end for
            every formulation that has several).

    Raises:
        ValueError: an unknown report, or a plugin declaring an option it does not have.
    """
    from prioik import formulations
    if report not in REPORTS:
        raise ValueError(f"unknown report {report!r}; known: {', '.join(REPORTS)}")
    if scenario is None and report in STUDY_MODULES:
        scenario = report
    studies = _studies(scenario) if report in SCENARIO_REPORTS and scenario else ()
    rows: list[Variant] = []
    known: dict[str, Variant] = {}
    notes: list[str] = []
    unavailable: dict[str, str] = {}

    def add(v: Variant, selected: bool) -> None:
        if v.label in known:
            raise ValueError(f"report {report!r}: two rows labelled {v.label!r}")
        known[v.label] = v
        if selected:
            rows.append(v)

    for info in formulations.available():
        if not info.available:
            unavailable[info.name] = f"not available here ({info.reason})"
            notes.append(f"{info.name}: not available here ({info.reason})")
            continue
        try:
            formulations.get(info.name)
        except formulations.FormulationError as exc:
            unavailable[info.name] = str(exc)
            notes.append(f"{info.name}: {exc}")
            continue
        out = _opt_out(info.name, report)
        if out is not None:
            notes.append(f"{info.name}: left out of {report} ({out})")
        own, more = _formulation_rows(info, report, all_backends)
        notes += more
        for v in own:
            add(v, out is None)
        for v in studies:
            if v.formulation == info.name:
                add(v, True)
    if report in SCENARIO_REPORTS:
        base, why = _baseline_rows(report)
        for v in base:
            add(v, True)
        for name, reason in why.items():
            unavailable[name] = reason
            notes.append(f"{name}: {reason}")
    return VariantTable(report, rows, known, notes, unavailable)
