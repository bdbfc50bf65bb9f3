"""Typed formulation options: declared once per plugin, they validate and document.

Each plugin's ``OPTIONS`` maps an option name to an :class:`Option` (default, type,
range or choices, description). The registry validates every option once, at the
boundary (:func:`prioik.solve`, :func:`prioik.prepare`), and the plugin receives them
clean, as an instance of its typed settings dataclass (:func:`settings_class`);
``prioik list`` and ``--help`` print the same declarations.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .base import FormulationError

__all__ = ["Option", "validate_options", "describe", "settings_class"]

#: ``kind`` values an :class:`Option` understands.
KINDS = ("float", "int", "bool", "str", "matrix", "vector", "any")


@dataclass(frozen=True)
class Option:
    """One option of a formulation.

    Args:
        default: Value used when the option is not given (validated like any value,
            except that ``None`` is allowed when ``optional``).
        kind: ``"float"``, ``"int"``, ``"bool"``, ``"str"``, ``"matrix"`` (``n × n``,
            finite, symmetric), ``"vector"`` (length ``n``, finite) or ``"any"`` (checked by
            ``check`` alone).
        description: One line for ``prioik list`` and the docs.
        minimum: Inclusive lower bound of a number (``None``: unbounded).
        maximum: Inclusive upper bound of a number (``None``: unbounded).
        exclusive_minimum: ``minimum`` itself is not allowed (e.g. ``> 0``).
        exclusive_maximum: ``maximum`` itself is not allowed (e.g. ``< 1``).
        choices: Allowed values of a ``"str"`` option.
        optional: ``None`` is an allowed value (meaning "not given").
        allow_inf: ``±inf`` is an allowed number (else numbers must be finite).
        check: Extra validation ``check(value) -> value`` that raises ``ValueError``
            with a message (it is re-raised as :class:`FormulationError` naming the
            option); used for options whose shape depends on more than a type.
    """

    default: Any
    kind: str
    description: str
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    exclusive_maximum: bool = False
    choices: tuple[str, ...] = ()
    optional: bool = False
    allow_inf: bool = False
    check: Callable[[Any], Any] | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise FormulationError(f"unknown option kind {self.kind!r}; kinds: "
                                   f"{', '.join(KINDS)}")

    # ---------------------------------------------------------------- validate
    def validate(self, name: str, value: Any, n: int | None = None) -> Any:
        """The normalised value of option ``name``.

        Args:
            name: The option's name (used in messages).
            value: The value given.
            n: The stack's number of unknowns (for ``matrix`` and ``vector`` options).

        Raises:
            FormulationError: naming the option, for a wrong type, a value out of range,
                NaN, a string not among the choices, or a failed ``check``.
        """
        if value is None:
            if self.optional:
                return None
            raise FormulationError(f"option {name!r} must be {self._what()}, got None")
        kind = self.kind
        if kind == "float":
            value = self._number(name, value, float)
        elif kind == "int":
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise FormulationError(f"option {name!r} must be an integer, got "
                                       f"{value!r} ({type(value).__name__})")
            value = self._bounded(name, int(value))
        elif kind == "bool":
            if not isinstance(value, (bool, np.bool_)):
                raise FormulationError(f"option {name!r} must be True or False, got "
                                       f"{value!r} ({type(value).__name__})")
            value = bool(value)
        elif kind == "str":
            if not isinstance(value, str):
                raise FormulationError(f"option {name!r} must be a string, got {value!r} "
                                       f"({type(value).__name__})")
            if self.choices and value not in self.choices:
                raise FormulationError(f"option {name!r} must be one of "
                                       f"{', '.join(map(repr, self.choices))}, got {value!r}")
        elif kind == "matrix":
            value = _matrix(name, value, n)
        elif kind == "vector":
            value = _vector(name, value, n)
        if self.check is not None:
            try:
                value = self.check(value)
            except FormulationError:
                raise
            except (TypeError, ValueError) as exc:
                raise FormulationError(f"option {name!r}: {exc}") from None
        return value

    def _number(self, name: str, value: Any, cast) -> float:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            raise FormulationError(f"option {name!r} must be a number, got {value!r} "
                                   f"({type(value).__name__})")
        value = cast(value)
        if math.isnan(value):
            raise FormulationError(f"option {name!r} must be a number, got NaN")
        if math.isinf(value) and not self.allow_inf:
            raise FormulationError(f"option {name!r} must be finite, got {value!r}")
        return self._bounded(name, value)

    def _bounded(self, name: str, value):
        lo, hi = self.minimum, self.maximum
        if lo is not None and (value < lo or (self.exclusive_minimum and value == lo)):
            raise FormulationError(f"option {name!r} must be {self._range()}, got {value!r}")
        if hi is not None and (value > hi or (self.exclusive_maximum and value == hi)):
            raise FormulationError(f"option {name!r} must be {self._range()}, got {value!r}")
        return value

    def _range(self) -> str:
        lo, hi = self.minimum, self.maximum
        left = "" if lo is None else (f"> {lo:g}" if self.exclusive_minimum else f"≥ {lo:g}")
        right = "" if hi is None else (f"< {hi:g}" if self.exclusive_maximum else f"≤ {hi:g}")
        if left and right:
            return f"a finite number {left} and {right}"
        return f"a finite number {left or right}".rstrip()

    def _what(self) -> str:
        return {"float": self._range(), "int": "an integer", "bool": "True or False",
                "str": "a string", "matrix": "an n x n matrix", "vector": "a vector",
                "any": "given"}[self.kind]

    # ------------------------------------------------------------------- docs
    def doc(self) -> str:
        """``default; range; description`` in one line."""
        parts = [f"default {self.default!r}"]
        if self.choices:
            parts.append("one of " + "/".join(self.choices))
        elif self.kind in ("float", "int") and (self.minimum is not None
                                                 or self.maximum is not None):
            parts.append(self._range().replace("a finite number ", ""))
        return f"{self.description} ({'; '.join(parts)})"


def _real_array(name: str, value: Any, what: str) -> np.ndarray:
    """A float64 copy of ``value``; refuses what cannot be read and non-real dtypes."""
    try:
        arr = np.array(value, copy=True)
    except (TypeError, ValueError) as exc:
        raise FormulationError(f"option {name!r} cannot be read as a {what} ({exc})") from None
    if arr.dtype.kind not in "iuf":
        raise FormulationError(f"option {name!r} must hold real numbers, got dtype "
                               f"{arr.dtype}")
    return arr.astype(np.float64)


def _matrix(name: str, value: Any, n: int | None) -> np.ndarray:
    arr = _real_array(name, value, "matrix")
    if arr.ndim != 2 or (n is not None and arr.shape != (n, n)):
        raise FormulationError(f"option {name!r} must be {n}x{n} for this stack, got shape "
                               f"{arr.shape}")
    if not np.isfinite(arr).all():
        raise FormulationError(f"option {name!r} holds NaN or inf")
    if not np.allclose(arr, arr.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(arr).max())):
        raise FormulationError(f"option {name!r} must be symmetric (max |M - Mᵀ| = "
                               f"{np.abs(arr - arr.T).max():.3e})")
    arr.setflags(write=False)
    return arr


def _vector(name: str, value: Any, n: int | None) -> np.ndarray:
    arr = _real_array(name, value, "vector").reshape(-1)
    if (n is not None and arr.shape != (n,)) or not np.isfinite(arr).all():
        raise FormulationError(f"option {name!r} must be a finite vector of length {n}, got "
                               f"shape {np.shape(value)}")
    arr.setflags(write=False)
    return arr


def positive_semidefinite(value: np.ndarray) -> np.ndarray:
    """A ``check`` for a metric ``W``: symmetric positive semidefinite (a ``W`` that is
    singular is allowed; where it is not definite on the remaining null space the
    plugin reports it)."""
    eig = np.linalg.eigvalsh(value)
    if eig.size and eig[0] < -1e-12 * max(1.0, float(np.abs(eig).max())):
        raise ValueError(f"must be symmetric positive semidefinite (smallest eigenvalue "
                         f"{eig[0]:.3e})")
    return value


def rcond_option(what: str = "‖A_i‖_F") -> Option:
    """The relative rank threshold every plugin shares (``hierarchy.linalg``'s rule)."""
    from prioik.hierarchy import DEFAULT_RCOND
    return Option(DEFAULT_RCOND, "float", f"relative rank threshold: σ counts if "
                  f"σ > rcond·{what}", minimum=0.0, maximum=1.0, exclusive_maximum=True)


def dictionary(value: Any) -> dict:
    """A ``check``: a ``dict`` of keyword arguments (copied)."""
    if not isinstance(value, dict):
        raise ValueError(f"must be a dict of keyword arguments, got {type(value).__name__}")
    return dict(value)


def per_level_nonnegative(value: Any):
    """A ``check``: one finite number ≥ 0 or a sequence of them (one per level; the
    length is checked against the stack by the plugin)."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"must be a number ≥ 0 or one per level, got {value!r}") from None
    if arr.ndim > 1 or not np.isfinite(arr).all() or (arr < 0).any():
        raise ValueError(f"must be finite numbers ≥ 0 (one per level), got {value!r}")
    return value


def validate_options(formulation: str, declared: Mapping[str, Option], given: dict[str, Any],
                     n: int | None) -> dict[str, Any]:
    """Every declared option's value: the given ones validated, the rest defaulted.

    Raises:
        FormulationError: an unknown option (listing the declared ones) or an invalid
            value (naming the option).
    """
    unknown = sorted(set(given) - set(declared))
    if unknown:
        raise FormulationError(f"formulation {formulation!r} has no option "
                               f"{', '.join(unknown)}; its options: "
                               f"{', '.join(declared) or 'none'}")
    out = {}
    for key, opt in declared.items():
        if key in given:
            out[key] = opt.validate(key, given[key], n)
        else:
            out[key] = opt.default
    return out


def describe(declared: dict[str, Option]) -> dict[str, tuple[Any, str]]:
    """``{option: (default, one-line doc)}`` for listings."""
    return {key: (opt.default, opt.doc()) for key, opt in declared.items()}


#: the Python type of an option's value, by :attr:`Option.kind`
_TYPES: dict[str, Any] = {"float": float, "int": int, "bool": bool, "str": str,
                          "matrix": np.ndarray, "vector": np.ndarray, "any": Any}


def settings_class(formulation: str, declared: Mapping[str, Option]) -> type:
    """A frozen dataclass with one field per declared option, in order: its type from
    :attr:`Option.kind` (``T | None`` when ``optional``), its default the option's, its
    description in the field's metadata (``"description"``). Its name is the
    formulation's in CamelCase with ``Settings`` (``ExtendedJacobianSettings``).

    ``settings_class(name, declared)(**validate_options(name, declared, given, n))`` is
    a formulation's settings, typed.
    """
    fields = []
    for key, opt in declared.items():
        kind = _TYPES[opt.kind]
        kind = kind | None if opt.optional and kind is not Any else kind
        default = opt.default
        meta = {"description": opt.description}
        spec = (dataclasses.field(default_factory=functools.partial(copy.copy, default),
                                  metadata=meta)
                if type(default).__hash__ is None      # a dict, list or array: copied
                else dataclasses.field(default=default, metadata=meta))
        fields.append((key, kind, spec))
    name = "".join(part.capitalize() for part in formulation.split("_") if part) + "Settings"
    return dataclasses.make_dataclass(name, fields, frozen=True)
