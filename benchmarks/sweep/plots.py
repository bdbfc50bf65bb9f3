"""Figures of a sweep: errors against reach margin, success rates, time per step.

Colours are :func:`prioik.benchmarks.plots.color_of`'s, the same as in the scenario
pages; runs that stopped early are drawn as ✕ at the top of the error axes.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from prioik.benchmarks.plots import color_of

__all__ = ["error_vs_margin", "success_rates", "step_times"]


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def error_vs_margin(path: Path, judged: list[dict[str, Any]], labels: list[str],
                    key: str, ylabel: str, bound: float | None, title: str) -> Path:
    """``key`` of every run against its reach margin, one panel per variant (log y;
    the success bound as a dashed line; failed runs as ✕ at the top)."""
    plt = _plt()
    cols = min(4, len(labels))
    rows_n = math.ceil(len(labels) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(3.4 * cols, 2.6 * rows_n),
                             sharex=True, sharey=True, squeeze=False)
    vals = [r[key] for r in judged if r.get(key) is not None and r[key] > 0]
    lo = max(min(vals), 1e-12) if vals else 1e-9
    hi = max(vals) if vals else 1.0
    top = hi * 3
    for ax, label in zip(axes.flat, labels, strict=False):
        rs = [r for r in judged if r["label"] == label]
        ok = [r for r in rs if not r["failed"] and r.get(key) is not None]
        bad = [r for r in rs if r["failed"]]
        ax.scatter([r["reach_margin_m"] for r in ok], [max(r[key], lo) for r in ok], s=9,
                   color=color_of(label), alpha=0.8, linewidths=0)
        if bad:
            ax.scatter([r["reach_margin_m"] for r in bad], [top] * len(bad), marker="x",
                       s=16, color="black", linewidths=0.8, label=f"stopped ({len(bad)})")
            ax.legend(loc="lower right", fontsize=7, frameon=False)
        if bound is not None:
            ax.axhline(bound, color="0.4", lw=0.8, ls="--")
        ax.axvline(0.0, color="0.75", lw=0.8)
        ax.set_yscale("log")
        ax.set_ylim(lo / 3, top * 3)
        ax.set_title(label, fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
    for ax in axes.flat[len(labels):]:
        ax.axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("reach margin (m)")
    for ax in axes[:, 0]:
        ax.set_ylabel(ylabel, fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def success_rates(path: Path, table: dict, labels: list[str], criteria: list[tuple[str, str]],
                  title: str) -> Path:
    """Horizontal bars: per variant the rate of each criterion with its Wilson interval."""
    plt = _plt()
    fig, axes = plt.subplots(1, len(criteria), figsize=(3.0 * len(criteria),
                                                        0.35 * len(labels) + 1.2),
                             sharey=True, squeeze=False)
    y = np.arange(len(labels))
    for ax, (key, name) in zip(axes[0], criteria, strict=False):
        rates = [table[lb][key] for lb in labels]
        r = np.array([x.rate for x in rates])
        lo = np.array([x.interval[0] for x in rates])
        hi = np.array([x.interval[1] for x in rates])
        ax.barh(y, np.nan_to_num(r), color=[color_of(lb) for lb in labels], alpha=0.85)
        ax.errorbar(r, y, xerr=[np.clip(np.nan_to_num(r - lo), 0, None),
                                np.clip(np.nan_to_num(hi - r), 0, None)], fmt="none",
                    ecolor="black", elinewidth=0.8, capsize=2)
        ax.set_xlim(0, 1.02)
        ax.set_title(name, fontsize=9)
        ax.grid(True, axis="x", alpha=0.3)
    axes[0][0].set_yticks(y, labels, fontsize=8)
    axes[0][0].invert_yaxis()
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def step_times(path: Path, judged: list[dict[str, Any]], labels: list[str], title: str) -> Path:
    """Box plot of the median step time of every run, per variant (log axis)."""
    plt = _plt()
    data, shown = [], []
    for lb in labels:
        v = [1e3 * r["median_step_time_s"] for r in judged
             if r["label"] == lb and r.get("median_step_time_s")]
        if v:
            data.append(v)
            shown.append(lb)
    fig, ax = plt.subplots(figsize=(7.5, 0.35 * len(shown) + 1.2))
    if data:
        parts = ax.boxplot(data, orientation="horizontal", patch_artist=True, widths=0.6,
                           flierprops={"markersize": 3})
        for patch, lb in zip(parts["boxes"], shown, strict=False):
            patch.set_facecolor(color_of(lb))
            patch.set_alpha(0.8)
        ax.set_yticks(np.arange(1, len(shown) + 1), shown, fontsize=8)
        ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("median time per control step of a run (ms): kinematics + solve + torque")
    ax.set_title(title, fontsize=10)
    ax.grid(True, axis="x", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
