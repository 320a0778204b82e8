"""Read ``evaluation.mcap`` (channels ``/eval/*``, schemas in ``schemas/mcap/eval_*.json``).

The pipeline's only door to the evaluation recording; it knows nothing of the rig.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.errors import RecordingError
from pipeline.stages.recording import check_required_fields

TOPICS = ("/eval/description", "/eval/teach", "/eval/program", "/eval/measurement")
_REQUIRED = {
    "/eval/description": ("mode", "servo", "instruments", "robot"),
    "/eval/teach": ("task", "point", "q_encoder", "units"),
    "/eval/program": ("task", "controller", "point", "q_commanded", "units"),
    "/eval/measurement": ("task", "controller", "point", "instrument"),
}


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
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    p = Path(path)
    msgs: dict[str, list[tuple[int, dict[str, Any]]]] = {t: [] for t in TOPICS}
    try:
        with p.open("rb") as fh:
            for _schema, channel, message in make_reader(fh).iter_messages(log_time_order=False):
                if channel.topic in msgs:
                    msgs[channel.topic].append((message.log_time, json.loads(message.data)))
    except (McapError, EOFError, ValueError, OSError, json.JSONDecodeError) as exc:
        raise RecordingError(
            f"{p}: evaluation recording is unreadable",
            got=f"{type(exc).__name__}: {exc}",
            fix="delete it and run `pipeline evaluate` again (a simulated session re-records it)",
        ) from exc
    for topic in _REQUIRED:
        msgs[topic].sort(key=lambda tm: tm[0])
    check_required_fields(p, msgs, _REQUIRED)
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
