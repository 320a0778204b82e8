"""The report's joint figures drawn again on one figure (issue 18): the same PNG bytes as
figures drawn each on a new one."""

from pathlib import Path

import numpy as np
import pytest

from pipeline.report import figures
from pipeline.report.figures import JointResiduals, Panels


def _joints(rng: np.random.Generator) -> list[JointResiduals]:
    q = np.linspace(-90.0, 90.0, 9)
    return [
        JointResiduals(1, "waist", "deg", q, rng.normal(0, 0.01, 9), rng.normal(0, 0.02, 9)),
        JointResiduals(2, "slide", "cm", q / 10, rng.normal(0, 0.05, 9), None),  # prismatic
        JointResiduals(3, "exact", "deg", q, np.full(9, 1e-12), np.zeros(9)),  # one bin
        JointResiduals(4, "one", "deg", q[:1], np.zeros(1), np.zeros(1)),  # no histogram
        JointResiduals(5, "wrist", "deg", q, rng.normal(0, 3.0, 9), rng.normal(5, 1.0, 9)),
    ]


def _draw(joints: list[JointResiduals], d: Path, panels: Panels | None) -> list[bytes]:
    d.mkdir()
    paths = [
        figures.residuals_vs_q(joints, d / "residuals.png", panels),
        figures.residual_histograms(joints, "normal", d / "hist_normal.png", panels),
        figures.residual_histograms(joints, "radial", d / "hist_radial.png", panels),
        figures.residuals_vs_q(joints, d / "again.png", panels),
    ]
    return [p.read_bytes() for p in paths]


def test_reused_panels_draw_the_same_pngs(tmp_path: Path, rng: np.random.Generator) -> None:
    joints = _joints(rng)
    assert _draw(joints, tmp_path / "reused", Panels(len(joints))) == _draw(
        joints, tmp_path / "new", None
    )


def test_panels_of_another_joint_count_are_refused(tmp_path: Path, rng) -> None:
    with pytest.raises(ValueError, match="panels of 2 joints given for 5 joints"):
        figures.residuals_vs_q(_joints(rng), tmp_path / "r.png", Panels(2))
