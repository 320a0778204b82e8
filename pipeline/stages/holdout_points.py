"""Stage ``holdout`` of a point-sensor session: :mod:`pipeline.stages.holdout` without the
``ranges`` input (a point session records none)."""

from __future__ import annotations

from pipeline.stages.holdout import POINTS_STAGE as STAGE

__all__ = ["STAGE"]
