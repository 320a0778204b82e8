"""Seeded mutations of import inputs and faults around the outputs (issue 32, item 8):
refused in one line or accepted, never a traceback, exit 70, a hang, a destroyed file or
a stale or silently changed signature. ``make fuzz-import`` runs the acceptance campaign
(1,000 cases and concurrent runs); this runs a seeded sample bounded to about 10 s of CPU."""

from __future__ import annotations

from fuzz_import import FAILURES, fuzz, summary

BUDGET_S = 10.0  # CPU seconds: about 70 cases, 15 s on an idle machine


def test_mutated_imports_and_faulty_outputs_are_refused_or_accepted() -> None:
    outcomes = fuzz(n=200, seed=32, budget_s=BUDGET_S)
    assert len(outcomes) >= 24, "too few cases ran within the budget to mean anything"
    assert not [o for o in outcomes if o.result in FAILURES], summary(outcomes)
    assert {o.result for o in outcomes} >= {"refused", "accepted"}, summary(outcomes)
