"""Documented numbers against the code's output (issue 30, item 8). A change that moves
them must come with the documents refreshed (each failure shows what the code gives now):

- the evaluation table of docs/evaluation.md ("Measured") and the README's evaluation line:
  what `pipeline evaluate` prints for the committed sessions robot1-7;
- docs/verdict.md's example line: `identify` of the committed robot3 recording;
- docs/export.md's (and the README's) D-H numbers of robot3: its pseudo D-H (stage `dh`)
  and the exported D-H table (`pipeline export --format dh`);
- docs/refine.md's rows robot1-7 (what `python -m bench.accuracy` prints for them) and
  docs/compensate.md's audited robot3 RMS.

The committed sessions are copied (recording, evaluation, rig truth) and identified once
per module; robot3's copy serves every robot3 check.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import pytest
from doc_quotes import assert_quoted

from pipeline.evaluate import evaluate
from pipeline.export import export
from pipeline.identify import IdentifyResult, identify
from pipeline.montecarlo.refine_study import session_accuracy
from pipeline.stages.tables import read_table

ROOT = Path(__file__).resolve().parent.parent
TASKS = ("lines1d", "grid2d", "grid3d", "grid12")
VERTICES = ("1", "4", "5", "8")


def _committed(k: int, parent: Path) -> Path:
    """A copy of what git holds of session robot``k``, in ``parent/robot{k}``."""
    d = parent / f"robot{k}"
    d.mkdir()
    for name in ("recording.mcap", "evaluation.mcap", "rig-truth.json"):
        shutil.copy(ROOT / "sessions" / f"robot{k}" / name, d)
    return d


@pytest.fixture(scope="module")
def robot3(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, IdentifyResult]:
    """The committed robot3 session, copied and identified (no report)."""
    d = _committed(3, tmp_path_factory.mktemp("docs"))
    return d, identify(d, report=False)


@pytest.fixture(scope="module")
def committed(
    tmp_path_factory: pytest.TempPathFactory, robot3: tuple[Path, IdentifyResult]
) -> dict[int, Path]:
    """Every committed session, copied and identified (no report), by robot number."""
    out = {}
    for k in range(1, 8):
        if k == 3:
            out[k] = robot3[0]
            continue
        out[k] = _committed(k, tmp_path_factory.mktemp("docs"))
        identify(out[k], report=False)
    return out


@pytest.fixture(scope="module")
def summaries(committed: dict[int, Path]) -> dict[int, dict[str, Any]]:
    """`evaluate` of each committed session, by robot number."""
    return {k: evaluate(d, report=False).summary for k, d in committed.items()}


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


def test_verdict_example_is_the_codes(robot3: tuple[Path, IdentifyResult]) -> None:
    verdict = robot3[1].verdict
    lines = (ROOT / "docs" / "verdict.md").read_text().splitlines()
    line = next(x for x in lines if x.startswith("robot3: "))
    assert line == verdict, f"docs/verdict.md's example line is now:\n{verdict}"


def _cm(value: float, sign: bool = False) -> str:
    """A length as the docs write it: whole cm, thousands separated, a true minus sign."""
    return f"{value:{'+' if sign else ''},.0f}".replace("-", "\u2212")


def test_pseudo_dh_of_robot3_is_the_codes(robot3: tuple[Path, IdentifyResult]) -> None:
    d = read_table(robot3[0] / "stages" / "dh.arrow").to_pydict()["d_cm"]
    assert_quoted(
        "docs/export.md", f"robot3 has `d2 = {_cm(d[1])} cm` and `d3 = {_cm(d[2], True)} cm`"
    )
    assert_quoted("docs/export.md", f"(the pseudo D-H: {_cm(max(map(abs, d)))} cm)")


def test_exported_dh_of_robot3_is_the_codes(
    robot3: tuple[Path, IdentifyResult], tmp_path: Path
) -> None:
    r = export(robot3[0], "dh", out=tmp_path / "r.dh.json")
    rows = json.loads(Path(r.path).read_text())["rows"]
    largest = f"{max(abs(row['d_cm']) for row in rows):.1f}"
    assert_quoted("docs/export.md", f"Robot3: largest `|d|` is {largest} cm")
    assert_quoted("README.md", f"robot3 D-H with Hayati's β, largest \\|d\\| {largest} cm")
    # docs/export.md: "the table reproduces the signature to within 1e-14 m"
    assert r.max_position_error_m < 1e-14, r.max_position_error_m


def test_refine_table_rows_are_the_codes(committed: dict[int, Path]) -> None:
    """docs/refine.md's "Numbers" table, robot1-7: the row `bench.accuracy` prints (the
    audit of the thesis S-Model and of the refined chain, 1,000 configurations)."""
    for k, d in committed.items():
        a = session_accuracy(d)
        thesis, refined = a.smodel.rms_position_cm, a.refined.rms_position_cm
        cells = (f"{thesis:.5f}", f"{refined:.5f}", f"{thesis / refined:.2f}")
        cells += (f"{a.predicted_rms_cm:.5f}", f"{a.crb_cm:.5f}", f"{a.chi2_per_dof:.2f}")
        assert_quoted("docs/refine.md", f"| robot{k} | " + " | ".join(cells) + f" | {a.verdict} |")
        if k == 3:  # the same audit, docs/compensate.md's last paragraph
            assert_quoted("docs/compensate.md", f"(robot3 RMS {refined:.4f} cm,")
