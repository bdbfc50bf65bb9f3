"""README's and docs/usage.md's Python examples run as written, and the commands README
names are the ones that exist."""

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
def test_example_runs(page, index, block, capsys):
    namespace: dict = {}
    exec(compile(block, f"{page} python block {index}", "exec"), namespace)
    if "sol" in namespace:
        assert namespace["sol"].status == "optimal"
        assert np.isfinite(namespace["sol"].x).all()


def test_make_demo_is_the_command_readme_names():
    """README says what `make demo` runs; the Makefile runs that (OUT = results)."""
    named = re.search(r"runs `(prioik fencing [^`]*)`", README.read_text()).group(1)
    makefile = (ROOT / "Makefile").read_text()
    recipe = re.search(r"^demo:.*\n\t(.*)$", makefile, flags=re.M).group(1)
    assert re.search(r"^OUT\s*\?=\s*results$", makefile, flags=re.M)
    assert recipe.replace("$(VENV)/bin/", "").replace("$(OUT)", "results") == named


def test_the_commands_readme_names_parse():
    """Every `prioik ...` command README shows is accepted by the command line."""
    from prioik.benchmarks.cli import build_parser
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
