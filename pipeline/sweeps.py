"""Sweep ids: the ``sweep`` key of every table, and how a recording spells it.

Joint sweeps are their joint number (1..n); the tool-probe measurement and the
validation configurations have ids of their own. Pure vocabulary shared by the
recording readers (:mod:`pipeline.stages.recording_keys`), the stage modules and the
math below them (:mod:`pipeline.refine`, :mod:`pipeline.sensor`), defined once here.
"""

from __future__ import annotations

TOOL_SWEEP = 0  # the tool-probe measurement's sweep id in tables ("tool" in the recording)
CHECK_SWEEP = -1  # validation configurations' sweep id in tables ("check" in the recording)
_NAMED = {"tool": TOOL_SWEEP, "check": CHECK_SWEEP}


def sweep_name(sweep: int) -> str:
    """A sweep id as the recording spells it: the target number, 'tool' or 'check'."""
    return {TOOL_SWEEP: "tool", CHECK_SWEEP: "check"}.get(int(sweep), str(int(sweep)))


def sweep_id(recorded: int | str) -> int:
    """The table id of a recorded sweep (a joint number, 'tool' or 'check')."""
    return _NAMED[recorded] if isinstance(recorded, str) else int(recorded)
