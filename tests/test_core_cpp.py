"""The compiled core (``prioik._core``, core/): how it was built, and that its answers
equal the numba kernels' (the oracle while both exist)."""

from __future__ import annotations

import prioik._core as core


def test_core_is_built_with_the_stated_rounding_rule():
    info = core.build_info()
    assert info.fast_math is False
    assert info.fp_contract is False      # a * b + c is rounded twice, as written
    assert info.eigen.startswith("3.4.")
    assert info.compiler
