"""The optional parts of prioik: which ``pip install prioik[EXTRA]`` brings which module.

``pip install prioik`` installs the core (numpy, scipy, threadpoolctl, tqdm and the compiled
C++ core ``prioik._core``): the task-stack spec, the closed-form formulations and the
``solve``/``list``/``validate``/
``compare``/``properties`` commands. Everything else is an extra of ``pyproject.toml``
named by what it is for; :data:`EXTRAS` names the distributions that show each one is
installed, and a part that needs a missing extra raises :class:`MissingExtraError`
saying which to install (the formulation registry says the same in its reasons).
"""

from __future__ import annotations

import importlib.metadata

from .errors import PrioikError, UnknownNameError

#: extra -> (distributions that must be installed for it to count as installed, what it
#: is for). The requirements themselves, with their versions, are in pyproject.toml.
EXTRAS: dict[str, tuple[tuple[str, ...], str]] = {
    "robots": (("pin", "example-robot-data"),
               "robot models and task writers (prioik.robots), the fencing scenario"),
    "qp": (("qpsolvers",), "cascaded_qp and daqp_hierarchical with their QP back-ends"),
    "cvxpy": (("cvxpy", "qpsolvers"), "the cvxpy formulation (reference for inequality stacks)"),
    "placo": (("placo",), "the placo formulation and the PlaCo baseline"),
    "pink": (("pin-pink",), "the pink baseline"),
    "mink": (("mink", "mujoco"), "the mink baseline (the robot converted to MuJoCo)"),
    "plots": (("matplotlib",), "plots of `prioik fencing` and `prioik bench`"),
    "view": (("meshcat", "fast-simplification"),
             "3-D views of robot motions with their meshes (meshed replay, live view)"),
    "sweep": (("dask", "distributed"), "parameter sweeps on a Dask cluster"),
    "docs": (("mkdocs", "mkdocs-material", "mkdocstrings-python"),
             "the documentation site (`make docs`, mkdocs.yml)"),
}


def install_hint(extra: str) -> str:
    """``install it with `pip install prioik[EXTRA]```, the one wording every part uses."""
    return f"install it with `pip install prioik[{extra}]`"


class MissingExtraError(PrioikError, ImportError):
    """A part of prioik needs an extra that is not installed here.

    An :class:`ImportError`, so ``except ImportError`` still catches it; its message
    names the part, what is missing and the ``pip install prioik[EXTRA]`` to run.

    Attributes:
        extras: The extras to install.
        missing: The distributions (or modules) of those extras that are missing.
    """

    def __init__(self, extras: tuple[str, ...], what: str, missing: tuple[str, ...]):
        self.extras = extras
        self.missing = missing
        names = " and ".join(f"`{e}`" for e in extras)
        hint = install_hint(",".join(extras))
        if len(extras) > 1:
            names, hint = names + " extras", hint.replace("install it", "install them")
        else:
            names += " extra"
        super().__init__(f"{what} needs the {names} ({', '.join(missing)} not installed); "
                         f"{hint}", name=missing[0])


def _installed(distribution: str) -> bool:
    try:
        importlib.metadata.distribution(distribution)
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


def missing_distributions(extra: str) -> tuple[str, ...]:
    """The distributions of ``extra`` that are not installed here (empty when it is).
    Nothing is imported.

    Raises:
        KeyError: ``extra`` is not one of :data:`EXTRAS`.
    """
    if extra not in EXTRAS:
        raise UnknownNameError(f"unknown extra {extra!r}; known: {', '.join(EXTRAS)}")
    return tuple(d for d in EXTRAS[extra][0] if not _installed(d))


def installed() -> list[str]:
    """The extras installed here (every distribution of each)."""
    return [e for e in EXTRAS if not missing_distributions(e)]


def require(*extras: str, what: str) -> None:
    """Raise :class:`MissingExtraError` naming every one of ``extras`` not installed.

    Args:
        *extras: Keys of :data:`EXTRAS`.
        what: The part that needs them, as the message should name it
            (e.g. ``"prioik.robots"``, ``"this command"``).
    """
    absent = {e: missing_distributions(e) for e in extras}
    absent = {e: m for e, m in absent.items() if m}
    if absent:
        raise MissingExtraError(tuple(absent), what, sum(absent.values(), ()))
