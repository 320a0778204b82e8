"""The ``verdict`` Monte-Carlo study (issue 41): the verdict of whole simulated sessions of
every kind, its rules by name, the audited against the predicted accuracy.

Small plans for speed (tests only): every kind's options with N_i = 12 points and N_avg = 5
cycles (the pose sets keep their 100 poses), one session per kind; the registered kinds use
the default plan.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from pipeline.montecarlo import report, verdict_report
from pipeline.montecarlo.refine_study import simulate_command
from pipeline.montecarlo.studies import LATER, STUDY_NAMES, StudyRun
from pipeline.montecarlo.verdict_study import (
    KINDS,
    LEVELS,
    VerdictResult,
    VerdictSession,
    run_verdict,
    summarize_kind,
)

SMALL = {k: replace(o, points=12, repeats=5) for k, o in KINDS.items()}


@pytest.fixture(scope="module")
def small() -> VerdictResult:
    return run_verdict(1, seed=0, progress=None, kinds=SMALL)


def test_one_session_per_kind_with_the_verdict_tables_numbers(small: VerdictResult) -> None:
    assert [s.kind for s in small.sessions] == list(KINDS)
    assert [s.seed for s in small.sessions] == [0] * len(KINDS)
    for s in small.sessions:
        assert s.verdict in LEVELS and len(s.rules) == len(s.levels)
        assert (s.verdict == "PASS") == (not s.rules)  # PASS: no rule fired
        if s.rules:  # the verdict is its worst reason's level
            assert s.verdict == max(s.levels, key=LEVELS.index)
        assert s.predicted_rms_cm > 0 and s.holdout_rms_cm > 0 and s.audited_rms_cm > 0
        assert s.audited_over_predicted == s.audited_rms_cm / s.predicted_rms_cm
    by_kind = {s.kind: s for s in small.sessions}
    # the backlash is what the fit cannot express: the same pose set without it audits
    # several times better (seed 0: 0.013 against 0.001 cm)
    assert by_kind["backlash"].audited_rms_cm > 3.0 * by_kind["pose_set"].audited_rms_cm


def test_rules_are_counted_by_name_once_per_session() -> None:
    """Whatever rules the verdict stage has: names the study never heard of are counted."""

    def session(verdict: str, rules: tuple[str, ...], levels: tuple[str, ...]) -> VerdictSession:
        return VerdictSession("k", 0, verdict, rules, levels, 0.1, 0.1, 1.0, 0.2)

    sessions = [
        session("PASS", (), ()),
        session("CHECK", ("new_rule", "new_rule"), ("CHECK", "CHECK")),  # two microphones
        session("FAIL", ("new_rule", "other"), ("CHECK", "FAIL")),
    ]
    k = summarize_kind("k", sessions)
    assert k.counts == {"PASS": 1, "CHECK": 1, "FAIL": 1} and k.rate("PASS") == 1 / 3
    assert k.rules == (("new_rule", "CHECK", 2), ("other", "FAIL", 1))
    assert k.ratio_percentiles == (2.0, 2.0, 2.0)


def test_seeds_run_on_from_the_study_seed_the_same_in_worker_processes() -> None:
    kinds = {"pose_set": SMALL["pose_set"]}
    here = run_verdict(2, seed=5, progress=None, kinds=kinds)
    assert [s.seed for s in here.sessions] == [5, 6]
    pool = run_verdict(2, seed=5, workers=2, progress=None, kinds=kinds)
    assert pool.sessions == here.sessions


def test_tables_figure_and_report(small: VerdictResult, tmp_path: Path) -> None:
    d = verdict_report.write_tables(tmp_path, small)
    for f in ("sessions.arrow", "summary.arrow", "rules.arrow", "ratio.png"):
        assert (d / f).is_file(), f
    sessions = pl.read_ipc(d / "sessions.arrow")
    assert sessions["kind"].to_list() == list(KINDS)
    assert sessions["reason_rules"].to_list() == [list(s.rules) for s in small.sessions]
    summary = pl.read_ipc(d / "summary.arrow")
    assert (summary["pass"] + summary["check"] + summary["fail"] == summary["sessions"]).all()
    assert summary.filter(pl.col("kind") == "backlash")["clean"].to_list() == [False]
    ratio = np.array([s.audited_over_predicted for s in small.sessions])
    np.testing.assert_array_equal(summary["ratio_median"].to_numpy(), ratio)  # one each

    text = report.write_report(tmp_path).read_text()
    assert "## False alarms of the verdict on clean sessions (issue 41)" in text
    assert "| verdict | 1 | 6 |" in text  # the wall-time table: sessions per kind, kinds
    assert re.findall(r"!\[[^\]]*\]\((verdict/[^)]+)\)", text) == ["verdict/ratio.png"]
    assert "| backlash (not clean) | 1 |" in text
    for s in small.sessions:
        row = next(ln for ln in text.splitlines() if ln.startswith(f"| {s.kind}"))
        assert f"| {s.audited_over_predicted:.2f} |" in row
        for rule in s.rules:
            assert rule in row
    assert f"`{simulate_command(replace(SMALL['backlash'], seed=0))}`" in text

    run = StudyRun("verdict", d, small.wall_s, 1, small)
    assert run.line.startswith("verdict: 1 sessions x 6 kinds")
    kinds = run.to_dict()["kinds"]
    assert [k["kind"] for k in kinds] == list(KINDS)
    assert [sum(k["counts"].values()) for k in kinds] == [1] * len(KINDS)


def test_the_kinds_re_record_commands() -> None:
    assert simulate_command(replace(KINDS["backlash"], seed=3)) == (
        "pipeline simulate NAME --seed 3 --noise-factor 1 --points 100 --repeats 10 "
        "--sensor tracker --poses 100 --no-sweeps --backlash-mm 0.3"
    )
    assert simulate_command(replace(KINDS["sonic"], seed=3)).endswith("--repeats 10")


def test_verdict_runs_last_in_all() -> None:
    assert LATER[-1] == "verdict" and STUDY_NAMES[-2:] == ("verdict", "all")
