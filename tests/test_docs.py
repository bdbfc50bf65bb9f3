"""The documentation site (mkdocs.yml, docs/): it builds with warnings as errors, every
public name has a docstring and an entry in the API reference, and the user pages'
Python examples run as written (as README's do, tests/test_readme.py)."""

from __future__ import annotations

import os
import re
import runpy
import shlex
import subprocess
import sys
from pathlib import Path

import griffe
import numpy as np
import pytest

import prioik
import prioik.robots

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
#: the pages written for users (the generated reports and the design notes are not)
USER_PAGES = sorted([DOCS / "index.md", DOCS / "getting-started.md",
                     *(DOCS / "how-to").glob("*.md"), *(DOCS / "explanation").glob("*.md")])
BLOCKS = [(page, i, block) for page in USER_PAGES
          for i, block in enumerate(re.findall(r"```python\n(.*?)```", page.read_text(),
                                               flags=re.S))]


COMMANDS = [(page, line) for page in USER_PAGES
            for block in re.findall(r"```sh\n(.*?)```", page.read_text(), flags=re.S)
            for line in block.replace("\\\n", " ").splitlines()
            if line.startswith("prioik ")]


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site built by ``mkdocs build --strict`` (a warning fails the build)."""
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                          str(out)], cwd=ROOT, env=env, capture_output=True, text=True)
    log = run.stdout + run.stderr
    assert run.returncode == 0, log
    assert not re.search(r"^(WARNING|ERROR)", log, flags=re.M), log
    return out


def _anchors(site: Path) -> set[str]:
    return {a for page in (site / "reference").rglob("index.html")
            for a in re.findall(r'id="(prioik\.[\w.]+)"', page.read_text())}


def test_site_builds_strict_with_every_user_page(site):
    for page in USER_PAGES:
        rel = page.relative_to(DOCS).with_suffix("")        # a/b.md -> a/b/index.html
        built = site / (rel.parent if rel.name == "index" else rel) / "index.html"
        assert built.is_file(), built
    options = (site / "reference" / "options" / "index.html").read_text()
    for name in prioik.formulations.names():
        assert f"<code>{name}</code>" in options, name


def test_every_public_name_has_a_reference_entry(site):
    anchors = _anchors(site)
    assert [n for n in prioik.__all__ if f"prioik.{n}" not in anchors] == []
    # prioik.robots: `simulate` is both a sub-module and the function it exports
    missing = [n for n in prioik.robots.__all__
               if not any(a.startswith("prioik.robots.") and a.endswith(f".{n}")
                          for a in anchors)]
    assert missing == []


def test_every_public_name_has_a_docstring(tmp_path):
    """Read as the site reads them: griffe's static analysis of the installed layout."""
    hooks = runpy.run_path(str(DOCS / "hooks.py"), run_name="docs_hooks")
    tree = hooks["package_tree"](tmp_path / "src")
    package = griffe.GriffeLoader(search_paths=[str(tree)]).load("prioik",
                                                                 try_relative_path=False)
    empty = []
    for name in prioik.__all__:
        obj = package[name]
        obj = obj.final_target if obj.is_alias else obj
        if obj.docstring is None or not obj.docstring.value.strip():
            empty.append(name)
    assert empty == []


@pytest.mark.parametrize("page, line", COMMANDS,
                         ids=[f"{p.relative_to(DOCS)}:{line[:40]}" for p, line in COMMANDS])
def test_user_page_commands_parse(page, line):
    """Every `prioik` command of the user pages is accepted by the command line as written
    (the sub-command and its options; running them is the commands' own tests), and the
    repository files it names exist."""
    from prioik.cli import build_parser
    argv = shlex.split(line, comments=True)[1:]
    build_parser().parse_args(argv)                  # SystemExit on an unknown option
    for arg in argv:
        if "/" in arg and Path(arg).suffix in (".json", ".dat", ".txt", ".toml") \
                and not arg.startswith("/"):
            assert (ROOT / arg).is_file(), arg


def test_user_pages_have_examples():
    pages = {page for page, _, _ in BLOCKS}
    assert DOCS / "getting-started.md" in pages and len(BLOCKS) >= 10 and len(COMMANDS) >= 10


@pytest.mark.parametrize("page, index, block", BLOCKS,
                         ids=[f"{p.relative_to(DOCS)}:{i}" for p, i, _ in BLOCKS])
def test_user_page_example_runs(page, index, block, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)                  # paths in the examples are from a clone's root
    namespace: dict = {}
    exec(compile(block, f"{page.relative_to(ROOT)} python block {index}", "exec"), namespace)
    if isinstance(namespace.get("sol"), prioik.Solution):   # the last answer of the example
        assert namespace["sol"].ok and np.isfinite(namespace["sol"].x).all()
