"""Plausibility in the verdict (issue 32, item 5): an identified geometry implausibly far
from the design (mm declared as m, x and y swapped) is FAIL with that reason, however well
it fits its own data. Thresholds and the measurements behind them: docs/verdict.md."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from import_data import TABLE, TWO_LINK, TWO_LINK_MAP, sscanss2_text, two_link_table
from test_refine_verdict import GOOD

from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.refine.verdict import FAIL, PASS, judge
from pipeline.robots.description import load_description
from pipeline.stages.tables import read_table

#: SScanSS-2's positioning table (P R P P), each joint swept alone (deg / mm).
TABLE_VALUES = [[0, 100, 200, 300, 400, 500], [-180, -108, -36, 36, 108, 180],
                [-200, -120, -40, 40, 120, 200], [-200, -120, -40, 40, 120, 200]]  # fmt: skip
#: TWO_LINK_MAP with its first target only (the tool sweep plans one target).
ONE_TARGET_MAP = TWO_LINK_MAP.replace('[[targets]]\nid = "b"\nx = "x2"\ny = "y2"\nz = "z2"\n', "")


def _verdict(session: Path) -> dict[str, object]:
    identify(session, report=False)
    return read_table(session / "stages" / "verdict.arrow").to_pylist()[0]  # type: ignore[no-any-return]


def test_reach_is_the_sum_of_the_designs_lengths() -> None:
    assert load_description(TWO_LINK).reach_cm == pytest.approx(0.2)  # two links of 1 mm
    # P R P P: the travels (50, 20, 20 cm) and the D-H lengths
    assert load_description(TABLE).reach_cm > 90.0


def test_misfit_rule_on_evidence() -> None:
    near = dataclasses.replace(GOOD, design_misfit_cm=0.44, reach_cm=176.6)  # robot4
    assert judge(near).level == PASS
    far = dataclasses.replace(GOOD, design_misfit_cm=39.5, reach_cm=125.4)
    v = judge(far)
    assert v.level == FAIL and len(v.reasons) == 1
    assert v.findings[0].rule == "max_design_misfit" and v.findings[0].threshold == 0.05
    assert "39.5 cm RMS" in v.reasons[0] and "0.315× the design's reach of 125.4 cm" in v.reasons[0]


def test_x_and_y_swapped_fail(tmp_path: Path) -> None:
    """The table's x and y columns swapped: a mirror image, which the chain fits exactly
    (PASS, "4.2e3× the design model" before) and 39.5 cm from the design."""
    rows = []
    for line in sscanss2_text(TABLE, TABLE_VALUES, digits=15).splitlines():
        c = line.split("\t")
        c[1], c[2] = c[2], c[1]
        rows.append("\t".join(c))
    src = tmp_path / "swapped.txt"
    src.write_text("\n".join(rows) + "\n")
    import_file(src, "sscanss2", TABLE, tmp_path / "s")
    v = _verdict(tmp_path / "s")
    assert v["verdict"] == FAIL and "max_design_misfit" in v["reason_rules"], v["reasons"]
    assert "x and y swapped" in v["reasons"][0]  # the first reason names the likely cause


def test_mm_declared_as_m_fails(tmp_path: Path) -> None:
    src = two_link_table(tmp_path / "two.csv")
    ok, wrong = tmp_path / "ok.toml", tmp_path / "m.toml"
    ok.write_text(ONE_TARGET_MAP)
    wrong.write_text(ONE_TARGET_MAP.replace('length_unit = "mm"', 'length_unit = "m"'))
    import_file(src, "table", TWO_LINK, tmp_path / "ok", ok)
    assert _verdict(tmp_path / "ok")["verdict"] == PASS
    import_file(src, "table", TWO_LINK, tmp_path / "m", wrong)
    v = _verdict(tmp_path / "m")
    assert v["verdict"] == FAIL and v["reason_rules"] == ["max_design_misfit"], v["reasons"]
    assert v["design_reach_cm"] == pytest.approx(0.2)
