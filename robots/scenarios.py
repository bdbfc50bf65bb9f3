"""The scenarios by name, above the scenario modules: :data:`SCENARIOS` and
:func:`make`, which builds one (``prioik fencing``, ``prioik arm``, a saved run's
replay). Each scenario implements :class:`robots.scenario.Scenario`."""

from __future__ import annotations

from .arm import ArmScenario
from .fencing import FencingScenario
from .scenario import Scenario
from .simulate import SimulationError

__all__ = ["SCENARIOS", "make"]

#: scenario name -> class
SCENARIOS: dict[str, type[Scenario]] = {"fencing": FencingScenario, "arm": ArmScenario}


def make(name: str, variant: str | None = None) -> Scenario:
    """Build scenario ``name`` (``"fencing"``, ``"arm"``) in ``variant`` (its first by
    default).

    Raises:
        SimulationError: unknown scenario or variant (lists the known ones).
    """
    if name not in SCENARIOS:
        raise SimulationError(f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)}")
    cls = SCENARIOS[name]
    return cls(variant or cls.variants[0])
