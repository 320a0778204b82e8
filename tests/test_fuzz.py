"""Seeded mutations of a small committed recording (issue 13): refused or unchanged, never a
traceback, a hang, or a silently different signature. ``make fuzz`` runs the full acceptance
(700 mutations of robot3); this runs a sample bounded to about 30 s."""

from __future__ import annotations

from pathlib import Path

from fuzz_recording import FAILURES, fuzz, summary

#: `pipeline simulate tests/data/fuzz-small --seed 13 --points 12 --repeats 3`, then only
#: recording.mcap kept (25 kB: 6 sweeps of 12 positions, 3 cycles each).
SMALL = Path(__file__).parent / "data" / "fuzz-small" / "recording.mcap"
BUDGET_S = 30.0


def test_mutated_recordings_are_refused_or_unchanged() -> None:
    outcomes = fuzz(SMALL, n_byte=150, n_json=100, seed=13, budget_s=BUDGET_S)
    assert len(outcomes) >= 20, "too few mutations ran within the budget to mean anything"
    assert not [o for o in outcomes if o.result in FAILURES], summary(outcomes)
    assert {o.result for o in outcomes} >= {"refused"}
