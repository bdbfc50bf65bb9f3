"""Figures of the scenario runs that people can read.

* **One colour per run label, the same in every figure**: :func:`color_of` assigns
  colours from a fixed list of the known labels (fencing and arm runs), so
  ``extended_jacobian`` is the same blue in the tip-error, algorithmic-error, ``‖q̈‖``
  and step-time figures of every scenario.
* **Grouped panels** instead of 25 lines on one axis (:func:`group_of`): exact methods,
  damped methods (a damping or step-bound option), approximate methods (formulations
  that declare ``exact=False``) and external baselines (PlaCo, pink).
* **Legends outside the data** (right of each panel), every entry with its line.
* **Axes clipped to the informative range**: log axes span the 1st–99.9th percentile
  of the positive values of the figure (at most 12 decades); values outside are drawn
  at the edge. **Failures are marked** where they happen: an ✕ at the last recorded
  time of a run that stopped, at its (clipped) last value.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

GROUPS = ("exact", "damped", "approximate", "external")
GROUP_TITLES = {"exact": "exact methods", "damped": "damped / step-bounded methods",
                "approximate": "approximate methods", "external": "external baselines"}
EXTERNAL = ("placo_kinematics_solver", "pink")
_DAMPING_OPTIONS = ("damping", "level_damping", "step_bound", "singular_threshold")

#: every run label the scenarios know, in a fixed order: index → colour
KNOWN_LABELS = (
    "extended_jacobian", "extended_jacobian:exact", "extended_jacobian:selective",
    "extended_jacobian:eq27", "nullspace", "nullspace:damped", "chiaverini", "unifying",
    "unifying:armature", "operational_space", "cascaded_qp", "cascaded_qp:velocity", "cvxpy",
    "daqp_hierarchical", "placo", "reference", "sns", "sns:velocity",
    "placo_kinematics_solver", "pink", "pink:daqp")


def _palette() -> list:
    import matplotlib
    cols = list(matplotlib.colormaps["tab20"].colors) + list(matplotlib.colormaps["Dark2"].colors)
    # tab20 pairs a strong and a light shade: take the strong ones first
    return cols[0::2] + cols[1::2] + cols[20:]


def color_of(label: str):
    """The colour of a run label (stable across figures and runs)."""
    pal = _palette()
    if label in KNOWN_LABELS:
        return pal[KNOWN_LABELS.index(label) % len(pal)]
    return pal[(sum(map(ord, label)) * 7) % len(pal)]


def group_of(label: str, formulation: str | None = None, options: dict | None = None) -> str:
    """``"exact"``, ``"damped"``, ``"approximate"`` or ``"external"`` for a run."""
    formulation = formulation or label.split(":")[0]
    if formulation in EXTERNAL:
        return "external"
    if options and any(k in options and options[k] not in (None, 0, 0.0, {})
                       for k in _DAMPING_OPTIONS):
        return "damped"
    try:
        from prioik import formulations
        if not formulations.get(formulation).CAPABILITIES.exact:
            return "approximate"
    except Exception:  # noqa: BLE001 - an unavailable plugin: judge by name only
        pass
    return "exact"


def _group_results(results: dict) -> dict[str, list]:
    out: dict[str, list] = {g: [] for g in GROUPS}
    for label, res in results.items():
        info = getattr(res, "info", {}) or {}
        out[group_of(label, info.get("formulation"), info.get("options"))].append((label, res))
    return {g: v for g, v in out.items() if v}


def _log_limits(values: list[np.ndarray]) -> tuple[float, float] | None:
    pos = np.concatenate([v[np.isfinite(v) & (v > 0)] for v in values] or [np.zeros(0)])
    if pos.size == 0:
        return None
    lo, hi = np.percentile(pos, [1.0, 99.9])
    hi = max(hi * 2.0, lo * 10.0)
    lo = max(lo / 2.0, hi * 1e-12)
    return float(lo), float(hi)


def grouped_series(path: Path, results: dict, get, ylabel: str, title: str) -> Path:
    """One panel per group, one line per run (``get(res)`` → values over ``res.t``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    groups = _group_results(results)
    series = {lb: np.abs(np.asarray(get(r), dtype=float)) for g in groups.values()
              for lb, r in g if get(r) is not None and r.steps}
    lims = _log_limits(list(series.values()))
    fig, axes = plt.subplots(len(groups), 1, figsize=(9.0, 2.3 * len(groups) + 0.6),
                             sharex=True, squeeze=False)
    for ax, (group, runs) in zip(axes[:, 0], groups.items()):
        for label, res in runs:
            if label not in series:
                continue
            y = series[label]
            if lims is not None:
                y = np.clip(y, lims[0], lims[1])
            ax.semilogy(res.t, y, color=color_of(label), lw=1.3, label=label)
            if res.failed and res.steps:
                ax.plot(res.t[-1], y[-1], marker="X", ms=9, color=color_of(label),
                        markeredgecolor="k", ls="none")
        if lims is not None:
            ax.set_ylim(*lims)
        ax.set_title(GROUP_TITLES[group], fontsize=9, loc="left")
        ax.grid(True, which="major", alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        failed = [lb for lb, r in runs if r.failed]
        labels = [lb + (" ✕ failed" if lb in failed else "") for lb in labels]
        ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
                  frameon=False)
    axes[-1, 0].set_xlabel("time (s)")
    fig.supylabel(ylabel, fontsize=9)
    fig.suptitle(title + (f" (clipped to [{lims[0]:.0e}, {lims[1]:.0e}])" if lims else ""),
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def step_times(path: Path, summary: dict, title: str) -> Path:
    """Median step time per run (horizontal bars, one colour per run, one panel per
    variant; failed runs hatched)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    variants = list(summary)
    labels = sorted({k for v in summary.values() for k in v},
                    key=lambda lb: (KNOWN_LABELS.index(lb) if lb in KNOWN_LABELS else 99, lb))
    fig, axes = plt.subplots(1, len(variants), figsize=(4.5 * len(variants) + 1.5,
                                                          0.28 * len(labels) + 1.2),
                             sharey=True, squeeze=False)
    for ax, variant in zip(axes[0], variants):
        runs = summary[variant]
        for i, lb in enumerate(labels):
            s = runs.get(lb)
            if not s or s.get("median_step_time_s") is None:
                continue
            ax.barh(i, 1e3 * s["median_step_time_s"], color=color_of(lb),
                    hatch="//" if s.get("failed") else None, edgecolor="k", lw=0.3)
        ax.set_xscale("log")
        ax.set_title(variant, fontsize=9)
        ax.set_xlabel("median step (ms, log)")
        ax.grid(True, axis="x", which="both", alpha=0.3)
    axes[0, 0].set_yticks(range(len(labels)), labels, fontsize=8)
    axes[0, 0].invert_yaxis()
    fig.suptitle(title + " — hatched: the run failed", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path
