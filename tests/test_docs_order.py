"""The README's and docs/plan.md's command blocks run in their order on a fresh clone
(issue 44): no line reads a file or a signature that no earlier line writes."""

from __future__ import annotations

import shlex
import shutil
import subprocess
from pathlib import Path

from markdown_it import MarkdownIt
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app

ROOT = Path(__file__).resolve().parent.parent
PIPELINE = ".venv/bin/pipeline "


def sh_lines(path: Path) -> list[list[str]]:
    """The lines of each ``sh`` fence of ``path`` (comments after `` # `` dropped)."""
    blocks = []
    for tok in MarkdownIt().parse(path.read_text()):
        if tok.type == "fence" and tok.info.strip() == "sh":
            lines = [
                ln.split("   # ")[0].split("  # ")[0].rstrip() for ln in tok.content.splitlines()
            ]
            blocks.append([ln for ln in lines if ln])
    return blocks


def _run(line: str, cwd: Path) -> tuple[int, str]:
    """A documented line in ``cwd``: ``pipeline ...`` through the CLI, a shell line as is."""
    if line.startswith(PIPELINE):
        r = CliRunner().invoke(app, shlex.split(line.removeprefix(PIPELINE)))
        return r.exit_code, r.output
    p = subprocess.run(line, shell=True, cwd=cwd, capture_output=True, text=True, check=False)
    return p.returncode, p.stdout + p.stderr


def test_the_readme_control_lines_run_in_their_order(
    robot3_identified: Path, tmp_path: Path, monkeypatch
) -> None:
    """Before: ``ik --targets poses.arrow`` came before the only line writing poses.arrow
    (``fk --q-file joints.arrow --out poses.arrow``, whose joints.arrow ik wrote)."""
    (block,) = [b for b in sh_lines(ROOT / "README.md") if b[0] == PIPELINE + "--help"]
    at = block.index(PIPELINE + "identify sessions/robot3")
    session = tmp_path / "sessions" / "robot3"
    shutil.copytree(robot3_identified, session)  # what that line writes (no report)
    monkeypatch.chdir(tmp_path)
    ran = []
    for line in block[at + 1 :]:
        words = line.split()
        if line.startswith("printf") or (
            words[1] in ("ik", "fk", "compensate") and "sessions/robot3" in words
        ):
            code, out = _run(line, tmp_path)
            assert code == 0, (line, out)
            ran.append(words[1])
    assert ran.count("ik") == 4 and "fk" in ran and "compensate" in ran, ran
    assert (tmp_path / "joints.arrow").is_file() and (tmp_path / "compensated.arrow").is_file()


def test_the_plan_doc_block_runs_in_its_order(tmp_path: Path, monkeypatch) -> None:
    """Before: it planned for ``ur10.toml`` (no such file) and then wrote that UR10 plan
    over the Puma's plan.csv that ``simulate --plan plan.csv`` records."""
    block = sh_lines(ROOT / "docs" / "plan.md")[0]
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    monkeypatch.chdir(tmp_path)
    for line in block:
        code, out = _run(line, tmp_path)
        assert code == 0, (line, out)
    assert (tmp_path / "sessions" / "planned" / "signature.json").is_file()
    again = _run(block[0], tmp_path)  # a plan is never written over without --force
    assert again[0] == EXIT_REFUSED and "already exists" in again[1]
