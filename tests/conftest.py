"""Test configuration: single-threaded BLAS (small matrices; see prioik.threads)
and the hypothesis profile (``ci`` where the environment variable ``CI`` is set).

Set here, for the test process only: importing prioik changes no environment variable.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# hypothesis: in CI (the environment variable CI set) every run draws the same examples
# (derandomize, no example database) and a failure prints the blob that replays it
# (@reproduce_failure); elsewhere the default profile keeps drawing new examples.
# (tests/core runs in the core-only environment, without hypothesis.)
try:
    from hypothesis import settings as _hypothesis_settings
except ImportError:
    _hypothesis_settings = None
if _hypothesis_settings is not None:
    _hypothesis_settings.register_profile("ci", derandomize=True, database=None,
                                          print_blob=True)
    _hypothesis_settings.load_profile("ci" if os.environ.get("CI") else "default")


def assert_truthful(sol, stack, metric=None):
    """A Solution says "optimal" exactly when its answer passes the certificate
    (issue 13, point 4), and an "approximate" one names the level at fault."""
    from prioik.hierarchy import check_lexicographic
    assert sol.status in ("optimal", "approximate"), sol.diagnostics.reason
    passes = check_lexicographic(stack, sol.x, minimum_norm=True, metric=metric).ok
    assert (sol.status == "optimal") == passes, (sol.status, sol.diagnostics.reason)
    verdict = sol.diagnostics.verification
    if sol.status == "approximate" and verdict is not None and verdict.method != "solver":
        assert sol.diagnostics.fault.level is not None and sol.diagnostics.fault.tasks


# tests/core checks the core-only environment (`make test` runs it in .venv-core); where any
# extra is installed its premise does not hold, so it is collected only where none is.
from prioik import extras as _extras  # noqa: E402

collect_ignore = ["core"] if _extras.installed() else []


import pytest  # noqa: E402

#: the toy formulation of :func:`toy_plugin`
TOY = "toy_flat_lstsq"


def stack_formulation(name, solve, capabilities=None, options=None, description=""):
    """A test double of a formulation: a :class:`~prioik.formulations.contract.Formulation`
    whose prepared solver is a :class:`~prioik.formulations.contract.StackPrepared` over
    ``solve(stack, **options)`` (the fields of its settings, by name)."""
    import dataclasses

    from prioik.formulations import Capabilities
    from prioik.formulations.contract import Formulation, StackPrepared

    class Prepared(StackPrepared):
        def solve_stack(self, stack, settings):
            return solve(stack, **{f.name: getattr(settings, f.name)
                                   for f in dataclasses.fields(settings)})

    Prepared.name = name
    Prepared.capabilities = Capabilities() if capabilities is None else capabilities
    return Formulation(name, description, Prepared.capabilities, dict(options or {}),
                       Prepared)


@pytest.fixture
def toy_plugin(monkeypatch):
    """A formulation registered for one test (registry.PLUGINS and its loaded
    Formulation), built on the plugin base classes as a plugin module is: every row of
    every level in one least-squares problem, with a ``scale`` option; the benchmarks'
    table declares one bench row for it (``toy_flat_lstsq[half]``) and an opt-out of the
    arm report. The reports must show it with no edit of their own."""
    import numpy as np

    from prioik.benchmarks import report_rows
    from prioik.benchmarks.report_rows import ReportVariant
    from prioik.formulations import Capabilities, Option, registry
    from prioik.formulations.base import Outcome
    from prioik.formulations.contract import Formulation, StackPrepared

    capabilities = Capabilities(exact=False)

    class ToyPrepared(StackPrepared):
        """The toy prepared for one layout: one least-squares solve per stack."""

        name = TOY

        def solve_stack(self, stack, settings):
            A = np.vstack([t.A for t in stack.tasks])
            b = np.concatenate([t.b for t in stack.tasks])
            return Outcome(settings.scale * np.linalg.lstsq(A, b, rcond=None)[0],
                           "approximate")

    ToyPrepared.capabilities = capabilities
    toy = Formulation(TOY, "every row in one least-squares problem", capabilities,
                      {"scale": Option(1.0, "float", "factor on the answer", minimum=0.0)},
                      ToyPrepared)
    # its report rows, declared by the benchmarks' table (not by the plugin)
    monkeypatch.setitem(report_rows.REPORT_VARIANTS, TOY,
                        (ReportVariant("half", {"scale": 0.5}, reports=("bench",),
                                       note="the answer halved"),))
    monkeypatch.setitem(report_rows.REPORT_OPT_OUTS, TOY, {"arm": "a toy: not for robots"})
    monkeypatch.setitem(registry.PLUGINS, TOY, ("tests.toy_flat_lstsq", ""))
    monkeypatch.setitem(registry._loaded, TOY, toy)
    return toy


def pytest_report_header(config):
    """The arithmetic the run computes with: how the C++ core was built (its one rounding
    rule) and OpenBLAS's kernels (``make test-forced-cpu`` changes them)."""
    from threadpoolctl import threadpool_info
    try:
        import prioik._core as core
        info = core.build_info()
        built = (f"C++ core {'native' if info.native else 'portable'}, "
                 f"{'fast math' if info.fast_math else 'IEEE'}, "
                 f"{'contraction' if info.fp_contract else 'no contraction'}, "
                 f"hot functions' clone {info.vector_clones}")
    except ImportError:
        built = "C++ core not built"
    blas = ", ".join(f"{i['internal_api']} {i.get('version')} {i.get('architecture')}"
                     for i in threadpool_info() if i["user_api"] == "blas")
    return f"arithmetic: {built}; BLAS {blas or 'unknown'}"


def unaligned(values):
    """A writable float64 copy of ``values`` one byte off 8-byte alignment (a view of
    packed bytes: what a binding must refuse by name, never read)."""
    import numpy as np

    out = np.zeros(values.nbytes + 1, np.uint8)[1:].view(np.float64).reshape(values.shape)
    out[...] = values
    assert not out.flags.aligned and out.flags.writeable
    return out
