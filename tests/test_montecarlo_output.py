"""Monte-Carlo outputs are first-class (issue 16): tables carry schema name and version
and the package version like the stage tables; montecarlo.md embeds its figures with
relative links and has no empty heading after a run of one kind of study."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pipeline import __version__
from pipeline.cli import app
from pipeline.stages.tables import read_provenance, read_table


@pytest.fixture(scope="module")
def machining(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A design-only run (the machining study, 4 robots)."""
    out = tmp_path_factory.mktemp("mc") / "mc"
    cmd = ["montecarlo", "--study", "machining", "--robots", "4", "--out", str(out)]
    r = CliRunner().invoke(app, cmd)
    assert r.exit_code == 0, r.output
    return out


@pytest.mark.parametrize(
    ("table", "schema"),
    [("indices.arrow", "montecarlo_indices"), ("summary.arrow", "montecarlo_summary")],
)
def test_tables_carry_schema_and_package_version(machining: Path, table: str, schema: str) -> None:
    path = machining / "machining" / table
    meta = read_table(path).schema.metadata
    assert meta[b"schema_name"] == schema.encode() and meta[b"schema_version"] == b"1"
    assert read_provenance(path)["package_version"] == __version__


def test_report_embeds_its_figures(machining: Path) -> None:
    text = (machining / "montecarlo.md").read_text()
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    figures = ("radial_std.png", "std_grid.png", "mean_grid.png")
    assert set(links) == {f"machining/{f}" for f in figures}
    assert all((machining / link).is_file() for link in links)  # relative to the report


def test_design_only_run_leaves_no_empty_heading(machining: Path) -> None:
    lines = (machining / "montecarlo.md").read_text().splitlines()
    heads = [k for k, ln in enumerate(lines) if ln.startswith("#")]
    for a, b in zip(heads, [*heads[1:], len(lines)], strict=True):
        below = [ln for ln in lines[a + 1 : b] if ln.strip()]
        deeper = b < len(lines) and lines[b].count("#") > lines[a].count("#")
        assert below or deeper, f"empty heading {lines[a]!r}"
    assert not any(ln.startswith("## Signature control") for ln in lines)
