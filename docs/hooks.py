"""MkDocs hooks of prioik's site (``mkdocs.yml``: ``hooks``).

* The API reference is read from the sources by mkdocstrings (griffe's static analysis).
  The installed package ``prioik`` maps the repository's top-level folders to its
  sub-packages (``pyproject.toml``, ``[tool.scikit-build.wheel.packages]``:
  ``prioik/hierarchy`` is ``hierarchy/``, ...), which griffe cannot follow through the
  editable install. Loading this file lays the same tree out under ``build/docs-src``
  (:func:`package_tree`: the sub-packages as symbolic links), and mkdocstrings reads it
  (``paths: [build/docs-src]``).
* ``reference/options.md`` is written at build time from every formulation's ``OPTIONS``
  (:mod:`prioik.formulations.options`): what ``prioik list --options`` prints, as tables.
"""

from __future__ import annotations

import importlib
import shutil
from pathlib import Path

import tomllib
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
SOURCE_TREE = ROOT / "build" / "docs-src"


def package_tree(dest: Path = SOURCE_TREE) -> Path:
    """``dest/prioik/...``: the wheel's package layout, as links to the sources."""
    with open(ROOT / "pyproject.toml", "rb") as f:
        packages = tomllib.load(f)["tool"]["scikit-build"]["wheel"]["packages"]
    if dest.exists():
        shutil.rmtree(dest)
    top = dest / "prioik"
    top.mkdir(parents=True)
    for source in sorted((ROOT / packages["prioik"]).glob("*.py")):
        shutil.copy2(source, top / source.name)
    for target, source in packages.items():
        if target != "prioik":
            (dest / target).symlink_to(ROOT / source, target_is_directory=True)
    return dest


# laid out when MkDocs loads this file, before any plugin reads its configuration
package_tree()


def _cell(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def options_page() -> str:
    """The formulations' typed options as markdown tables (one section per formulation)."""
    from prioik.formulations.registry import PLUGINS

    lines = [
        "# Formulation options",
        "",
        "Every formulation takes only the options it declares (its `OPTIONS`, a dict of "
        "[`Option`][prioik.Option]); `prioik.solve(stack, name, **options)` and "
        "`prioik.prepare(layout, name, **options)` validate them once and raise "
        "[`FormulationError`][prioik.FormulationError] naming the option at fault. "
        "`prioik list --options` prints the same declarations. This page is generated "
        "from the code when the site is built.",
        "",
    ]
    for name, (module_name, extra) in PLUGINS.items():
        lines += [f"## `{name}`", ""]
        try:
            module = importlib.import_module(module_name)
        except ImportError:
            lines += [f"Needs the `{extra}` extra (`pip install -e \".[{extra}]\"`), not "
                      "installed where this page was built.", ""]
            continue
        where = f"the `{extra}` extra" if extra else "the core"
        lines += [f"{_cell(module.DESCRIPTION)} — in {where}; module `{module_name}`.", ""]
        if not module.OPTIONS:
            lines += ["No options.", ""]
            continue
        lines += ["| option | kind | meaning (default; allowed values) |", "|---|---|---|"]
        for key, option in module.OPTIONS.items():
            lines.append(f"| `{key}` | {option.kind} | {_cell(option.doc())} |")
        lines.append("")
    return "\n".join(lines)


def on_files(files, config):
    files.append(File.generated(config, "reference/options.md", content=options_page()))
    return files
