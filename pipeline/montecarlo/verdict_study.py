"""The ``verdict`` study (issue 41): how often the verdict raises a false alarm on clean
simulated sessions of every kind, and what it says of a session with unmodelled error.

Each session is a whole ``pipeline simulate`` + ``pipeline identify`` run of a Puma 560
(the refine study's runner, :func:`.refine_study.run_session`) of one of :data:`KINDS`,
seeds ``seed .. seed + N − 1`` per kind (``--robots N``), then the audit of its signature
against the truth (:func:`pipeline.rig.audit.table_errors`, 1,000 configurations; the
pipeline never reads the truth). Per session it records what the ``verdict`` stage table
says, read by column name: the level, the rules that fired (``reason_rules`` with their
``reason_levels``, whatever rules the verdict has), the predicted RMS tool error
(``predicted_rms_cm``), the held-out RMS (``holdout_rms_cm``) and χ²/dof, beside the
audited RMS and audited / predicted. The sessions are the unit of work, one task each on
the engine's pool or Dask (:func:`.engine.run_tasks`).

Clean kinds (no error the model lacks, the documented noise): ``sonic`` (the thesis's
sweeps and digitizer), ``tracker_sweeps``, ``pose_set`` (100 poses, no sweeps),
``pose_set_compliance`` and ``sweeps_compliance`` (a 0.3 mm joint compliance, which the
model has). Not clean: ``backlash``, the pose set with 0.3 mm of joint backlash
(:mod:`pipeline.rig.backlash`), which no signature can express.

Cost: ~0.4-0.6 s of CPU per tracker session, ~1.1-2.4 s per sonic one (measured
2026-11-28; docs/montecarlo.md).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from pipeline.montecarlo.engine import run_tasks
from pipeline.montecarlo.refine_study import run_session, session_folders, verdict_row
from pipeline.progress import Progress
from pipeline.rig.audit import table_errors
from pipeline.rig.simulate import SimulationOptions

_TRACKER = SimulationOptions(sensor="tracker")
_POSES = replace(_TRACKER, poses=100, sweeps=False)
#: The kinds of session, each the options of ``pipeline simulate`` (the seed set per session).
KINDS: dict[str, SimulationOptions] = {
    "sonic": SimulationOptions(),
    "tracker_sweeps": _TRACKER,
    "pose_set": _POSES,
    "pose_set_compliance": replace(_POSES, compliance_mm=0.3),
    "sweeps_compliance": replace(_TRACKER, compliance_mm=0.3),
    "backlash": replace(_POSES, backlash_mm=0.3),
}
#: Kinds with error the model does not have: not false alarms when the verdict objects.
UNCLEAN = ("backlash",)
LEVELS = ("PASS", "CHECK", "FAIL")


@dataclass(frozen=True)
class VerdictSession:
    """One identified session: its kind and seed, the verdict table's level, rules (with
    their levels, in the order it gives them), predicted and held-out RMS (cm, NaN when
    absent) and χ²/dof, and the audited RMS tool position error (cm)."""

    kind: str
    seed: int
    verdict: str
    rules: tuple[str, ...]
    levels: tuple[str, ...]
    predicted_rms_cm: float
    holdout_rms_cm: float
    chi2_per_dof: float
    audited_rms_cm: float

    @property
    def audited_over_predicted(self) -> float:
        return self.audited_rms_cm / self.predicted_rms_cm


def _number(value: Any) -> float:
    return math.nan if value is None else float(value)


def _judged(folder: Path, kind: str, seed: int) -> VerdictSession:
    """Identify the session in ``folder`` as ``pipeline identify`` does, read its verdict
    and audit its signature."""
    from pipeline.identify import identify

    identify(folder, report=False)
    row = verdict_row(folder)
    return VerdictSession(
        kind=kind,
        seed=seed,
        verdict=str(row["verdict"]),
        rules=tuple(str(r) for r in row["reason_rules"]),
        levels=tuple(str(v) for v in row["reason_levels"]),
        predicted_rms_cm=_number(row.get("predicted_rms_cm")),
        holdout_rms_cm=_number(row.get("holdout_rms_cm")),
        chi2_per_dof=_number(row.get("chi2_per_dof")),
        audited_rms_cm=table_errors(folder, ("chain",))["chain"].rms_position_cm,
    )


def verdict_session(kind: str, opts: SimulationOptions) -> VerdictSession:
    """Simulate, identify, judge and audit one session of ``kind`` (its options ``opts``,
    seed included) in a temporary folder: the study's unit of work."""
    with session_folders() as tmp:
        judged = partial(_judged, kind=kind, seed=opts.seed)
        return run_session(tmp / "session", opts, judged, "verdict")


@dataclass(frozen=True)
class KindSummary:
    """The sessions of one kind: counts per level, how many sessions each (rule, level)
    fired in (most first), the 5th, 50th and 95th percentiles of audited / predicted and
    the medians of the predicted and the audited RMS (cm)."""

    kind: str
    sessions: int
    counts: dict[str, int]
    rules: tuple[tuple[str, str, int], ...]
    ratio_percentiles: tuple[float, float, float]
    predicted_median_cm: float
    audited_median_cm: float

    @property
    def clean(self) -> bool:
        return self.kind not in UNCLEAN

    def rate(self, level: str) -> float:
        return self.counts[level] / self.sessions


def summarize_kind(kind: str, sessions: list[VerdictSession]) -> KindSummary:
    """The summary of ``sessions`` (all of ``kind``, at least one)."""
    counts = {level: sum(s.verdict == level for s in sessions) for level in LEVELS}
    fired: dict[tuple[str, str], int] = {}
    for s in sessions:
        for key in set(zip(s.rules, s.levels, strict=True)):  # a session counts once
            fired[key] = fired.get(key, 0) + 1
    rules = tuple((r, lv, c) for (r, lv), c in sorted(fired.items(), key=lambda kv: -kv[1]))
    ratio = np.array([s.audited_over_predicted for s in sessions])
    finite = ratio[np.isfinite(ratio)]
    pct = np.percentile(finite, [5, 50, 95]) if len(finite) else np.full(3, np.nan)
    predicted = np.array([s.predicted_rms_cm for s in sessions])
    return KindSummary(
        kind, len(sessions), counts, rules, (float(pct[0]), float(pct[1]), float(pct[2])),
        float(np.nanmedian(predicted)) if np.isfinite(predicted).any() else math.nan,
        float(np.median([s.audited_rms_cm for s in sessions])),
    )  # fmt: skip


@dataclass(frozen=True)
class VerdictResult:
    """Every session of a run (kind by kind, seeds ascending), the kinds' options, the
    first seed and the wall time (s)."""

    sessions: list[VerdictSession]
    kinds: dict[str, SimulationOptions]
    seed: int
    wall_s: float

    @property
    def per_kind(self) -> int:
        return len(self.sessions) // max(len(self.kinds), 1)

    def summaries(self) -> list[KindSummary]:
        return [summarize_kind(k, [s for s in self.sessions if s.kind == k]) for k in self.kinds]


def run_verdict(
    sessions: int,
    seed: int = 0,
    workers: int = 1,
    progress: TextIO | None = sys.stderr,
    client: Any = None,
    kinds: dict[str, SimulationOptions] | None = None,
) -> VerdictResult:
    """``sessions`` sessions of each of ``kinds`` (default :data:`KINDS`; tests pass
    smaller plans), seeds ``seed`` to ``seed + sessions − 1``, on ``workers`` processes or
    the Dask ``client``."""
    kinds = KINDS if kinds is None else kinds
    tasks = [(k, replace(o, seed=seed + i)) for k, o in kinds.items() for i in range(sessions)]
    bar = Progress("verdict", len(tasks), progress, unit="sessions")
    t0 = time.perf_counter()
    done = run_tasks(verdict_session, tasks, workers, bar, client)
    return VerdictResult(done, dict(kinds), seed, time.perf_counter() - t0)
