"""Seeded odd input on issue 44's surfaces (plan numbers, map conventions and σ, validate
cells, long session names, export --onto non-files): refused in one line or accepted,
never a traceback, exit 70, a hang, a destroyed file or a number out of range taken
without a word. ``make fuzz-inputs`` runs the campaign (1,000 cases); this runs a seeded
sample bounded to about 10 s of CPU."""

from __future__ import annotations

from fuzz_import import summary
from fuzz_inputs import FAILURES, fuzz

BUDGET_S = 10.0  # CPU seconds


def test_odd_input_on_the_issue_44_surfaces_is_refused_or_accepted() -> None:
    outcomes = fuzz(n=200, seed=44, budget_s=BUDGET_S)
    assert len(outcomes) >= 20, "too few cases ran within the budget to mean anything"
    assert not [o for o in outcomes if o.result in FAILURES], summary(outcomes, FAILURES)
    assert {o.result for o in outcomes} >= {"refused", "accepted"}, summary(outcomes, FAILURES)
