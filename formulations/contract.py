"""The plugin contract, declared: a :class:`Formulation` and its :class:`Prepared` solver.

A plugin module defines one :class:`Formulation` (``FORMULATION``): its name, one-line
description, :class:`~prioik.formulations.Capabilities`, typed options
(:class:`~prioik.formulations.Option`; their settings dataclass is
:attr:`Formulation.settings`), the back-ends it can use here, and the :class:`Prepared`
subclass that :meth:`Formulation.prepare` builds for one stack layout. The registry
(:mod:`.registry`) holds these objects and :class:`~prioik.formulations.PreparedSolver`
calls the prepared solver's methods, every one declared here: nothing of a plugin is
discovered by probing for attributes.

A plugin whose solve takes a whole stack and keeps no workspace subclasses
:class:`StackPrepared`, which checks each stack against the capabilities and rescales
the levels of extreme scale of an exact formulation around the plugin's own solve.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from prioik.hierarchy import StackData, StackLayout, TaskStack, UnsupportedTaskError

from .base import Capabilities, CheckRequest, FormulationError, Outcome, in_original_units
from .options import Option, settings_class

#: what a batched kernel gives (:meth:`Prepared.solve_batch`): the answers ``X`` (one row
#: per stack), their statuses, and the checks they ask the verification stage for
BatchOutcome = tuple[np.ndarray, list[str], "list[CheckRequest | None] | None"]

__all__ = ["Formulation", "Prepared", "StackPrepared", "check_layout_support",
           "check_support"]


def check_layout_support(name: str, caps: Capabilities, layout: StackLayout) -> None:
    """Raise :class:`UnsupportedTaskError` naming the first task of ``layout`` whose kind
    ``caps`` cannot take."""
    for i, level in enumerate(layout.levels):
        for task, _, kind in level:
            if kind == "inequality" and not caps.inequalities:
                raise UnsupportedTaskError("inequality tasks are not supported",
                                           formulation=name, task=task, level=i)
            if kind == "equality" and not caps.equalities:
                raise UnsupportedTaskError("equality tasks are not supported",
                                           formulation=name, task=task, level=i)


def check_support(name: str, caps: Capabilities, stack: TaskStack) -> None:
    """Raise :class:`UnsupportedTaskError` naming the first task ``caps`` cannot take
    (kinds, and differently weighted tasks sharing a level)."""
    check_layout_support(name, caps, stack.layout)
    if caps.weights:
        return
    for i, level in enumerate(stack.levels):
        if len(level) > 1:
            w = {float(v) for t in level for v in np.unique(t.weight)}
            if len(w) > 1:
                raise UnsupportedTaskError("weighted tasks sharing a level are not "
                                           "supported", formulation=name,
                                           task=level[0].name, level=i)


class Prepared(abc.ABC):
    """A formulation prepared for one stack layout: what
    :class:`~prioik.formulations.PreparedSolver` calls (one thread at a time; it enforces
    it). A subclass is built as ``Prepared(layout, settings)``: ``settings`` is an instance
    of its formulation's :attr:`Formulation.settings` (frozen, one typed field per option,
    every value validated), read by name (``settings.rcond``).

    Attributes:
        compiled: :meth:`solve_checked` reads the data's arrays in a compiled kernel and
            checks its own answer there (finite, of length ``n``, with its residuals).
        accepts_step_options: :meth:`solve` takes options that change every step
            (``mass_matrix``); the others are fixed at prepare.
    """

    compiled: bool = False
    accepts_step_options: ClassVar[bool] = False

    @abc.abstractmethod
    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        """Solve one stack of the layout (its data; the layout is checked by the caller).

        Args:
            data: The rows.
            settings: The settings of this call (the prepared ones with the step's
                options over them, ``dataclasses.replace``, validated), when the
                formulation :attr:`accepts_step_options` and a step gave some;
                ``None``: the prepared ones.
        """

    def solve_checked(self, data: StackData) -> Outcome | tuple:
        """:meth:`solve`, or, for an answer the plugin checked itself (what
        ``Outcome(..., checked=True)`` means: finite, of length ``n``, residuals given,
        ``‖x‖`` below the precision limit) with the status ``optimal``, the tuple ``(x,
        residuals, snapshot)``: ``snapshot`` is a
        :data:`~prioik.formulations.base.DiagnosticsSnapshot`, ``(diagnostics_of,
        values)`` with ``values`` the solve's own (copies: the next solve does not change
        them), and ``diagnostics_of(values)`` the :class:`~prioik.formulations.Diagnostics`
        that :meth:`solve` would give, built only when the Solution's diagnostics are
        read. The verification stage runs after it either way."""
        return self.solve(data)

    def solve_batch(self, datas: list[StackData]) -> BatchOutcome | None:
        """``(X, statuses, checks)`` of many stacks of the layout from a batched kernel
        (``checks``: per stack the :class:`~prioik.formulations.base.CheckRequest` its
        answer asks the verification stage for, as :attr:`Outcome.check`, or ``None``
        when no answer asks), or ``None`` when the formulation has none (the caller
        solves them one by one)."""
        return None

    def reset(self) -> None:
        """Forget what was kept from the last solve (a warm start): the next solve
        starts as after prepare. Nothing to forget by default."""
        return None


class StackPrepared(Prepared):
    """A :class:`Prepared` that solves each data's stack (``data.as_stack()``) with the
    plugin's own :meth:`solve_stack`, keeping no workspace: the stack is checked against
    :attr:`capabilities` (kinds, weights sharing a level), and an exact formulation
    solves it with its levels of extreme scale equilibrated
    (:meth:`~prioik.hierarchy.TaskStack.equilibrated`), its residuals read in the user's
    units. Step options are accepted.

    A subclass sets :attr:`name` and :attr:`capabilities` and defines
    :meth:`solve_stack`; :meth:`stacks_of` gives a batched kernel its stacks.
    """

    accepts_step_options: ClassVar[bool] = True
    #: the formulation's registry name (in messages)
    name: ClassVar[str]
    #: what it can take
    capabilities: ClassVar[Capabilities]

    def __init__(self, layout: StackLayout, settings: Any) -> None:
        self.layout = layout
        #: the formulation's settings (:attr:`Formulation.settings`) fixed at prepare
        self.settings = settings

    @abc.abstractmethod
    def solve_stack(self, stack: TaskStack, settings: Any) -> Outcome:
        """The plugin's solve of one (checked, equilibrated) stack with ``settings`` (an
        instance of its :attr:`Formulation.settings`)."""

    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        stack = data.as_stack()
        check_support(self.name, self.capabilities, stack)
        levels: list[int] = []
        if self.capabilities.exact:     # levels of extreme scale rescaled
            stack, levels = stack.equilibrated()
        out = self.solve_stack(stack, self.settings if settings is None else settings)
        if levels:
            out = in_original_units(out, data, levels)
        return out

    def stacks_of(self, datas: Sequence[StackData]) -> list[TaskStack]:
        """The stacks of ``datas`` as :meth:`solve` gives them to :meth:`solve_stack`:
        checked, and equilibrated for an exact formulation."""
        stacks = [d.as_stack() for d in datas]
        for s in stacks:
            check_support(self.name, self.capabilities, s)
        if self.capabilities.exact:
            stacks = [s.equilibrated()[0] for s in stacks]
        return stacks


def _no_backends() -> list[str]:
    return []


@dataclasses.dataclass(frozen=True)
class Formulation:
    """A formulation as a plugin declares it (its module's ``FORMULATION``), what the
    registry holds.

    Attributes:
        name: Registry name.
        description: One line.
        capabilities: What it can take.
        options: ``{option: Option}``, the only options it accepts (the registry
            validates them once).
        prepared: Its :class:`Prepared` subclass, built by :meth:`prepare`.
        backends: The back-ends it can use here (QP solvers); none by default.
    """

    name: str
    description: str
    capabilities: Capabilities
    options: Mapping[str, Option]
    prepared: type[Prepared]
    backends: Callable[[], list[str]] = _no_backends

    def prepare(self, layout: StackLayout, settings: Any) -> Prepared:
        """Its prepared solver for ``layout`` with ``settings``, an instance of
        :attr:`settings` (:meth:`settings_of` the validated options).

        Raises:
            FormulationError: ``settings`` is not an instance of :attr:`settings`.
        """
        if not isinstance(settings, self.settings):
            raise FormulationError(f"formulation {self.name!r} is prepared with its "
                                   f"{self.settings.__name__}, got "
                                   f"{type(settings).__name__}")
        return self.prepared(layout, settings)  # type: ignore[call-arg]

    def settings_of(self, options: Mapping[str, Any]) -> Any:
        """The :attr:`settings` instance holding ``options``: every declared option,
        validated (what :func:`~prioik.formulations.options.validate_options` gives)."""
        return self.settings(**options)

    @property
    def batched(self) -> bool:
        """Its prepared solver has a batched kernel of its own (its class defines
        :meth:`Prepared.solve_batch`)."""
        return self.prepared.solve_batch is not Prepared.solve_batch

    @functools.cached_property
    def settings(self) -> type:
        """The typed settings dataclass of :attr:`options` (one field per option, its
        type and default from the :class:`Option`):
        :func:`~prioik.formulations.options.settings_class`."""
        return settings_class(self.name, self.options)
