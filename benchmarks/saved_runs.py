"""``prioik replay RESULT`` and ``prioik plot RESULT``: work on saved runs (``.npz``).

A run saved by :meth:`robots.SimulationResult.save` (``prioik fencing`` and
``prioik arm`` save every run next to its CSV) reloads with its joint names and the
scenario it came from, which is all a replay or a plot needs. ``prioik replay`` writes
the light stick page (:func:`benchmarks.replay.write_replay`, scenario runs) and the
page with the robot's meshes (:func:`robots.write_mesh_replay`, any run whose robot is
known: its scenario's, or ``--robot``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

#: triangles of the meshed page's robot (robots.mesh_replay.TRIANGLES; not imported
#: here so that building the parser needs no pinocchio)
TRIANGLES = 40_000


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
    """Write the HTML replays of saved runs (or play one live in meshcat): the light
    stick page (runs of the toolkit's scenarios) and the page with the robot's meshes."""
    results = _load(args.results)
    if args.live:
        from prioik.benchmarks.replay import live_view
        live_view(next(iter(results.values())), open_browser=args.open)
        return 0
    out = _out_dir(args, args.results[0])
    stem = Path(args.results[0]).stem if len(results) == 1 else "replay"
    title = ", ".join(results)
    scenarios = {(r.info.get("scenario"), r.info.get("variant")) for r in results.values()}
    from_scenarios = all(name is not None for name, _ in scenarios)
    if from_scenarios:
        from prioik.benchmarks.replay import write_replay
        path = write_replay(out / f"{stem}_replay.html", results, title=title)
        print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
    if args.no_meshes:
        if not from_scenarios:
            raise ValueError("nothing to write: the light page replays runs of prioik's "
                             "scenarios only, and --no-meshes leaves out the meshed page")
        return 0
    from prioik.robots import write_mesh_replay
    from prioik.robots.scenarios import make
    markers = None
    if args.robot is not None:
        robot = args.robot
    elif from_scenarios and len(scenarios) == 1:
        scenario = make(*next(iter(scenarios)))
        robot, markers = scenario.robot, scenario.markers
    elif from_scenarios:
        robots = {make(*s).robot.name for s in scenarios}
        if len(robots) > 1:
            raise ValueError(f"the runs come from different robots ({', '.join(sorted(robots))}); "
                             "replay them one robot at a time")
        robot = make(*next(iter(scenarios))).robot
    else:
        raise ValueError("these runs do not say which scenario they come from "
                         "(SimulationResult.info['scenario']); give the robot with "
                         "--robot NAME_OR_URDF")
    path = write_mesh_replay(out / f"{stem}_replay_meshes.html", robot, results,
                             title=title, markers=markers, triangles=args.triangles)
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
    p = subparsers.add_parser(
        "replay", help="replay saved runs (.npz) in browser pages or live in meshcat",
        description="Write two self-contained HTML pages (no server, no network) that "
                    "animate the saved runs, every run selectable: STEM_replay.html, the "
                    "light page of link segments, targets and the tip's trace (runs of "
                    "prioik fencing / arm), and STEM_replay_meshes.html, the robot with "
                    "its URDF meshes (decimated) in meshcat's viewer, for any run whose "
                    "robot is known (its scenario, or --robot). STEM is the run's file "
                    "name, or 'replay' for several runs.")
    p.add_argument("results", nargs="+", metavar="RESULT.npz",
                   help="runs saved by prioik fencing / arm or SimulationResult.save")
    p.add_argument("--out", default=None, help="output folder (default: ./results)")
    p.add_argument("--robot", default=None, metavar="NAME_OR_URDF",
                   help="the robot of runs that name no scenario: a name (g1, talos, "
                        "panda, ur5, go2, solo12) or a URDF path")
    p.add_argument("--triangles", type=int, default=TRIANGLES,
                   help="triangles of the whole robot's meshes after decimation "
                        f"(default {TRIANGLES:,}; more: a finer and larger page)")
    p.add_argument("--no-meshes", action="store_true",
                   help="write only the light page")
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
