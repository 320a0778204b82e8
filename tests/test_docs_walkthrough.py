"""examples/README.md's walk-through (sections 1-5) run as written (issue 30, item 8).

Every ``console`` block before "Measured data" is run in one empty folder holding a copy
of ``examples/my_scara.toml``, in the order of the document, with typer's ``CliRunner`` on
``pipeline.cli.app``; each documented output line must be the line the command prints.
A line ``...`` stands for any number of lines; durations (``159.2 ms``, ``1.5 s``) are
not compared. On a mismatch the failure shows the whole output the code gives now, to
paste into the document.
"""

from __future__ import annotations

import re
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest
from markdown_it import MarkdownIt
from typer.testing import CliRunner

from pipeline.cli import app

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "examples" / "README.md"
LAST_SECTION = "Measured data"  # real data (tests/test_realdata.py), not run here
#: a duration, with the padding before it: "ran     159.2 ms", "16/16 stages    1.5 s"
DURATION = re.compile(r" +\d+(\.\d+)? m?s\b")


@dataclass(frozen=True)
class Command:
    """One ``$ pipeline ...`` line of a console block and the output shown under it."""

    line: str
    output: tuple[str, ...]


def walkthrough_commands(text: str) -> list[Command]:
    """The commands of the ``console`` fences before the section ``LAST_SECTION``."""
    tokens = MarkdownIt().parse(text)
    commands: list[Command] = []
    for k, tok in enumerate(tokens):
        if tok.type == "heading_open" and tokens[k + 1].content.startswith(LAST_SECTION):
            break
        if tok.type != "fence" or tok.info.strip() != "console":
            continue
        for chunk in re.split(r"^(?=\$ )", tok.content, flags=re.M):
            if chunk.strip():
                head, *out = chunk.rstrip("\n").split("\n")
                commands.append(Command(head.removeprefix("$ "), tuple(out)))
    return commands


def _masked(line: str) -> str:
    return DURATION.sub(" <duration>", line.rstrip())


#: A printed number and its documented text may differ by one unit in their last digit
#: where another CPU's BLAS kernels round otherwise: the SCARA quill's q offset
#: (-72941.298543 cm, an ill-conditioned intersection) printed -72941.298544 on an AMD EPYC.
#: Two numbers both below ROUNDING (a converged solve's residual, 9.43e-12 deg there and
#: 9.46e-12 deg here) are the same rounding.
NUMBER = re.compile(r"-?\d+\.(\d+)(?:e[-+]?\d+)?")
ROUNDING = 1e-6


def _same(printed: str, want: str) -> bool:
    """The documented line ``want`` is the ``printed`` one: the same text (durations
    masked), each decimal number within one unit of the documented number's last digit."""
    a, b = _masked(printed), _masked(want)
    if a == b:
        return True
    if NUMBER.sub("<n>", a) != NUMBER.sub("<n>", b):
        return False
    pairs = zip(NUMBER.finditer(a), NUMBER.finditer(b), strict=True)

    def same(x: re.Match[str], y: re.Match[str]) -> bool:
        u, v = float(x.group(0)), float(y.group(0))
        if abs(u) < ROUNDING and abs(v) < ROUNDING:
            return True
        digits = len(y.group(1))
        return (
            "e" not in y.group(0)
            and len(x.group(1)) == digits
            and (abs(u - v) <= 1.01 * 10.0**-digits)
        )

    return all(same(x, y) for x, y in pairs)


def mismatch(documented: tuple[str, ...], printed: list[str]) -> str | None:
    """The first documented line the output does not give at its place (None: all do)."""
    at, skipping = 0, False
    for want in documented:
        if want.strip() == "...":
            skipping = True
            continue
        while skipping and at < len(printed) and not _same(printed[at], want):
            at += 1
        if at >= len(printed) or not _same(printed[at], want):
            return want
        at, skipping = at + 1, False
    if not skipping and at < len(printed):
        return f"(nothing: the output goes on with {printed[at]!r})"
    return None


def test_walkthrough_is_parsed() -> None:
    commands = walkthrough_commands(DOC.read_text())
    words = [shlex.split(c.line)[1] for c in commands]
    assert words[:5] == ["fk", "simulate", "simulate", "identify", "show"], words
    assert {"audit", "ik"} <= set(words) and all(c.line.startswith("pipeline ") for c in commands)


def test_mismatch_reports_the_missing_line() -> None:
    printed = ["a", "  dh ran  12.3 ms  4 rows", "b", "c"]
    assert mismatch(("a", "  dh ran   2.8 ms  4 rows", "...", "c"), printed) is None
    assert mismatch(("a", "...", "x"), printed) == "x"
    assert mismatch(("a", "b"), printed) == "b"
    assert "goes on with 'b'" in str(mismatch(("a", "  dh ran 1 s  4 rows"), printed))


def test_walkthrough_prints_what_the_document_shows(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "examples").mkdir()
    shutil.copy(ROOT / "examples" / "my_scara.toml", tmp_path / "examples")
    # Section 1's broken.toml: my_scara.toml with the quill's type misspelt (as the text says).
    scara = (tmp_path / "examples" / "my_scara.toml").read_text()
    assert scara.count('type = "prismatic"') == 1
    (tmp_path / "broken.toml").write_text(scara.replace('"prismatic"', '"helical"'))
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    for cmd in walkthrough_commands(DOC.read_text()):
        r = runner.invoke(app, shlex.split(cmd.line)[1:])
        printed = r.output.rstrip("\n").split("\n")
        failing = any(line.startswith("error:") for line in cmd.output)
        assert r.exit_code == (1 if failing else 0), (cmd.line, r.output)
        wrong = mismatch(cmd.output, printed)
        assert wrong is None, (
            f"examples/README.md, `$ {cmd.line}`: the documented line\n{wrong}\n"
            f"is not what the code prints; it prints now:\n{r.output}"
        )


def test_a_number_matches_to_its_last_digits_only() -> None:
    """Cross-CPU rounding in the last printed digit passes; a changed number does not."""
    doc = ("│ 3 ┆ prismatic ┆ -72941.298543 ┆ 0.0 │",)
    assert mismatch(doc, ["│ 3 ┆ prismatic ┆ -72941.298544 ┆ 0.0 │"]) is None
    assert mismatch(doc, ["│ 3 ┆ prismatic ┆ -72941.298545 ┆ 0.0 │"]) == doc[0]  # two units
    assert mismatch(doc, ["│ 3 ┆ prismatic ┆ -72941.3 ┆ 0.0 │"]) == doc[0]
    assert mismatch(doc, ["│ 3 ┆ revolute ┆ -72941.298543 ┆ 0.0 │"]) == doc[0]
    res = ("residual 2.42e-09 cm, 9.43e-12 deg",)
    assert mismatch(res, ["residual 2.42e-09 cm, 9.46e-12 deg"]) is None  # both rounding
    assert mismatch(res, ["residual 2.42e-09 cm, 9.43e-05 deg"]) == res[0]
