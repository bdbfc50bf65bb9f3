"""lexls: the C++ lexicographic least-squares solver this field compares with.

lexls (Dimitrov, Sherikov & Wieber, "Efficient resolution of potentially conflicting
linear constraints in robotics", 2015; header-only C++ over Eigen, BSD-2) solves

    lex min over x, v:  (‖v_1‖², …, ‖v_k‖²)   s.t.   lower_i ≤ A_i x − v_i ≤ upper_i,

by a primal active set over all levels at once on its lexicographic QR. prioik binds it
(``prioik._lexls``, core/bindings/lexls.cpp) when its headers are found at build time
(``PRIOIK_LEXLS_DIR``, else ``../shared/peer/lexls`` beside the repository): a peer for
the benchmarks and ``prioik validate``, not one of prioik's own solvers.

Each task's rows enter weighted by ``√w`` (an equality row as ``b ≤ A x − v ≤ b``, an
infinite bound as ±1e30, lexls's phase 1 needing finite numbers; a zero row, whose
violation no ``x`` changes, is left free). lexls has no
minimum-norm tie-break: on a stack that leaves directions free its ``x`` is a
lexicographic optimum, not the minimum-norm one (the certificate below checks the
levels only). A prepared solver hot-starts as lexls's documentation says — the previous
``x`` (``set_x0``) and the previous working set (``api_activate``) — when
``hot_start=True``; every solve builds lexls's problem anew (lexls's ``reset`` cannot
clear a hot start).

Status: ``"optimal"`` when lexls reports the problem solved and, with ``check=True``
(default), the answer passes the verification stage's certificate
(:func:`~prioik.formulations.verification.certify`) on the levels (no tie-break: the
certificate, its ambiguity record, and the exact active set's answer as a witness of a
lower point); ``"approximate"`` when it does not (``diagnostics.reason`` says why) or
lexls stopped at its factorization cap (:attr:`Detail.capped`: its answer is where it
stopped, not solved); ``"failed"`` on a non-finite answer. Its own record:
:class:`Detail`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from prioik.hierarchy import StackData, StackLayout, TaskStack

from . import contract
from .base import Capabilities, CheckRequest, Diagnostics, Outcome, Status
from .options import Option, validate_options

try:
    from prioik import _lexls
except ImportError as exc:
    raise ImportError(
        "lexls was not built with this prioik: its headers were not found when prioik was "
        "installed; point PRIOIK_LEXLS_DIR at the folder holding lexls/lexlsi.h and "
        "reinstall (`PRIOIK_LEXLS_DIR=... pip install -e .`)", name=__name__) from exc

@dataclass(frozen=True, slots=True)
class Detail:
    """``lexls``'s own record (``sol.diagnostics.detail``).

    Attributes:
        termination: lexls's status name.
        factorizations: Factorizations lexls made.
        active: Rows in its final working set.
        hot_started: The solve started from the last one's ``x`` and working set.
        capped: lexls stopped at ``max_factorizations`` (its answer is where it stopped).
    """

    termination: str
    factorizations: int
    active: int
    hot_started: bool
    capped: bool = False


NAME = "lexls"
DESCRIPTION = ("lexls (Dimitrov, Sherikov & Wieber 2015): C++ lexicographic least squares "
               "with inequalities, a peer built from its headers (no minimum-norm tie-break)")
CAPABILITIES = Capabilities(equalities=True, inequalities=True, weights=True,
                            needs_mass_matrix=False, exact=False)
OPTIONS = {
    "max_factorizations": Option(200, "int", "lexls's cap on factorizations (its default "
                                 "200; a capped solve is 'approximate', Detail.capped)",
                                 minimum=1),
    "tol_linear_dependence": Option(1e-12, "float", "lexls's absolute tolerance on squared "
                                    "column norms in its QR (its default)", minimum=0.0,
                                    exclusive_minimum=True),
    "hot_start": Option(True, "bool", "prepared solver: start from the previous x and "
                        "working set (lexls's set_x0 and api_activate); False: every solve "
                        "cold"),
    "check": Option(True, "bool", "'optimal' only when the answer passes "
                    "check_lexicographic (the levels; lexls has no tie-break)"),
}

_TERMINATION = {_lexls.PROBLEM_SOLVED: "solved",
                _lexls.PROBLEM_SOLVED_CYCLING_HANDLING: "solved (cycling handling)",
                _lexls.MAX_NUMBER_OF_FACTORIZATIONS_EXCEEDED: "factorization cap"}


def solve(stack: TaskStack, **options) -> Outcome:
    """lexls's answer to ``stack`` (a cold solve; see the module docstring)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, FORMULATION.settings_of(opts)).solve(stack.data)


class Prepared(contract.Prepared):
    """lexls prepared for one layout: the weighted rows' buffers allocated once, the
    previous ``x`` and working set kept for the next solve's hot start.

    Args:
        layout: The stack layout.
        settings: :data:`FORMULATION`'s settings (every option of :data:`OPTIONS`,
            validated).
    """

    def __init__(self, layout: StackLayout, settings: Any) -> None:
        self.layout = layout
        self.hot_start = bool(settings.hot_start)
        self.check = bool(settings.check)
        #: the verification stage checks the levels only (lexls has no tie-break)
        self._check = CheckRequest(auto=self.check, minimum_norm=False)
        self.max_factorizations = int(settings.max_factorizations)
        starts = np.asarray(layout.starts)
        self._solver = _lexls.LexlsSolver(layout.n, np.diff(starts).astype(int).tolist(),
                                          self.max_factorizations,
                                          float(settings.tol_linear_dependence))
        m = int(starts[-1])
        self._eq = np.asarray(layout.row_is_equality, dtype=bool)
        self._A = np.empty((m, layout.n))
        self._lower, self._upper = np.empty(m), np.empty(m)

    def reset(self) -> None:
        """Forget the previous solve (the next one is cold)."""
        self._solver.reset()

    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        """lexls on the data's rows, weighted by ``√w`` (see the module docstring).

        Raises:
            CoreInputError: a value lexls cannot take (non-finite ``A``, a NaN bound,
                ``lower > upper``), naming it.
        """
        sw, eq = data.sqrt_weight, self._eq
        np.multiply(sw[:, None], data.A, out=self._A)
        for bound, side in ((self._lower, data.lower), (self._upper, data.upper)):
            np.copyto(bound, side)
            np.copyto(bound, data.b, where=eq)      # an equality row: b ≤ A x − v ≤ b
            bound *= sw
        # a zero row's violation is the same at every x: left free (lexls would hold it
        # violated and print a warning), its residual counted by the registry as is
        zero = ~self._A.any(axis=1)
        if zero.any():
            self._lower[zero], self._upper[zero] = -np.inf, np.inf
        res = self._solver.solve(self._A, self._lower, self._upper, self.hot_start)
        x = self._solver.x.copy()
        capped = res.termination == _lexls.MAX_NUMBER_OF_FACTORIZATIONS_EXCEEDED
        detail = Detail(_TERMINATION.get(res.termination, str(res.termination)),
                        int(res.factorizations), int(res.active), bool(res.hot_started),
                        capped)
        out = Outcome(x, Status.OPTIMAL, Diagnostics(detail=detail), check=self._check)
        if not np.isfinite(x).all():
            self._solver.reset()
            return out.fail("lexls returned non-finite values", "non_finite")
        if capped:
            out.status = Status.APPROXIMATE
            out.diagnostics.reason = (f"lexls stopped at its cap of {self.max_factorizations}"
                                      f" factorizations (max_factorizations): not solved")
        return out


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
