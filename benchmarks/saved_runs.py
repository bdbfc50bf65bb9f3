"""``prioik replay RESULT`` and ``prioik plot RESULT``: work on saved runs (``.npz``).

A run saved by :meth:`robots.SimulationResult.save` (``prioik fencing`` and
``prioik arm`` save every run next to its CSV) reloads with its joint names and the
scenario it came from, which is all a replay or a plot needs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _load(paths: list[str]) -> dict:
    from prioik.robots import SimulationResult
    out = {}
    for p in paths:
        res = SimulationResult.load(p)
        out[res.info.get("label") or Path(p).stem] = res
    return out


def _out_dir(args, first: str) -> Path:
    return Path(args.out) if args.out else Path("results")


def cmd_replay(args: argparse.Namespace) -> int:
    """Write the HTML replay of saved runs (or play one live in meshcat)."""
    results = _load(args.results)
    if args.live:
        from prioik.benchmarks.replay import live_view
        live_view(next(iter(results.values())), open_browser=args.open)
        return 0
    from prioik.benchmarks.replay import write_replay
    out = _out_dir(args, args.results[0])
    path = out / (Path(args.results[0]).stem + "_replay.html") if len(results) == 1 \
        else out / "replay.html"
    write_replay(path, results, title=", ".join(results))
    print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    """Plot saved runs: tip error, algorithmic error and ‖q̈‖ (grouped panels)."""
    from prioik.benchmarks.plots import scenario_figures
    from prioik.benchmarks.scenario_runs import scenario_class
    results = _load(args.results)
    out = _out_dir(args, args.results[0])
    out.mkdir(parents=True, exist_ok=True)
    first = next(iter(results.values()))
    scenario = first.info.get("scenario", "run")
    try:
        tip = scenario_class(scenario).tip_label
    except KeyError:
        tip = "tip"
    files = scenario_figures(out, first.info.get("variant", "run"), results, scenario, tip)
    for f in files:
        print(f"wrote {f}")
    return 0


def add_parser(subparsers) -> None:
    """Register ``prioik replay`` and ``prioik plot``."""
    p = subparsers.add_parser("replay", help="replay saved runs (.npz) in a browser page "
                                             "or live in meshcat")
    p.add_argument("results", nargs="+", metavar="RESULT.npz",
                   help="runs saved by prioik fencing / arm (SimulationResult.save)")
    p.add_argument("--out", default=None, help="output folder (default: ./results)")
    p.add_argument("--live", action="store_true",
                   help="play the first run in meshcat (pinocchio's MeshcatVisualizer) "
                        "instead of writing HTML")
    p.add_argument("--open", action="store_true", help="with --live: open the browser")
    p.set_defaults(func=cmd_replay)
    p = subparsers.add_parser("plot", help="plot saved runs (.npz): tip error, "
                                           "algorithmic error, ‖q̈‖")
    p.add_argument("results", nargs="+", metavar="RESULT.npz")
    p.add_argument("--out", default=None, help="output folder (default: ./results)")
    p.set_defaults(func=cmd_plot)
