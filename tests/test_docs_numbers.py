"""Documented numbers against the code's output (issue 30, item 8): the evaluation table of
docs/evaluation.md ("Measured") and the README's evaluation line are what `pipeline
evaluate` prints for the committed sessions robot1-7. A change that moves them must come
with the documents refreshed (the failure shows the row the code gives now)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

import pytest

from pipeline.evaluate import evaluate

ROOT = Path(__file__).resolve().parent.parent
TASKS = ("lines1d", "grid2d", "grid3d", "grid12")
VERTICES = ("1", "4", "5", "8")


@pytest.fixture(scope="module")
def summaries(tmp_path_factory: pytest.TempPathFactory) -> dict[int, dict[str, Any]]:
    """`evaluate` of each committed session (a copy of what git holds), by robot number."""
    out = {}
    for k in range(1, 8):
        d = tmp_path_factory.mktemp("docs") / f"robot{k}"
        d.mkdir()
        for name in ("recording.mcap", "evaluation.mcap", "rig-truth.json"):
            shutil.copy(ROOT / "sessions" / f"robot{k}" / name, d)
        out[k] = evaluate(d, report=False).summary
    return out


def _row(summary: dict[str, Any], k: int) -> str:
    medians = " | ".join(f"{summary['tasks'][t]['median_improvement']:.2f}" for t in TASKS)
    radial = summary["grid12_signature_radial_cm"]
    return f"| {k} | {medians} | " + ", ".join(f"{radial[v]:.4f}" for v in VERTICES) + " |"


def test_evaluation_table_is_the_codes(summaries: dict[int, dict[str, Any]]) -> None:
    text = (ROOT / "docs" / "evaluation.md").read_text()
    table = text[text.index("## Measured (robot1") :]
    for k, s in summaries.items():
        assert _row(s, k) in table, f"docs/evaluation.md row {k} is now: {_row(s, k)}"


def test_readme_evaluation_line_is_the_codes(summaries: dict[int, dict[str, Any]]) -> None:
    grid12 = [s["tasks"]["grid12"]["median_improvement"] for s in summaries.values()]
    radial = max(max(s["grid12_signature_radial_cm"].values()) for s in summaries.values())
    line = next(
        x for x in (ROOT / "README.md").read_text().splitlines() if "`pipeline evaluate` |" in x
    )
    m = re.search(
        r"over the 34 indices ([\d.]+)-([\d.]+), signature radial errors <= ([\d.]+) cm", line
    )
    assert m, line
    assert (m[1], m[2]) == (f"{min(grid12):.1f}", f"{max(grid12):.1f}")
    assert m[3] == f"{radial:.4f}"
