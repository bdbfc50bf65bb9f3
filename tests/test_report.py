"""benchmarks/report.py: pages from templates, prose out of the code."""

from __future__ import annotations

import pytest

from prioik.benchmarks import report
from prioik.benchmarks.report import Page, table


@pytest.fixture
def page(monkeypatch):
    text = ("# $title\n\n$body\n\n\n\n$missing_section\nEnd.\n\n"
            "<!-- block: item -->\n- `$label`:\n  $what\n"
            "<!-- block: tail -->\n and more ($n)\n")
    monkeypatch.setattr(report, "_text", lambda name: text)
    return Page("test.md")


def test_body_blocks_and_inline(page):
    assert set(page.blocks) == {"item", "tail"}
    item = page.block("item", label="sns", what="bounds first")
    assert item == "- `sns`:\n  bounds first"
    assert page.inline("item", label="sns", what="x") == "- `sns`: x"
    assert page.inline("tail", n=2) == " and more (2)"      # a continuation keeps its space
    text = page.render(title="T", body=item, missing_section="")
    assert text == "# T\n\n- `sns`:\n  bounds first\n\nEnd.\n"   # no run of blank lines


def test_a_missing_value_is_an_error_naming_it(page):
    with pytest.raises(KeyError, match=r"needs \$what"):
        page.block("item", label="x")
    with pytest.raises(KeyError, match="no block 'nope'"):
        page.block("nope")


def test_every_shipped_template_loads():
    for name in ("benchmarks.md", "reproduction.md", "arm.md", "validation.md",
                 "properties.md", "scenario.md"):
        assert Page(name).blocks, name


def test_table():
    assert table(["a", "b"], [[1, "x"]], "lr") == "| a | b |\n|---|---:|\n| 1 | x |"
