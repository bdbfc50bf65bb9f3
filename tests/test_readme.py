"""README's and docs/usage.md's Python examples run as written, and the commands README
names are the ones that exist."""

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = (README, ROOT / "docs" / "usage.md")
BLOCKS = [(page.name, i, block) for page in PAGES
          for i, block in enumerate(re.findall(r"```python\n(.*?)```", page.read_text(),
                                               flags=re.S))]


def test_readme_fits_on_two_screens():
    assert len(README.read_text().splitlines()) <= 150


def test_pages_have_examples():
    assert [name for name, _, _ in BLOCKS].count("README.md") >= 1
    assert [name for name, _, _ in BLOCKS].count("usage.md") >= 2


@pytest.mark.parametrize("page,index,block", BLOCKS, ids=[f"{n}-{i}" for n, i, _ in BLOCKS])
def test_example_runs(page, index, block, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)                 # what an example writes lands here
    namespace: dict = {}
    exec(compile(block, f"{page} python block {index}", "exec"), namespace)
    if "sol" in namespace:
        assert namespace["sol"].status == "optimal"
        assert np.isfinite(namespace["sol"].x).all()


#: docs/usage.md's joint-limits writer loop (the block that writes the joint-limit bounds)
LIMITS_LOOP = next(b for _, _, b in BLOCKS if 'add_joint_limits' in b and "KinematicState" in b)
#: its damping line, the remedy for chatter out of reach
DAMPING_LINE = next(line for line in LIMITS_LOOP.splitlines() if "add_damping" in line)


def _limits_loop_speeds(source: str, steps: int, monkeypatch):
    """docs/usage.md's joint-limits loop run as written but for ``steps`` steps; returns every
    step's ``q̇`` and the hand's position after it."""
    import builtins

    import pinocchio as pin

    import prioik

    answers = []
    prepare = prioik.prepare

    def recording_prepare(*args, **kwargs):
        solver = prepare(*args, **kwargs)

        class Recording:
            def solve(self, data):
                sol = solver.solve(data)
                answers.append(sol.x.copy())
                return sol

        return Recording()

    monkeypatch.setattr(prioik, "prepare", recording_prepare)
    namespace = {"range": lambda n: builtins.range(steps)}
    exec(compile(source, "docs/usage.md joint-limits loop", "exec"), namespace)
    robot, dt = namespace["robot"], namespace["dt"]
    data, fid = robot.model.createData(), robot.frame_id("panda_hand")
    q, hand = robot.q0.copy(), []
    for x in answers:
        q = pin.integrate(robot.model, q, x * dt)
        pin.framesForwardKinematics(robot.model, data, q)
        hand.append(data.oMf[fid].translation.copy())
    return np.array(answers), np.array(hand)


#: the hand's target in docs/usage.md's joint-limits loop
HAND_TARGET = np.array(json.loads(re.search(r'"hand", np\.array\((\[[^\]]*\])\)',
                                            LIMITS_LOOP).group(1)))


@pytest.mark.parametrize("damped", [True, False])
def test_readme_limits_loop_does_not_chatter_out_of_reach(damped, monkeypatch):
    """2,500 steps of the loop as written: once the hand has stopped making progress
    (:func:`~prioik.benchmarks.out_of_reach.settled_step`), at most 2
    sign changes of any joint's q̇ per 100 steps (at least 10 such windows); without its
    damping line the joints flip between their bounds every step."""
    from prioik.benchmarks.out_of_reach import settled_step, sign_changes

    source = LIMITS_LOOP if damped else LIMITS_LOOP.replace(DAMPING_LINE + "\n", "")
    qdot, hand = _limits_loop_speeds(source, 2500, monkeypatch)
    assert qdot.shape[0] == 2500
    counts = sign_changes(qdot, settled_step(np.linalg.norm(hand - HAND_TARGET, axis=1)))
    assert counts.shape[0] >= 10
    if damped:
        assert counts.max() <= 2, counts.max(axis=1)
    else:
        assert counts.max() >= 90, counts.max(axis=1)


def test_make_demo_is_the_command_readme_names():
    """README says what `make demo` runs; the Makefile runs that (OUT = results)."""
    named = re.search(r"runs `(prioik fencing [^`]*)`", README.read_text()).group(1)
    makefile = (ROOT / "Makefile").read_text()
    recipe = re.search(r"^demo:.*\n\t(.*)$", makefile, flags=re.M).group(1)
    assert re.search(r"^OUT\s*\?=\s*results$", makefile, flags=re.M)
    assert recipe.replace("$(VENV)/bin/", "").replace("$(OUT)", "results") == named


def test_the_commands_readme_names_parse():
    """Every `prioik ...` command README shows is accepted by the command line."""
    from prioik.cli import build_parser
    commands = re.findall(r"`(prioik [a-z]+[^`]*)`", README.read_text())
    assert commands
    parser = build_parser()
    for command in commands:
        argv = shlex.split(command)[1:]
        parser.parse_args(argv)            # an unknown option or command exits (SystemExit)


def test_readme_benchmark_command_exists():
    """The figures' command: `python -m prioik.benchmarks.mink_step STEPS SOLVERS`."""
    import importlib
    assert "python -m prioik.benchmarks.mink_step 300 daqp,quadprog" in README.read_text()
    assert callable(importlib.import_module("prioik.benchmarks.mink_step").run)


def test_every_measured_figure_names_its_command():
    """A README line quoting a measurement (µs, a ratio ×, a %) follows, within its
    paragraph and table, the command that produces it (tests/test_doc_commands.py runs
    that command as written)."""
    lines = README.read_text().splitlines()
    figures = [i for i, line in enumerate(lines)
               if re.search(r"\d\s*(µs|×)|\d\s*%", line) and not line.startswith("```")]
    for i in figures:
        start = i
        while start > 0 and (lines[start - 1].strip() or lines[start].startswith("|")):
            start -= 1                      # back to the paragraph before the table
        context = "\n".join(lines[start:i + 1])
        assert re.search(r"`(python -m prioik\.[\w.]+|prioik [a-z]+)[^`]*`", context), \
            f"README.md:{i + 1} quotes a figure without the command that produces it"
    assert figures
