"""The whole IK step (kinematics + rows + solve) against PlaCo: G1 fencing, Panda reach,
and hierarchical_active_set with joint limits as bounds (the lead's modules
:mod:`~prioik.benchmarks.placo_step`, :mod:`~prioik.benchmarks.panda_step`,
:mod:`~prioik.benchmarks.active_set_bench` measure; this module runs them), with two
parts of the step on their own: ``prepared.solve``'s cost on top of its compiled kernel
(:mod:`~prioik.benchmarks.solve_overhead`) and writing the G1 fencing rows without the
references (:mod:`~prioik.benchmarks.row_writing`); and mink beside prioik and PlaCo with
limits (:mod:`~prioik.benchmarks.mink_step`; without the ``mink`` extra, ``mink_error``
says which extra to install)."""

from __future__ import annotations

from typing import Any

from prioik.benchmarks.progress import Progress

from .settings import Settings

__all__ = ["measure_ik_step"]


def measure_ik_step(settings: Settings, progress: Progress | None = None
                    ) -> tuple[dict[str, Any], str]:
    """The whole G1 IK step of ``extended_jacobian`` against PlaCo's
    ``KinematicsSolver``, the Panda reach step, and the active-set benchmark; or
    ``({}, reason)`` when PlaCo or the robots cannot run here."""
    from prioik.extras import MissingExtraError, require
    try:
        require("robots", "placo", what="the PlaCo IK step")
    except MissingExtraError as exc:
        return {}, str(exc)
    try:
        from prioik.benchmarks.placo_step import ik_step_times
    except ImportError as exc:
        return {}, f"PlaCo step unavailable ({type(exc).__name__}: {exc})"
    try:
        out = ik_step_times(settings.ik_steps)
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        return {}, f"PlaCo step failed ({type(exc).__name__}: {exc})"
    from prioik.benchmarks.panda_step import panda_step_times
    try:
        out["panda"] = panda_step_times(settings.ik_steps)
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        out["panda_error"] = f"{type(exc).__name__}: {exc}"
    # the two Python-cost targets: prepared.solve on top of its compiled kernel,
    # and writing the G1 fencing rows without the references (computed beforehand)
    from prioik.benchmarks import row_writing, solve_overhead
    sizes = dict(rounds=2, calls=200) if settings.quick else {}
    try:
        out["solve_overhead"] = {
            "g1": solve_overhead.solve_overhead(*solve_overhead.fencing_rows(), **sizes),
            "panda": solve_overhead.solve_overhead(*solve_overhead.panda_rows(), **sizes),
            # hierarchical_active_set with the joint limits as bounds
            "g1_bounds": solve_overhead.solve_overhead(
                *solve_overhead.fencing_rows(limits=True), **sizes),
            "panda_limits": solve_overhead.solve_overhead(
                *solve_overhead.panda_rows(limits=True), **sizes)}
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        out["solve_overhead_error"] = f"{type(exc).__name__}: {exc}"
    try:
        steps = dict(n_steps=50, repeats=2) if settings.quick else {}
        out["rows"] = {limits: row_writing.time_fencing_rows(limits=limits, **steps)
                       for limits in ("none", "bounds")}
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        out["rows_error"] = f"{type(exc).__name__}: {exc}"
    # hierarchical_active_set with joint limits as bounds: the G1 bounds stacks (cold,
    # warm, DAQP's raw call, cascaded_qp[daqp]) and the like-for-like IK steps with limits
    from prioik.benchmarks import active_set_bench
    try:
        sizes = dict(windows=1, steps=3, repeats=1) if settings.quick else {}
        out["active_set"] = active_set_bench.run(ik_steps=settings.ik_steps, **sizes)
        out["active_set_table"] = active_set_bench.format_table(out["active_set"])
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        out["active_set_error"] = f"{type(exc).__name__}: {exc}"
    # mink beside prioik and PlaCo on the same two problems with limits (the mink extra)
    try:
        require("mink", what="the mink IK step")
        from prioik.benchmarks import mink_step
        out["mink"] = mink_step.run(steps=settings.ik_steps,
                                    rounds=2 if settings.quick else None)
        out["mink_table"] = mink_step.format_table(out["mink"])
    except MissingExtraError as exc:
        out["mink_error"] = str(exc)
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        out["mink_error"] = f"{type(exc).__name__}: {exc}"
    if progress:
        progress.step("IK step: PlaCo vs extended_jacobian")
    return out, ""
