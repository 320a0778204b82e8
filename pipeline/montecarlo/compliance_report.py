"""Figures and the ``montecarlo.md`` section of the ``compliance`` study (issue 27).

``OUT/compliance/fits.png``         audited RMS with the terms against the rigid fit's, per
                                    robot and true compliance, with y = x
``OUT/compliance/calibration.png``  audited against predicted RMS of both fits on the
                                    compliant robots, with y = x

The table gives per true compliance the medians a reader compares: the audited RMS of
both fits and their ratio, the fraction of robots the terms improve, audited / predicted,
χ²/dof and the PASS fraction of each fit. Figure helpers and the reader of the indices
are the refine study's (:mod:`.refine_report`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.kinematics.transforms import Array
from pipeline.montecarlo.compliance_study import INDEX_NAMES
from pipeline.montecarlo.engine import StudyResult
from pipeline.montecarlo.refine_report import column, per_robot, scatter_figure
from pipeline.montecarlo.refine_study import VERDICT_CODES

HEADING = "## Joint compliance: rigid fit against the fit with its terms (issue 27)"
FIGURES = (
    ("fits.png", "audited RMS with the compliance terms against the rigid fit (y = x)"),
    ("calibration.png", "audited against predicted RMS of both fits, compliant robots (y = x)"),
)
FIT_LABELS = (("rigid", "rigid"), ("terms", "with terms"))


def _col(values: Array, name: str) -> Array:
    return column(values, name, INDEX_NAMES)


def write_figures(res: StudyResult, folder: Path) -> None:
    """The two figures of the study under ``folder``."""
    mm, v, robots = res.study.values, res.values, res.values.shape[1]
    rigid, terms = _col(v, "rigid_rms_cm"), _col(v, "terms_rms_cm")
    labels = (
        "audited RMS, rigid fit (cm)",
        "audited RMS, fit with compliance (cm)",
        f"compliance: two fits of one recording, {robots} robots",
    )
    series = [(rigid[i], terms[i], f"compliance {c:g} mm") for i, c in enumerate(mm)]
    scatter_figure(folder / "fits.png", series, labels, left=0.18)

    top = int(np.argmax(mm))
    labels = (
        "predicted RMS (cm)",
        "audited RMS (cm)",
        f"uncertainty calibration at {mm[top]:g} mm, {robots} robots",
    )
    series = [
        (_col(v, f"{fit}_predicted_rms_cm")[top], _col(v, f"{fit}_rms_cm")[top], label)
        for fit, label in FIT_LABELS
    ]
    scatter_figure(folder / "calibration.png", series, labels, left=0.18)


def _row(c: float, v: Array) -> str:
    """The table's row of one setting; ``v`` (robots, K)."""

    def med(name: str) -> float:
        return float(np.median(_col(v, name)))

    rigid, terms = _col(v, "rigid_rms_cm"), _col(v, "terms_rms_cm")
    cells = [f"{c:g}", f"{med('rigid_rms_cm'):.4f}", f"{med('terms_rms_cm'):.4f}"]
    cells += [f"{med('ratio'):.2f}", f"{np.mean(terms < rigid):.0%}"]
    for fit, _ in FIT_LABELS:
        aud, pred = _col(v, f"{fit}_rms_cm"), _col(v, f"{fit}_predicted_rms_cm")
        cells.append(f"{np.median(aud / pred):.2f}")
    cells += [f"{med(f'{fit}_chi2_per_dof'):.3f}" for fit, _ in FIT_LABELS]
    cells += [
        f"{np.mean(_col(v, f'{fit}_verdict') == VERDICT_CODES['PASS']):.0%}"
        for fit, _ in FIT_LABELS
    ]
    return "| " + " | ".join(cells) + " |"


def section(out: Path, wall_s: float) -> list[str]:
    """The study's section of ``montecarlo.md`` (figures, table, how to rerun a robot)."""
    folder = out / "compliance"
    x, v = per_robot(folder / "indices.arrow", "compliance_mm", INDEX_NAMES)
    robots = v.shape[1]
    figures = [
        f"![compliance: {caption}](compliance/{name})"
        for name, caption in FIGURES
        if (folder / name).is_file()
    ]
    seeds = _col(v, "simulate_seed")[0]
    return [
        f"### compliance ({robots} robots, {wall_s:.1f} s)",
        "",
        "Robots of the `refine` study (Puma 560 joint sweeps, (7.9) at k = 1) whose true",
        "joints deflect under gravity by the compliance (RMS flange displacement over the",
        "joint ranges); each recording identified twice, `refine.nongeometric=none` (rigid)",
        "and `=compliance` (with the terms), each audited against the truth, its terms",
        "included, over 1,000 random configurations. The same robots and deviates at",
        "every compliance.",
        "",
        *figures,
        "",
        "| compliance (mm) | median rigid RMS (cm) | median with-terms RMS (cm) "
        "| median rigid / with terms | with terms < rigid "
        "| median audited / predicted, rigid | with terms | median χ²/dof, rigid "
        "| with terms | PASS, rigid | with terms |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        *(_row(float(c), v[i]) for i, c in enumerate(x)),
        "",
        "A robot's session at compliance C is re-recorded by `pipeline simulate NAME",
        f"--seed N --compliance C` (N: its `simulate_seed` index; robot 0: {int(seeds[0])})",
        "and identified by `pipeline identify sessions/NAME --param",
        "refine.nongeometric=none` (or `=compliance`).",
        "",
    ]
