"""The studies of Chapter 7 and the ``pipeline montecarlo`` entry point.

=============  ==========================================  ======================
study          swept parameter                              controller
=============  ==========================================  ======================
encoder        σ_e = 0.1 … 0.5° (σ_p = .01 cm, σ_o = .01°)  design model (7.4.1)
machining      σ_p = σ_o = 0.01 … 0.05 (σ_e = 0.1°)         design model (7.4.2)
noise          k = 1, 2.8, 4.6, 6.4, 8.2, 10 times (7.9)    signature (7.4.3)
points         N_i = 20, 40, 60, 80, 100                    signature (7.4.4)
radius         R_nom = 30, 35, 40, 45, 50 cm                signature (7.4.5)
misalignment   W_AC error −1 … +1 cm (11 values)            signature (7.3)
features       sweep X, N, noise (Section 6.6)              feature fits only
refine         k = 1, 4.6, 10 times (7.9)                   audit: S-Model, refined
compliance     true compliance 0, 0.3 mm                    audit: rigid, with terms
verdict        kind of session (6 kinds)                    verdict; audit
=============  ==========================================  ======================

``refine`` (issue 15) runs whole ``pipeline simulate`` + ``identify`` sessions, seconds of
CPU per robot and setting (the thesis studies: ~0.02 s; measured in docs/montecarlo.md);
``compliance`` (issue 27) two such sessions per robot, each identified twice; ``verdict``
(issue 41) one session per kind and seed, counting the verdict's false alarms (not a swept
study of the engine: its records are rules by name); ``--study all`` runs them last.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from pipeline.atomic import check_writable
from pipeline.errors import ArmsigError
from pipeline.evaluation.grid12 import INDEX_NAMES, INDEX_SIGNED, INDEX_UNITS
from pipeline.montecarlo import design
from pipeline.montecarlo.engine import Evaluate, Study, run_study


def _grid_study(
    name: str,
    title: str,
    parameter: str,
    unit: str,
    values: tuple[float, ...],
    evaluate: Evaluate,
    batch: int = 500,
) -> Study:
    """A study scored by the 34 indices of the 12-vertex grid."""
    return Study(
        name, title, parameter, unit, values, evaluate, INDEX_NAMES, INDEX_UNITS, INDEX_SIGNED,
        batch=batch,
    )  # fmt: skip


def _registry() -> dict[str, Study]:
    from pipeline.montecarlo import compliance_study, control, refine_study

    return {
        "encoder": _grid_study(
            "encoder",
            "encoder calibration error std σ_e (deg)",
            "sigma_e_deg",
            "deg",
            (0.1, 0.2, 0.3, 0.4, 0.5),
            design.encoder_setting,
        ),
        "machining": _grid_study(
            "machining",
            "machining error std σ_p = σ_o (cm, deg)",
            "sigma_po",
            "",
            (0.01, 0.02, 0.03, 0.04, 0.05),
            design.machining_setting,
        ),
        "noise": _grid_study(
            "noise",
            "slant-range noise factor k (times (7.9))",
            "noise_factor",
            "",
            (1.0, 2.8, 4.6, 6.4, 8.2, 10.0),
            control.noise_setting,
            batch=control.BATCH,
        ),
        "points": _grid_study(
            "points",
            "points per circle N_i",
            "points",
            "",
            (20.0, 40.0, 60.0, 80.0, 100.0),
            control.points_setting,
            batch=control.BATCH,
        ),
        "radius": _grid_study(
            "radius",
            "target radius R_nom (cm)",
            "radius_cm",
            "cm",
            (30.0, 35.0, 40.0, 45.0, 50.0),
            control.radius_setting,
            batch=control.BATCH,
        ),
        "misalignment": Study(
            "misalignment",
            "W_AC calibration error (cm)",
            "wac_error_cm",
            "cm",
            tuple(round(-1.0 + 0.2 * k, 1) for k in range(11)),
            control.misalignment_setting,
            index_names=control.LINE3_NAMES,
            index_units=("cm",) * 3,
            index_signed=(True,) * 3,
            batch=control.BATCH,
            evaluate_all=control.misalignment_all,
        ),
        "refine": Study(
            "refine",
            "slant-range noise factor k (times (7.9))",
            "noise_factor",
            "",
            refine_study.NOISE_FACTORS,
            refine_study.refine_setting,
            index_names=refine_study.INDEX_NAMES,
            index_units=refine_study.INDEX_UNITS,
            index_signed=refine_study.INDEX_SIGNED,
            batch=refine_study.BATCH,
            evaluate_all=refine_study.refine_all,
        ),
        "compliance": Study(
            "compliance",
            "true joint compliance: RMS flange displacement (mm)",
            "compliance_mm",
            "mm",
            compliance_study.COMPLIANCE_MM,
            compliance_study.compliance_setting,
            index_names=compliance_study.INDEX_NAMES,
            index_units=compliance_study.INDEX_UNITS,
            index_signed=compliance_study.INDEX_SIGNED,
            batch=compliance_study.BATCH,
            evaluate_all=compliance_study.compliance_all,
        ),
    }


#: The thesis's swept studies in the order ``--study all`` runs them (then ``features``).
SWEPT = ("encoder", "machining", "noise", "points", "radius", "misalignment")
#: Studies of issues after the thesis, run by ``--study all`` after the thesis's.
LATER = ("refine", "compliance", "verdict")
STUDY_NAMES = (*SWEPT, "features", *LATER, "all")


def get_study(name: str) -> Study:
    """The registered swept study ``name``."""
    reg = _registry()
    if name not in reg:
        raise ArmsigError(f"unknown study {name!r}", expected=", ".join(STUDY_NAMES))
    return reg[name]


@dataclass(frozen=True)
class StudyRun:
    """One study of a ``montecarlo`` run: where its tables went and, for a swept study,
    its settings and the mean and std of every index over the robots (settings × indices);
    for the verdict study, each kind's verdict counts, rules and audited / predicted."""

    name: str
    folder: Path
    wall_s: float
    robots: int  # robots per setting; features: trials per configuration; verdict: sessions
    result: Any  # StudyResult, or the features or verdict study's result

    @property
    def line(self) -> str:
        if self.name == "features":
            return f"features: 36 configurations, {self.wall_s:.1f} s"
        if self.name == "verdict":
            kinds = len(self.result.kinds)
            return f"verdict: {self.robots} sessions x {kinds} kinds, {self.wall_s:.1f} s"
        settings = len(self.result.study.values)
        return f"{self.name}: {self.robots} robots x {settings} settings, {self.wall_s:.1f} s"

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"study": self.name, "folder": str(self.folder),
                               "wall_s": self.wall_s}  # fmt: skip
        if self.name == "features":
            r = self.result
            return {**out, "trials": r.trials, "radius_cm": r.radius_cm,
                    "fit_6_12": list(r.fit_612), "fit_6_13": list(r.fit_613)}  # fmt: skip
        if self.name == "verdict":
            kinds = [
                {"kind": k.kind, "clean": k.clean, "sessions": k.sessions, "counts": k.counts,
                 "rules": [{"rule": r, "level": lv, "sessions": c} for r, lv, c in k.rules],
                 "audited_over_predicted_p05_p50_p95": list(k.ratio_percentiles)}
                for k in self.result.summaries()
            ]  # fmt: skip
            return {**out, "sessions": self.robots, "seed": self.result.seed, "kinds": kinds}
        st, summary = self.result.study, self.result.summary
        return {
            **out,
            "robots": self.robots,
            "seed": self.result.seed,
            "parameter": st.parameter,
            "settings": list(st.values),
            "indices": list(st.index_names),
            "index_units": list(st.index_units),
            "mean": summary.mean.tolist(),
            "std": summary.std.tolist(),
        }


@dataclass(frozen=True)
class MonteCarloRun:
    """What ``pipeline montecarlo`` did: its studies in the order run, and the report."""

    studies: list[StudyRun]
    report: Path

    @property
    def lines(self) -> list[str]:
        """One line per study with its wall time, then the report's path."""
        return [*(s.line for s in self.studies), f"wrote {self.report}"]

    def to_dict(self) -> dict[str, Any]:
        return {"studies": [s.to_dict() for s in self.studies], "report": str(self.report)}


def run_montecarlo(
    study: str,
    robots: int = 500,
    seed: int = 0,
    out: str | Path = "montecarlo",
    workers: int = 1,
    progress: TextIO | None = sys.stderr,
    client: Any = None,
) -> MonteCarloRun:
    """Run ``study`` (or ``all``), write tables, figures and ``montecarlo.md`` under ``out``
    (``client``: a Dask client to run the batches on instead of ``workers`` processes)."""
    from pipeline.montecarlo import features_study, output, report, verdict_report, verdict_study

    if study not in STUDY_NAMES:
        raise ArmsigError(f"unknown study {study!r}", expected=", ".join(STUDY_NAMES))
    if robots < 2:
        raise ArmsigError("too few robots", expected="--robots >= 2", got=str(robots))
    names = [*SWEPT, "features", *LATER] if study == "all" else [study]
    out_dir = check_writable(out, "--out", folder=True)  # before hours of computing
    done = []
    for name in names:
        if name == "features":
            feat = features_study.run_features(seed=seed, progress=progress)
            folder = output.write_features(out_dir, feat)
            done.append(StudyRun(name, folder, feat.wall_s, feat.trials, feat))
            continue
        if name == "verdict":
            ver = verdict_study.run_verdict(robots, seed, workers, progress, client=client)
            folder = verdict_report.write_tables(out_dir, ver)
            done.append(StudyRun(name, folder, ver.wall_s, robots, ver))
            continue
        res = run_study(get_study(name), robots, seed, workers, progress, client=client)
        done.append(StudyRun(name, output.write_study(out_dir, res), res.wall_s, robots, res))
    return MonteCarloRun(done, report.write_report(out_dir))
