"""What the documents say, for tests that compare a documented number with the code's
output (issue 30, item 8): a quote is looked for with every run of whitespace (line
breaks included) read as one space, and a failure names the text the code gives now."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def doc_text(name: str) -> str:
    """The text of ``name`` (a path from the repository's root), whitespace runs as one space."""
    return " ".join((ROOT / name).read_text().split())


def assert_quoted(name: str, quoted: str) -> None:
    """``quoted``, built from the code's output, is what document ``name`` says."""
    assert " ".join(quoted.split()) in doc_text(name), (
        f"{name} should say (the code gives now):\n{quoted}"
    )
