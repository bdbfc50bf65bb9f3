"""A griffe extension for prioik's site (``mkdocs.yml``: mkdocstrings' ``extensions``).

prioik's docstrings are Google style with Sphinx roles for cross-references
(``:class:`TaskStack```, ``:func:`~hierarchy.check_lexicographic```) and reST's ``::``
before a literal block. Markdown reads neither; this extension rewrites them in the
docstrings the site renders (the sources are not changed):

* a role naming a public object the site documents (a name of ``prioik.__all__`` or of
  ``prioik.robots.__all__``; functions, classes, exceptions, modules and data) becomes a
  link to its reference entry, ``[`TaskStack`][prioik.TaskStack]``;
* any other role becomes a code span of the name (its last component after ``~``);
* a paragraph ending in ``::`` ends in ``:`` (the indented block after it stays code).
"""

from __future__ import annotations

import re

import griffe

_ROLE = re.compile(r":(?P<role>[a-z]+):`(?P<target>[^`]+)`")
_LITERAL = re.compile(r"(?<=\S)::$", flags=re.M)
#: roles whose last component names the object itself (``:meth:`solve``` does not: the
#: name of a method may be that of a public function)
_LINKED_ROLES = ("class", "func", "exc", "mod", "data")


def _public_targets() -> dict[str, str]:
    """Last component of a public name → the identifier of its reference entry."""
    import prioik
    import prioik.robots

    targets = {f"robots.{n}": f"prioik.robots.{n}" for n in prioik.robots.__all__}
    targets.update({n: f"prioik.robots.{n}" for n in prioik.robots.__all__})
    targets.update({n: f"prioik.{n}" for n in prioik.__all__})
    targets.pop("simulate", None)        # both a sub-module and the function it exports
    return targets


class SphinxRoles(griffe.Extension):
    """Sphinx roles and reST ``::`` in docstrings, rewritten for Markdown."""

    def __init__(self) -> None:
        super().__init__()
        self.targets = _public_targets()

    def _rewrite(self, match: re.Match) -> str:
        role, target = match["role"], match["target"].strip()
        text = target
        if "<" in target and target.endswith(">"):         # :role:`text <target>`
            text, target = (p.strip() for p in target[:-1].split("<", 1))
        name = target.lstrip("~").lstrip(".")
        if target.startswith("~") and text == match["target"].strip():
            text = name.rsplit(".", 1)[-1]
        link = (self.targets.get(name.removeprefix("prioik."))
                or self.targets.get(name.rsplit(".", 1)[-1]))
        if role in _LINKED_ROLES and link is not None:
            return f"[`{text}`][{link}]"
        return f"`{text}`"

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is None:
            return
        value = _ROLE.sub(self._rewrite, obj.docstring.value)
        obj.docstring.value = _LITERAL.sub(":", value)
