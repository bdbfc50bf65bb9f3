"""Report variants derived from the formulation registry.

A :class:`Variant` is a formulation with fixed options under one label, in one syntax:
``formulation`` for its defaults, ``formulation:tag`` otherwise (``cascaded_qp:daqp``
for a back-end, ``extended_jacobian:svd`` for a declared setting) — the syntax of the
fencing table's run labels.

:func:`from_registry` lists the variants of every available formulation, so a
formulation added to :data:`prioik.formulations.registry.PLUGINS` appears in a report
that uses it without an edit there. A plugin module may declare

* ``REPORT_VARIANTS = {tag: {option: value}}`` — settings worth a row of their own;
* ``REPORT_OPT_OUTS = {report: reason}`` — reports it stays out of (``"sweep"``,
  ``"bench"``, ...), with the reason printed in their notes.

Used by ``prioik sweep`` (``formulations = "registry"``); ``bench``, ``validate`` and
``properties`` still carry their own variant tables (see the module docstrings there).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["Variant", "from_registry", "split_label"]


def split_label(label: str) -> tuple[str, str]:
    """``(formulation, tag)`` of a label (``tag`` empty for the defaults)."""
    name, _, tag = label.partition(":")
    return name, tag


@dataclass(frozen=True)
class Variant:
    """A formulation with fixed options.

    Attributes:
        formulation: Registry name.
        tag: ``""`` for the defaults, else what distinguishes the options.
        options: Options of every solve (validated by the registry when solving).
        needs_mass_matrix: Whether the formulation takes ``mass_matrix``.
    """

    formulation: str
    tag: str = ""
    options: dict[str, Any] = field(default_factory=dict, hash=False, compare=False)
    needs_mass_matrix: bool = False

    @property
    def label(self) -> str:
        return f"{self.formulation}:{self.tag}" if self.tag else self.formulation


def from_registry(report: str) -> tuple[list[Variant], list[str]]:
    """Every available formulation's variants for ``report``: its defaults (one per
    back-end when it has a ``solver`` option and several back-ends) and its
    ``REPORT_VARIANTS``; plugins opting out of ``report`` are left out.

    Returns:
        The variants and notes (unavailable formulations and opt-outs, with reasons).
    """
    from prioik import formulations
    out: list[Variant] = []
    notes: list[str] = []
    for info in formulations.available():
        if not info.available:
            notes.append(f"{info.name}: not available here ({info.reason})")
            continue
        mod = formulations.get(info.name)
        opt_outs = getattr(mod, "REPORT_OPT_OUTS", {}) or {}
        if report in opt_outs:
            notes.append(f"{info.name}: left out of {report} ({opt_outs[report]})")
            continue
        mm = bool(info.capabilities and info.capabilities.needs_mass_matrix)
        if info.backends and "solver" in info.options and len(info.backends) > 1:
            out += [Variant(info.name, b, {"solver": b}, mm) for b in info.backends]
        else:
            out.append(Variant(info.name, "", {}, mm))
        for tag, opts in (getattr(mod, "REPORT_VARIANTS", {}) or {}).items():
            if set(opts) <= set(info.options):
                out.append(Variant(info.name, tag, dict(opts), mm))
    return out, notes
