"""Stage ``holdout`` of a sonic session: :mod:`pipeline.stages.holdout` with the raw slant
ranges as an input too (the refinement's level ``ranges`` rebuilds its problem from them)."""

from __future__ import annotations

from pipeline.stages.holdout import SONIC_STAGE as STAGE

__all__ = ["STAGE"]
