"""Every figure of the benchmark commands.

Scenario runs (``prioik fencing``, ``arm``, ``plot``):

* **One colour per run label, the same in every figure**: :func:`color_of` assigns
  colours in the order of the scenario reports' run tables
  (:mod:`prioik.benchmarks.variants`), so ``extended_jacobian`` is the same blue in the
  tip-error, algorithmic-error, ``‖q̈‖`` and step-time figures of every scenario.
* **Grouped panels** instead of 25 lines on one axis (:func:`group_of`): exact methods,
  damped methods (a damping or step-bound option), approximate methods (formulations
  that declare ``exact=False``) and external baselines (PlaCo, pink, mink, TSID).
* **Legends outside the data** (right of each panel), every entry with its line.
* **Axes clipped to the informative range**: log axes span the 1st–99.9th percentile
  of the positive values of the figure (at most 12 decades); values outside are drawn
  at the edge. **Failures are marked** where they happen: an ✕ at the last recorded
  time of a run that stopped, at its (clipped) last value.

Timings (``prioik bench``): :func:`time_vs_size`, log-log median solve time against
``n`` (one panel per ``k``) and against ``k`` (one panel per ``n``).
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

GROUPS = ("exact", "damped", "approximate", "external")
GROUP_TITLES = {"exact": "exact methods", "damped": "damped / step-bounded methods",
                "approximate": "approximate methods", "external": "external baselines"}


@lru_cache(maxsize=1)
def known_labels() -> tuple[str, ...]:
    """Every run label of the scenario reports, in table order (index → colour)."""
    from prioik.benchmarks.variants import STUDY_MODULES, table
    out: list[str] = []
    for report in STUDY_MODULES:
        try:
            labels = table(report).known
        except Exception:  # noqa: BLE001 - a broken optional plugin must not stop a figure
            continue
        out += [lb for lb in labels if lb not in out]
    return tuple(out)


def _palette() -> list:
    import matplotlib
    cols = list(matplotlib.colormaps["tab20"].colors) + list(matplotlib.colormaps["Dark2"].colors)
    # tab20 pairs a strong and a light shade: take the strong ones first
    return cols[0::2] + cols[1::2] + cols[20:]


def color_of(label: str):
    """The colour of a run label (stable across figures and runs)."""
    pal = _palette()
    known = known_labels()
    if label in known:
        return pal[known.index(label) % len(pal)]
    return pal[(sum(map(ord, label)) * 7) % len(pal)]


def group_of(label: str, formulation: str | None = None, options: dict | None = None) -> str:
    """``"exact"``, ``"damped"``, ``"approximate"`` or ``"external"`` for a run."""
    from prioik.benchmarks.variants import BASELINES, capabilities, is_damped, parse_label
    formulation = formulation or parse_label(label)[0]
    if formulation in BASELINES:
        return "external"
    if is_damped(options or {}):
        return "damped"
    caps = capabilities(formulation)
    if caps is not None and not caps.exact:
        return "approximate"
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
    for ax, (group, runs) in zip(axes[:, 0], groups.items(), strict=False):
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


def step_times(path: Path, summary: dict, title: str,
               side_by_side: dict[str, dict] | None = None) -> Path:
    """Median step time per run (horizontal bars, one colour per run, one panel per
    variant; failed runs hatched). ``side_by_side``: per variant, a
    :func:`~prioik.benchmarks.fencing.headline_timing` record, whose runs get a black
    diamond at their fastest round's median (the table's runs are minutes apart on a
    machine whose speed drifts; these were timed in alternation)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    variants = list(summary)
    known = known_labels()
    labels = sorted({k for v in summary.values() for k in v},
                    key=lambda lb: (known.index(lb) if lb in known else len(known), lb))
    fig, axes = plt.subplots(1, len(variants), figsize=(4.5 * len(variants) + 1.5,
                                                          0.28 * len(labels) + 1.2),
                             sharey=True, squeeze=False)
    for ax, variant in zip(axes[0], variants, strict=False):
        runs = summary[variant]
        for i, lb in enumerate(labels):
            s = runs.get(lb)
            if not s or s.get("median_step_time_s") is None:
                continue
            ax.barh(i, 1e3 * s["median_step_time_s"], color=color_of(lb),
                    hatch="//" if s.get("failed") else None, edgecolor="k", lw=0.3)
        h = (side_by_side or {}).get(variant)
        if h:
            best = h["best_median_step_s"]
            rows = [(labels.index(lb), t) for lb, t in best.items() if lb in labels]
            ax.plot([1e3 * t for _, t in rows], [i for i, _ in rows], "kD", ms=5,
                    label=f"side by side ({h['rounds']} alternating rounds, the fastest; "
                          f"ratio {h['ratio']:.2f})")
            ax.legend(fontsize=7, loc="lower right")
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


def scenario_figures(out: Path, variant: str, results: dict, scenario: str = "fencing",
                     tip_label: str = "tip") -> list[Path]:
    """Tip error, algorithmic error and ‖q̈‖ over time of one scenario variant's runs
    (``<variant>_tip_error.png``, ``_algorithmic_error.png``, ``_qdd.png``)."""
    series = [("tip_error", f"{tip_label} error to the target (m)",
               lambda r: r.errors.get("tip_error_m")),
              ("algorithmic_error", "‖e_algorithm‖ (eq. 29)", lambda r: r.algorithmic_error),
              ("qdd", "‖q̈‖ (rad/s², m/s²)", lambda r: np.linalg.norm(r.a, axis=1))]
    return [grouped_series(Path(out) / f"{variant}_{key}.png", results, get, ylabel,
                           f"{scenario}, {variant}: {ylabel}")
            for key, ylabel, get in series]


def step_time_figure(out: Path, summary: dict, scenario: str = "fencing",
                     side_by_side: dict[str, dict] | None = None) -> Path:
    """Median step time per run and variant (``step_time.png``; ``side_by_side`` as
    :func:`step_times`)."""
    return step_times(Path(out) / "step_time.png", summary,
                      f"{scenario}: compute time per control step (kinematics + solve + "
                      "torque)", side_by_side)


def time_vs_size(rows: list, out: Path) -> list[str]:
    """Log-log plots of the median time (:class:`~prioik.benchmarks.results.TimingRow`
    of the random cases) against ``n`` (one panel per ``k``) and against ``k`` (one
    panel per ``n``): ``time_vs_n.png``, ``time_vs_k.png``; returns the names written."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    from prioik.benchmarks.variants import parse_label

    sub = [r for r in rows if r.suite == "random" and math.isfinite(r.median_us)]
    if not sub:
        return []
    labels = sorted({r.label for r in sub})
    cmap = plt.get_cmap("tab10")
    families = sorted({parse_label(lb)[0] for lb in labels})

    def style(label: str) -> dict:
        fam, tag = parse_label(label)
        if label == "extended_jacobian":
            return {"color": "black", "lw": 2.6, "ls": "-", "marker": "o", "zorder": 5}
        same = sorted(lb for lb in labels if lb.startswith(fam + "["))
        if tag and r_backends.get(label):        # one line per QP back-end: own colour
            return {"color": cmap(same.index(label) % 10), "lw": 1.0, "marker": "x",
                    "ls": ("--", ":", (0, (3, 1, 1, 1)))[backend_families.index(fam) % 3]}
        if tag:                # extra paths of one formulation: same colour, own marker
            return {"color": cmap(families.index(fam) % 10), "lw": 1.4, "ls": "-.",
                    "marker": "s^vD"[same.index(label) % 4]}
        return {"color": cmap(families.index(fam) % 10), "lw": 1.6, "marker": "o", "ls": "-"}

    r_backends = {r.label: bool(r.backend) for r in sub}
    backend_families = sorted({parse_label(lb)[0] for lb, b in r_backends.items() if b})
    written = []
    for axis, other, fname in (("n", "k", "time_vs_n.png"), ("k", "n", "time_vs_k.png")):
        panels = sorted({getattr(r, other) for r in sub})
        ticks = sorted({getattr(r, axis) for r in sub})
        fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels) + 2.5, 4.6),
                                 squeeze=False, sharey=True)
        for ax, p in zip(axes[0], panels, strict=False):
            for lb in labels:
                pts = sorted((getattr(r, axis), r.median_us) for r in sub
                             if r.label == lb and getattr(r, other) == p)
                if pts:
                    xs, ys = zip(*pts, strict=False)
                    ax.plot(xs, ys, ms=3, label=lb, **style(lb))
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xticks(ticks)
            ax.set_xticklabels([str(t) for t in ticks])
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_title(f"{other} = {p}")
            ax.set_xlabel(axis + (" (unknowns)" if axis == "n" else " (levels)"))
            ax.grid(True, which="both", alpha=0.3)
        axes[0][0].set_ylabel("median solve time (µs)")
        handles, names = axes[0][0].get_legend_handles_labels()
        fig.legend(handles, names, loc="center right", fontsize=7)
        fig.tight_layout(rect=(0, 0, 1 - 2.3 / (4.2 * len(panels) + 2.5), 1))
        fig.savefig(Path(out) / fname, dpi=110)
        plt.close(fig)
        written.append(fname)
    return written
