"""``PRIOIK_SMOKE=1``: every command of the command line shrunk to a few steps (a testing aid).

With the environment variable :data:`ENV` set (to anything but ``""`` or ``"0"``), a
command runs as written — the same sub-command, options, formulations, files and outputs
— but on a few simulated steps, stacks and timed solves, so that the documentation's
commands can be executed as written in seconds (``tests/test_doc_commands.py``). Its
numbers are not measurements. The variable is read here only (:func:`active`); the
commands take their smaller sizes from the functions below:

* :func:`shrink_arguments` — the parsed options of every ``prioik`` sub-command
  (:data:`ARGUMENT_CAPS`: simulated seconds, stacks, timed solves, rounds);
* :func:`shrink_bench_settings` — ``prioik bench``'s cases and time budget;
* :func:`shrink_sweep_config` — a sweep file's draws, grid axes and simulated seconds;
* :func:`cap` — any other count (``python -m prioik.benchmarks.mink_step``'s steps, the
  simulated seconds of the runs a benchmark samples, :data:`SAMPLED_RUN_S`).
"""

from __future__ import annotations

import argparse
import os
from typing import Any

__all__ = ["ENV", "ARGUMENT_CAPS", "SAMPLED_RUN_S", "active", "cap", "shrink_arguments",
           "shrink_bench_settings", "shrink_sweep_config", "EPILOG"]

#: the environment variable that turns the smoke sizes on
ENV = "PRIOIK_SMOKE"

#: the largest value of each sub-command option under ``PRIOIK_SMOKE=1`` (by its
#: ``argparse`` destination; an option left at ``None`` keeps the command's own choice)
ARGUMENT_CAPS: dict[str, float] = {
    "duration": 0.02,          # fencing, arm: simulated seconds (10 steps of 2 ms)
    "headline_rounds": 1,      # fencing: rounds of the side-by-side timing
    "n_stacks": 2,             # validate: stacks per family
    "stacks": 2,               # properties: stacks per family
    "n": 3,                    # fuzz: stacks per kind
    "repeats": 2,              # compare, bench: timed solves
    "samples": 1,              # bench: stacks per random case
    "throughput": 2,           # sweep --throughput: timed runs
}

#: simulated seconds, under ``PRIOIK_SMOKE=1``, of the runs a benchmark draws its states
#: from (:func:`prioik.benchmarks.stacks.g1_fencing_samples`: 10 steps of 5 ms)
SAMPLED_RUN_S = 0.05

#: ``prioik --help``'s note on the variable
EPILOG = (f"{ENV}=1 (environment): every command runs as written but on a few steps, "
          "stacks and timed solves — a testing aid (the documentation's commands are "
          "executed so in the tests); its numbers are not measurements.")


def active() -> bool:
    """Whether ``PRIOIK_SMOKE`` is set (to anything but ``""`` or ``"0"``)."""
    return os.environ.get(ENV, "") not in ("", "0")


def cap(value: Any, smoke_value: Any) -> Any:
    """``min(value, smoke_value)`` under ``PRIOIK_SMOKE=1``, else ``value``."""
    return min(value, smoke_value) if active() else value


def shrink_arguments(args: argparse.Namespace) -> argparse.Namespace:
    """``args`` with each option of :data:`ARGUMENT_CAPS` capped, under ``PRIOIK_SMOKE=1``
    (a new namespace; ``args`` itself is not changed)."""
    if not active():
        return args
    values = vars(args).copy()
    for name, largest in ARGUMENT_CAPS.items():
        value = values.get(name)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            values[name] = type(value)(min(value, largest))
    return argparse.Namespace(**values)


def shrink_bench_settings(settings: Any) -> Any:
    """``prioik bench``'s :class:`~prioik.benchmarks.bench.Settings` under
    ``PRIOIK_SMOKE=1``: random cases n ≤ 35, k ≤ 4 (the first two of each list), one
    stack per case and G1 state, two timed solves per row, experiments of a few steps.
    Changes and returns ``settings`` (the command's own object)."""
    if not active():
        return settings
    settings.sizes = tuple(settings.sizes[:2])
    settings.levels = tuple(settings.levels[:2])
    settings.sizes = tuple(n for n in settings.sizes if n <= 35) or (12,)
    settings.levels = tuple(k for k in settings.levels if k <= 4) or (2,)
    settings.repeats, settings.min_repeats, settings.warmup = 2, 1, 0
    settings.cap_s = 0.01
    settings.samples, settings.g1_samples = 1, 1
    settings.batch_size, settings.batch_rounds = 10, 1
    settings.control_duration_s, settings.ik_steps = 0.02, 5
    settings.quick = True
    return settings


def shrink_sweep_config(cfg: dict, fixed: dict[str, Any]) -> dict:
    """A sweep file's table under ``PRIOIK_SMOKE=1``: at most 2 random draws and 2 values
    per grid axis, and the parameters ``fixed`` (the scenario's short run, e.g. its
    simulated seconds) fixed (a new table; ``cfg`` itself is not changed)."""
    if not active():
        return cfg
    grid = {name: axis[:2] if isinstance(axis, list)
            else {**axis, "n": min(axis["n"], 2)}
            if isinstance(axis, dict) and isinstance(axis.get("n"), int) else axis
            for name, axis in (cfg.get("grid") or {}).items() if name not in fixed}
    sample = {name: value for name, value in (cfg.get("sample") or {}).items()
              if name not in fixed}
    if set(sample) <= {"n"}:
        sample = {}                   # nothing left to draw
    elif isinstance(sample.get("n"), int):
        sample["n"] = min(sample["n"], 2)
    shrunk = {**cfg, "fixed": {**(cfg.get("fixed") or {}), **fixed}}
    for key, table in (("grid", grid), ("sample", sample)):
        if table:
            shrunk[key] = table
        else:
            shrunk.pop(key, None)
    return shrunk
