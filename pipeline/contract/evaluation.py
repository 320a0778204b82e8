"""Read ``evaluation.mcap`` (channels ``/eval/*``, schemas in ``schemas/mcap/eval_*.json``).

The pipeline's only door to the evaluation recording; it knows nothing of the rig.
Integrity (CRCs, the ``armsig.content`` digest) and every message's schema are
checked by :func:`pipeline.contract.mcap_read.read_mcap`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.contract.channels import EVAL_CHANNELS
from pipeline.contract.mcap_read import read_mcap
from pipeline.errors import RecordingError

TOPICS = tuple(EVAL_CHANNELS)


@dataclass(frozen=True)
class EvaluationRecording:
    """The messages of an evaluation recording, in time order per channel.

    ``program`` and ``measurements`` are empty when only the teaching was recorded.
    """

    path: Path
    description: dict[str, Any]
    teach: list[dict[str, Any]]
    program: list[dict[str, Any]]
    measurements: list[dict[str, Any]]


def read_evaluation(path: str | Path) -> EvaluationRecording:
    """Parse an evaluation recording, with clear errors for foreign or broken files."""
    p = Path(path)
    msgs = read_mcap(
        p,
        EVAL_CHANNELS,
        fix="delete it and run `pipeline evaluate` again (a simulated session re-records it)",
    ).messages
    for topic in TOPICS:
        msgs[topic].sort(key=lambda tm: tm[0])  # stable: equal times keep file order
    if len(msgs["/eval/description"]) != 1 or not msgs["/eval/teach"]:
        raise RecordingError(
            f"{p}: no /eval/description or /eval/teach",
            expected="one /eval/description message and the teach readings of every task",
            fix="record the teaching (schemas/mcap/eval_teach.json)",
        )
    return EvaluationRecording(
        path=p,
        description=msgs["/eval/description"][0][1],
        teach=[m for _, m in msgs["/eval/teach"]],
        program=[m for _, m in msgs["/eval/program"]],
        measurements=[m for _, m in msgs["/eval/measurement"]],
    )
