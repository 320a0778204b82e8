"""Sweep ids: the ``sweep`` key of every table, and how a recording spells it.

Joint sweeps are their joint number (1..n); the tool-probe measurement, the
validation configurations and a pose set (configurations in which any joints move, the
whole arm measured at each: random poses of a laser-tracker calibration) have ids of
their own. Pure vocabulary shared by the
recording readers (:mod:`pipeline.stages.recording_keys`), the stage modules and the
math below them (:mod:`pipeline.refine`, :mod:`pipeline.sensor`), defined once here.
"""

from __future__ import annotations

TOOL_SWEEP = 0  # the tool-probe measurement's sweep id in tables ("tool" in the recording)
CHECK_SWEEP = -1  # validation configurations' sweep id in tables ("check" in the recording)
POSES_SWEEP = -2  # a pose set's sweep id in tables ("poses" in the recording)
_NAMED = {"tool": TOOL_SWEEP, "check": CHECK_SWEEP, "poses": POSES_SWEEP}
_NAMES = {v: k for k, v in _NAMED.items()}
#: Sweeps whose configurations move any joints and whose points are on the last link:
#: the tool's own measurements, not a joint's circle or line.
WHOLE_ARM_SWEEPS = (TOOL_SWEEP, CHECK_SWEEP, POSES_SWEEP)


def sweep_name(sweep: int) -> str:
    """A sweep id as the recording spells it: the target number, 'tool', 'check' or 'poses'."""
    return _NAMES.get(int(sweep), str(int(sweep)))


def sweep_id(recorded: int | str) -> int:
    """The table id of a recorded sweep (a joint number, 'tool', 'check' or 'poses')."""
    return _NAMED[recorded] if isinstance(recorded, str) else int(recorded)
