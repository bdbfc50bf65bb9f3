"""The declared sweep: read, validated once, expanded into independent runs.

A sweep file (TOML, or JSON with the same keys)::

    scenario = "fencing"                 # prioik.benchmarks.sweep.scenarios.SWEEP_SCENARIOS
    formulations = ["extended_jacobian", "nullspace", "sns[velocity]"]   # or "default", "registry"
    seed = 0
    algorithmic_error = false            # record eq. 29 per step (an SVD per level)

    [fixed]                              # one value for every run
    duration = 3.0

    [grid]                               # axes of a Cartesian product
    kp = [25.0, 50.0]
    step_length = {from = 0.0, to = 0.3, n = 4}   # evenly spaced, ends included

    [sample]                             # n seeded random draws
    n = 200
    reach_margin_m = [-0.4, 0.5]         # uniform in [low, high]
    azimuth_deg = [-30.0, 30.0]
    robot = {choices = ["g1"]}           # uniform among values

    [criteria]                           # success bounds (the scenario's defaults otherwise)
    tip_m = 1e-3

Every run is one point (grid × sample) × one formulation variant. A formulation entry
is a run label of the scenario's table for sweeps
(:func:`prioik.benchmarks.scenario_runs.run_table` with report ``"sweep"``:
``formulation`` or ``formulation[tag]``, the same labels as ``prioik fencing``), or a
table ``{label, formulation, options, level, limits, armature}`` declaring a variant of
its own (``label``, if given, is ``formulation[tag]``). ``"default"`` takes the table's
default selection (registry formulations, plugins that opt out of ``"sweep"`` left out,
the scenario's studies and the external baselines); ``"registry"`` the registry's rows
alone (:mod:`prioik.benchmarks.variants`: every available formulation, the settings
plugins declare for sweeps), so a new formulation is swept without an edit here.

A run's id is a hash of the scenario, its resolved parameters and its variant, so a
resumed or extended sweep recognises the rows it already has.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from prioik.benchmarks.variants import Variant, parse_label
from prioik.errors import PrioikError

from .scenarios import SWEEP_SCENARIOS, SweepScenario

__all__ = ["SweepConfigError", "Run", "Plan", "load_config", "plan_from_config"]

TOP_KEYS = ("scenario", "formulations", "seed", "algorithmic_error", "fixed", "grid",
            "sample", "criteria", "title")


class SweepConfigError(PrioikError, ValueError):
    """A sweep file that cannot run; the message names the file, key and value."""


@dataclass(frozen=True)
class Run:
    """One independent task: resolved parameters × variant."""

    run_id: str
    point: int
    params: dict
    variant: Variant

    def task(self, scenario: str, algorithmic_error: bool) -> dict[str, Any]:
        """The plain-data description a worker executes (:func:`.task.run_task`)."""
        return {"run_id": self.run_id, "point": self.point, "scenario": scenario,
                "params": self.params, "variant": self.variant.to_dict(),
                "algorithmic_error": algorithmic_error}


@dataclass
class Plan:
    """The expanded sweep."""

    scenario: str
    runs: list[Run]
    variants: list[Variant]
    criteria: dict[str, float]
    config: dict
    algorithmic_error: bool
    swept: list[str]
    title: str = ""
    source: str = ""

    @property
    def points(self) -> int:
        return len({r.point for r in self.runs})

    def fingerprint(self) -> str:
        """Hash of every run id (same plan ⇔ same fingerprint)."""
        h = hashlib.sha1()
        for r in self.runs:
            h.update(r.run_id.encode())
        return h.hexdigest()[:16]


# ------------------------------------------------------------------ loading
def load_config(path) -> dict:
    """Read a sweep file (``.toml`` or ``.json``).

    Raises:
        SweepConfigError: unreadable or malformed (names the file).
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise SweepConfigError(f"cannot read sweep file {path}: {exc}") from None
    try:
        if path.suffix == ".json":
            cfg = json.loads(text)
        else:
            import tomllib
            cfg = tomllib.loads(text)
    except ValueError as exc:
        raise SweepConfigError(f"{path}: not valid {'JSON' if path.suffix == '.json' else 'TOML'}: "
                               f"{exc}") from None
    if not isinstance(cfg, dict):
        raise SweepConfigError(f"{path}: the sweep must be a table of keys")
    cfg["_source"] = str(path)
    return cfg


def _err(cfg: dict, msg: str) -> SweepConfigError:
    return SweepConfigError(f"{cfg.get('_source', 'sweep')}: {msg}")


# ------------------------------------------------------------------- variants
def _table_variant(cfg: dict, e: dict) -> Variant:
    """A variant declared by a table of the sweep file."""
    from prioik import formulations
    from prioik.formulations.options import validate_options
    extra = sorted(set(e) - {"label", "formulation", "options", "level", "limits",
                             "armature"})
    if extra or "formulation" not in e:
        raise _err(cfg, f"formulation table {e!r}: needs 'formulation'"
                        f"{'; unknown key(s) ' + ', '.join(extra) if extra else ''}")
    name = e["formulation"]
    try:
        mod = formulations.get(name)
    except formulations.FormulationError as exc:
        raise _err(cfg, f"formulation {name!r}: {exc}") from None
    opts = dict(e.get("options", {}))
    try:
        validate_options(name, mod.options, opts, None)
    except formulations.FormulationError as exc:
        raise _err(cfg, str(exc)) from None
    level = e.get("level", "acceleration")
    if level not in ("acceleration", "velocity"):
        raise _err(cfg, f"formulation {name!r}: level must be 'acceleration' or "
                        f"'velocity', got {level!r}")
    if "label" in e:
        try:
            own, tag = parse_label(str(e["label"]))
        except ValueError as exc:
            raise _err(cfg, str(exc)) from None
        if own != name:
            raise _err(cfg, f"formulation table {e!r}: its label names {own!r}, not {name!r}")
    else:
        tag = ",".join([f"{k}={v}" for k, v in opts.items()]
                       + (["velocity"] if level == "velocity" else []))
    return Variant(name, tag, opts, level=level, limits=e.get("limits"),
                   armature=float(e.get("armature", 0.0)))


def _variants(cfg: dict, scenario: str) -> list[Variant]:
    from prioik.benchmarks.scenario_runs import run_table
    runs = run_table(scenario, "sweep")
    entries = cfg.get("formulations", "default")
    if entries == "default":
        entries = list(runs.rows)
    elif entries == "registry":
        entries = [v for v in runs.rows if v.origin not in ("study", "baseline")]
    if isinstance(entries, str) or not isinstance(entries, list):
        raise _err(cfg, f"'formulations' must be a list of run labels or tables, "
                        f"\"default\" or \"registry\"; got {entries!r}")
    if not entries:
        raise _err(cfg, "'formulations' is empty: nothing to run")
    out: list[Variant] = []
    for e in entries:
        if isinstance(e, Variant):
            out.append(e)
        elif isinstance(e, str):
            chosen, skipped = [], []
            try:
                chosen, skipped = runs.select([e])
            except ValueError:
                raise _err(cfg, f"unknown formulation {e!r}; the {scenario} runs are "
                                f"{', '.join(runs.known)} (or a table with label, "
                                f"formulation, options)") from None
            if skipped:
                raise _err(cfg, "formulation(s) not available here: " + "; ".join(skipped))
            out += chosen
        elif isinstance(e, dict):
            out.append(_table_variant(cfg, e))
        else:
            raise _err(cfg, f"formulation entry {e!r} is neither a label nor a table")
    labels = [v.label for v in out]
    dup = sorted({lb for lb in labels if labels.count(lb) > 1})
    if dup:
        raise _err(cfg, f"formulation label(s) listed twice: {', '.join(dup)}")
    return out


# --------------------------------------------------------------------- points
def _axis(cfg: dict, name: str, value: Any) -> list:
    if isinstance(value, dict):
        if set(value) != {"from", "to", "n"}:
            raise _err(cfg, f"grid axis {name!r}: a range is {{from, to, n}}, got {value!r}")
        n = value["n"]
        if not isinstance(n, int) or n < 1:
            raise _err(cfg, f"grid axis {name!r}: n must be an integer ≥ 1, got {n!r}")
        return [float(x) for x in np.linspace(value["from"], value["to"], n)]
    if not isinstance(value, list):
        raise _err(cfg, f"grid axis {name!r} must be a list of values or {{from, to, n}}, "
                        f"got {value!r}")
    if not value:
        raise _err(cfg, f"grid axis {name!r} is empty: the grid has no point")
    return value


def _sampler(cfg: dict, name: str, value: Any, rng: np.random.Generator):
    if isinstance(value, dict):
        if set(value) != {"choices"} or not isinstance(value["choices"], list) \
                or not value["choices"]:
            raise _err(cfg, f"sample {name!r}: a choice is {{choices = [non-empty list]}}, "
                            f"got {value!r}")
        choices = value["choices"]
        return lambda: choices[int(rng.integers(len(choices)))]
    if (isinstance(value, list) and len(value) == 2
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)
            and all(math.isfinite(x) for x in value)):
        lo, hi = float(value[0]), float(value[1])
        if hi < lo:
            raise _err(cfg, f"sample {name!r}: range [{lo:g}, {hi:g}] is empty")
        return lambda: float(rng.uniform(lo, hi))
    raise _err(cfg, f"sample {name!r} must be [low, high] or {{choices = [...]}}, got "
                    f"{value!r}")


def _points(cfg: dict, sc: SweepScenario) -> tuple[list[dict], list[str]]:
    from prioik.smoke import shrink_sweep_config
    cfg = shrink_sweep_config(cfg, sc.smoke_parameters)     # PRIOIK_SMOKE=1: a short run
    fixed = cfg.get("fixed", {}) or {}
    grid = cfg.get("grid", {}) or {}
    sample = dict(cfg.get("sample", {}) or {})
    for key, tab in (("fixed", fixed), ("grid", grid), ("sample", sample)):
        if not isinstance(tab, dict):
            raise _err(cfg, f"[{key}] must be a table, got {tab!r}")
    n = sample.pop("n", None)
    if sample and n is None:
        raise _err(cfg, "[sample] needs n (the number of draws)")
    if n is not None and (not isinstance(n, int) or isinstance(n, bool) or n < 1):
        raise _err(cfg, f"[sample] n must be an integer ≥ 1, got {n!r}")
    seen: dict[str, str] = {}
    for key, tab in (("fixed", fixed), ("grid", grid), ("sample", sample)):
        for name in tab:
            if name not in sc.parameters:
                raise _err(cfg, f"unknown parameter {name!r} in [{key}]; the {sc.name} "
                                f"scenario's parameters: {', '.join(sc.parameters)}")
            if name in seen:
                raise _err(cfg, f"parameter {name!r} is in both [{seen[name]}] and [{key}]")
            seen[name] = key
    axes = {name: _axis(cfg, name, v) for name, v in grid.items()}
    rng = np.random.default_rng(cfg.get("seed", 0))
    samplers = {name: _sampler(cfg, name, v, rng) for name, v in sample.items()}
    grid_points = [dict(zip(axes, combo, strict=False))
                   for combo in itertools.product(*axes.values())]
    draws = [{name: draw() for name, draw in samplers.items()} for _ in range(n or 1)]
    points = [{**fixed, **g, **d} for d in draws for g in grid_points]
    return points, list(axes) + list(samplers)


def _run_id(scenario: str, params: dict, variant: Variant) -> str:
    key = json.dumps({"scenario": scenario, "params": params, "variant": variant.to_dict()},
                     sort_keys=True, default=str)
    return hashlib.sha1(key.encode()).hexdigest()[:12]


def plan_from_config(cfg: dict) -> Plan:
    """Validate ``cfg`` (from :func:`load_config`) and expand it into runs.

    Raises:
        SweepConfigError: an unknown key, parameter, formulation or robot, an empty
            grid or sample, a value out of range, a formulation not available here —
            before anything runs, naming the file and the key.
    """
    unknown = sorted(k for k in cfg if k not in TOP_KEYS and not k.startswith("_"))
    if unknown:
        raise _err(cfg, f"unknown key(s) {', '.join(unknown)}; a sweep has "
                        f"{', '.join(TOP_KEYS)}")
    scenario = cfg.get("scenario", "fencing")
    if scenario not in SWEEP_SCENARIOS:
        raise _err(cfg, f"unknown scenario {scenario!r}; sweepable: "
                        f"{', '.join(SWEEP_SCENARIOS)}")
    sc = SWEEP_SCENARIOS[scenario]()
    criteria = {k: float(v[0]) for k, v in sc.criteria.items()}
    for k, v in (cfg.get("criteria", {}) or {}).items():
        if k not in criteria:
            raise _err(cfg, f"unknown criterion {k!r}; the {scenario} criteria: "
                            f"{', '.join(criteria)}")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise _err(cfg, f"criterion {k!r} must be a finite number, got {v!r}")
        criteria[k] = float(v)
    variants = _variants(cfg, scenario)
    points, swept = _points(cfg, sc)
    runs: list[Run] = []
    for i, point in enumerate(points):
        try:
            params = sc.resolve(point)
        except ValueError as exc:
            raise _err(cfg, f"point {i} ({point}): {exc}") from None
        for v in variants:
            runs.append(Run(_run_id(scenario, params, v), i, params, v))
    ids = [r.run_id for r in runs]
    if len(set(ids)) != len(ids):
        raise _err(cfg, "the grid or sample repeats a point (two runs with the same "
                        "parameters and formulation)")
    return Plan(scenario, runs, variants, criteria, {k: v for k, v in cfg.items()
                                                     if not k.startswith("_")},
                bool(cfg.get("algorithmic_error", False)), swept, str(cfg.get("title", "")),
                str(cfg.get("_source", "")))
