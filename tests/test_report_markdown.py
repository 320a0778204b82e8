"""The identification report's figure captions render as one emphasis in markdown
(issue 16: ``*Normal (*) and radial (o)…*`` ended the emphasis at the inner ``*``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.report.identification import _figures_section


def _section() -> str:
    names = ("residuals", "hist_normal", "hist_radial")
    return _figures_section({k: Path(f"{k}.png") for k in names})


def test_captions_have_no_markdown_characters() -> None:
    captions = [ln for ln in _section().splitlines() if ln.startswith("*")]
    assert len(captions) == 3
    for line in captions:
        inner = line[1:-1]
        assert line.endswith("*") and not set("*_`[]<>\\") & set(inner), line


def test_captions_render_as_one_emphasis() -> None:
    markdown_it = pytest.importorskip("markdown_it", reason="markdown-it-py not installed")
    html = markdown_it.MarkdownIt().render(_section())
    for line in (ln for ln in _section().splitlines() if ln.startswith("*")):
        assert f"<p><em>{line[1:-1]}</em></p>" in html, line
