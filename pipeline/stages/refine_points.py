"""Stage ``refine`` of a point-sensor session: :mod:`pipeline.stages.refine` without the
``ranges`` input (a point session records none; level ``points``)."""

from __future__ import annotations

import dataclasses

from pipeline.stages import refine

STAGE = dataclasses.replace(
    refine.STAGE, inputs=tuple(i for i in refine.STAGE.inputs if i != "ranges")
)
